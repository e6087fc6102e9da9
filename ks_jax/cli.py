"""`ks-jax`: solve case files, run the seed chapters' demo, fit and sweep.

The command line computes in float64. A user error (bad file, bad field, bad unit) prints one
message naming the case, the field, the value and the rule, and exits with status 2. In a file
with several cases, a bad case is reported (on stderr and in the output) and the others are
solved; the exit status is then 1, so that a script can tell.
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import signal
import sys
import threading
from importlib import resources

import jax

from .case import CaseError
from .stored import keep_programs
from .units import UnitError

# subcommands that live in their own modules: name -> module with add_arguments(p) and run(args)
EXTERNAL = {"fit": ("fit.cli", "reconstruct unknown inputs from evidence"),
            "sweep": ("ks_jax.sweeps", "solve a grid or samples of inputs")}

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


def smoothing_option(text: str) -> float:
    """``--smoothing``: a number in [0, 1) (argparse type: a bad value is a usage error, exit 2)."""
    try:
        tau = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not 0.0 <= tau < 1.0:  # NaN fails too
        raise argparse.ArgumentTypeError(f"{text}: smoothing must be in [0, 1)")
    return tau


def seed_option(text: str) -> int:
    """``--seed``: a whole number >= 0 (NumPy's generators take no negative seed)."""
    try:
        seed = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    if seed < 0:
        raise argparse.ArgumentTypeError(f"{text}: a seed must be 0 or more")
    return seed


def check_output_file(path, option: str):
    """Raise CaseError unless ``path`` can be written: its folder exists and it is not a folder itself.
    Called before anything is solved, so that a bad name loses no work."""
    from pathlib import Path

    from .case import CaseError

    target = Path(path)
    folder = target.parent
    if target.is_dir():
        raise CaseError(f"{option} {path}: is a folder; give a file name")
    if not folder.is_dir():
        why = "is a file, not a folder" if folder.exists() else "does not exist"
        raise CaseError(f"{option} {path}: the folder '{folder}' {why}")


def _cmd_solve(args) -> int:
    from .case import load_cases
    from .report import solution_dict, text_report
    from .solve import solve

    if args.plot:
        from .plot import check_picture_path

        check_picture_path(args.plot)  # before solving: a bad name loses no work
    cases = load_cases(args.file)
    if len(cases) == 1 and not cases[0].valid:
        raise CaseError(cases[0].error)
    solutions = solve(cases, smoothing=args.smoothing)
    if args.json:
        print(json.dumps({"cases": [solution_dict(s) for s in solutions]}, indent=1))
    else:
        print("\n\n".join(text_report(s) for s in solutions))
    if args.plot:
        from .plot import save_top_view

        save_top_view(solutions, args.plot)
        print(f"\ntop view written to {args.plot}", file=sys.stderr if args.json else sys.stdout)
    bad = [s for s in solutions if s.status.startswith("invalid")]
    for s in bad:
        print(f"ks-jax: case '{s.case.name}' not solved: {s.status}", file=sys.stderr)
    return 1 if bad else 0


def _cmd_demo(args) -> int:
    from .case import load_case
    from .report import text_report
    from .solve import solve

    print("ks-jax demo: the two Virtual CRASH manual chapters on Kudlich-Slibar impulse data,\n"
          "solved from the case files shipped in ks_jax/cases, beside the manual's panel values.\n")
    for name in DEMO_CASES:
        with resources.as_file(resources.files("ks_jax.cases") / name) as path:
            case = load_case(path)
        print(text_report(solve(case)))
        note = "".join(f"\n  {line}" for line in DEMO_NOTES[name].splitlines())
        print(f"{note}\n\n  (case file: ks_jax/cases/{name})\n" + "-" * 100 + "\n")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="ks-jax", description="Kudlich-Slibar impulse-momentum collisions in JAX.")
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("solve", help="solve the case(s) in a JSON or TOML file")
    p.add_argument("file")
    p.add_argument("--json", action="store_true", help="print MODEL.md section 4 as JSON (SI units)")
    p.add_argument("--smoothing", type=smoothing_option, default=0.0,
                   help="smooth friction cone, tau in [0, 1) (default 0: exact)")
    p.add_argument("--plot", metavar="PNG", help="write a top view of the contact to this file")
    p.set_defaults(run=_cmd_solve)
    p = sub.add_parser("demo", help="solve the seed chapters' examples shipped with the package")
    p.set_defaults(run=_cmd_demo)
    for name, (module, help_text) in EXTERNAL.items():
        try:
            mod = importlib.import_module(module)
        except ImportError:
            continue
        p = sub.add_parser(name, help=help_text)
        mod.add_arguments(p)
        p.set_defaults(run=mod.run)
    return parser


def _compilation_cache():
    """Keep programs between runs (``ks_jax.keep_programs``: the first run of a command compiles for seconds;
    later runs load them). KS_JAX_CACHE=off disables it; KS_JAX_CACHE=DIR moves it."""
    where = os.environ.get("KS_JAX_CACHE", "")
    if where.lower() in ("off", "0", "no"):
        return
    try:
        keep_programs(where or None)
    except OSError:
        return


def _show_case_warnings():
    import warnings

    from .case import CaseWarning

    if getattr(warnings.showwarning, "_ks_jax", False):
        return

    def show(message, category, filename, lineno, file=None, line=None):
        if issubclass(category, CaseWarning):
            print(f"ks-jax: warning: {message}", file=sys.stderr)
        else:
            default_show(message, category, filename, lineno, file, line)

    default_show = warnings.showwarning
    show._ks_jax = True
    warnings.showwarning = show
    warnings.simplefilter("always", CaseWarning)


_SIGNALLED = []  # signals received by the command (``_stopped``), kept in case a library swallows the exception


def _stopped(signum, frame):
    """SIGINT (Ctrl-C) and SIGTERM (a kill): KeyboardInterrupt and SystemExit(128 + signum). The signal is
    also kept, and ``raise_if_stopped`` raises again where the command checks: a library that catches the
    exception raised inside it cannot make the command carry on as if nothing had happened."""
    _SIGNALLED.append(signum)
    if signum == signal.SIGINT:
        raise KeyboardInterrupt
    raise SystemExit(128 + signum)


def raise_if_stopped():
    """Raise again for a signal that ``_stopped`` received (nothing if none did)."""
    if _SIGNALLED:
        _stopped(_SIGNALLED[-1], None)


def main(argv=None) -> int:
    jax.config.update("jax_enable_x64", True)
    _show_case_warnings()
    _compilation_cache()
    args = build_parser().parse_args(argv)
    if argv is None and threading.current_thread() is threading.main_thread():
        # the command itself (not a call from Python): a kill unwinds as Ctrl-C does, so that a sweep
        # removes its unfinished file and an earlier --out stays as it was
        signal.signal(signal.SIGTERM, _stopped)
        signal.signal(signal.SIGINT, _stopped)
    try:
        return args.run(args)
    except (CaseError, UnitError, FileNotFoundError, IsADirectoryError) as err:
        print(f"ks-jax: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("ks-jax: interrupted (nothing half-written is left behind)", file=sys.stderr)
        return 130
    except BrokenPipeError:  # the reader went away (ks-jax demo | head): not an error
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
