"""Rigid-body motion and low-order figure of the blank's front face (our own FEA).

Rigid-body motion: the front face's 6-DOF motion (:func:`optics.rigid_body.fit_rigid_body`,
area-weighted on the corner nodes of the front facets, mirrored onto the whole face)
*relative to the best-fit rigid motion of the whole blank* (volume-weighted on the corner
nodes of the tetrahedra, mirrored onto the whole blank), both about the face centre
(0, 0, z_front). Taking it relative to the blank makes it independent of how the solver
pins the free body, so it is a property of the deformation: how the optical face moves and
tilts against the blank as a whole. Displacements are those of ``FEAResult.displacement_mm``
(relative to the uniform contraction of the substrate). With the symmetry planes of the
eighth/quarter models, dx, dy, rx, ry, rz vanish by construction (to round-off): a free,
symmetric blank only changes the height of its face; a mount would add the others.

Low-order figure: P/V and RMS over a region with piston, tilt and power (``x² + y²``)
removed, area-weighted on the lattice samples of :class:`fea.surface.FrontSag`.
"""

from __future__ import annotations

import numpy as np

from optics.rigid_body import RigidBodyMotion, fit_rigid_body, pv_rms_um, remove_low_order
from optics.sagmap import resolve_region

__all__ = ["front_rigid_body", "pttp_stats", "front_figure_outputs"]

_MIRROR = {"sym_x": 0, "sym_y": 1, "sym_z": 2}


def _mirror(points, disp, weights, planes):
    """Reflect points (n, 3) and displacements (n, 3) about each symmetry plane present."""
    for name, ax in _MIRROR.items():
        if name in planes:
            flip = np.ones(3)
            flip[ax] = -1.0
            points = np.concatenate([points, points * flip])
            disp = np.concatenate([disp, disp * flip])
            weights = np.concatenate([weights, weights])
    return points, disp, weights


def front_rigid_body(mesh, displacement_mm: np.ndarray, symmetry_planes=()) -> RigidBodyMotion:
    """Rigid-body motion (µm, µrad) of the front face relative to the whole blank (module docstring).

    Parameters
    ----------
    mesh : skfem mesh (mm) with a ``front`` boundary; ``mesh.p`` indexes the displacement.
    displacement_mm : ndarray, shape (3, N)
        Nodal displacement, N >= number of mesh vertices (P2 fields: vertices first).
    symmetry_planes : iterable of str
        ``sym_x``/``sym_y``/``sym_z`` present.
    """
    p = np.asarray(mesh.p, float)
    u = 1e3 * np.asarray(displacement_mm, float)[:, : p.shape[1]]
    planes = tuple(symmetry_planes)
    tri = mesh.facets[:3, mesh.boundaries["front"]]
    z_front = float(p[2, tri].mean())
    origin = (0.0, 0.0, z_front)
    a = 0.5 * np.linalg.norm(np.cross((p[:, tri[1]] - p[:, tri[0]]).T, (p[:, tri[2]] - p[:, tri[0]]).T), axis=1)
    w = np.bincount(tri.ravel(), weights=np.tile(a / 3, 3), minlength=p.shape[1])  # lumped nodal areas
    on = w > 0
    face = fit_rigid_body(*_mirror(p[:, on].T, u[:, on].T, w[on], [s for s in planes if s != "sym_z"]),
                          origin_mm=origin)
    t = mesh.t[:4]
    e1, e2, e3 = (p[:, t[i]] - p[:, t[0]] for i in (1, 2, 3))
    vol = np.abs(np.einsum("ij,ij->j", e1, np.cross(e2.T, e3.T).T)) / 6
    wv = np.bincount(t.ravel(), weights=np.tile(vol / 4, 4), minlength=p.shape[1])
    inv = wv > 0
    body = fit_rigid_body(*_mirror(p[:, inv].T, u[:, inv].T, wv[inv], planes), origin_mm=origin)
    return face.minus(body)


def pttp_stats(sag, region) -> dict:
    """P/V, RMS (µm) of a :class:`fea.surface.FrontSag` over ``region`` with piston, tilt and power removed,
    and the removed power coefficient (µm/mm², of ``x² + y²``)."""
    m = resolve_region(region).contains(sag.x_mm, sag.y_mm)
    if not m.any():
        raise ValueError(f"no front-face samples inside region {resolve_region(region).name!r}")
    r, c = remove_low_order(sag.x_mm[m], sag.y_mm[m], sag.sag_um[m], sag.weight_mm2[m],
                            ("piston", "tilt", "power"))
    pv, rms = pv_rms_um(r, sag.weight_mm2[m])
    return {"pv_um": pv, "rms_um": rms, "power_um_per_mm2": c["power_um_per_mm2"]}


def front_figure_outputs(mesh, result, symmetry_planes=()) -> dict:
    """The per-case outputs: ``rb_*`` rigid-body motion and ``*_pttp_um`` figure over centre and full."""
    out = front_rigid_body(mesh, result.displacement_mm, symmetry_planes).as_dict("rb_")
    for region in ("center", "full"):
        st = pttp_stats(result.sag, region)
        out[f"pv_{region}_pttp_um"] = st["pv_um"]
        out[f"rms_{region}_pttp_um"] = st["rms_um"]
        out[f"power_{region}_um_per_mm2"] = st["power_um_per_mm2"]
    return out
