"""The Kudlich-Slibar impulse exchange for one collision (MODEL.md section 3).

``exchange`` is pure and unbatched: the caller jits and vmaps it (below: what vmap does on a
CPU). Nothing here branches in Python on array values, so one bad row in a batch gets its own
status code while the others are solved; every quantity that could be singular (|T_c| = 0,
mu = 0, the cone boundary, eps = -1, a separating contact) goes through the double-where
helpers of ``linalg``.

``jax.vmap(exchange)`` on a CPU
-------------------------------
Over a whole batch in one program, XLA's CPU loops stream hundreds of batch-sized temporaries
through memory (at 2^20 rows in three benchmark runs, 1.2-1.7 us per row; benchmarks/RESULTS.md).
So ``exchange`` has a vmap rule (``jax.custom_batching.custom_vmap``): over more than CHUNK_ROWS
rows, on a CPU, with one device, it computes the batch in a loop over chunks of CHUNK_ROWS rows,
each in ``exchange_batch``'s three stages, each stage fenced off from the others by a conditional
(``_fenced``) so that XLA compiles it as it would a separate jitted call. Elsewhere (a GPU, several
devices, a short batch, a traced ``smoothing``) the rule is ``jax.vmap`` of the same function, and
over one row it is the function of that row unbatched: XLA's program for a batch of one row was
6.7x the size of the program for two rows or for none (55,378 instructions against 8,894 and 8,250;
4.5 s to compile).
Derivatives: a custom JVP, ``exchange``'s JVP, carries every derivative. Batched by ``jax.vmap``
(a gradient or a JVP of a batched loss) it has a vmap rule of its own: the same chunks, in a
``lax.scan`` that reverse mode runs backwards, each chunk computed again in the reverse pass
rather than keeping the whole batch's intermediate values (``_jvp_in_chunks``). The derivatives
are those of the whole-batch program, to rounding (about 1e-13 relative).

The friction-cone limit, written without dividing by N_c or |T_c|
----------------------------------------------------------------------
MODEL.md step 5 takes d(s*) = n + s* T_c / N_c with s* = min(1, mu N_c / |T_c|), and
d = n + mu t when N_c <= 0. Both cases are one formula:

    d = n + mu T_c / M,   M = max(mu max(N_c, 0), |T_c|)

(M = mu N_c gives d = J_c / N_c, the stick impulse; M = |T_c| gives n + mu t, sliding on the
cone). The smooth mode (``smoothing`` tau > 0) replaces the max by the p-norm
M_tau = (a^p + b^p)^(1/p), p = 1/tau, which is the smooth minimum s*_tau = ((1)^-p + (mu N_c/|T_c|)^-p)^(-1/p)
of the model. It never leaves the cone (M_tau >= M, so |T| <= mu N) and
M <= M_tau <= 2^tau M: s* moves by at most a factor 2^-tau, so |J_tau - J_0| <= C tau |J_0|, where
C = ln 2 * s |dJ/ds| / |J| depends on mu and K, and has no bound of its own: it grows with
n.K.n / n.K.d(1). Measured at the cone boundary: 1.73 for a planar pair of cars at mu = 1.13 (tau 1e-3
and 1e-2), 6.2 at mu = 3.7 (tests/test_gradients.py); an independent check found 12.1 for a 3D pair
with full inertia tensors at mu = 1.10. Near grazing it is far larger: over 190 random 3D pairs pushed
to the cone boundary, one with u_n = -0.0075 m/s of |u| = 32 m/s gave C = 96 at tau = 1e-2, 732 at 1e-3
(|J_tau - J_0| = 0.73 |J_0|) and 2.1e3 at 1e-4; the next worst 56 and 15.
``sliding`` always reports the exact criterion |T_c| > mu N_c.
"""

from __future__ import annotations

import functools
import operator
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from . import derived
from . import linalg as la
from .types import (
    INVALID_BOX_1,
    INVALID_BOX_2,
    INVALID_FRICTION,
    INVALID_INERTIA_1,
    INVALID_INERTIA_2,
    INVALID_MASS_1,
    INVALID_MASS_2,
    INVALID_NONFINITE,
    INVALID_NORMAL,
    INVALID_OVERFLOW,
    INVALID_PENETRATION_TIME,
    INVALID_RESTITUTION,
    INVALID_SMOOTHING,
    OK,
    SEPARATING,
    Contact,
    ExchangeResult,
    State,
    Vehicle,
)


def inverse_inertia_world(inertia, yaw, pitch, roll, trig=None):
    """I^-1 in the global frame, R I_body^-1 R^T, and R. Closed form, no LAPACK.
    ``trig``: ``linalg.trig(yaw, pitch, roll)`` if the caller already has it."""
    trig = la.trig(yaw, pitch, roll) if trig is None else trig
    return _world_inverse(jnp.asarray(inertia), tuple(trig))


def _times_body_c(a, m):
    """a M (components): M as rows of components, or a (3,) array, the diagonal of M (each column
    of a scaled: XLA would compute every product by the zeros of a diagonal matrix, NaN * 0 being
    NaN)."""
    if isinstance(m, (tuple, list)):
        return la.matmul_c(a, m)
    d = la.vec(m)
    return tuple(tuple(row[j] * d[j] for j in range(3)) for row in la.mat(a))


def _body_inverse(inertia):
    """I_body^-1: rows of components from a (3, 3) inertia; from the principal moments (3,), the (3,)
    array of its diagonal (for ``_times_body_c``)."""
    if inertia.ndim == 1:
        return 1.0 / inertia
    det = la.det3(inertia)
    return tuple(tuple(c / det for c in row) for row in la.adjugate_c(inertia))


def _world_inverse_c(inertia, trig):
    """(R M R^T, R) as rows of components, M = I_body^-1, R from the six sines/cosines."""
    rot = la.rotation_c(*trig)
    return la.matmul_c(_times_body_c(rot, _body_inverse(jnp.asarray(inertia))), rot, transpose_b=True), rot


@jax.custom_jvp
def _world_inverse(inertia, trig):
    """``_world_inverse_c`` as (3, 3) arrays, with a hand-written derivative."""
    world, rot = _world_inverse_c(inertia, trig)
    return la.from_rows(world), la.from_rows(rot)


@_world_inverse.defjvp
def _world_inverse_jvp(primals, tangents):
    """With W = R M (M = I_body^-1): d(R M R^T) = P + P^T - W dI W^T, P = dR W^T (dM = -M dI M; a
    diagonal inertia gives dI = diag(d)). Autodiff of the forward gives the same derivative through
    the adjugate, the determinant and every intermediate 3x3 array; batched, its backward pass
    assembled those arrays in XLA concatenate loops that recompute shared products for each entry
    (benchmarks/RESULTS.md). Here each entry of the cotangents is a short sum of its own."""
    inertia, trig = primals
    d_inertia, d_trig = tangents
    rot, d_rot = jax.jvp(la.rotation_c, tuple(trig), tuple(d_trig))
    w = _times_body_c(rot, _body_inverse(inertia))
    world = la.matmul_c(w, rot, transpose_b=True)
    p = la.matmul_c(d_rot, w, transpose_b=True)
    q = la.matmul_c(_times_body_c(w, d_inertia if inertia.ndim == 1 else la.mat(d_inertia)), w, transpose_b=True)
    d_world = tuple(tuple(p[i][j] + p[j][i] - q[i][j] for j in range(3)) for i in range(3))
    return (la.from_rows(world), la.from_rows(rot)), (la.from_rows(d_world), la.from_rows(d_rot))


def _components(x):
    """The scalar components of a (), (3,) or (3, 3) leaf."""
    x = jnp.asarray(x)
    if x.ndim == 0:
        return (x,)
    if x.ndim == 1:
        return la.vec(x)
    return tuple(c for row in la.mat(x) for c in row)


def _all(flags):
    return functools.reduce(operator.and_, flags)


def _inertia_ok(inertia):
    # element by element, no reductions: XLA's CPU reductions over a few components per row
    # are several times slower than the same checks written out
    inertia = jnp.asarray(inertia)
    if inertia.ndim == 1:
        return _all([c > 0 for c in la.vec(inertia)])
    m = la.mat(inertia)
    scale = jnp.abs(m[0][0])
    for row in m:
        for c in row:
            scale = jnp.maximum(scale, jnp.abs(c))
    symmetric = _all([jnp.abs(m[i][j] - m[j][i]) <= 1e-6 * scale for i, j in ((0, 1), (0, 2), (1, 2))])
    minor1 = m[0][0]
    minor2 = m[0][0] * m[1][1] - m[0][1] * m[1][0]
    return symmetric & (minor1 > 0) & (minor2 > 0) & (la.det3(m) > 0)


def input_status(vehicle1, state1, vehicle2, state2, contact):
    """() int32: OK, or the first rule an input breaks (codes in ``ks_jax.types``)."""
    leaves = jax.tree_util.tree_leaves((vehicle1, state1, vehicle2, state2, contact))
    finite = _all([jnp.isfinite(c) for x in leaves for c in _components(x)])

    def box_ok(v):  # the CG inside the box, as case files require (a swept cg_to_front may leave it)
        return ((v.length > 0) & (v.width > 0) & (v.height > 0) & (v.cg_to_front >= 0) & (v.cg_to_front <= v.length)
                & (v.cg_height >= 0) & (v.cg_height <= v.height))

    checks = [
        (finite, INVALID_NONFINITE),
        (vehicle1.mass > 0, INVALID_MASS_1),
        (vehicle2.mass > 0, INVALID_MASS_2),
        (_inertia_ok(vehicle1.inertia), INVALID_INERTIA_1),
        (_inertia_ok(vehicle2.inertia), INVALID_INERTIA_2),
        (box_ok(vehicle1), INVALID_BOX_1),
        (box_ok(vehicle2), INVALID_BOX_2),
        ((contact.restitution >= -1) & (contact.restitution <= 1), INVALID_RESTITUTION),
        (contact.friction >= 0, INVALID_FRICTION),
        (la.dot(contact.normal, contact.normal) > 0, INVALID_NORMAL),
        (contact.penetration_time >= 0, INVALID_PENETRATION_TIME),
    ]
    code = jnp.int32(OK)
    for ok, bad in reversed(checks):  # the first failing rule wins
        code = jnp.where(ok, code, jnp.int32(bad))
    return code


def _benign(tree, ok):
    """Replace every leaf by a harmless value where ``ok`` is False (no NaN can leak into
    values or gradients of a bad row)."""
    vehicle1, state1, vehicle2, state2, contact = tree

    # stand-ins of the inputs' dtypes (a float64 constant would promote float32 inputs under x64)
    def veh(v):
        inertia = jnp.ones_like(v.inertia) if v.inertia.ndim == 1 else jnp.eye(3, dtype=jnp.result_type(v.inertia))
        good = Vehicle(1.0, inertia, 4.0, 2.0, 1.5, 2.0, 0.5)
        return jax.tree_util.tree_map(lambda x, g: jnp.where(ok, x, g), v, good)

    def st(s):
        return jax.tree_util.tree_map(lambda x: jnp.where(ok, x, jnp.zeros_like(x)), s)

    normal = jnp.asarray(contact.normal)
    good_contact = Contact(jnp.zeros_like(contact.point), jnp.array([1.0, 0.0, 0.0], dtype=normal.dtype), 0.0, 0.0, 0.0)
    contact = jax.tree_util.tree_map(lambda x, g: jnp.where(ok, x, g), contact, good_contact)
    return veh(vehicle1), st(state1), veh(vehicle2), st(state2), contact


def _cone_scale(a, b, smoothing):
    """M = max(a, b) (smoothing == 0) or the p-norm (a^p + b^p)^(1/p), p = 1/smoothing.
    a, b >= 0. Finite gradients everywhere, including a = b and a = b = 0."""
    hard = jnp.maximum(a, b)
    if isinstance(smoothing, (int, float)) and smoothing == 0:
        return hard
    tau = jnp.asarray(smoothing)
    p = 1.0 / jnp.where(tau > 0, tau, 1.0)
    hi, lo = hard, jnp.minimum(a, b)
    ratio = la.safe_div(lo, hi)
    smooth = hi * jnp.exp(jnp.log1p(ratio**p) / p)
    return jnp.where(tau > 0, smooth, hard)


def _rounding(n_c, t_norm):
    """How far |T_c| may be rounded off mu N_c (the sticking bound) where the two are equal: ``sliding``
    needs |T_c| above mu N_c by more. Else the flag of a contact with no tangential part, such as an
    inline crash at mu = 0 (|T_c| = mu N_c = 0), was decided by rounding and differed between programs
    (a case solved alone and in a batch)."""
    return derived.ROUNDING * jnp.finfo(t_norm.dtype).eps * (jnp.abs(n_c) + t_norm)


def impulse(K, u, n, restitution, friction, smoothing=0.0):
    """The KS impulse on vehicle 1 (MODEL.md section 3, steps 3-6).

    K: (3, 3) SPD, u: (3,) relative velocity at P, n: (3,) unit normal.
    Returns (J (3,), sliding (), approaching (), size (), ratio ()): J = 0 when u.n >= 0;
    J = size (n + T / N) with size = (1 + eps) N >= 0 and ratio = |T| / N (``ImpulseStage``).
    """
    un = la.dot(n, u)
    approaching = un < 0
    j_stick = -la.matvec(la.adjugate3(K), u) / la.det3(K)
    n_c = la.dot(n, j_stick)
    t_c = j_stick - n_c * n
    t_norm = la.safe_norm(t_c)
    a = friction * jnp.maximum(n_c, 0.0)
    m = _cone_scale(a, t_norm, smoothing)
    d = n + la.safe_div(friction, m) * t_c
    denom = la.dot(n, la.matvec(K, d))
    normal = jnp.where(approaching, -un / jnp.where(approaching, denom, 1.0), 0.0)
    size = (1.0 + restitution) * normal
    j = size * d
    sliding = approaching & (t_norm > a + _rounding(n_c, t_norm))
    return j, sliding, approaching, size, la.safe_div(friction, m) * t_norm


def _impulse_c(K, u, n, restitution, friction, smoothing):
    """``impulse``, step for step, on components: K as rows, u and n as 3-tuples; J as a 3-tuple.
    For values only (``impulse_stage(for_gradients=False)``): differentiated on K's array, this
    form made value_and_grad of a batched loss 1.5x slower than ``impulse``, and on K's
    components 70x slower (benchmarks/RESULTS.md). tests/test_batch.py holds the two forms to the
    same values."""
    un = la.dot(n, u)
    approaching = un < 0
    det = la.det3(K)
    j_stick = tuple(-c / det for c in la.matvec_c(la.adjugate_c(K), u))
    n_c = la.dot(n, j_stick)
    t_c = tuple(js - n_c * nk for js, nk in zip(j_stick, n))
    t_norm = la.safe_norm(t_c)
    a = friction * jnp.maximum(n_c, 0.0)
    m = _cone_scale(a, t_norm, smoothing)
    f = la.safe_div(friction, m)
    d = tuple(nk + f * tk for nk, tk in zip(n, t_c))
    denom = la.dot(n, la.matvec_c(K, d))
    normal = jnp.where(approaching, -un / jnp.where(approaching, denom, 1.0), 0.0)
    size = (1.0 + restitution) * normal
    j = tuple(size * dk for dk in d)
    sliding = approaching & (t_norm > a + _rounding(n_c, t_norm))
    return j, sliding, approaching, size, f * t_norm


def _arm_c(r, a):
    """-[r]x A [r]x (rows of components) for r (3,) and A (3, 3)."""
    # cross products, not products with the matrix [r]x: XLA computes every x * 0 (NaN * 0 is NaN).
    # The columns of B = [r]x A are r x (columns of A); the rows of B [r]x^T are r x (rows of B).
    r = la.vec(r)
    b_columns = [la.cross_c(r, column) for column in la.transpose_c(a)]
    return tuple(la.cross_c(r, row) for row in zip(*b_columns))


def collision_matrix(mass1, inv_inertia1, r1, mass2, inv_inertia2, r2):
    """K = (1/m1 + 1/m2) Id - [r1]x I1^-1 [r1]x - [r2]x I2^-1 [r2]x (MODEL.md section 3, step 2)."""
    eye = jnp.eye(3, dtype=r1.dtype)
    return ((1.0 / mass1 + 1.0 / mass2) * eye + la.from_rows(_arm_c(r1, inv_inertia1))
            + la.from_rows(_arm_c(r2, inv_inertia2)))


def _collision_matrix_c(mass1, inv_inertia1, r1, mass2, inv_inertia2, r2):
    """``collision_matrix`` as rows of components."""
    s = 1.0 / mass1 + 1.0 / mass2
    b1, b2 = _arm_c(r1, inv_inertia1), _arm_c(r2, inv_inertia2)
    return tuple(tuple(b1[i][k] + b2[i][k] + (s if i == k else 0.0) for k in range(3)) for i in range(3))


def exchange(vehicle1: Vehicle, state1: State, vehicle2: Vehicle, state2: State, contact: Contact,
             smoothing=0.0) -> ExchangeResult:
    """One KS impulse exchange at an explicit contact (MODEL.md sections 3 and 4).

    Pure and unbatched; works under ``jax.jit``, ``jax.vmap`` and ``jax.grad``.
    ``smoothing`` tau >= 0 (dimensionless, < 1): 0 is the exact model; tau > 0 the smooth
    friction-cone limit, O(tau) from it. A row whose inputs break a rule gets that rule's status
    code and NaN in every numeric result; it never affects other rows. (An overflow, INVALID_OVERFLOW,
    is found from results that are not finite: the row's status says so, its other numbers are left as
    computed, and so are its derivatives: they are NaN, and so is the gradient of any parameter the row
    shares with others, however a loss masks the row. Leave such rows out of a batch that is
    differentiated.)
    How the smoothing works and what ``jax.vmap`` of this function does on a CPU are written in the
    docstring of the module ``ks_jax.exchange`` (``ks_jax.exchange`` itself names this function:
    ``help(sys.modules["ks_jax.exchange"])``).
    """
    args = (vehicle1, state1, vehicle2, state2, contact)
    traced = any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(args))
    if not traced or isinstance(smoothing, jax.core.Tracer):  # eager (4x slower through the rule), or a traced tau
        return _exchange(vehicle1, state1, vehicle2, state2, contact, smoothing)
    return _vmappable(float(smoothing))(vehicle1, state1, vehicle2, state2, contact)


def _exchange(vehicle1, state1, vehicle2, state2, contact, smoothing):
    """``exchange`` as written: every transformation sees these operations. A ``smoothing`` that is
    an array (traced under jit, or a JAX scalar) is checked per row: out of [0, 1), status
    INVALID_SMOOTHING (a Python number is checked, and refused, by ``impulse_stage``)."""
    status = input_status(vehicle1, state1, vehicle2, state2, contact)
    if not isinstance(smoothing, (int, float)):
        tau_ok = (smoothing >= 0) & (smoothing < 1)  # NaN fails
        status = jnp.where((status == OK) & ~tau_ok, jnp.int32(INVALID_SMOOTHING), status)
    return exchange_with_status(vehicle1, state1, vehicle2, state2, contact, smoothing, status)


@functools.lru_cache(maxsize=None)
def _vmappable(smoothing):
    """``exchange`` at a fixed tau: ``_exchange``, whose batching on one CPU device runs in chunks
    (module docstring): the values by ``_batched``, the derivatives by ``_batched_jvp``. Every
    derivative is that of ``_exchange`` (the custom JVP is its JVP, computed in chunks when the
    tangents are batched), so the values and derivatives are those of the whole-batch program."""
    plain = functools.partial(_exchange, smoothing=smoothing)
    values = jax.custom_batching.custom_vmap(plain)
    values.def_vmap(functools.partial(_batched, smoothing))
    jvp = jax.custom_batching.custom_vmap(functools.partial(_float_jvp, plain))
    jvp.def_vmap(functools.partial(_batched_jvp, smoothing))

    @jax.custom_jvp
    def vmappable(vehicle1, state1, vehicle2, state2, contact):
        return values(vehicle1, state1, vehicle2, state2, contact)

    @vmappable.defjvp
    def _(primals, tangents):
        if not any(_is_batched(t) for t in jax.tree_util.tree_leaves(tangents)):
            return jax.jvp(plain, primals, tangents)
        out, floats = jvp(primals, tangents)
        it = iter(floats)
        return out, jax.tree_util.tree_map(lambda o: next(it) if _is_float(o) else _float0(o), out)

    return vmappable


def _is_batched(tangent):
    """Whether a tangent is a ``jax.vmap`` tracer: then the rule above runs inside a vmap (the
    batch is the innermost transformation, as in ``grad(loss(vmap(exchange)))`` or ``jvp`` of a
    batch), and the JVP's batching is ``_batched_jvp``. Otherwise (say ``vmap(grad(...))``, where
    a row's JVP is transposed before it is batched) the JVP is the plain one. Either way the
    derivatives are the same; only their batching differs. (JAX does not export the tracer's
    class, so it is recognized by its name; tests/test_batch.py checks that a batched gradient
    takes the chunked path, so a JAX that renamed it would fail a test, not slow down unseen.)"""
    return type(tangent).__name__ == "BatchTracer"


def _is_float(x):
    return jnp.issubdtype(x.dtype, jnp.inexact)


def _float0(x):
    return np.zeros(x.shape, jax.dtypes.float0)


def _float_jvp(fn, primals, tangents):
    """``jax.jvp(fn)``: the outputs, and the tangents of the float outputs (a list)."""
    out, tangents_out = jax.jvp(fn, primals, tangents)
    return out, [t for t, o in zip(jax.tree_util.tree_leaves(tangents_out), jax.tree_util.tree_leaves(out))
                 if _is_float(o)]


# rows per chunk of a batched exchange on a CPU: a stage reads and writes about 1.5 kB per row, 24 MiB per
# chunk, within the benchmark machine's 32 MiB L3 (2048 to 65536 rows ran 0.70-1.03x as fast; benchmarks/RESULTS.md)
CHUNK_ROWS = 1 << 14


def _batched(smoothing, axis_size, in_batched, *args):
    """The vmap rule of ``_vmappable``'s values: leaves with ``in_batched`` True have the batch first."""
    return _in_chunks_or_whole(functools.partial(_exchange, smoothing=smoothing),
                               functools.partial(_in_chunks, smoothing), axis_size, in_batched, args)


def _batched_jvp(smoothing, axis_size, in_batched, primals, tangents):
    """The vmap rule of ``_vmappable``'s JVP (``_float_jvp`` of ``_exchange``)."""
    plain = functools.partial(_float_jvp, functools.partial(_exchange, smoothing=smoothing))
    if not any(jax.tree_util.tree_leaves(in_batched[0])):
        # only the tangents are batched (``jax.jacfwd`` of one exchange): the primal outputs are not
        axes = tuple(jax.tree_util.tree_map(lambda b: 0 if b else None, b) for b in in_batched)
        out, floats = jax.vmap(plain, in_axes=axes, out_axes=(None, 0))(primals, tangents)
        return (out, floats), (jax.tree_util.tree_map(lambda _: False, out), [True] * len(floats))
    return _in_chunks_or_whole(plain, functools.partial(_jvp_in_chunks, smoothing), axis_size, in_batched,
                               (primals, tangents))


def _in_chunks_or_whole(fn, in_chunks, n, in_batched, args):
    """``jax.vmap(fn)`` over the n rows of ``args``, computed by ``in_chunks(n, in_batched, axes, *args)``
    on one CPU device over more than CHUNK_ROWS rows."""
    axes = tuple(jax.tree_util.tree_map(lambda b: 0 if b else None, b) for b in in_batched)

    def whole(*args):
        return jax.vmap(fn, in_axes=axes)(*args)

    if n == 1:  # one row unbatched (module docstring)
        row = fn(*jax.tree_util.tree_map(lambda x, b: x[0] if b else x, args, tuple(in_batched)))
        out = jax.tree_util.tree_map(lambda x: x[None], row)
    elif n <= CHUNK_ROWS or jax.device_count() > 1:  # several devices: leave sharding to XLA
        out = whole(*args)
    else:
        chunks = functools.partial(in_chunks, n, tuple(in_batched), axes)
        out = platform_dependent(*args, cpu=chunks, default=whole)
    return out, jax.tree_util.tree_map(lambda _: True, out)


def _in_chunks(smoothing, n, in_batched, axes, *args):
    """``_exchange`` over the n rows of ``args`` in chunks of CHUNK_ROWS, inside one loop, each
    chunk in the three stages of ``exchange_batch``, each stage fenced off (``_fenced``) as a
    separate jitted call would be; the last chunk ends at row n (it recomputes rows of the one
    before, which get the same values)."""
    size = CHUNK_ROWS

    vmapped = functools.partial(_vmapped, axes)

    def cut_and_prepare(args, start):  # the chunk's rows, cut out of the batch once
        rows = jax.tree_util.tree_map(
            lambda x, b: jax.lax.dynamic_slice_in_dim(x, start, size, 0) if b else x, args, in_batched)
        return rows, vmapped(prepare)(*rows)

    def impulse_(rows, status, trig):
        return vmapped(values_impulse_stage(smoothing), 0, 0)(*rows, status, trig)

    def results(rows, status, stage):
        return vmapped(results_stage, 0, 0)(*rows, status, stage)

    def chunk(i):
        start = jnp.minimum(i * size, n - size)
        fenced = functools.partial(_fenced, i >= 0)  # true, but not to XLA
        rows, (status, trig) = fenced(cut_and_prepare, args, start)
        return start, fenced(results, rows, status, fenced(impulse_, rows, status, trig))

    def step(i, out):
        start, result = chunk(i)
        return jax.tree_util.tree_map(lambda o, x: jax.lax.dynamic_update_slice_in_dim(o, x, start, 0),
                                      out, result)

    row = jax.tree_util.tree_map(lambda x, b: jax.ShapeDtypeStruct(x.shape[1:] if b else x.shape, x.dtype), args, in_batched)
    shapes = _row_shapes(smoothing, tuple(row))
    out = jax.tree_util.tree_map(lambda s: jnp.zeros((n,) + s.shape, s.dtype), shapes)
    return jax.lax.fori_loop(0, -(-n // size), step, out)


@functools.lru_cache(maxsize=64)
def _row_shapes(smoothing, row):
    """The shapes and dtypes of ``_exchange``'s results for one row of the given shapes and dtypes:
    those of a chunk's rows, known without tracing the chunk's three stages once more."""
    return jax.eval_shape(functools.partial(_exchange, smoothing=smoothing), *row)


def _vmapped(axes, fn, *extra):
    """``jax.vmap(fn)`` over a chunk's rows (``axes``: 0 or None per leaf of the five inputs), with
    one batched argument after them for each of ``extra``."""
    return jax.vmap(fn, in_axes=axes + (0,) * len(extra))


def _fenced(pred, fn, *operands):
    """``fn(*operands)`` as the taken branch of ``lax.cond(pred, ...)``, ``pred`` true at run time.

    XLA compiles a conditional's branches as computations of their own and fuses nothing across
    their boundary, so the branch's outputs are computed in loops of their own and stored, as the
    outputs of a separate jitted call are. Without the fences, one program fuses the stages
    together: with the outputs of each stage stored by ``linalg.materialize`` instead, the chunked
    loop took 1.3-1.8x the time per row (benchmarks/RESULTS.md). The other branch returns
    zeros and never runs. It takes the shapes of the zeros from ``fn``'s outputs as ``lax.cond``
    traced them (it traces the true branch first), so that ``fn`` is traced once, not twice."""
    traced = []

    def taken(*operands):
        out = fn(*operands)
        traced.append(jax.tree_util.tree_map(lambda x: jax.ShapeDtypeStruct(jnp.shape(x), jnp.result_type(x)), out))
        return out

    def skipped(*operands):
        # a JAX that traced the false branch first: ``fn`` traced here too
        shapes = traced[-1] if traced else jax.eval_shape(fn, *operands)
        return jax.tree_util.tree_map(lambda s: jnp.zeros(s.shape, s.dtype), shapes)

    return jax.lax.cond(pred, taken, skipped, *operands)


def fence(fn, *operands):
    """``fn(*operands)``, on a CPU fenced off (``_fenced``) from what reads its outputs, where no loop
    index is at hand: the predicate is True passed through ``lax.optimization_barrier``, which XLA does
    not see through. Elsewhere (a GPU) it is ``fn(*operands)``: no conditional, no predicate to read."""
    def fenced(*operands):
        return _fenced(jax.lax.optimization_barrier(jnp.bool_(True)), fn, *operands)

    return platform_dependent(*operands, cpu=fenced, default=fn)


def platform_dependent(*args, cpu, default):
    """``jax.lax.platform_dependent(*args, cpu=cpu, default=default)``, which traces both branches,
    except where JAX's default backend is a CPU: there only ``cpu`` is traced. Both branches compute
    the same values (the CPU one in a form that is faster on a CPU), so a program lowered for another
    platform than the default still computes them. Tracing the other branch too took most of the
    trace time of a batched gradient: nested, as in ``sum_over_rows`` of ``jax.vmap(exchange)``, the
    branches multiply (benchmarks/RESULTS.md)."""
    if jax.default_backend() == "cpu":
        return cpu(*args)
    return jax.lax.platform_dependent(*args, cpu=cpu, default=default)


def _jvp_in_chunks(smoothing, n, in_batched, axes, primals, tangents):
    """``_float_jvp`` of ``_exchange`` over n rows: a ``lax.scan`` over chunks of CHUNK_ROWS rows,
    each in the three stages of ``exchange_with_status`` (``prepare``, ``impulse_stage``,
    ``results_stage``), each stage's JVP fenced off (``_fenced``) as in ``_in_chunks``.

    Reverse mode transposes it into a scan over the chunks in reverse. The body is a
    ``jax.checkpoint``: the reverse pass computes each chunk's forward again instead of keeping
    the whole batch's intermediate values (at 2^20 rows, XLA's temporaries for the gradient of a
    batched loss went from 1033-1685 MiB to 46-164 MiB; benchmarks/RESULTS.md). The rows are scanned
    over, not cut out of the batch inside a loop: the transpose of a cut is a batch-sized array
    per chunk. A batch that is not a multiple of CHUNK_ROWS is padded with copies of its last row."""
    size, axes = CHUNK_ROWS, axes[0]  # the vmap axes of the primals (0 or None per leaf)
    vmapped = functools.partial(_vmapped, axes)
    count = -(-n // size)
    leaves, treedef = jax.tree_util.tree_flatten((primals, tangents))
    batched = jax.tree_util.tree_leaves(in_batched)

    def body(i, rows_of_batched):
        fenced = functools.partial(_fenced, i >= 0)  # true, but not to XLA
        it = iter(rows_of_batched)
        rows, d_rows = jax.tree_util.tree_unflatten(treedef, [next(it) if b else x for x, b in zip(leaves, batched)])

        def prepare_(rows, d_rows):
            (status, trig), (_, d_trig) = jax.jvp(lambda r: vmapped(prepare)(*r), (rows,), (d_rows,))
            return status, trig, d_trig

        status, trig, d_trig = fenced(prepare_, rows, d_rows)

        def impulse_(rows, d_rows, trig, d_trig):
            def floats(r, t):  # the stage's floats; its flags (sliding, approaching) have no tangents
                stage = vmapped(lambda *a: impulse_stage(*a[:5], smoothing, a[5], a[6]), 0, 0)(*r, status, t)
                return stage._replace(sliding=None, approaching=None), (stage.sliding, stage.approaching)

            return jax.jvp(floats, (rows, trig), (d_rows, d_trig), has_aux=True)

        stage, d_stage, flags = fenced(impulse_, rows, d_rows, trig, d_trig)

        def results_(rows, d_rows, stage, d_stage):
            def results(r, s):
                return vmapped(results_stage, 0, 0)(*r, status, s._replace(sliding=flags[0], approaching=flags[1]))

            return _float_jvp(results, (rows, stage), (d_rows, d_stage))

        return i + 1, fenced(results_, rows, d_rows, stage, d_stage)

    _, out = jax.lax.scan(jax.checkpoint(body), jnp.int32(0), [as_chunks(x, count, size) for x, b in zip(leaves, batched) if b])
    return jax.tree_util.tree_map(lambda y: y.reshape((count * size,) + y.shape[2:])[:n], out)


def as_chunks(x, count, size):
    """The rows of ``x`` as (count, size, ...): ``count`` chunks of ``size`` rows, the last one padded
    with copies of the last row."""
    pad = count * size - x.shape[0]
    if pad:
        x = jnp.concatenate([x, jnp.broadcast_to(x[-1:], (pad,) + x.shape[1:])])
    return x.reshape((count, size) + x.shape[1:])


def prepare(vehicle1, state1, vehicle2, state2, contact):
    """(status, trig): ``input_status`` and, for both vehicles, ``linalg.trig`` of the angles
    the exchange uses (those of ``_benign``: 0 in a row with invalid inputs).

    Batched callers run this in its own jitted call and hand both to the next stages
    (``impulse_stage``, ``exchange_with_status``): the status and the twelve sines/cosines are
    stored once per row.
    """
    status = input_status(vehicle1, state1, vehicle2, state2, contact)
    ok = status == OK

    def tr(s):
        return la.trig(*(jnp.where(ok, a, jnp.zeros_like(a)) for a in (s.yaw, s.pitch, s.roll)))

    return status, (tr(state1), tr(state2))


def exchange_with_status(vehicle1, state1, vehicle2, state2, contact, smoothing, status, trig=None) -> ExchangeResult:
    """``exchange`` given ``input_status`` of the same inputs (() int32), computed elsewhere
    (a batched caller may compute the status in its own jitted call and store it once).
    ``trig``: the second result of ``prepare`` (optional; computed here if None)."""
    impulse_ = impulse_stage(vehicle1, state1, vehicle2, state2, contact, smoothing, status, trig)
    return results_stage(vehicle1, state1, vehicle2, state2, contact, status, impulse_)


class ImpulseStage(NamedTuple):
    """What ``results_stage`` needs from ``impulse_stage``: J on vehicle 1, sliding, approaching,
    size and ratio, n, u, I^-1 and R of both vehicles, r_i = P - x_i. Vectors as 3-tuples and
    matrices as rows of 3-tuples (``linalg.vec``/``linalg.mat``).

    J = size (n + T / N): size = (1 + eps) N, ratio = |T| / N. A norm's derivative at 0 is 0,
    where |J| at eps = -1 and |J_t| at mu = 0 have the one-sided derivatives (1 + eps) and mu times
    their factors (d|J|/deps = |J_c(s*)|, d|J_t|/dmu = (1 + eps) N). So |J_t| = size ratio, and |J|
    is the norm of J plus a term of value 0 whose derivative where size = 0 is
    sqrt(1 + ratio^2) d(size) (``derived.results``)."""

    j: tuple
    sliding: jnp.ndarray
    approaching: jnp.ndarray
    size: jnp.ndarray
    ratio: jnp.ndarray
    n: tuple
    u: tuple
    a1: tuple
    rot1: tuple
    a2: tuple
    rot2: tuple
    r1: tuple
    r2: tuple


def impulse_stage(vehicle1, state1, vehicle2, state2, contact, smoothing, status, trig=None,
                  for_gradients=True) -> ImpulseStage:
    """MODEL.md section 3, steps 1-6: the impulse and what the results are derived from.

    ``exchange_with_status`` is ``results_stage(impulse_stage(...))``. A batched caller on CPU
    may run the two stages as separate jitted calls: the ~60 numbers of ``ImpulseStage`` are then
    stored once per row instead of being re-derived inside every loop XLA's fusion makes of the
    ~40 results (half the time per row at cache-sized chunks; benchmarks/RESULTS.md).

    ``for_gradients``: the same values either way. True (the default) passes the world inverse
    inertias, R and K between the steps as (3, 3) arrays; XLA's backward pass needs those
    boundaries (``_impulse_c`` says what components cost there). The stage path of ``sweep`` and
    ``exchange_batch`` computes values only and passes False: the same algebra in components,
    about 10% faster there (benchmarks/RESULTS.md)."""
    if isinstance(smoothing, (int, float)) and not 0.0 <= smoothing < 1.0:
        raise ValueError(f"smoothing = {smoothing}: smoothing must be in [0, 1)")
    ok = status == OK
    vehicle1, state1, vehicle2, state2, contact = _benign((vehicle1, state1, vehicle2, state2, contact), ok)

    # |normal| > 0 here (INVALID_NORMAL, _benign). A sum, not la.safe_norm: XLA copied the expression of
    # sqrt(max(n.n, tiny)) into every loop that reads n, and the batched exchange became 7x the
    # instructions of one row's, 15 us per row instead of 0.4-0.5 (2026-11-25; tests/test_batch.py)
    n = contact.normal / jnp.sqrt(jnp.sum(contact.normal * contact.normal))
    p = contact.point
    trig1, trig2 = (None, None) if trig is None else trig
    if for_gradients:
        a1, rot1 = inverse_inertia_world(vehicle1.inertia, state1.yaw, state1.pitch, state1.roll, trig1)
        a2, rot2 = inverse_inertia_world(vehicle2.inertia, state2.yaw, state2.pitch, state2.roll, trig2)
    else:
        trig1 = la.trig(state1.yaw, state1.pitch, state1.roll) if trig1 is None else trig1
        trig2 = la.trig(state2.yaw, state2.pitch, state2.roll) if trig2 is None else trig2
        a1, rot1 = _world_inverse_c(vehicle1.inertia, tuple(trig1))
        a2, rot2 = _world_inverse_c(vehicle2.inertia, tuple(trig2))
    r1 = p - state1.position
    r2 = p - state2.position
    u = (state1.velocity + la.cross(state1.angular_velocity, r1)) - (
        state2.velocity + la.cross(state2.angular_velocity, r2)
    )
    if for_gradients:
        K = collision_matrix(vehicle1.mass, a1, r1, vehicle2.mass, a2, r2)
        j, sliding, approaching, size, ratio = impulse(K, u, n, contact.restitution, contact.friction, smoothing)
    else:
        K = _collision_matrix_c(vehicle1.mass, a1, r1, vehicle2.mass, a2, r2)
        j, sliding, approaching, size, ratio = _impulse_c(K, la.vec(u), la.vec(n), contact.restitution,
                                                          contact.friction, smoothing)
    # components, not (3,) and (3, 3) arrays: stored by a batched caller as one array each, with no
    # concatenate loop to assemble them (XLA's CPU concatenate loops are slow on long expressions)
    return ImpulseStage(la.vec(j), sliding, approaching, size, ratio, la.vec(n), la.vec(u), la.mat(a1), la.mat(rot1),
                        la.mat(a2), la.mat(rot2), la.vec(r1), la.vec(r2))


def values_impulse_stage(smoothing):
    """``impulse_stage`` for values only (``for_gradients=False``) at a fixed tau, called as
    ``(vehicle1, state1, vehicle2, state2, contact, status, trig)``: the stage that the chunked
    batch paths (``exchange_batch``, ``exchange``'s vmap rule) vmap between ``prepare`` and
    ``results_stage``."""
    return lambda *a: impulse_stage(*a[:5], smoothing, *a[5:], for_gradients=False)


def results_stage(vehicle1, state1, vehicle2, state2, contact, status, stage: ImpulseStage) -> ExchangeResult:
    """MODEL.md section 4 from ``impulse_stage``'s output (same inputs and status). Finite inputs
    far too large (e.g. a speed of 1e300 m/s), where |J|^2, |u|^2 or m |v|^2 overflows, get status
    INVALID_OVERFLOW, never a silent NaN under "ok" or "separating". Their other results are left as
    computed (some infinite or NaN): masking them all by such a check made XLA recompute it in every
    output's loop, 1.3x the time per row (benchmarks/RESULTS.md), for rows no real case reaches."""
    ok = status == OK
    vehicle1, state1, vehicle2, state2, contact = _benign((vehicle1, state1, vehicle2, state2, contact), ok)
    status = jnp.where(ok & ~stage.approaching, jnp.int32(SEPARATING), status)
    arr, rows = la.array, la.from_rows  # back to (3,) and (3, 3) arrays for derived.results
    stage = stage._replace(j=arr(stage.j), n=arr(stage.n), u=arr(stage.u), a1=rows(stage.a1), rot1=rows(stage.rot1),
                           a2=rows(stage.a2), rot2=rows(stage.rot2), r1=arr(stage.r1), r2=arr(stage.r2))
    result = derived.results(
        stage.j, (stage.size, stage.ratio), stage.n, contact.point, stage.u, stage.sliding, status,
        (vehicle1, state1, stage.rot1, stage.a1, stage.r1),
        (vehicle2, state2, stage.rot2, stage.a2, stage.r2),
    )
    # from what every result reads anyway (J, u, the velocities and masses): an energy check would make a
    # loss that masks by the status compute the energy loss too (1.1-1.2x its forward; RESULTS.md)
    j, u = stage.j, stage.u
    scale = la.dot(j, j) + la.dot(u, u) + vehicle1.mass * la.dot(state1.velocity, state1.velocity) + \
        vehicle2.mass * la.dot(state2.velocity, state2.velocity)
    finite = jnp.isfinite(scale)
    status = jnp.where(ok & ~finite, jnp.int32(INVALID_OVERFLOW), result.contact.status)
    result = result._replace(contact=result.contact._replace(status=status))
    return derived.mask_invalid(result, ok)
