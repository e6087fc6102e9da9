"""The text panel of ``ks-jax solve`` (ks_jax.report): its columns stay apart and aligned whatever the
numbers, its numbers are the solution's, and it names each vehicle as the output paths do."""

import json
import math
import re
import tomllib
from pathlib import Path

import numpy as np
import pytest

import ks_jax
from ks_jax import units as U
from ks_jax.case import get_output
from ks_jax.report import text_report
from samples import SEED1

# A 40-tonne truck at 120 km/h into the left side of a car crossing at 50 km/h: an impulse, and its normal
# and tangential parts, of five digits before the decimal point, in N s and in lbf s.
HEAVY = {
    "name": "40-tonne truck into the side of a car",
    "vehicles": [
        {"name": "Car", "mass": "1500 kg", "inertia": [500, 2400, 2600], "length": 4.7, "width": 1.8,
         "height": 1.45, "cg_to_front": 2.1, "cg_height": 0.55, "position": [0, 0], "yaw": 90, "speed": "50 km/h"},
        {"name": "Truck", "mass": "40000 kg", "inertia": [40000, 400000, 400000], "length": 16.5, "width": 2.55,
         "height": 4.0, "cg_to_front": 6.0, "cg_height": 1.5, "position": [-6.7, 0.3], "yaw": 0,
         "speed": "120 km/h"},
    ],
    "contact": {"point": [-0.8, 0.3, 0.8], "normal": 0, "restitution": 0.1, "friction": 0.5},
}
US_UNIT = re.compile(r"\b(lbf s|ft lbf|mph|ft|deg/s)\b")


def solved(tmp_path, case, name="case.json"):
    path = tmp_path / name
    path.write_text(json.dumps(case))
    return ks_jax.solve(ks_jax.load_case(path))


def two_column_rows(panel):
    """{label: [(SI text, US text, offset of the US text), ...]} of the panel's rows with a US unit in them.
    A row splits at runs of two or more spaces into its label, its SI text and its US text (none of which
    holds two spaces running); a row whose columns ran together splits into fewer parts and fails here.
    The reference table, after the panel, has columns of its own."""
    rows = {}
    for line in panel.split("\n\n  reference ", 1)[0].splitlines():
        if not US_UNIT.search(line) or not line.startswith("  "):
            continue
        parts = re.split(r" {2,}", line.strip())
        assert len(parts) == 3, f"the columns run together: {line!r}"
        label, si, us = parts
        assert US_UNIT.search(us) and not US_UNIT.search(si), line
        rows.setdefault(label, []).append((si, us, len(line) - len(us)))
    return rows


def number(text):
    return float(text.replace(",", ""))


def test_wide_numbers_keep_the_columns_apart_and_aligned(tmp_path):
    sol = solved(tmp_path, HEAVY)
    c = sol.result.contact
    assert sol.status == "ok"
    assert min(c.impulse_magnitude, c.impulse_normal, c.impulse_tangential) >= 1e4  # five digits in N s
    assert min(c.impulse_normal, c.impulse_tangential) / U.LBF_S >= 1e3  # and four or five in lbf s
    panel = text_report(sol)
    rows = two_column_rows(panel)
    offsets = {offset for entries in rows.values() for _, _, offset in entries}
    assert len(offsets) == 1, offsets  # the US column starts at one offset in every row
    (offset,) = offsets
    gaps = [len(line[:offset]) - len(line[:offset].rstrip()) for line in panel.splitlines()
            if US_UNIT.search(line) and line.startswith("  ")]
    assert min(gaps) == 2  # two spaces after the widest SI text, more after the others
    # the SI and US texts are whole: their numbers are the solution's
    ((si, us, _),) = rows["impulse"]
    assert si.endswith(" N s") and us.endswith(" lbf s")
    assert number(si[:-4]) == pytest.approx(c.impulse_magnitude, abs=5e-4)
    assert number(us[:-6]) == pytest.approx(c.impulse_magnitude / U.LBF_S, abs=5e-4)
    ((si, us, _),) = rows["normal / tangential"]
    assert [number(x) for x in si.removesuffix(" N s").split(" / ")] == pytest.approx(
        [c.impulse_normal, c.impulse_tangential], abs=5e-4)
    assert [number(x) for x in us.removesuffix(" lbf s").split(" / ")] == pytest.approx(
        [c.impulse_normal / U.LBF_S, c.impulse_tangential / U.LBF_S], abs=5e-4)
    ((si, us, _),) = rows["deformation energy (loss)"]
    assert number(si.removesuffix(" J")) == pytest.approx(c.energy_loss, abs=5e-4)
    assert number(us.removesuffix(" ft lbf")) == pytest.approx(c.energy_loss / U.FT_LBF, abs=5e-3)


def test_an_ordinary_panel_keeps_its_columns():
    """Numbers that fit take the panel's usual columns: SI text at offset 36, US text at 62."""
    panel = text_report(ks_jax.solve(ks_jax.load_case(SEED1)))
    assert "\n  impulse" + " " * 27 + "6,570.775 N s" + " " * 13 + "1,477.169 lbf s\n" in panel
    assert {offset for entries in two_column_rows(panel).values() for _, _, offset in entries} == {62}
    assert all(line == line.rstrip() for line in panel.splitlines())


def test_vehicles_are_named_as_the_output_paths_name_them():
    """Each vehicle's block is headed with its number, its path (as sweeps, fits and --json name it) and its
    name, and the values under it are that path's."""
    sol = ks_jax.solve(ks_jax.load_case(SEED1))
    panel = text_report(sol)
    assert "object" not in panel
    for k, name in enumerate(("Lucid Air", "Kia K5")):
        header = f"\n  vehicle {k + 1} = vehicles[{k}]: {name}\n"
        assert header in panel
        block = panel.split(header, 1)[1].split("\n\n", 1)[0]
        delta_v = re.search(r"^  delta-V +([\d.,]+) m/s", block, re.M).group(1)
        assert number(delta_v) == pytest.approx(float(get_output(sol.result, f"vehicles[{k}].delta_v_magnitude")),
                                                abs=5e-4)


def test_reference_table_columns_stay_apart(tmp_path):
    """A reported value wider than its column pushes the next column out, for every row alike."""
    case = tomllib.loads(SEED1.read_text())
    case["reference"] = {"contact.impulse_magnitude": "6571.96 N*s", "contact.energy_loss": "1234567.5 ft*lbf"}
    panel = text_report(solved(tmp_path, case))
    table = panel.split("\n  reference", 1)[1].splitlines()
    rows = [re.split(r" {2,}", line.strip()) for line in table[1:]]
    assert [r[:2] for r in rows] == [["contact.impulse_magnitude", "6,571.960 N*s"],
                                     ["contact.energy_loss", "1,234,567.500 ft*lbf"]]
    assert all(len(r) == 4 for r in rows)
    starts = {line.index(r[2]) for line, r in zip(table[1:], rows)}
    assert len(starts) == 1  # the ks-jax column is aligned


@pytest.mark.slow
def test_long_notes_are_wrapped_and_the_label_column_keeps_its_width(tmp_path):
    """A vehicle still moving at the time limit: the remark on its rest position goes under the row, the notes
    are wrapped to lines of at most 100 characters, the columns stay where an ordinary panel has them (US
    text at offset 62), and the wrapped notes say, word for word, what ``Solution.notes`` says."""
    from samples import CASES

    case = json.loads((CASES / "rest_seed_000.json").read_text())
    case["road"]["time_limit"] = "0.5 s"
    sol = solved(tmp_path, case)
    notes = sol.notes()
    moving = [n for n in notes if "still moves" in n]
    assert len(moving) == 2 and all(len(n) > 150 for n in moving)  # both vehicles still move: long sentences
    panel = text_report(sol)
    lines = panel.splitlines()
    assert max(len(line) for line in lines) <= 100
    assert {offset for entries in two_column_rows(panel).values() for _, _, offset in entries} == {62}
    rows = [k for k, line in enumerate(lines) if line.startswith("  rest position (x, y)")]
    assert len(rows) == 2
    for k in rows:
        assert re.fullmatch(r"  rest position \(x, y\) {14}\S.*", lines[k])  # the values at the label's width
        assert lines[k + 1] == "    still moving at the time limit (0.5 s): where it is then"
    paragraphs = [" ".join(p.split()) for p in panel.split("\n\n") if p.lstrip().startswith("note: ")]
    assert paragraphs == [f"note: {n}." for n in notes]


def test_the_panel_in_one_unit_system_alone():
    """``text_report(units="us")`` and ``"si"`` (``ks-jax solve --units``): the manual's Lucid-Kia crash,
    whose exact impulse is 1.1 x 61.04 slug x 22 ft/s = 1477.169 lbf s (6570.775 N s) and whose Kia's delta-V
    is 10.03 mph. Each panel holds its own system's units and none of the other's; every other row (angles,
    times, words) is as in the panel of both."""
    sol = ks_jax.solve(ks_jax.load_case(SEED1))
    us, si, both = (text_report(sol, units=u) for u in ("us", "si", "both"))
    assert "1,477.169 lbf s" in us and "10.03 mph" in us
    assert "6,570.775 N s" in si
    dv = [[float(m) for m in re.findall(r"delta-V +([\d.]+) (?:m/s|mph)", panel)] for panel in (si, us)]
    np.testing.assert_allclose(np.array(dv[0]) / 0.44704, dv[1], atol=0.006)  # 1 mph = 0.44704 m/s exactly
    assert not re.search(r"\b(N s|m/s|J|m)\b", us.split("reference")[0])
    assert not re.search(r"\b(lbf s|mph|ft lbf|ft)\b", si.split("reference")[0])
    assert [line for line in both.splitlines() if "deg" in line and "rad" not in line] == \
        [line for line in si.splitlines() if "deg" in line and "rad" not in line]
    with pytest.raises(ValueError, match="units"):
        text_report(sol, units="imperial")


SEMI = Path(__file__).resolve().parents[1] / "docs" / "examples" / "semi_trailer_side_impact.json"


@pytest.fixture(scope="module")
def semi():
    """docs/examples/semi_trailer_side_impact.json (a sedan into a semi-trailer on its tractor's fifth wheel) solved
    once, its JSON, and its panel in each unit system."""
    sol = ks_jax.solve(ks_jax.load_case(SEMI))
    assert sol.status == "ok" and sol.case.between == (0, 1) and len(sol.exchange_list()) == 1
    return sol, sol.to_dict(), {u: text_report(sol, units=u) for u in ("both", "si", "us")}


def vehicle_block(panel, k):
    """The panel's block of vehicles[k]: its header line and its rows, up to the next blank line."""
    return re.search(rf"^  (?:vehicle \d = )?vehicles\[{k}\]: .*?(?=\n\n|\Z)", panel, re.M | re.S).group(0)


def row_text(block, label):
    """The text after ``label`` on its row of ``block``, or None where the block has no such row."""
    found = re.search(rf"^  {re.escape(label)}  +(.*)$", block, re.M)
    return None if found is None else found.group(1)


def pdof_by_hand(delta_v, yaw):
    """A PDOF worked from a delta-V vector (m/s, global) and the heading ``yaw`` (deg): the direction the force came
    from, clockwise from the vehicle's front, in [0, 360)."""
    return (yaw - math.degrees(math.atan2(delta_v[1], delta_v[0])) - 180.0) % 360.0


@pytest.mark.slow
def test_a_towed_vehicle_names_its_tow_and_a_tow_what_it_tows(semi):
    """The trailer's block says what tows it, how and how far it may turn (the file's hitch: to 2, "fifth_wheel",
    90 deg); the tractor's what it tows; the sedan's nothing of hitches."""
    sol, d, panels = semi
    hitch = json.loads(SEMI.read_text())["vehicles"][1]["hitch"]
    assert (hitch["to"], hitch["kind"], hitch["max_angle"]) == (2, "fifth_wheel", "90 deg")
    for panel in panels.values():  # words and degrees: alike in every unit system
        assert row_text(vehicle_block(panel, 1), "hitch") == "towed by vehicles[2] (Tractor), fifth wheel; max 90.0 deg"
        assert row_text(vehicle_block(panel, 2), "hitch") == "tows vehicles[1] (Semi-trailer), fifth wheel"
        assert row_text(vehicle_block(panel, 0), "hitch") is None
    assert vehicle_block(panels["both"], 2).startswith("  vehicles[2]: Tractor (not in the first exchange)")


@pytest.mark.slow
def test_the_cumulative_delta_v_of_each_vehicle_the_joint_moved(semi):
    """Trailer and tractor: a "cumulative delta-V (with hitch)" row whose magnitude is the length of the JSON's
    ``delta_v_cumulative`` and whose PDOF is that vector's direction against the vehicle's heading (90 deg), in m/s
    and in mph; the tractor's, from the joint alone (no exchange of its own), is not 0. The sedan's cumulative delta-V
    is its exchange's delta-V: no such row."""
    sol, d, panels = semi
    label = "cumulative delta-V (with hitch)"
    tractor = d["vehicles"][2]
    assert [entry["exchanges"] for entry in tractor["interactions"]] == [[]]
    assert np.linalg.norm(tractor["delta_v_cumulative"]) > 0.1
    assert row_text(vehicle_block(panels["both"], 0), label) is None
    for k in (1, 2):
        dv = np.asarray(d["vehicles"][k]["delta_v_cumulative"])
        pdof = pdof_by_hand(dv, 90.0)
        assert d["vehicles"][k]["delta_v_cumulative_pdof"] == pytest.approx(pdof, abs=1e-4)
        for units, scale in (("si", 1.0), ("us", U.MPH)):
            text = row_text(vehicle_block(panels[units], k), label)
            size, direction = re.fullmatch(r"([\d.,]+) (?:m/s|mph), PDOF ([\d.]+) deg", text).groups()
            assert number(size) == pytest.approx(np.linalg.norm(dv) / scale, abs=5e-3 if units == "us" else 5e-4)
            assert float(direction) == pytest.approx(pdof, abs=0.05)
    assert len(two_column_rows(panels["both"])[label]) == 2  # SI beside US in the panel of both, apart


@pytest.mark.slow
def test_the_articulation_at_rest(semi):
    """The trailer's "articulation at rest" is its rest yaw minus the tractor's (the JSON's), wrapped to
    (-180, 180] deg; no other vehicle has one."""
    sol, d, panels = semi
    angle = (d["vehicles"][1]["rest_yaw"] - d["vehicles"][2]["rest_yaw"] + 180.0) % 360.0 - 180.0
    assert abs(angle) > 1.0  # the struck trailer turned on the fifth wheel
    text = row_text(vehicle_block(panels["both"], 1), "articulation at rest")
    assert float(re.fullmatch(r"(-?[\d.]+) deg \(its yaw minus its tow's\)", text).group(1)) == pytest.approx(
        angle, abs=0.05)
    assert all(row_text(vehicle_block(panels["both"], k), "articulation at rest") is None for k in (0, 2))


def test_a_panel_without_hitches_has_no_hitch_rows():
    panel = text_report(ks_jax.solve(ks_jax.load_case(SEED1)))
    assert not re.search(r"hitch|articulation", panel)
