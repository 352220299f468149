"""Linear interpolation of scattered samples (what ``griddata(method="linear")`` computes).

The piecewise-linear interpolant on the samples' Delaunay triangulation, NaN outside the
convex hull. scipy builds the triangulation; the points are located and weighted here, by
rasterising each triangle over the query nodes in its bounding box with barycentric
weights in closed form, instead of by ``LinearNDInterpolator`` / ``Delaunay.find_simplex``.
Reason (a gap in the library): both need ``Delaunay.transform``, which factorises every
triangle of the mesh one by one before the first point is located; measured with scipy 1.17
on the 213 537 front-face samples of the default FEA mesh (425 k triangles) gridded at
0.5 mm, scipy takes 14.7 s of CPU per sag map and this module 1.7 s, of which 1.6 s is
the triangulation (``benchmarks/results_gridding.md``). The values agree with ``LinearNDInterpolator``'s to
rounding, outside-hull NaNs included (``tests/test_triangulation.py``).

:func:`weight_square_sums` gives each node's sum of squared weights from the same (memoised)
triangulation: white noise of sigma on the samples becomes ``sigma * sqrt(sum w^2)`` on the node.
"""

from __future__ import annotations

import functools

import numpy as np
from scipy.spatial import Delaunay

__all__ = ["linear_on_grid", "weight_square_sums"]

#: Barycentric tolerance for a node on a triangle's edge, relative (scipy's ``find_simplex``
#: uses 100 machine epsilons).
_EDGE_TOL = 100 * np.finfo(float).eps


def linear_on_grid(x: np.ndarray, y: np.ndarray, values: np.ndarray, gx: np.ndarray,
                   gy: np.ndarray) -> np.ndarray:
    """Piecewise-linear interpolant of scattered samples on the grid ``gx`` x ``gy``.

    Parameters
    ----------
    x, y : ndarray, shape (n,)
        Sample positions (the grid's length unit).
    values : ndarray, shape (n,)
        Sample values.
    gx, gy : ndarray
        Uniformly spaced, increasing grid coordinates.

    Returns
    -------
    ndarray, shape (gy.size, gx.size)
        NaN outside the samples' convex hull.

    Raises
    ------
    scipy.spatial.QhullError
        If the samples cannot be triangulated (collinear or coincident).
    """
    pts = np.column_stack([np.ravel(x), np.ravel(y)]).astype(float)
    v = np.asarray(values, float).ravel()
    gx, gy = np.asarray(gx, float), np.asarray(gy, float)
    jj, ii, s, wa, wb, wc = _weights(pts, gx, gy)
    out = np.full((gy.size, gx.size), np.nan)
    out[jj, ii] = wa * v[s[:, 0]] + wb * v[s[:, 1]] + wc * v[s[:, 2]]
    return out


def weight_square_sums(x: np.ndarray, y: np.ndarray, gx: np.ndarray, gy: np.ndarray) -> np.ndarray:
    """Sum of the squared interpolation weights of each grid node (dimensionless).

    A node of :func:`linear_on_grid` is ``sum_i w_i v_i`` over its triangle's three samples
    (barycentric weights, ``sum_i w_i = 1``), so independent sample errors of sigma give it an
    error of ``sigma * sqrt(sum_i w_i^2)``: 1 on a sample, 1/2 on an edge's midpoint, 1/3 at a
    triangle's centroid. The triangulation and weights are those of :func:`linear_on_grid`
    for the same positions (memoised, not rebuilt).

    Parameters
    ----------
    x, y : ndarray, shape (n,)
        Sample positions (the grid's length unit).
    gx, gy : ndarray
        Uniformly spaced, increasing grid coordinates.

    Returns
    -------
    ndarray, shape (gy.size, gx.size)
        ``sum_i w_i^2`` in [1/3, 1] inside the samples' convex hull, NaN outside.

    Raises
    ------
    scipy.spatial.QhullError
        If the samples cannot be triangulated (collinear or coincident).
    """
    pts = np.column_stack([np.ravel(x), np.ravel(y)]).astype(float)
    gx, gy = np.asarray(gx, float), np.asarray(gy, float)
    jj, ii, _, wa, wb, wc = _weights(pts, gx, gy)
    out = np.full((gy.size, gx.size), np.nan)
    # a node on a shared edge is listed by both triangles with the same two non-zero weights
    out[jj, ii] = wa**2 + wb**2 + wc**2
    return out


def _weights(pts: np.ndarray, gx: np.ndarray, gy: np.ndarray) -> tuple:
    """``(jj, ii, s, wa, wb, wc)``: for each (grid node, triangle holding it) pair, the node's
    row and column, the triangle's three sample indexes and its barycentric weights (read-only
    arrays), memoised on the positions (:func:`_weights_of`)."""
    return _weights_of(pts.shape, pts.tobytes(), gx.tobytes(), gy.tobytes())


@functools.lru_cache(maxsize=4)
def _weights_of(pts_shape: tuple, pts_bytes: bytes, gx_bytes: bytes, gy_bytes: bytes) -> tuple:
    # Memoised on the positions' bytes: every FEA case on one mesh grids its sag on the same
    # front-face samples and grid, and the triangulation and the rasterisation depend on the
    # positions only (213 537 samples on a 0.5 mm grid: 1.3 s of CPU per map, under 0.01 s
    # once kept; the values are those of a fresh evaluation).
    pts = np.frombuffer(pts_bytes).reshape(pts_shape)
    gx, gy = np.frombuffer(gx_bytes), np.frombuffer(gy_bytes)
    simp = Delaunay(pts).simplices
    a, b, c = pts[simp[:, 0]], pts[simp[:, 1]], pts[simp[:, 2]]
    lo, hi = np.minimum(np.minimum(a, b), c), np.maximum(np.maximum(a, b), c)
    i0, i1 = _node_range(lo[:, 0], hi[:, 0], gx)
    j0, j1 = _node_range(lo[:, 1], hi[:, 1], gy)
    ni, nj = np.maximum(i1 - i0 + 1, 0), np.maximum(j1 - j0 + 1, 0)
    count = ni * nj
    t = np.repeat(np.arange(simp.shape[0]), count)              # one row per (triangle, node) candidate
    k = np.arange(t.size) - np.repeat(np.cumsum(count) - count, count)
    ii = i0[t] + k % ni[t]
    jj = j0[t] + k // ni[t]
    a, ab, ac = a[t], b[t] - a[t], c[t] - a[t]
    px, py = gx[ii] - a[:, 0], gy[jj] - a[:, 1]
    det = ab[:, 0] * ac[:, 1] - ac[:, 0] * ab[:, 1]
    with np.errstate(divide="ignore", invalid="ignore"):        # a flat triangle (det 0) is never inside
        wb = (px * ac[:, 1] - ac[:, 0] * py) / det
        wc = (ab[:, 0] * py - px * ab[:, 1]) / det
    wa = 1.0 - wb - wc
    inside = (wa >= -_EDGE_TOL) & (wb >= -_EDGE_TOL) & (wc >= -_EDGE_TOL)
    hit = (jj[inside], ii[inside], simp[t[inside]], wa[inside], wb[inside], wc[inside])
    for arr in hit:
        arr.flags.writeable = False
    return hit


def _node_range(lo: np.ndarray, hi: np.ndarray, g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """First and last index of the grid ``g`` within ``[lo, hi]`` (widened by a rounding margin,
    so a node on a triangle's edge is a candidate of both its triangles)."""
    if g.size == 1:
        hit = (lo <= g[0]) & (g[0] <= hi)
        return np.where(hit, 0, 1), np.zeros(lo.size, dtype=int)
    h = (g[-1] - g[0]) / (g.size - 1)
    pad = 1e-9 * abs(h)
    first = np.ceil((lo - g[0] - pad) / h).astype(int)
    last = np.floor((hi - g[0] + pad) / h).astype(int)
    return np.clip(first, 0, g.size), np.clip(last, -1, g.size - 1)
