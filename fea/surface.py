"""Front-surface sag of a solved blank: nodal values, statistics and gridded maps.

Units: mm for positions, µm for sag. Sag is the displacement along +z (the outward
normal of the front face); ``sag_normal_um`` is the displacement along the local
undeformed outward normal of the front facets (identical for a flat face, kept so
that a curved front surface is handled correctly).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from optics.sagmap import Region, SagMap, resolve_region

__all__ = ["FrontSag", "front_sag"]


@dataclass(frozen=True)
class FrontSag:
    """Nodal sag of the front face, mirrored onto the whole face.

    Attributes
    ----------
    x_mm, y_mm : ndarray, shape (n,)
        Node positions on the front face.
    sag_um : ndarray, shape (n,)
        Displacement along +z (µm), relative to the uniform contraction.
    sag_normal_um : ndarray, shape (n,)
        Displacement along the local outward normal (µm).
    """

    x_mm: np.ndarray
    y_mm: np.ndarray
    sag_um: np.ndarray
    sag_normal_um: np.ndarray

    def _sel(self, region: str | Region | None) -> np.ndarray:
        m = resolve_region(region).contains(self.x_mm, self.y_mm)
        if not m.any():
            raise ValueError(f"no front-face nodes inside region {resolve_region(region).name!r}")
        return m

    def detrended(self, region: str | Region | None = "center") -> np.ndarray:
        """Sag (µm) minus the least-squares piston and tilt over ``region`` (all nodes)."""
        m = self._sel(region)
        A = np.column_stack([np.ones(m.sum()), self.x_mm[m], self.y_mm[m]])
        c, *_ = np.linalg.lstsq(A, self.sag_um[m], rcond=None)
        return self.sag_um - (c[0] + c[1] * self.x_mm + c[2] * self.y_mm)

    def pv_um(self, region: str | Region | None = "center", remove_tilt: bool = True) -> float:
        """Peak-to-valley (µm) over the nodes in ``region`` (piston/tilt removed there)."""
        m = self._sel(region)
        s = self.detrended(region)[m] if remove_tilt else self.sag_um[m]
        return float(s.max() - s.min())

    def rms_um(self, region: str | Region | None = "center", remove_tilt: bool = True) -> float:
        """RMS about the mean (µm) over the nodes in ``region``.

        Nodes are unevenly spaced (graded mesh), so this is a node-weighted RMS; use
        :meth:`sag_map` for an area-weighted one.
        """
        m = self._sel(region)
        s = self.detrended(region)[m] if remove_tilt else self.sag_um[m]
        return float(np.sqrt(np.mean((s - s.mean()) ** 2)))

    def value_at(self, x_mm: float, y_mm: float) -> float:
        """Sag (µm) of the node nearest to (x, y)."""
        i = np.argmin((self.x_mm - x_mm) ** 2 + (self.y_mm - y_mm) ** 2)
        return float(self.sag_um[i])

    def sag_map(self, spacing_mm: float = 0.5, normal: bool = False, label: str = "") -> SagMap:
        """Linear interpolation of the nodal sag onto a regular grid over the whole face."""
        s = self.sag_normal_um if normal else self.sag_um
        x0, x1 = self.x_mm.min(), self.x_mm.max()
        y0, y1 = self.y_mm.min(), self.y_mm.max()
        # snap the grid to multiples of the spacing about the centre so that x=0, y=0 are samples
        nx = int(np.floor((x1 - x0) / spacing_mm / 2)) * 2 + 1
        ny = int(np.floor((y1 - y0) / spacing_mm / 2)) * 2 + 1
        cx, cy = 0.5 * (x0 + x1), 0.5 * (y0 + y1)
        ext = (cx - (nx - 1) / 2 * spacing_mm, cx + (nx - 1) / 2 * spacing_mm,
               cy - (ny - 1) / 2 * spacing_mm, cy + (ny - 1) / 2 * spacing_mm)
        return SagMap.from_scattered(self.x_mm, self.y_mm, s, spacing_mm, ext, label)


def _mirror(x: np.ndarray, y: np.ndarray, vals: list[np.ndarray], planes) -> tuple:
    if "sym_x" in planes:
        x, y = np.concatenate([x, -x]), np.concatenate([y, y])
        vals = [np.concatenate([v, v]) for v in vals]
    if "sym_y" in planes:
        x, y = np.concatenate([x, x]), np.concatenate([y, -y])
        vals = [np.concatenate([v, v]) for v in vals]
    key = np.round(np.column_stack([x, y]), 9)
    _, idx = np.unique(key, axis=0, return_index=True)
    return x[idx], y[idx], [v[idx] for v in vals]


def front_sag(mesh, basis, displacement_mm: np.ndarray, symmetry_planes) -> FrontSag:
    """Extract the front-face sag from a nodal displacement field.

    Parameters
    ----------
    mesh : skfem mesh with a ``front`` boundary.
    basis : scalar P2 CellBasis on ``mesh``.
    displacement_mm : ndarray, shape (3, N)
    symmetry_planes : iterable of str
        ``sym_x``/``sym_y`` present means the face is mirrored about x=0 / y=0.
    """
    facets = mesh.boundaries["front"]
    dofs = basis.get_dofs(facets).all()
    xyz = basis.doflocs[:, dofs]
    u = displacement_mm[:, dofs]
    normals = _nodal_normals(mesh, facets, basis, dofs)
    sag = 1e3 * u[2]
    sag_n = 1e3 * np.einsum("in,in->n", u, normals)
    x, y, (sag, sag_n) = _mirror(xyz[0], xyz[1], [sag, sag_n], symmetry_planes)
    return FrontSag(x, y, sag, sag_n)


def _nodal_normals(mesh, facets, basis, dofs) -> np.ndarray:
    """Outward unit normals at the front-face nodes (average of adjacent facet normals)."""
    from skfem import ElementTetP2, FacetBasis

    fb = FacetBasis(mesh, ElementTetP2(), facets=facets, intorder=1)
    n_f = fb.normals.value.mean(axis=2)  # (3, nf)
    lookup = -np.ones(basis.N, dtype=int)
    lookup[dofs] = np.arange(dofs.size)
    acc = np.zeros((3, dofs.size))
    for a in range(fb.element_dofs.shape[0]):
        d = fb.element_dofs[a]
        ok = lookup[d] >= 0
        np.add.at(acc, (slice(None), lookup[d[ok]]), n_f[:, ok])
    return acc / np.linalg.norm(acc, axis=0, keepdims=True)
