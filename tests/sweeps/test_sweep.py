"""``ks_jax.sweep``: values equal single solves, shapes, chunking, programs shared between sizes, zip samples,
bad rows, ties between inputs, index ranges, sharding, a scene far from the origin in float32."""

from __future__ import annotations

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

import ks_jax
from ks_jax import units as U
from ks_jax.case import CaseError, as_arrays, get_output, set_input
from ks_jax.sweeps import sweep
from samples import CASES, SEED0, SEED1, SWEEP_OUTPUTS as OUTPUTS, reference_jit


RTOL = 1e-12  # sweep vs single solve: the same kernel, batched; only rounding may differ
# a grid of 65 to 128 points over speed and restitution: test_chunk_boundaries_do_not_change_results' whole sweep
# and test_sharded_equals_unsharded's sweep in this process, one program
GRID_OUTPUTS = OUTPUTS + ["vehicles[0].delta_v[1]"]


@pytest.fixture(scope="module")
def case():
    return ks_jax.load_case(SEED0)


def single(case, point, path):
    inputs = case.inputs
    for p, v in point.items():
        inputs = set_input(inputs, p, v)
        if p.endswith(".yaw"):  # the seed cases give no course: it follows the yaw (docs/model.md, "Inputs")
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
    never = int(res.contact.status) == ks_jax.model.types.NO_CONTACT
    if never and (name == "ees" or path.startswith("contact.") and name in (
            "time", "point", "normal", "closing_velocity", "separation_velocity")):
        return np.full_like(x, np.nan)
    if name == "course_after":
        v = res.vehicles[int(path[9])]
        after, dv = np.asarray(v.velocity_after, float), np.asarray(v.delta_v, float)
        if np.hypot(*after[:2]) <= 1e-6 * (np.hypot(*(after - dv)[:2]) + float(v.delta_v_magnitude)):
            return np.full_like(x, np.nan)
    return x


_SOLVE = reference_jit(ks_jax.solve_inputs, static_argnums=(1, 2))  # one compile per contact mode


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


@pytest.mark.slow
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


@pytest.mark.slow
def test_chunk_boundaries_do_not_change_results(case):
    """Chunks of other sizes (other programs, which XLA may vectorize and contract differently) give the same
    results to rounding, and the same flags and statuses."""
    over = {"vehicles[1].speed": np.linspace(2, 20, 13), "contact.restitution": np.linspace(0, 1, 7)}
    whole = sweep(case, over, outputs=GRID_OUTPUTS, chunk_size=1000)
    for chunk in (5, 13):
        part = sweep(case, over, outputs=GRID_OUTPUTS, chunk_size=chunk)
        for p in GRID_OUTPUTS + ["status"]:
            if whole[p].dtype.kind in "bi":
                np.testing.assert_array_equal(part[p], whole[p], err_msg=f"{p}, chunk {chunk}")
            else:
                scale = np.nanmax(np.abs(whole[p]))
                np.testing.assert_allclose(part[p], whole[p], rtol=1e-13, atol=1e-13 * scale, err_msg=f"{p}, {chunk}")


@pytest.mark.slow
def test_a_sweep_of_another_size_runs_the_programs_already_compiled(case, monkeypatch):
    """The programs do not depend on the axes' sizes, and a short sweep's one chunk is rounded up to a power
    of two: after a 5 x 3 grid, a 7 x 2 grid and a zip of 11 samples over the same paths compile nothing
    (the jitted programs' caches keep their sizes), and the 7 x 2 grid's values are those of the same grid
    in chunks of 3 points (other programs) and of single solves. A range of a larger sweep is not padded."""
    engine = sys.modules["ks_jax.sweeps.engine"]
    programs = []
    compiled = engine._program

    calls = []

    def spy(key):
        calls.append(key)
        programs.append(compiled(key))
        return programs[-1]

    monkeypatch.setattr(engine, "_program", spy)
    paths = ("vehicles[1].speed", "contact.restitution")
    sweep(case, {paths[0]: np.linspace(4.0, 12.0, 5), paths[1]: np.array([0.0, 0.1, 0.2])}, outputs=OUTPUTS)
    sizes = programs[-1]._cache_size()
    over = {paths[0]: np.linspace(3.0, 15.0, 7), paths[1]: np.array([0.05, 0.4])}
    grid = sweep(case, over, outputs=OUTPUTS)
    assert programs[-1] is programs[0] and programs[-1]._cache_size() == sizes
    samples = sweep(case, {paths[0]: np.linspace(3.0, 15.0, 11), paths[1]: np.linspace(0.0, 0.5, 11)},
                    outputs=OUTPUTS, mode="zip")
    assert samples.shape == (11,) and set(samples.status_counts) == {"ok"}
    assert programs[0]._cache_size() == sizes  # zip: another program, but the grid's stayed
    small = sweep(case, over, outputs=OUTPUTS, chunk_size=3)
    for p in OUTPUTS + ["status"]:
        np.testing.assert_allclose(grid[p], small[p], rtol=1e-13, atol=1e-13, err_msg=p)
    # a range of a larger sweep keeps its exact axes (a zip's are as long as the sweep) and sizes
    many = {paths[0]: np.linspace(3.0, 15.0, 40000), paths[1]: np.linspace(0.0, 0.5, 40000)}
    part = sweep(case, many, outputs=OUTPUTS, mode="zip", index_range=(39990, 40000))
    assert part.shape == (10,) and set(part.status_counts) == {"ok"}
    assert calls[-1].static_sizes == (40000, 40000)
    for i, j in ((0, 0), (6, 1), (3, 0)):
        point = {paths[0]: over[paths[0]][i], paths[1]: over[paths[1]][j]}
        for p in OUTPUTS:
            value, status = single(case, point, p)
            np.testing.assert_allclose(grid[p][i, j], value, rtol=RTOL, atol=RTOL, err_msg=p)
            assert grid["status"][i, j] == status


@pytest.mark.slow
@pytest.mark.skipif(jax.default_backend() != "cpu", reason="XLA's CPU settings")
def test_a_small_sweep_compiles_quick_and_gets_the_values_of_xla_defaults(case, monkeypatch):
    """A sweep of at most ``QUICK_POINTS`` points compiles with ``ks_jax.compilation.QUICK_CPU``, a larger one with
    XLA's defaults; the small sweep's values, every output of an 18-point grid over speed, yaw and friction
    (sliding and sticking), are those of the same sweep compiled at XLA's defaults, to rounding."""
    engine = sys.modules["ks_jax.sweeps.engine"]
    seen = []
    compiled = engine._program

    def spy(key):
        seen.append(key.quick)
        return compiled(key)

    monkeypatch.setattr(engine, "_program", spy)
    over = {"vehicles[1].speed": np.linspace(3.0, 15.0, 3), "vehicles[1].yaw": np.radians([0.0, 25.0]),
            "contact.friction": np.array([0.0, 0.3, 2.0])}
    outputs = [p for p in OUTPUTS if not p.startswith("contact.sliding")] + ["contact.sliding", "vehicles[1].ees"]
    quick = sweep(case, over, outputs=outputs)
    monkeypatch.setattr(engine, "QUICK_POINTS", 17)
    sweep(case, over, outputs=outputs)
    assert seen == [True, False]
    monkeypatch.setattr(sys.modules["ks_jax.compilation"], "QUICK_CPU", {})  # "quick" programs at XLA's defaults
    monkeypatch.setattr(engine, "QUICK_POINTS", 18)
    compiled.cache_clear()
    defaults = sweep(case, over, outputs=outputs)
    assert seen[-1] is True and compiled.cache_info().misses == 1 and set(quick.status_counts) == {"ok"}
    assert quick["contact.sliding"].any() and not quick["contact.sliding"].all()
    for p in outputs + ["status"]:
        if quick[p].dtype.kind in "bi":
            np.testing.assert_array_equal(quick[p], defaults[p], err_msg=p)
        else:
            np.testing.assert_allclose(quick[p], defaults[p], rtol=RTOL, atol=RTOL, err_msg=p)


@pytest.mark.slow
def test_automatic_contact_case_matches_single_solves():
    """A case with automatic contact goes through the geometry in its sweep (three stages: the input rules, the
    contact, the exchange): the same values as solving a point alone, across chunk boundaries."""
    auto = ks_jax.load_case(CASES / "auto_tbone.json")
    assert auto.auto_point and auto.auto_normal
    speeds = np.array([11.0, 13.4112, 16.0])  # the pickup (its case speed: 30 mph)
    mus = np.array([0.2, 0.8])
    outputs = ["contact.time", "contact.impulse_magnitude", "vehicles[0].pdof", "vehicles[1].delta_v[1]"]
    r = sweep(auto, {"vehicles[1].speed": speeds, "contact.friction": mus}, outputs=outputs, chunk_size=4)
    assert r.shape == (3, 2) and r.status_counts == {"ok": 6}
    for i, j in [(0, 0), (2, 1), (1, 1)]:  # (2, 1) and (1, 1) are in the second chunk
        inputs = set_input(set_input(auto.inputs, "vehicles[1].speed", speeds[i]), "contact.friction", mus[j])
        res = _SOLVE(as_arrays(inputs), True, True)
        assert int(res.contact.status) == 0
        for path in outputs:
            np.testing.assert_allclose(r[path][i, j], get_output(res, path), rtol=RTOL, atol=1e-9, err_msg=path)
    assert len(set(np.round(r["contact.time"][:, 0], 12))) == 3  # the time to contact depends on the speed


@pytest.mark.slow
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
            if path == "contact.sliding" and status >= ks_jax.model.types.INVALID_NONFINITE:
                continue
            np.testing.assert_allclose(got, want, rtol=RTOL, atol=1e-9, err_msg=f"{path} at {index}")
    assert {"ok", "no_contact", "invalid: contact.restitution must be in [-1, 1]",
            "invalid: vehicles[1].speed must be >= 0 (reverse the course for backwards travel)"} <= seen
    assert r.status_counts["ok"] == 4  # 11 and 16 m/s, eps 0.1, the sedan at 0 ft, turning or not


# a sweep's outputs by default, of a case of two vehicles without a road (docs/model.md, "Sweeps")
TWO_VEHICLE_DEFAULTS = {"contact.impulse_magnitude", "contact.energy_loss", "contact.sliding", "status",
                        *(f"vehicles[{i}].{name}" for i in (0, 1)
                          for name in ("delta_v_magnitude", "pdof", "speed_after"))}


@pytest.mark.slow
def test_default_outputs_and_status(case):
    r = sweep(case, {"contact.restitution": [0.0, 0.1]})
    assert set(r) == TWO_VEHICLE_DEFAULTS
    np.testing.assert_allclose(r["contact.impulse_magnitude"][1], 5946.847, rtol=2e-4)  # the seed chapter


@pytest.mark.slow
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


@pytest.mark.slow
def test_bad_rows_get_their_status_others_match(case):
    """Restitutions above 1 get their status and NaN, the others the values of single solves: every default
    output (the program of test_default_outputs_and_status, a sweep of the restitution alone)."""
    eps = np.linspace(0.0, 1.5, 7)  # 1.25 and 1.5 break the rule eps <= 1
    r = sweep(case, {"contact.restitution": eps})
    assert set(r) == TWO_VEHICLE_DEFAULTS
    bad = eps > 1
    assert np.all(r["status"][bad] == ks_jax.model.types.INVALID_RESTITUTION)
    assert np.all(r["status"][~bad] == 0)
    assert np.all(np.isnan(r["contact.impulse_magnitude"][bad]))
    assert not r["contact.sliding"][bad].any()
    assert r.status_counts["invalid: contact.restitution must be in [-1, 1]"] == bad.sum()
    assert_matches(r, case, [(k, {"contact.restitution": eps[k]}) for k in range(len(eps))])


@pytest.mark.slow
def test_negative_speeds_get_their_status_others_match(case):
    """A case file refuses a negative speed; a sampled one gets the status, NaN results, and the other
    rows are solved. (``solve_inputs`` of one point, as an automatic-contact sweep's rows are finished,
    checked last.)"""
    speeds = np.array([-3.0, 0.0, 4.0, -0.5, 9.0])
    r = sweep(case, {"vehicles[1].speed": speeds}, outputs=OUTPUTS, chunk_size=2)
    bad = speeds < 0
    assert np.all(r["status"][bad] == ks_jax.model.types.INVALID_SPEED_2)
    assert np.all(np.isnan(r["contact.impulse_magnitude"][bad])) and not r["contact.sliding"][bad].any()
    assert r.status_counts["invalid: vehicles[1].speed must be >= 0 (reverse the course for backwards travel)"] == 2
    assert np.all(np.isfinite(r["contact.impulse_magnitude"][~bad]))
    assert_matches(r, case, [(k, {"vehicles[1].speed": speeds[k]}) for k in np.flatnonzero(~bad)])
    r = sweep(case, {"vehicles[0].speed": [-1.0], "vehicles[1].speed": [-1.0]})
    assert r["status"][0, 0] == ks_jax.model.types.INVALID_SPEED_1  # the first vehicle's reason first
    # solve_inputs jitted as single() runs it (one program for the file), not op by op: ~100 small programs
    res = _SOLVE(as_arrays(set_input(case.inputs, "vehicles[1].speed", -1.0)), False, False)
    assert int(res.contact.status) == ks_jax.model.types.INVALID_SPEED_2
    assert all(np.isnan(x).all() for x in jax.tree_util.tree_leaves(res) if np.asarray(x).dtype.kind == "f")
    inputs = set_input(case.inputs, "vehicles[0].mass", -5.0)
    res = _SOLVE(as_arrays(set_input(inputs, "vehicles[1].speed", -1.0)), False, False)
    assert int(res.contact.status) == ks_jax.model.types.INVALID_MASS_1  # an exchange input's reason first


@pytest.mark.slow
def test_yaw_turns_the_course_where_the_case_gives_none(case):
    """Sweeping a yaw gives what solving the case file written with that yaw gives (its course
    defaults to the yaw, docs/model.md, "Inputs"); with a course in the file, only the body turns."""
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


@pytest.mark.slow
def test_cg_height_moves_the_cg_where_the_case_gives_a_2d_position(case):
    """A 2-D position puts the CG at z = cg_height (docs/model.md, "Inputs"): sweeping cg_height gives what
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


@pytest.mark.slow
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


def test_automatic_parts_and_swept_outputs_are_refused(case):
    auto = ks_jax.load_case(CASES / "auto_seed_000.json")
    for path in ("contact.point[0]", "contact.normal"):
        with pytest.raises(CaseError, match=rf"sweep over '{path[:13]}.*automatic in this case"):
            sweep(auto, {path: [0.0, 1.0]})
    with pytest.raises(CaseError, match=r"output 'contact.point\[0\]' is also a swept input"):
        sweep(case, {"contact.point[0]": [0.0, 1.0]}, outputs=["contact.point[0]"])


@pytest.mark.slow
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

    # chunks of 4, as the range above: its program (54 points in chunks of 4, the last one short)
    r = sweep(case, over, outputs=["contact.energy_loss"], chunk_size=4, on_chunk=on_chunk, keep=False)
    assert len(r) == 0 and r.points == 54
    assert seen[0] == (0, 4) and seen[-1] == (52, 54)
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


@pytest.mark.slow
def test_sharded_equals_unsharded(case):
    env = dict(os.environ, JAX_NUM_CPU_DEVICES="2", XLA_FLAGS="--xla_force_host_platform_device_count=2",
               JAX_PLATFORMS="cpu")
    proc = subprocess.run([sys.executable, "-c", SHARDED, str(SEED0)], capture_output=True, text=True, env=env,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    data = json.loads(proc.stdout.strip().splitlines()[-1])
    here = sweep(case, {"vehicles[1].speed": np.linspace(2, 20, 11), "contact.restitution": np.linspace(0, 1.2, 7)},
                 outputs=GRID_OUTPUTS)  # the subprocess's outputs and more: the program of a test above
    for k, (sharded, single_device) in data.items():
        sharded = np.array(sharded, dtype=float)
        np.testing.assert_array_equal(sharded, np.array(single_device, dtype=float), err_msg=k)
        # this process's default device may be a GPU, whose rounding differs from the CPU's: to 1e-13 of the
        # output's scale, since an output near 0 (a rear impact's lateral delta-V) differs by rounding far more
        # than 1e-13 of itself
        np.testing.assert_allclose(sharded, np.asarray(here[k], dtype=float), rtol=1e-13,
                                   atol=1e-13 * np.nanmax(np.abs(sharded), initial=0.0), err_msg=k)


@pytest.mark.slow
def test_a_long_sweep_shows_a_bar(capsys, monkeypatch):
    """progress=None: a bar on stderr once the sweep has run PROGRESS_DELAY seconds (any size: a million
    points with automatic contact run for 5-15 s), none before; progress=False: never."""
    import ks_jax.sweeps.engine as sweeps_module

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


def test_without_tqdm_progress_is_a_plain_line_on_stderr(monkeypatch, capsys):
    """tqdm is an extra (``progress``): without it, long work shows a line that counts to its total and ends there,
    at most once a second between, nothing before its delay, and nothing at all where progress is turned off."""
    monkeypatch.setitem(sys.modules, "tqdm.auto", None)  # what "import tqdm.auto" finds: an ImportError
    bar = ks_jax.progress.Progress(40, "ks-jax sweep", "rows", delay=0.0)
    assert bar.bar is None
    for _ in range(5):
        bar.update(8)
    bar.close()
    err = capsys.readouterr().err
    assert err.startswith("\rks-jax sweep: 8/40 rows (20%, ")  # the first update is shown, later ones once a second
    assert re.search(r"\rks-jax sweep: 40/40 rows \(100%, [0-9.e+]+/s\)\n$", err) and err.count("\n") == 1
    for quiet in (ks_jax.progress.Progress(40, "x", "rows", enabled=False),
                  ks_jax.progress.Progress(40, "x", "rows", delay=60.0)):
        quiet.update(40)
        quiet.close()
    assert capsys.readouterr().err == ""


@pytest.mark.slow
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
        one = _SOLVE(inputs._replace(vehicles=(inputs.vehicles[0]._replace(inertia=inertia), inputs.vehicles[1])),
                     False, False)  # solve_inputs alone, jitted as single() runs it
        for p in ("vehicles[0].delta_yaw_rate", "contact.impulse[1]"):
            np.testing.assert_allclose(r[p][k], get_output(one, p), rtol=RTOL, atol=1e-12, err_msg=f"{p} at {v}")


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


@pytest.mark.slow
def test_float32_scene_far_from_the_origin_is_solved_as_at_the_origin():
    """In float32 (JAX's default) a position 512 km out keeps ~3 cm, which once gave the seed chapter's
    Pontiac an EES of 2.90 mph instead of 2.21. The exchange is the same in a translated scene (docs/model.md
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


FAR_ROAD = r"""
import json, sys, warnings
import ks_jax
from ks_jax.case import CaseWarning, case_from_dict
out = {}
with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always")
    for name, d in json.loads(sys.argv[1]).items():
        r = ks_jax.solve(case_from_dict(d)).result
        out[name] = {"rest": [x.rest_position.tolist() for x in r.rest],
                     "rest_dtype": str(r.rest[0].rest_position.dtype),
                     "approach": [a.position.tolist() for a in r.approach], "point": [r.contact.point[:2].tolist()]}
    out["warned"] = [str(w.message) for w in caught if w.category is CaseWarning]
print(json.dumps(out))
"""


@pytest.mark.slow
def test_float32_scene_far_from_the_origin_with_a_road_comes_back_to_rest_where_it_would_at_the_origin():
    """In float32, a scene in survey coordinates (300 km, 210 km) with a road and approaches is solved about its CGs'
    midpoint, and its rest positions and its approaches' positions are moved back in float64, as its centroid is: each
    is where the same scene at the origin puts it, moved by the same offset. Without the move back they would be
    300 km off; solved where they are, float32 keeps 3 cm there."""
    example = Path(__file__).resolve().parents[2] / "docs" / "examples" / "tbone_skids_before_impact.json"
    d = json.loads(example.read_text())
    shift = np.array([3e5, 2.1e5])
    scenes = {"near": _moved(d, 0.0, 0.0), "far": _moved(d, *shift)}
    proc = subprocess.run([sys.executable, "-c", FAR_ROAD, json.dumps(scenes)], capture_output=True, text=True,
                          timeout=600, env=dict(os.environ, JAX_PLATFORMS="cpu"))
    assert proc.returncode == 0, proc.stderr[-3000:]
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    near, far = out["near"], out["far"]
    assert out["warned"] == [] and near["rest_dtype"] == "float32" and far["rest_dtype"] == "float64"
    for key, count in (("point", 1), ("rest", 2), ("approach", 2)):  # the centroid; each vehicle's rest, approach
        assert len(far[key]) == len(near[key]) == count
        for w, v in zip(far[key], near[key]):
            np.testing.assert_allclose(np.asarray(w) - shift, v, rtol=0, atol=1e-4, err_msg=key)  # float32's rounding


@pytest.mark.slow
def test_the_accelerator_path_counts_on_the_device(case):
    """On the accelerator's path (``plan="accelerator"``, forced here), each chunk's statuses and undefined values
    are counted on the device over the rows of the range alone; a sweep that keeps nothing copies no rows
    to the host. Values, statuses and counts are the CPU path's, in chunks that end inside the range."""
    over = {"vehicles[1].speed": np.linspace(0.0, 20.0, 9), "contact.restitution": np.linspace(0.0, 1.5, 7)}
    outputs = ["contact.impulse_magnitude", "vehicles[0].pdof", "vehicles[1].course_after"]
    cpu = sweep(case, over, outputs=outputs, chunk_size=1000, plan="cpu")
    flat = {k: v.ravel() for k, v in cpu.items()}

    def counted(lo, hi):  # the counts a sweep of flat indices lo..hi should give, from the kept results
        codes, k = np.unique(flat["status"][lo:hi], return_counts=True)
        solved = flat["status"][lo:hi] < ks_jax.model.types.INVALID_NONFINITE
        return ({ks_jax.model.types.status_text(c): int(n) for c, n in zip(codes, k)},
                {p: int(np.sum(np.isnan(flat[p][lo:hi]) & solved)) for p in outputs[1:]})

    r = sweep(case, over, outputs=outputs, chunk_size=5, plan="accelerator")  # the last chunk ends past the grid
    for p in outputs + ["status"]:
        np.testing.assert_allclose(r[p], cpu[p], rtol=1e-12, atol=1e-12, err_msg=p)
    assert (r.status_counts, r.undefined) == counted(0, 63)
    part = sweep(case, over, outputs=outputs, chunk_size=5, index_range=(10, 33), keep=False, plan="accelerator")
    assert len(part) == 0 and (part.status_counts, part.undefined) == counted(10, 33)
    # the grid has each kind of row counted: solved, separating at speed 0 (its PDOF and course undefined), invalid
    assert set(cpu.status_counts) == {"ok", "separating", "invalid: contact.restitution must be in [-1, 1]"}
    assert cpu.undefined == {"vehicles[0].pdof": 5, "vehicles[1].course_after": 5}
