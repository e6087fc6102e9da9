"""``ks_jax.exchange_batch``: the values of ``jax.vmap(exchange)``, row for row, in chunks (a last chunk
that overlaps the one before), with bad rows, into NumPy arrays or into earlier results (``out=``)."""

from __future__ import annotations

import copy

import jax
import numpy as np
import pytest

import ks_jax
from ks_jax import backend
from ks_jax.cli import main
from ks_jax.model import types as t
from samples import assert_same_leaves, with_bad_rows
import kit


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["principal", "full"])
def test_exchange_batch_equals_vmap(random_cases, kind):
    cases = random_cases[kind][:150]
    # rows with invalid inputs among them: each keeps its own status, the others are solved
    bad = copy.deepcopy(cases[7])
    bad["vehicles"][1]["mass"] = -5.0
    nan = copy.deepcopy(cases[40])
    nan["contact"]["point"] = np.array([0.0, np.nan, 0.0])
    cases = cases[:7] + [bad] + cases[8:40] + [nan] + cases[41:]
    args = kit.inputs(cases)
    reference = kit.batch_exchange(args)  # jax.vmap(exchange) (the test kit's program)
    # 150 rows in chunks of 64: 64, 64, then a last chunk aligned to the end (rows 86..149)
    for chunk in (64, 150, 1000):
        batched = ks_jax.exchange_batch(*args, chunk=chunk)
        assert_same_leaves(batched, reference)
    assert all(isinstance(x, np.ndarray) for x in jax.tree_util.tree_leaves(batched))  # NumPy results, like sweep's
    one = ks_jax.exchange_batch(*jax.tree_util.tree_map(lambda x: x[3:4], args))  # a batch of one row
    assert_same_leaves(one, jax.tree_util.tree_map(lambda x: x[3:4], reference))
    status = np.asarray(batched.contact.status)
    assert status[7] == t.INVALID_MASS_2 and status[40] == t.INVALID_NONFINITE
    assert np.all(np.isnan(np.asarray(batched.vehicles[0].delta_v)[[7, 40]]))
    good = np.ones(len(cases), bool)
    good[[7, 40]] = False
    assert np.all(np.isfinite(np.asarray(batched.contact.impulse)[good]))
    # and against the independent NumPy reference
    kit.assert_matches(kit.engine_dict(jax.tree_util.tree_map(lambda x: x[good], batched)),
                       kit.reference_batch([c for c, g in zip(cases, good) if g]), 1e-9,
                       [c for c, g in zip(cases, good) if g])


@pytest.mark.slow
def test_exchange_batch_smoothing_matches_vmap(random_cases):
    args = kit.inputs(random_cases["principal"][:40])
    reference = kit.batch_exchange(args, 0.05)
    assert_same_leaves(ks_jax.exchange_batch(*args, smoothing=0.05, chunk=16), reference)


def test_exchange_batch_rejects_mismatched_batch_and_bad_arguments(random_cases):
    args = kit.inputs(random_cases["principal"][:10])
    short = args[4]._replace(friction=args[4].friction[:9])
    with pytest.raises(ValueError, match="same leading batch axis"):
        ks_jax.exchange_batch(*args[:4], short)
    with pytest.raises(ValueError, match="smoothing must be in"):
        ks_jax.exchange_batch(*args, smoothing=1.5)
    with pytest.raises(ValueError, match="chunk must be a positive"):
        ks_jax.exchange_batch(*args, chunk=0)
    with pytest.raises(TypeError, match="jax.vmap"):  # values only: not under a transformation
        jax.jit(lambda *a: ks_jax.exchange_batch(*a).contact.impulse_magnitude)(*args)


@pytest.mark.slow
def test_exchange_batch_writes_into_out(random_cases):
    """``out``: the results of another batch of the same size are overwritten in place (chunks of 16
    over 40 rows, the last one aligned to the end) and equal a fresh call; a wrong ``out`` is refused,
    naming the field (every call in chunks of 16: one program)."""
    a, b = (kit.inputs(random_cases["principal"][k:k + 40]) for k in (0, 40))
    fresh = ks_jax.exchange_batch(*a, chunk=16)
    out = ks_jax.exchange_batch(*b, chunk=16)
    before = [np.copy(x) for x in jax.tree_util.tree_leaves(out)]
    got = ks_jax.exchange_batch(*a, chunk=16, out=out)
    assert all(x is y for x, y in zip(jax.tree_util.tree_leaves(got), jax.tree_util.tree_leaves(out)))
    assert_same_leaves(got, fresh)
    assert any(not np.array_equal(x, y) for x, y in zip(before, jax.tree_util.tree_leaves(got)) if x.dtype.kind == "f")
    wrong = out._replace(vehicles=(out.vehicles[0]._replace(pdof=np.zeros(39)), out.vehicles[1]))
    with pytest.raises(ValueError, match=r"out\.vehicles\[0\]\.pdof = ndarray float64\[39\].*float64\[40\]"):
        ks_jax.exchange_batch(*a, chunk=16, out=wrong)
    frozen = [np.copy(x) for x in jax.tree_util.tree_leaves(out)]
    frozen[0].flags.writeable = False
    with pytest.raises(ValueError, match="writeable"):
        ks_jax.exchange_batch(*a, chunk=16, out=jax.tree_util.tree_unflatten(jax.tree_util.tree_structure(out), frozen))
    numpy_inputs = jax.tree_util.tree_map(np.array, a)
    aliased = out._replace(contact=out.contact._replace(energy_loss=numpy_inputs[4].friction))
    with pytest.raises(ValueError, match="out.contact.energy_loss shares memory with an input"):
        ks_jax.exchange_batch(*numpy_inputs, chunk=16, out=aliased)


@pytest.mark.slow
def test_exchange_batch_of_no_rows(random_cases):
    """An empty batch (a filtered batch may be) gives empty results with the fields, trailing shapes and
    dtypes of a one-row batch's; an ``out`` of that shape is returned as it is."""
    one = kit.inputs(random_cases["principal"][:1])
    none = jax.tree_util.tree_map(lambda x: np.asarray(x)[:0], one)
    got, row = ks_jax.exchange_batch(*none), ks_jax.exchange_batch(*one)
    assert jax.tree_util.tree_structure(got) == jax.tree_util.tree_structure(row)
    for a, b in zip(jax.tree_util.tree_leaves(got), jax.tree_util.tree_leaves(row)):
        assert isinstance(a, np.ndarray) and a.shape == (0,) + b.shape[1:] and a.dtype == b.dtype
    assert ks_jax.exchange_batch(*none, out=got) is got
    wrong = got._replace(contact=got.contact._replace(impulse=np.zeros((1, 3))))
    with pytest.raises(ValueError, match=r"out\.contact\.impulse = ndarray float64\[1, 3\]"):
        ks_jax.exchange_batch(*none, out=wrong)


@pytest.mark.slow
def test_exchange_batch_on_the_accelerator_path(random_cases):
    """The accelerator's path (``plan="accelerator"``, forced on whatever device runs the tests): rows given as
    NumPy arrays go to the device chunk by chunk (64, 64, then a last chunk aligned to the end), results are
    copied to the host while the next chunk runs, or stay on the device (``to_host=False``); device rows in
    the chunk of the policy. The values are ``jax.vmap(exchange)``'s, row for row, with bad rows among them;
    an ``out`` cannot go with ``to_host=False``."""
    cases = with_bad_rows(random_cases["full"][:150])
    args = kit.inputs(cases)
    reference = kit.batch_exchange(args)
    host = jax.tree_util.tree_map(np.array, args)
    plan = backend.Plan("accelerator")
    for rows, chunk in ((host, 64), (args, None)):
        got = ks_jax.exchange_batch(*rows, chunk=chunk, plan=plan)
        assert all(isinstance(x, np.ndarray) for x in jax.tree_util.tree_leaves(got))
        assert_same_leaves(got, reference)
        kept = ks_jax.exchange_batch(*rows, chunk=chunk, to_host=False, plan="accelerator")
        assert all(isinstance(x, jax.Array) for x in jax.tree_util.tree_leaves(kept))
        assert_same_leaves(kept, reference)
    with pytest.raises(ValueError, match="out= .* to_host=False"):
        ks_jax.exchange_batch(*args, out=got, to_host=False, plan=plan)
    # the two paths' programs are kept apart: the same chunk's program, one per plan
    assert ks_jax.batch.kernel._chunk_program(64, 0.0, True, plan) is not \
        ks_jax.batch.kernel._chunk_program(64, 0.0, True, backend.Plan("cpu"))


def test_chunk_rows_from_free_memory(monkeypatch):
    """The accelerator's chunk: the largest power of two whose working set (``WORKING_SET`` x the row's
    bytes) is at most ``MEMORY_SHARE`` of the free memory, within [MIN_ROWS, MAX_ROWS]; the CPU's is fixed."""
    free = {"bytes": 80 << 30}
    monkeypatch.setattr(backend, "free_bytes", lambda device=None: free["bytes"])
    assert backend.Plan("cpu").rows(1000) == backend.CPU_CHUNK_ROWS
    accelerator = backend.Plan("accelerator")
    # 0.25 * 80 GiB / (4 * 1000 B) = 5.4e6 rows -> 2^22
    assert accelerator.rows(1000) == 1 << 22
    free["bytes"] = 1 << 30  # 0.25 GiB / 4 kB = 67108 -> 2^16
    assert accelerator.rows(1000) == 1 << 16
    free["bytes"] = 1 << 20  # far too little: the smallest chunk still
    assert accelerator.rows(1000) == backend.MIN_ROWS
    free["bytes"] = 1 << 50
    assert accelerator.rows(8) == backend.MAX_ROWS
    # a plan's own chunk is taken as given, on either path
    assert backend.Plan("accelerator", 300).rows(1000) == backend.Plan("cpu", 300).rows(8) == 300


def test_the_path_of_a_process_from_the_environment(monkeypatch, capsys):
    """``KS_JAX_PATH`` names the path a process takes ("cpu" or "accelerator"; unset or empty: the default
    device's); any other value is refused, naming the variable, the value and what it must be, by the command
    line before any work."""
    for value, plan in (("accelerator", backend.Plan("accelerator")), ("cpu", backend.Plan("cpu")), ("", None)):
        monkeypatch.setenv("KS_JAX_PATH", value)
        assert backend.path_from_environment() == plan
    monkeypatch.delenv("KS_JAX_PATH")
    assert backend.path_from_environment() is None
    monkeypatch.setenv("KS_JAX_PATH", "gpu")
    with pytest.raises(ValueError, match="KS_JAX_PATH = 'gpu': must be 'cpu' or 'accelerator'"):
        backend.path_from_environment()
    assert main(["demo"]) == 2  # the command line refuses it up front
    assert "ks-jax: error: KS_JAX_PATH = 'gpu'" in capsys.readouterr().err
