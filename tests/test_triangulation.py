"""Linear interpolation of scattered samples: the closed-form rasterisation against scipy's
LinearNDInterpolator (the reference implementation of the same interpolant), on samples
shaped as they come (a curved FE lattice with samples on grid nodes, a random cloud, a
masked disc), and against exactly linear data."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.interpolate import LinearNDInterpolator
from scipy.spatial import QhullError

from optics.triangulation import linear_on_grid


def _lattice_samples():
    """A P2-like lattice: 1 mm nodes, every fourth row shifted by half a step, so many
    samples sit exactly on the 0.5 mm grid nodes (the case scipy's walk ties on)."""
    xs, ys = np.meshgrid(np.arange(-20.0, 20.01, 1.0), np.arange(-15.0, 15.01, 0.5))
    xs = xs + 0.25 * (np.round(ys / 0.5) % 4 == 1)
    return xs.ravel(), ys.ravel()


def _reference(x, y, v, gx, gy):
    X, Y = np.meshgrid(gx, gy)
    return LinearNDInterpolator(np.column_stack([x, y]), v)(X, Y)


@pytest.mark.parametrize("kind", ["lattice", "cloud", "disc"])
def test_equals_scipy_linear_interpolator(kind):
    rng = np.random.default_rng(3)
    if kind == "lattice":
        x, y = _lattice_samples()
    elif kind == "cloud":
        x, y = rng.uniform(-20, 20, 3000), rng.uniform(-15, 15, 3000)
    else:
        r, t = 18 * np.sqrt(rng.uniform(0, 1, 4000)), rng.uniform(0, 2 * np.pi, 4000)
        x, y = r * np.cos(t), r * np.sin(t)
    v = np.sin(x / 3.0) * np.cos(y / 4.0) + 0.1 * rng.standard_normal(x.size)
    gx, gy = np.arange(-22.0, 22.01, 0.5), np.arange(-17.0, 17.01, 0.5)
    got, ref = linear_on_grid(x, y, v, gx, gy), _reference(x, y, v, gx, gy)
    assert np.array_equal(np.isnan(got), np.isnan(ref))  # the same convex hull
    assert np.nanmax(np.abs(got - ref)) < 1e-12
    assert np.isfinite(got).sum() > 0.4 * got.size


def test_reproduces_a_plane_exactly_and_is_nan_outside_the_hull():
    x, y = _lattice_samples()
    v = 0.3 + 2.0 * x - 0.7 * y
    gx, gy = np.linspace(-25, 25, 51), np.linspace(-20, 20, 41)
    got = linear_on_grid(x, y, v, gx, gy)
    X, Y = np.meshgrid(gx, gy)
    inside = (np.abs(X) <= 20.0) & (np.abs(Y) <= 15.0)
    assert np.all(np.isfinite(got[inside])) and np.all(np.isnan(got[~inside]))
    np.testing.assert_allclose(got[inside], (0.3 + 2.0 * X - 0.7 * Y)[inside], atol=1e-12)


def test_one_node_grid_and_collinear_samples():
    x, y = _lattice_samples()
    got = linear_on_grid(x, y, x + y, np.array([0.5]), np.array([1.0]))
    assert got.shape == (1, 1) and got[0, 0] == pytest.approx(1.5)
    with pytest.raises(QhullError):
        linear_on_grid(np.arange(5.0), np.zeros(5), np.ones(5), np.arange(3.0), np.arange(3.0))


def test_memoised_weights_give_the_values_of_a_fresh_evaluation():
    """The weights are kept per (sample positions, grid): other values on the same samples,
    or moved samples, give exactly what an evaluation with an empty memo gives."""
    from optics import triangulation

    rng = np.random.default_rng(5)
    x, y = rng.uniform(-1, 1, 400), rng.uniform(-1, 1, 400)
    gx = gy = np.linspace(-1, 1, 41)
    cases = [(x, y, rng.normal(size=400)), (x, y, rng.normal(size=400)), (x + 0.01, y, rng.normal(size=400)),
             (x, y, np.hypot(x, y))]
    seen = [linear_on_grid(*c, gx, gy) for c in cases]
    for c, got in zip(cases, seen):
        triangulation._weights_of.cache_clear()
        np.testing.assert_array_equal(got, linear_on_grid(*c, gx, gy))
    assert not np.array_equal(seen[0], seen[1], equal_nan=True)


def test_weight_square_sums_equal_scipy_barycentric_weights():
    """Each node's sum of squared weights against scipy's own point location and affine
    transform (``Delaunay.find_simplex`` and ``transform``) on the same samples."""
    from scipy.spatial import Delaunay

    from optics.triangulation import weight_square_sums

    rng = np.random.default_rng(4)
    x, y = rng.uniform(-20, 20, 2000), rng.uniform(-15, 15, 2000)
    gx, gy = np.arange(-22.0, 22.01, 0.7), np.arange(-17.0, 17.01, 0.7)
    got = weight_square_sums(x, y, gx, gy)
    X, Y = np.meshgrid(gx, gy)
    q = np.column_stack([X.ravel(), Y.ravel()])
    tri = Delaunay(np.column_stack([x, y]))
    s = tri.find_simplex(q)
    inside = s >= 0
    T = tri.transform[s[inside]]
    b = np.einsum("nij,nj->ni", T[:, :2], q[inside] - T[:, 2])
    w = np.column_stack([b, 1.0 - b.sum(axis=1)])
    ref = np.full(X.size, np.nan)
    ref[inside] = np.sum(w**2, axis=1)
    ref = ref.reshape(X.shape)
    assert np.array_equal(np.isnan(got), np.isnan(ref))
    assert np.nanmax(np.abs(got - ref)) < 1e-12
    # bounds of sum w^2 for w >= 0 summing to 1: 1/3 (centroid) to 1 (on a sample)
    assert np.nanmin(got) >= 1 / 3 - 1e-12 and np.nanmax(got) <= 1 + 1e-12


def test_weight_square_sums_on_samples_and_edge_midpoints():
    """A node on a sample has weight 1 (sum 1); a node at the midpoint of an edge has two
    weights of 1/2 (sum 1/2), whichever of the edge's two triangles holds it."""
    from optics.triangulation import weight_square_sums

    x, y = np.array([0.0, 2.0, 0.0, 2.0]), np.array([0.0, 0.0, 2.0, 2.0])
    got = weight_square_sums(x, y, np.array([0.0, 1.0, 2.0]), np.array([0.0, 1.0, 2.0]))
    assert got[0, 0] == pytest.approx(1.0) and got[2, 2] == pytest.approx(1.0)
    assert got[0, 1] == pytest.approx(0.5) and got[1, 0] == pytest.approx(0.5)
    assert got[1, 1] == pytest.approx(0.5)  # the square's centre: midpoint of the diagonal
