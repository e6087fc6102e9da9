"""``ks-jax fit FILE``: the case's ``unknowns`` reconstructed from its ``evidence`` (docs/fit.md).

The text report is ``fit.report.text_report``; ``--json`` prints ``{"cases": [...]}``, as ``ks-jax solve --json``
does, one entry per case of the file (one case or several): ``FitResult.to_dict`` (SI values, null for "not
determined"), or for a case that was not fitted the same keys, its status and nothing fitted
(``FitResult.refused``). Names are written exactly as the file gives them in JSON, and escaped
(``case.visible``) where they reach the terminal. Monte Carlo shows a progress
bar on stderr. ``--plot FILE`` draws the top view of each fitted case solved at its estimate (the case's
inputs with the unknowns set to it), with the measured rest positions among its evidence marked and their
sigmas drawn about them: the picture to set beside a scene diagram.
"""

from __future__ import annotations

import dataclasses
import json
import sys
from pathlib import Path

import numpy as np

from fit import reconstruct
from fit.posterior import TARGET_ACCEPTANCE
from fit.posterior import sampler as posterior_sampler
from fit.problem import case_at
from fit.reconstruction import FitResult
from fit.report import DISPLAY, text_report

from ..case import input_kind, load_cases
from ..case.errors import CaseError, visible, visible_lines
from ..plot import check_picture_path, save_corner, save_top_view
from ..solve import solve
from .options import acceptance_option, seed_option, smoothing_option


def add_arguments(parser) -> None:
    """The arguments of ``ks-jax fit``."""
    parser.add_argument("file", help="case file (JSON or TOML) with 'unknowns' and 'evidence'")
    parser.add_argument("--json", action="store_true", help="print the result as JSON (SI units)")
    parser.add_argument("--starts", type=int, default=8,
                        help="starts per round (default 8): more rounds follow until two starts reach the best fit "
                             "and its chi^2 is probable, up to --max-starts")
    parser.add_argument("--max-starts", type=int, default=None, metavar="N",
                        help="starts in all, at most (default 8 x --starts; --max-starts equal to --starts: one "
                             "round)")
    parser.add_argument("--monte-carlo", type=int, default=0, metavar="N",
                        help="refit N copies of the evidence perturbed by its sigmas; report 5/50/95 percentiles")
    parser.add_argument("--posterior", type=int, default=0, metavar="N",
                        help="draw N samples per chain of the unknowns' posterior by NUTS, after as many adaptation "
                             "steps (the 'posterior' extra); report mean, std, quantiles, R-hat and ESS")
    parser.add_argument("--chains", type=int, default=4, help="NUTS chains for --posterior (default 4)")
    parser.add_argument("--target-acceptance", type=acceptance_option, default=TARGET_ACCEPTANCE, metavar="P",
                        help="the mean acceptance that --posterior's adaptation tunes NUTS's step size toward, in "
                             f"(0, 1) (default {TARGET_ACCEPTANCE}); 0.9 or 0.95 where transitions diverge (a bound, "
                             "a sharp edge): smaller steps, more gradients per draw")
    parser.add_argument("--seed", type=seed_option, default=0, help="random seed for the starts, Monte Carlo and "
                                                                       "the posterior")
    parser.add_argument("--smoothing", type=smoothing_option, default=1e-3,
                        help="smooth friction cone tau (> 0 keeps the fit differentiable; default 1e-3)")
    parser.add_argument("--solver", choices=("lm", "lbfgs", "adam"), default="lm",
                        help="lm: Levenberg-Marquardt (default); lbfgs, adam: optax")
    parser.add_argument("--plot", metavar="PNG",
                        help="write the top view of the case solved at the estimate (.png, .pdf or .svg), with the "
                             "measured rest positions marked (matplotlib); with --posterior also the posterior's "
                             "corner plot, to PNG's name with '_posterior' ('_posterior_1', '_posterior_2', ... "
                             "where several cases are sampled)")


def run(args) -> int:
    """``ks-jax fit``: exit status 0 where every case was fitted, converged, with an impulse exchanged at its
    estimate; 1 where one was not (each said on stderr); 2 for a file or an argument that is refused."""
    if args.plot:
        check_picture_path(args.plot)  # before fitting: a bad name loses no work
        if args.posterior:
            check_picture_path(posterior_path(args.plot))
    cases = load_cases(args.file)
    if args.starts < 1:
        raise CaseError(f"--starts {args.starts}: need at least one start")
    if args.max_starts is not None and args.max_starts < args.starts:
        raise CaseError(f"--max-starts {args.max_starts}: must be at least --starts ({args.starts})")
    if args.posterior < 0 or args.chains < 1:
        raise CaseError(f"--posterior {args.posterior} --chains {args.chains}: draws must be >= 0 and chains >= 1")
    if args.posterior:
        try:  # before fitting: a missing extra loses no work
            posterior_sampler()
        except ImportError as err:
            raise CaseError(f"--posterior: {err}") from None
    if args.monte_carlo < 0:
        raise CaseError(f"--monte-carlo {args.monte_carlo}: must be >= 0")
    results = []
    for case in cases:
        try:
            if not case.valid:
                raise CaseError(case.error)
            for key in ("unknowns", "evidence"):
                if key not in case.raw:
                    raise CaseError(f"case '{visible(case.name)}': {key}: missing field "
                                    "(ks-jax fit needs 'unknowns' and 'evidence', docs/fit.md)")
            results.append(reconstruct(case, starts=args.starts, seed=args.seed, monte_carlo=args.monte_carlo,
                                       smoothing=args.smoothing, solver=args.solver,
                                       progress=args.monte_carlo > 0 or args.posterior > 0,
                                       max_starts=args.max_starts, posterior=args.posterior, chains=args.chains,
                                       plan=args.plan, target_acceptance=args.target_acceptance))
        except CaseError as err:  # in a file of several cases: reported, and the others are fitted
            if len(cases) == 1:
                raise
            results.append(FitResult.refused(case.name, err))
    if args.json:
        print(json.dumps({"cases": [r.to_dict() for r in results]}, indent=1))
    else:
        print("\n\n".join(visible_lines(text_report(dataclasses.replace(r, case_name=visible(r.case_name),
                                                                              status=visible(r.status))))
                           for r in results))
    failed = {k: r.status for k, r in enumerate(results) if r.status.startswith("invalid")}
    for k, message in sorted(failed.items()):
        print(f"ks-jax: case '{visible(cases[k].name)}' not fitted: {visible(message)}", file=sys.stderr)
    # a fit that ended without converging, or where the vehicles exchange no impulse, is no answer either: a
    # script reading the exit status must be able to tell
    unfinished = {k: r for k, r in enumerate(results) if k not in failed
                  and not (r.converged and r.status == "ok")}
    for k, r in sorted(unfinished.items()):
        why = "did not converge" if not r.converged else f"ended where the exchange is '{r.status}'"
        print(f"ks-jax: case '{visible(cases[k].name)}': the fit {why} (see its notes); its estimate is not an answer",
              file=sys.stderr)
    if args.plot:
        drawn = [(c, r) for k, (c, r) in enumerate(zip(cases, results)) if k not in failed]
        if drawn:
            save_top_view(solve([case_at(c, r.estimate, f"{c.name}\nat the fit's estimate") for c, r in drawn],
                                plan=args.plan), args.plot,
                          evidence=[{e.path: e.value for e in r.evidence} for _, r in drawn],
                          sigma=[{e.path: e.sigma for e in r.evidence} for _, r in drawn])
            print(f"\ntop view at the estimate written to {args.plot}", file=sys.stderr if args.json else sys.stdout)
            sampled = [r for _, r in drawn if r.posterior is not None]
            for k, r in enumerate(sampled):
                path = posterior_path(args.plot, k if len(sampled) > 1 else None)
                save_posterior(r, path)
                print(f"posterior corner plot written to {path}", file=sys.stderr if args.json else sys.stdout)
        else:
            print(f"ks-jax: --plot {args.plot}: no case was fitted; nothing drawn", file=sys.stderr)
    return 1 if failed or unfinished else 0


def posterior_path(plot, k=None) -> str:
    """Where ``--plot FILE`` puts a posterior's corner plot, of FILE's type: FILE_posterior where one case of the
    file is sampled; where several are, FILE_posterior_1, FILE_posterior_2, ... in their order (``k`` from 0)."""
    p = Path(plot)
    return str(p.with_name(f"{p.stem}_posterior{'' if k is None else f'_{k + 1}'}{p.suffix}"))


def save_posterior(result, path):
    """The corner plot of ``result``'s posterior draws in the trade's units, the Laplace estimate and covariance
    over them (``ks_jax.plot.corner``)."""
    paths = [u.path for u in result.unknowns]
    units = [DISPLAY.get(input_kind(p), ("", 1.0, 1.0)) for p in paths]
    scale = np.array([u[1] for u in units])
    labels = [f"{p} [{u[0]}]" if u[0] else p for p, u in zip(paths, units)]
    post = result.posterior
    samples = post.samples.reshape(-1, len(paths)) / scale
    estimate = np.array([result.estimate[p] for p in paths]) / scale
    return save_corner(path, samples, labels, estimate, np.asarray(result.covariance) / np.outer(scale, scale),
                       title=f"{visible(result.case_name)}: posterior ({post.chains} chains x {post.draws} draws) "
                             "and Laplace")
