"""``ks_jax.compilation``: programs kept on disk between runs (JAX's compiled programs, and the traced programs of
``quick_jit``, read back without tracing, with jax.jit's values)."""

import importlib
import json
import os
import subprocess
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import fit.rows as rows
import ks_jax
from ks_jax import compilation
from ks_jax.compilation import _CACHE_ENTRY, prune_cache

pytest.importorskip("flatbuffers")  # the ``cache`` extra (in ``test``): JAX writes exported programs with it


def _leaves_equal(a, b):
    for x, y in zip(jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b), strict=True):
        assert np.asarray(x).dtype == np.asarray(y).dtype
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))


def _exports(folder):
    return sorted(p.name for p in folder.iterdir() if p.name.endswith(compilation._SUFFIX))


def test_a_program_is_written_once_and_read_back_without_tracing(tmp_path, monkeypatch):
    """The first call writes the program; a new function object (a later process) reads it and calls
    nothing of the Python function; the values are jax.jit's, bit for bit. Another static value or
    another dtype is another program; a damaged file is written again; without a folder nothing is."""
    traced = []

    def fn(x, power, scale):
        traced.append(power)
        return {"y": jnp.sin(x) * scale**power, "pair": (x * power, jnp.cumsum(x))}

    x = np.linspace(0.0, 2.0, 7)
    want = jax.jit(fn, static_argnames="power")(x, power=3, scale=2.0)
    monkeypatch.setattr(compilation, "_FOLDER", None)
    compilation.quick_jit(fn, static_argnames=("power",)).plain(x, power=3, scale=2.0)
    assert not any(tmp_path.iterdir())

    monkeypatch.setattr(compilation, "_FOLDER", tmp_path)
    _leaves_equal(compilation.quick_jit(fn, static_argnames=("power",)).plain(x, power=3, scale=2.0), want)
    (first,) = _exports(tmp_path)
    before = len(traced)
    later = compilation.quick_jit(fn, static_argnames=("power",)).plain
    _leaves_equal(later(x, power=3, scale=2.0), want)
    assert len(traced) == before  # read back, not traced
    assert _exports(tmp_path) == [first]

    _leaves_equal(later(x, power=4, scale=2.0), jax.jit(fn, static_argnames="power")(x, power=4, scale=2.0))
    _leaves_equal(later(x.astype(np.float32), power=4, scale=2.0),
                  jax.jit(fn, static_argnames="power")(x.astype(np.float32), power=4, scale=2.0))
    _leaves_equal(later(x[:5], power=4, scale=2), jax.jit(fn, static_argnames="power")(x[:5], power=4, scale=2))
    _leaves_equal(later(x, power=4, scale=2.0), jax.jit(fn, static_argnames="power")(x, power=4, scale=2.0))
    assert len(_exports(tmp_path)) == 4  # power 4: float64, float32, and 5 values with an int scale

    (tmp_path / first).write_bytes(b"not a program")
    _leaves_equal(compilation.quick_jit(fn, static_argnames=("power",)).plain(x, power=3, scale=2.0), want)
    assert len(traced) > before and (tmp_path / first).read_bytes() != b"not a program"


def test_a_program_that_cannot_be_written_is_used_and_leaves_no_partial_file(tmp_path, monkeypatch):
    """A write that fails half-way (a full disk: here the final rename fails) loses nothing: the call gets
    jax.jit's values from the exported program, and no temporary file is left in the folder."""
    def no_rename(src, dst):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(compilation, "_FOLDER", tmp_path)
    monkeypatch.setattr(compilation.os, "replace", no_rename)
    fn = lambda x: jnp.cos(x) * 3.0  # noqa: E731
    x = np.linspace(0.0, 1.0, 5)
    _leaves_equal(compilation.quick_jit(fn).plain(x), jax.jit(fn)(x))
    assert list(tmp_path.iterdir()) == []


def test_a_static_value_without_a_faithful_repr_is_not_stored(tmp_path, monkeypatch):
    class Opaque:  # printed as <...Opaque object at 0x...>: two of them with other values would print alike
        def __init__(self, k):
            self.k = k

        def __hash__(self):
            return hash(self.k)

        def __eq__(self, other):
            return isinstance(other, Opaque) and other.k == self.k

    monkeypatch.setattr(compilation, "_FOLDER", tmp_path)
    fn = compilation.quick_jit(lambda x, o: x * o.k, static_argnums=(1,)).plain
    assert float(fn(jnp.float64(2.0), Opaque(3))) == 6.0
    assert float(fn(jnp.float64(2.0), Opaque(5))) == 10.0
    assert _exports(tmp_path) == []


@pytest.mark.slow
def test_a_solve_read_back_gives_the_same_results(tmp_path, monkeypatch):
    """What the command line runs: ``ks_jax.solve`` of a case with automatic contact, its program stored,
    then read back by a new function object (``quick_jit`` made again): no export the second time, and the
    results of the jitted program, bit for bit."""
    sv = importlib.import_module("ks_jax.solve.cases")
    case = ks_jax.load_case(ks_jax.__path__[0] + "/cases/auto_tbone.json")
    monkeypatch.setattr(compilation, "_FOLDER", None)
    want = ks_jax.solve(case).result
    monkeypatch.setattr(compilation, "_FOLDER", tmp_path)
    _leaves_equal(ks_jax.solve(case).result, want)
    written = _exports(tmp_path)
    assert len(written) == 1, written
    exports = []
    monkeypatch.setattr(compilation._Stored, "_export", lambda self, *a: exports.append(a) or None)
    monkeypatch.setattr(sv, "_solve", compilation.quick_jit(sv._solve_rows, **sv._solve.quick.jit_kwargs))
    _leaves_equal(ks_jax.solve(case).result, want)
    assert exports == [] and _exports(tmp_path) == written


@pytest.mark.slow
def test_keep_programs_in_python_keeps_them_in_its_folder(tmp_path, monkeypatch):
    """``ks_jax.keep_programs(DIR)`` in a notebook's process returns DIR and keeps there what the command line
    keeps: ``solve``'s traced program, and pint's parsed units are put there, with the same results as keeping
    nothing.
    (JAX's compiled programs go there too, in a process that has compiled nothing before:
    ``test_compile_cache_is_used_and_kept_apart`` reads them back in a later process.)"""
    case = ks_jax.load_case(ks_jax.__path__[0] + "/cases/seed_000_saturn_pontiac.json")
    want = ks_jax.solve(case).result
    folder = tmp_path / "kept"
    monkeypatch.setattr(compilation.units, "REGISTRY_CACHE", None)
    monkeypatch.setattr(compilation, "_FOLDER", None)
    sv = importlib.import_module("ks_jax.solve.cases")  # a new function object: its program is traced and stored
    monkeypatch.setattr(sv, "_solve", compilation.quick_jit(sv._solve_rows, **sv._solve.quick.jit_kwargs))
    cache_dir = jax.config.jax_compilation_cache_dir
    try:
        assert ks_jax.keep_programs(folder) == folder
        _leaves_equal(ks_jax.solve(case).result, want)
    finally:
        jax.config.update("jax_compilation_cache_dir", cache_dir)
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    assert len(_exports(folder)) == 1
    assert compilation.units.REGISTRY_CACHE == folder / "units"  # pint's folder (``test_units``)


# runs the command line and reports on stderr how many programs it loaded from the persistent
# compile cache and how many it wrote there (JAX's events "cache_hits" and "cache_misses"; the
# latter is recorded only when an entry is written). Every program is stored, however quickly it
# compiled, so that one compiling near the command line's 0.5 s threshold cannot make the counts differ.
_COUNT_CACHE_HITS = """
import collections, json, sys, jax
from ks_jax import cli
setup = cli._compilation_cache
def store_all():
    setup()
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
cli._compilation_cache = store_all
seen, traced = collections.Counter(), set()
jax.monitoring.register_event_listener(lambda event, **_: seen.update([event.rsplit("/", 1)[-1]]))
def on_duration(event, duration, fun_name=None, **_):
    if event.endswith("jaxpr_trace_duration"):
        traced.add(fun_name)
jax.monitoring.register_event_duration_secs_listener(on_duration)
code = cli.main(sys.argv[1:])
print(json.dumps({"loaded": seen["cache_hits"], "written": seen["cache_misses"], "traced": sorted(traced)}),
      file=sys.stderr)
sys.exit(code)
"""


@pytest.mark.slow
def test_compile_cache_is_used_and_kept_apart(tmp_path):
    """KS_JAX_CACHE=DIR: the first run stores its compiled programs there and a second run loads
    them (JAX's own cache-hit events) and gives the same report; so with pint's parsed unit definitions
    (the folder ``units``, written once) and with the programs as traced (``ks_jax.compilation``: the second run
    traces none of ``solve``'s functions, and its report is the one of jax.jit's programs, KS_JAX_CACHE=off);
    nothing outside DIR is written, and KS_JAX_CACHE=off stores and loads nothing."""
    case = Path(ks_jax.__file__).parent / "cases" / "seed_000_saturn_pontiac.json"
    cache, off_home = tmp_path / "cache", tmp_path / "home"

    def run(where):
        # on the CPU whatever the machine: what is checked is ks-jax's use of the cache, not a backend's
        env = dict(os.environ, KS_JAX_CACHE=str(where), XDG_CACHE_HOME=str(off_home), JAX_PLATFORMS="cpu")
        done = subprocess.run([sys.executable, "-c", _COUNT_CACHE_HITS, "solve", str(case), "--json"],
                              env=env, capture_output=True, text=True, timeout=300)
        assert done.returncode == 0, done.stderr
        return json.loads(done.stdout), json.loads(done.stderr.strip().splitlines()[-1])

    first, counts = run(cache)
    written = counts.pop("written")
    assert counts.pop("loaded") == 0 and written > 0
    assert "flat" in counts["traced"]  # the export of a traced program
    entries = [p.name for p in cache.iterdir()]
    assert "units" in entries and any((cache / "units").iterdir())  # pint's definitions, parsed
    assert all(_CACHE_ENTRY.fullmatch(name) for name in entries if name != "units")
    assert any(name.endswith("-export") for name in entries) and any(name.endswith("-cache") for name in entries)
    kept = {p.name: p.stat().st_mtime_ns for p in (cache / "units").iterdir()}
    again, counts = run(cache)
    assert again == first
    assert counts.pop("loaded") == written and counts.pop("written") == 0  # every program it stored, loaded
    assert not {"flat", "_solve_rows", "solve_inputs"} & set(counts["traced"]), counts["traced"]
    assert sorted(p.name for p in cache.iterdir()) == sorted(entries)
    assert {p.name: p.stat().st_mtime_ns for p in (cache / "units").iterdir()} == kept  # read, not written again
    off, counts = run("off")
    assert off == first
    assert counts["loaded"] == 0 and counts["written"] == 0 and "_solve_rows" in counts["traced"]
    assert not off_home.exists()


def test_an_option_xla_does_not_know_is_left_out(monkeypatch):
    """XLA's options come and go between jaxlib versions (``xla_cpu_use_fusion_emitters`` is gone from later ones)
    and a compile that names one it does not know fails. ``known_options`` leaves such an option out and keeps the
    others; a quick program and a quick chunk's options made with one compile, and compute jax.jit's values."""
    unknown = "xla_cpu_an_option_no_xla_has"
    with pytest.raises(jax.errors.JaxRuntimeError, match="No such compile option"):
        jax.jit(jnp.sin, compiler_options={unknown: False}).lower(1.0).compile()
    known = {"xla_backend_optimization_level": 0}
    assert compilation.known_options({**known, unknown: True}) == known
    assert compilation.known_options({}) == {} and compilation.known_options(None) is None

    monkeypatch.setattr(compilation, "QUICK_CPU", {**compilation.QUICK_CPU, unknown: True})
    fun = compilation.quick_jit(lambda x, power: jnp.sin(x) ** power, static_argnames=("power",))
    x = np.linspace(0.0, 2.0, 7)
    want = jax.jit(lambda x: jnp.sin(x) ** 3)(x)
    np.testing.assert_allclose(np.asarray(fun.quick(x, power=3)), np.asarray(want), rtol=1e-15)
    assert unknown not in fun.quick.options and unknown not in (compilation.compiler_options(True) or {})
    if jax.default_backend() == "cpu":
        assert compilation.compiler_options(True) == compilation.known_options(compilation.QUICK_CPU)


class _Device:
    """A device of a platform this machine may not have: what the fit's solver reads of one."""

    def __init__(self, platform):
        self.platform = platform


def test_quick_programs_take_the_quick_options_of_the_platform_they_compile_for():
    """A quick program (a file's few cases, a fit's few hundred rows, a short sweep) compiles with ``QUICK_CPU`` for
    a CPU and ``QUICK_GPU`` for a GPU (JAX names its platform "gpu", "cuda" or "rocm"), with XLA's defaults
    elsewhere. The installed XLA knows every option of ``QUICK_GPU`` (none is left out), and a program compiled with
    them (here for the CPU: XLA's options are one set) computes jax.jit's values. The fit's solver takes the quick
    options of the devices its rows go to up to ``QUICK_ROWS`` rows, and XLA's defaults above."""
    assert compilation.quick_options("cpu") == compilation.known_options(compilation.QUICK_CPU)
    for name in ("gpu", "cuda", "rocm"):
        assert compilation.quick_options(name) == compilation.QUICK_GPU
    assert compilation.quick_options("tpu") is None and compilation.compiler_options(False, "gpu") is None
    assert compilation.compiler_options(True, "cuda") == compilation.QUICK_GPU

    fun = compilation.quick_jit(lambda x, power: jnp.sin(x) ** power, static_argnames=("power",))
    x = np.linspace(0.0, 2.0, 7)
    want = jax.jit(lambda x: jnp.sin(x) ** 3)(x)
    np.testing.assert_allclose(np.asarray(fun.on("cuda")(x, power=3)), np.asarray(want), rtol=1e-15)
    assert fun.on("cuda") is fun.on("gpu") and fun.on("gpu").options == compilation.QUICK_GPU
    assert fun.quick is fun.on(jax.default_backend()) and fun.plain.options is None

    gpu, cpu = [_Device("gpu")], [_Device("cpu")]
    assert rows.solver_for(rows.QUICK_ROWS, gpu) is rows.fit_rows.on("gpu")
    assert rows.solver_for(8, cpu) is rows.fit_rows.on("cpu")
    assert rows.solver_for(rows.QUICK_ROWS + 1, gpu) is rows.fit_rows.plain


def test_prune_cache_drops_least_recently_used_entries_only(tmp_path):
    names = [f"jit_solve_fn-{k:064x}-cache" for k in range(5)]
    names[1] = f"ks_jax__solve_rows-{1:064x}-export"  # a traced program kept by ks_jax.compilation: counted alike
    for age, name in enumerate(names):  # names[0] used last, names[4] first
        (tmp_path / name).write_bytes(b"x" * 1000)
        os.utime(tmp_path / name, (1e9 - 100 * age, 1e9 - 100 * age))
    other = tmp_path / "notes-cache"  # not a name JAX gives an entry: never counted or deleted
    other.write_bytes(b"y" * 10_000)
    os.utime(other, (1.0, 1.0))

    assert prune_cache(tmp_path, 5000) == 0
    assert prune_cache(tmp_path, 2500) == 3
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(names[:2] + ["notes-cache"])
    assert prune_cache(tmp_path, 0) == 2
    assert [p.name for p in tmp_path.iterdir()] == ["notes-cache"]


def test_free_programs_frees_the_executables_jax_clear_caches_leaves():
    """``compiled`` keeps executables that ``jax.clear_caches`` does not reach: after ``jax.clear_caches`` the
    same executable comes back; after ``free_programs`` a new one is compiled, and it computes the same."""
    jitted = jax.jit(lambda x: 2.0 * x + 1.0)
    x = jnp.arange(3.0)
    first = compilation.compiled(jitted, x)
    jax.clear_caches()
    assert compilation.compiled(jitted, x) is first
    compilation.free_programs()
    again = compilation.compiled(jitted, x)
    assert again is not first
    np.testing.assert_array_equal(np.asarray(again(x)), 2.0 * np.arange(3.0) + 1.0)
