"""The top view (ks_jax.plot): what is drawn is where the results and a hand calculation put it."""

import io
import math
from contextlib import redirect_stdout
from importlib import resources

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402
import pytest  # noqa: E402

pytest.importorskip("matplotlib")

from matplotlib.figure import Figure  # noqa: E402
from matplotlib.patches import Polygon, Wedge  # noqa: E402

import ks_jax  # noqa: E402
from ks_jax import plot  # noqa: E402
from ks_jax.plot.top_view import clip_polygon  # noqa: E402
from ks_jax import units as U  # noqa: E402
from ks_jax.cli import main  # noqa: E402

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


def test_cli_writes_the_picture(tmp_path):
    png = tmp_path / "tbone.png"
    with resources.as_file(case_path("auto_tbone.json")) as path, redirect_stdout(io.StringIO()):
        assert main(["solve", str(path), "--json", "--plot", str(png)]) == 0
    data = png.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 20_000


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
    assert f"impulse on Sedan: {total} N s ({np.linalg.norm(j) / U.LBF_S:,.0f} lbf s), horizontal part {horizontal} N s" in labels
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


def test_clip_polygon_against_the_engine():
    """plot's NumPy clipping and the engine's fixed-size clipping give the same overlap."""
    from ks_jax.model import overlap

    a = np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 2.0], [0.0, 2.0]])
    c, s = math.cos(0.4), math.sin(0.4)
    b = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]]) @ np.array([[c, s], [-s, c]]) + [3.5, 1.6]
    mine = clip_polygon(a, b)
    with jax.disable_jit():
        poly, count = overlap.overlap_polygon(np.asarray(a), np.asarray(b))
        area, centroid = overlap.polygon_area_centroid(poly, count)
    assert int(count) == len(mine)
    assert float(area) == pytest.approx(shoelace(mine), rel=1e-12)
    x, y = mine[:, 0], mine[:, 1]
    cr = x * np.roll(y, -1) - np.roll(x, -1) * y
    want = np.array([np.sum((x + np.roll(x, -1)) * cr), np.sum((y + np.roll(y, -1)) * cr)]) / (6 * np.sum(cr) / 2)
    np.testing.assert_allclose(np.asarray(centroid), want, rtol=1e-12)
