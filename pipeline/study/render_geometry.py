"""The deformed blank as a surface to draw: the solved symmetric part mirrored to the whole body.

Units: mm for geometry and displacement.

The FEA solves the symmetric part of the blank (eighth/quarter model); the surface
mirrors its boundary through the symmetry planes to the whole body (the cut faces on
the planes are dropped, except where a cut-away exposes them). Only the boundary is
built: each quadratic boundary triangle (6 nodes, curved on the hole walls) becomes 4
flat ones through its mid-edge nodes. Pure NumPy: no rendering library is needed.

Functions
---------
blank_surface       symmetric-part mesh + displacement → whole-body triangle surface
auto_exaggeration   displacement scale that makes the front face's P/V visible
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["BlankSurface", "blank_surface", "auto_exaggeration"]

_PLANE_AXIS = {"sym_x": 0, "sym_y": 1, "sym_z": 2}
#: skfem's local edge order of a P2 tetrahedron (element_dofs rows 4..9)
_TET_EDGES = ((0, 1), (1, 2), (0, 2), (0, 3), (1, 3), (2, 3))


@dataclass(frozen=True)
class BlankSurface:
    """Triangulated boundary of the whole blank with its nodal displacement.

    Attributes
    ----------
    points_mm : ndarray (n, 3)
    triangles : ndarray (m, 3) of int, counter-clockwise seen from outside
    displacement_mm : ndarray (n, 3)
    cut : ndarray (m,) of bool
        Triangles on a symmetry plane exposed by a cut-away.
    """

    points_mm: np.ndarray
    triangles: np.ndarray
    displacement_mm: np.ndarray
    cut: np.ndarray

    def front_mask(self, tol_mm: float = 1e-6) -> np.ndarray:
        """Nodes on the (undeformed) front face, the plane of the largest z."""
        z = self.points_mm[:, 2]
        return z > z.max() - tol_mm


def _edge_midnodes(mesh):
    """(sorted corner pair key → mid-edge node) lookup of a MeshTet2."""
    ed = mesh.dofs.element_dofs
    n = int(mesh.doflocs.shape[1])
    a = np.concatenate([ed[i] for i, _ in _TET_EDGES])
    b = np.concatenate([ed[j] for _, j in _TET_EDGES])
    mid = np.concatenate([ed[4 + k] for k in range(6)])
    keys = np.minimum(a, b).astype(np.int64) * n + np.maximum(a, b)
    keys, first = np.unique(keys, return_index=True)
    return keys, mid[first], n


def _facet_triangles(mesh, coords, facets):
    """Boundary facets → 4 flat triangles each (corners + mid-edge nodes), outward."""
    keys, mids, n = _edge_midnodes(mesh)
    F = mesh.facets[:, facets].astype(np.int64)
    # outward orientation: away from the owning tetrahedron's centroid
    owner = mesh.f2t[0, facets]
    tc = coords[:, mesh.t[:, owner]].mean(axis=1)
    fc = coords[:, F].mean(axis=1)
    nrm = np.cross((coords[:, F[1]] - coords[:, F[0]]).T, (coords[:, F[2]] - coords[:, F[0]]).T)
    flip = np.einsum("ij,ij->i", nrm, (fc - tc).T) < 0
    F[1, flip], F[2, flip] = F[2, flip], F[1, flip].copy()

    def mid(p, q):
        k = np.minimum(p, q) * n + np.maximum(p, q)
        i = np.searchsorted(keys, k)
        if not np.array_equal(keys[np.minimum(i, len(keys) - 1)], k):
            raise ValueError("a boundary edge has no mid-edge node: not a quadratic (MeshTet2) mesh")
        return mids[i]

    a, b, c = F
    ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
    return np.concatenate([np.stack(t, axis=1) for t in
                           ((a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca))])


def blank_surface(mesh, coords_mm, displacement_mm, symmetry_planes=None, *,
                  cutaway: bool = False) -> BlankSurface:
    """Whole-body boundary surface of a solved symmetric part.

    Parameters
    ----------
    mesh : skfem.MeshTet2
        The solved part (``PreparedBlank.mesh``), with ``sym_x/sym_y/sym_z`` boundaries.
    coords_mm, displacement_mm : ndarray (3, N)
        ``FEAResult.coords_mm`` and ``FEAResult.displacement_mm`` (nodes = ``mesh.doflocs``).
    symmetry_planes : sequence of str, optional
        Planes to mirror through; default: the ``sym_*`` boundaries of the mesh.
    cutaway : bool
        Leave out the quadrant x < 0, y < 0 and show the cut faces it exposes (needs the
        x and y symmetry planes; ignored otherwise).
    """
    coords = np.asarray(coords_mm, float)
    disp = np.asarray(displacement_mm, float)
    if coords.shape != disp.shape or coords.shape[0] != 3 or coords.shape[1] != mesh.doflocs.shape[1]:
        raise ValueError(f"coords {coords.shape} and displacement {disp.shape} must both be "
                         f"(3, {mesh.doflocs.shape[1]}) (one column per mesh node)")
    planes = [s for s in (symmetry_planes if symmetry_planes is not None else _PLANE_AXIS)
              if s in mesh.boundaries and s in _PLANE_AXIS]
    sym = {s: np.asarray(mesh.boundaries[s]) for s in planes}
    outer = np.setdiff1d(mesh.boundary_facets(), np.concatenate(list(sym.values())) if sym else [])
    cutaway = cutaway and "sym_x" in sym and "sym_y" in sym
    parts = [(_facet_triangles(mesh, coords, outer), None)]
    if cutaway:
        parts += [(_facet_triangles(mesh, coords, sym[s]), s) for s in ("sym_x", "sym_y")]
    pts, tris, us, cuts = [], [], [], []
    offset = 0
    axes = [_PLANE_AXIS[s] for s in planes]
    for signs in np.ndindex(*(2,) * len(axes)):
        sgn = np.ones(3)
        for ax, s in zip(axes, signs):
            sgn[ax] = -1.0 if s else 1.0
        for tri, plane in parts:
            if cutaway:
                sx, sy = sgn[0], sgn[1]
                if sx < 0 and sy < 0:
                    continue  # the removed quadrant
                # exposed cut faces: x = 0 of the (+x, -y) copy, y = 0 of the (-x, +y) copy
                if plane == "sym_x" and not (sx > 0 and sy < 0):
                    continue
                if plane == "sym_y" and not (sx < 0 and sy > 0):
                    continue
            used, inv = np.unique(tri, return_inverse=True)
            t = inv.reshape(tri.shape) + offset
            if np.prod(sgn) < 0:  # a reflection turns the triangles inside out
                t = t[:, [0, 2, 1]]
            pts.append(coords[:, used].T * sgn)
            us.append(disp[:, used].T * sgn)
            tris.append(t)
            cuts.append(np.full(len(t), plane is not None))
            offset += len(used)
    P, U, T = np.concatenate(pts), np.concatenate(us), np.concatenate(tris)
    # merge the copies' shared nodes on the symmetry planes (smooth shading across seams):
    # positions quantised to 21 bits per axis (< 0.1 µm for the default blank) in one int64
    lo = P.min(axis=0)
    res = max(float(np.ptp(P, axis=0).max()), 1e-12) / (2 ** 21 - 2)
    q = np.rint((P - lo) / res).astype(np.int64)
    key = (q[:, 0] << 42) | (q[:, 1] << 21) | q[:, 2]
    _, first, inv = np.unique(key, return_index=True, return_inverse=True)
    inv = inv.ravel()
    return BlankSurface(P[first], inv[T], U[first], np.concatenate(cuts))


def _nice(x: float) -> float:
    """The nearest (in ratio) of 1, 2 or 5 × 10^k."""
    if not (np.isfinite(x) and x > 0):
        return 1.0
    e = 10.0 ** math.floor(math.log10(x))
    return min((m * e for m in (1.0, 2.0, 5.0, 10.0)), key=lambda v: abs(math.log(v / x)))


def auto_exaggeration(surfaces, fraction: float = 0.02) -> float:
    """Factor that makes the front face's out-of-plane P/V ``fraction`` of the blank's size.

    The largest P/V over ``surfaces`` decides (a comparison shares one factor); the factor
    is rounded to the nearest 1, 2 or 5 × 10^k.
    """
    pv, size = 0.0, 0.0
    for s in surfaces:
        uz = s.displacement_mm[s.front_mask(), 2]
        pv = max(pv, float(uz.max() - uz.min()))
        size = max(size, float(np.ptp(s.points_mm, axis=0).max()))
    return _nice(fraction * size / pv) if pv > 0 else 1.0
