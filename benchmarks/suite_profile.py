"""Where the test suite's time goes, program by program: a pytest plugin that records, for each test, its CPU
and wall seconds, and every program JAX compiles during it (its name, its seconds, and whether the run's shared
compile cache had it); and, run as a script, a summary of a profiled run.

    PROF_DIR=/tmp/prof PROF_TAG=run1 PYTHONPATH=benchmarks .venv/bin/python -m pytest -q -n auto --dist loadfile \\
        -p suite_profile
    .venv/bin/python benchmarks/suite_profile.py /tmp/prof run1
    .venv/bin/python benchmarks/suite_profile.py /tmp/prof run1 --durations tests/durations.json

The last writes each test file's wall seconds in the profiled run to ``tests/durations.json``, from which
tests/conftest.py hands the longest files to the test workers first.

Each process (each pytest-xdist worker) writes PROF_DIR/TAG_<worker>.json after every test, so that a run stopped
by a time limit still tells what it did. The summary lists per file and per test the wall and CPU seconds, the
wall and CPU seconds of compiles the cache did not have, their count, and the programs compiled most; then the
programs that cost most over the whole run. On a CPU a test's CPU seconds are its work; on a GPU its wall seconds
less its compiles' are the device's share (and the time it waited for other processes' kernels). The hook
wraps ``jax._src.compiler``'s ``compile_or_get_cached`` (JAX's own entry to XLA's compile and its persistent
cache): a private name, for measuring only."""

from __future__ import annotations

import collections
import glob
import json
import os
import resource
import sys
import time

import jax._src.compiler as compiler
import jax.monitoring as monitoring
import pytest

_HITS = [0]
_ROWS, _TESTS, _CURRENT = [], [], ["<none>"]


def _install():
    def event(name, **kwargs):
        if name == "/jax/compilation_cache/cache_hits":
            _HITS[0] += 1

    monitoring.register_event_listener(event)
    original = compiler.compile_or_get_cached

    def wrapped(backend, computation, *args, **kwargs):
        try:
            name = str(computation.operation.attributes["sym_name"]).strip('"')
        except (AttributeError, KeyError):
            name = "<unnamed>"
        hits, wall, cpu = _HITS[0], time.perf_counter(), time.process_time()
        out = original(backend, computation, *args, **kwargs)
        _ROWS.append((_CURRENT[0], name, time.perf_counter() - wall, time.process_time() - cpu, _HITS[0] - hits))
        return out

    compiler.compile_or_get_cached = wrapped


def pytest_configure(config):
    _install()


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    _CURRENT[0] = item.nodeid
    wall, cpu = time.perf_counter(), time.process_time()
    yield
    _TESTS.append((item.nodeid, time.perf_counter() - wall, time.process_time() - cpu,
                   resource.getrusage(resource.RUSAGE_SELF).ru_maxrss))
    _write()


def pytest_sessionfinish(session):
    _write()


def _write():
    folder = os.environ.get("PROF_DIR", "/tmp/prof")
    os.makedirs(folder, exist_ok=True)
    worker = os.environ.get("PYTEST_XDIST_WORKER", "main")
    with open(os.path.join(folder, f"{os.environ.get('PROF_TAG', 'run')}_{worker}.json"), "w") as f:
        json.dump({"compiles": _ROWS, "tests": _TESTS}, f)


def summary(folder, tag, top=40):
    compiles, tests = [], []
    for path in glob.glob(os.path.join(folder, f"{tag}_*.json")):
        with open(path) as f:
            data = json.load(f)
        compiles += data["compiles"]
        tests += data["tests"]
    cost = collections.defaultdict(lambda: [0.0, 0.0, 0])  # per test: compile wall s, compile CPU s, compiles
    names, programs = collections.defaultdict(collections.Counter), collections.defaultdict(lambda: [0, 0.0, 0.0])
    for test, name, wall, cpu, hit in compiles:
        if not hit:
            cost[test][0] += wall
            cost[test][1] += cpu
            cost[test][2] += 1
            names[test][name] += 1
            programs[name][0] += 1
            programs[name][1] += wall
            programs[name][2] += cpu
    files = collections.defaultdict(lambda: [0.0, 0.0, 0.0, 0.0, 0])
    for test, wall, cpu, _ in tests:
        f = files[test.split("::")[0]]
        for i, v in enumerate((wall, cpu, *cost[test])):
            f[i] += v
    walls = sum(t[1] for t in tests)
    compile_wall = sum(c[0] for c in cost.values())
    print(f"{len(tests)} tests, {walls:.0f} wall s; {sum(c[2] for c in cost.values())} compiles not in the cache "
          f"({compile_wall:.0f} wall s, {sum(c[1] for c in cost.values()):.0f} CPU s), "
          f"{sum(1 for c in compiles if c[4])} loaded from it\n\n"
          "per file: wall s, CPU s, compile wall s, compile CPU s, compiles")
    for name, (wall, cpu, cw, cc, n) in sorted(files.items(), key=lambda x: -x[1][0]):
        print(f"{wall:7.1f} {cpu:7.1f} {cw:7.1f} {cc:7.1f} {n:5d}  {name}")
    print("\nper test (the longest): wall s, CPU s, compile wall s, compile CPU s, compiles, programs compiled most")
    for test, wall, cpu, _ in sorted(tests, key=lambda x: -x[1])[:top]:
        most = ", ".join(f"{k} x{v}" for k, v in names[test].most_common(3))
        cw, cc, n = cost[test]
        print(f"{wall:7.1f} {cpu:7.1f} {cw:7.1f} {cc:7.1f} {n:5d}  {test}  [{most}]")
    print("\nper program: compile wall s, compile CPU s, compiles")
    for name, (n, wall, cpu) in sorted(programs.items(), key=lambda x: -x[1][1])[:top]:
        print(f"{wall:7.1f} {cpu:7.1f} {n:5d}  {name}")


def write_durations(folder, tag, path):
    """Each test file's wall seconds in a profiled run, longest first, as JSON at ``path``."""
    seconds = collections.defaultdict(float)
    for file in glob.glob(os.path.join(folder, f"{tag}_*.json")):
        with open(file) as f:
            for test, wall, _, _ in json.load(f)["tests"]:
                seconds[test.split("::")[0]] += wall
    with open(path, "w") as f:
        json.dump({k: round(v, 1) for k, v in sorted(seconds.items(), key=lambda x: -x[1])}, f, indent=1)
        f.write("\n")


if __name__ == "__main__":
    if len(sys.argv) == 5 and sys.argv[3] == "--durations":
        write_durations(sys.argv[1], sys.argv[2], sys.argv[4])
    elif len(sys.argv) == 3:
        summary(sys.argv[1], sys.argv[2])
    else:
        sys.exit("usage: suite_profile.py PROF_DIR TAG [--durations PATH]")
