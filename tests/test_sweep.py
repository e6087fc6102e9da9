"""ks_jax.sweep: values equal single solves, shapes, chunking, zip, sharding, bad rows, CLI."""

from __future__ import annotations

import csv
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

jax.config.update("jax_enable_x64", True)  # also set by conftest; kept so the module runs alone

import ks_jax  # noqa: E402
from ks_jax.case import CaseError, as_arrays, get_output, set_input  # noqa: E402
from ks_jax.cli import main  # noqa: E402
from ks_jax import units as U  # noqa: E402
from ks_jax.sweeps import DEFAULT_OUTPUTS, ResultWriter, parse_over, sweep, write_results  # noqa: E402

CASES = Path(ks_jax.__file__).parent / "cases"
SEED0 = CASES / "seed_000_saturn_pontiac.json"
SEED1 = CASES / "seed_001_lucid_kia.toml"
RTOL = 1e-12  # sweep vs single solve: the same kernel, batched; only rounding may differ

OUTPUTS = ["contact.impulse_magnitude", "contact.energy_loss", "contact.sliding", "vehicles[0].delta_v[0]",
           "vehicles[1].pdof", "vehicles[0].speed_after", "contact.impulse[1]"]


@pytest.fixture(scope="module")
def case():
    return ks_jax.load_case(SEED0)


def single(case, point, path):
    inputs = case.inputs
    for p, v in point.items():
        inputs = set_input(inputs, p, v)
        if p.endswith(".yaw"):  # the seed cases give no course: it follows the yaw (MODEL.md section 2)
            inputs = set_input(inputs, p.replace(".yaw", ".course"), v)
    res = _SOLVE(as_arrays(inputs), case.auto_point, case.auto_normal)
    return expected(res, path), int(res.contact.status)


def expected(res, path):
    """What a sweep holds at ``path`` for the point solved alone as ``res``: its number, NaN where the JSON of
    ``ks-jax solve`` writes null although the point is solved (a direction of the impulse where none was
    exchanged; the time, centroid, normal, relative velocities and EES of a contact that never happens; the
    course of a vehicle at rest after)."""
    x = np.asarray(get_output(res, path), float)
    name = re.sub(r"\[\d\]$", "", path.split(".")[-1])
    no_impulse = not float(res.contact.impulse_magnitude) > 0
    if name in ("pdof", "pdof_clock", "impulse_azimuth", "impulse_elevation") and no_impulse:
        return np.full_like(x, np.nan)
    never = int(res.contact.status) == ks_jax.types.NO_CONTACT
    if never and (name == "ees" or path.startswith("contact.") and name in (
            "time", "point", "normal", "closing_velocity", "separation_velocity")):
        return np.full_like(x, np.nan)
    if name == "course_after":
        v = res.vehicles[int(path[9])]
        after, dv = np.asarray(v.velocity_after, float), np.asarray(v.delta_v, float)
        if np.hypot(*after[:2]) <= 1e-6 * (np.hypot(*(after - dv)[:2]) + float(v.delta_v_magnitude)):
            return np.full_like(x, np.nan)
    return x


_SOLVE = jax.jit(ks_jax.solve_inputs, static_argnums=(1, 2))  # one compile per contact mode


def _no_tangential(case, point):
    tangential, _ = single(case, point, "contact.impulse_tangential")
    magnitude, _ = single(case, point, "contact.impulse_magnitude")
    return tangential <= 1e-12 * magnitude


def assert_matches(result, case, points):
    """points: list of (result index, {path: value})."""
    for index, point in points:
        for path in result.output_paths:
            want, status = single(case, point, path)
            got = result[path][index]
            assert result["status"][index] == status
            if status >= 10 and path != "contact.sliding":  # invalid: NaN; separating: numbers
                assert np.isnan(got), (path, index)
            elif path == "contact.sliding" and status == 0 and _no_tangential(case, point):
                # |T_c| > mu N_c with mu = 0 and T_c = 0 to rounding (an inline impact): the flag is the
                # sign of rounding noise, which the sweep's and the single solve's programs round
                # differently; the impulse is the same either way (compared above and below)
                continue
            else:
                np.testing.assert_allclose(got, want, rtol=RTOL, atol=1e-9, err_msg=f"{path} at {point}")


def test_grid_values_and_shape(case):
    speeds = np.linspace(3.0, 15.0, 5)
    yaws = np.radians([0.0, 10.0, 25.0])
    mus = np.array([0.0, 0.3, 0.9, 2.0])
    over = {"vehicles[1].speed": speeds, "vehicles[1].yaw": yaws, "contact.friction": mus}
    r = sweep(case, over, outputs=OUTPUTS, chunk_size=7)  # 60 points: chunks of 7 do not divide it
    assert r.shape == (5, 3, 4) and r.points == 60
    for p in OUTPUTS + ["status"]:
        assert r[p].shape == (5, 3, 4), p
    assert r["contact.sliding"].dtype == bool and r["status"].dtype == np.int8
    pts = [((i, j, k), {"vehicles[1].speed": speeds[i], "vehicles[1].yaw": yaws[j], "contact.friction": mus[k]})
           for i, j, k in [(0, 0, 0), (4, 2, 3), (2, 1, 1), (3, 0, 2), (1, 2, 0)]]
    assert_matches(r, case, pts)
    assert sum(r.status_counts.values()) == 60


def test_chunk_boundaries_do_not_change_results(case):
    over = {"vehicles[1].speed": np.linspace(2, 20, 13), "contact.restitution": np.linspace(0, 1, 7)}
    whole = sweep(case, over, outputs=OUTPUTS, chunk_size=1000)
    for chunk in (5, 13):
        part = sweep(case, over, outputs=OUTPUTS, chunk_size=chunk)
        for p in OUTPUTS + ["status"]:
            np.testing.assert_array_equal(part[p], whole[p], err_msg=f"{p}, chunk {chunk}")



def test_a_sweep_of_another_size_runs_the_programs_already_compiled(case, monkeypatch):
    """The programs do not depend on the axes' sizes, and a short sweep's one chunk is rounded up to a power
    of two: after a 5 x 3 grid, a 7 x 2 grid and a zip of 11 samples over the same paths compile nothing
    (the jitted programs' caches keep their sizes), and the 7 x 2 grid's values are those of the same grid
    in chunks of 3 points (other programs) and of single solves. A range of a larger sweep is not padded."""
    sweeps = sys.modules["ks_jax.sweeps"]
    programs = []
    compiled = sweeps._compiled

    calls = []

    def spy(*args):
        calls.append(args)
        programs.append(compiled(*args))
        return programs[-1]

    monkeypatch.setattr(sweeps, "_compiled", spy)
    paths = ("vehicles[1].speed", "contact.restitution")
    sweep(case, {paths[0]: np.linspace(4.0, 12.0, 5), paths[1]: np.array([0.0, 0.1, 0.2])}, outputs=OUTPUTS)
    sizes = [f._cache_size() for f in programs[-1]]
    over = {paths[0]: np.linspace(3.0, 15.0, 7), paths[1]: np.array([0.05, 0.4])}
    grid = sweep(case, over, outputs=OUTPUTS)
    assert programs[-1] is programs[0] and [f._cache_size() for f in programs[-1]] == sizes
    samples = sweep(case, {paths[0]: np.linspace(3.0, 15.0, 11), paths[1]: np.linspace(0.0, 0.5, 11)},
                    outputs=OUTPUTS, mode="zip")
    assert samples.shape == (11,) and set(samples.status_counts) == {"ok"}
    assert [f._cache_size() for f in programs[0]] == sizes  # zip: other programs, but the grid's stayed
    small = sweep(case, over, outputs=OUTPUTS, chunk_size=3)
    for p in OUTPUTS + ["status"]:
        np.testing.assert_array_equal(grid[p], small[p], err_msg=p)
    # a range of a larger sweep keeps its exact axes (a zip's are as long as the sweep) and sizes
    many = {paths[0]: np.linspace(3.0, 15.0, 40000), paths[1]: np.linspace(0.0, 0.5, 40000)}
    part = sweep(case, many, outputs=OUTPUTS, mode="zip", index_range=(39990, 40000))
    assert part.shape == (10,) and set(part.status_counts) == {"ok"}
    assert calls[-1][5] == (40000, 40000)  # static_sizes
    for i, j in ((0, 0), (6, 1), (3, 0)):
        point = {paths[0]: over[paths[0]][i], paths[1]: over[paths[1]][j]}
        for p in OUTPUTS:
            value, status = single(case, point, p)
            np.testing.assert_allclose(grid[p][i, j], value, rtol=RTOL, atol=RTOL, err_msg=p)
            assert grid["status"][i, j] == status


@pytest.mark.skipif(jax.default_backend() != "cpu", reason="XLA's CPU settings")
def test_a_small_sweep_compiles_quick_and_gets_the_values_of_xla_defaults(case, monkeypatch, kit):
    """A sweep of at most ``QUICK_POINTS`` points compiles with ``ks_jax.quick.QUICK_CPU``, a larger one with
    XLA's defaults; the small sweep's values, every output of an 18-point grid over speed, yaw and friction
    (sliding and sticking), are those of the same sweep compiled at XLA's defaults, to rounding."""
    sweeps = sys.modules["ks_jax.sweeps"]
    seen = []
    compiled = sweeps._compiled

    def spy(*args):
        seen.append(args[-1])
        return compiled(*args)

    monkeypatch.setattr(sweeps, "_compiled", spy)
    over = {"vehicles[1].speed": np.linspace(3.0, 15.0, 3), "vehicles[1].yaw": np.radians([0.0, 25.0]),
            "contact.friction": np.array([0.0, 0.3, 2.0])}
    outputs = [p for p in OUTPUTS if not p.startswith("contact.sliding")] + ["contact.sliding", "vehicles[1].ees"]
    quick = sweep(case, over, outputs=outputs)
    monkeypatch.setattr(sweeps, "QUICK_POINTS", 17)
    sweep(case, over, outputs=outputs)
    assert seen == [True, False]
    monkeypatch.setattr(sweeps, "QUICK_CPU", kit.xla_defaults)  # "quick" programs compiled at XLA's defaults
    monkeypatch.setattr(sweeps, "QUICK_POINTS", 18)
    compiled.cache_clear()
    defaults = sweep(case, over, outputs=outputs)
    assert seen[-1] is True and compiled.cache_info().misses == 1 and set(quick.status_counts) == {"ok"}
    assert quick["contact.sliding"].any() and not quick["contact.sliding"].all()
    for p in outputs + ["status"]:
        if quick[p].dtype.kind in "bi":
            np.testing.assert_array_equal(quick[p], defaults[p], err_msg=p)
        else:
            np.testing.assert_allclose(quick[p], defaults[p], rtol=RTOL, atol=RTOL, err_msg=p)


def test_automatic_contact_case_matches_single_solves():
    """A case with automatic contact goes through the geometry in its sweep (three calls: status, contact,
    exchange): the same values as solving a point alone, across chunk boundaries."""
    auto = ks_jax.load_case(CASES / "auto_tbone.json")
    assert auto.auto_point and auto.auto_normal
    speeds = np.array([11.0, 13.4112, 16.0])  # the pickup (its case speed: 30 mph)
    mus = np.array([0.2, 0.8])
    outputs = ["contact.time", "contact.impulse_magnitude", "vehicles[0].pdof", "vehicles[1].delta_v[1]"]
    r = sweep(auto, {"vehicles[1].speed": speeds, "contact.friction": mus}, outputs=outputs, chunk_size=4)
    assert r.shape == (3, 2) and r.status_counts == {"ok": 6}
    for i, j in [(0, 0), (2, 1), (1, 1)]:  # (2, 1) and (1, 1) are in the second chunk
        inputs = set_input(set_input(auto.inputs, "vehicles[1].speed", speeds[i]), "contact.friction", mus[j])
        res = ks_jax.solve_inputs(as_arrays(inputs), True, True)
        assert int(res.contact.status) == 0
        for path in outputs:
            np.testing.assert_allclose(r[path][i, j], get_output(res, path), rtol=RTOL, atol=1e-9, err_msg=path)
    assert len(set(np.round(r["contact.time"][:, 0], 12))) == 3  # the time to contact depends on the speed


def test_automatic_contact_sweep_with_bad_missed_and_turning_rows():
    """Every point of an automatic-contact grid against ``solve_inputs`` alone: a negative speed and a
    restitution of 1.5 (invalid: their status, NaN), the sedan 80 ft ahead (no contact), a turning sedan
    (the first contact searched), in chunks of 5."""
    auto = ks_jax.load_case(CASES / "auto_tbone.json")
    over = {"vehicles[1].speed": np.array([-2.0, 11.0, 16.0]), "contact.restitution": np.array([0.1, 1.5]),
            "vehicles[0].yaw_rate": np.radians([0.0, 40.0]), "vehicles[0].position[0]": np.array([0.0, 80 * U.FT])}
    outputs = ["contact.time", "contact.impulse_magnitude", "contact.normal[1]", "vehicles[0].pdof",
               "vehicles[1].crush", "contact.sliding"]
    r = sweep(auto, over, outputs=outputs, chunk_size=5)
    paths = list(over)
    seen = set()
    for index in np.ndindex(r.shape):
        inputs = auto.inputs
        for p, k in zip(paths, index):
            inputs = set_input(inputs, p, over[p][k])
        res = _SOLVE(as_arrays(inputs), True, True)
        status = int(res.contact.status)
        seen.add(ks_jax.status_text(status))
        assert r["status"][index] == status, index
        for path in outputs:
            want = expected(res, path)
            got = np.asarray(r[path][index], float)
            if path == "contact.sliding" and status >= ks_jax.types.INVALID_NONFINITE:
                continue
            np.testing.assert_allclose(got, want, rtol=RTOL, atol=1e-9, err_msg=f"{path} at {index}")
    assert {"ok", "no_contact", "invalid: contact.restitution must be in [-1, 1]",
            "invalid: vehicles[1].speed must be >= 0 (reverse the course for backwards travel)"} <= seen
    assert r.status_counts["ok"] == 4  # 11 and 16 m/s, eps 0.1, the sedan at 0 ft, turning or not


def test_default_outputs_and_status(case):
    r = sweep(case, {"contact.restitution": [0.0, 0.1]})
    assert set(r) == set(DEFAULT_OUTPUTS) | {"status"}
    np.testing.assert_allclose(r["contact.impulse_magnitude"][1], 5946.847, rtol=2e-4)  # the seed chapter


def test_zip_mode_monte_carlo(case):
    rng = np.random.default_rng(3)
    n = 37
    over = {"vehicles[1].speed": rng.uniform(5, 15, n), "contact.restitution": rng.uniform(0, 0.3, n),
            "contact.point[1]": rng.uniform(-0.5, 0.5, n), "vehicles[0].inertia[2]": rng.uniform(1500, 3000, n)}
    r = sweep(case, over, outputs=OUTPUTS, mode="zip", chunk_size=8)
    assert r.shape == (n,)
    assert_matches(r, case, [(k, {p: v[k] for p, v in over.items()}) for k in (0, 7, 8, 20, 36)])
    with pytest.raises(CaseError, match="same number of values"):
        sweep(case, {"vehicles[1].speed": [1.0, 2.0], "contact.friction": [0.1]}, mode="zip")


def test_bad_rows_get_their_status_others_match(case):
    eps = np.linspace(0.0, 1.5, 7)  # 1.25 and 1.5 break the rule eps <= 1
    r = sweep(case, {"contact.restitution": eps}, outputs=OUTPUTS)
    bad = eps > 1
    assert np.all(r["status"][bad] == ks_jax.types.INVALID_RESTITUTION)
    assert np.all(r["status"][~bad] == 0)
    assert np.all(np.isnan(r["contact.impulse_magnitude"][bad]))
    assert not r["contact.sliding"][bad].any()
    assert r.status_counts["invalid: contact.restitution must be in [-1, 1]"] == bad.sum()
    assert_matches(r, case, [(k, {"contact.restitution": eps[k]}) for k in range(len(eps))])


def test_negative_speeds_get_their_status_others_match(case):
    """A case file refuses a negative speed; a sampled one gets the status, NaN results, and the other
    rows are solved. (``solve_inputs`` of one point, as an automatic-contact sweep's rows are finished,
    checked last.)"""
    speeds = np.array([-3.0, 0.0, 4.0, -0.5, 9.0])
    r = sweep(case, {"vehicles[1].speed": speeds}, outputs=OUTPUTS, chunk_size=2)
    bad = speeds < 0
    assert np.all(r["status"][bad] == ks_jax.types.INVALID_SPEED_2)
    assert np.all(np.isnan(r["contact.impulse_magnitude"][bad])) and not r["contact.sliding"][bad].any()
    assert r.status_counts["invalid: vehicles[1].speed must be >= 0 (reverse the course for backwards travel)"] == 2
    assert np.all(np.isfinite(r["contact.impulse_magnitude"][~bad]))
    assert_matches(r, case, [(k, {"vehicles[1].speed": speeds[k]}) for k in np.flatnonzero(~bad)])
    r = sweep(case, {"vehicles[0].speed": [-1.0], "vehicles[1].speed": [-1.0]})
    assert r["status"][0, 0] == ks_jax.types.INVALID_SPEED_1  # the first vehicle's reason first
    res = ks_jax.solve_inputs(as_arrays(set_input(case.inputs, "vehicles[1].speed", -1.0)))
    assert int(res.contact.status) == ks_jax.types.INVALID_SPEED_2
    assert all(np.isnan(x).all() for x in jax.tree_util.tree_leaves(res) if np.asarray(x).dtype.kind == "f")
    inputs = set_input(case.inputs, "vehicles[0].mass", -5.0)
    res = ks_jax.solve_inputs(as_arrays(set_input(inputs, "vehicles[1].speed", -1.0)))
    assert int(res.contact.status) == ks_jax.types.INVALID_MASS_1  # an exchange input's reason first


def test_yaw_turns_the_course_where_the_case_gives_none(case):
    """Sweeping a yaw gives what solving the case file written with that yaw gives (its course
    defaults to the yaw, MODEL.md section 2); with a course in the file, only the body turns."""
    yaws = np.radians([0.0, 20.0, -35.0])
    r = sweep(case, {"vehicles[1].yaw": yaws}, outputs=OUTPUTS)
    raw = json.loads(SEED0.read_text())
    for k, yaw in enumerate(yaws):
        raw["vehicles"][1]["yaw"] = f"{float(np.degrees(yaw))!r} deg"
        want = ks_jax.solve(ks_jax.case.case_from_dict(raw)).result
        for path in OUTPUTS:
            np.testing.assert_allclose(r[path][k], get_output(want, path), rtol=RTOL, atol=1e-9, err_msg=path)
    assert len(set(np.round(r["vehicles[0].speed_after"], 9))) == 3
    raw["vehicles"][1]["course"] = 0
    fixed = ks_jax.case.case_from_dict(raw)
    r = sweep(fixed, {"vehicles[1].yaw": yaws}, outputs=OUTPUTS)
    for k, yaw in enumerate(yaws):
        raw["vehicles"][1]["yaw"] = f"{float(np.degrees(yaw))!r} deg"
        want = ks_jax.solve(ks_jax.case.case_from_dict(raw)).result
        np.testing.assert_allclose(r["vehicles[0].speed_after"][k], want.vehicles[0].speed_after, rtol=RTOL)
    r2 = sweep(case, {"vehicles[1].yaw": yaws, "vehicles[1].course": [0.0]}, outputs=OUTPUTS)  # course held
    np.testing.assert_allclose(r2["contact.impulse_magnitude"][:, 0], r["contact.impulse_magnitude"], rtol=RTOL)


def test_cg_height_moves_the_cg_where_the_case_gives_a_2d_position(case):
    """A 2-D position puts the CG at z = cg_height (MODEL.md section 2): sweeping cg_height gives what
    solving the file with that cg_height gives (the Saturn's CG 0.24 m lower than the centroid: a pitch
    rate after); with the CG's z swept too, it stays where it is swept to."""
    heights = np.array([0.30, 0.54])
    outs = OUTPUTS + ["vehicles[0].angular_velocity_after[1]"]
    r = sweep(case, {"vehicles[0].cg_height": heights}, outputs=outs)
    raw = json.loads(SEED0.read_text())
    assert len(raw["vehicles"][0]["position"]) == 2
    for k, h in enumerate(heights):
        raw["vehicles"][0]["cg_height"] = f"{float(h)!r} m"
        want = ks_jax.solve(ks_jax.case.case_from_dict(raw)).result
        for path in outs:
            np.testing.assert_allclose(r[path][k], get_output(want, path), rtol=RTOL, atol=1e-9, err_msg=path)
    assert abs(r["vehicles[0].angular_velocity_after[1]"][0]) > 0.1
    held = sweep(case, {"vehicles[0].cg_height": heights, "vehicles[0].position[2]": [0.54]}, outputs=outs)
    np.testing.assert_allclose(held["contact.impulse_magnitude"][:, 0], r["contact.impulse_magnitude"][1], rtol=RTOL)


def test_ties_follow_the_case_as_it_is_and_paths_with_spaces(case):
    """A Case whose course (or CG height) was changed with ``set_input`` keeps that value when its yaw (or
    cg_height) is swept: the sweep at the case's own yaw is ``solve`` of that Case. A path spelled with
    spaces is the same path: a swept "vehicles[1]. course" is held as "vehicles[1].course" is, and an
    output "contact.point [0]" is the swept input "contact.point[0]"."""
    import dataclasses

    turned = dataclasses.replace(case, inputs=set_input(case.inputs, "vehicles[1].course", 0.2))
    lowered = dataclasses.replace(case, inputs=set_input(case.inputs, "vehicles[0].position[2]", 0.3))
    for c, path in ((turned, "vehicles[1].yaw"), (lowered, "vehicles[0].cg_height")):
        want = ks_jax.solve(c).result
        r = sweep(c, {path: [float(ks_jax.get_input(c.inputs, path))]}, outputs=OUTPUTS)
        for out in OUTPUTS:
            np.testing.assert_allclose(r[out][0], get_output(want, out), rtol=RTOL, atol=1e-9, err_msg=f"{path} {out}")
    yaws = np.radians([0.0, 20.0])
    spaced = sweep(case, {"vehicles[1].yaw": yaws, " vehicles[1]. course ": [0.3]}, outputs=OUTPUTS)
    plain = sweep(case, {"vehicles[1].yaw": yaws, "vehicles[1].course": [0.3]}, outputs=OUTPUTS)
    assert list(spaced.axes) == list(plain.axes)
    for out in OUTPUTS:
        np.testing.assert_array_equal(spaced[out], plain[out])
    with pytest.raises(CaseError, match=r"output 'contact.point\[0\]' is also a swept input"):
        sweep(case, {"contact.point[0]": [1.0]}, outputs=["contact.point [0]"])


def test_bad_sweep_arguments_are_refused_by_name(case):
    """What is not a sweep is refused with its field and rule, before anything is solved; a sweep too
    large to keep in memory names the memory and the way round it."""
    speed = {"vehicles[1].speed": [1.0, 2.0]}
    for kwargs, message in (
            (dict(over={3: [1.0]}), "sweep over 3: an input path is a string"),
            (dict(over=[("vehicles[1].speed", [5.0])]), r"give a mapping \{path: values\}, got list"),
            (dict(over={"contact.restitution": [True, False]}), "the values are booleans"),
            (dict(over=speed, index_range=(1,)), r"index_range = \(1,\): give two whole numbers"),
            (dict(over=speed, index_range=(0.7, 2.9)), r"index_range = \(0.7, 2.9\): lo and hi must be whole"),
            (dict(over=speed, chunk_size=2.7), "chunk_size = 2.7: must be a whole number"),
            (dict(over={f"vehicles[{i}].{f}": np.zeros(10**5) for i in (0, 1) for f in ("speed", "mass")}),
             "1e\\+20 points, more than a 64-bit index counts"),
            (dict(over={"vehicles[1].speed": np.zeros(10**6), "contact.friction": np.zeros(10**6)}),
             # 6 float64 outputs + the sliding flag + the status: 50 bytes a point, 5e13 bytes = 4.66e4 GiB
             r"keeping 1000000000000 points of 7 outputs needs 4.66e\+04 GiB, more than this machine's .*keep=False")):
        with pytest.raises(CaseError, match=message):
            sweep(case, outputs=OUTPUTS, **kwargs)
    with pytest.raises(CaseError, match="a value is missing between commas"):
        parse_over("vehicles[1].speed=1,,2")
    with pytest.raises(CaseError, match="a grid of N = 1000000000000 values needs .* GiB"):
        parse_over("vehicles[1].speed=0:1e9:1000000000000")
    part = sweep(case, {"vehicles[1].speed": np.linspace(1, 30, 10)}, mode="zip", outputs=OUTPUTS, index_range=(0, 5))
    with pytest.raises(CaseError, match="this result holds points 0..4 of a sweep"):
        part.thinned(limit=2)


def test_automatic_parts_and_swept_outputs_are_refused(case):
    auto = ks_jax.load_case(CASES / "auto_seed_000.json")
    for path in ("contact.point[0]", "contact.normal"):
        with pytest.raises(CaseError, match=rf"sweep over '{path[:13]}.*automatic in this case"):
            sweep(auto, {path: [0.0, 1.0]})
    with pytest.raises(CaseError, match=r"output 'contact.point\[0\]' is also a swept input"):
        sweep(case, {"contact.point[0]": [0.0, 1.0]}, outputs=["contact.point[0]"])


def test_index_range_and_reducing_callback(case):
    over = {"vehicles[1].speed": np.linspace(2, 20, 9), "contact.friction": np.linspace(0, 1, 6)}
    whole = sweep(case, over, outputs=["contact.energy_loss"])
    part = sweep(case, over, outputs=["contact.energy_loss"], index_range=(10, 33), chunk_size=4)
    np.testing.assert_array_equal(part["contact.energy_loss"], whole["contact.energy_loss"].ravel()[10:33])
    seen = []
    total = [0.0]

    def on_chunk(lo, hi, chunk):
        seen.append((lo, hi))
        total[0] += float(np.sum(chunk["contact.energy_loss"]))

    r = sweep(case, over, outputs=["contact.energy_loss"], chunk_size=5, on_chunk=on_chunk, keep=False)
    assert len(r) == 0 and r.points == 54
    assert seen[0] == (0, 5) and seen[-1][1] == 54
    np.testing.assert_allclose(total[0], whole["contact.energy_loss"].sum(), rtol=1e-12)


def test_bad_paths_and_arguments(case):
    with pytest.raises(CaseError, match="'sped' is not a vehicle input"):
        sweep(case, {"vehicles[1].sped": [1.0]})
    with pytest.raises(CaseError, match="not a contact result"):
        sweep(case, {"vehicles[1].speed": [1.0]}, outputs=["contact.impulse_size"])
    with pytest.raises(CaseError, match="is a vector"):
        sweep(case, {"vehicles[1].speed": [1.0]}, outputs=["contact.impulse"])
    with pytest.raises(CaseError, match="mode"):
        sweep(case, {"vehicles[1].speed": [1.0]}, mode="random")
    with pytest.raises(CaseError, match="non-empty"):
        sweep(case, {"vehicles[1].speed": []})
    with pytest.raises(CaseError, match=r"'vehicles\[1\].speed': the values must be numbers \(SI\): could not convert"):
        sweep(case, {"vehicles[1].speed": ["fast", 2.0]})
    for size in (0, -5):  # 0 is not "the default"
        with pytest.raises(CaseError, match=f"chunk_size = {size}: must be positive"):
            sweep(case, {"vehicles[1].speed": [1.0]}, chunk_size=size)


def test_parse_over_units():
    path, v = parse_over("vehicles[1].speed=10mph:60mph:51")
    assert path == "vehicles[1].speed" and len(v) == 51
    np.testing.assert_allclose(v[[0, -1]], np.array([10, 60]) * ks_jax.units.MPH)
    _, yaw = parse_over("vehicles[0].yaw=0:90:3")  # bare angles are degrees
    np.testing.assert_allclose(yaw, np.radians([0, 45, 90]))
    _, rate = parse_over("vehicles[0].yaw_rate=10,20")  # bare rates are deg/s
    np.testing.assert_allclose(rate, np.radians([10, 20]))
    with pytest.raises(CaseError, match="START:STOP:N"):
        parse_over("vehicles[0].yaw")
    with pytest.raises(CaseError, match=r"vehicles\[1\].speed: START = 'nan' must be a finite number"):
        parse_over("vehicles[1].speed=nan:60mph:5")  # linspace would make every point but the last NaN
    with pytest.raises(CaseError, match="'-inf mph' is not a '<number> <unit>' quantity"):
        parse_over("vehicles[1].speed=10mph:-inf mph:5")


def test_parse_over_random_values():
    from ks_jax.sweeps import Draws, draw_over

    mph = 1609.344 / 3600
    assert parse_over("vehicles[1].speed=normal:20mph:2mph") == ("vehicles[1].speed",
                                                                  Draws("vehicles[1].speed", "normal", 20 * mph, 2 * mph))
    _, d = parse_over("vehicles[0].yaw=uniform:-5:5")  # bare angles are degrees, as everywhere
    assert (d.law, d.a, d.b) == ("uniform", np.radians(-5), np.radians(5))
    for spec, words in (("normal:0.1:-0.02", "SD must be >= 0"), ("uniform:0.3:0.1", "LO must not exceed HI"),
                        ("uniform:0:nan", "HI = 'nan' must be a finite number"), ("normal:1", "expected normal:MEAN:SD")):
        with pytest.raises(CaseError, match=words):
            parse_over(f"contact.restitution={spec}")
    specs = [parse_over("contact.restitution=uniform:0:0.3"), parse_over("contact.friction=0.4,0.5,0.6")]
    with pytest.raises(CaseError, match="need --samples N"):
        draw_over(specs, None, None, 0)
    with pytest.raises(CaseError, match="not a grid"):
        draw_over(specs, "grid", 3, 0)
    with pytest.raises(CaseError, match="--samples N is for random values"):
        draw_over(specs[1:], None, 3, 0)
    over, mode = draw_over(specs, None, 3, 11)
    assert mode == "zip" and list(over) == ["contact.restitution", "contact.friction"]
    np.testing.assert_array_equal(over["contact.restitution"], np.random.default_rng(11).uniform(0, 0.3, 3))
    np.testing.assert_array_equal(over["contact.friction"], [0.4, 0.5, 0.6])


def test_cli_monte_carlo_sweep(tmp_path, capsys, case):
    """Random inputs from the command line: the draws are numpy's default_rng(seed) in the order of the
    --over options, they are stored as the axes of the file, and the results are the sweep of those
    samples; the normal draws' mean is 20 mph within five standard errors."""
    out = tmp_path / "mc.npz"
    argv = ["sweep", str(SEED0), "--over", "vehicles[1].speed=normal:20mph:2mph", "--over",
            "contact.restitution=uniform:0.05:0.15", "--samples", "2000", "--seed", "7",
            "--output", "vehicles[0].delta_v_magnitude", "--out", str(out)]
    assert main(argv) == 0
    assert "2000 points (zip" in capsys.readouterr().out
    mph = 1609.344 / 3600
    rng = np.random.default_rng(7)
    speed, eps = rng.normal(20 * mph, 2 * mph, 2000), rng.uniform(0.05, 0.15, 2000)
    data = np.load(out)
    np.testing.assert_array_equal(data["axis:vehicles[1].speed"], speed)
    np.testing.assert_array_equal(data["axis:contact.restitution"], eps)
    assert abs(speed.mean() / mph - 20) < 5 * 2 / np.sqrt(2000)
    kept = sweep(case, {"vehicles[1].speed": speed, "contact.restitution": eps}, mode="zip",
                 outputs=["vehicles[0].delta_v_magnitude"])
    np.testing.assert_array_equal(data["vehicles[0].delta_v_magnitude"], kept["vehicles[0].delta_v_magnitude"])


def test_cli_writes_csv_and_npz(tmp_path, capsys):
    csv_path, npz_path = tmp_path / "r.csv", tmp_path / "r.npz"
    args = [str(SEED1), "--over", "vehicles[1].speed=10mph:30mph:5", "--over", "contact.restitution=0:1.5:4",
            "--output", "contact.impulse_magnitude", "--output", "vehicles[0].delta_v_magnitude"]
    assert main(["sweep", *args, "--out", str(csv_path)]) == 0
    out = capsys.readouterr().out
    assert "20 points" in out and "ok: 15" in out and "invalid: contact.restitution" in out
    lines = list(csv.reader(csv_path.read_text().splitlines()))
    assert lines[0] == ["vehicles[1].speed", "contact.restitution", "contact.impulse_magnitude",
                                   "vehicles[0].delta_v_magnitude", "status", "status_text"]
    assert len(lines) == 21
    assert main(["sweep", *args, "--out", str(npz_path)]) == 0
    data = np.load(npz_path)
    assert data["contact.impulse_magnitude"].shape == (5, 4)
    row = lines[1 + 4 * 2 + 1]  # speed index 2, restitution index 1
    np.testing.assert_allclose(float(row[2]), data["contact.impulse_magnitude"][2, 1], rtol=1e-15)
    np.testing.assert_allclose(data["axis:vehicles[1].speed"], np.linspace(10, 30, 5) * ks_jax.units.MPH)


def read_table(path):
    """Columns of a .csv or .parquet sweep file as NumPy arrays (status_text as str)."""
    if path.suffix == ".parquet":
        table = pytest.importorskip("pyarrow.parquet").read_table(path)
        return {c: table[c].to_numpy(zero_copy_only=False) for c in table.column_names}
    with path.open(newline="") as f:
        names, *rows = list(csv.reader(f))

    def column(values):
        flags = {v.lower() for v in values}
        if flags <= {"true", "false", ""} and flags != {""}:  # the csv module writes True, pyarrow true
            read = np.array([{"true": True, "false": False}.get(v.lower()) for v in values], dtype=object)
            return read if "" in flags else read.astype(bool)  # an empty field (invalid row): None
        try:
            return np.array(values, dtype=float)
        except ValueError:
            return np.array(values, dtype=str)

    return {n: column([r[k] for r in rows]) for k, n in enumerate(names)}


@pytest.mark.parametrize("suffix", [".csv", ".npz", ".parquet"])
def test_cli_streams_the_same_file_as_a_kept_sweep(tmp_path, capsys, suffix):
    """``ks-jax sweep`` writes chunk by chunk (7 points a chunk here, so 39 chunks over a grid of 273
    points with invalid rows); the file holds what ``write_results`` writes from the same sweep kept
    in memory, and its values equal the sweep's."""
    if suffix == ".parquet":
        pytest.importorskip("pyarrow")
    outs = ["contact.impulse_magnitude", "contact.sliding", "vehicles[1].delta_v[0]"]
    over = ["vehicles[1].speed=2:30:21", "contact.restitution=0:1.2:13"]  # restitution > 1: invalid rows
    args = ["sweep", str(SEED0), *sum((["--over", o] for o in over), []), *sum((["--output", o] for o in outs), []),
            "--chunk-size", "7", "--out", str(tmp_path / f"cli{suffix}")]
    assert main(args) == 0
    capsys.readouterr()
    kept = sweep(ks_jax.load_case(SEED0), dict(parse_over(o) for o in over), outputs=outs)
    assert 0 < kept.status_counts["ok"] < 273
    write_results(kept, tmp_path / f"kept{suffix}")
    if suffix == ".npz":
        a, b = np.load(tmp_path / "cli.npz"), np.load(tmp_path / "kept.npz")
        assert sorted(a.files) == sorted(b.files)
        for k in a.files:
            np.testing.assert_array_equal(a[k], b[k], err_msg=k)
        for p in outs + ["status"]:
            np.testing.assert_array_equal(a[p], kept[p], err_msg=p)
        return
    a, b = read_table(tmp_path / f"cli{suffix}"), read_table(tmp_path / f"kept{suffix}")
    assert list(a) == ["vehicles[1].speed", "contact.restitution", *outs, "status", "status_text"] == list(b)
    for k in a:
        np.testing.assert_array_equal(a[k], b[k], err_msg=k)
    np.testing.assert_array_equal(a["vehicles[1].delta_v[0]"], kept["vehicles[1].delta_v[0]"].ravel())
    # the grid's values as typed: 2, 3.4, ..., 30 and 0, 0.1, ..., 1.2 (parse_over)
    speeds, eps = ([float(f"{a + step * k:.12g}") for k in range(n)] for a, step, n in ((2, 1.4, 21), (0, 0.1, 13)))
    np.testing.assert_array_equal(a["vehicles[1].speed"], np.repeat(speeds, 13))
    np.testing.assert_array_equal(a["contact.restitution"], np.tile(eps, 21))
    assert list(a["status_text"]) == [ks_jax.status_text(int(c)) for c in a["status"]]
    assert {"ok", "separating", "invalid: contact.restitution must be in [-1, 1]"} == set(a["status_text"])
    assert_no_flag_on_invalid_rows(a, kept)


def assert_no_flag_on_invalid_rows(table, result):
    """A flag (``contact.sliding``) of an invalid row is an empty field (.csv) or null (.parquet): its
    numbers are NaN, and "false" would read as a result; every other row holds the sweep's flag."""
    invalid = table["status"] >= 10
    assert invalid.any() and not invalid.all()
    flags = table["contact.sliding"]
    assert all(f is None for f in flags[invalid])
    assert [bool(f) for f in flags[~invalid]] == np.ravel(result["contact.sliding"])[~invalid].tolist()
    assert all(isinstance(f, (bool, np.bool_)) for f in flags[~invalid])


def test_csv_reads_back_the_same_with_or_without_pyarrow(tmp_path, monkeypatch):
    """A .csv is written by pyarrow where it is installed, else by the csv module: the two files
    differ in text (1 against 1.0, true against True, quoting) but read back to the sweep's values,
    bit for bit, NaN of invalid rows included, in a grid and in zipped samples; float32 results read
    back as float32 (pyarrow writes their shortest text, 0.1 for float32(0.1), the csv module the
    float64 value's)."""
    pytest.importorskip("pyarrow")
    import ks_jax.sweeps as sweeps_module

    outs = ["contact.impulse_magnitude", "contact.sliding", "vehicles[0].pdof"]
    case = ks_jax.load_case(SEED0)
    rng = np.random.default_rng(3)
    grid = sweep(case, {"contact.normal": np.linspace(0, 1.2, 9), "contact.friction": np.linspace(0.1, 0.6, 7)},
                 outputs=outs)
    zipped = sweep(case, {"vehicles[1].speed": rng.uniform(1, 40, 50), "contact.restitution": rng.uniform(0, 1.3, 50)},
                   outputs=outs, mode="zip")
    narrow = sweep(case, {"vehicles[1].speed": np.linspace(2, 30, 11)}, outputs=outs, output_dtype=np.float32)
    assert grid["contact.sliding"].any() and not grid["contact.sliding"].all()
    assert np.isnan(zipped["contact.impulse_magnitude"]).any()  # restitution > 1: invalid rows
    assert narrow["contact.impulse_magnitude"].dtype == np.float32
    for name, result in (("grid", grid), ("zip", zipped), ("float32", narrow)):
        write_results(result, tmp_path / f"{name}_arrow.csv")
        with monkeypatch.context() as m:
            m.setattr(sweeps_module, "_arrow_csv", lambda: None)
            write_results(result, tmp_path / f"{name}_csv.csv")
        a, b = read_table(tmp_path / f"{name}_arrow.csv"), read_table(tmp_path / f"{name}_csv.csv")
        assert (tmp_path / f"{name}_arrow.csv").read_text() != (tmp_path / f"{name}_csv.csv").read_text()
        assert list(a) == list(b) == [*result.inputs(), *outs, "status", "status_text"]
        if name == "zip":  # with invalid rows
            assert_no_flag_on_invalid_rows(a, result)
            assert_no_flag_on_invalid_rows(b, result)
        for p in outs:  # as the sweep stored them (float32 read as float32; None, a missing flag: False)
            a[p], b[p] = (x[p].astype(result[p].dtype) for x in (a, b))
        for k in a:
            np.testing.assert_array_equal(a[k], b[k], err_msg=f"{name}: {k}")
        for p in outs:
            np.testing.assert_array_equal(a[p], np.ravel(result[p]), err_msg=f"{name}: {p}")
        for p, v in result.inputs().items():
            np.testing.assert_array_equal(a[p], np.ravel(v), err_msg=f"{name}: {p}")


def test_large_csv_without_pyarrow_suggests_it(tmp_path, capsys, monkeypatch):
    """Without pyarrow a large .csv is written by the csv module, and the command says how to write it
    faster; the file holds every point either way."""
    pytest.importorskip("pyarrow")
    import ks_jax.sweeps as sweeps_module

    hint = "written several times faster with pyarrow installed"
    monkeypatch.setattr(sweeps_module, "CSV_HINT_POINTS", 40)
    args = ["sweep", str(SEED0), "--over", "vehicles[1].speed=2:30:8", "--over", "contact.friction=0:1:5",
            "--output", "contact.impulse_magnitude", "--no-progress"]
    assert main([*args, "--out", str(tmp_path / "a.csv")]) == 0
    assert hint not in capsys.readouterr().out  # pyarrow wrote it
    monkeypatch.setattr(sweeps_module, "_arrow_csv", lambda: None)
    assert main([*args, "--out", str(tmp_path / "b.csv")]) == 0
    assert hint in capsys.readouterr().out
    monkeypatch.setattr(sweeps_module, "CSV_HINT_POINTS", 41)
    assert main([*args, "--out", str(tmp_path / "c.csv")]) == 0
    assert hint not in capsys.readouterr().out  # fewer points than the threshold
    assert len(read_table(tmp_path / "b.csv")["status"]) == 40
    np.testing.assert_array_equal(read_table(tmp_path / "a.csv")["contact.impulse_magnitude"],
                                  read_table(tmp_path / "b.csv")["contact.impulse_magnitude"])


def test_swept_values_in_us_units_read_as_typed(tmp_path, capsys):
    """A value typed in mph or ft comes back from SI as 24.999999999999996 mph or 1.9999999999999996 ft;
    the file (and the .npz axis) give it as typed, and leave values that are not short decimals as
    converted (within 2 units in the last place)."""
    args = ["sweep", str(SEED1), "--over", "vehicles[1].speed=10mph:30mph:5",
            "--over", "vehicles[0].cg_height=1ft:3ft:7", "--output", "contact.impulse_magnitude", "--units", "us",
            "--no-progress"]
    assert main([*args, "--out", str(tmp_path / "us.csv")]) == 0
    assert main([*args, "--out", str(tmp_path / "us.npz")]) == 0
    capsys.readouterr()
    # a grid's own values: linspace's rounding undone, to 2 ulp (0.05, not 0.049999999999999996)
    assert np.linspace(0, 0.3, 7)[1] != 0.05
    np.testing.assert_array_equal(parse_over("contact.restitution=0:0.3:7")[1], [0, 0.05, 0.1, 0.15, 0.2, 0.25, 0.3])
    np.testing.assert_allclose(parse_over("vehicles[1].speed=3:60:7")[1], np.linspace(3, 60, 7), rtol=5e-16, atol=0)
    # converted from a unit (deg/s here): solved as converted, and the US file types it back
    np.testing.assert_array_equal(parse_over("vehicles[0].yaw_rate=-30:30:3")[1], np.radians([-30.0, 0.0, 30.0]))
    miles, feet = np.linspace(10 * U.MPH, 30 * U.MPH, 5) / U.MPH, np.linspace(1 * U.FT, 3 * U.FT, 7) / U.FT
    assert miles[3] != 25.0 and feet[3] != 2.0  # what plain conversion gives
    table, npz = read_table(tmp_path / "us.csv"), np.load(tmp_path / "us.npz")
    for speeds, heights in ((table["vehicles[1].speed [mph]"][::7], table["vehicles[0].cg_height [ft]"][:7]),
                            (npz["axis:vehicles[1].speed [mph]"], npz["axis:vehicles[0].cg_height [ft]"])):
        np.testing.assert_array_equal(speeds, [10.0, 15.0, 20.0, 25.0, 30.0])
        np.testing.assert_array_equal(heights[::3], [1.0, 2.0, 3.0])
        np.testing.assert_allclose(heights, feet, rtol=4e-16)
        assert heights[1] != round(heights[1], 14)  # 4/3 ft: as converted


def test_files_in_us_units(tmp_path, capsys):
    """``--units us`` writes the same sweep in mph, deg, ft lbf, lbf s, deg/s (the unit in each
    column's name), against the SI file divided by the units' definitions (1 mph = 0.44704 m/s,
    1 lbf = 4.4482216152605 N, 1 ft = 0.3048 m); dimensionless columns, booleans and the
    status unchanged, in .csv and .npz, and in ``SweepResult.table``."""
    mph, lbf, ft = 0.44704, 4.4482216152605, 0.3048
    outs = {"contact.energy_loss": ("ft lbf", lbf * ft), "contact.impulse_magnitude": ("lbf s", lbf),
            "vehicles[0].delta_v_magnitude": ("mph", mph), "vehicles[0].pdof": ("deg", 1.0),
            "vehicles[1].yaw_rate_after": ("deg/s", np.pi / 180), "contact.sliding": (None, None)}
    args = [str(SEED1), "--over", "vehicles[1].speed=10mph:30mph:3", "--over", "contact.normal=0:40:3",
            "--over", "contact.restitution=0.1,1.2", *sum((["--output", o] for o in outs), []), "--no-progress"]
    for units, suffix in (("si", ".csv"), ("us", ".csv"), ("si", ".npz"), ("us", ".npz")):
        assert main(["sweep", *args, "--units", units, "--out", str(tmp_path / f"{units}{suffix}")]) == 0
    capsys.readouterr()
    si, us = read_table(tmp_path / "si.csv"), read_table(tmp_path / "us.csv")
    si_npz, us_npz = np.load(tmp_path / "si.npz"), np.load(tmp_path / "us.npz")
    assert list(us)[:3] == ["vehicles[1].speed [mph]", "contact.normal [deg]", "contact.restitution"]
    np.testing.assert_array_equal(us["vehicles[1].speed [mph]"], np.repeat([10.0, 20.0, 30.0], 6))
    np.testing.assert_array_equal(us["contact.normal [deg]"], np.tile(np.repeat([0.0, 20.0, 40.0], 2), 3))
    np.testing.assert_array_equal(us_npz["axis:vehicles[1].speed [mph]"], [10.0, 20.0, 30.0])
    np.testing.assert_array_equal(us_npz["axis:contact.normal [deg]"], [0.0, 20.0, 40.0])
    for p, (unit, scale) in outs.items():
        name = p if unit is None else f"{p} [{unit}]"
        if unit is None:
            np.testing.assert_array_equal(us[name], si[p])
            np.testing.assert_array_equal(us_npz[name], si_npz[p])
            continue
        assert np.isnan(si[p]).sum() == 9 and np.isnan(us[name]).sum() == 9  # restitution 1.2: invalid rows
        np.testing.assert_allclose(us[name], si[p] / scale, rtol=1e-13, atol=1e-12, err_msg=p)
        np.testing.assert_allclose(us_npz[name], si_npz[p] / scale, rtol=1e-13, atol=1e-12, err_msg=p)
    for k in ("status", "status_text"):
        np.testing.assert_array_equal(us[k], si[k])
    # the same columns from a kept sweep, in memory (SweepResult.table)
    kept = sweep(ks_jax.load_case(SEED1), {"vehicles[1].speed": np.array([10, 20, 30]) * mph,
                                           "contact.normal": np.radians([0, 20, 40]),
                                           "contact.restitution": np.array([0.1, 1.2])}, outputs=list(outs))
    table_si, table_us = kept.table(), kept.table(units="us")
    assert set(table_us) == set(us) and set(table_si) == set(si)
    for table, file in ((table_us, us), (table_si, si)):
        for k in table:
            if k in ("contact.sliding", "status_text"):  # None on the invalid rows, in the file and in the table
                np.testing.assert_array_equal(table[k], file[k], err_msg=k)
            else:
                np.testing.assert_allclose(table[k], file[k], rtol=1e-13, atol=1e-12, err_msg=k)
    with pytest.raises(CaseError, match="units = 'imperial': the units of a results file must be 'si' or 'us'"):
        write_results(kept, tmp_path / "x.csv", units="imperial")
    assert not (tmp_path / "x.csv").exists()
    with pytest.raises(ValueError, match="units = 'metric': units must be 'si' or 'us'"):
        kept.table(units="metric")
    streamed = sweep(ks_jax.load_case(SEED1), {"contact.restitution": np.array([0.1, 0.2])}, keep=False)
    with pytest.raises(CaseError, match="this sweep kept no results"):
        streamed.table()


def test_writer_errors_keep_other_files(tmp_path, capsys):
    """A sweep that fails leaves no file of its own and an earlier file as it was, even after some
    chunks were written; a writer refuses chunks out of order and an incomplete file."""
    out = tmp_path / "r.csv"
    out.write_text("earlier results\n")
    code = main(["sweep", str(SEED0), "--mode", "zip", "--over", "vehicles[1].speed=1,2,3",
                 "--over", "contact.restitution=0,0.1", "--out", str(out)])
    assert code == 2 and "same number of values" in capsys.readouterr().err
    assert out.read_text() == "earlier results\n"
    for suffix in (".csv", ".npz"):
        (tmp_path / f"w{suffix}").write_text("earlier results\n")  # kept until a new file is complete
        w = ResultWriter(tmp_path / f"w{suffix}", {"contact.friction": np.array([0.1, 0.2, 0.3])}, "grid", (3,))
        w.chunk(0, 1, {"contact.impulse_magnitude": np.array([1.0]), "status": np.array([0], np.int8)})
        with pytest.raises(CaseError, match="arrived after 1 of 3"):
            w.chunk(2, 3, {"contact.impulse_magnitude": np.array([1.0]), "status": np.array([0], np.int8)})
        with pytest.raises(CaseError, match="1 of 3 points written"):
            w.close()
        w.abort()
        assert (tmp_path / f"w{suffix}").read_text() == "earlier results\n"
        assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith(".")) == []  # nothing left behind
    empty = sweep(ks_jax.load_case(SEED0), {"contact.friction": [0.1, 0.2]}, index_range=(1, 1))
    with pytest.raises(CaseError, match="no points to write"):
        write_results(empty, tmp_path / "empty.csv")
    assert not (tmp_path / "empty.csv").exists()


def test_cli_bad_path_is_a_clear_error(tmp_path, capsys):
    code = main(["sweep", str(SEED1), "--over", "vehicles[1].sped=1:2:3", "--out", str(tmp_path / "x.csv")])
    err = capsys.readouterr().err
    assert code == 2 and "'sped' is not a vehicle input" in err and "Traceback" not in err
    code = main(["sweep", str(SEED1), "--over", "vehicles[1].speed=1:2:3", "--out", str(tmp_path / "x.xlsx")])
    assert code == 2 and "unknown file type" in capsys.readouterr().err


SHARDED = r"""
import json, sys, jax, numpy as np
jax.config.update("jax_enable_x64", True)
import ks_jax
from ks_jax import sweep
assert len(jax.devices()) == 2, jax.devices()
case = ks_jax.load_case(sys.argv[1])
over = {"vehicles[1].speed": np.linspace(2, 20, 11), "contact.restitution": np.linspace(0, 1.2, 7)}
outs = ["contact.impulse_magnitude", "vehicles[0].delta_v[1]", "contact.sliding"]
a = sweep(case, over, outputs=outs, chunk_size=3)                                  # 2 devices, 6 rows a chunk
b = sweep(case, over, outputs=outs, chunk_size=1000, devices=jax.devices()[:1])   # one device
print(json.dumps({k: [np.asarray(a[k]).tolist(), np.asarray(b[k]).tolist()] for k in outs + ["status"]}))
"""


def test_sharded_equals_unsharded(case):
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=2", JAX_PLATFORMS="cpu")
    proc = subprocess.run([sys.executable, "-c", SHARDED, str(SEED0)], capture_output=True, text=True, env=env,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    data = json.loads(proc.stdout.strip().splitlines()[-1])
    here = sweep(case, {"vehicles[1].speed": np.linspace(2, 20, 11), "contact.restitution": np.linspace(0, 1.2, 7)},
                 outputs=["contact.impulse_magnitude", "vehicles[0].delta_v[1]", "contact.sliding"])
    for k, (sharded, single_device) in data.items():
        sharded = np.array(sharded, dtype=float)
        np.testing.assert_array_equal(sharded, np.array(single_device, dtype=float), err_msg=k)
        np.testing.assert_allclose(sharded, np.asarray(here[k], dtype=float), rtol=1e-13, err_msg=k)


@pytest.mark.parametrize("sig, code", [("SIGTERM", 143), ("SIGINT", 130)])
def test_a_killed_sweep_leaves_the_earlier_file(tmp_path, sig, code):
    """``ks-jax sweep`` stopped by a kill (a batch system's SIGTERM) or Ctrl-C while it writes: the
    unfinished file is removed, the earlier --out is as it was, the exit status says so (128 + signal,
    130 for Ctrl-C) and no traceback is printed."""
    import signal
    import time

    out = tmp_path / "out.csv"
    out.write_text("earlier results\n")
    env = dict(os.environ, JAX_PLATFORMS="cpu")
    proc = subprocess.Popen([sys.executable, "-m", "ks_jax.cli", "sweep", str(SEED1), "--over",
                             "vehicles[1].speed=1:40:3000", "--over", "contact.restitution=0:0.5:1000",
                             "--out", str(out), "--no-progress"], stderr=subprocess.PIPE, text=True, env=env)
    partial = tmp_path / ".out.csv.partial"
    deadline = time.monotonic() + 120
    while not partial.exists() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
    assert partial.exists(), "the sweep never started writing"
    proc.send_signal(getattr(signal, sig))
    err = proc.communicate(timeout=120)[1]
    assert proc.returncode == code, err[-2000:]
    assert "Traceback" not in err
    assert out.read_text() == "earlier results\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.csv"]


def test_a_signal_that_a_library_swallowed_still_stops_the_command(monkeypatch):
    """Ctrl-C raises KeyboardInterrupt wherever the command's main thread is, possibly inside a library that
    catches it (``test_a_killed_sweep_leaves_the_earlier_file`` once saw a sweep finish with exit status 0
    after its SIGINT). The command keeps the signal, and ``raise_if_stopped``, called before each chunk is
    written and before the file is finished, raises it again: KeyboardInterrupt for SIGINT, exit status
    128 + 15 for SIGTERM."""
    import signal

    from ks_jax import cli

    monkeypatch.setattr(cli, "_SIGNALLED", [])
    cli.raise_if_stopped()  # no signal: nothing
    for sig, raised in ((signal.SIGINT, KeyboardInterrupt), (signal.SIGTERM, SystemExit)):
        try:
            cli._stopped(sig, None)  # as the handler runs, inside a library that swallows what it raises
        except BaseException:
            pass
        with pytest.raises(raised) as info:
            cli.raise_if_stopped()
        assert raised is KeyboardInterrupt or info.value.code == 128 + 15


def test_a_long_sweep_shows_a_bar(capsys, monkeypatch):
    """progress=None: a bar on stderr once the sweep has run PROGRESS_DELAY seconds (any size: a million
    points with automatic contact run for 5-15 s), none before; progress=False: never."""
    import ks_jax.sweeps as sweeps_module

    case = ks_jax.load_case(SEED1)
    over = {"vehicles[1].speed": np.linspace(2, 30, 40)}
    monkeypatch.setattr(sweeps_module, "PROGRESS_DELAY", 3600.0)
    sweep(case, over, chunk_size=8)
    assert "ks-jax sweep" not in capsys.readouterr().err
    monkeypatch.setattr(sweeps_module, "PROGRESS_DELAY", 0.0)
    sweep(case, over, chunk_size=8)
    err = capsys.readouterr().err
    assert "ks-jax sweep" in err and ("40.0/40.0" in err or "40/40" in err)  # tqdm, or the plain line
    sweep(case, over, chunk_size=8, progress=False)
    assert capsys.readouterr().err == ""


def test_one_input_named_twice_is_refused(tmp_path, capsys):
    """yaw_rate is angular_velocity[2], inertia[0][1] is inertia[1][0], a space changes nothing, and a
    path given twice is one input: the later would override the earlier under the earlier's name."""
    case = ks_jax.load_case(SEED1)
    for over, words in (({"vehicles[0].yaw_rate": [0, 1], "vehicles[0].angular_velocity[2]": [0, 1]},
                         "'vehicles[0].angular_velocity[2]' and 'vehicles[0].yaw_rate'"),
                        ({"vehicles[1].speed": [1.0], "vehicles[1]. speed": [2.0]},
                         "'vehicles[1]. speed' and 'vehicles[1].speed'"),
                        ({"vehicles[0].inertia[0][1]": [0.0], "vehicles[0].inertia[1][0]": [1.0]},
                         "'vehicles[0].inertia[1][0]' and 'vehicles[0].inertia[0][1]'")):
        with pytest.raises(CaseError, match=re.escape(words + ": both name the same input")):
            sweep(case, over)
    code = main(["sweep", str(SEED1), "--over", "vehicles[1].speed=10mph:30mph:3", "--over", "vehicles[1].speed=1,2",
                 "--out", str(tmp_path / "x.csv")])
    assert code == 2 and "--over 'vehicles[1].speed' twice: both name the same input" in capsys.readouterr().err
    assert not (tmp_path / "x.csv").exists()


def test_a_product_of_inertia_keeps_the_tensor_symmetric():
    """Sweeping inertia[0][1] sets [1][0] too (a product of inertia is one number of a symmetric
    tensor): the rows are solved, and equal single solves of the case with both entries set."""
    case = ks_jax.load_case(SEED1)
    values = [0.0, 10.0, 100.0]
    r = sweep(case, {"vehicles[0].inertia[0][1]": values}, outputs=["vehicles[0].delta_yaw_rate", "contact.impulse[1]"])
    assert r["status"].tolist() == [0, 0, 0]
    for k, v in enumerate(values):
        inputs = as_arrays(case.inputs)
        inertia = jnp.asarray(inputs.vehicles[0].inertia).at[0, 1].set(v).at[1, 0].set(v)
        one = ks_jax.solve_inputs(inputs._replace(vehicles=(inputs.vehicles[0]._replace(inertia=inertia),
                                                            inputs.vehicles[1])))
        for p in ("vehicles[0].delta_yaw_rate", "contact.impulse[1]"):
            np.testing.assert_allclose(r[p][k], get_output(one, p), rtol=RTOL, atol=1e-12, err_msg=f"{p} at {v}")


def test_file_columns_follow_the_outputs_asked(tmp_path, capsys):
    """The command writes the outputs in the order of --output, as write_results does for the same
    sweep (the compiled program returns them sorted by name)."""
    outs = ["vehicles[1].pdof", "contact.energy_loss", "vehicles[0].delta_v[1]"]
    args = ["sweep", str(SEED1), "--over", "vehicles[1].speed=10mph:30mph:3", *sum((["--output", o] for o in outs), []),
            "--out", str(tmp_path / "cli.csv")]
    assert main(args) == 0
    capsys.readouterr()
    write_results(sweep(ks_jax.load_case(SEED1), {"vehicles[1].speed": np.linspace(10, 30, 3) * U.MPH}, outputs=outs),
                  tmp_path / "kept.csv")
    cli, kept = (list(csv.reader((tmp_path / n).read_text().splitlines()))[0] for n in ("cli.csv", "kept.csv"))
    assert cli == kept == ["vehicles[1].speed", *outs, "status", "status_text"]


def test_undefined_results_are_nan_and_named(case, tmp_path, capsys):
    """Where a solved point has no impulse (restitution -1: (1 + eps) J_c = 0 by hand), its PDOF and impulse
    direction are undefined: NaN in the sweep, not the stand-in 0 (a frontal impact), as null in the JSON of
    ``ks-jax solve``; with the centroid 10 ft up, above both boxes, both crushes are 0 and EES is undefined
    (MODEL.md section 4). The summary counts them and says why."""
    over = {"contact.restitution": np.array([-1.0, 0.1]), "contact.point[2]": np.array([0.54, 10 * U.FT])}
    outs = ["vehicles[0].pdof", "vehicles[1].pdof_clock", "contact.impulse_azimuth", "vehicles[0].ees",
            "contact.impulse_magnitude"]
    r = sweep(case, over, outputs=outs)
    assert r.status_counts == {"ok": 4}
    assert np.all(r["contact.impulse_magnitude"][0] == 0) and np.all(r["contact.impulse_magnitude"][1] > 0)
    for p in outs[:3]:
        assert np.isnan(r[p][0]).all() and np.isfinite(r[p][1]).all(), p
    np.testing.assert_allclose(r["vehicles[0].pdof"][1], 180.0, atol=5.0)  # struck from behind
    assert np.isnan(r["vehicles[0].ees"][:, 1]).all() and np.isfinite(r["vehicles[0].ees"][:, 0]).all()
    assert r.undefined == {"vehicles[0].pdof": 2, "vehicles[1].pdof_clock": 2, "contact.impulse_azimuth": 2,
                           "vehicles[0].ees": 2}
    text = r.summary()
    assert "undefined (NaN) at 2 solved points: vehicles[0].pdof, where no impulse was exchanged" in text
    assert "undefined (NaN) at 2 solved points: vehicles[0].ees, where both crushes are 0" in text
    code = main(["sweep", str(SEED0), "--over", "contact.restitution=-1,0.1", "--output", "vehicles[0].pdof",
                 "--out", str(tmp_path / "u.csv")])
    out = capsys.readouterr().out
    assert code == 0 and "undefined (NaN) at 1 solved point: vehicles[0].pdof, where no impulse" in out


def test_cli_over_refuses_a_dropped_stop_and_non_finite_values():
    with pytest.raises(CaseError, match="N = 1 would solve START alone and leave STOP out"):
        parse_over("vehicles[1].speed=60mph:10mph:1")
    assert parse_over("vehicles[1].speed=10mph:10mph:1")[1].tolist() == [10 * U.MPH]
    for spec in ("contact.restitution=0.1,nan", "contact.restitution=inf,0.2"):
        with pytest.raises(CaseError, match="must be a finite number"):
            parse_over(spec)


FAR_SCENES = r"""
import json, sys, warnings
import ks_jax
from ks_jax.case import CaseWarning, case_from_dict
OUT = ["contact.impulse_magnitude", "contact.energy_loss", "vehicles[0].crush", "vehicles[1].crush",
       "vehicles[0].ees", "vehicles[1].ees", "contact.point[0]", "contact.point[1]"]
out = {}
with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always")
    for name, d in json.loads(sys.argv[1]).items():
        case = case_from_dict(d)
        OUT = OUT[:8] + ["contact.time"] * case.auto_point  # a first-contact time: automatic contact only
        r = ks_jax.solve(case).result
        x = float(case.inputs.vehicles[1].position[0])
        s = ks_jax.sweep(case, {"vehicles[1].position[0]": [x - 0.1, x, x + 0.1], "contact.restitution": [0.0, 0.1]},
                         outputs=OUT)
        out[name] = {"solve": {p: float(ks_jax.case.get_output(r, p)) for p in OUT},
                     "point_dtype": str(r.contact.point.dtype), "sweep": {p: s[p].ravel().tolist() for p in OUT},
                     "sweep_dtype": [str(s[p].dtype) for p in OUT]}
    out["warned"] = [str(w.message) for w in caught if w.category is CaseWarning]
    ks_jax.sweep(case, {"vehicles[1].position[0]": [x, x + 5000.0]})
    out["warned_wide"] = [str(w.message) for w in caught if w.category is CaseWarning][len(out["warned"]):]
print(json.dumps(out))
"""


def _moved(d, dx, dy):
    """Case dict ``d`` (positions in ft strings or SI numbers) with the scene moved by (dx, dy) m."""
    d = json.loads(json.dumps(d))
    q = lambda v, k: (ks_jax.units.parse_quantity(v, "length") if isinstance(v, str) else v) + k  # noqa: E731
    for v in d["vehicles"]:
        v["position"] = [q(v["position"][0], dx), q(v["position"][1], dy), *v["position"][2:]]
    if "point" in d["contact"]:
        p = d["contact"]["point"]
        d["contact"]["point"] = [q(p[0], dx), q(p[1], dy), p[2]]
    return d


def test_float32_scene_far_from_the_origin_is_solved_as_at_the_origin():
    """In float32 (JAX's default) a position 512 km out keeps ~3 cm, which once gave the seed chapter's
    Pontiac an EES of 2.90 mph instead of 2.21. The exchange is the same in a translated scene (MODEL.md
    section 3): solve and sweep, explicit and automatic contact, give 512 km out what they give at the
    origin, contact.point moved back (in float64), and no warning; a sweep of positions over 5 km still
    warns."""
    scenes = {}
    for label, path in (("seed", SEED0), ("tbone", CASES / "auto_tbone.json")):
        d = json.loads(path.read_text())
        scenes[label], scenes[label + " far"] = _moved(d, 0.0, 0.0), _moved(d, 512064.0, -256032.0)
    proc = subprocess.run([sys.executable, "-c", FAR_SCENES, json.dumps(scenes)], capture_output=True, text=True,
                          timeout=600, env=dict(os.environ, JAX_PLATFORMS="cpu"))
    assert proc.returncode == 0, proc.stderr[-3000:]
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert out["warned"] == []
    (wide,) = out["warned_wide"]
    assert "reaches 5e+03 m from its CGs' midpoint" in wide and "jax_enable_x64" in wide
    shift = {"contact.point[0]": 512064.0, "contact.point[1]": -256032.0}
    assert out["seed"]["solve"]["vehicles[1].ees"] / U.MPH == pytest.approx(2.213, abs=1e-3)  # the manual
    for label in ("seed", "tbone"):
        near, far = out[label], out[label + " far"]
        assert near["point_dtype"] == "float32" and far["point_dtype"] == "float64"
        assert far["sweep_dtype"] == ["float64" if p in shift else "float32" for p in near["sweep"]]
        for kind in ("solve", "sweep"):
            for p, v in near[kind].items():
                v, w = np.asarray(v), np.asarray(far[kind][p]) - shift.get(p, 0.0)
                scale = 1.0 if p.endswith("crush") or "point" in p else np.abs(v).max()  # lengths: 1 m
                np.testing.assert_allclose(w, v, rtol=0, atol=5e-5 * scale, err_msg=f"{label} {kind} {p}")
