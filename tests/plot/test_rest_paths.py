"""The top view of a case with a road: each vehicle's path from the exchange to rest, its outline at rest and
the measured rest positions are drawn where the results, a hand calculation and the given evidence put them."""

import dataclasses
import math
from importlib import resources

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np
import pytest

pytest.importorskip("matplotlib")

from matplotlib.figure import Figure
from matplotlib.patches import Ellipse

import fit
import ks_jax
from ks_jax import plot
from ks_jax import units as U
from ks_jax.plot.trajectory import draw_measured_rest
from ks_jax.solve import cases as solve_cases
from ks_jax.solve import motion_paths
from samples import assert_json_close

pytestmark = pytest.mark.slow  # every test draws the module fixture's solved motion to rest: compiling it is slow

# measured rest positions (the reconstruction case's evidence, fit_rest_positions.json), away from the solved
# ones so that a mark drawn at the solved rest position instead would fail
MEASURED = {"vehicles[0].rest_position[0]": 19.5 * U.FT, "vehicles[0].rest_position[1]": 50.6 * U.FT,
            "vehicles[1].rest_position[0]": 8.1 * U.FT, "vehicles[1].rest_position[1]": 14.3 * U.FT}
SIGMA = {"vehicles[0].rest_position[0]": 1.0 * U.FT, "vehicles[0].rest_position[1]": 2.0 * U.FT}


@pytest.fixture(scope="module")
def drawn():
    """The T-bone spin-out (explicit contact; both vehicles slide and turn to rest) solved once, its paths
    as ``motion_paths`` gives them, and its top view with the measured rest positions marked."""
    with resources.as_file(resources.files("ks_jax.cases") / "tbone_spin_out.json") as path:
        sol = ks_jax.solve(ks_jax.load_case(path))
    assert sol.status == "ok" and sol.result.rest is not None
    ax = plot.top_view(sol, Figure(figsize=(8, 7)).subplots(), evidence=MEASURED, sigma=SIGMA)
    ax.figure.canvas.draw()  # the equal aspect sets the final limits when drawn
    return sol, motion_paths(sol), ax


def by_gid(ax, gid):
    return [a for a in [*ax.lines, *ax.patches] if a.get_gid() == gid]


def hand_box(v, xy, yaw_deg):
    """A footprint's corners by hand: rear right, front right, front left, rear left (the front face is the
    second and third), from the CG ``xy``, the heading ``yaw_deg`` and the vehicle's size."""
    f = np.array([math.cos(math.radians(yaw_deg)), math.sin(math.radians(yaw_deg))])
    left = np.array([-f[1], f[0]])
    front, rear = float(v.cg_to_front), float(v.cg_to_front) - float(v.length)
    half = 0.5 * float(v.width)
    return np.array([xy + rear * f - half * left, xy + front * f - half * left,
                     xy + front * f + half * left, xy + rear * f + half * left])


@pytest.mark.parametrize("i", [0, 1])
def test_cg_path_runs_from_the_exchange_to_the_rest_position(drawn, i):
    sol, paths, ax = drawn
    (line,) = by_gid(ax, f"rest-path-{i}")
    xy = np.column_stack([line.get_xdata(), line.get_ydata()])
    rest = sol.result.rest[i]
    np.testing.assert_allclose(xy[-1], rest.rest_position, rtol=1e-6)
    # explicit contact: the exchange is at the case's own state
    np.testing.assert_allclose(xy[0], np.asarray(sol.case.inputs.vehicles[i].position)[:2], rtol=0, atol=1e-9)
    # the CG moves on: the drawn path is at least as long as the straight line from its start to rest
    assert np.sum(np.hypot(*np.diff(xy, axis=0).T)) >= np.linalg.norm(xy[-1] - xy[0]) > 1.0
    assert any(sol.case.vehicle_names[i] in t.get_text() and "CG path to rest" in t.get_text()
               for t in ax.get_legend().get_texts())


@pytest.mark.parametrize("i", [0, 1])
def test_rest_outline_is_the_box_at_the_rest_position_and_yaw(drawn, i):
    sol, _, ax = drawn
    rest, v = sol.result.rest[i], sol.case.inputs.vehicles[i]
    (outline,) = by_gid(ax, f"rest-outline-{i}")
    corners = np.column_stack([outline.get_xdata(), outline.get_ydata()])
    want = hand_box(v, np.asarray(rest.rest_position, float), float(rest.rest_yaw))
    np.testing.assert_allclose(corners, np.vstack([want, want[:1]]), rtol=0, atol=1e-9)
    assert outline.get_linestyle() == "-" and "at rest" in outline.get_label()
    (cg,) = by_gid(ax, f"rest-cg-{i}")
    np.testing.assert_allclose(np.ravel(cg.get_xydata()), rest.rest_position, rtol=1e-12)
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert f"{sol.case.vehicle_names[i]} at rest" in "\n".join(labels)


@pytest.mark.parametrize("i", [0, 1])
def test_outlines_on_the_way_sit_on_the_path(drawn, i):
    """Faded outlines between the exchange and rest, each a box about a point of the vehicle's path at that
    point's yaw (the path from ``motion_paths``), evenly spaced in time."""
    sol, paths, ax = drawn
    v, path = sol.case.inputs.vehicles[i], paths[i]
    outlines = by_gid(ax, f"path-outline-{i}")
    assert 6 <= len(outlines) <= 10
    steps = []
    for line in outlines:
        corners = np.column_stack([line.get_xdata(), line.get_ydata()])[:4]
        k = int(np.argmin([np.abs(hand_box(v, p[1:3], math.degrees(p[3])) - corners).max() for p in path]))
        np.testing.assert_allclose(corners, hand_box(v, path[k, 1:3], math.degrees(path[k, 3])), atol=1e-9)
        assert line.get_alpha() < 1
        steps.append(k)
    times = path[steps, 0]
    assert 0 < times[0] and times[-1] < path[-1, 0]
    gaps = np.diff(times)
    step = float(np.median(np.diff(path[:, 0])))
    np.testing.assert_allclose(gaps, gaps.mean(), atol=step)


def test_later_exchanges_leave_every_path_drawn(drawn):
    """The T-bone spin-out meets again after the first exchange (many small later exchanges, each marked where it
    happened): each vehicle's path to rest, its outlines on the way and at rest are drawn all the same."""
    sol, _, ax = drawn
    exchanges = sol.exchange_list()
    assert len(exchanges) > 1
    assert len([a for a in ax.lines if (a.get_gid() or "").startswith("exchange-")]) == len(exchanges) - 1
    for i in (0, 1):
        assert len(by_gid(ax, f"rest-path-{i}")) == 1 and len(by_gid(ax, f"rest-outline-{i}")) == 1
        assert by_gid(ax, f"path-outline-{i}")


def test_axes_take_in_every_path_and_mark(drawn):
    sol, paths, ax = drawn
    (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
    points = [p[:, 1:3] for p in paths] + [np.asarray(r.rest_position)[None] for r in sol.result.rest]
    points += [np.column_stack([a.get_xdata(), a.get_ydata()]) for a in ax.lines
               if (a.get_gid() or "").startswith(("rest-", "path-", "measured-"))]
    points += [np.array([[MEASURED[f"vehicles[{i}].rest_position[0]"], MEASURED[f"vehicles[{i}].rest_position[1]"]]])
               for i in (0, 1)]
    xy = np.vstack(points)
    assert (x0 <= xy[:, 0]).all() and (xy[:, 0] <= x1).all() and (y0 <= xy[:, 1]).all() and (xy[:, 1] <= y1).all()
    # every rest outline's corner too (the sedan's lies far from the contact)
    for i in (0, 1):
        rest = sol.result.rest[i]
        box = hand_box(sol.case.inputs.vehicles[i], np.asarray(rest.rest_position), float(rest.rest_yaw))
        assert ((x0 <= box[:, 0]).all() and (box[:, 0] <= x1).all()
                and (y0 <= box[:, 1]).all() and (box[:, 1] <= y1).all())


def test_measured_rest_positions_are_marked(drawn):
    sol, _, ax = drawn
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    for i in (0, 1):
        (mark,) = by_gid(ax, f"measured-rest-{i}")
        want = [MEASURED[f"vehicles[{i}].rest_position[{k}]"] for k in (0, 1)]
        np.testing.assert_allclose(np.ravel(mark.get_xydata()), want, rtol=1e-12)
        assert mark.get_marker() == "x"
        assert any(f"{sol.case.vehicle_names[i]} measured rest" in s for s in labels)
    # sigmas given for the sedan only: its ellipse, semi-axes 1 ft and 2 ft, about the mark
    (ellipse,) = by_gid(ax, "measured-rest-sigma-0")
    assert isinstance(ellipse, Ellipse)
    np.testing.assert_allclose(ellipse.center, [19.5 * U.FT, 50.6 * U.FT], rtol=1e-12)
    assert (ellipse.width, ellipse.height) == pytest.approx((2 * U.FT, 4 * U.FT), rel=1e-12)
    assert not by_gid(ax, "measured-rest-sigma-1")


def test_a_mark_needs_both_coordinates(drawn):
    sol, _, _ = drawn
    ax = Figure().subplots()
    draw_measured_rest(ax, sol.case.vehicle_names, {"vehicles[0].rest_position[0]": 1.0,
                                                    "vehicles[1]. rest_position[0]": 2.0,
                                                    "vehicles[1].rest_position[1]": 3.0}, None)
    assert not by_gid(ax, "measured-rest-0")
    (mark,) = by_gid(ax, "measured-rest-1")  # the path written with a space is read as the canonical one
    np.testing.assert_allclose(np.ravel(mark.get_xydata()), [2.0, 3.0])
    assert not [p for p in ax.patches if isinstance(p, Ellipse)]


def test_save_top_view_takes_one_evidence_per_panel(drawn, tmp_path):
    sol, _, _ = drawn
    with pytest.raises(ValueError, match="one mapping for all, or one per solution"):
        plot.save_top_view([sol, sol], tmp_path / "two.png", evidence=[MEASURED])


def test_the_paths_drawn_are_the_ones_solve_kept_and_a_solve_without_them_gives_the_same(drawn, monkeypatch):
    """``solve`` keeps a road case's paths, so its top view solves nothing more (and compiles no second program). A
    group whose paths would take more than ``PATH_BYTES`` is solved without them: the same numbers, and its picture
    solves it once more for the same paths, which end at the rest positions that the solve without them found."""
    sol, paths, _ = drawn
    assert all(r.path is not None for r in sol.result.rest)
    calls = []
    solve = solve_cases.solve
    monkeypatch.setattr(solve_cases, "solve", lambda case: calls.append(case.motion) or solve(case))
    for a, b in zip(motion_paths(sol), paths):
        np.testing.assert_array_equal(a, b)
    assert calls == []

    monkeypatch.setattr(solve_cases, "PATH_BYTES", 0)
    bare = solve(sol.case)
    assert all(r.path is None for r in bare.result.rest)
    assert_json_close(bare.to_dict(), sol.to_dict())  # two programs (with and without the steps)
    again = motion_paths(bare)
    assert [m.path for m in calls] == [True]
    for a, b, rest in zip(again, paths, bare.result.rest):
        np.testing.assert_array_equal(a, b)
        np.testing.assert_allclose(a[-1, 1:3], np.asarray(rest.rest_position)[:2], rtol=1e-12, atol=1e-12)



def test_fit_plot_solves_the_case_at_the_estimate(drawn):
    """``ks-jax fit --plot`` draws the case with its unknowns at the estimate (``fit.case_at``), and the inputs
    that follow them (a course that follows its yaw) moved too, as the fit solved it."""
    sol, _, _ = drawn
    estimate = {"vehicles[0].speed": 12.5, "vehicles[1].yaw": math.radians(80.0)}
    assert fit.case_at(sol.case, estimate).name == sol.case.name
    case = fit.case_at(sol.case, estimate, f"{sol.case.name}\nat the fit's estimate")
    assert float(ks_jax.get_input(case.inputs, "vehicles[0].speed")) == 12.5
    assert float(ks_jax.get_input(case.inputs, "vehicles[1].yaw")) == pytest.approx(math.radians(80.0))
    assert float(ks_jax.get_input(case.inputs, "vehicles[1].course")) == pytest.approx(math.radians(80.0))
    assert float(ks_jax.get_input(case.inputs, "vehicles[1].speed")) == float(sol.case.inputs.vehicles[1].speed)
    assert "estimate" in case.name


# names of the length reconstructionists write: a case named after its source and what happened, vehicles by
# model year, make, model, trim and colour
LONG_CASE = ("Reading Kudlich-Slibar Impulse Data (Virtual CRASH manual), intersection of Main Street and "
             "5th Avenue: a 2019 Ford F-150 into the right side of a 2015 Honda Accord, both spun out to rest")
LONG_NAMES = ("2015 Honda Accord EX-L V6 sedan (silver)", "2019 Ford F-150 XLT SuperCrew 4x4 (red)")


def inside(outer, inner, slack=0.5):
    """``inner`` (a Bbox, pixels) lies within ``outer``, to ``slack`` pixels (rounding)."""
    return (outer.x0 - slack <= inner.x0 and inner.x1 <= outer.x1 + slack
            and outer.y0 - slack <= inner.y0 and inner.y1 <= outer.y1 + slack)


@pytest.mark.parametrize("panels", [1, 3])
def test_long_names_keep_the_legend_and_the_title_inside_the_figure(drawn, panels):
    """With a long case name and vehicle names of 40 characters, every entry of the legend (the paths to rest
    with their "outlines every ... s", the outlines at rest with their "turned ... deg") and the whole title are
    in the figure ``ks-jax solve --plot`` writes, one panel or several: wrapped, none cut at its edge."""
    sol = drawn[0]
    case = dataclasses.replace(sol.case, name=LONG_CASE, vehicle_names=LONG_NAMES)
    fig = plot.top_view_figure([dataclasses.replace(sol, case=case)] * panels, evidence=MEASURED, sigma=SIGMA)
    renderer = fig.canvas.get_renderer()
    fig.canvas.draw()
    legends = [ax.get_legend() for ax in fig.axes if ax.get_legend() is not None]
    assert len(legends) == panels
    for legend in legends:
        assert inside(fig.bbox, legend.get_window_extent(renderer))
        labels = [t.get_text().replace("\n  ", " ") for t in legend.get_texts()]
        for i, name in enumerate(LONG_NAMES):  # every entry whole, once the line breaks are read back as spaces
            rest = sol.result.rest[i]
            assert any(s.startswith(f"{name}: CG path to rest") and s.endswith(
                f"outlines every {float(rest.time_to_rest) / 9:.2f} s") for s in labels), labels
            assert any(s.startswith(f"{name} at rest") and s.endswith(
                f"(turned {float(rest.rotation_to_rest):+.1f} deg)") for s in labels), labels
        assert any("\n" in t.get_text() for t in legend.get_texts())  # the long ones were wrapped
    titles = [ax.title for ax in fig.axes if ax.title.get_text()]
    assert len(titles) == panels and all(t.get_text().replace("\n", " ").startswith(LONG_CASE) for t in titles)
    # everything drawn (tick labels within the limits, axis labels of both units, titles, legends): each axes'
    # tight box, and the secondary axes' (feet) inside theirs
    boxes = [a.get_tightbbox(renderer) for ax in fig.axes if ax.get_visible() for a in [ax, *ax.child_axes]]
    assert len(boxes) == 3 * panels
    for box in boxes:
        assert inside(fig.bbox, box)
    assert not [t for t in fig.texts if t.get_visible() and not inside(fig.bbox, t.get_window_extent(renderer))]
