"""Thin-layer film vs an explicitly meshed NiP layer on a slice through one hole.

Units: µm for film thickness and sag, mm for geometry.

The slice (``fea.verification.cell.cell_mesh``) is a quarter of one lightweighting cell in the x–z
plane (x ∈ [0, pitch/2], z ∈ [0, T/2], minus the quarter hole), extruded one slice in
y. Both models use the same boundary conditions: symmetry (u_x = 0) on x = 0 and
x = pitch/2 (a periodic row of holes), u_z = 0 on the mid-plane, u_y = 0 on both
slice faces (plane strain). The explicit model meshes the film as solid elements with
an isotropic eigenstrain ε_m; the thin model puts the bonded-film operators of
:mod:`fea.assembly` on the aluminium surfaces. The compared quantity is the quilt
amplitude of the aluminium front surface, w(x=0) − w(x=pitch/2), i.e. over the hole
minus over the rib.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..assembly import bulk_stiffness, scalar_basis
from .cell import cell_mesh
from ..coating import Coating
from ..linsolve import solve_spd
from ..materials import AL6061_T6, NIP_HIGH_P, Material
from ..model import PreparedBlank, ThermalLoad

__all__ = ["LayerComparison", "compare_thin_vs_explicit"]

_CELL_CONSTRAINTS = {"sym_x0": 0, "sym_xp": 0, "sym_z": 2, "y0": 1, "y1": 1}


@dataclass(frozen=True)
class LayerComparison:
    """Quilt amplitude (µm) of the thin-layer and explicit models and their relative difference."""

    film_hole_um: float
    film_front_um: float
    thin_um: float
    explicit_um: float
    ndof_thin: int
    ndof_explicit: int

    @property
    def relative_error(self) -> float:
        return self.thin_um / self.explicit_um - 1.0


def _quilt_amplitude(coords, disp, front_z_mm, pitch_mm) -> float:
    x, y, z = coords
    on = np.isclose(z, front_z_mm, atol=1e-9)
    w = disp[2, on]
    xs = x[on]
    return float(1e3 * (w[np.isclose(xs, 0.0)].mean() - w[np.isclose(xs, pitch_mm / 2)].mean()))


def _explicit(mesh, substrate: Material, film: Material, eps_m: float) -> tuple[np.ndarray, np.ndarray, int]:
    from skfem import CellBasis, ElementTetP2

    b = scalar_basis(mesh)
    K = None
    for name, mat in (("substrate", substrate), ("film", film)):
        bs = CellBasis(mesh, ElementTetP2(), intorder=2, elements=mesh.subdomains[name])
        Ks = bulk_stiffness(bs, mat.youngs_modulus_Pa * 1e-6, mat.poisson_ratio)
        K = Ks if K is None else K + Ks
    # isotropic eigenstrain ε_m in the film: f = ∫ (3λ+2μ) ε_m div v
    bf = CellBasis(mesh, ElementTetP2(), intorder=2, elements=mesh.subdomains["film"])
    E, nu = film.youngs_modulus_Pa * 1e-6, film.poisson_ratio
    bulk3 = E / (1 - 2 * nu)  # 3λ + 2μ
    f = np.zeros(3 * b.N)
    for a in range(bf.Nbfun):
        g = bf.basis[a][0].grad  # (3, nel, q)
        contrib = bulk3 * eps_m * np.einsum("ieq,eq->ie", g, bf.dx)
        np.add.at(f, 3 * bf.element_dofs[a][None, :] + np.arange(3)[:, None], contrib)
    fixed = np.unique(np.concatenate([3 * b.get_dofs(mesh.boundaries[s]).all() + c
                                      for s, c in _CELL_CONSTRAINTS.items()]))
    free = np.setdiff1d(np.arange(3 * b.N), fixed)
    u = np.zeros(3 * b.N)
    u[free] = solve_spd(K[free][:, free], f[free])
    return b.doflocs, u.reshape(-1, 3).T, 3 * b.N


def compare_thin_vs_explicit(film_hole_um: float = 150.0, film_front_um: float = 0.0,
                             pitch_mm: float = 21.0, thickness_mm: float = 20.0,
                             hole_diameter_mm: float = 15.0, substrate: Material = AL6061_T6,
                             film: Material = NIP_HIGH_P, load: ThermalLoad = ThermalLoad(),
                             size_mm: float = 0.1, size_bulk_mm: float = 0.5) -> LayerComparison:
    """Solve the one-hole slice with both film models and compare the quilt amplitude.

    Parameters
    ----------
    film_hole_um, film_front_um : float
        NiP thickness in the hole and on the front face (µm); 0 for none.
    size_mm, size_bulk_mm : float
        Element sizes of the slice meshes near the film and in the bulk.
    """
    eps_m = film.strain_between(load.warm_K, load.cold_K) - substrate.strain_between(load.warm_K, load.cold_K)
    geo = dict(pitch_mm=pitch_mm, thickness_mm=thickness_mm, hole_diameter_mm=hole_diameter_mm,
               size_mm=size_mm, size_bulk_mm=size_bulk_mm)
    m_thin = cell_mesh(**geo)
    pb = PreparedBlank(m_thin.with_boundaries({**m_thin.boundaries}), substrate, constraints=_CELL_CONSTRAINTS)
    thick = {k: v for k, v in (("hole", film_hole_um), ("front", film_front_um)) if v > 0}
    r = pb.solve(Coating(t0_um=max(thick.values()), coverage="all"), film, load, thickness_override_um=thick)
    thin = _quilt_amplitude(pb.coords_mm, r.displacement_mm, thickness_mm / 2, pitch_mm)
    m_exp = cell_mesh(film_hole_um=film_hole_um, film_front_um=film_front_um, **geo)
    coords, disp, ndof = _explicit(m_exp, substrate, film, eps_m)
    explicit = _quilt_amplitude(coords, disp, thickness_mm / 2, pitch_mm)
    return LayerComparison(film_hole_um, film_front_um, thin, explicit, pb.ndof, ndof)
