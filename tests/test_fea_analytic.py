"""Thin-film formulation against closed forms (no gmsh needed: box meshes).

* a free plate with a film on one face bends to the exact bilayer (Timoshenko /
  laminate) curvature, which tends to Stoney's formula for thin films;
* the exact bilayer displacement field satisfies the discrete equations in the
  interior (consistency: the recovered-θ offset film leaves no spurious moments);
* no film, or zero mismatch, gives zero deformation.
"""
import numpy as np
import pytest
from skfem import MeshTet

from fea.verification.analytic import bilayer_curvature, stoney_curvature
from fea.assembly import bulk_stiffness, film_operators, scalar_basis
from fea.coating import Coating
from fea.materials import Material
from fea.model import PreparedBlank, ThermalLoad

A_MM, H_MM = 20.0, 2.0
SUB = Material("sub", 70e9, 0.3, 2e-5)
FILM = Material("film", 60e9, 0.3, 1e-5, strain_scale=0.5)


def plate(nxy=10, nz=3, z0=-H_MM / 2):
    m = MeshTet.init_tensor(np.linspace(0, A_MM, nxy + 1), np.linspace(0, A_MM, nxy + 1),
                            np.linspace(z0, z0 + H_MM, nz + 1))
    top = z0 + H_MM
    return m.with_boundaries({"front": lambda x: np.isclose(x[2], top),
                              "sym_x": lambda x: np.isclose(x[0], 0),
                              "sym_y": lambda x: np.isclose(x[1], 0)})


def central_curvature(sag, radius_mm):
    sel = sag.x_mm**2 + sag.y_mm**2 < radius_mm**2
    A = np.column_stack([np.ones(sel.sum()), sag.x_mm[sel] ** 2 + sag.y_mm[sel] ** 2])
    c, *_ = np.linalg.lstsq(A, sag.sag_um[sel] * 1e-3, rcond=None)
    return -2 * c[1]


@pytest.fixture(scope="module")
def prepared():
    return PreparedBlank(plate(10, 4), SUB)


@pytest.mark.parametrize("t_um", [10, 50, 100, 200])
def test_plate_matches_bilayer_curvature(prepared, t_um):
    r = prepared.solve(Coating(t_um, 1, 1, "faces"), FILM, thickness_override_um={"front": t_um})
    eps = r.info["mismatch_strain"]
    k_ref = bilayer_curvature(H_MM, t_um * 1e-3, SUB.biaxial_modulus_Pa, FILM.biaxial_modulus_Pa, eps)
    assert central_curvature(r.sag, A_MM / 3) == pytest.approx(k_ref, rel=2e-3)
    assert k_ref > 0  # film in compression bends its side convex


def test_thin_film_tends_to_stoney(prepared):
    t_um = 2.0
    r = prepared.solve(Coating(t_um, 1, 1, "faces"), FILM, thickness_override_um={"front": t_um})
    eps = r.info["mismatch_strain"]
    k_st = stoney_curvature(H_MM, t_um * 1e-3, SUB.biaxial_modulus_Pa, FILM.biaxial_modulus_Pa, eps)
    assert central_curvature(r.sag, A_MM / 3) == pytest.approx(k_st, rel=5e-3)


def test_surface_membrane_misses_the_offset(prepared):
    """A membrane on the surface (no lever arm, no film bending) errs by about t/h."""
    t_um = 200
    r = prepared.solve(Coating(t_um, 1, 1, "faces"), FILM, thickness_override_um={"front": t_um}, offset=False)
    eps = r.info["mismatch_strain"]
    k_ref = bilayer_curvature(H_MM, 0.2, SUB.biaxial_modulus_Pa, FILM.biaxial_modulus_Pa, eps)
    err = central_curvature(r.sag, A_MM / 3) / k_ref - 1
    assert -0.08 < err < -0.03


def test_exact_bilayer_field_is_a_discrete_solution():
    """Consistency: the laminate field leaves no residual at interior nodes."""
    m = plate(8, 6, z0=0.0).with_boundaries({"front": lambda x: np.isclose(x[2], H_MM)})
    b = scalar_basis(m)
    K = bulk_stiffness(b, 70e3, 0.3)
    ops = film_operators(m, m.boundaries["front"], 60e3, 0.3, b.doflocs)
    t, eps = 0.2, 1e-3
    Kf, ff = ops.system(t, eps)
    E1, E2 = 70e3 / 0.7, 60e3 / 0.7
    zs = np.array([0, H_MM, H_MM + t])
    E, e = np.array([E1, E2]), np.array([0, eps])
    M = np.array([[np.sum(E * np.diff(zs)), np.sum(E * np.diff(zs**2) / 2)],
                  [np.sum(E * np.diff(zs**2) / 2), np.sum(E * np.diff(zs**3) / 3)]])
    e0, k = np.linalg.solve(M, [np.sum(E * e * np.diff(zs)), np.sum(E * e * np.diff(zs**2) / 2)])
    x, y, z = b.doflocs
    c = 2 * 0.3 / 0.7
    u = np.stack([(e0 + k * z) * x, (e0 + k * z) * y, -k * (x**2 + y**2) / 2 - c * (e0 * z + k * z**2 / 2)])
    r = ((K + Kf) @ u.T.ravel() - ff).reshape(-1, 3).T
    inner = (x > 3) & (x < A_MM - 3) & (y > 3) & (y < A_MM - 3)
    assert np.abs(r[:, inner]).max() < 1e-9 * np.abs(ff).max()


def test_no_film_gives_zero_deformation(prepared):
    r = prepared.solve(Coating(200, 1, 1, "none"), FILM)
    assert np.abs(r.displacement_mm).max() == 0.0
    assert r.sag.pv_um("full") == 0.0


def test_equal_expansion_gives_zero_deformation(prepared):
    same = Material("same", 60e9, 0.3, SUB.cte_293K_per_K, strain_scale=SUB.strain_scale)
    r = prepared.solve(Coating(200, 1, 1, "faces"), same, thickness_override_um={"front": 200})
    assert np.abs(r.displacement_mm).max() == 0.0


def test_temperature_outside_data_range_is_refused(prepared):
    with pytest.raises(ValueError, match=r"cold_K=2\.0 K is outside"):
        prepared.solve(Coating(200, 1, 1, "faces"), FILM, ThermalLoad(293, 2.0))


def test_production_code_never_imports_verification_code():
    """fea.verification is a reference for tests and benchmarks, not part of the model."""
    import ast
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    offenders = []
    for package in ("fea", "optics", "pipeline"):
        for path in (root / package).rglob("*.py"):
            if "verification" in path.relative_to(root).parts:
                continue
            for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
                names = ([a.name for a in node.names] if isinstance(node, ast.Import)
                         else [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
                if any(n.startswith("fea.verification") or n == "verification" for n in names):
                    offenders.append(str(path.relative_to(root)))
    assert offenders == []
