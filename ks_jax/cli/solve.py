"""``ks-jax solve FILE`` (the auto-ees panel, or ``--json``) and ``ks-jax demo`` (the two Virtual CRASH manual
chapters beside the manual's values)."""

from __future__ import annotations

import json
import sys
from importlib import resources

from ..case import load_case, load_cases
from ..case.errors import CaseError, visible
from ..plot import check_picture_path, save_top_view
from ..report import text_report
from ..solve import solve
from .options import smoothing_option

DEMO_CASES = ("seed_000_saturn_pontiac.json", "seed_001_lucid_kia.toml")
DEMO_NOTES = {  # what the reference table cannot say by itself
    "seed_000_saturn_pontiac.json": (
        "The crushes agree by construction: the case's CG positions (cg_to_front) were chosen to put the\n"
        "boxes at the panel's deformations from the centroid; the EES follow from them."),
    "seed_001_lucid_kia.toml": (
        "The chapter's own arithmetic is off in its last digits: 1.1 x 61.04 slug x 22 ft/s = 1477.17 lbf s\n"
        "(it prints 1477.21), its 6571.96 N s is 1477.44 lbf s, and its energies carry the same slips.\n"
        "ks-jax gives the exact 1477.169 lbf s (6570.775 N s)."),
}


def add_solve_arguments(parser):
    """The arguments of ``ks-jax solve``."""
    parser.add_argument("file", help="a case file (JSON or TOML): one case, or several under 'cases'")
    parser.add_argument("--json", action="store_true",
                        help="print the results as JSON (SI units; the names of docs/model.md, \"Results\")")
    parser.add_argument("--smoothing", type=smoothing_option, default=0.0,
                        help="smooth friction cone, tau in [0, 1) (default 0: exact)")
    parser.add_argument("--plot", metavar="PNG", help="write a top view of the contact to this file")
    parser.add_argument("--units", choices=("si", "us"), default=None,
                        help="the panel in SI or US units alone (default: SI beside US); the JSON is SI")


def run_solve(args) -> int:
    """``ks-jax solve``: exit status 0, or 1 where a case of several was not solved."""
    if args.plot:
        check_picture_path(args.plot)  # before solving: a bad name loses no work
    if args.json and args.units:
        raise CaseError(f"--units {args.units} sets the panel's units; --json is SI (docs/model.md, \"Results\"): "
                        "give one of them")
    cases = load_cases(args.file)
    if len(cases) == 1 and not cases[0].valid:
        raise CaseError(cases[0].error)
    solutions = solve(cases, smoothing=args.smoothing, plan=args.plan)
    if args.json:
        print(json.dumps({"cases": [s.to_dict() for s in solutions]}, indent=1))
        for s in solutions:  # the panel prints them; beside JSON they are said on stderr too
            for note in s.notes():
                print(f"ks-jax: case '{visible(s.case.name)}': {visible(note)}", file=sys.stderr)
    else:
        print("\n\n".join(text_report(s, units=args.units or "both") for s in solutions))
    if args.plot:
        save_top_view(solutions, args.plot)
        print(f"\ntop view written to {args.plot}", file=sys.stderr if args.json else sys.stdout)
    bad = [s for s in solutions if s.status.startswith("invalid")]
    for s in bad:
        print(f"ks-jax: case '{visible(s.case.name)}' not solved: {visible(s.status)}", file=sys.stderr)
    return 1 if bad else 0


def run_demo(args) -> int:
    """``ks-jax demo``: both Virtual CRASH manual chapters solved from the case files shipped in the package."""
    print("ks-jax demo: the two Virtual CRASH manual chapters on Kudlich-Slibar impulse data,\n"
          "solved from the case files shipped in ks_jax/cases, beside the manual's panel values.\n")
    for name in DEMO_CASES:
        with resources.as_file(resources.files("ks_jax.cases") / name) as path:
            case = load_case(path)
        print(text_report(solve(case, plan=args.plan)))
        note = "".join(f"\n  {line}" for line in DEMO_NOTES[name].splitlines())
        print(f"{note}\n\n  (case file: ks_jax/cases/{name})\n" + "-" * 100 + "\n")
    return 0
