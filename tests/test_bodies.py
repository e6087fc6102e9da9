"""Cases of several bodies (docs/model.md, "Contact interactions"): three or more vehicles and several fixed objects
in one case file, the first exchange between the bodies the case names (``between``), per-pair values (``pairs``),
through ``ks-jax solve --json``, the Python results and a fit, against the closed form of sequential one-dimensional
impacts of cars in line on a frictionless road (with a wall of infinite mass at the end of the line), and the words of
what a case file may not say."""

import copy
import json
import warnings

import numpy as np
import pytest

import fit
import ks_jax
from ks_jax.case import CaseError, CaseWarning, case_from_dict
from samples import run_cli

LENGTH = 4.5  # m, every car of these cases; its CG in the middle


def car(name, mass, x, speed):
    """A car of the line: a 4.5 m box, its CG in the middle, heading +x on y = 0, free wheels."""
    return {"name": name, "mass": f"{mass} kg", "inertia": [f"{0.2 * 1.8 * mass} kg*m^2", f"{0.9 * 1.8 * mass} kg*m^2",
                                                           f"{1.8 * mass} kg*m^2"],
            "length": f"{LENGTH} m", "width": "1.8 m", "height": "1.4 m", "cg_to_front": f"{LENGTH / 2} m",
            "cg_height": "0.7 m", "position": [f"{x} m", "0 m"], "yaw": 0, "speed": f"{speed} m/s",
            "wheelbase": "2.7 m", "track": "1.55 m", "cg_to_front_axle": "1.35 m", "after": {"wheels": "free"}}


def line(masses, speeds, xs, e, limit=3.0, **more):
    """Cars in line on a road of friction 0 (nothing acts between exchanges), the first exchange cars 0 and 1 by
    automatic contact with restitution ``e``."""
    return {"name": "cars in line", "vehicles": [car(f"car {k}", m, x, v) for k, (m, v, x) in
                                                 enumerate(zip(masses, speeds, xs))],
            "contact": {"restitution": e, "friction": 0.5}, "road": {"friction": 0, "time_limit": f"{limit} s"},
            **more}


def sequential_impacts(masses, speeds, xs, e, end, wall=None, pair_e=None, first=None):
    """The closed form of cars in line (each ``LENGTH`` long) meeting one pair of neighbours, or the last car a wall
    whose face is at x = ``wall``, at a time: at a touch of a closing pair k, k + 1 the impulse
    J = (1 + e) m_k m_k+1 / (m_k + m_k+1) (v_k - v_k+1), at the wall J = (1 + e) m v; between impacts every car
    keeps its velocity. ``pair_e``: {(k, k + 1) or (k, "wall"): e} where a pair has its own restitution after the
    first impact; ``first``: the first impact's pair, where it is not the earliest touch's. Returns the impacts up to
    ``end`` s, [(t s, pair, J N s)], and the positions and velocities at ``end``."""
    m, v, x = (np.array(a, float) for a in (masses, speeds, xs))
    t, impacts, pair_e = 0.0, [], pair_e or {}
    while len(impacts) < 100:
        closing = [((x[k + 1] - x[k] - LENGTH) / (v[k] - v[k + 1]), (k, k + 1)) for k in range(len(m) - 1)
                   if v[k] > v[k + 1]]
        if wall is not None and v[-1] > 0:
            closing.append(((wall - x[-1] - LENGTH / 2) / v[-1], (len(m) - 1, "wall")))
        if first is not None and not impacts:
            closing = [c for c in closing if c[1] == first]
        if not closing or t + min(closing)[0] > end:
            break
        step, pair = min(closing)
        t, x = t + step, x + v * step
        eps = pair_e.get(pair, e) if impacts else e
        k = pair[0]
        if pair[1] == "wall":
            j = (1 + eps) * m[k] * v[k]
            v[k] -= j / m[k]
        else:
            j = (1 + eps) * m[k] * m[k + 1] / (m[k] + m[k + 1]) * (v[k] - v[k + 1])
            v[k], v[k + 1] = v[k] - j / m[k], v[k + 1] + j / m[k + 1]
        impacts.append((t, pair, j))
    return impacts, x + v * (end - t), v


def check_against(out, closed_form, masses, speeds, wall_body=None):
    """The JSON of a solved line (``out``) against the closed form (``sequential_impacts`` of the cars of
    ``masses`` and ``speeds``): every exchange's pair, time from the first and impulse, every car's place at the time
    limit, and the energy lost (the kinetic energy before less that at the end)."""
    impacts, x, v = closed_form
    t0 = impacts[0][0]
    assert len(out["exchanges"]) == len(impacts)
    for ex, (t, pair, j) in zip(out["exchanges"], impacts):
        want = [pair[0], wall_body if pair[1] == "wall" else pair[1]]
        assert sorted(ex["between"], key=str) == sorted(want, key=str)
        assert ex["time"] == pytest.approx(t - t0, abs=1e-9)
        assert ex["impulse_magnitude"] == pytest.approx(j, rel=1e-9)
    for k, vehicle in enumerate(out["vehicles"]):
        np.testing.assert_allclose(vehicle["rest_position"], [x[k], 0.0], rtol=0, atol=1e-8)
    energy = sum(0.5 * m * (s ** 2 - w ** 2) for m, s, w in zip(masses, speeds, v))
    assert out["energy_loss_total"] == pytest.approx(energy, rel=1e-9)


def closed_form(masses, speeds, xs, e, limit, **kw):
    """``sequential_impacts`` up to ``limit`` s after the first impact (the watched motion's clock starts there)."""
    first = sequential_impacts(masses, speeds, xs, e, 1e9, **kw)[0][0][0]
    return sequential_impacts(masses, speeds, xs, e, first + limit, **kw)


MASSES, SPEEDS, XS, E = [1500.0, 1400.0, 1600.0], [20.0, 0.0, 0.0], [-10.0, 0.0, 6.0], 0.3


@pytest.mark.slow
def test_three_cars_in_line_through_solve_json_meet_the_closed_form(tmp_path, capsys):
    """``ks-jax solve --json`` of three cars in line: the first car strikes the second, which strikes the third, and
    the first catches the second again (a new interaction of that pair); every exchange, place and velocity against
    the closed form. The third car took no part in the first exchange: no delta-V and no PDOF of it, its velocity
    then as its velocity after."""
    path = tmp_path / "line.json"
    path.write_text(json.dumps(line(MASSES, SPEEDS, XS, E)))
    code, text, err = run_cli(capsys, "solve", str(path), "--json")
    assert code == 0, err
    (out,) = json.loads(text)["cases"]
    expected = closed_form(MASSES, SPEEDS, XS, E, 3.0)
    impacts = expected[0]
    assert [pair for _, pair, _ in impacts] == [(0, 1), (1, 2), (0, 1)]
    check_against(out, expected, MASSES, SPEEDS)
    assert out["between"] == [0, 1]
    assert [ex["interaction"] for ex in out["exchanges"]] == [0, 1, 2]
    third = out["vehicles"][2]
    assert third["delta_v_magnitude"] == 0.0 and third["pdof"] is None and third["pdof_clock"] is None
    assert third["velocity_after"] == [0.0, 0.0, 0.0]
    # each car's cumulative delta-V is its first interaction's: for the third, the second exchange
    second = impacts[1][2]
    np.testing.assert_allclose(third["delta_v_cumulative"], [second / MASSES[2], 0.0, 0.0], rtol=1e-9, atol=1e-9)
    assert [i["exchanges"] for i in out["vehicles"][0]["interactions"]] == [[0], [2]]


@pytest.mark.slow
def test_an_oblique_three_car_crash_keeps_its_momentum_through_every_exchange():
    """The first car strikes the second, turned 60 deg, off its centre; the second is sent into the third, parked at
    an angle: side-slaps of both pairs follow. On a road of friction 0 nothing acts between exchanges, so the cars'
    total momentum after their last exchanges (each car's velocity after its last exchange in the JSON, or its own
    where it had none) is what it was before the first, and no exchange gains energy. (The program of the line of
    cars above: the same bodies and settings.)"""
    raw = line(MASSES, SPEEDS, XS, E)
    raw["vehicles"][1].update(yaw=60, position=["0 m", "1 m"])
    raw["vehicles"][2].update(yaw=-30, position=["5 m", "4.5 m"])
    out = ks_jax.solve(case_from_dict(raw)).to_dict()
    pairs = [tuple(ex["between"]) for ex in out["exchanges"]]
    assert pairs.count((0, 1)) >= 2 and pairs.count((1, 2)) >= 2  # a side-slap of each pair
    velocity = {k: np.array([s, 0.0, 0.0]) for k, s in enumerate(SPEEDS)}
    before = sum(m * velocity[k] for k, m in enumerate(MASSES))
    for ex in out["exchanges"]:
        assert ex["energy_loss"] >= 0.0
        for v in ex["vehicles"]:
            velocity[v["vehicle"]] = np.asarray(v["velocity_after"])
    after = sum(m * velocity[k] for k, m in enumerate(MASSES))
    np.testing.assert_allclose(after, before, rtol=0, atol=1e-9 * np.linalg.norm(before))


@pytest.mark.slow
def test_the_first_exchange_between_named_bodies_and_a_pair_of_its_own_restitution():
    """Two cars in line, a wall at the end of the line and a pole far away that nothing meets (the fixed objects a
    list, reported as one); ``"between": [1, "fixed[0]"]``: the second car strikes the wall first (the first car,
    behind it, not yet touching), rebounds into the first car and strikes the wall again; ``pairs`` gives the two
    cars a restitution of their own. Against the closed form of impacts in line with a wall of infinite mass; the
    panel names the first exchange's pair."""
    raw = line([1500.0, 1400.0], [5.0, 10.0], [-6.0, 0.0], 0.5, limit=1.2,
               fixed=[{"name": "wall", "kind": "wall", "point": ["4 m", "0 m"], "normal": 180},
                      {"kind": "pole", "position": ["0 m", "30 m"], "diameter": "0.3 m"}],
               between=[1, "fixed[0]"], pairs=[{"between": [1, 0], "restitution": 0.3}])
    case = case_from_dict(raw)
    assert case.between == (1, 2) and case.motion.pairs == ((0, 1),) and case.motion.poles == (3,)
    solution = ks_jax.solve(case)
    out = solution.to_dict()
    expected = closed_form([1500.0, 1400.0], [5.0, 10.0], [-6.0, 0.0], 0.5, 1.2, wall=4.0, pair_e={(0, 1): 0.3})
    assert [pair for _, pair, _ in expected[0]] == [(1, "wall"), (0, 1), (1, "wall")]
    check_against(out, expected, [1500.0, 1400.0], [5.0, 10.0], wall_body="fixed[0]")
    assert out["between"] == [1, "fixed[0]"]
    assert [f["kind"] for f in out["fixed"]] == ["wall", "pole"] and out["fixed"][0]["name"] == "wall"
    assert out["vehicles"][0]["delta_v_magnitude"] == 0.0  # not in the first exchange
    assert out["vehicles"][1]["delta_v_magnitude"] == pytest.approx(1.5 * 10.0, rel=1e-9)
    assert "vehicles[1] (car 1) and fixed[0] (wall)" in ks_jax.report.text_report(solution)
    # in each unit system alone, every exchange still names its pair and each vehicle's PDOF
    for units in ("si", "us"):
        panel = ks_jax.report.text_report(solution, units=units)
        assert panel.count("vehicles[1] and fixed[0]") == 2 and panel.count("vehicles[0] and vehicles[1]") == 1
        rows = [row for row in panel.splitlines() if row.lstrip().startswith("vehicles[") and " delta-V " in row]
        assert len(rows) == sum(len(ex["vehicles"]) for ex in out["exchanges"]), panel
        assert all("PDOF" in row and ("mph" if units == "us" else "m/s") in row for row in rows), panel


def fitted_line():
    raw = line(MASSES, SPEEDS, XS, E, limit=3.0)
    truth = ks_jax.solve(case_from_dict(raw)).to_dict()
    raw["unknowns"] = {"vehicles[0].speed": {"bounds": ["5 m/s", "40 m/s"], "start": "12 m/s"}}
    raw["evidence"] = [{"quantity": "vehicles[2].rest_position[0]",
                        "value": f"{truth['vehicles'][2]['rest_position'][0]} m", "sigma": "0.3 m"},
                       {"quantity": "exchanges[1].impulse_magnitude",
                        "value": f"{truth['exchanges'][1]['impulse_magnitude']} N*s", "sigma": "100 N*s"}]
    return raw


@pytest.mark.slow
def test_a_fit_reads_a_third_car_and_a_later_exchange_as_evidence():
    """The first car's speed from the third car's place at the time limit and the second exchange's impulse (both
    noise-free, from the case at 20 m/s): the fit finds 20 m/s."""
    result = fit.reconstruct(case_from_dict(fitted_line()), starts=2)
    assert result.estimate["vehicles[0].speed"] == pytest.approx(20.0, abs=1e-3)
    assert result.cost < 1e-6 and result.converged


@pytest.mark.parametrize("change, words", [
    (lambda d: d.update(vehicles=d["vehicles"] * 3), "a case has 1 to 8 vehicles"),
    (lambda d: d.update(vehicles=d["vehicles"][:1]), "a case needs two bodies"),
    (lambda d: d.update(fixed=[{"kind": "pole", "position": [0, 30], "diameter": 0.3}] * 9), "at most 8"),
    (lambda d: d.update(between=[0, 3]), "between[1] = 3: no such body"),
    (lambda d: d.update(between=[0, "fixed[0]"]), "between[1] = 'fixed[0]': no such body"),
    (lambda d: d.update(between=[1, 1]), "a body cannot strike itself"),
    (lambda d: d.update(between=[0]), "must name the first exchange's two bodies"),
    (lambda d: d.update(between=["fixed[0]", 0], fixed={"kind": "pole", "position": [0, 30], "diameter": 0.3}),
     "the first body must be a vehicle"),
    (lambda d: d.pop("road"), "a case of more than two bodies needs a road"),
    (lambda d: d.update(pairs=[{"between": [0, 1], "restitution": 2}]), r"pairs\[0\].restitution = 2: must be in"),
    (lambda d: d.update(pairs=[{"between": [0, 1]}, {"between": [1, 0]}]), "pairs[0] names the same pair"),
    (lambda d: d.update(pairs=[{"between": [0, 7]}]), r"pairs\[0\].between\[1\] = 7: no such body"),
    (lambda d: d.update(pairs={"between": [0, 1]}), "must be a list of pairs"),
])
def test_bad_bodies_are_refused_by_name(change, words):
    raw = line(MASSES, SPEEDS, XS, E)
    change(raw)
    with pytest.raises(CaseError, match=words if "\\" in words else words.replace("[", r"\[").replace("]", r"\]")):
        case_from_dict(raw)


def test_a_pair_without_a_road_is_ignored_with_a_warning():
    raw = copy.deepcopy(line(MASSES[:2], SPEEDS[:2], XS[:2], E))
    raw.pop("road")
    for v in raw["vehicles"]:  # nothing of the motion to rest: the one warning is the pairs'
        for k in ("wheelbase", "track", "cg_to_front_axle", "after"):
            v.pop(k)
    raw["pairs"] = [{"between": [0, 1], "restitution": 0.1}]
    with pytest.warns(CaseWarning, match="pairs: later exchanges happen while the bodies move on"):
        case = case_from_dict(raw)
    assert case.inputs.pairs == () and case.motion is None


def test_paths_to_a_vehicle_the_case_does_not_have_are_refused_with_the_count():
    """A sweep or fit naming vehicles[3] of a case of three vehicles, or vehicles[8] of any case, is refused with
    the rule; a case file in a batch with such evidence is reported and the others are fitted."""
    case = case_from_dict(line(MASSES, SPEEDS, XS, E))
    with pytest.raises(CaseError, match=r"vehicles\[3\].speed: this case has 3 vehicles \(vehicles\[0\] to "
                                        r"vehicles\[2\]\)"):
        ks_jax.sweep(case, {"vehicles[3].speed": [1.0, 2.0]})
    with pytest.raises(CaseError, match="vehicle index must be 0 to 7"):
        ks_jax.sweep(case, {"vehicles[8].speed": [1.0, 2.0]})
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert ks_jax.case.on_fixed_object(case, "vehicles[2].rest_position[0]") is None
