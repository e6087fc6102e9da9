"""The top view (ks_jax.plot): what is drawn is where the results and a hand calculation put it."""

import dataclasses
import io
import json
import math
import re
import warnings
from contextlib import redirect_stdout
from importlib import import_module, resources
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np
import pytest

pytest.importorskip("matplotlib")

import matplotlib.text
from matplotlib.colors import to_rgba
from matplotlib.figure import Figure
from matplotlib.patches import Polygon, Wedge

import ks_jax
from ks_jax import plot
from ks_jax.case import case_from_dict
from ks_jax.plot.outline import COLORS, clip_polygon
from ks_jax.plot.top_view import LATER_NORMAL, LATER_SHARE, top_view_figure
from ks_jax.solve import Solution
from ks_jax import units as U
from ks_jax.cli import main
from samples import SEED0

FT2 = U.FT**2


def case_path(name):
    return resources.files("ks_jax.cases") / name


def shoelace(xy):
    x, y = xy[:, 0], xy[:, 1]
    return 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def draw(solution):
    ax = Figure().subplots()
    plot.top_view(solution, ax)
    return ax


@pytest.mark.slow
def test_cli_writes_the_picture(tmp_path):
    png = tmp_path / "tbone.png"
    with resources.as_file(case_path("auto_tbone.json")) as path, redirect_stdout(io.StringIO()):
        assert main(["solve", str(path), "--json", "--plot", str(png)]) == 0
    data = png.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 20_000


@pytest.mark.slow
def test_automatic_tbone_drawing():
    with resources.as_file(case_path("auto_tbone.json")) as path:
        sol = ks_jax.solve(ks_jax.load_case(path))
    ax = draw(sol)
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert sum("at first contact" in s for s in labels) == 2 and sum("at the exchange" in s for s in labels) == 2
    # the impulse has a vertical part (centroid above one CG, below the other): the legend gives |J| as the
    # report does, and the horizontal part the arrow draws
    j = np.asarray(sol.result.contact.impulse)
    total, horizontal = f"{np.linalg.norm(j):,.0f}", f"{np.linalg.norm(j[:2]):,.0f}"
    assert total != horizontal
    assert (f"impulse on Sedan: {total} N s ({np.linalg.norm(j) / U.LBF_S:,.0f} lbf s), "
            f"horizontal part {horizontal} N s") in labels
    overlap = [p for p in ax.patches if isinstance(p, Polygon) and not isinstance(p, Wedge)]
    assert len(overlap) == 1
    # the pickup's front (6.7 ft wide) 44 ft/s * 0.05 s = 2.2 ft into the sedan's side
    assert shoelace(overlap[0].get_xy()[:-1]) == pytest.approx(6.7 * 2.2 * FT2, rel=1e-9)
    (wedge,) = [p for p in ax.patches if isinstance(p, Wedge)]
    assert wedge.theta2 - wedge.theta1 == pytest.approx(2 * math.degrees(math.atan(0.5)))
    assert 0.5 * (wedge.theta1 + wedge.theta2) == pytest.approx(90.0)  # about n = +y
    np.testing.assert_allclose(wedge.center, sol.result.contact.point[:2])
    # dashed outlines (first contact) are t_i = 19/44 s behind the solid ones along each path
    dashed = [ln for ln in ax.lines if ln.get_linestyle() == "--" and len(ln.get_xdata()) == 5]
    solid = [ln for ln in ax.lines if ln.get_linestyle() == "-" and len(ln.get_xdata()) == 5]
    assert len(dashed) == 2 and len(solid) == 2
    shift = np.array(solid[1].get_ydata()) - np.array(dashed[1].get_ydata())
    np.testing.assert_allclose(shift, 44 * U.FT * 0.05, rtol=1e-9)  # the pickup moves 2.2 ft in dt_p


@pytest.mark.parametrize("name", ["auto_tbone.json", "seed_001_lucid_kia.toml", "auto_seed_000.json"])
@pytest.mark.slow
def test_every_arrow_is_inside_the_axes(name):
    """Each arrow (the normal, the impulses, the velocities) ends inside the drawn limits: matplotlib
    does not draw an annotation whose tip is outside them (the normal of the T-bone was missing)."""
    with resources.as_file(case_path(name)) as path:
        sol = ks_jax.solve(ks_jax.load_case(path))
    ax = draw(sol)
    ax.figure.canvas.draw()
    (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
    arrows = [t for t in ax.texts if t.arrow_patch is not None]
    assert len(arrows) == 7  # the normal, two impulses, four velocities
    for a in arrows:
        for x, y in (a.xy, a.xyann):
            assert x0 <= x <= x1 and y0 <= y <= y1, (a.arrow_patch.get_edgecolor(), (x, y), (x0, x1), (y0, y1))


@pytest.mark.slow
def test_explicit_contact_drawing_and_two_panels(tmp_path):
    with resources.as_file(case_path("seed_001_lucid_kia.toml")) as path:
        sol = ks_jax.solve(ks_jax.load_case(path))
    ax = draw(sol)
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert not any("first contact" in s for s in labels)
    assert not [ln for ln in ax.lines if ln.get_linestyle() == "--"]
    (overlap,) = [p for p in ax.patches if isinstance(p, Polygon) and not isinstance(p, Wedge)]
    # at the case state: Lucid rear at 2.09 + 8.1 - 16.3 = -6.11 ft, Kia front at -11.64 + 6.85 = -4.79 ft
    assert shoelace(overlap.get_xy()[:-1]) == pytest.approx(1.32 * 6.0 * FT2, rel=1e-9)
    out = tmp_path / "both.png"
    plot.save_top_view([sol, sol], out)
    assert out.read_bytes()[:4] == b"\x89PNG"


@pytest.mark.slow
def test_clip_polygon_against_the_engine():
    """plot's NumPy clipping and the engine's fixed-size clipping give the same overlap."""
    from ks_jax.model.contact import overlap_polygon, polygon_area_centroid

    a = np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 2.0], [0.0, 2.0]])
    c, s = math.cos(0.4), math.sin(0.4)
    b = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]]) @ np.array([[c, s], [-s, c]]) + [3.5, 1.6]
    mine = clip_polygon(a, b)
    with jax.disable_jit():
        poly, count = overlap_polygon(np.asarray(a), np.asarray(b))
        area, centroid = polygon_area_centroid(poly, count)
    assert int(count) == len(mine)
    assert float(area) == pytest.approx(shoelace(mine), rel=1e-12)
    x, y = mine[:, 0], mine[:, 1]
    cr = x * np.roll(y, -1) - np.roll(x, -1) * y
    want = np.array([np.sum((x + np.roll(x, -1)) * cr), np.sum((y + np.roll(y, -1)) * cr)]) / (6 * np.sum(cr) / 2)
    np.testing.assert_allclose(np.asarray(centroid), want, rtol=1e-12)


# An oblique impact with low friction, in one plane (the centroid at both CGs' height, a horizontal normal):
# the contact slides and the impulse, horizontal, lies on the edge of the cone as drawn.
SLIDING = {
    "name": "oblique impact, low friction",
    "vehicles": [
        {"name": "Sedan", "mass": "1500 kg", "inertia": [500, 2400, 2600], "length": 4.7, "width": 1.8,
         "height": 1.45, "cg_to_front": 2.3, "cg_height": 0.55, "position": [0, 0], "yaw": 0, "speed": "10 km/h"},
        {"name": "SUV", "mass": "2000 kg", "inertia": [700, 3500, 3800], "length": 4.9, "width": 1.9,
         "height": 1.7, "cg_to_front": 2.4, "cg_height": 0.55, "position": [-3.2, -3.3], "yaw": 45,
         "speed": "50 km/h"},
    ],
    "contact": {"point": [-1.4, -0.9, 0.55], "normal": 110, "restitution": 0.1, "friction": 0.1},
}


def legend_texts(ax):
    return [t.get_text() for t in ax.get_legend().get_texts()]


def scale_in_legend(ax, pattern):
    """The X of the legend's "1 m = X unit" after ``pattern`` (a regular expression)."""
    (x,) = [float(m.group(1).replace(",", "")) for s in legend_texts(ax)
            for m in [re.search(pattern + r"1 m = ([\d,.]+(?:e[-+]?\d+)?) ", s)] if m]
    return x


def cone_edges(ax):
    """The dashed navy line along the cone's edge that marks a sliding contact."""
    return [ln for ln in ax.lines if ln.get_linestyle() == "--" and ln.get_color() == "navy"]


def impulse_arrows(ax, p):
    """The two impulse arrows: the annotations drawn from the centroid ``p`` that are not the (red) normal."""
    red = to_rgba("red")
    return [a for a in ax.texts if a.arrow_patch is not None and np.allclose(a.xyann, p, rtol=0, atol=1e-12)
            and tuple(a.arrow_patch.get_edgecolor()) != red]


def check_arrow_scales(sol, ax):
    """The impulse arrows are J's horizontal part (on vehicle 1) and its opposite (on vehicle 2) divided by
    the legend's impulse scale, and the velocity arrows are as long as each speed (before, after) divided
    by the legend's velocity scale."""
    c = sol.result.contact
    p = np.asarray(c.point)[:2]
    per_m = scale_in_legend(ax, "impulse arrows: ")
    (lbf,) = [re.search(r"N s \(([\d,.]+) lbf s\)", s).group(1) for s in legend_texts(ax) if "impulse arrows" in s]
    assert float(lbf.replace(",", "")) == pytest.approx(per_m / U.LBF_S, rel=1e-5)
    j = np.asarray(c.impulse)[:2]
    drawn = sorted((np.subtract(a.xy, a.xyann) for a in impulse_arrows(ax, p)), key=lambda d: -np.dot(d, j))
    assert len(drawn) == 2
    for d, sign in zip(drawn, (1.0, -1.0)):
        np.testing.assert_allclose(d, sign * j / per_m, rtol=1e-6, atol=1e-9 * np.linalg.norm(j) / per_m)
        assert np.linalg.norm(d) == pytest.approx(np.linalg.norm(j) / per_m, rel=1e-6)
    # velocities: every CG arrow's length is a speed over the stated scale
    v_per_m = scale_in_legend(ax, r"CG velocity before \(")
    assert v_per_m == scale_in_legend(ax, r"CG velocity after \(")
    speeds = [float(v.speed) for v in sol.case.inputs.vehicles]
    speeds += [float(np.linalg.norm(np.asarray(v.velocity_after)[:2])) for v in sol.result.vehicles]
    lengths = [float(np.linalg.norm(np.subtract(a.xy, a.xyann))) for a in ax.texts
               if a.arrow_patch is not None and not np.allclose(a.xyann, p, rtol=0, atol=1e-12)]
    np.testing.assert_allclose(sorted(lengths), sorted(s / v_per_m for s in speeds if s > 0), rtol=1e-9)
    return drawn


def test_sliding_contact_is_marked_and_the_arrows_are_to_scale(tmp_path):
    path = tmp_path / "sliding.json"
    path.write_text(json.dumps(SLIDING))
    sol = ks_jax.solve(ks_jax.load_case(path))
    c = sol.result.contact
    assert sol.status == "ok" and bool(c.sliding)
    assert c.impulse_tangential == pytest.approx(0.1 * c.impulse_normal, rel=1e-9)  # |T| = mu N
    ax = draw(sol)
    assert "sliding (|T| = mu N)" in ax.get_title()
    labels = legend_texts(ax)
    assert "sliding: |T| = mu N, impulse on the cone's edge (dashed)" in labels
    assert not any("sticking" in s for s in labels + [ax.get_title()])
    on_1, _ = check_arrow_scales(sol, ax)
    # the impulse on vehicle 1 lies on an edge of the wedge drawn, and along the dashed edge line
    (wedge,) = [p for p in ax.patches if isinstance(p, Wedge)]
    mid = 0.5 * (wedge.theta1 + wedge.theta2)
    off = (math.degrees(math.atan2(on_1[1], on_1[0])) - mid + 180.0) % 360.0 - 180.0
    assert abs(off) == pytest.approx(0.5 * (wedge.theta2 - wedge.theta1), abs=1e-9)
    (edge,) = cone_edges(ax)
    along = np.array([np.ptp(edge.get_xdata()), np.ptp(edge.get_ydata())]) * np.sign(on_1)
    np.testing.assert_allclose(along / np.linalg.norm(along), on_1 / np.linalg.norm(on_1), atol=1e-9)
    assert np.linalg.norm(along) > np.linalg.norm(on_1)  # it shows past the arrow's head


def test_sticking_contact_is_marked_and_the_arrows_are_to_scale():
    with resources.as_file(case_path("auto_tbone.json")) as path:
        sol = ks_jax.solve(ks_jax.load_case(path))
    c = sol.result.contact
    assert not bool(c.sliding) and c.impulse_tangential > 0.1 * c.impulse_normal  # inside the cone, off its axis
    ax = draw(sol)
    assert "sticking (inside the cone)" in ax.get_title()
    labels = legend_texts(ax)
    ratio = f"{c.impulse_tangential / c.impulse_normal:.3f}"
    assert f"sticking (inside the cone): |T| / N = {ratio} <= mu = 0.5" in labels
    assert not any("sliding" in s for s in labels + [ax.get_title()])
    assert not cone_edges(ax)
    check_arrow_scales(sol, ax)


def test_wrapped_lines_fit_the_width_as_drawn():
    """``wrap_to_width`` breaks between words only, keeps a name with its value, and every line, drawn by
    matplotlib's Agg renderer (not the font measure it wraps by), is no wider than asked."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    from ks_jax.plot.text import wrap_to_width

    text = ("2015 Honda Accord EX-L V6 sedan (silver) at first contact, t_i = 0.1580 s; "
            "2019 Ford F-150 XLT SuperCrew 4x4 (red): CG path to rest, 17.80 m (58.4 ft) in 3.57 s")
    fig = Figure(dpi=72)  # 1 pixel = 1 point
    FigureCanvasAgg(fig)
    for width in (120.0, 200.0, 330.0):
        wrapped = wrap_to_width(text, width, 6.5)
        lines = wrapped.split("\n")
        assert len(lines) >= 2 and all(line.startswith("  ") for line in lines[1:])
        assert " ".join(line.strip() for line in lines) == text
        assert not any(line.rstrip().endswith(("t_i", "=")) for line in lines)
        for line in lines:
            drawn = fig.text(0, 0, line, fontsize=6.5).get_window_extent(fig.canvas.get_renderer())
            assert drawn.width <= width + 0.5, (line, drawn.width)
    assert wrap_to_width("a\nb", 100.0, 6.5) == "a\nb"


def test_names_with_control_characters_are_drawn_as_their_escapes(tmp_path):
    """A case and a vehicle named with an escape sequence and a direction override: the picture shows their
    escapes (as the panel does), so that no glyph is missing and nothing is drawn reversed."""
    case = ks_jax.load_case(SEED0)
    bad = ("Crash \x1b[2J\u202eevil\u202c", "Saturn \x07")
    case = dataclasses.replace(case, name=bad[0], vehicle_names=(bad[1], case.vehicle_names[1]))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # matplotlib warns of a glyph it cannot draw
        fig = top_view_figure([ks_jax.solve(case)])
        fig.canvas.draw()
    texts = [t.get_text() for t in fig.findobj(matplotlib.text.Text)]
    assert any("\\x1b[2J\\u202eevil\\u202c" in t for t in texts) and any("Saturn \\x07" in t for t in texts)
    assert not any(c in t for t in texts for c in "\x1b\u202e\u202c\x07")


# Cases with a road run a watched motion after the first exchange (docs/model.md, "Contact interactions"): the top
# view draws every later exchange where it happened, numbered as the panel numbers them.


@pytest.fixture(scope="module")
def wall_slap():
    """The sedan glancing off a wall (its rear then slaps it: several exchanges, two of them at least
    ``LATER_SHARE`` of the largest, one smaller) solved once, and its top view as drawn, without the path to rest
    (which would solve it again; tests/plot/test_rest_paths.py draws the paths of a case with later exchanges)."""
    with resources.as_file(case_path("wall_side_slap.json")) as path:
        sol = ks_jax.solve(ks_jax.load_case(path))
    sol = dataclasses.replace(sol, result=sol.result._replace(rest=None))
    ax = draw(sol)
    ax.figure.canvas.draw()  # the equal aspect sets the final limits when drawn
    return sol, ax


def by_gid(ax, gid):
    return [a for a in [*ax.lines, *ax.patches, *ax.texts] if a.get_gid() == gid]


def later_gids(ax):
    """The gids of every artist the later exchanges drew ("exchange-..."; "#0" beside the first included)."""
    artists = [*ax.lines, *ax.patches, *ax.texts]
    return sorted(a.get_gid() for a in artists if (a.get_gid() or "").startswith("exchange-"))


@pytest.mark.slow
def test_later_exchanges_are_drawn_where_they_happened(wall_slap):
    sol, ax = wall_slap
    exchanges = sol.exchange_list()
    sizes = [ex["impulse_magnitude"] for ex in exchanges]
    big = [ex["index"] for ex in exchanges[1:] if ex["impulse_magnitude"] >= LATER_SHARE * max(sizes)]
    small = [ex["index"] for ex in exchanges[1:] if ex["index"] not in big]
    assert len(exchanges) >= 3 and big and small  # both kinds of later exchange are drawn
    # one marker at each later exchange's centroid: an open circle for a large one, a dot for a small one
    markers = [a for a in ax.lines if re.fullmatch(r"exchange-\d+", a.get_gid() or "")]
    assert len(markers) == len(exchanges) - 1
    for ex in exchanges[1:]:
        (marker,) = by_gid(ax, f"exchange-{ex['index']}")
        np.testing.assert_allclose(np.ravel(marker.get_xydata()), ex["point"][:2], rtol=0, atol=1e-12)
        assert marker.get_marker() == "o" and marker.get_markersize() == (6 if ex["index"] in big else 2)
    # the numbers: "#k" at each large one's centroid, "#0" at the first's, none at a small one
    for k in [0, *big]:
        (number,) = by_gid(ax, f"exchange-number-{k}")
        assert number.get_text() == f"#{k}"
        np.testing.assert_allclose(number.xy, exchanges[k]["point"][:2], rtol=0, atol=1e-12)
    for k in small:
        assert not by_gid(ax, f"exchange-number-{k}") and not by_gid(ax, f"exchange-impulse-{k}-0")
    numbers = sorted(t.get_text() for t in ax.texts if t.get_text().startswith("#"))
    assert numbers == sorted(f"#{k}" for k in [0, *big])
    labels = legend_texts(ax)
    assert any(s.startswith(f"{len(exchanges)} exchanges, numbered as the panel numbers them") for s in labels)
    assert any(s.startswith(f"later exchange ({len(big)}, impulse at least 5% of the largest") for s in labels)
    assert any(s.startswith(f"smaller later exchange ({len(small)}, impulse under 5%") for s in labels)


@pytest.mark.slow
def test_later_exchanges_normal_and_impulse_on_the_first_exchanges_scale(wall_slap):
    """A large later exchange's normal (a short red arrow from its centroid) and its impulse on the vehicle (its
    horizontal part over the legend's impulse scale: the scale of the first exchange's arrow, so that their sizes
    compare); every arrow inside the axes."""
    sol, ax = wall_slap
    exchanges = sol.exchange_list()
    per_m = scale_in_legend(ax, "impulse arrows: ")
    j0 = np.asarray(exchanges[0]["impulse"])[:2]
    (first,) = impulse_arrows(ax, np.asarray(sol.result.contact.point)[:2])  # one vehicle against the wall
    np.testing.assert_allclose(np.subtract(first.xy, first.xyann), j0 / per_m, rtol=1e-9)
    v = sol.case.inputs.vehicles[0]  # the one vehicle (the wall stands in as the second)
    extent = max(float(v.length), float(v.width))
    drawn = 0
    for ex in exchanges[1:]:
        k, p = ex["index"], np.asarray(ex["point"])[:2]
        if not by_gid(ax, f"exchange-number-{k}"):
            continue
        (normal,) = by_gid(ax, f"exchange-normal-{k}")
        n = np.asarray(ex["normal"])[:2]
        np.testing.assert_allclose(normal.xyann, p, rtol=0, atol=1e-12)
        np.testing.assert_allclose(np.subtract(normal.xy, normal.xyann), LATER_NORMAL * extent * n / np.linalg.norm(n),
                                   rtol=1e-9, atol=1e-12)
        (arrow,) = by_gid(ax, f"exchange-impulse-{k}-0")
        np.testing.assert_allclose(arrow.xyann, p, rtol=0, atol=1e-12)
        np.testing.assert_allclose(np.subtract(arrow.xy, arrow.xyann), np.asarray(ex["impulse"])[:2] / per_m,
                                   rtol=1e-9, atol=1e-12)
        assert not by_gid(ax, f"exchange-impulse-{k}-1")  # the wall gets no arrow
        drawn += 1
    assert drawn >= 2
    (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
    for a in [t for t in ax.texts if t.arrow_patch is not None]:
        for x, y in (a.xy, a.xyann):
            assert x0 <= x <= x1 and y0 <= y <= y1


@pytest.mark.slow
def test_the_wall_face_takes_in_every_exchange_with_it(wall_slap):
    """The wall's face is drawn 1.2 vehicle lengths beyond the first centroid's foot and beyond each later one's
    (the rear's slap lies further along the wall than the first exchange's face would reach)."""
    sol, ax = wall_slap
    (wall,) = [p for p in ax.patches if "(fixed wall; its face)" in p.get_label()]
    ends = wall.get_xy()[:2]  # the face's two ends, then the hatched depth behind it
    along = (ends[1] - ends[0]) / np.linalg.norm(ends[1] - ends[0])
    v = sol.case.inputs.vehicles[0]
    half = 1.2 * max(float(v.length), float(v.width))
    reach = [float(along @ (np.asarray(ex["point"])[:2] - ends[0])) for ex in sol.exchange_list()]
    assert min(reach) == pytest.approx(half, rel=1e-9)
    assert max(reach) == pytest.approx(np.linalg.norm(ends[1] - ends[0]) - half, rel=1e-9)
    assert max(abs(r - reach[0]) for r in reach) > half  # one lies beyond the face drawn about the first alone


@dataclasses.dataclass
class Pushed(Solution):
    """A solution whose exchanges after the first are ``later`` (plain data, as ``exchange_list`` gives them)."""

    later: list = dataclasses.field(default_factory=list)

    def exchange_list(self):
        return Solution.exchange_list(self)[:1] + self.later


@pytest.mark.slow
def test_a_push_of_many_small_exchanges_is_drawn_as_dots(wall_slap):
    """20 exchanges of 50 N s after the first (a sustained push): a dot at each centroid, no number, no arrow; the
    legend says how many exchanges there were."""
    sol, _ = wall_slap
    first, one = sol.exchange_list()[:2]
    later = [dict(one, index=k, point=[6.0, 11.0 + 0.05 * k, 0.7], impulse=[-50.0, 0.0, 0.0], impulse_magnitude=50.0)
             for k in range(1, 21)]
    ax = draw(Pushed(sol.case, sol.result, sol.status, later))
    assert [t.get_text() for t in ax.texts if t.get_text().startswith("#")] == ["#0"]
    assert not [g for g in later_gids(ax) if g.startswith(("exchange-normal", "exchange-impulse"))]
    dots = [a for a in ax.lines if re.fullmatch(r"exchange-\d+", a.get_gid() or "")]
    assert len(dots) == 20 and {a.get_markersize() for a in dots} == {2}
    np.testing.assert_allclose([np.ravel(a.get_xydata()) for a in dots], [ex["point"][:2] for ex in later])
    labels = legend_texts(ax)
    assert any(s.startswith("21 exchanges, numbered as the panel numbers them") for s in labels)
    assert any(s.startswith("smaller later exchange (20, impulse under 5%") for s in labels)


def test_a_single_exchange_case_draws_no_later_exchange_artists():
    with resources.as_file(case_path("seed_001_lucid_kia.toml")) as path:
        sol = ks_jax.solve(ks_jax.load_case(path))
    assert len(sol.exchange_list()) == 1
    ax = draw(sol)
    assert later_gids(ax) == []
    assert not [t for t in ax.texts if t.get_text().startswith("#")]
    assert not any("exchange" in s for s in legend_texts(ax))


# A case of several bodies (docs/model.md, "Contact interactions"): three vehicles and a pole, the first exchange
# between vehicles[2] (its vehicle 1) and vehicles[1] (its vehicle 2), not the first two bodies. The van strikes the
# pickup's side; the sedan then runs into the pickup's rear, and the pickup is pushed into the pole.


def car(name, mass, length, width, cg_to_front, xy, yaw, speed):
    return {"name": name, "mass": f"{mass} kg", "inertia": [0.2 * mass, 1.5 * mass, 1.7 * mass],
            "length": f"{length} m", "width": f"{width} m", "height": "1.5 m", "cg_to_front": f"{cg_to_front} m",
            "cg_height": "0.6 m", "wheelbase": "2.8 m", "track": "1.6 m", "cg_to_front_axle": "1.3 m",
            "position": [f"{xy[0]} m", f"{xy[1]} m"], "yaw": yaw, "speed": f"{speed} m/s",
            "after": {"wheels": "locked"}}


SEVERAL = {
    "name": "three vehicles and a pole",
    "vehicles": [car("2015 Honda Accord EX-L V6 sedan", 1500, 4.9, 1.85, 2.3, (-14.0, 0.3), 0, 14.0),
                 car("2019 Ford F-150 XLT SuperCrew pickup", 2300, 5.9, 2.0, 2.6, (0.0, 0.0), 0, 0.0),
                 car("2018 Toyota Sienna van", 2000, 5.1, 1.95, 2.4, (0.8, -6.0), 90, 8.0)],
    "fixed": [{"kind": "pole", "position": ["1.2 m", "2.6 m"], "diameter": "0.35 m", "name": "utility pole"}],
    "between": [2, 1],
    "contact": {"restitution": 0.1, "friction": 0.5, "penetration_time": "0.03 s"},
    "road": {"friction": 0.7, "time_limit": "3 s"},
    "interaction": {"max_exchanges": 8},
}


@pytest.fixture(scope="module")
def several():
    """``SEVERAL`` solved once and its top view as ``ks-jax solve --plot`` draws it (``top_view_figure``: the paths
    to rest included, which solve it once more), drawn so that the equal aspect has set the limits."""
    sol = ks_jax.solve(case_from_dict(SEVERAL))
    assert sol.status == "ok" and sol.case.between == (2, 1) and sol.case.vehicle_count == 3
    fig = top_view_figure([sol])
    fig.canvas.draw()
    return sol, fig.axes[0]


def hand_box(v, xy, yaw):
    """A footprint's corners by hand, from the CG ``xy``, the heading ``yaw`` (rad) and the vehicle's size: rear
    right, front right, front left, rear left."""
    f = np.array([math.cos(yaw), math.sin(yaw)])
    left = np.array([-f[1], f[0]])
    front, rear, half = float(v.cg_to_front), float(v.cg_to_front) - float(v.length), 0.5 * float(v.width)
    return np.array([xy + rear * f - half * left, xy + front * f - half * left, xy + front * f + half * left,
                     xy + rear * f + half * left])


def free_pose(v, t):
    """A vehicle's CG and yaw after free motion for ``t`` s from the case state."""
    xy = np.asarray(v.position, float)[:2] + float(v.speed) * t * np.array([math.cos(v.course), math.sin(v.course)])
    return xy, float(v.yaw) + float(np.asarray(v.angular_velocity)[2]) * t


def drawn_polygon(line):
    """A closed outline's corners as drawn (its last point repeats its first)."""
    xy = np.column_stack([line.get_xdata(), line.get_ydata()])
    np.testing.assert_allclose(xy[-1], xy[0], rtol=0, atol=1e-12)
    return xy[:-1]


@pytest.mark.slow
def test_every_vehicle_is_drawn_as_its_box_in_its_own_colour(several):
    """Each vehicle's outline at the first exchange and at first contact is its box moved freely from the case state
    (the vehicle not in the first exchange as far as its pair), in the vehicle's own colour, labelled with its name."""
    sol, ax = several
    inputs = sol.case.inputs
    t_i = float(sol.result.contact.time)
    t_x = t_i + float(inputs.contact.penetration_time)
    labels = legend_texts(ax)
    colours = []
    for i, name in enumerate(sol.case.vehicle_names[:3]):
        v = inputs.vehicles[i]
        for gid, t in ((f"outline-{i}", t_x), (f"first-contact-outline-{i}", t_i)):
            (line,) = by_gid(ax, gid)
            np.testing.assert_allclose(drawn_polygon(line), hand_box(v, *free_pose(v, t)), rtol=0, atol=1e-9)
        colours.append(to_rgba(line.get_color()))
        assert any(s.replace("\n  ", " ").startswith(f"{name} at the first exchange, t = {t_x:.4f} s")
                   for s in labels)
    assert len(set(colours)) == 3
    assert not by_gid(ax, "outline-3")  # the pole is no vehicle


@pytest.mark.slow
def test_the_fixed_object_is_drawn_as_what_it_is(several):
    sol, ax = several
    (pole,) = by_gid(ax, "fixed-0")
    obj = sol.case.fixed[0]
    np.testing.assert_allclose(pole.center, obj.position, rtol=0, atol=1e-12)
    assert pole.radius == pytest.approx(0.5 * 0.35, rel=1e-12)
    assert pole.get_label() == "utility pole (fixed pole, 0.350 m)"


@pytest.mark.slow
def test_the_first_exchange_is_drawn_for_its_pair(several):
    """The overlap, the normal, the cone and the impulse arrows are those of the first exchange's pair (vehicles[2]
    and vehicles[1]): each arrow starts at the centroid and is the impulse on its vehicle, its mass times its delta-V,
    over the legend's scale; the vehicle outside the exchange gets none."""
    sol, ax = several
    c, inputs = sol.result.contact, sol.case.inputs
    p = np.asarray(c.point)[:2]
    per_m = scale_in_legend(ax, "impulse arrows: ")
    for b in (2, 1):
        (arrow,) = by_gid(ax, f"impulse-{b}")
        np.testing.assert_allclose(arrow.xyann, p, rtol=0, atol=1e-12)
        on_b = float(inputs.vehicles[b].mass) * np.asarray(sol.result.vehicles[b].delta_v)[:2]
        np.testing.assert_allclose(np.subtract(arrow.xy, arrow.xyann), on_b / per_m, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(np.subtract(*(by_gid(ax, f"impulse-{b}")[0].xy for b in (2, 1))),
                               2 * np.asarray(c.impulse)[:2] / per_m, rtol=1e-9)  # J on vehicle 1, -J on vehicle 2
    assert not by_gid(ax, "impulse-0") and len(impulse_arrows(ax, p)) == 2
    (wedge,) = [w for w in ax.patches if isinstance(w, Wedge)]
    np.testing.assert_allclose(wedge.center, p, rtol=0, atol=1e-12)
    n = np.asarray(c.normal)[:2]
    assert 0.5 * (wedge.theta1 + wedge.theta2) == pytest.approx(math.degrees(math.atan2(n[1], n[0])), abs=1e-9)
    # the overlap lies in both of the pair's boxes at the exchange, and not in the sedan's
    t_x = float(c.time) + float(inputs.contact.penetration_time)
    (overlap,) = [q for q in ax.patches if isinstance(q, Polygon) and (q.get_label() or "").startswith("overlap")]
    corners = overlap.get_xy()[:-1]
    assert shoelace(corners) > 0.01
    for b in (2, 1):
        box = hand_box(inputs.vehicles[b], *free_pose(inputs.vehicles[b], t_x))
        assert shoelace(clip_polygon(corners, box)) == pytest.approx(shoelace(corners), rel=1e-9)
    sedan = hand_box(inputs.vehicles[0], *free_pose(inputs.vehicles[0], t_x))
    assert len(clip_polygon(corners, sedan)) == 0
    names = sol.case.vehicle_names
    assert f"normal n (from {names[1]} into {names[2]})" in [s.replace("\n  ", " ") for s in legend_texts(ax)]


@pytest.mark.slow
def test_every_later_exchange_is_numbered_at_its_centroid_with_its_impulses(several):
    """Each later exchange of any pair (vehicles, or a vehicle and the pole) is marked at its centroid, a large one
    numbered there, its impulse arrow on each vehicle of its pair the vehicle's mass times its delta-V in that
    exchange over the legend's scale, none on the pole."""
    sol, ax = several
    exchanges = sol.exchange_list()
    per_m = scale_in_legend(ax, "impulse arrows: ")
    largest = max(ex["impulse_magnitude"] for ex in exchanges)
    big = [ex for ex in exchanges[1:] if ex["impulse_magnitude"] >= LATER_SHARE * largest]
    pairs = {tuple(ex["between"]) for ex in big}
    assert {(0, 1), (1, "fixed[0]")} <= pairs  # a pair without the first exchange's vehicle 1, and the pole
    (first,) = by_gid(ax, "exchange-number-0")
    np.testing.assert_allclose(first.xy, np.asarray(sol.result.contact.point)[:2], rtol=0, atol=1e-12)
    for ex in exchanges[1:]:
        k, p = ex["index"], np.asarray(ex["point"])[:2]
        (marker,) = by_gid(ax, f"exchange-{k}")
        np.testing.assert_allclose(np.ravel(marker.get_xydata()), p, rtol=0, atol=1e-12)
    for ex in big:
        k, p = ex["index"], np.asarray(ex["point"])[:2]
        (number,) = by_gid(ax, f"exchange-number-{k}")
        assert number.get_text() == f"#{k}"
        np.testing.assert_allclose(number.xy, p, rtol=0, atol=1e-12)
        for entry in ex["vehicles"]:
            b = entry["vehicle"]
            (arrow,) = by_gid(ax, f"exchange-impulse-{k}-{b}")
            np.testing.assert_allclose(arrow.xyann, p, rtol=0, atol=1e-12)
            on_b = float(sol.case.inputs.vehicles[b].mass) * np.asarray(entry["delta_v"])[:2]
            np.testing.assert_allclose(np.subtract(arrow.xy, arrow.xyann), on_b / per_m, rtol=1e-9, atol=1e-12)
        assert len([g for g in later_gids(ax) if g.startswith(f"exchange-impulse-{k}-")]) == len(ex["vehicles"])


@pytest.mark.slow
def test_every_vehicle_path_runs_from_the_first_exchange_to_its_rest_position(several):
    sol, ax = several
    inputs = sol.case.inputs
    t_x = float(sol.result.contact.time) + float(inputs.contact.penetration_time)
    for i in range(3):
        rest, v = sol.result.rest[i], inputs.vehicles[i]
        (line,) = by_gid(ax, f"rest-path-{i}")
        xy = np.column_stack([line.get_xdata(), line.get_ydata()])
        np.testing.assert_allclose(xy[0], free_pose(v, t_x)[0], rtol=0, atol=1e-9)
        np.testing.assert_allclose(xy[-1], rest.rest_position, rtol=1e-6, atol=1e-9)
        assert np.linalg.norm(xy[-1] - xy[0]) > 0.5  # every vehicle was struck and moved
        (outline,) = by_gid(ax, f"rest-outline-{i}")
        np.testing.assert_allclose(drawn_polygon(outline),
                                   hand_box(v, np.asarray(rest.rest_position), math.radians(float(rest.rest_yaw))),
                                   rtol=0, atol=1e-9)
    assert sol.result.rest[3] is None and not by_gid(ax, "rest-path-3")


@pytest.mark.slow
def test_the_legend_of_several_vehicles_fits_below_the_axes(several):
    """Every legend entry (three long vehicle names, each in several entries) is inside the figure, no wider than
    the axes, and below the axes' x label."""
    sol, ax = several
    fig = ax.figure
    renderer = fig.canvas.get_renderer()
    axes = ax.get_window_extent(renderer)
    label = ax.xaxis.label.get_window_extent(renderer)
    legend = ax.get_legend()
    assert legend.get_window_extent(renderer).y1 <= label.y0
    for text in legend.get_texts():
        box = text.get_window_extent(renderer)
        assert axes.x0 - 1 <= box.x0 and box.x1 <= axes.x1 + 1 and box.y0 >= 0, text.get_text()
    texts = [s.replace("\n  ", " ") for s in legend_texts(ax)]
    for name in sol.case.vehicle_names[:3]:
        assert sum(s.startswith(name) for s in texts) == 4  # at first contact, at the exchange, path, at rest


def test_eight_vehicles_have_eight_colours_apart_from_the_contacts():
    """One colour per vehicle of a case (at most 8), none of them the red of the plane and normal, the cyan of the
    cone, the navy of a sliding edge, the black of the centroids or the grey of the overlap and fixed objects."""
    colours = [to_rgba(c) for c in COLORS]
    assert len(COLORS) == 8 and len(set(colours)) == 8
    reserved = [to_rgba(c) for c in ("red", "tab:cyan", "darkcyan", "navy", "black", "0.6", "0.75", "0.25")]
    assert all(np.linalg.norm(np.subtract(c, r)) > 0.2 for c in colours for r in reserved)


SEMI = Path(__file__).resolve().parents[2] / "docs" / "examples" / "semi_trailer_side_impact.json"


@pytest.fixture(scope="module")
def semi():
    """docs/examples/semi_trailer_side_impact.json (a sedan into a semi-trailer on its tractor's fifth wheel, 8 ft
    behind the tractor's CG) solved once and its top view as drawn, the rest results kept but not the paths to rest
    (which would solve it again; the hitch at rest is drawn from the rest results)."""
    sol = ks_jax.solve(ks_jax.load_case(SEMI))
    assert sol.status == "ok" and sol.case.motion.links == ((1, 2, "fifth_wheel"),)
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(import_module("ks_jax.plot.top_view"), "trajectories", lambda solution: None)
        ax = draw(sol)
    return sol, ax


def drawn_points(line):
    return np.column_stack([line.get_xdata(), line.get_ydata()])


@pytest.mark.slow
def test_the_hitch_is_drawn_at_the_tractors_fifth_wheel(semi):
    """At the first exchange the hitch's marker is 8 ft behind the tractor's CG moved freely from the case state (both
    head north: 8 ft south of it), at rest 8 ft behind the tractor's rest CG along its rest yaw; each marker's line
    runs from the tractor's CG through it to the trailer's CG. One legend entry for the hitch."""
    sol, ax = semi
    d, inputs = sol.to_dict(), sol.case.inputs
    t_x = float(sol.result.contact.time) + float(inputs.contact.penetration_time)
    tractor, _ = free_pose(inputs.vehicles[2], t_x)
    trailer, _ = free_pose(inputs.vehicles[1], t_x)
    at_exchange = tractor + np.array([0.0, -8.0 * U.FT])
    rest_yaw = math.radians(d["vehicles"][2]["rest_yaw"])
    at_rest = np.asarray(d["vehicles"][2]["rest_position"]) - 8.0 * U.FT * np.array([math.cos(rest_yaw),
                                                                                     math.sin(rest_yaw)])
    for prefix, hitch, cgs in (("", at_exchange, (tractor, trailer)),
                               ("rest-", at_rest, (d["vehicles"][2]["rest_position"],
                                                   d["vehicles"][1]["rest_position"]))):
        (marker,) = by_gid(ax, f"{prefix}hitch-1")
        np.testing.assert_allclose(drawn_points(marker), [hitch], rtol=0, atol=1e-9)
        (line,) = by_gid(ax, f"{prefix}hitch-line-1")
        np.testing.assert_allclose(drawn_points(line), [cgs[0], hitch, cgs[1]], rtol=0, atol=1e-9)
    # where the joint holds them: the trailer's kingpin (21 ft ahead of its CG) on the marker, at rest within 1 mm
    trailer_yaw = math.radians(d["vehicles"][1]["rest_yaw"])
    kingpin = np.asarray(d["vehicles"][1]["rest_position"]) + 21.0 * U.FT * np.array([math.cos(trailer_yaw),
                                                                                       math.sin(trailer_yaw)])
    assert np.linalg.norm(kingpin - at_rest) < 1e-3
    np.testing.assert_allclose(trailer + np.array([0.0, 21.0 * U.FT]), at_exchange, rtol=0, atol=1e-9)
    assert sum(s.startswith("hitch") for s in legend_texts(ax)) == 1


@pytest.mark.slow
def test_a_case_without_hitches_draws_none(several):
    sol, ax = several
    artists = [*ax.lines, *ax.patches, *ax.texts]
    assert not [a for a in artists if "hitch" in (a.get_gid() or "")]
    assert not [s for s in legend_texts(ax) if "hitch" in s]


# An approach before the impact (docs/model.md, "The approach"): the car skids straight along +x with its wheels
# locked for SKID_DISTANCE into a parked car, striking it at SKID_SPEED from the case position SKID_AT. Worked back by
# hand, its CG was SKID_DISTANCE behind the case position at the skid's start, sqrt(v^2 + 2 mu g d) faster,
# (sqrt(v^2 + 2 mu g d) - v) / (mu g) before the impact.

SKID_AT, SKID_DISTANCE, SKID_SPEED, SKID_FRICTION = (3.0, -2.0), 12.0, 14.0, 0.7
SKID = {
    "name": "a straight skid into a parked car",
    "vehicles": [dict(car("sedan", 1500, 4.5, 1.8, 2.25, SKID_AT, 0, SKID_SPEED),
                      approach=[{"wheels": "locked", "distance": f"{SKID_DISTANCE} m"}]),
                 car("parked car", 1500, 4.5, 1.8, 2.25, (SKID_AT[0] + 4.5, SKID_AT[1]), 0, 0.0)],
    "contact": {"point": [f"{SKID_AT[0] + 2.25} m", f"{SKID_AT[1]} m", "0.5 m"], "normal": 180, "restitution": 0.1,
                "friction": 0.3},
    "road": {"friction": SKID_FRICTION, "time_limit": "2 s"},
}


@pytest.fixture(scope="module")
def skid():
    """``SKID`` solved once and its top view as ``ks-jax solve --plot`` draws it (``top_view_figure``), drawn so that
    the equal aspect has set the limits. Solved with every step kept (``Motion.path``), as the top view solves it
    again for the paths: that solve is then the same compiled program."""
    case = case_from_dict(SKID)
    case = dataclasses.replace(case, motion=dataclasses.replace(case.motion, path=True))
    sol = ks_jax.solve(case)
    assert sol.status == "ok" and sol.result.approach[1] is None
    fig = top_view_figure([sol])
    fig.canvas.draw()
    return sol, fig.axes[0]


@pytest.mark.slow
def test_the_approach_is_drawn_from_the_skids_start_to_the_impact(skid):
    """The car's approach path runs straight along +x from SKID_DISTANCE behind the case position to it, where its
    path to rest goes on; its phase's start is marked there with its time from the impact worked by hand, and its
    outline drawn at the skid's start; the parked car has none. One legend entry; the view takes the approach in."""
    sol, ax = skid
    x0, y0 = SKID_AT
    start = np.array([x0 - SKID_DISTANCE, y0])
    (line,) = by_gid(ax, "approach-path-0")
    xy = drawn_points(line)
    np.testing.assert_allclose(xy[0], start, rtol=0, atol=1e-5)
    np.testing.assert_allclose(xy[-1], SKID_AT, rtol=0, atol=1e-5)
    np.testing.assert_allclose(xy[:, 1], y0, rtol=0, atol=1e-5)  # straight, along +x
    assert np.all(np.diff(xy[:, 0]) > 0)
    assert line.get_linestyle() == "--" and to_rgba(line.get_color()) == to_rgba(COLORS[0])
    (rest,) = by_gid(ax, "rest-path-0")  # one trajectory: the path to rest starts where the approach ends
    np.testing.assert_allclose(drawn_points(rest)[0], xy[-1], rtol=0, atol=1e-5)
    (marker,) = by_gid(ax, "approach-phase-0-0")
    np.testing.assert_allclose(drawn_points(marker), [start], rtol=0, atol=1e-5)
    assert not by_gid(ax, "approach-phase-0-1")  # one phase
    mu_g = SKID_FRICTION * U.G0
    before = (math.sqrt(SKID_SPEED**2 + 2 * mu_g * SKID_DISTANCE) - SKID_SPEED) / mu_g
    (time,) = by_gid(ax, "approach-time-0-0")
    assert time.get_text() == f"{-before:.2f} s" == "-0.73 s"
    np.testing.assert_allclose(time.xy, start, rtol=0, atol=1e-5)
    (outline,) = by_gid(ax, "approach-outline-0")
    np.testing.assert_allclose(drawn_polygon(outline), hand_box(sol.case.inputs.vehicles[0], start, 0.0),
                               rtol=0, atol=1e-5)
    gids = [a.get_gid() or "" for a in [*ax.lines, *ax.patches, *ax.texts]]
    assert sorted(g for g in gids if g.startswith("approach-")) == sorted(
        ["approach-path-0", "approach-phase-0-0", "approach-time-0-0", "approach-outline-0"])  # none for the parked car
    texts = [s.replace("\n  ", " ") for s in legend_texts(ax)]
    assert texts.count("approach (CG path before the impact; marks at each phase's start)") == 1
    (x_min, _), (y_min, y_max) = ax.get_xlim(), ax.get_ylim()
    assert x_min <= start[0] - (4.5 - 2.25) and y_min <= y0 - 0.9 and y0 + 0.9 <= y_max  # the outline's rear inside
