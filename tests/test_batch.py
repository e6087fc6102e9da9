"""ks_jax.exchange_batch: the chunked batch path gives the values of vmap(exchange), row for row,
across chunk boundaries (including a last chunk that overlaps the one before), with bad rows.

The two compute the impulse in two forms (``impulse_stage(for_gradients=False)``: components;
``exchange``: (3, 3) arrays), so these tests also hold the two forms to the same values."""

from __future__ import annotations

import copy
import importlib
import re
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import ks_jax
from ks_jax import types as t

EXCHANGE_MODULE = importlib.import_module("ks_jax.exchange")  # ks_jax.exchange is the function
CASES = Path(ks_jax.__file__).parent / "cases"


def _leaves(result):
    return jax.tree_util.tree_leaves(result)


def _assert_same(batched, reference):
    for a, b in zip(_leaves(batched), _leaves(reference)):
        a, b = np.asarray(a), np.asarray(b)
        assert a.shape == b.shape
        if a.dtype.kind == "f":
            np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-9)
        else:
            np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("kind", ["principal", "full"])
def test_exchange_batch_equals_vmap(kit, random_cases, kind):
    cases = random_cases[kind][:150]
    # rows with invalid inputs among them: each keeps its own status, the others are solved
    bad = copy.deepcopy(cases[7])
    bad["vehicles"][1]["mass"] = -5.0
    nan = copy.deepcopy(cases[40])
    nan["contact"]["point"] = np.array([0.0, np.nan, 0.0])
    cases = cases[:7] + [bad] + cases[8:40] + [nan] + cases[41:]
    args = kit.inputs(cases)
    reference = jax.vmap(ks_jax.exchange)(*args)
    # 150 rows in chunks of 64: 64, 64, then a last chunk aligned to the end (rows 86..149)
    for chunk in (64, 150, 1000):
        batched = ks_jax.exchange_batch(*args, chunk=chunk)
        _assert_same(batched, reference)
    assert all(isinstance(x, np.ndarray) for x in _leaves(batched))  # NumPy results, like sweep's
    one = ks_jax.exchange_batch(*jax.tree_util.tree_map(lambda x: x[3:4], args))  # a batch of one row
    _assert_same(one, jax.tree_util.tree_map(lambda x: x[3:4], reference))
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


def test_exchange_batch_smoothing_matches_vmap(kit, random_cases):
    args = kit.inputs(random_cases["principal"][:40])
    reference = jax.vmap(lambda *a: ks_jax.exchange(*a, 0.05))(*args)
    _assert_same(ks_jax.exchange_batch(*args, smoothing=0.05, chunk=16), reference)


def test_exchange_batch_rejects_mismatched_batch_and_bad_arguments(kit, random_cases):
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


def test_exchange_batch_writes_into_out(kit, random_cases):
    """``out``: the results of another batch of the same size are overwritten in place (chunks of 16
    over 40 rows, the last one aligned to the end) and equal a fresh call; a wrong ``out`` is refused,
    naming the field."""
    a, b = (kit.inputs(random_cases["principal"][k:k + 40]) for k in (0, 40))
    fresh = ks_jax.exchange_batch(*a, chunk=16)
    out = ks_jax.exchange_batch(*b, chunk=16)
    before = [np.copy(x) for x in _leaves(out)]
    got = ks_jax.exchange_batch(*a, chunk=16, out=out)
    assert all(x is y for x, y in zip(_leaves(got), _leaves(out)))
    _assert_same(got, fresh)
    assert any(not np.array_equal(x, y) for x, y in zip(before, _leaves(got)) if x.dtype.kind == "f")
    wrong = out._replace(vehicles=(out.vehicles[0]._replace(pdof=np.zeros(39)), out.vehicles[1]))
    with pytest.raises(ValueError, match=r"out\.vehicles\[0\]\.pdof = ndarray float64\[39\].*float64\[40\]"):
        ks_jax.exchange_batch(*a, out=wrong)
    frozen = [np.copy(x) for x in _leaves(out)]
    frozen[0].flags.writeable = False
    with pytest.raises(ValueError, match="writeable"):
        ks_jax.exchange_batch(*a, out=jax.tree_util.tree_unflatten(jax.tree_util.tree_structure(out), frozen))
    numpy_inputs = jax.tree_util.tree_map(np.array, a)
    aliased = out._replace(contact=out.contact._replace(energy_loss=numpy_inputs[4].friction))
    with pytest.raises(ValueError, match="out.contact.energy_loss shares memory with an input"):
        ks_jax.exchange_batch(*numpy_inputs, out=aliased)


def test_exchange_batch_of_no_rows(kit, random_cases):
    """An empty batch (a filtered batch may be) gives empty results with the fields, trailing shapes and
    dtypes of a one-row batch's; an ``out`` of that shape is returned as it is."""
    one = kit.inputs(random_cases["principal"][:1])
    none = jax.tree_util.tree_map(lambda x: np.asarray(x)[:0], one)
    got, row = ks_jax.exchange_batch(*none), ks_jax.exchange_batch(*one)
    assert jax.tree_util.tree_structure(got) == jax.tree_util.tree_structure(row)
    for a, b in zip(_leaves(got), _leaves(row)):
        assert isinstance(a, np.ndarray) and a.shape == (0,) + b.shape[1:] and a.dtype == b.dtype
    assert ks_jax.exchange_batch(*none, out=got) is got
    wrong = got._replace(contact=got.contact._replace(impulse=np.zeros((1, 3))))
    with pytest.raises(ValueError, match=r"out\.contact\.impulse = ndarray float64\[1, 3\]"):
        ks_jax.exchange_batch(*none, out=wrong)


# --------------------------------------------------------------------------- jax.vmap(exchange) in chunks
@pytest.fixture
def small_chunks(monkeypatch):
    """``jax.vmap(exchange)`` over more than CHUNK_ROWS rows runs in chunks on one CPU device;
    64-row chunks exercise that path on small batches."""
    monkeypatch.setattr(EXCHANGE_MODULE, "CHUNK_ROWS", 64)
    return 64


def _with_bad_rows(cases):
    bad = copy.deepcopy(cases[63])  # the last row of the first chunk
    bad["vehicles"][0]["inertia"] = -np.abs(np.asarray(bad["vehicles"][0]["inertia"]))
    wild = copy.deepcopy(cases[100])  # a row the end-aligned last chunk computes again (restitution > 1)
    wild["contact"]["restitution"] = 1.5
    return cases[:63] + [bad] + cases[64:100] + [wild] + cases[101:]


def test_vmap_of_exchange_in_chunks_equals_single_solves(kit, random_cases, small_chunks):
    cases = _with_bad_rows(random_cases["full"][:150])  # chunks at 0, 64 and 86 (end-aligned)
    args = kit.inputs(cases)
    fn = jax.jit(jax.vmap(ks_jax.exchange))
    assert "scan" in str(jax.make_jaxpr(fn)(*args))  # the loop over chunks, not the whole-batch program
    batched = fn(*args)
    singles = [kit.exchange(*kit.inputs(c)) for c in cases]
    stacked = jax.tree_util.tree_map(lambda *xs: np.stack([np.asarray(x) for x in xs]), *singles)
    _assert_same(batched, stacked)
    status = np.asarray(batched.contact.status)
    assert status[63] == t.INVALID_INERTIA_1 and status[100] == t.INVALID_RESTITUTION
    good = np.ones(len(cases), bool)
    good[[63, 100]] = False
    kit.assert_matches(kit.engine_dict(jax.tree_util.tree_map(lambda x: np.asarray(x)[good], batched)),
                       kit.reference_batch([c for c, g in zip(cases, good) if g]), 1e-9,
                       [c for c, g in zip(cases, good) if g])
    # a batch of at most one chunk is one whole-batch program
    assert "scan" not in str(jax.make_jaxpr(jax.vmap(ks_jax.exchange))(*kit.inputs(cases[:64])))


def test_vmap_of_exchange_in_chunks_with_unbatched_inputs_and_smoothing(kit, random_cases, small_chunks):
    cases = random_cases["principal"][:130]
    v1, s1, v2, s2, c = kit.inputs(cases)
    first = jax.tree_util.tree_map(lambda x: x[0], (v1, v2))  # both vehicles the same in every row
    fn = jax.jit(jax.vmap(lambda s1, s2, c: ks_jax.exchange(first[0], s1, first[1], s2, c, smoothing=0.05)))
    batched = fn(s1, s2, c)
    reference = jax.jit(jax.vmap(lambda s1, s2, c: ks_jax.exchange(first[0], s1, first[1], s2, c, smoothing=0.05)))(
        *jax.tree_util.tree_map(lambda x: x[:64], (s1, s2, c)))  # one chunk: the whole-batch program
    _assert_same(jax.tree_util.tree_map(lambda x: x[:64], batched), reference)
    row = ks_jax.exchange(first[0], *jax.tree_util.tree_map(lambda x: x[129], (s1,)), first[1],
                          *jax.tree_util.tree_map(lambda x: x[129], (s2, c)), smoothing=0.05)
    _assert_same(jax.tree_util.tree_map(lambda x: x[129], batched), row)


def test_vmap_of_exchange_in_chunks_differentiates(kit, random_cases, small_chunks):
    """Forward and reverse mode through the chunked batch (two chunks, the second padded): the
    derivatives are those of the whole-batch program (per-row gradients, batched after the
    transpose, which is the plain JVP's), and match central differences."""
    args = kit.inputs(random_cases["principal"][:100])

    def loss(args):
        r = jax.vmap(ks_jax.exchange)(*args)
        return jnp.sum(r.vehicles[0].delta_v_magnitude + r.contact.energy_loss * 1e-4)

    def row_loss(*row):
        r = ks_jax.exchange(*row)
        return r.vehicles[0].delta_v_magnitude + r.contact.energy_loss * 1e-4

    # the gradient's own batching ran in chunks: a scan over them in the reverse pass too
    traced = jax.jit(jax.grad(loss)).trace(args)  # traced once: its jaxpr read, then compiled
    assert str(traced.jaxpr).count("scan[") >= 2
    grad = traced.lower().compile()(args)
    traced = jax.jit(jax.vmap(jax.grad(row_loss, argnums=(0, 1, 2, 3, 4)))).trace(*args)
    assert "scan[" not in str(traced.jaxpr)
    per_row = traced.lower().compile()(*args)
    for a, b in zip(jax.tree_util.tree_leaves(grad), jax.tree_util.tree_leaves(per_row)):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-10, atol=1e-12)
    # central differences along the speed of vehicle 1 in every row at once
    direction = np.zeros_like(np.asarray(args[1].velocity))
    direction[:, 0] = 1.0
    h = 1e-5

    @jax.jit
    def shifted(step):
        return loss((args[0], args[1]._replace(velocity=args[1].velocity + step * direction), *args[2:]))

    fd = (shifted(h) - shifted(-h)) / (2 * h)
    np.testing.assert_allclose(float(np.sum(np.asarray(grad[1].velocity) * direction)), float(fd), rtol=1e-6)
    # forward mode of the batch (fit uses jax.jacfwd)
    tangents = jax.tree_util.tree_map(jnp.zeros_like, args)
    tangents = (tangents[0], tangents[1]._replace(velocity=jnp.asarray(direction)), *tangents[2:])
    _, along = jax.jit(lambda a, t: jax.jvp(loss, (a,), (t,)))(args, tangents)
    np.testing.assert_allclose(float(along), float(fd), rtol=1e-6)


def test_gradient_in_chunks_with_a_shared_vehicle_and_bad_rows(kit, random_cases, small_chunks):
    """Reverse mode through the chunks with an unbatched input (one vehicle 2 in every row: its
    gradient is the sum over the rows) and rows with invalid inputs (zero gradient, nothing NaN),
    against per-row gradients."""
    cases = _with_bad_rows(random_cases["full"][:150])
    v1, s1, v2, s2, c = kit.inputs(cases)
    shared = jax.tree_util.tree_map(lambda x: x[0], v2)

    def row_loss(v2, v1, s1, s2, c):
        r = ks_jax.exchange(v1, s1, v2, s2, c)
        return jnp.where(r.contact.status == 0, r.vehicles[1].delta_v_magnitude + r.vehicles[0].speed_after ** 2
                         + 1e-4 * r.contact.energy_loss, 0.0)

    def loss(v2, s1, c):
        return jnp.sum(jax.vmap(row_loss, in_axes=(None, 0, 0, 0, 0))(v2, v1, s1, s2, c))

    assert "scan[" in str(jax.make_jaxpr(jax.grad(loss))(shared, s1, c))
    grads = jax.jit(jax.grad(loss, argnums=(0, 1, 2)))(shared, s1, c)
    per_row = jax.jit(jax.vmap(jax.grad(row_loss, argnums=(0, 2, 4)), in_axes=(None, 0, 0, 0, 0)))(
        shared, v1, s1, s2, c)
    reference = (jax.tree_util.tree_map(lambda x: np.sum(np.asarray(x), 0), per_row[0]), *per_row[1:])
    for a, b in zip(jax.tree_util.tree_leaves(grads), jax.tree_util.tree_leaves(reference)):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-10, atol=1e-10)
    assert all(np.all(np.isfinite(np.asarray(x))) for x in jax.tree_util.tree_leaves(grads))
    for bad in (63, 100):
        assert all(np.all(np.asarray(x)[bad] == 0) for x in jax.tree_util.tree_leaves(grads[1:]))


def _library_calls(lowered):
    """The targets of the custom calls (LAPACK and other library routines) in a lowered program."""
    if not isinstance(lowered, str):
        lowered = lowered.as_text()
    return set(re.findall(r"custom_call @(\w+)", lowered))


def test_batched_programs_call_no_library_routines(kit, random_cases, small_chunks):
    """The batch, its gradient and the sweep's stages are closed-form XLA loops: no per-row LAPACK
    call (issue #5), which would also be unsafe here: two batched LAPACK calls running at once never
    returned on the 2-core benchmark machine (benchmarks/RESULTS.md). The check itself sees the
    LAPACK calls of a batched 3x3 solve."""
    args = kit.inputs(random_cases["full"][:150])  # three chunks of 64 rows

    def loss(args):
        r = jax.vmap(ks_jax.exchange)(*args)
        return jnp.sum(jnp.where(r.contact.status == 0, r.vehicles[0].pdof + r.vehicles[1].ees, 0.0))

    assert _library_calls(jax.jit(jax.vmap(ks_jax.exchange)).lower(*args)) == set()
    gradient = jax.jit(jax.value_and_grad(loss)).lower(args).as_text()
    assert "stablehlo.while" in gradient  # the chunked gradient's loops over chunks
    assert _library_calls(gradient) == set()
    prep, imp, res = importlib.import_module("ks_jax.batch")._stages(64, 0.0)
    rows, prepared = jax.eval_shape(prep, args, 0)
    impulse = jax.eval_shape(imp, rows, prepared)
    for stage, stage_args in ((prep, (args, 0)), (imp, (rows, prepared)), (res, (rows, prepared, impulse))):
        assert _library_calls(stage.lower(*stage_args)) == set()
    solve = jax.jit(jax.vmap(jnp.linalg.solve)).lower(jnp.eye(3)[None].repeat(8, 0), jnp.ones((8, 3)))
    assert _library_calls(solve)


def test_a_chunked_batch_traces_each_stage_once(kit, random_cases, small_chunks, monkeypatch):
    """Tracing (JAX, in Python) was most of the first call of a chunked gradient: on a CPU each stage of
    the exchange is traced once per program that runs it, not also in the branch that
    ``lax.platform_dependent`` keeps for other platforms, nor again for the shapes of a conditional's
    skipped branch or of the loop's outputs. Counted (no compile): the stages traced for
    ``jax.jit(jax.vmap(exchange))`` and its gradient, and a row's loss traced for the gradient of a loss
    built by ``sum_over_rows``. The code before traced the impulse and results stages 4 times each for
    the batch and for its gradient, and for ``sum_over_rows`` the row's loss 3 times and the stages 8
    (benchmarks/RESULTS.md)."""
    if jax.default_backend() != "cpu":
        pytest.skip("counts the CPU path's traces")
    counts = {}

    def counted(name, fn):
        def traced(*a, **k):
            counts[name] = counts.get(name, 0) + 1
            return fn(*a, **k)
        return traced

    for name in ("prepare", "impulse_stage", "results_stage"):
        monkeypatch.setattr(EXCHANGE_MODULE, name, counted(name, getattr(EXCHANGE_MODULE, name)))
    EXCHANGE_MODULE._row_shapes.cache_clear()
    args = kit.inputs(random_cases["full"][:150])  # three chunks of 64 rows

    def row(*a):
        counts["row"] = counts.get("row", 0) + 1
        r = ks_jax.exchange(*a)
        return jnp.where(r.contact.status == 0, r.vehicles[0].delta_v_magnitude, 0.0)

    def loss(args):
        return jnp.sum(jax.vmap(row)(*args))

    # the function as written (custom_vmap's jaxpr of one row), the shapes of a row's results, the loop
    jax.jit(jax.vmap(ks_jax.exchange)).trace(*args)
    assert counts == {"impulse_stage": 3, "results_stage": 3, "prepare": 1}
    counts.clear()
    traced = jax.jit(jax.grad(loss)).trace(args)  # the same, and the JVP's loop over chunks
    assert "scan[" in str(traced.jaxpr)
    assert counts["row"] == 1 and counts["impulse_stage"] <= 3 and counts["results_stage"] <= 3
    counts.clear()
    summed = ks_jax.sum_over_rows(row, chunk=64)
    jax.jit(jax.grad(lambda a: summed(*a))).trace(args)
    assert counts["row"] == 1 and counts["impulse_stage"] <= 2 and counts["results_stage"] <= 2


def _instructions(fn, *args):
    """The number of HLO instructions in XLA's compiled program of ``jax.jit(fn)``, fusions' bodies
    included."""
    return len(re.findall(r"^\s+\S+ = ", jax.jit(fn).lower(*args).compile().as_text(), re.M))


def test_a_batch_compiles_to_about_the_program_of_one_row(kit, random_cases):
    """``jax.vmap`` adds a batch axis, not work: XLA's program for one or two rows has about the
    instructions of the program of one unbatched row (1.03x and 1.08x here, 2026-11-25). With the
    contact normal divided by ``la.safe_norm`` (``sqrt(maximum(n.n, tiny))``) XLA copied that expression
    into every loop that reads the normal: 7.0x the instructions of one row (58,515 against 8,389), 15 us
    per row against 0.4-0.5 at 16,384 rows (benchmarks/RESULTS.md). Batches up to CHUNK_ROWS rows run
    that program, and so do a multi-case ``solve``, the last stage of automatic contact and the fit.
    Checked for the exchange and for that stage. A batch of one row, now computed unbatched, was 6.7x
    the size of one row as well."""
    from ks_jax.solve import auto_contact, auto_exchange, auto_status

    one = tuple(jax.tree_util.tree_map(lambda x: x[0], kit.inputs(random_cases["full"][:1])))
    unbatched = _instructions(ks_jax.exchange, *one)
    for rows in (1, 2):  # one row batched by vmap was 55,378 against 8,250
        assert _instructions(jax.vmap(ks_jax.exchange), *kit.inputs(random_cases["full"][:rows])) <= 1.5 * unbatched

    inputs = ks_jax.load_case(CASES / "auto_tbone.json").inputs
    status = jax.jit(auto_status)(inputs)
    row = (inputs, status, jax.jit(auto_contact, static_argnums=(2, 3))(inputs, status, True, True))
    rows = jax.tree_util.tree_map(lambda x: jnp.stack([x, x]), row)
    assert _instructions(jax.vmap(auto_exchange), *rows) <= 1.5 * _instructions(auto_exchange, *row)


def test_automatic_contact_in_one_program_compiles_to_about_its_three_stages():
    """``solve_inputs`` with automatic contact in one program (a fit's residuals are) has about the
    instructions of its three stages compiled apart (``_solve_batch``), batched or not: 16,366 against
    16,565 for two rows, 14,962 against 15,019 for one unbatched here (2026-11-25). Unless the status
    is fenced off, XLA computes it again from every input in each loop that reads a stand-in input:
    43,057 and 40,105 instructions (stored by ``linalg.materialize`` instead: 16,170 and 40,105)."""
    from ks_jax.case import as_arrays
    from ks_jax.solve import auto_contact, auto_exchange, auto_status, solve_inputs

    def contact_(x, s):
        return auto_contact(x, s, True, True)

    inputs = as_arrays(ks_jax.load_case(CASES / "auto_tbone.json").inputs)
    for batch in (lambda f: f, jax.vmap):
        rows = inputs if batch is not jax.vmap else jax.tree_util.tree_map(lambda x: jnp.stack([x, x]), inputs)
        status = batch(auto_status)(rows)
        contact = batch(contact_)(rows, status)
        stages = (_instructions(batch(auto_status), rows) + _instructions(batch(contact_), rows, status)
                  + _instructions(batch(auto_exchange), rows, status, contact))
        assert _instructions(batch(lambda x: solve_inputs(x, True, True)), rows) <= 1.2 * stages


def test_a_batch_of_one_row_is_the_row(kit, random_cases):
    """``jax.vmap(exchange)`` over one row computes the row unbatched (the test above): its values,
    and its gradient and JVP with one vehicle shared (unbatched), are those of ``exchange`` of the row,
    for a valid row and for one with invalid inputs."""
    good = random_cases["full"][5]
    bad = copy.deepcopy(good)
    bad["vehicles"][0]["mass"] = 0.0
    for case in (good, bad):
        v1, s1, v2, s2, c = kit.inputs([case])
        shared = jax.tree_util.tree_map(lambda x: x[0], v2)
        row = tuple(jax.tree_util.tree_map(lambda x: x[0], (v1, s1, v2, s2, c)))
        batched = jax.jit(jax.vmap(ks_jax.exchange))(v1, s1, v2, s2, c)
        _assert_same(batched, jax.tree_util.tree_map(lambda x: np.asarray(x)[None], kit.exchange(*row)))

        def row_loss(v2, s1, c, v1=row[0], s2=row[3]):
            r = ks_jax.exchange(v1, s1, v2, s2, c)
            return jnp.where(r.contact.status == 0, r.vehicles[1].delta_v_magnitude + r.vehicles[0].speed_after ** 2
                             + 1e-4 * r.contact.energy_loss, 0.0)

        def loss(v2, s1, c):
            return jnp.sum(jax.vmap(lambda s1, c: row_loss(v2, s1, c))(s1, c))

        grads = jax.jit(jax.grad(loss, argnums=(0, 1, 2)))(shared, s1, c)
        reference = jax.jit(jax.grad(row_loss, argnums=(0, 1, 2)))(shared, row[1], row[4])
        for a, b in zip(jax.tree_util.tree_leaves(grads), jax.tree_util.tree_leaves(reference)):
            np.testing.assert_allclose(np.asarray(a), np.reshape(np.asarray(b), a.shape), rtol=1e-12, atol=1e-15)
        assert any(np.any(np.asarray(x) != 0) for x in jax.tree_util.tree_leaves(grads)) == (case is good)
        ones = jax.tree_util.tree_map(jnp.ones_like, s1)
        along = jax.jit(lambda t: jax.jvp(lambda s: loss(shared, s, c), (s1,), (t,))[1])(ones)
        row_along = jax.jvp(lambda s: row_loss(shared, s, row[4]), (row[1],),
                            (jax.tree_util.tree_map(lambda x: x[0], ones),))[1]
        np.testing.assert_allclose(float(along), float(row_along), rtol=1e-12, atol=1e-15)


def test_four_results_of_one_row_compile_to_less_than_all_of_them():
    """A fit's residuals read a few results of ``solve_inputs``, smoothed: XLA keeps what they need of
    the exchange, so the program is smaller than the one of every result (4,218 against 9,396
    instructions here, 2026-11-25). The copies of the normal's length that made the batched exchange
    7x its size (the test above) were made here without a batch: 23,917 against 9,774."""
    from ks_jax.case import as_arrays, get_output, set_input
    from ks_jax.solve import solve_inputs

    inputs = as_arrays(ks_jax.load_case(CASES / "seed_000_saturn_pontiac.json").inputs)
    paths = ("vehicles[0].delta_v_magnitude", "vehicles[1].delta_v_magnitude", "vehicles[0].speed_after",
             "vehicles[1].speed_after")

    def residuals(p, x):
        x = set_input(set_input(x, "vehicles[1].speed", p[0]), "contact.friction", p[1])
        return jnp.stack([get_output(solve_inputs(x, smoothing=1e-3), q) for q in paths])

    every = _instructions(lambda x: solve_inputs(x, smoothing=1e-3), inputs)
    assert _instructions(residuals, jnp.array([13.0, 0.5]), inputs) < every, every


def test_second_derivatives_in_chunks(kit, random_cases, small_chunks, monkeypatch):
    """Forward over reverse (``jax.hessian``) through the chunked gradient equals the same Hessian of
    the whole-batch program (the chunks switched off)."""
    v1, s1, v2, s2, c = kit.inputs(random_cases["principal"][:100])

    def loss(p):
        r = jax.vmap(ks_jax.exchange)(v1, s1._replace(velocity=s1.velocity * p[0]), v2, s2,
                                       c._replace(friction=c.friction * p[1]))
        return jnp.sum(jnp.where(r.contact.status == 0, r.vehicles[0].delta_v_magnitude ** 2
                                 + r.vehicles[1].speed_after, 0.0))

    p = jnp.array([1.0, 0.9])
    traced = jax.jit(jax.hessian(loss)).trace(p)  # traced once: its jaxpr read, then compiled
    assert "scan[" in str(traced.jaxpr)
    chunked = traced.lower().compile()(p)
    monkeypatch.setattr(EXCHANGE_MODULE, "CHUNK_ROWS", 1 << 14)
    traced = jax.jit(jax.hessian(loss)).trace(p)
    assert "scan[" not in str(traced.jaxpr)
    whole = traced.lower().compile()(p)
    np.testing.assert_allclose(np.asarray(chunked), np.asarray(whole), rtol=1e-11)
    assert abs(float(whole[0, 1])) > 1.0  # the two parameters interact


def test_float32_inputs_stay_float32_with_x64(kit, random_cases, small_chunks):
    """With 64-bit types enabled (as in these tests, the CLI and the benchmarks), float32 inputs give
    float32 results computed in float32: no float64 constant may promote them (the stand-ins of
    invalid rows once did). Values against the float64 reference at float32 tolerance."""
    cases = random_cases["full"][:100]
    args = kit.inputs(cases, np.float32)
    for result in (jax.jit(jax.vmap(ks_jax.exchange))(*args), ks_jax.exchange_batch(*args, chunk=64)):
        floats = [x for x in _leaves(result) if np.asarray(x).dtype.kind == "f"]
        assert len(floats) == 38 and all(np.asarray(x).dtype == np.float32 for x in floats)
        kit.assert_matches(kit.engine_dict(result), kit.reference_batch(cases), kit.rtol_float32, cases)


# --------------------------------------------------------------------------- sum_over_rows
def _evidence_row_loss(v1, s1, v2, s2, c, target):
    r = ks_jax.exchange(v1, s1, v2, s2, c)
    ok = r.contact.status == 0
    delta_v = jnp.where(ok, r.vehicles[0].delta_v_magnitude, target)  # NaN in a bad row: no NaN times the target
    return jnp.where(ok, (delta_v - target) ** 2 + r.vehicles[1].speed_after ** 2 + 1e-4 * r.contact.energy_loss, 0.0)


def test_sum_over_rows_equals_the_sum_and_per_row_gradients(kit, random_cases):
    """Chunks of 64 rows over 150 (the last chunk padded), a vehicle and an evidence target shared by
    every row, rows with invalid inputs: the value is the plain sum, the gradients are the per-row
    gradients (summed over the rows for the shared inputs), zero and finite in the bad rows, and a
    central difference agrees."""
    cases = _with_bad_rows(random_cases["full"][:150])
    v1, s1, v2, s2, c = kit.inputs(cases)
    shared = jax.tree_util.tree_map(lambda x: x[0], v2)
    axes = (0, 0, None, 0, 0, None)
    loss = ks_jax.sum_over_rows(_evidence_row_loss, in_axes=axes, chunk=64)
    target = jnp.asarray(4.0)

    traced = jax.jit(jax.value_and_grad(loss, argnums=(1, 2, 4, 5))).trace(v1, s1, shared, s2, c, target)
    assert "cond[" in str(traced.jaxpr)
    value, grads = traced.lower().compile()(v1, s1, shared, s2, c, target)
    plain = jax.jit(lambda *a: jnp.sum(jax.vmap(_evidence_row_loss, in_axes=axes)(*a)))(v1, s1, shared, s2, c, target)
    np.testing.assert_allclose(float(value), float(plain), rtol=1e-13)
    loss_jit = jax.jit(loss)
    np.testing.assert_allclose(float(loss_jit(v1, s1, shared, s2, c, target)), float(plain), rtol=1e-13)
    per_row = jax.jit(jax.vmap(jax.grad(_evidence_row_loss, argnums=(1, 2, 4, 5)), in_axes=axes))(
        v1, s1, shared, s2, c, target)
    reference = (per_row[0], jax.tree_util.tree_map(lambda x: np.sum(np.asarray(x), 0), per_row[1]), per_row[2],
                 np.sum(np.asarray(per_row[3])))
    for a, b in zip(jax.tree_util.tree_leaves(grads), jax.tree_util.tree_leaves(reference)):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-10, atol=1e-10)
    assert all(np.all(np.isfinite(np.asarray(x))) for x in jax.tree_util.tree_leaves(grads))
    for bad in (63, 100):
        assert all(np.all(np.asarray(x)[bad] == 0) for x in jax.tree_util.tree_leaves((grads[0], grads[2])))
    h = 1e-6
    fd = (loss_jit(v1, s1, shared, s2, c, target + h) - loss_jit(v1, s1, shared, s2, c, target - h)) / (2 * h)
    np.testing.assert_allclose(float(grads[3]), float(fd), rtol=1e-6)


def test_sum_over_rows_forward_mode_and_second_derivatives(kit, random_cases):
    """Forward mode (the gradient dotted with the tangent) against central differences, and the
    Hessian of the chunked sum against that of the plain sum."""
    v1, s1, v2, s2, c = kit.inputs(random_cases["principal"][:100])
    loss = ks_jax.sum_over_rows(_evidence_row_loss, in_axes=(0, 0, 0, 0, 0, None), chunk=32)

    def scaled(p, fn):
        return fn(v1, s1._replace(velocity=s1.velocity * p[0]), v2, s2, c._replace(friction=c.friction * p[1]), 3.0)

    def plain(*args):
        return jnp.sum(jax.vmap(_evidence_row_loss, in_axes=(0, 0, 0, 0, 0, None))(*args))

    p = jnp.array([1.0, 0.9])
    _, along = jax.jit(lambda p: jax.jvp(lambda q: scaled(q, loss), (p,), (jnp.array([1.0, 0.0]),)))(p)
    h = 1e-6
    plain_jit = jax.jit(lambda q: scaled(q, plain))
    fd = (plain_jit(p + jnp.array([h, 0.0])) - plain_jit(p - jnp.array([h, 0.0]))) / (2 * h)
    np.testing.assert_allclose(float(along), float(fd), rtol=1e-6)
    chunked = jax.jit(jax.hessian(lambda q: scaled(q, loss)))(p)
    whole = jax.jit(jax.hessian(lambda q: scaled(q, plain)))(p)
    np.testing.assert_allclose(np.asarray(chunked), np.asarray(whole), rtol=1e-10)
    assert abs(float(whole[0, 1])) > 1.0  # the two parameters interact


def test_sum_over_rows_rejects_bad_arguments(kit, random_cases):
    args = kit.inputs(random_cases["principal"][:10])
    with pytest.raises(ValueError, match=r"chunk = 0: chunk must be a positive number of rows"):
        ks_jax.sum_over_rows(_evidence_row_loss, chunk=0)
    with pytest.raises(ValueError, match=r"in_axes\[5\] = 1: each entry must be 0 \(batched\) or None"):
        ks_jax.sum_over_rows(_evidence_row_loss, in_axes=(0, 0, 0, 0, 0, 1))(*args, 3.0)
    with pytest.raises(ValueError, match=r"in_axes = \(0, None\) has 2 entries for 6 arguments"):
        ks_jax.sum_over_rows(_evidence_row_loss, in_axes=(0, None))(*args, 3.0)
    with pytest.raises(TypeError, match=r"fn returns shape \(3,\) per row; it must return a scalar"):
        ks_jax.sum_over_rows(lambda *a: ks_jax.exchange(*a).vehicles[0].delta_v)(*args)


def test_sum_over_rows_forward_mode_with_a_python_number():
    """jvp and jacfwd with a Python float as the shared argument (as docs/sweeps.md passes a measured value):
    d/dt sum_k (x_k - t)^2 = -2 sum_k (x_k - t), by hand."""
    loss = ks_jax.sum_over_rows(lambda x, t: (x - t) ** 2, in_axes=(0, None))
    x = jnp.arange(5.0)
    value, slope = jax.jvp(lambda t: loss(x, t), (3.0,), (1.0,))
    assert float(value) == 15.0 and float(slope) == 10.0
    assert float(jax.jacfwd(lambda t: loss(x, t))(3.0)) == 10.0 == float(jax.grad(lambda t: loss(x, t))(3.0))
