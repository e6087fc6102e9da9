"""Fixed objects (docs/model.md, "Fixed objects"): a wall, a pole or a barrier struck by one vehicle, against
hand calculations (a frontal into a wall; an oblique wall impact with friction, sticking and sliding, worked
with the planar collision matrix), the limit of a second vehicle whose mass grows without bound, the vehicle's
angular momentum about the contact point, first-contact times by hand, case files, sweeps and fits."""

import json
import math
from importlib import resources
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np
import pytest

import fit
import ks_jax
from ks_jax.case import CaseError, case_from_dict, to_pytrees
from ks_jax.cli import main
from ks_jax.model.contact import automatic_exchange
from ks_jax.report import text_report
from samples import reference_jit

M, IZZ, V = 1500.0, 2700.0, 15.0  # kg, kg m^2, m/s
CAR = {"name": "Sedan", "mass": M, "inertia": [500, 2500, IZZ], "length": 4.5, "width": 1.8, "height": 1.4,
       "cg_to_front": 2.0, "cg_height": 0.55, "position": [0, 0], "yaw": 0, "speed": V}


def wall_case(name="wall", point=None, normal=180.0, e=0.2, mu=0.5, car=None, wall_normal=None, **contact):
    """The sedan at (0, 0) heading +x at V into a wall whose face runs through x = 3 m (normal 180 deg by
    default); ``point`` (x, y) of an explicit contact at the CG's height, else automatic."""
    c = {"restitution": e, "friction": mu, **contact}
    if point is not None:
        c.update(point=[point[0], point[1], 0.55], normal=normal)
    return {"name": name, "vehicles": [dict(CAR, **(car or {}))],
            "fixed": {"kind": "wall", "point": [3.0, 0.0], "normal": normal if wall_normal is None else wall_normal},
            "contact": c}


def solve_all(dicts):
    """``ks_jax.solve`` of each case alone: ks_jax.solve compiles a program per contact mode and number of rows,
    and one row is what the command line solves (``test_full_frontal_into_a_wall_is_the_hand_calculation``)."""
    return [ks_jax.solve(case_from_dict(d)) for d in dicts]


def test_full_frontal_into_a_wall_is_the_hand_calculation(tmp_path, capsys):
    """J = (1 + e) m v along the normal, delta-V (1 + e) v, energy loss (1 - e^2) m v^2 / 2 and
    EES = sqrt(2 E / m): through ``ks-jax solve --json``, which lists the vehicle alone and the object."""
    e = 0.2
    path = tmp_path / "wall.json"
    path.write_text(json.dumps(wall_case(point=(2.0, 0.0), e=e)))
    assert main(["solve", str(path), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)["cases"][0]
    c, (v,) = out["contact"], out["vehicles"]
    E = 0.5 * (1 - e * e) * M * V * V
    assert c["status"] == "ok" and not c["sliding"]
    assert c["impulse_magnitude"] == pytest.approx((1 + e) * M * V, rel=1e-12)
    np.testing.assert_allclose(c["impulse"], [-(1 + e) * M * V, 0, 0], atol=1e-9 * M * V)
    assert v["delta_v_magnitude"] == pytest.approx((1 + e) * V, rel=1e-12)
    assert c["energy_loss"] == pytest.approx(E, rel=1e-12)
    assert v["ees"] == pytest.approx(math.sqrt(2 * E / M), rel=1e-12)
    assert v["pdof"] == pytest.approx(0.0, abs=1e-9)
    assert out["fixed"]["kind"] == "wall" and out["fixed"]["point"] == [3.0, 0.0]


def _planar_hand(r, n, u, e, mu):
    """The KS impulse of a planar impact of one body (mass M, yaw inertia IZZ, centroid at r from the CG)
    against a fixed one, worked with 2 x 2 matrices: K = Id / M + [[r_y^2, -r_x r_y], [-r_x r_y, r_x^2]] / IZZ;
    stick J_c = -K^-1 u; where |T_c| > mu N_c, slide: J = N (n + mu t), t along T_c, N = -(1+e) u_n / n.K(n + mu t)."""
    K = np.eye(2) / M + np.array([[r[1] ** 2, -r[0] * r[1]], [-r[0] * r[1], r[0] ** 2]]) / IZZ
    jc = -np.linalg.solve(K, u)
    nc = jc @ n
    tc = jc - nc * n
    if np.linalg.norm(tc) <= mu * nc:
        return (1 + e) * jc, False
    d = n + mu * tc / np.linalg.norm(tc)
    return -(1 + e) * (u @ n) / (n @ K @ d) * d, True


@pytest.mark.parametrize("mu, sliding", [(0.9, False), (0.1, True)])
def test_oblique_wall_impact_by_hand(mu, sliding):
    """The sedan strikes a wall turned 30 deg (normal 150 deg) with its front-left corner region (centroid
    0.6 m left of its axis, at the CG's height): the impulse, the velocity and yaw rate after against the
    planar hand calculation, sticking at mu = 0.9 and sliding at mu = 0.1."""
    e, azimuth = 0.15, math.radians(150.0)
    point = np.array([2.0, 0.6])
    (sol,) = solve_all([wall_case(point=tuple(point), normal=150.0, e=e, mu=mu)])
    n = np.array([math.cos(azimuth), math.sin(azimuth)])
    u = np.array([V, 0.0])  # the CG's velocity; no yaw rate before
    j, slides = _planar_hand(point, n, u, e, mu)
    assert slides == sliding and bool(sol.result.contact.sliding) == sliding
    np.testing.assert_allclose(sol.result.contact.impulse, [j[0], j[1], 0.0], rtol=0, atol=1e-9 * np.linalg.norm(j))
    v = sol.result.vehicles[0]
    np.testing.assert_allclose(v.velocity_after[:2], u + j / M, rtol=0, atol=1e-9 * V)
    assert float(v.yaw_rate_after) == pytest.approx((point[0] * j[1] - point[1] * j[0]) / IZZ, rel=1e-9)
    if sliding:
        jn = j @ n
        assert np.linalg.norm(j - jn * n) == pytest.approx(mu * jn, rel=1e-9)


def test_a_second_vehicle_of_1e12_kg_gives_the_walls_results():
    """The wall as the limit of a second vehicle whose mass grows: a 1e12 kg box in the wall's place gives every
    result of vehicle 1 and of the contact to 1e-9 relative. (The box's 1/m and r^2 / I add to the sedan's
    collision matrix, about 2e-3 1/kg here; with I = 1e14 kg m^2, a radius of gyration of 10 m, both are below
    1e-12, and its CG is at the centroid's height, so that nothing tilts.)"""
    wall = wall_case(point=(2.0, 0.6), normal=150.0, e=0.15, mu=0.3)
    heavy = dict(wall)
    del heavy["fixed"]
    heavy["vehicles"] = [CAR, {"name": "block", "mass": 1e12, "inertia": [1e14] * 3, "length": 4.0, "width": 8.0,
                               "height": 2.0, "cg_to_front": 2.0, "cg_height": 0.55, "position": [5.0, 0.6],
                               "yaw": 0, "speed": 0}]
    a, b = solve_all([wall, heavy])
    for name in ("impulse", "energy_loss", "separation_velocity"):
        x, y = np.asarray(getattr(a.result.contact, name)), np.asarray(getattr(b.result.contact, name))
        np.testing.assert_allclose(x, y, rtol=0, atol=1e-9 * max(1.0, np.abs(x).max()), err_msg=name)
    for name in ("delta_v", "velocity_after", "angular_velocity_after", "pdof"):
        x, y = np.asarray(getattr(a.result.vehicles[0], name)), np.asarray(getattr(b.result.vehicles[0], name))
        np.testing.assert_allclose(x, y, rtol=0, atol=1e-9 * max(1.0, np.abs(x).max()), err_msg=name)


def test_an_off_centre_pole_impact_keeps_the_vehicles_angular_momentum_about_the_contact_point():
    """The impulse acts at the centroid P, so the vehicle's angular momentum about P, m (x - P) x v + I w, is
    the same after as before (3D, the centroid above the CG: pitch and roll take part), and the pole takes
    all of the energy loss (EES = sqrt(2 E / m)), with a crush measured in the vehicle's own box."""
    d = {"name": "pole", "vehicles": [dict(CAR, yaw_rate=20.0)],
         "fixed": {"kind": "pole", "position": [2.15, 0.6], "diameter": "30 cm"},
         "contact": {"point": [1.9, 0.6, 0.8], "normal": 195, "restitution": 0.1, "friction": 0.6}}
    (sol,) = solve_all([d])
    c, v = sol.result.contact, sol.result.vehicles[0]
    assert sol.status == "ok"
    inertia = np.diag([500.0, 2500.0, IZZ])  # yaw 0, no pitch or roll: body and global axes agree
    x = np.array([0.0, 0.0, 0.55])
    p = np.asarray(c.point)
    w_before = np.array([0.0, 0.0, math.radians(20.0)])
    before = M * np.cross(x - p, [V, 0, 0]) + inertia @ w_before
    after = M * np.cross(x - p, v.velocity_after) + inertia @ v.angular_velocity_after
    np.testing.assert_allclose(after, before, rtol=0, atol=1e-9 * np.abs(before).max())
    assert float(v.ees) == pytest.approx(math.sqrt(2 * float(c.energy_loss) / M), rel=1e-12)
    assert float(v.crush) == pytest.approx(0.1 / math.cos(math.radians(15.0)), rel=1e-9)  # front face at x = 2


@pytest.mark.slow
def test_first_contact_with_each_object_by_hand():
    """Automatic contact: the sedan's front face (x = 2 m at t = 0) reaches a wall at x = 3 m after 1 / V; a
    pole of 0.3 m at x = 3.15 m (its face at 3.0) at the same time; a barrier whose near face is at x = 4 m
    after 2 / V. The normal is the object's face's, from the object into the vehicle (180 deg), and the
    centroid lies on the face; the vehicle's EES takes all of the energy."""
    barrier = {"kind": "barrier", "position": [5.0, 0.3], "yaw": 0, "length": 2.0, "width": 6.0}
    cases = [wall_case(),
             dict(wall_case(), fixed={"kind": "pole", "position": [3.15, 0.4], "diameter": 0.3}),
             dict(wall_case(), fixed=barrier)]
    wall, pole, box = ks_jax.solve([case_from_dict(d) for d in cases])  # as a file: the example file's programs
    for sol, t, face in ((wall, 1 / V, 3.0), (pole, 1 / V, 3.0), (box, 2 / V, 4.0)):
        c = sol.result.contact
        assert sol.status == "ok"
        assert float(c.time) == pytest.approx(t, abs=1e-9)
        np.testing.assert_allclose(c.normal, [-1.0, 0.0, 0.0], atol=1e-12)
        assert float(c.point[0]) == pytest.approx(face, abs=1e-9)
        assert float(sol.result.vehicles[0].ees) == pytest.approx(
            math.sqrt(2 * float(c.energy_loss) / M), rel=1e-12)
    assert float(pole.result.contact.point[1]) == pytest.approx(0.4, abs=1e-9)  # the pole's line
    assert float(wall.result.contact.point[1]) == pytest.approx(0.0, abs=1e-9)  # the middle of the front face


def test_fixed_objects_in_case_files_say_what_is_wrong():
    good = wall_case()
    bad = {
        "two vehicles and a fixed object without a road": (dict(good, vehicles=[CAR, CAR]),
                                                            "a case of more than two bodies needs a road"),
        "unknown kind": (dict(good, fixed={"kind": "tree"}), r"fixed\.kind.*wall, pole, barrier"),
        "pole without a diameter": (dict(good, fixed={"kind": "pole", "position": [3, 0]}),
                                    r"fixed\.diameter: missing"),
        "negative diameter": (dict(good, fixed={"kind": "pole", "position": [3, 0], "diameter": -0.3}),
                              "diameter must be positive"),
        "wall normal in a unit of length": (dict(good, fixed={"kind": "wall", "point": [3, 0], "normal": "2 m"}),
                                            r"fixed\.normal"),
    }
    for why, (d, words) in bad.items():
        with pytest.raises(CaseError, match=words):
            case_from_dict(d)


@pytest.mark.slow
def test_sweeps_and_fits_against_a_wall():
    """A sweep over the vehicle's speed gives the hand impulse (1 + e) m v at every speed; a sweep or a fit of
    the object's paths is refused (``test_a_fit_recovers_the_speed_into_a_pole_from_its_delta_v`` fits
    through an object)."""
    case = case_from_dict(wall_case(point=(2.0, 0.0), e=0.2))
    speeds = np.array([5.0, 10.0, 20.0])
    r = ks_jax.sweep(case, {"vehicles[0].speed": speeds})
    assert "vehicles[1].delta_v_magnitude" not in r.outputs  # the object has no results of its own
    np.testing.assert_allclose(r["contact.impulse_magnitude"], 1.2 * M * speeds, rtol=1e-12)
    with pytest.raises(CaseError, match="fixed wall"):
        ks_jax.sweep(case, {"vehicles[1].mass": [1.0, 2.0]})
    with pytest.raises(CaseError, match="fixed wall"):
        ks_jax.sweep(case, {"vehicles[0].speed": speeds}, outputs=["vehicles[1].speed_after"])
    with pytest.raises(CaseError, match="fixed wall"):
        fit.reconstruct(case, {"vehicles[1].speed": {"bounds": [0.0, 1.0]}},
                        [{"quantity": "vehicles[0].delta_v_magnitude", "value": 21.6, "sigma": 0.5}])


@pytest.mark.slow
def test_a_contact_that_cannot_exchange_an_impulse_says_why():
    """Seed chapter 001 (the Kia, 20 mph, into the rear of the Lucid, 5 mph) with its normal reversed (pointing
    from the Lucid into the Kia): no impulse, and the notes give the relative velocity along the normal,
    n . u = 15 mph by hand, and say the normal may point the wrong way, with the reversed azimuth (0 deg). The
    same with the right normal but the Kia slower than the Lucid (truly parting): only the first note. A wall
    whose normal points into the wall: the wrong-way note names the object."""
    raw = ks_jax.load_case(resources.files("ks_jax.cases") / "seed_001_lucid_kia.toml").raw
    reversed_ = dict(raw, contact=dict(raw["contact"], normal=180))
    slower = dict(raw, vehicles=[raw["vehicles"][0], dict(raw["vehicles"][1], speed="2 mph")])
    into_wall = wall_case(point=(2.0, 0.0), normal=0.0, wall_normal=180.0)
    rev, part, wall = solve_all([reversed_, slower, into_wall])
    mph = 1609.344 / 3600
    assert rev.status == part.status == wall.status == "separating"
    assert float(rev.result.contact.impulse_magnitude) == 0.0
    first, second = rev.notes()
    assert f"n . u = {15 * mph:.4g} m/s" in first
    assert "wrong way" in second and "from vehicle 2 (Kia K5) into vehicle 1 (Lucid Air)" in second
    assert "azimuth 0.0 deg" in second
    (only,) = part.notes()
    assert f"n . u = {3 * mph:.4g} m/s" in only
    assert "from the fixed wall into Sedan" in wall.notes()[1]
    assert rev.to_dict()["notes"] == rev.notes()
    assert "note: the normal may point the wrong way" in text_report(rev)


def _pole(centre, diameter=0.3, dt=0.0, speed=V):
    return {"name": "pole", "vehicles": [dict(CAR, speed=speed)],
            "fixed": {"kind": "pole", "position": list(centre), "diameter": diameter},
            "contact": {"restitution": 0.1, "friction": 0.6, "penetration_time": dt}}


@pytest.mark.slow
def test_a_pole_is_met_as_a_circle():
    """Automatic contact with a pole of radius 0.15 m, by hand. A corner: the pole's centre 0.1 m outside the
    sedan's left side (y = 0.9 m) is first touched by the front-left corner, where the corner's line y = 0.9
    meets the circle, x = x_c - sqrt(0.15^2 - 0.1^2), with the normal radial there (azimuth 180 + atan(0.1 /
    0.1118) = 221.8 deg). A centred pole, 0.1 m in: the overlap is a circular segment, whose centroid lies
    4 r sin^3(a/2) / (3 (a - sin a)) from the centre (a: the segment's angle, cos(a/2) = (r - 0.1) / r), and
    the normal is along the sedan's axis. A pole wholly inside the footprint (0.5 m in), and one 0.5 m off the
    axis, 0.4 m from the left side when 0.56 m in: the centroid is its centre and the normal the front face's,
    through which it came, turned inwards."""
    r, xc = 0.15, 4.0
    # one at a time: the one-row program of a pole that the tests above compiled
    corner, segment, inside, aside = (ks_jax.solve(case_from_dict(d)) for d in (
        _pole((xc, 1.0)), _pole((xc, 0.0), dt=0.1 / V), _pole((xc, 0.0), dt=0.5 / V), _pole((xc, 0.5), dt=0.56 / V)))
    x_touch = xc - math.sqrt(r * r - 0.1 ** 2)
    c = corner.result.contact
    assert float(c.time) == pytest.approx((x_touch - 2.0) / V, abs=1e-9)
    np.testing.assert_allclose(c.point[:2], [x_touch, 0.9], atol=1e-9)
    azimuth = math.degrees(math.atan2(float(c.normal[1]), float(c.normal[0]))) % 360
    assert azimuth == pytest.approx(180 + math.degrees(math.atan2(0.1, xc - x_touch)), abs=1e-6)
    assert azimuth == pytest.approx(221.81, abs=0.01)

    half = math.acos((r - 0.1) / r)  # a / 2
    a = 2 * half
    d = 4 * r * math.sin(half) ** 3 / (3 * (a - math.sin(a)))
    c = segment.result.contact
    assert float(c.time) == pytest.approx((xc - r - 2.0) / V, abs=1e-9)
    assert float(c.point[0]) == pytest.approx(xc - d, abs=2e-3 * r)  # the 32-sided polygon of the disc
    assert float(c.point[1]) == pytest.approx(0.0, abs=1e-12)
    np.testing.assert_allclose(c.normal, [-1.0, 0.0, 0.0], atol=1e-12)
    for sol, y in ((inside, 0.0), (aside, 0.5)):
        c = sol.result.contact
        np.testing.assert_allclose(c.point[:2], [xc, y], atol=1e-9)
        np.testing.assert_allclose(c.normal, [-1.0, 0.0, 0.0], atol=1e-12)


@pytest.mark.slow
def test_a_fit_recovers_the_speed_into_a_pole_from_its_delta_v():
    """Noise-free delta-V of an off-centre pole impact (automatic contact with the circle, 0.04 s of
    penetration, the centroid off the sedan's axis so that it spins): the fit, which differentiates through
    the first touch and the overlap, returns the speed it was made with."""
    case = case_from_dict(_pole((4.0, 0.5), dt=0.04, speed=14.0))
    (sol,) = ks_jax.solve([case])
    assert sol.status == "ok" and abs(float(sol.result.vehicles[0].yaw_rate_after)) > 0.1
    dv = float(sol.result.vehicles[0].delta_v_magnitude)
    result = fit.reconstruct(case, {"vehicles[0].speed": {"bounds": [5.0, 30.0]}},
                             [{"quantity": "vehicles[0].delta_v_magnitude", "value": dv, "sigma": 0.3}])
    assert result.converged
    assert result.estimate["vehicles[0].speed"] == pytest.approx(14.0, rel=1e-6)


@pytest.mark.slow
def test_the_example_file_of_fixed_objects_solves():
    """docs/examples/fixed_objects.json (named in the README): a wall at 160 deg, a pole and a barrier, each
    solved with automatic contact; the wall's normal is its own, and each EES takes all of the energy."""
    path = Path(__file__).resolve().parents[2] / "docs" / "examples" / "fixed_objects.json"
    wall, pole, barrier = ks_jax.solve(ks_jax.case.load_cases(path))
    for sol in (wall, pole, barrier):
        assert sol.status == "ok", sol.status
        mass = float(sol.case.inputs.vehicles[0].mass)
        assert float(sol.result.vehicles[0].ees) == pytest.approx(
            math.sqrt(2 * float(sol.result.contact.energy_loss) / mass), rel=1e-12)
    n = np.asarray(wall.result.contact.normal)
    assert math.degrees(math.atan2(n[1], n[0])) == pytest.approx(160.0, abs=1e-9)
    assert [s.case.vehicle_names[1] for s in (wall, pole, barrier)] == ["retaining wall", "utility pole", "barrier"]


@pytest.mark.slow
def test_a_wall_in_float32_is_met_as_in_float64():
    """A wall is a box kilometres long; in float32 the geometry's tolerances must not grow with it (they
    once put the centroid 0.45 m off and the EES 5 % low): the example wall at 160 deg, solved with float32
    inputs, gives the float64 contact to float32's rounding of a scene metres across."""
    path = Path(__file__).resolve().parents[2] / "docs" / "examples" / "fixed_objects.json"
    cases = ks_jax.case.load_cases(path)
    want = ks_jax.solve(cases)[0].result  # float64 (the programs of the example's test)
    inputs = ks_jax.case.as_arrays(cases[0].inputs, np.float32)
    run = reference_jit(lambda args, pitch: automatic_exchange(*args, pitch, auto_point=True, auto_normal=True))
    got = run(to_pytrees(inputs), inputs.contact.normal_pitch)
    assert got.contact.point.dtype == np.float32 and int(got.contact.status) == 0
    np.testing.assert_allclose(got.contact.point, want.contact.point, atol=1e-4)
    np.testing.assert_allclose(got.contact.normal, want.contact.normal, atol=1e-5)
    assert float(got.vehicles[0].ees) == pytest.approx(float(want.vehicles[0].ees), rel=1e-4)
