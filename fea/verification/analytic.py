"""Closed-form references for verification: bilayer plate curvature.

Units: mm for thicknesses, 1/mm for curvature; moduli in any consistent unit.
"""

from __future__ import annotations

import numpy as np

__all__ = ["bilayer_curvature", "stoney_curvature"]


def bilayer_curvature(h_s_mm: float, h_f_mm: float, E_s: float, E_f: float, mismatch_strain: float) -> float:
    """Curvature (1/mm) of a free bilayer plate whose film has eigenstrain ``mismatch_strain``.

    Exact Kirchhoff laminate solution (Timoshenko 1925, in its plate form): with
    biaxial moduli ``E_s``, ``E_f`` (E/(1−ν), equal ν assumed so the plate bends
    spherically), in-plane strain ε(z) = ε₀ + κ z, force and moment balance over the
    two layers give a 2x2 linear system. Positive curvature means the film side
    becomes convex (film in compression for positive mismatch strain).
    """
    zs = np.array([0.0, h_s_mm, h_s_mm + h_f_mm])
    E = np.array([E_s, E_f])
    e = np.array([0.0, mismatch_strain])
    A = np.array([[np.sum(E * np.diff(zs)), np.sum(E * np.diff(zs**2) / 2)],
                  [np.sum(E * np.diff(zs**2) / 2), np.sum(E * np.diff(zs**3) / 3)]])
    b = np.array([np.sum(E * e * np.diff(zs)), np.sum(E * e * np.diff(zs**2) / 2)])
    _, kappa = np.linalg.solve(A, b)
    return float(kappa)


def stoney_curvature(h_s_mm: float, h_f_mm: float, E_s: float, E_f: float, mismatch_strain: float) -> float:
    """Stoney's thin-film limit κ = 6 E_f h_f ε / (E_s h_s²) (biaxial moduli)."""
    return 6.0 * E_f * h_f_mm * mismatch_strain / (E_s * h_s_mm**2)
