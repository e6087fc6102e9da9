"""The posterior's corner plot (``ks_jax.plot.corner``) against what it is drawn from: Gaussian draws of a known
mean and covariance, whose Laplace overlay is then exact."""

import math
import re

import numpy as np
import pytest

pytest.importorskip("matplotlib")

from matplotlib.figure import Figure

from ks_jax.plot import corner, save_corner

MEAN = np.array([20.0, 0.3, -2.0])
COV = np.array([[0.25, 0.004, 0.05], [0.004, 0.0004, 0.0], [0.05, 0.0, 0.09]])
LABELS = ["vehicles[1].speed [mph]", "contact.restitution", "contact.point[0] [ft]"]


def test_the_diagonal_is_each_unknowns_density_and_the_ellipses_are_the_laplace_sigma_levels(tmp_path):
    """Diagonal: each histogram is a density (its bars' area 1) of the draws, and the Laplace curve peaks at
    1 / (s sqrt(2 pi)) over the estimate. Below: every pair's scatter holds the (thinned) draws, and the two
    Laplace curves are the 1- and 2-sigma ellipses, (x - m)^T C^-1 (x - m) = 1 and 4 for the pair's block of the
    covariance. Above the diagonal nothing is drawn. The labels name each unknown with its unit."""
    draws = np.random.default_rng(0).multivariate_normal(MEAN, COV, 6000)
    axes = corner(Figure(), draws, LABELS, MEAN, COV)
    n = len(MEAN)
    for i in range(n):
        ax = axes[i, i]
        area = sum(p.get_width() * p.get_height() for p in ax.patches)
        assert area == pytest.approx(1.0, rel=1e-9)
        (curve,) = ax.lines
        x, y = curve.get_data()
        s = math.sqrt(COV[i, i])
        assert y.max() == pytest.approx(1 / (s * math.sqrt(2 * math.pi)), rel=1e-3)
        assert x[np.argmax(y)] == pytest.approx(MEAN[i], abs=(x[1] - x[0]))
        for j in range(i + 1, n):
            assert not axes[i, j].get_visible()
        for j in range(i):
            scatter, *rings = axes[i, j].lines
            assert len(scatter.get_xdata()) == 3000  # every second of 6000 draws (at most 4000 shown)
            block = np.linalg.inv(COV[np.ix_([j, i], [j, i])])
            for ring, level in zip(rings, (1.0, 2.0)):
                d = np.stack(ring.get_data(), 1) - MEAN[[j, i]]
                np.testing.assert_allclose(np.einsum("ka,ab,kb->k", d, block, d), level ** 2, rtol=1e-9)
    assert axes[n - 1, 0].get_xlabel() == LABELS[0] and axes[1, 0].get_ylabel() == LABELS[1]
    path = save_corner(tmp_path / "corner.svg", draws, LABELS, MEAN, COV, title="test")
    assert "contact.restitution" in path.read_text()


def test_an_undetermined_unknown_gets_no_laplace_overlay():
    """Where the Laplace covariance is infinite (an unknown the evidence does not determine) only the draws are
    drawn: no curve on its diagonal, no ellipse in its pairs."""
    cov = COV.copy()
    cov[1, :] = cov[:, 1] = np.inf
    draws = np.random.default_rng(1).multivariate_normal(MEAN, COV, 500)
    axes = corner(Figure(), draws, LABELS, MEAN, cov)
    assert len(axes[1, 1].lines) == 0 and len(axes[0, 0].lines) == 1
    assert len(axes[1, 0].lines) == 1 and len(axes[2, 1].lines) == 1 and len(axes[2, 0].lines) == 3


@pytest.mark.parametrize("samples, labels, estimate, covariance, words", [
    (MEAN, LABELS, None, None, "samples has shape (3,): give the draws as (draws, unknowns)"),
    (np.zeros((5, 0)), [], None, None, "samples has shape (5, 0)"),
    (np.zeros((5, 3)), LABELS[:2], None, None, "2 labels for 3 unknowns"),
    (np.zeros((5, 3)), LABELS, MEAN[:2], None, "estimate has shape (2,): give (3,)"),
    (np.zeros((5, 3)), LABELS, MEAN, COV[:2], "covariance has shape (2, 3): give (3, 3)"),
])
def test_draws_labels_estimate_and_covariance_of_other_shapes_are_refused_by_name(tmp_path, samples, labels,
                                                                                  estimate, covariance, words):
    """Each failed inside matplotlib or NumPy with an IndexError; the picture and the file are refused alike."""
    with pytest.raises(ValueError, match=re.escape(words)):
        corner(Figure(), samples, labels, estimate, covariance)
    with pytest.raises(ValueError, match=re.escape(words)):
        save_corner(tmp_path / "c.png", samples, labels, estimate, covariance)
    assert not (tmp_path / "c.png").exists()
