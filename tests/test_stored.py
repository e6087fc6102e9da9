"""``ks_jax.stored``: programs kept on disk between runs, read back without tracing, with jax.jit's values."""

import importlib

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import ks_jax
from ks_jax import stored

pytest.importorskip("flatbuffers")  # the ``cache`` extra (in ``test``): JAX writes exported programs with it


def _leaves_equal(a, b):
    for x, y in zip(jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b), strict=True):
        assert np.asarray(x).dtype == np.asarray(y).dtype
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))


def _exports(folder):
    return sorted(p.name for p in folder.iterdir() if p.name.endswith(stored.SUFFIX))


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
    monkeypatch.setattr(stored, "FOLDER", None)
    stored.stored_jit(fn, static_argnames=("power",))(x, power=3, scale=2.0)
    assert not any(tmp_path.iterdir())

    monkeypatch.setattr(stored, "FOLDER", tmp_path)
    _leaves_equal(stored.stored_jit(fn, static_argnames=("power",))(x, power=3, scale=2.0), want)
    (first,) = _exports(tmp_path)
    before = len(traced)
    later = stored.stored_jit(fn, static_argnames=("power",))
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
    _leaves_equal(stored.stored_jit(fn, static_argnames=("power",))(x, power=3, scale=2.0), want)
    assert len(traced) > before and (tmp_path / first).read_bytes() != b"not a program"


def test_a_program_that_cannot_be_written_is_used_and_leaves_no_partial_file(tmp_path, monkeypatch):
    """A write that fails half-way (a full disk: here the final rename fails) loses nothing: the call gets
    jax.jit's values from the exported program, and no temporary file is left in the folder."""
    def no_rename(src, dst):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(stored, "FOLDER", tmp_path)
    monkeypatch.setattr(stored.os, "replace", no_rename)
    fn = lambda x: jnp.cos(x) * 3.0  # noqa: E731
    x = np.linspace(0.0, 1.0, 5)
    _leaves_equal(stored.stored_jit(fn)(x), jax.jit(fn)(x))
    assert list(tmp_path.iterdir()) == []


def test_a_static_value_without_a_faithful_repr_is_not_stored(tmp_path, monkeypatch):
    class Opaque:  # printed as <...Opaque object at 0x...>: two of them with other values would print alike
        def __init__(self, k):
            self.k = k

        def __hash__(self):
            return hash(self.k)

        def __eq__(self, other):
            return isinstance(other, Opaque) and other.k == self.k

    monkeypatch.setattr(stored, "FOLDER", tmp_path)
    fn = stored.stored_jit(lambda x, o: x * o.k, static_argnums=(1,))
    assert float(fn(jnp.float64(2.0), Opaque(3))) == 6.0
    assert float(fn(jnp.float64(2.0), Opaque(5))) == 10.0
    assert _exports(tmp_path) == []


def test_a_small_sweep_and_a_solve_read_back_give_the_same_results(tmp_path, monkeypatch):
    """What the command line runs: ``ks_jax.solve`` (automatic contact: three programs) and a small sweep
    (three programs), stored, then read back by new function objects (``sweeps._compiled`` emptied,
    ``quick_jit`` made again), with the results of the jitted programs."""
    sweeps = importlib.import_module("ks_jax.sweeps")
    case = ks_jax.load_case(ks_jax.__path__[0] + "/cases/auto_tbone.json")
    over = {"vehicles[1].speed": np.linspace(9.0, 18.0, 5), "contact.restitution": np.linspace(0.0, 0.3, 3)}

    def run():
        sweeps._compiled.cache_clear()
        swept = ks_jax.sweep(case, over, progress=False)
        return ks_jax.solve(case).result, {k: v for k, v in swept.outputs.items()}

    monkeypatch.setattr(stored, "FOLDER", None)
    want = run()
    monkeypatch.setattr(stored, "FOLDER", tmp_path)
    _leaves_equal(run(), want)
    written = _exports(tmp_path)
    assert len(written) == 3 + 3, written
    exports = []
    monkeypatch.setattr(stored._Stored, "_export", lambda self, *a: exports.append(a) or None)
    sv = importlib.import_module("ks_jax.solve")
    for name in ("_auto_status", "_auto_contact", "_auto_exchange"):  # new function objects
        fn = getattr(sv, name)
        monkeypatch.setattr(sv, name, ks_jax.quick.quick_jit(fn.__wrapped__, **fn.jit_kwargs))
    _leaves_equal(run(), want)
    assert exports == [] and _exports(tmp_path) == written
    sweeps._compiled.cache_clear()


def test_exchange_batch_stored_and_read_back_gives_the_same_results(tmp_path, monkeypatch):
    """``exchange_batch``'s three stages (chunks of 4 rows over 10 rows of the seed chapter, the bullet car's
    speed varied) stored, then read back by new function objects (``batch._stages`` emptied): no export the
    second time, and the results of the jitted stages, bit for bit."""
    batch = importlib.import_module("ks_jax.batch")
    case = ks_jax.load_case(ks_jax.__path__[0] + "/cases/seed_000_saturn_pontiac.json")
    args = ks_jax.case.to_pytrees(case.inputs)
    rows = jax.tree_util.tree_map(lambda x: np.repeat(np.asarray(x)[None], 10, axis=0), args)
    rows[3].velocity[:, 0] = np.linspace(5.0, 25.0, 10)

    def run():
        batch._stages.cache_clear()
        return ks_jax.exchange_batch(*rows, chunk=4)

    monkeypatch.setattr(stored, "FOLDER", None)
    want = run()
    monkeypatch.setattr(stored, "FOLDER", tmp_path)
    _leaves_equal(run(), want)
    written = _exports(tmp_path)
    assert len(written) == 3, written
    exports = []
    monkeypatch.setattr(stored._Stored, "_export", lambda self, *a: exports.append(a) or None)
    _leaves_equal(run(), want)
    assert exports == [] and _exports(tmp_path) == written
    batch._stages.cache_clear()


_IN_PYTHON = """
import json, sys
import jax
jax.config.update("jax_enable_x64", True)
import numpy as np
import ks_jax
traced, loaded = set(), []
jax.monitoring.register_event_duration_secs_listener(
    lambda event, d, fun_name=None, **_: traced.add(fun_name) if event.endswith("jaxpr_trace_duration") else None)
jax.monitoring.register_event_listener(lambda event, **_: loaded.append(1) if event.endswith("cache_hits") else None)
folder = ks_jax.keep_programs(sys.argv[1])
case = ks_jax.load_case(ks_jax.__path__[0] + "/cases/seed_000_saturn_pontiac.json")
solved = ks_jax.solve(case).to_dict()
swept = ks_jax.sweep(case, {"vehicles[1].speed": np.linspace(9.0, 18.0, 5)}, progress=False)
print(json.dumps({"folder": str(folder), "solved": solved, "traced": sorted(traced), "loaded": len(loaded),
                  "delta_v": swept["vehicles[0].delta_v_magnitude"].tolist()}))
"""


def test_keep_programs_in_python_keeps_them_for_the_next_process(tmp_path):
    """``ks_jax.keep_programs(DIR)`` in a notebook's process: the first process writes its programs to DIR
    (traced and compiled), the next one reads them back, traces none of ``solve``'s or ``sweep``'s functions,
    and gets the same results as a process that keeps nothing."""
    import json
    import os
    import subprocess
    import sys

    def run(*argv):
        env = {k: v for k, v in os.environ.items() if k != "KS_JAX_TEST_COMPILE_CACHE"}
        done = subprocess.run([sys.executable, "-c", _IN_PYTHON, *argv], capture_output=True, text=True,
                              timeout=300, env=env)
        assert done.returncode == 0, done.stderr
        return json.loads(done.stdout)

    folder = tmp_path / "kept"
    first = run(str(folder))
    assert first["folder"] == str(folder) and first["loaded"] == 0 and "flat" in first["traced"]
    assert len(_exports(folder)) == 4  # solve's one program, the sweep's three
    again = run(str(folder))
    assert again["loaded"] > 0
    assert not {"flat", "_solve_explicit", "status_fn", "impulse_fn", "solve_fn"} & set(again["traced"])
    alone = _IN_PYTHON.replace("folder = ks_jax.keep_programs(sys.argv[1])", "folder = sys.argv[1]")
    done = subprocess.run([sys.executable, "-c", alone, str(tmp_path / "unused")], capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr
    reference = json.loads(done.stdout)
    assert "_solve_explicit" in reference["traced"] and not (tmp_path / "unused").exists()
    for key in ("solved", "delta_v"):
        assert first[key] == reference[key] and again[key] == reference[key]
