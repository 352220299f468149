"""Nodal values on an FE face interpolated onto a regular grid with the elements' own shape functions.

The point location uses the triangulation of the face's corner nodes (quads split in
two) in the projected (x, y) plane; inside the found cell the local coordinates come
from the corner nodes (affine for triangles, bilinear inverted by Newton for quads),
i.e. straight-edged cells, which every flat face meshed by a solver is except along
curved boundaries (holes). The value is then the cell's shape-function sum over all
its nodes: quadratic for ``triangle6``/``quad8``/``quad9``, linear/bilinear for
``triangle``/``quad``. Grid points outside the face are NaN.
"""

from __future__ import annotations

import numpy as np

from .fe_face import FACE_TYPES, FaceMesh

__all__ = ["evaluate_face", "interpolate_face", "shape_functions"]

_QUAD_CORNERS = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
_QUAD_MIDS = np.array([[0.0, -1.0], [1.0, 0.0], [0.0, 1.0], [-1.0, 0.0]])


def shape_functions(cell_type: str, local: np.ndarray) -> np.ndarray:
    """Shape functions (p, k) of a face cell at local coordinates (p, 2).

    Triangles take area coordinates ``(l1, l2)`` (``l0 = 1 - l1 - l2``); quads take
    ``(xi, eta)`` in [-1, 1]². Node order as meshio/VTK.
    """
    a, b = local[:, 0], local[:, 1]
    if cell_type in ("triangle", "triangle6"):
        l = np.stack([1 - a - b, a, b], axis=1)
        if cell_type == "triangle":
            return l
        mids = np.stack([4 * l[:, 0] * l[:, 1], 4 * l[:, 1] * l[:, 2], 4 * l[:, 2] * l[:, 0]], axis=1)
        return np.concatenate([l * (2 * l - 1), mids], axis=1)
    xs, ys = _QUAD_CORNERS[:, 0], _QUAD_CORNERS[:, 1]
    if cell_type == "quad":
        return 0.25 * (1 + a[:, None] * xs) * (1 + b[:, None] * ys)
    if cell_type == "quad8":
        corner = 0.25 * (1 + a[:, None] * xs) * (1 + b[:, None] * ys) * (a[:, None] * xs + b[:, None] * ys - 1)
        mx, my = _QUAD_MIDS[:, 0], _QUAD_MIDS[:, 1]
        mid = np.where(mx == 0, 0.5 * (1 - a[:, None] ** 2) * (1 + b[:, None] * my),
                       0.5 * (1 + a[:, None] * mx) * (1 - b[:, None] ** 2))
        return np.concatenate([corner, mid], axis=1)
    if cell_type == "quad9":
        def lag(t, node):  # 1-D quadratic Lagrange on nodes -1, 0, 1
            return np.where(node == -1, 0.5 * t * (t - 1), np.where(node == 1, 0.5 * t * (t + 1), 1 - t**2))
        nodes = np.concatenate([_QUAD_CORNERS, _QUAD_MIDS, [[0.0, 0.0]]])
        return lag(a[:, None], nodes[:, 0]) * lag(b[:, None], nodes[:, 1])
    raise ValueError(f"cell_type={cell_type!r} is unknown; valid face types are {sorted(FACE_TYPES)}")


def _local_coords(cell_type: str, corners: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Local coordinates (p, 2) of points ``p`` (p, 2) in cells with ``corners`` (p, nc, 2)."""
    if FACE_TYPES[cell_type][0] == 3:
        T = np.stack([corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]], axis=2)  # (p, 2, 2)
        return np.linalg.solve(T, (p - corners[:, 0])[..., None])[..., 0]
    xi = np.zeros_like(p)
    for _ in range(12):  # Newton on the bilinear map; converges in a few steps for convex quads
        N = shape_functions("quad", xi)
        a, b = xi[:, 0], xi[:, 1]
        dNa = 0.25 * _QUAD_CORNERS[:, 0] * (1 + b[:, None] * _QUAD_CORNERS[:, 1])
        dNb = 0.25 * _QUAD_CORNERS[:, 1] * (1 + a[:, None] * _QUAD_CORNERS[:, 0])
        r = np.einsum("pk,pkd->pd", N, corners) - p
        J = np.stack([np.einsum("pk,pkd->pd", dNa, corners), np.einsum("pk,pkd->pd", dNb, corners)], axis=2)
        step = np.linalg.solve(J, r[..., None])[..., 0]
        xi = xi - step
        if np.abs(step).max(initial=0.0) < 1e-12:
            break
    return xi


def interpolate_face(xy: np.ndarray, values: np.ndarray, face: FaceMesh, x_mm: np.ndarray,
                     y_mm: np.ndarray) -> np.ndarray:
    """Nodal ``values`` on ``face`` evaluated on the grid ``x_mm`` × ``y_mm``.

    Parameters
    ----------
    xy : ndarray, shape (n, 2)
        Projected positions of all mesh points (mm); only face nodes are used.
    values : ndarray, shape (n,)
        Nodal values (any unit) at all mesh points.
    face : FaceMesh
    x_mm, y_mm : ndarray, shape (nx,), (ny,)

    Returns
    -------
    ndarray, shape (ny, nx)
        NaN outside the face.
    """
    X, Y = np.meshgrid(np.asarray(x_mm, float), np.asarray(y_mm, float))
    return evaluate_face(xy, values, face, X.ravel(), Y.ravel()).reshape(X.shape)


def evaluate_face(xy: np.ndarray, values: np.ndarray, face: FaceMesh, px_mm: np.ndarray,
                  py_mm: np.ndarray) -> np.ndarray:
    """Nodal ``values`` on ``face`` at the points (px_mm, py_mm), shape (p,); NaN outside the face.

    Same parameters as :func:`interpolate_face`, with points instead of grid lines.
    """
    from matplotlib.tri import Triangulation

    tris, owner = [], []
    for b, (t, c) in enumerate(face.blocks):
        if FACE_TYPES[t][0] == 3:
            tris.append(c[:, :3])
            owner.append(np.stack([np.full(len(c), b), np.arange(len(c))], axis=1))
        else:
            tris += [c[:, [0, 1, 2]], c[:, [0, 2, 3]]]
            own = np.stack([np.full(len(c), b), np.arange(len(c))], axis=1)
            owner += [own, own]
    tris, owner = np.concatenate(tris), np.concatenate(owner)
    used, local_tris = np.unique(tris, return_inverse=True)
    local_tris = local_tris.reshape(tris.shape)
    try:
        finder = Triangulation(xy[used, 0], xy[used, 1], local_tris).get_trifinder()
    except (RuntimeError, ValueError) as exc:
        raise ValueError(f"the face's cells overlap or are degenerate when projected on the optical x-y plane "
                         f"({exc}); is the optical z axis the face's normal?") from None
    px, py = np.asarray(px_mm, float).ravel(), np.asarray(py_mm, float).ravel()
    found = np.asarray(finder(px, py))
    miss = np.flatnonzero(found < 0)
    if miss.size:
        # a grid point on the face's edge can lie outside it by round-off (a model in inches:
        # an edge at 0.787401574803 in is 19.999999999996 mm): moved inward by 1e-9 of the
        # face's size, it is found; a point truly outside stays outside
        c, size = xy[used].mean(axis=0), float(np.ptp(xy[used], axis=0).max())
        d = np.column_stack([c[0] - px[miss], c[1] - py[miss]])
        d *= 1e-9 * size / np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-300)[:, None]
        again = np.asarray(finder(px[miss] + d[:, 0], py[miss] + d[:, 1]))
        px, py = px.copy(), py.copy()
        px[miss[again >= 0]] += d[again >= 0, 0]
        py[miss[again >= 0]] += d[again >= 0, 1]
        found[miss] = again
    out = np.full(px.size, np.nan)
    inside = found >= 0
    blk, cell = owner[found[inside], 0], owner[found[inside], 1]
    pts = np.column_stack([px[inside], py[inside]])
    res = np.full(pts.shape[0], np.nan)
    for b, (t, c) in enumerate(face.blocks):
        m = blk == b
        if not m.any():
            continue
        conn = c[cell[m]]
        loc = _local_coords(t, xy[conn[:, :FACE_TYPES[t][0]]], pts[m])
        res[m] = np.einsum("pk,pk->p", shape_functions(t, loc), values[conn])
    out[inside] = res
    return out
