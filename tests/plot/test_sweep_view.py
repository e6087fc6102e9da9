"""Pictures of sweeps (ks_jax.plot.sweep_view, ks-jax sweep --plot): what is drawn is the sweep's
results in the units asked for (US units in most tests here), thinned the way the result says, with the
points that have no result marked."""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np
import pytest

pytest.importorskip("matplotlib")

from matplotlib.collections import QuadMesh
from matplotlib.figure import Figure

import ks_jax
from ks_jax import plot
from ks_jax.case import CaseError
from ks_jax.cli import main
from ks_jax.sweeps import SweepSample, sweep

SEED1 = Path(ks_jax.__file__).parent / "cases" / "seed_001_lucid_kia.toml"
MPH = 1609.344 / 3600  # m/s per mph, written out here (ks_jax.units is what is tested)
DV1 = "vehicles[0].delta_v_magnitude"
# outputs shared by several tests' sweeps (a sweep's program is compiled per paths, outputs and size bucket, ~2 s
# each): those of a grid of 17 to 32 points (at most 8 a side) over the Kia's speed and the restitution, and of a
# line of 3 to 8 speeds
FIGURE_OUTPUTS = ["contact.impulse_magnitude", "contact.energy_loss", "contact.sliding", DV1,
                  "vehicles[1].delta_v_magnitude", "vehicles[0].pdof", "vehicles[1].pdof"]
LINE_OUTPUTS = [DV1, "contact.energy_loss", "vehicles[1].pdof"]
GRID_OUTPUTS = [DV1, "contact.sliding"]  # of a grid of at most 8 points over the Kia's speed and the restitution


@pytest.fixture(scope="module")
def case():
    return ks_jax.load_case(SEED1)


def draw(result, output=None, units="us", typed=None):
    ax = Figure().subplots()
    plot.sweep_view(result, output, ax, units=units, typed=typed)
    return ax


def mesh_of(ax):
    (mesh,) = [c for c in ax.collections if isinstance(c, QuadMesh)]
    return mesh


@pytest.mark.slow
def test_map_shows_the_results_in_mph_with_invalid_points_grey(case):
    speed = np.linspace(6, 60, 10) * MPH
    eps = np.linspace(0, 1.5, 7)  # above 1 is refused per point (status "invalid: ... restitution")
    r = sweep(case, {"vehicles[1].speed": speed, "contact.restitution": eps}, outputs=[DV1, "contact.energy_loss"])
    ax = draw(r)
    shown = mesh_of(ax).get_array()
    want = r[DV1] / MPH
    bad = eps > 1
    assert shown.shape == want.shape == (10, 7)
    np.testing.assert_allclose(shown[:, ~bad], want[:, ~bad], rtol=1e-12)
    assert shown.mask[:, bad].all() and not shown.mask[:, ~bad].any()
    assert (r["status"][:, bad] == 17).all()
    assert f"{10 * bad.sum()} of 70 points without a result (grey)" in ax.get_title()
    assert ax.get_xlabel() == "vehicles[1].speed (Kia K5) [mph]" and ax.get_ylabel() == "contact.restitution"
    assert ax.get_title().startswith(f"{DV1} (Lucid Air) [mph]")
    assert ax.get_xlim()[0] < 6 < 60 < ax.get_xlim()[1]
    # the energy in ft lbf: 1 ft lbf = 0.3048 m x 4.4482216152605 N
    shown = mesh_of(draw(r, "contact.energy_loss")).get_array()
    np.testing.assert_allclose(shown[:, ~bad], r["contact.energy_loss"][:, ~bad] / (0.3048 * 4.4482216152605),
                               rtol=1e-12)
    # an inline rear impact: the Lucid is struck from behind (PDOF 180 deg) wherever it is struck; a
    # single value is said, not drawn as contours of its rounding
    pdof = sweep(case, {"vehicles[1].speed": speed[:8], "contact.restitution": eps[:3]}, outputs=FIGURE_OUTPUTS)
    ax = draw(pdof, "vehicles[0].pdof")
    assert "180 deg everywhere" in ax.get_title() and not [c for c in ax.collections if c is not mesh_of(ax)]


@pytest.mark.slow
def test_line_for_one_input_and_histogram_for_samples(case):
    speed = np.linspace(10, 40, 16) * MPH
    r = sweep(case, {"vehicles[1].speed": speed}, outputs=[DV1])
    ax = draw(r)
    (line,) = ax.get_lines()
    np.testing.assert_allclose(line.get_xdata(), np.linspace(10, 40, 16), rtol=1e-12)
    np.testing.assert_allclose(line.get_ydata(), r[DV1] / MPH, rtol=1e-12)

    eps = np.random.default_rng(3).uniform(0.0, 0.3, 400)
    eps[:7] = 1.5  # out of range: no result, left out of the histogram
    z = sweep(case, {"contact.restitution": eps}, outputs=[DV1], mode="zip")
    ax = draw(z)
    assert sum(p.get_height() for p in ax.patches) == 393
    assert "7 of 400 points without a result (left out)" in ax.get_title()
    median = [ln for ln in ax.get_lines() if ln.get_label().startswith("median")][0]
    assert median.get_xdata()[0] == pytest.approx(np.median(z[DV1][7:]) / MPH, rel=1e-12)


@pytest.mark.slow
def test_a_grid_axis_of_one_value_is_drawn_as_a_line(case):
    """Two swept inputs, one of them with a single value: a line over the other, the fixed value in
    the title (a map one cell wide draws nothing); both single: one point."""
    eps = np.linspace(0, 0.3, 7)
    for over, x in (({"vehicles[1].speed": [20 * MPH], "contact.restitution": eps}, eps),
                    ({"contact.restitution": eps, "vehicles[1].speed": [20 * MPH]}, eps),
                    ({"vehicles[1].speed": [20 * MPH], "contact.restitution": [0.1]}, np.array([20.0]))):
        r = sweep(case, over, outputs=GRID_OUTPUTS)
        ax = draw(r)  # the first output, DV1
        (line,) = ax.get_lines()
        assert not [c for c in ax.collections if isinstance(c, QuadMesh)]
        np.testing.assert_allclose(line.get_xdata(), x, rtol=1e-12)
        np.testing.assert_allclose(line.get_ydata(), np.ravel(r[DV1]) / MPH, rtol=1e-12)
        fixed = "contact.restitution = 0.1" if x.size == 1 else "vehicles[1].speed (Kia K5) = 20 [mph]"
        assert fixed in ax.get_title()


@pytest.mark.slow
def test_sliding_is_drawn_as_stick_or_slide(case):
    r = sweep(case, {"contact.friction": np.linspace(0, 1, 6), "vehicles[1].course": np.radians([0, 20, 40, 60])},
              outputs=["contact.sliding"])
    assert r["contact.sliding"].any() and not r["contact.sliding"].all()
    ax = draw(r, "contact.sliding")
    np.testing.assert_array_equal(mesh_of(ax).get_array(), r["contact.sliding"].astype(float))
    labels = [t.get_text() for t in ax.figure.axes[-1].get_yticklabels()]
    assert labels == ["stick", "slide"]
    assert ax.get_ylabel() == "vehicles[1].course (Kia K5) [deg]"


@pytest.mark.slow
def test_thinned_sweep_and_streamed_sample_agree(case):
    """2500 x 3 points: every 10th speed is drawn (at most 250 per axis), the same whether the sweep was
    kept and thinned or streamed through a SweepSample in chunks that do not line up with the lattice."""
    over = {"vehicles[1].speed": np.linspace(5, 30, 2500), "contact.restitution": [0.0, 0.1, 0.2]}
    kept = sweep(case, over, outputs=[DV1])
    thin = kept.thinned()
    assert thin.strides == (10, 1) and thin.shape == (250, 3)
    np.testing.assert_array_equal(thin[DV1], kept[DV1][::10])
    np.testing.assert_array_equal(thin.axes["vehicles[1].speed"], over["vehicles[1].speed"][::10])

    sample = SweepSample(over, "grid", (2500, 3))
    streamed = sweep(case, over, outputs=[DV1], keep=False, chunk_size=1000, on_chunk=sample.chunk)
    got = sample.result(streamed)
    assert got.strides == (10, 1)
    for k in (DV1, "status"):
        np.testing.assert_array_equal(got[k], thin[k])
    ax = draw(got)
    assert "shown: 1 in 10 x 1 points" in ax.get_title()
    assert mesh_of(ax).get_array().shape == (250, 3)  # what is drawn is the thinned view


@pytest.mark.parametrize("mode, shape, limit, strides", [("grid", (50, 7), 10, (5, 1)), ("grid", (23, 31), 4, (6, 8)),
                                                         ("grid", (101,), 10, (11,)), ("zip", (97,), 10, (10,))])
def test_sample_keeps_the_lattice_whatever_the_chunks(mode, shape, limit, strides):
    """Chunks of random sizes (many of them holding no kept point) give the slices of the whole array."""
    full = np.arange(np.prod(shape), dtype=float).reshape(shape) * 0.5
    axes = {f"contact.point[{k}]": np.arange(n, dtype=float) for k, n in enumerate(shape)}
    sample = SweepSample(axes, mode, shape, limit)
    assert sample.strides == strides
    rng, lo, flat = np.random.default_rng(0), 0, full.ravel()
    while lo < flat.size:
        hi = min(flat.size, lo + int(rng.integers(1, 20)))
        sample.chunk(lo, hi, {"x": flat[lo:hi], "status": np.zeros(hi - lo, np.int8)})
        lo = hi
    want = full[tuple(slice(None, None, k) for k in strides)]
    np.testing.assert_array_equal(sample.store["x"].reshape(sample.thin_shape), want)


@pytest.mark.slow
def test_what_cannot_be_drawn_is_refused(case):
    r = sweep(case, {"contact.restitution": [0.1, 0.2], "contact.friction": [0.3, 0.5],
                     "vehicles[1].speed": [8.0, 9.0]}, outputs=[DV1])
    with pytest.raises(CaseError, match="over 3 inputs"):
        draw(r)
    r = sweep(case, {"contact.restitution": [0.1, 0.2]}, outputs=[DV1])
    with pytest.raises(CaseError, match="'vehicles\\[1\\].pdof' is not among"):
        draw(r, "vehicles[1].pdof")
    with pytest.raises(CaseError, match="kept no results"):
        draw(sweep(case, {"contact.restitution": [0.1, 0.2]}, outputs=[DV1], keep=False))
    part = sweep(case, {"contact.restitution": [0.1, 0.2, 0.3]}, outputs=[DV1], index_range=(1, 3))
    with pytest.raises(CaseError, match="points 1..2"):
        draw(part)


@pytest.mark.slow
def test_cli_draws_the_sweep_and_refuses_before_solving(tmp_path, capsys):
    out, png = tmp_path / "g.npz", tmp_path / "g.png"
    args = ["sweep", str(SEED1), "--over", "vehicles[1].speed=10mph:60mph:6", "--over", "contact.restitution=0:0.3:4",
            "--output", DV1, "--output", "contact.sliding", "--out", str(out), "--plot", str(png)]
    assert main(args) == 0
    assert f"drawn to {png}" in capsys.readouterr().out
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and out.exists()

    three = ["sweep", str(SEED1), "--over", "vehicles[1].speed=10mph:60mph:3", "--over", "contact.restitution=0:0.3:2",
             "--over", "contact.friction=0.2,0.4", "--out", str(tmp_path / "h.csv"), "--plot", str(tmp_path / "h.png")]
    bad_type = args[:-1] + [str(tmp_path / "g.bmp")]
    for argv, words in ((three, "one or two inputs; this one has 3"), (bad_type, "unknown picture type '.bmp'")):
        assert main(argv) == 2
        assert words in capsys.readouterr().err
    assert not (tmp_path / "h.csv").exists() and not (tmp_path / "h.png").exists()


@pytest.mark.slow
def test_separating_points_have_no_stick_or_slide(case):
    """The Kia slower than the Lucid (0 and 1 m/s against 2.24 m/s): separating, no exchange, so neither
    stick nor slide: masked (grey) in the map, as invalid points are, and counted in the title (a grid over
    speed and restitution: the program of test_a_grid_axis_of_one_value_is_drawn_as_a_line)."""
    r = sweep(case, {"vehicles[1].speed": np.array([0.0, 1.0, 5.0, 9.0]), "contact.restitution": np.array([0.1, 0.9])},
              outputs=GRID_OUTPUTS)
    separating = r["status"] == 1
    assert separating[:2].all() and not separating[2:].any()
    ax = draw(r, "contact.sliding")
    shown = mesh_of(ax).get_array()
    np.testing.assert_array_equal(np.ma.getmaskarray(shown).reshape(r.shape), separating)
    assert "4 of 8 points without a result (grey)" in ax.get_title()


@pytest.mark.slow
def test_status_is_drawn_by_its_texts(case):
    """``"status"`` drawn as an output: each point's status in words (ks_jax.status_text of its code), on the
    colour bar of a map and on the axis of a line (the grid of test_separating_points_have_no_stick_or_slide,
    separating where the Kia is the slower)."""
    r = sweep(case, {"vehicles[1].speed": np.array([0.0, 1.0, 5.0, 9.0]), "contact.restitution": np.array([0.1, 0.9])},
              outputs=GRID_OUTPUTS)
    codes = np.unique(r["status"])
    texts = [ks_jax.status_text(int(c)) for c in codes]
    assert texts == ["ok", "separating"]
    ax = draw(r, "status")
    np.testing.assert_array_equal(mesh_of(ax).get_array(), np.searchsorted(codes, r["status"]))
    (bar,) = [a for a in ax.figure.axes if a is not ax]
    assert [t.get_text() for t in bar.get_yticklabels()] == texts
    assert ax.get_title() == "status"
    line = sweep(case, {"vehicles[1].speed": np.array([0.0, 1.0, 5.0])}, outputs=[DV1])
    ax = draw(line, "status")
    assert [t.get_text() for t in ax.get_yticklabels()] == texts
    np.testing.assert_array_equal(ax.get_lines()[0].get_ydata(), [1, 1, 0])


@pytest.mark.slow
def test_directions_are_drawn_on_the_circle(case):
    """A PDOF spread about 0 deg (the Kia's, with the Lucid's heading drawn about 0): the histogram is one
    hump unwrapped about the circular mean, not two bars at 0 and 360, on an axis that reads as plain
    numbers about 0 (-0.4, not 359.6), and its percentiles are those of the unwrapped samples, reported in
    [0, 360) and said where they are drawn."""
    yaw = np.radians(np.random.default_rng(5).normal(0.0, 3.0, 300))
    # the Kia's PDOF, and the Lucid's for the second histogram below
    z = sweep(case, {"vehicles[0].yaw": yaw}, outputs=["vehicles[1].pdof", "vehicles[0].pdof"], mode="zip")
    pdof = z["vehicles[1].pdof"]
    assert (pdof > 350).any() and (pdof < 10).any()  # both sides of north
    unwrapped = (pdof + 180.0) % 360.0 - 180.0
    ax = draw(z, "vehicles[1].pdof")
    lines = {ln.get_label().split(" ")[0]: ln for ln in ax.get_lines()}
    for name, q in (("median", 50), ("5th", 5), ("95th", 95)):
        x = np.percentile(unwrapped, q)
        assert lines[name].get_xdata()[0] == pytest.approx(x, abs=1e-9)
        assert f" {round(x % 360.0, 2) % 360.0:.2f} deg" in lines[name].get_label()
        assert (f"(drawn at {x:.2f})" in lines[name].get_label()) == (x < 0)
    left = min(p.get_x() for p in ax.patches)
    right = max(p.get_x() + p.get_width() for p in ax.patches)
    assert unwrapped.min() - 1e-9 <= left < 0 < right <= unwrapped.max() + 1e-9  # one hump about 0, no bar near 360
    assert ax.xaxis.get_major_formatter()(-1.0, 0) == "-1"  # the axis reads on through 0
    assert "drawn from -180 to 180 deg" in ax.get_title()

    # about 180 deg (the Lucid's PDOF): [0, 360) holds the hump, and the axis is as it would be anyway
    ax = draw(z, "vehicles[0].pdof")  # the same sweep
    assert 170 < min(p.get_x() for p in ax.patches) < 180 < max(p.get_x() + p.get_width() for p in ax.patches) < 190
    assert "-180" not in ax.get_title()


@pytest.mark.slow
def test_a_direction_the_same_everywhere_is_drawn_on_a_scale_of_whole_degrees(case):
    """The Kia is struck head-on wherever it is: PDOF 0 deg, to rounding on either side of 0 (359.99...,
    0.00...). The colour bar and a line's axis run over whole degrees about 0 (not 0.1 ... 0, 360, 359.9),
    and the title says the value."""
    # 8 x 3 points: the program of test_a_figure_leaves_out_what_is_constant_and_keeps_one_unit_system's
    r = sweep(case, {"vehicles[1].speed": np.linspace(8, 20, 8), "contact.restitution": [0.0, 0.2, 0.4]},
              outputs=FIGURE_OUTPUTS)
    pdof = r["vehicles[1].pdof"]
    assert np.all(np.minimum(pdof, 360.0 - pdof) < 1e-9)
    ax = draw(r, "vehicles[1].pdof")
    mesh = mesh_of(ax)
    assert (mesh.norm.vmin, mesh.norm.vmax) == (-1.0, 1.0)
    assert np.all(np.abs(mesh.get_array()) < 1e-9)
    bar = ax.figure.axes[-1]
    ticks = [bar.yaxis.get_major_formatter()(v, 0) for v in bar.get_yticks()]
    assert all(-1.0 <= float(t) <= 1.0 for t in ticks), ticks
    assert "0 deg everywhere" in ax.get_title()
    line = sweep(case, {"vehicles[1].speed": np.linspace(8, 20, 5)}, outputs=LINE_OUTPUTS)
    assert draw(line, "vehicles[1].pdof").get_ylim() == (-1.0, 1.0)


@pytest.mark.slow
def test_drawn_in_the_units_asked_for_and_those_typed(case):
    """SI by default; an input typed in km/h is drawn along its axis in km/h, and every output in the system
    asked for (delta-V in m/s with SI, mph with US, whatever unit the speed was typed in). The values are the
    sweep's divided by the unit's size, written out here: 1 km/h = 1/3.6 m/s, 1 ft lbf = 0.3048 x
    4.4482216152605 J."""
    speed = np.array([20.0, 40.0, 60.0]) / 3.6
    r = sweep(case, {"vehicles[1].speed": speed}, outputs=LINE_OUTPUTS)  # DV1 first: drawn when none is named
    si = draw(r, units="si")
    assert si.get_xlabel() == "vehicles[1].speed (Kia K5) [m/s]" and si.get_ylabel() == f"{DV1} (Lucid Air) [m/s]"
    np.testing.assert_allclose(si.get_lines()[0].get_ydata(), r[DV1], rtol=1e-12)
    for units, scale, unit in (("si", 1.0, "m/s"), ("us", MPH, "mph")):
        kmh = draw(r, units=units, typed={"vehicles[1].speed": "km/h"})
        assert kmh.get_xlabel() == "vehicles[1].speed (Kia K5) [km/h]"
        assert kmh.get_ylabel() == f"{DV1} (Lucid Air) [{unit}]"
        np.testing.assert_allclose(kmh.get_lines()[0].get_xdata(), [20.0, 40.0, 60.0], rtol=1e-12)
        np.testing.assert_allclose(kmh.get_lines()[0].get_ydata(), r[DV1] / scale, rtol=1e-12)
    for units, scale, unit in (("si", 1.0, "J"), ("us", 0.3048 * 4.4482216152605, "ft lbf")):
        ax = draw(r, "contact.energy_loss", units=units, typed={"vehicles[1].speed": "km/h"})
        assert ax.get_ylabel() == f"contact.energy_loss [{unit}]"
        np.testing.assert_allclose(ax.get_lines()[0].get_ydata(), r["contact.energy_loss"] / scale, rtol=1e-12)


@pytest.mark.slow
def test_cli_draws_in_the_units_typed_with_the_vehicles_names(tmp_path, capsys):
    """``ks-jax sweep --over vehicles[1].speed=10km/h:80km/h:8 --plot``: the picture's text (an SVG with its
    text kept as text) has the swept speed in km/h with the Kia's name, and its outputs in the system of
    ``--units`` only: the speed after in m/s and the energy in J (no mph anywhere), or in mph and ft lbf."""
    import matplotlib

    out = tmp_path / "k.csv"
    with matplotlib.rc_context({"svg.fonttype": "none"}):
        for units, speed, energy, other in (("si", "m/s", "J", "mph"), ("us", "mph", "ft lbf", "m/s")):
            svg = tmp_path / f"k_{units}.svg"
            assert main(["sweep", str(SEED1), "--over", "vehicles[1].speed=10km/h:80km/h:8", "--units", units,
                         "--output", "vehicles[1].speed_after", "--output", "contact.energy_loss",
                         "--out", str(out), "--plot", str(svg), "--no-progress"]) == 0
            text = svg.read_text()
            assert "vehicles[1].speed (Kia K5) [km/h]" in text
            assert f"vehicles[1].speed_after (Kia K5) [{speed}]" in text and f"contact.energy_loss [{energy}]" in text
            assert other not in text and text.count("km/h") == 2  # the two panels' speed axes
    capsys.readouterr()


def test_typed_units_are_read_from_the_values_given():
    from ks_jax.cli.sweep import typed_units

    assert typed_units(["vehicles[1].speed=10km/h:80km/h:8", "contact.restitution=0:0.5:3",
                        "vehicles[0].yaw=normal:0.1rad:0.02rad", "vehicles[0].speed=5 mph,10 mph"]) == {
        "vehicles[1].speed": "km/h", "vehicles[0].yaw": "rad", "vehicles[0].speed": "mph"}


@pytest.mark.slow
def test_a_sweeps_rate_counts_solving_and_its_compile_is_said_apart(case, monkeypatch):
    """Compiling is timed apart from solving: with the compile made 0.4 s slower, the sweep's seconds (and so
    its rate) do not change, its compile_seconds do, and the summary says both."""
    from ks_jax.sweeps import engine

    real = engine.compiled

    def slow(*args):
        time.sleep(0.4)
        return real(*args)

    monkeypatch.setattr(engine, "compiled", slow)
    r = sweep(case, {"vehicles[1].speed": np.linspace(10, 40, 16) * MPH}, outputs=[DV1])  # a program compiled above
    assert r.compile_seconds >= 0.4 > r.seconds
    assert f"compiled first in {r.compile_seconds:.3g} s" in r.summary()
    assert f"({r.points / r.seconds:.3g} points/s)" in r.summary()


def panels(fig):
    """The figure's panels (the axes with a title; not the colour bars), by the output each draws."""
    return {ax.get_title().split("\n")[0]: ax for ax in fig.axes if ax.get_visible() and ax.get_title()}


@pytest.mark.parametrize("units, typed, unit", [
    ("si", {"vehicles[1].speed": "mph"}, {"velocity": "m/s", "impulse": "N s", "energy": "J", "speed": "mph"}),
    ("us", None, {"velocity": "mph", "impulse": "lbf s", "energy": "ft lbf", "speed": "mph"}),
    ("us", {"vehicles[1].speed": "km/h"}, {"velocity": "mph", "impulse": "lbf s", "energy": "ft lbf", "speed": "km/h"}),
])
@pytest.mark.slow
def test_a_figure_leaves_out_what_is_constant_and_keeps_one_unit_system(case, units, typed, unit):
    """``ks-jax sweep --plot`` of the rear impact over the Kia's speed and the restitution: the Lucid is struck
    from behind (PDOF 180 deg) and the Kia from the front (0 deg) at every point, and an inline contact sticks
    (no tangential impulse): these get no panel but one line that says them; the panels left are every output
    that changes, each in the one system asked for (only the swept speed's axis in the unit it was typed in)."""
    outputs = FIGURE_OUTPUTS
    r = sweep(case, {"vehicles[1].speed": np.linspace(10, 60, 6) * MPH, "contact.restitution": [0.0, 0.1, 0.3]},
              outputs=outputs)
    fig = plot.sweep_figure(r, units=units, typed=typed)
    drawn = panels(fig)
    assert drawn.keys() == {f"contact.impulse_magnitude [{unit['impulse']}]", f"contact.energy_loss [{unit['energy']}]",
                            f"{DV1} (Lucid Air) [{unit['velocity']}]",
                            f"vehicles[1].delta_v_magnitude (Kia K5) [{unit['velocity']}]"}
    assert fig.get_suptitle() == ("constant over the sweep: contact.sliding = false (stick), "
                                  "vehicles[0].pdof (Lucid Air) = 180 deg, vehicles[1].pdof (Kia K5) = 0 deg")
    for ax in drawn.values():
        assert ax.get_xlabel() == f"vehicles[1].speed (Kia K5) [{unit['speed']}]"
    bars = [ax.get_ylabel() for ax in fig.axes if not ax.get_title() and ax.get_ylabel()]  # the colour bars
    assert sorted(bars) == sorted(title for title in drawn)
    # what is drawn is in those units: the Lucid's delta-V over the unit's size written out here
    size = {"m/s": 1.0, "mph": MPH}[unit["velocity"]]
    np.testing.assert_allclose(mesh_of(drawn[f"{DV1} (Lucid Air) [{unit['velocity']}]"]).get_array(), r[DV1] / size,
                               rtol=1e-12)
    # an output with no value at any solved point (the PDOF of a vehicle no impulse reached, as a third vehicle's
    # in a case of three) gets no empty panel: the line above names it
    gone = dataclasses.replace(r, outputs={**r.outputs, "vehicles[1].pdof": np.full(r.shape, np.nan)})
    fig = plot.sweep_figure(gone, units=units, typed=typed)
    assert panels(fig).keys() == drawn.keys()
    assert fig.get_suptitle().splitlines()[-1] == "undefined over the sweep: vehicles[1].pdof (Kia K5)"
    assert "vehicles[1].pdof (Kia K5) = " not in fig.get_suptitle()
    # only constant outputs: each keeps its panel, which says its value, and no line above them
    only = plot.sweep_figure(r, outputs=["vehicles[0].pdof", "contact.sliding"], units=units)
    assert len(panels(only)) == 2 and not only.get_suptitle()
    assert "180 deg everywhere" in panels(only)["vehicles[0].pdof (Lucid Air) [deg]"].get_title()
