"""Gradients of the exchange (docs/model.md, "The impulse exchange", smooth mode): against central finite
differences in every continuous input, an analytic head-on derivative, finiteness at the
singular points in both modes, and the smooth -> exact limit.

All gradients come from one jitted, vmapped ``value_and_grad`` (conftest ``kit.value_and_grad``)
of a weighted sum of the result scalars listed in conftest ``OUTPUTS``; finite differences use
its values, so the whole file costs one compilation per inertia shape.
"""

from __future__ import annotations

import copy
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import ks_jax
import reference as ref
from ks_jax.compilation import quick_jit
from samples import reference_jit
import kit

TAU = 0.05  # the smoothing used for "smooth mode"
MODES = (0.0, TAU)
H_REL = 1e-6  # finite-difference step, relative to max(1, |x|)
# |AD - FD| <= RTOL_FD |AD| + ATOL_FD * F / max(1, |x|), with F = sum_k |w_k y_k| the size of the
# weighted sum: the central-difference error (h^2 f''' + roundoff f / h) on that scale.
# Measured worst |AD - FD| / tolerance over this file: about 0.07.
RTOL_FD = 2e-7
ATOL_FD = 2e-9
RTOL_ANALYTIC = 1e-12


def _labels(args):
    """(label, leaf index, flat index) for every scalar input of the five input pytrees."""
    names = []
    for tree_name, tree in zip(("vehicle1", "state1", "vehicle2", "state2", "contact"), args):
        for field, leaf in zip(tree._fields, tree):
            size = int(np.size(leaf))
            for k in range(size):
                names.append(f"{tree_name}.{field}" + (f"[{k}]" if size > 1 else ""))
    out = []
    i = 0
    leaves = jax.tree_util.tree_leaves(args)
    for li, leaf in enumerate(leaves):
        for k in range(int(np.size(leaf))):
            out.append((names[i], li, k))
            i += 1
    return out


def _outputs(case, smoothing=0.0):
    """(N_OUTPUTS,) the differentiated result scalars of one case."""
    res = kit.batch_exchange(kit.inputs([case]), smoothing)
    return np.asarray(kit.output_vector(jax.tree_util.tree_map(lambda x: x[0], res)))


def _weights(case, rng, skip=()):
    """Random weights, each output normalised by its size in this case (so F is O(1) per output). An
    output that is 0 up to rounding (below 1e-12 of the largest; the tangential impulse head-on, where
    XLA's roundings leave ~1e-13 N s in some compiled programs and exactly 0 in others) is not: its
    rounding would be weighted by 1e12."""
    y = _outputs(case)
    w = np.zeros(kit.N_OUTPUTS)
    floor = 1e-12 * np.nanmax(np.abs(y))
    for name, _, _ in kit.OUTPUTS:
        sl = kit.OUTPUT_SLICES[name]
        if name in skip:
            continue
        scale = np.linalg.norm(y[sl])
        w[sl] = rng.normal(size=sl.stop - sl.start) / (scale if scale > floor else 1.0)
    return np.where(np.isfinite(y), w, 0.0)


def fd_check(case, smoothing, rng, forward=(), skip_outputs=()):
    """Compare AD with finite differences in every scalar input of ``case``; central differences,
    or second-order one-sided ones for the inputs named in ``forward`` (at a bound of their
    domain). Returns the worst |AD - FD| / tolerance."""
    args = kit.inputs(case)
    leaves, treedef = jax.tree_util.tree_flatten(args)
    leaves = [np.asarray(x) for x in leaves]
    labels = _labels(args)
    w = _weights(case, rng, skip_outputs)
    rows = [leaves]
    plan = []
    for label, li, k in labels:
        x = float(leaves[li].reshape(-1)[k])
        h = H_REL * max(1.0, abs(x))
        fwd = label in forward or label == "contact.penetration_time"  # >= 0: at its bound
        steps = (h, 2 * h) if fwd else (h, -h)
        idx = []
        for st in steps:
            new = [a.copy() for a in leaves]
            flat = new[li].reshape(-1)
            flat[k] = x + st
            new[li] = flat.reshape(leaves[li].shape)
            idx.append(len(rows))
            rows.append(new)
        plan.append((label, li, k, x, h, idx, fwd))
    batched = jax.tree_util.tree_unflatten(treedef, [np.stack([r[i] for r in rows]) for i in range(len(leaves))])
    values, grads = kit.value_and_grad(batched, np.tile(w, (len(rows), 1)), smoothing)
    ad_leaves = [np.asarray(g)[0] for g in jax.tree_util.tree_leaves(grads)]
    for g in ad_leaves:
        assert np.all(np.isfinite(g))
    # size of the weighted sum, for the absolute part of the tolerance
    y = _outputs(case, smoothing)
    f_scale = float(np.sum(np.abs(np.where(w != 0, w * np.nan_to_num(y), 0.0)))) + 1.0
    worst = 0.0
    for label, li, k, x, h, idx, fwd in plan:
        f0 = values[0]
        if fwd:
            fd = (-3 * f0 + 4 * values[idx[0]] - values[idx[1]]) / (2 * h)
        else:
            fd = (values[idx[0]] - values[idx[1]]) / (2 * h)
        ad = float(ad_leaves[li].reshape(-1)[k])
        tol = RTOL_FD * abs(ad) + ATOL_FD * f_scale / max(1.0, abs(x))
        if fwd:
            tol *= 100  # one-sided: O(h^2) with a larger constant
        ratio = abs(ad - fd) / tol
        assert ratio <= 1.0, f"{label}: AD {ad!r} vs FD {fd!r} (tolerance {tol:.3g}, smoothing {smoothing})"
        worst = max(worst, ratio)
    return worst


# --------------------------------------------------------------------------- special cases
def head_on(speed2=15.0, eps=0.3, mu=0.5):
    """Vehicle 1 heading +x at 10 m/s, vehicle 2 (yaw pi) coming at it along -x; P on the line of
    both CGs at CG height; n = -x (from 2 into 1). T_c = 0."""
    rng = np.random.default_rng(1)
    v1 = ref.random_vehicle(rng, tilt=0.0)
    v2 = ref.random_vehicle(rng, tilt=0.0)
    for v, yaw in ((v1, 0.0), (v2, np.pi)):
        v.update(yaw=yaw, pitch=0.0, roll=0.0, cg_height=0.55, angular_velocity=np.zeros(3))
    v1["position"] = np.array([0.0, 0.0, 0.55])
    v2["position"] = np.array([v1["cg_to_front"] + v2["cg_to_front"] - 0.3, 0.0, 0.55])
    v1["velocity"] = np.array([10.0, 0.0, 0.0])
    v2["velocity"] = np.array([-speed2, 0.0, 0.0])  # speed2 along its course, yaw pi
    p = np.array([v1["cg_to_front"] - 0.2, 0.0, 0.55])
    return {"vehicles": [v1, v2], "contact": dict(point=p, normal=np.array([-1.0, 0.0, 0.0]), restitution=eps,
                                                  friction=mu)}


def exact_cone_boundary():
    """Both CGs at P (r = 0), m1 = m2 = 2 kg: K = Id, J_c = -u = (4, -3, 0) exactly, N_c = 4,
    |T_c| = 3, and mu = 0.75 puts s* = mu N_c / |T_c| = 1 exactly, in binary floating point."""
    rng = np.random.default_rng(2)
    vs = []
    for vel in ([0.0, 0.0, 0.0], [4.0, -3.0, 0.0]):
        v = ref.random_vehicle(rng, tilt=0.0)
        v.update(mass=2.0, yaw=0.0, pitch=0.0, roll=0.0, position=np.array([1.0, 2.0, v["cg_height"]]),
                 velocity=np.array(vel), angular_velocity=np.zeros(3))
        vs.append(v)
    vs[1]["position"] = vs[0]["position"].copy()
    case = {"vehicles": vs, "contact": dict(point=vs[0]["position"].copy(), normal=np.array([1.0, 0.0, 0.0]),
                                            restitution=0.2, friction=0.75)}
    s = ref.stick_split(case)
    assert s["n_c"] == 4.0 and np.linalg.norm(s["t_c"]) == 3.0 and case["contact"]["friction"] * s["n_c"] == 3.0
    return case


def _margin(case):
    """Relative distance of the case from the cone boundary |T_c| = mu N_c."""
    s = ref.stick_split(case)
    t = np.linalg.norm(s["t_c"])
    return abs(t - case["contact"]["friction"] * max(s["n_c"], 0.0)) / t


@pytest.fixture(scope="module")
def generic_cases(random_cases):
    """One sticking, one sliding and one N_c <= 0 case, all away from the cone boundary."""
    picked = {}
    for c in random_cases["principal"]:
        branch = ref.solve(c)["_"]["branch"]
        if branch not in picked and _margin(c) > 1e-2:
            picked[branch] = c
    assert set(picked) == {"stick", "slide", "pull"}, set(picked)
    return picked


@pytest.mark.parametrize("smoothing", MODES)
@pytest.mark.parametrize("branch", ["stick", "slide", "pull"])
@pytest.mark.slow
def test_gradients_match_finite_differences(generic_cases, branch, smoothing):
    rng = np.random.default_rng({"stick": 1, "slide": 2, "pull": 3}[branch])
    fd_check(generic_cases[branch], smoothing, rng)


@pytest.mark.slow
@pytest.mark.parametrize("smoothing", MODES)
def test_gradients_match_finite_differences_inertia_tensor(random_cases, smoothing):
    """A full 3x3 body inertia tensor: every one of its nine entries is an input."""
    case = next(c for c in random_cases["full"] if ref.solve(c)["contact"]["sliding"] and _margin(c) > 1e-2)
    fd_check(case, smoothing, np.random.default_rng(9))


@pytest.mark.parametrize("smoothing", MODES)
@pytest.mark.slow
def test_gradients_at_head_on(smoothing):
    fd_check(head_on(), smoothing, np.random.default_rng(4))


@pytest.mark.parametrize("smoothing", MODES)
@pytest.mark.slow
def test_gradients_at_separating_contact(random_cases, smoothing):
    case = copy.deepcopy(random_cases["principal"][3])
    s = ref.stick_split(case)
    case["vehicles"][1]["velocity"] = case["vehicles"][1]["velocity"] + (s["n"] @ s["u"] - 2.0) * s["n"]
    assert ref.solve(case)["contact"]["status"] == "separating"
    fd_check(case, smoothing, np.random.default_rng(5))


@pytest.mark.parametrize("smoothing", MODES)
def test_gradients_at_zero_friction(random_cases, smoothing):
    """mu = 0 is the edge of its domain: one-sided differences in mu. |J_t| = 0 there, and its
    derivative in mu is the one-sided slope (1 + eps) N, not a norm's 0 at zero."""
    case = copy.deepcopy(random_cases["principal"][5])
    case["contact"]["friction"] = 0.0
    assert np.linalg.norm(ref.stick_split(case)["t_c"]) > 0  # sliding at mu = 0, so |J_t| grows with mu
    fd_check(case, smoothing, np.random.default_rng(6), forward=("contact.friction",))


def test_gradients_on_the_cone_boundary_smooth_mode():
    """The smooth mode is C1 across the boundary, so finite differences apply there."""
    fd_check(exact_cone_boundary(), TAU, np.random.default_rng(7))


@pytest.mark.parametrize("kind", ["principal", "full"])
@pytest.mark.slow
def test_gradients_where_the_smooth_minimum_blends(random_cases, kind):
    """mu 2 % above the cone boundary: with p = 1/tau = 20 the smooth minimum differs from the
    hard one by a factor (1 + 0.98^20)^(1/20), so both of its arguments carry gradient."""
    case = copy.deepcopy(next(c for c in random_cases[kind] if ref.stick_split(c)["n_c"] > 0))
    s = ref.stick_split(case)
    case["contact"]["friction"] = 1.02 * float(np.linalg.norm(s["t_c"]) / s["n_c"])
    fd_check(case, TAU, np.random.default_rng(10))


def _all_output_grads(cases, smoothing):
    rng = np.random.default_rng(8)
    weights = rng.normal(size=(len(cases), kit.N_OUTPUTS))
    return kit.value_and_grad(kit.inputs(cases), weights, smoothing)


@pytest.mark.parametrize("smoothing", MODES)
def test_gradients_finite_at_singular_points(random_cases, smoothing):
    """Every output (norms, EES included), every input: head-on (T_c = 0), head-on with mu = 0,
    mu = 0, exactly on the cone boundary, eps = -1 (J = 0), a separating contact, u_n = 0."""
    cases = [head_on(), head_on(mu=0.0), exact_cone_boundary()]
    for k, edit in enumerate([("friction", 0.0), ("restitution", -1.0), ("restitution", 1.0)]):
        c = copy.deepcopy(random_cases["principal"][10 + k])
        c["contact"][edit[0]] = edit[1]
        cases.append(c)
    near = copy.deepcopy(random_cases["principal"][20])  # on the cone boundary, as close as floats allow
    s = ref.stick_split(near)
    near["contact"]["friction"] = np.linalg.norm(s["t_c"]) / s["n_c"] if s["n_c"] > 0 else 0.3
    cases.append(near)
    sep = head_on(speed2=-10.0)  # u_n = 0 exactly: both at 10 m/s along +x
    assert ref.stick_split(sep)["u"][0] == 0.0
    cases.append(sep)
    cases.append(head_on(speed2=-12.0))  # separating
    values, grads = _all_output_grads(cases, smoothing)
    assert np.all(np.isfinite(values))
    for g in jax.tree_util.tree_leaves(grads):
        assert np.all(np.isfinite(np.asarray(g))), g


@pytest.mark.parametrize("smoothing", MODES)
def test_head_on_delta_v_derivative_is_analytic(smoothing):
    """|dv1| = (1 + eps) m2 / (m1 + m2) (v1 + s2) head-on, so d|dv1|/d s2 = (1 + eps) m2 / (m1 + m2);
    the speed s2 enters as v2 = s2 (-1, 0, 0) (course = yaw = pi), so the derivative is grad_v2 . (-1, 0, 0)."""
    case = head_on(eps=0.3)
    w = np.zeros((1, kit.N_OUTPUTS))
    w[0, kit.OUTPUT_SLICES["delta_v_magnitude_1"]] = 1.0
    _, grads = kit.value_and_grad(kit.inputs([case]), w, smoothing)
    d_speed = float(np.asarray(grads[3].velocity)[0] @ np.array([-1.0, 0.0, 0.0]))
    m1, m2 = case["vehicles"][0]["mass"], case["vehicles"][1]["mass"]
    assert d_speed == pytest.approx(1.3 * m2 / (m1 + m2), rel=RTOL_ANALYTIC)


@pytest.mark.parametrize("smoothing", MODES)
def test_restitution_derivative_at_minus_one(random_cases, smoothing):
    """J = (1 + eps) J_c(s*): at eps = -1, J = 0 and dJ/deps = J_c(s*) (the reference at eps = 0).
    The magnitudes have the one-sided derivatives from eps > -1: d|dv_i|/deps = |J_c| / m_i and
    d|J_t|/deps = |J_c - (n.J_c) n| (a norm of J would give 0 at J = 0)."""
    base = copy.deepcopy(random_cases["principal"][30])
    base["contact"]["restitution"] = -1.0
    outputs = [("impulse", k) for k in range(3)] + [("delta_v_magnitude_1", 0), ("delta_v_magnitude_2", 0),
                                                     ("impulse_tangential", 0)]
    w = np.zeros((len(outputs), kit.N_OUTPUTS))
    for row, (name, k) in enumerate(outputs):
        w[row, kit.OUTPUT_SLICES[name].start + k] = 1.0
    values, grads = kit.value_and_grad(kit.inputs([base] * len(outputs)), w, smoothing)
    np.testing.assert_array_equal(values, 0.0)
    zero = copy.deepcopy(base)
    zero["contact"]["restitution"] = 0.0
    if smoothing == 0.0:
        j_c = ref.solve(zero)["contact"]["impulse"]
    else:  # the smooth J_c(s*_tau): the engine's own impulse at eps = 0
        j_c = kit.batch_exchange(kit.inputs([zero]), smoothing).contact.impulse[0]
    n = np.asarray(base["contact"]["normal"]) / np.linalg.norm(base["contact"]["normal"])
    masses = [v["mass"] for v in base["vehicles"]]
    expected = [*j_c, np.linalg.norm(j_c) / masses[0], np.linalg.norm(j_c) / masses[1],
                np.linalg.norm(j_c - (n @ j_c) * n)]
    assert expected[-1] > 1e-3 * np.linalg.norm(j_c)  # an oblique impulse: |J_t| has a slope to find
    d_eps = np.asarray(grads[4].restitution)
    np.testing.assert_allclose(d_eps[:3], expected[:3], rtol=0, atol=RTOL_ANALYTIC * np.linalg.norm(j_c) * 10)
    np.testing.assert_allclose(d_eps[3:], expected[3:], rtol=1e-10)
    # nothing else moves J while eps = -1
    for tree in grads[:4]:
        for g in tree:
            np.testing.assert_array_equal(np.asarray(g), 0.0)


# --------------------------------------------------------------------------- smooth -> exact
# |J_tau - J_0| <= C tau |J_0| (docs/model.md 3): C depends on mu and K; measured up to 6.2 (mu = 3.7, on the cone)
SMOOTHING_RATE_C = 10.0
TAUS = (1e-1, 1e-2, 1e-3, 1e-4)


def _on_the_cone(cases):
    """The cases with N_c > 0, with mu set to |T_c| / N_c: exactly where the smooth minimum
    departs most from the exact one (a = b, M_tau = 2^tau M)."""
    out = []
    for c in cases:
        s = ref.stick_split(c)
        if s["n_c"] > 0:
            c = copy.deepcopy(c)
            c["contact"]["friction"] = float(np.linalg.norm(s["t_c"]) / s["n_c"])
            out.append(c)
    return out


def _smoothing_ratios(cases):
    """(len(TAUS), B): |J_tau - J_0| / (tau |J_0|)."""
    args = kit.inputs(cases)
    j0 = kit.batch_exchange(args, 0.0).contact.impulse
    n0 = np.linalg.norm(j0, axis=-1)
    return np.array([np.linalg.norm(kit.batch_exchange(args, tau).contact.impulse - j0, axis=-1) / (tau * n0)
                     for tau in TAUS])


@pytest.fixture(scope="module")
def smoothing_ratios(random_cases):
    out = {}
    for kind, cases in random_cases.items():
        out[kind] = _smoothing_ratios(cases), [c["contact"]["friction"] for c in cases]
        cone = _on_the_cone(cases)
        out[kind + "-cone"] = _smoothing_ratios(cone), [c["contact"]["friction"] for c in cone]
    return out


@pytest.mark.parametrize("kind", ["principal", "full", "principal-cone", "full-cone"])
@pytest.mark.slow
def test_smooth_converges_to_exact_at_rate_tau(smoothing_ratios, kind):
    ratios, _ = smoothing_ratios[kind]
    assert np.all(ratios <= SMOOTHING_RATE_C), ratios.max()
    # O(tau): the ratio settles (does not grow) as tau -> 0
    assert np.all(ratios[-1] <= 1.01 * ratios[-2] + 1e-9)
    # and the bound is not vacuous: the smooth mode does differ from the exact one
    assert ratios[0].max() > 0.05




@pytest.mark.slow
def test_jacfwd_of_one_exchange_matches_central_differences(random_cases):
    """``jax.jacfwd`` of one unbatched exchange (only the tangents are batched, by jacfwd's vmap):
    the Jacobian of every output listed in conftest ``OUTPUTS`` with respect to vehicle 2's
    velocity and the contact point, against central differences of the values."""
    case = random_cases["principal"][3]
    v1, s1, v2, s2, c = kit.inputs(case)

    def outputs(vel, point):
        res = ks_jax.exchange(v1, s1, v2, s2._replace(velocity=vel), c._replace(point=point), smoothing=TAU)
        return kit.output_vector(res)

    # one program (one compile) for the Jacobian and the values of the differences
    program = reference_jit(lambda vel, point: (jax.jacfwd(outputs, argnums=(0, 1))(vel, point), outputs(vel, point)))
    jac_v, jac_p = program(s2.velocity, c.point)[0]

    def f(vel, point):
        return program(vel, point)[1]

    for k, (x, jac) in enumerate(((s2.velocity, jac_v), (c.point, jac_p))):
        for i in range(3):
            h = H_REL * max(1.0, abs(float(x[i])))
            args_p = [s2.velocity, c.point]
            args_m = [s2.velocity, c.point]
            args_p[k] = x.at[i].add(h)
            args_m[k] = x.at[i].add(-h)
            fd = (np.asarray(f(*args_p)) - np.asarray(f(*args_m))) / (2 * h)
            np.testing.assert_allclose(jac[:, i], fd, rtol=1e-5, atol=1e-5 * (1 + np.max(np.abs(fd))),
                                       err_msg=f"argument {k}, component {i}")


@pytest.mark.slow
def test_angle_derivatives_where_the_angle_is_exactly_zero():
    """In the inline head-on the force on vehicle 2 is exactly frontal (pdof 0.0) and the impulse
    azimuth is exactly 180 deg (vehicle 1 is pushed straight back). Turning vehicle 2's velocity a
    little sideways turns every angle: their derivatives with respect to v_y at exactly that point
    equal central differences of the angle taken modulo 360 (one side of the point reads near 0 deg,
    the other near 360)."""
    case = head_on()
    v1, s1, v2, s2, c = kit.inputs(case)
    names = ("pdof 1", "pdof 2", "impulse azimuth", "course after 1")

    def angles(vy):
        r = ks_jax.exchange(v1, s1, v2, s2._replace(velocity=s2.velocity.at[1].set(vy)), c, smoothing=TAU)
        return jnp.stack([r.vehicles[0].pdof, r.vehicles[1].pdof, r.contact.impulse_azimuth,
                          r.vehicles[0].course_after])

    h = 1e-6
    program = reference_jit(lambda vy: (angles(vy), jax.jacrev(angles)(vy)))  # one compile for both

    def values(vy):
        return program(vy)[0]

    at, up, down = (np.asarray(values(vy)) for vy in (0.0, h, -h))
    assert at[1] == 0.0 and at[2] == 180.0
    assert sorted([up[1], down[1]]) == [pytest.approx(0.0, abs=1e-3), pytest.approx(360.0, abs=1e-3)]
    fd = ((up - down + 180.0) % 360.0 - 180.0) / (2 * h)
    ad = np.asarray(program(0.0)[1])
    for name, a, f in zip(names, ad, fd):
        assert abs(f) > 1.0, name  # the angle does turn
        np.testing.assert_allclose(a, f, rtol=1e-6, err_msg=name)


@pytest.mark.slow
@pytest.mark.parametrize("file", ["seed_000_saturn_pontiac.json", "auto_tbone.json"])
def test_a_row_with_a_non_finite_input_leaves_a_shared_gradient_finite(file):
    """A loss over rows that share a parameter (here an angle added to vehicle 2's course, turned
    0.1 rad from the file's, and to the normal's azimuth), one row with a non-finite speed or normal pitch: that row
    gets its status and is left out of the loss, and the gradient is the gradient over the good row alone (before the
    double-where in ``to_pytrees``, inf * cos(course) made it NaN)."""
    from ks_jax.case import as_arrays

    case = ks_jax.load_case(Path(ks_jax.__file__).parent / "cases" / file)
    inputs = as_arrays(case.inputs)
    inputs = inputs._replace(contact=inputs.contact._replace(friction=0.2))  # sliding: the normal matters

    def row(theta, speed, normal_pitch):
        v2 = inputs.vehicles[1]
        v2 = v2._replace(course=v2.course + 0.1 + theta, speed=speed)
        c = inputs.contact._replace(normal=inputs.contact.normal + theta, normal_pitch=normal_pitch)
        return ks_jax.solve_inputs(inputs._replace(vehicles=(inputs.vehicles[0], v2), contact=c),
                                   case.auto_point, case.auto_normal)

    def loss(theta, speeds, pitches):
        res = jax.vmap(row, (None, 0, 0))(theta, speeds, pitches)
        ok = res.contact.status == 0
        return jnp.sum(jnp.where(ok, res.contact.impulse_magnitude + res.vehicles[0].delta_v_magnitude, 0.0)), \
            res.contact.status

    grad = quick_jit(jax.grad(loss, has_aux=True))  # compiled as ks_jax.solve compiles a case
    speed, pitch = inputs.vehicles[1].speed, inputs.contact.normal_pitch
    twice, status = grad(0.0, jnp.stack([speed, speed]), jnp.stack([pitch, pitch]))  # the good row, twice
    alone = twice / 2
    assert ks_jax.status_text(int(status[0])) == "ok"
    assert abs(float(alone)) > 1.0  # the shared angle does move the good row's results
    for bad_speed, bad_pitch in ((jnp.inf, pitch), (jnp.nan, pitch), (-jnp.inf, pitch), (speed, jnp.inf),
                                 (speed, jnp.nan)):
        g, status = grad(0.0, jnp.stack([speed, bad_speed]), jnp.stack([pitch, bad_pitch]))
        assert ks_jax.status_text(int(status[0])) == "ok"
        assert ks_jax.status_text(int(status[1])).startswith("invalid: "), status
        assert float(g) == pytest.approx(float(alone), rel=1e-12), (bad_speed, bad_pitch)
