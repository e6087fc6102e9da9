"""``ks-jax``: the command line (docs/ in the project: model.md, fit.md, sweeps.md, performance.md, devices.md).

Every command lives in a module of its own (``solve``: solve and demo; ``fit``; ``sweep``). The command line
computes in float64 and keeps compiled programs between runs (``ks_jax.compilation.keep_programs``;
``KS_JAX_CACHE=off`` disables it, ``KS_JAX_CACHE=DIR`` moves it). A user error (bad file, bad field, bad
unit) prints one message naming the case, the field, the value and the rule, and exits with status 2. In a
file with several cases, a bad case is reported (on stderr and in the output) and the others are solved;
the exit status is then 1, so that a script can tell.
"""

from __future__ import annotations

import argparse
import os
import re
import sys
import threading
import warnings

import jax

from .. import backend
from ..case.errors import CaseError, CaseWarning, visible
from ..compilation import keep_programs
from ..units import UnitError
from . import fit, signals, solve, sweep

EPILOG = ("The model, its frames, the case-file format and the result names: docs/model.md. Reconstruction: "
          "docs/fit.md. Sweeps: docs/sweeps.md. Speed and memory: docs/performance.md; GPUs and several devices: "
          "docs/devices.md. (In the project's "
          "repository; `ks-jax demo` solves the examples shipped in ks_jax/cases.)")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="ks-jax", description="Kudlich-Slibar impulse-momentum collisions in JAX.",
                                     epilog=EPILOG)
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("solve", help="solve the case(s) in a JSON or TOML file", epilog=EPILOG)
    solve.add_solve_arguments(p)
    p.set_defaults(run=solve.run_solve)
    p = sub.add_parser("demo", help="solve the two Virtual CRASH manual chapters' examples shipped with the package",
                       epilog=EPILOG)
    p.set_defaults(run=solve.run_demo)
    p = sub.add_parser("fit", help="reconstruct unknown inputs from evidence (docs/fit.md)", epilog=EPILOG)
    fit.add_arguments(p)
    p.set_defaults(run=fit.run)
    p = sub.add_parser("sweep", help="solve a grid or samples of inputs (docs/sweeps.md)", epilog=EPILOG)
    sweep.add_arguments(p)
    p.set_defaults(run=sweep.run)
    return parser


def _compilation_cache():
    """Keep programs between runs: the first run of a command compiles for seconds, later runs load them."""
    where = os.environ.get("KS_JAX_CACHE", "")
    if where.lower() in ("off", "0", "no"):
        return
    try:
        keep_programs(where or None)
    except OSError:
        return


def _show_case_warnings():
    """A CaseWarning (an unknown field ignored, precision lost) printed as one line, every time; a character of a
    name that the pictures' font cannot draw (matplotlib's warning, with its source lines) as one line per
    character."""
    if getattr(warnings.showwarning, "_ks_jax", False):
        return
    undrawn = set()

    def show(message, category, filename, lineno, file=None, line=None):
        glyph = re.match(r"Glyph (\d+) .*missing from font", str(message))
        if issubclass(category, CaseWarning):
            print(f"ks-jax: warning: {visible(message)}", file=sys.stderr)
        elif glyph and issubclass(category, UserWarning):
            code = int(glyph.group(1))
            if code not in undrawn:
                undrawn.add(code)
                print(f"ks-jax: note: the pictures' font has no glyph for {visible(chr(code))} (U+{code:04X}); it "
                      "is drawn as a box", file=sys.stderr)
        else:
            default_show(message, category, filename, lineno, file, line)

    default_show = warnings.showwarning
    show._ks_jax = True
    warnings.showwarning = show
    warnings.simplefilter("always", CaseWarning)


def _escape_what_the_terminal_cannot_show():
    """On a terminal whose encoding cannot write every character (LANG=C: ASCII), a name such as 'Café' is
    written with its escapes ('Caf\\xe9') rather than stopping the command with an encoding error."""
    for stream in (sys.stdout, sys.stderr):
        encoding = (getattr(stream, "encoding", None) or "").lower().replace("-", "").replace("_", "")
        if encoding not in ("utf8", "utf8sig") and hasattr(stream, "reconfigure"):
            try:
                stream.reconfigure(errors="backslashreplace")
            except (ValueError, OSError):  # a stream that cannot be reconfigured: left as it is
                pass


def main(argv=None) -> int:
    jax.config.update("jax_enable_x64", True)
    _escape_what_the_terminal_cannot_show()
    _show_case_warnings()
    _compilation_cache()
    args = build_parser().parse_args(argv)
    try:
        args.plan = backend.path_from_environment()  # read here only; a value that names no path is refused
    except ValueError as err:
        print(f"ks-jax: error: {err}", file=sys.stderr)
        return 2
    if argv is None and threading.current_thread() is threading.main_thread():
        # the command itself (not a call from Python): a kill unwinds as Ctrl-C does, so that a sweep
        # removes its unfinished file and an earlier --out stays as it was
        signals.install()
    try:
        return args.run(args)
    except (CaseError, UnitError, FileNotFoundError, IsADirectoryError) as err:
        print(f"ks-jax: error: {visible(err)}", file=sys.stderr)  # it may quote a name or a value from a file
        return 2
    except KeyboardInterrupt:
        print("ks-jax: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # the reader went away (ks-jax demo | head): not an error
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except OSError as err:  # a file that could not be read or written after its checks (a full disk, say)
        where = f"{err.filename}: " if getattr(err, "filename", None) else ""
        print(f"ks-jax: error: {visible(where)}{visible(err.strerror or err)}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
