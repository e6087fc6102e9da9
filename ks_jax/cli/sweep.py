"""``ks-jax sweep FILE --over PATH=START:STOP:N ... --out results.csv|.npz|.parquet`` (docs/sweeps.md)."""

from __future__ import annotations

import math
import sys
import time
from dataclasses import replace
from typing import NamedTuple

import numpy as np

from ..case import canonical_path, input_kind, input_leaf, load_cases
from ..case.errors import CaseError, visible
from ..plot import check_picture_path, save_sweep_view
from ..sweeps import ResultWriter, SweepSample, sweep
from ..sweeps.columns import typed_back
from ..limits import check_memory
from ..sweeps.engine import check_distinct, result_shape
from ..sweeps.files import CSV_HINT_POINTS
from .. import units as U
from ..units import UnitError, parse_quantity
from .options import seed_option, smoothing_option
from .signals import raise_if_stopped


def add_arguments(parser):
    """The arguments of ``ks-jax sweep``."""
    parser.add_argument("file", help="a case file (JSON or TOML): one case, or several with --case K")
    parser.add_argument("--over", action="append", required=True, metavar="PATH=START:STOP:N",
                        help="an input path and its values: START:STOP:N (N evenly spaced values), "
                             "V1,V2,..., or random values uniform:LO:HI or normal:MEAN:SD (with --samples); "
                             "bare numbers are SI except angles (deg) and rates (deg/s), whatever --units says "
                             "(with --units us a bare number of a kind whose unit differs, a speed or a length, is "
                             "refused: give its unit); unit strings allowed, e.g. vehicles[1].speed=10mph:60mph:51")
    parser.add_argument("--output", action="append", metavar="PATH",
                        help="a result's path, e.g. 'vehicles[0].delta_v_magnitude' "
                             "(repeat; default: the main results)")
    parser.add_argument("--mode", choices=("grid", "zip"), default=None,
                        help="grid: cartesian product (default); zip: the k-th values of every path together "
                             "(the default with random values)")
    parser.add_argument("--samples", type=int, default=None, metavar="N",
                        help="number of random values of each PATH=uniform:LO:HI or PATH=normal:MEAN:SD (Monte Carlo)")
    parser.add_argument("--seed", type=seed_option, default=0, help="seed of the random values (default 0)")
    parser.add_argument("--out", required=True, metavar="FILE", help="results file: .csv, .npz or .parquet")
    parser.add_argument("--case", type=int, default=None, metavar="K",
                        help="the K-th case (0-based) of a multi-case file")
    parser.add_argument("--chunk-size", type=int, default=None, help="rows per device and chunk (default 16384)")
    parser.add_argument("--smoothing", type=smoothing_option, default=0.0, help="smooth friction cone, tau in [0, 1)")
    parser.add_argument("--float32", action="store_true", help="store the results as float32")
    parser.add_argument("--units", choices=("si", "us"), default="si",
                        help="units of the file: si (default) or us (mph, ft, lbf s, ft lbf, deg, deg/s, lb; "
                             "each column's unit in its name, e.g. 'vehicles[1].speed [mph]')")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument("--plot", metavar="PNG", help="also draw the outputs over the swept inputs, in the units of "
                        "--units and, where --over gave values in a unit (10km/h:80km/h:8), in that unit: a map for "
                        "two inputs, a line for one, histograms for --mode zip (matplotlib)")


class Draws(NamedTuple):
    """Random values of one input (``--over PATH=uniform:LO:HI`` or ``normal:MEAN:SD``), SI."""

    path: str
    law: str
    a: float
    b: float

    def draw(self, n, rng):
        """n values from ``rng`` (a ``numpy.random.Generator``)."""
        if self.law == "uniform":
            return rng.uniform(self.a, self.b, n)
        return rng.normal(self.a, self.b, n)


def parse_over(text, units="si"):
    """'PATH=START:STOP:N' or 'PATH=V1,V2,...' -> (path, SI values); 'PATH=uniform:LO:HI' or
    'PATH=normal:MEAN:SD' -> (path, ``Draws``), drawn by ``draw_over``. A grid typed in plain SI numbers
    has its values within 2 ulp of a 15-digit decimal made that decimal (linspace's rounding undone: 0.05,
    not 0.049999999999999996). ``units``: the file's units (``--units``), which set what is written only:
    a bare number is SI as in case files, and with "us" one whose kind has another unit in US units (a
    speed, a length, a mass) is refused (``check_bare``)."""
    if "=" not in text:
        raise CaseError(f"--over {text!r}: expected PATH=START:STOP:N, PATH=V1,V2,..., PATH=uniform:LO:HI "
                        "or PATH=normal:MEAN:SD")
    path, spec = (s.strip() for s in text.split("=", 1))
    input_leaf(path)
    kind = input_kind(path)

    def q(v):
        try:
            return parse_quantity(v.strip(), kind)
        except UnitError as err:
            raise CaseError(f"--over {path}: {v.strip()!r}: {err}") from None

    parts = spec.split(":")
    law = parts[0].strip().lower()
    check_bare(path, spec, kind, units)
    if law in ("uniform", "normal"):
        names = ("LO", "HI") if law == "uniform" else ("MEAN", "SD")
        if len(parts) != 3:
            raise CaseError(f"--over {path}={spec}: expected {law}:{':'.join(names)}")
        a, b = q(parts[1]), q(parts[2])
        for name, part, value in zip(names, parts[1:], (a, b)):
            if not math.isfinite(value):
                raise CaseError(f"--over {path}: {name} = {part.strip()!r} must be a finite number")
        if law == "uniform" and a > b:
            raise CaseError(f"--over {path}={spec}: LO must not exceed HI")
        if law == "normal" and b < 0:
            raise CaseError(f"--over {path}={spec}: SD must be >= 0")
        return path, Draws(path, law, a, b)
    if len(parts) == 3:
        try:
            n = int(parts[2])
        except ValueError:
            raise CaseError(f"--over {path}: N = {parts[2]!r} must be a whole number") from None
        if n < 1:
            raise CaseError(f"--over {path}: N = {n} must be at least 1")
        check_memory(8 * n, f"--over {path}: a grid of N = {n} values", "give fewer values")
        ends = q(parts[0]), q(parts[1])
        for name, part, value in zip(("START", "STOP"), parts, ends):
            if not math.isfinite(value):
                raise CaseError(f"--over {path}: {name} = {part.strip()!r} must be a finite number")
        if n == 1 and ends[0] != ends[1]:
            raise CaseError(f"--over {path}={spec}: N = 1 would solve START alone and leave STOP out: give N >= 2, "
                            "or one value (PATH=V)")
        grid = np.linspace(*ends, n)
        return path, typed_back(grid) if all(_plain(t) == v for t, v in zip(parts, ends)) else grid
    if len(parts) == 1:
        if any(not v.strip() for v in spec.split(",")):
            raise CaseError(f"--over {path}={spec}: a value is missing between commas (V1,V2,...)")
        values = [(v.strip(), q(v)) for v in spec.split(",")]
        for text, value in values:
            if not math.isfinite(value):
                raise CaseError(f"--over {path}: {text!r} must be a finite number")
        return path, np.array([value for _, value in values])
    raise CaseError(f"--over {path}={spec}: expected START:STOP:N, V1,V2,..., uniform:LO:HI or normal:MEAN:SD")


def _values(spec):
    """The value texts of an --over spec (START and STOP, LO and HI, MEAN and SD, or V1, V2, ...) and how to
    put them back: (texts, join), join(new texts) giving the spec with each replaced."""
    parts = spec.split(":")
    if parts[0].strip().lower() in ("uniform", "normal"):
        return parts[1:], lambda new: ":".join([parts[0], *new])
    if len(parts) == 3:
        return parts[:2], lambda new: ":".join([*new, parts[2]])
    if len(parts) == 1:
        values = spec.split(",")
        return values, ",".join
    return [], None


def check_bare(path, spec, kind, units):
    """With ``--units us``, a bare number (other than 0) of a kind whose unit is another in US units than in
    SI (a speed: mph against m/s) is refused, naming both ways to write it: ``--units`` sets the units of the
    file written, not of the values typed, and a bare 20 for a speed is 20 m/s (45 mph). A dimensionless
    value (restitution, friction), a time (s) and an angle or a rate (deg, deg/s in both) need no unit."""
    if units != "us":
        return
    si, us = U.SI_DISPLAY[kind][1], U.US_DISPLAY[kind][1]
    if si == us:
        return
    texts, join = _values(spec)
    bare = [t for t in texts if U.typed_unit(t) is None and _plain(t) is not None and math.isfinite(_plain(t))
            and _plain(t) != 0.0]  # 0 is 0 in any unit; a non-finite value is refused as such
    if not bare:
        return
    typed = lambda unit: join([t if U.typed_unit(t) or _plain(t) is None else f"{t.strip()}{unit.replace(' ', '*')}"  # noqa: E731
                               for t in texts])
    raise CaseError(f"--over {path}={spec}: bare numbers are SI ({si}) but --units us was given (it sets the units "
                    f"of the file written, not of the values typed): write {typed(us)}, or give SI values with "
                    f"units ({typed(si)})")


def typed_units(texts):
    """{input path: the unit its --over values were typed in} ("vehicles[1].speed=10km/h:80km/h:8" ->
    {"vehicles[1].speed": "km/h"}; the unit of START, LO, MEAN or the first value), for the picture; paths
    given in bare numbers are left out."""
    typed = {}
    for text in texts:
        path, _, spec = text.partition("=")
        parts = spec.split(":")
        first = parts[1] if parts[0].strip().lower() in ("uniform", "normal") and len(parts) > 1 else parts[0]
        unit = U.typed_unit(first.split(",")[0])
        if unit:
            typed[canonical_path(path.strip())] = unit
    return typed


def _plain(text):
    """The number a bare numeral means (None for anything with a unit): a grid typed in SI numbers is
    snapped to its decimals (0:0.3:7 gives 0.05, not 0.049999999999999996); one converted from mph or
    deg is left as converted (the file in US units types it back)."""
    try:
        return float(text)
    except ValueError:
        return None


def draw_over(specs, mode, samples, seed):
    """({path: SI values}, mode) from ``parse_over``'s (path, values or Draws): the draws made with
    ``numpy.random.default_rng(seed)``, ``samples`` each, in the order given (zip mode). Values given as
    numbers stay as they are."""
    check_distinct([p for p, _ in specs], "--over")
    draws = [p for p, v in specs if isinstance(v, Draws)]
    if not draws:
        if samples is not None:
            raise CaseError("--samples N is for random values: give --over PATH=uniform:LO:HI or PATH=normal:MEAN:SD")
        return dict(specs), mode or "grid"
    if samples is None or samples < 1:
        raise CaseError(f"--over {draws[0]}=...: random values need --samples N (N >= 1), got {samples}")
    if mode == "grid":
        raise CaseError(f"--over {draws[0]}=...: random values are samples, swept together (--mode zip), not a grid")
    # every path's values are held in memory (8 bytes each) before the sweep starts
    check_memory(8 * samples * len(specs), f"--samples {samples} for {len(specs)} path{'s' * (len(specs) != 1)}",
                 "give fewer samples, or run several sweeps with other --seed values")
    rng = np.random.default_rng(seed)
    return {p: v.draw(samples, rng) if isinstance(v, Draws) else v for p, v in specs}, "zip"


def run(args) -> int:
    """``ks-jax sweep``: the case solved over the values of ``--over``, written to ``--out`` chunk by chunk."""
    cases = load_cases(args.file)
    if args.case is None:
        if len(cases) != 1:
            raise CaseError(f"{args.file} holds {len(cases)} cases: choose one with --case K (0-based)")
        case = cases[0]
    else:
        if not 0 <= args.case < len(cases):
            raise CaseError(f"--case {args.case}: {args.file} holds {len(cases)} cases (0..{len(cases) - 1})")
        case = cases[args.case]
    if not case.valid:  # the error names the case as the file does ("case 50" is the 50th); --case counts from 0
        chosen = "" if args.case is None else f"--case {args.case} (the file's case {args.case + 1}): "
        raise CaseError(chosen + case.error)
    over, mode = draw_over([parse_over(t, args.units) for t in args.over], args.mode, args.samples, args.seed)
    shape = result_shape({p: len(v) for p, v in over.items()}, mode)  # sweep's rule, checked before a file exists
    sample = _plot_sample(args.plot, over, mode, shape)  # checked before anything is solved
    writer = ResultWriter(args.out, over, mode, shape, units=args.units)  # chunk by chunk: memory stays bounded

    def on_chunk(lo, hi, chunk):
        raise_if_stopped()  # a Ctrl-C or kill that a library caught while the chunk was solved
        writer.chunk(lo, hi, chunk)
        if sample is not None:
            sample.chunk(lo, hi, chunk)

    t = time.perf_counter()
    try:
        result = sweep(case, over, outputs=args.output, mode=mode, chunk_size=args.chunk_size,
                       smoothing=args.smoothing, progress=False if args.no_progress else None,
                       output_dtype=np.float32 if args.float32 else None, on_chunk=on_chunk, keep=False,
                       plan=args.plan)
        raise_if_stopped()
        writer.close()
    except (KeyboardInterrupt, SystemExit):  # Ctrl-C or a kill: the finished points are kept, and said so
        kept, rows = writer.keep_incomplete()
        where = f"written to {kept}" if kept else "written"
        print(f"ks-jax sweep: stopped: {rows:,} of {writer.points:,} points {where}; {args.out} is left as it was",
              file=sys.stderr)
        raise
    except BaseException:
        writer.abort()
        raise
    result = replace(result, seconds=max(result.seconds - writer.chunk_seconds, 0.0))  # solving alone
    print(f"ks-jax sweep: {visible(case.name)}")
    print(f"  {result.summary()}")
    if args.samples is not None:
        print(f"  random values: {args.samples} per path, seed {args.seed}")
    print(f"  written to {args.out} in {writer.seconds:.3g} s ({time.perf_counter() - t:.3g} s in all)")
    if writer.slow_csv and writer.points >= CSV_HINT_POINTS:
        print("  (a large .csv is written several times faster with pyarrow installed: "
              "pip install 'ks-jax[parquet]'; or write .npz / .parquet)")
    if sample is not None:
        save_sweep_view(sample.result(result), args.plot, units=args.units, typed=typed_units(args.over))
        print(f"  drawn to {args.plot}")
    return 0


def _plot_sample(path, over, mode, shape):
    """A ``SweepSample`` for ``--plot PATH`` (None without it), after the checks a picture needs."""
    if path is None:
        return None
    check_picture_path(path)
    if mode != "zip" and len(over) > 2:
        raise CaseError(f"--plot draws a sweep over one or two inputs; this one has {len(over)} "
                        f"({', '.join(over)}): leave --plot out, or sweep fewer inputs")
    return SweepSample(over, mode, shape)
