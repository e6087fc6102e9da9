"""``jax.vmap(exchange)`` over more rows than a chunk runs in chunks on a CPU (``ks_jax.batch.chunks``):
the values are the single solves' and the independent reference's, across chunk boundaries (a last chunk
that overlaps the one before) and with bad rows; the derivatives are ``jax.vmap``'s, as through any batch."""

from __future__ import annotations

import copy
import functools
import importlib

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import ks_jax
from ks_jax import backend
from ks_jax.model import types as t
from samples import assert_same_leaves, reference_jit, with_bad_rows
import kit

CHUNKS = importlib.import_module("ks_jax.batch.chunks")
STAGES = importlib.import_module("ks_jax.batch.stages")

# ``jax.vmap(exchange)`` jitted once for the file (one compile per batch shape and dtype; the trace, and so
# whether it runs in chunks, is the one made under the test's CHUNK_ROWS)
# ``ks_jax.exchange`` on the CPU's path whatever the device: the chunked path is the CPU's
exchange = functools.partial(ks_jax.exchange, plan=backend.Plan("cpu"))
BATCH = reference_jit(jax.vmap(exchange))


def _first(tree):
    """Row 0 of every leaf, inside a traced function."""
    return jax.tree_util.tree_map(lambda x: x[0], tree)


def _rows(tree, rows):
    """Rows of every leaf, sliced in NumPy (no program compiled for the slice)."""
    return jax.tree_util.tree_map(lambda x: np.asarray(x)[rows], tree)


@pytest.fixture
def small_chunks(monkeypatch):
    """``jax.vmap(exchange)`` over more than CHUNK_ROWS rows runs in chunks on one CPU device;
    64-row chunks exercise that path on small batches, taken on any device (``exchange``, below)."""
    monkeypatch.setattr(CHUNKS, "CHUNK_ROWS", 64)
    yield 64


@pytest.mark.slow
def test_vmap_of_exchange_in_chunks_equals_single_solves(random_cases, small_chunks):
    cases = with_bad_rows(random_cases["full"][:150])  # chunks at 0, 64 and 86 (end-aligned)
    args = kit.inputs(cases)
    # the loop over chunks, not the whole-batch program
    assert "scan" in str(jax.make_jaxpr(jax.vmap(exchange))(*args))
    batched = BATCH(*args)
    singles = [kit.exchange(*kit.inputs(c)) for c in cases]
    stacked = jax.tree_util.tree_map(lambda *xs: np.stack([np.asarray(x) for x in xs]), *singles)
    assert_same_leaves(batched, stacked)
    status = np.asarray(batched.contact.status)
    assert status[63] == t.INVALID_INERTIA_1 and status[100] == t.INVALID_RESTITUTION
    good = np.ones(len(cases), bool)
    good[[63, 100]] = False
    kit.assert_matches(kit.engine_dict(jax.tree_util.tree_map(lambda x: np.asarray(x)[good], batched)),
                       kit.reference_batch([c for c, g in zip(cases, good) if g]), 1e-9,
                       [c for c, g in zip(cases, good) if g])
    # a batch of at most one chunk is one whole-batch program
    assert "scan" not in str(jax.make_jaxpr(jax.vmap(exchange))(*kit.inputs(cases[:64])))


@pytest.mark.slow
def test_vmap_of_exchange_in_chunks_with_unbatched_inputs_and_smoothing(random_cases, small_chunks):
    """Both vehicles the same in every row (unbatched), a smooth cone: the rows of the last chunk, which starts
    at row 66 so as to end at row 130, equal the whole-batch program of those 64 rows."""
    v1, s1, v2, s2, c = kit.inputs(random_cases["principal"][:130])
    first = _rows((v1, v2), 0)
    fn = reference_jit(jax.vmap(lambda s1, s2, c: exchange(first[0], s1, first[1], s2, c, smoothing=0.05)))
    batched = fn(s1, s2, c)
    for rows in (slice(0, 64), slice(66, 130)):  # one chunk: the whole-batch program
        assert_same_leaves(_rows(batched, rows), fn(*_rows((s1, s2, c), rows)))


@pytest.mark.slow
def test_derivatives_through_a_chunked_batch(random_cases, small_chunks):
    """Reverse and forward mode through a batch whose values run in chunks, with an unbatched input (one
    vehicle 2 in every row: its gradient is the sum over the rows) and rows with invalid inputs (zero
    gradient, nothing NaN): both are the gradients of the rows solved one at a time (``jax.grad`` of one
    exchange, vmapped; tests/model/test_gradients.py checks those against central differences)."""
    cases = with_bad_rows(random_cases["full"][:150])
    v1, s1, v2, s2, c = kit.inputs(cases)
    shared = _rows(v2, 0)

    def row_loss(v2, v1, s1, s2, c):
        r = exchange(v1, s1, v2, s2, c)
        return jnp.where(r.contact.status == 0, r.vehicles[1].delta_v_magnitude + r.vehicles[0].speed_after ** 2
                         + 1e-4 * r.contact.energy_loss, 0.0)

    def loss(v2, s1, c):
        return jnp.sum(jax.vmap(row_loss, in_axes=(None, 0, 0, 0, 0))(v2, v1, s1, s2, c))

    assert "scan[" in str(jax.make_jaxpr(loss)(shared, s1, c))  # the forward's loop over chunks
    direction = np.zeros_like(np.asarray(s1.velocity))  # vehicle 1's speed in every row at once
    direction[:, 0] = 1.0
    zeros = jax.tree_util.tree_map(jnp.zeros_like, s1)

    def checks(shared, s1, c, tangent):
        """One program (one compile): reverse and forward mode through the batch, and the per-row gradients."""
        return (jax.grad(loss, argnums=(0, 1, 2))(shared, s1, c),
                jax.vmap(jax.grad(row_loss, argnums=(0, 2, 4)), in_axes=(None, 0, 0, 0, 0))(shared, v1, s1, s2, c),
                jax.jvp(lambda x: loss(shared, x, c), (s1,), (tangent,))[1])  # forward mode (a fit uses jax.jacfwd)

    grads, per_row, along = reference_jit(checks)(shared, s1, c, zeros._replace(velocity=jnp.asarray(direction)))
    reference = (jax.tree_util.tree_map(lambda x: np.sum(np.asarray(x), 0), per_row[0]), *per_row[1:])
    for a, b in zip(jax.tree_util.tree_leaves(grads), jax.tree_util.tree_leaves(reference)):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-10, atol=1e-10)
    assert all(np.all(np.isfinite(np.asarray(x))) for x in jax.tree_util.tree_leaves(grads))
    for bad in (63, 100):
        assert all(np.all(np.asarray(x)[bad] == 0) for x in jax.tree_util.tree_leaves(grads[1:]))
    np.testing.assert_allclose(float(along), float(np.sum(np.asarray(per_row[1].velocity) * direction)), rtol=1e-10)


@pytest.mark.slow
def test_a_batch_of_one_row_is_the_row(random_cases):
    """``jax.vmap(exchange)`` over one row computes the row unbatched: its values are those of ``exchange``
    of the row, and its gradient with one vehicle shared (unbatched) is the row's to rounding, for a valid row
    and for one with invalid inputs."""
    good = random_cases["full"][5]
    bad = copy.deepcopy(good)
    bad["vehicles"][0]["mass"] = 0.0

    def row_loss(v2, s1, c, v1, s2):
        r = exchange(v1, s1, v2, s2, c)
        return jnp.where(r.contact.status == 0, r.vehicles[1].delta_v_magnitude + r.vehicles[0].speed_after ** 2
                         + 1e-4 * r.contact.energy_loss, 0.0)

    def loss(v2, s1, c, v1, s2):  # one row, batched
        return jnp.sum(jax.vmap(row_loss, in_axes=(None, 0, 0, 0, 0))(v2, s1, c, v1, s2))

    def checks(v1, s1, v2, s2, c):
        """One program (one compile): the batch's values, its gradient with vehicle 2 shared, and the row's."""
        shared, row = _first(v2), _first((v1, s1, v2, s2, c))
        return (jax.vmap(exchange)(v1, s1, v2, s2, c), jax.grad(loss, argnums=(0, 1, 2))(shared, s1, c, v1, s2),
                jax.grad(row_loss, argnums=(0, 1, 2))(shared, row[1], row[4], row[0], row[3]))

    program = reference_jit(checks)
    for case in (good, bad):
        v1, s1, v2, s2, c = kit.inputs([case])
        shared, row = _rows(v2, 0), _rows((v1, s1, v2, s2, c), 0)
        batched, grads, reference = program(v1, s1, v2, s2, c)
        assert_same_leaves(batched, jax.tree_util.tree_map(lambda x: np.asarray(x)[None], kit.exchange(*row)))
        # to rounding: a batch's JVP is jax.vmap's of the row's. Rounding in the loss's units: each derivative
        # times its input (at least 1 SI unit), against the sum of them all
        triples = [(np.asarray(a), np.reshape(np.asarray(b), np.shape(a)),
                    np.maximum(np.abs(np.reshape(x, np.shape(a))), 1))
                   for a, b, x in zip(*(jax.tree_util.tree_leaves(t)
                                        for t in (grads, reference, (shared, row[1], row[4]))))]
        total = sum(np.sum(np.abs(b) * x) for _, b, x in triples)
        for a, b, x in triples:
            assert np.all(np.abs(a - b) * x <= 1e-12 * total), (a, b)
        assert any(np.any(np.asarray(x) != 0) for x in jax.tree_util.tree_leaves(grads)) == (case is good)


@pytest.mark.slow
def test_second_derivatives_through_a_chunked_batch(random_cases, small_chunks):
    """Forward over reverse (``jax.hessian``) through a batch whose values run in chunks: the columns of the
    Hessian are central differences of the gradient."""
    v1, s1, v2, s2, c = kit.inputs(random_cases["principal"][:100])

    def loss(p):
        r = jax.vmap(exchange)(v1, s1._replace(velocity=s1.velocity * p[0]), v2, s2,
                                       c._replace(friction=c.friction * p[1]))
        return jnp.sum(jnp.where(r.contact.status == 0, r.vehicles[0].delta_v_magnitude ** 2
                                 + r.vehicles[1].speed_after, 0.0))

    p, h = jnp.array([1.0, 0.9]), 1e-6
    program = reference_jit(lambda p: (jax.hessian(loss)(p), jax.grad(loss)(p)))  # one compile for both
    hessian = np.asarray(program(p)[0])
    for k in range(2):
        step = h * np.eye(2)[k]
        column = (np.asarray(program(p + step)[1]) - np.asarray(program(p - step)[1])) / (2 * h)
        np.testing.assert_allclose(hessian[:, k], column, rtol=1e-5, atol=1e-6 * np.abs(hessian).max())
    assert abs(float(hessian[0, 1])) > 1.0  # the two parameters interact


@pytest.mark.slow
def test_float32_inputs_stay_float32_with_x64(random_cases, small_chunks):
    """With 64-bit types enabled (as in these tests, the CLI and the benchmarks), float32 inputs give
    float32 results computed in float32: no float64 constant may promote them (the stand-ins of
    invalid rows once did). Values against the float64 reference at float32 tolerance."""
    cases = random_cases["full"][:100]
    args = kit.inputs(cases, np.float32)
    for result in (BATCH(*args), ks_jax.exchange_batch(*args, chunk=64)):
        floats = [x for x in jax.tree_util.tree_leaves(result) if np.asarray(x).dtype.kind == "f"]
        assert len(floats) == 38 and all(np.asarray(x).dtype == np.float32 for x in floats)
        kit.assert_matches(kit.engine_dict(result), kit.reference_batch(cases), kit.RTOL_FLOAT32, cases)


def test_a_blocked_stage_over_more_rows_than_a_block_equals_it_over_all_rows_at_once():
    """``stages.in_blocks`` (the CPU's path of a motion over a file or sweep of more than a block of cases): 10 rows in
    blocks of 4, the last padded with copies of the last row, give each row what the vmapped stage gives it over all
    the rows at once; arguments without rows (axis None, whole or as a leaf of a tree) reach every block whole."""
    rng = np.random.default_rng(0)
    x, scale = jnp.asarray(rng.normal(size=(10, 3))), jnp.asarray(1.5)
    tree = {"a": jnp.asarray(rng.normal(size=10)), "b": jnp.asarray([2.0, -0.5])}
    axes = (0, None, {"a": 0, "b": None})
    stage = jax.vmap(lambda x, c, t: (jnp.sin(x).sum() * c + t["a"] * t["b"].sum(), x * t["a"]), in_axes=axes)
    want = stage(x, scale, tree)
    for rows in (4, 10, 16):  # three blocks, one, and more rows in a block than the batch has
        got = jax.jit(STAGES.in_blocks(stage, rows, axes))(x, scale, tree)
        for g, w in zip(got, want):
            assert g.shape == w.shape
            np.testing.assert_allclose(g, w, rtol=1e-14, atol=0)  # the same rows; vectorised apart, to rounding
