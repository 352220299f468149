"""Sag map and rigid-body motion of the optical face of any FE result (arrays in, SagMap out).

Units: mm for positions and displacements in, µm for sag and translations out, µrad
for rotations. The optical frame is that of :mod:`optics.sagmap` (x dispersion,
y rulings, z the face's outward normal); ``axes`` says which solver axis (with sign)
each optical axis is, e.g. ``"x,y,z"`` (default), ``"y,x,-z"`` or ``"-x,y,-z"``.

Steps: the face nodes' displacements are expressed in the optical frame; the 6-DOF
rigid-body motion about ``origin`` is fitted by area-weighted least squares on the face
nodes (:func:`optics.rigid_body.fit_rigid_body`) and removed; the sag is the residual
along +z or along the local outward normal; the nodal sag is interpolated onto the
grid with the face cells' shape functions (:mod:`fea.face_interp`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from optics.rigid_body import RigidBodyMotion, fit_rigid_body, pv_rms_um, remove_low_order, rigid_displacement_um
from optics.sagmap import SagMap

from .face_interp import interpolate_face
from .fe_face import FaceMesh

__all__ = ["FaceSagResult", "axes_matrix", "face_sag_map", "SAG_DIRECTIONS"]

#: Directions the sag can be taken along.
SAG_DIRECTIONS = ("z", "normal")


def axes_matrix(axes: str) -> np.ndarray:
    """Rows = optical x, y, z as signed solver axes: ``"y,-x,z"`` -> [[0,1,0],[-1,0,0],[0,0,1]]."""
    parts = [p.strip().lower() for p in str(axes).split(",")]
    R = np.zeros((3, 3))
    ok = len(parts) == 3
    for i, p in enumerate(parts if ok else []):
        sign = -1.0 if p.startswith("-") else 1.0
        name = p.lstrip("+-")
        if name not in ("x", "y", "z"):
            ok = False
            break
        R[i, "xyz".index(name)] = sign
    if not ok or not np.allclose(np.abs(R).sum(axis=0), 1):
        raise ValueError(f"axes={axes!r}: expected three signed solver axes, each once, giving the optical "
                         "x (dispersion), y (rulings), z (outward normal), e.g. 'x,y,z', 'y,x,-z', '-x,y,-z'")
    return R


@dataclass(frozen=True)
class FaceSagResult:
    """Sag map of an FE face with its rigid-body motion removed.

    Attributes
    ----------
    sag_map : SagMap
        Residual sag (µm) on the optical grid; ``meta`` records the choices made.
    rigid_body : RigidBodyMotion
        Removed motion (µm, µrad) about ``rigid_body.origin_mm`` (optical frame, mm).
    stats : dict
        Over the face nodes, area-weighted: ``pv_ptt_um``/``rms_ptt_um`` (piston, tilt
        removed, which the rigid-body removal already did) and ``pv_pttp_um``/``rms_pttp_um``
        (piston, tilt, power removed); ``power_um_per_mm2``.
    n_face_nodes : int
    """

    sag_map: SagMap
    rigid_body: RigidBodyMotion
    stats: dict = field(default_factory=dict)
    n_face_nodes: int = 0


def face_sag_map(points_mm: np.ndarray, displacement_mm: np.ndarray, face: FaceMesh, *, axes: str = "x,y,z",
                 origin_mm=None, sag_along: str = "z", spacing_mm: float = 0.5, label: str = "") -> FaceSagResult:
    """Sag map (µm) of ``face`` with its rigid-body motion removed.

    Parameters
    ----------
    points_mm : ndarray, shape (n, 3)
        Mesh points in the solver's frame (mm).
    displacement_mm : ndarray, shape (n, 3)
        Nodal displacements in the solver's frame (mm).
    face : FaceMesh
        Selected face (:func:`fea.fe_face.select_face`).
    axes : str
        Optical x, y, z as signed solver axes (:func:`axes_matrix`).
    origin_mm : (3,) sequence, optional
        Optical origin in the solver's frame (mm); default: centre of the face's x-y
        bounding box in the optical frame, at the face's mean height.
    sag_along : {"z", "normal"}
        Optical +z, or each node's outward face normal.
    spacing_mm : float
        Grid spacing (mm), > 0; grid lines at multiples of it about the origin.
    """
    if sag_along not in SAG_DIRECTIONS:
        raise ValueError(f"sag_along={sag_along!r} is unknown; valid values are {list(SAG_DIRECTIONS)}")
    if not spacing_mm > 0:
        raise ValueError(f"spacing_mm={spacing_mm} must be > 0")
    R = axes_matrix(axes)
    P = np.asarray(points_mm, float) @ R.T
    U = np.asarray(displacement_mm, float) @ R.T
    idx = face.node_index
    if origin_mm is None:
        lo, hi = P[idx].min(axis=0), P[idx].max(axis=0)
        origin = np.array([0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), P[idx, 2].mean()])
    else:
        origin = R @ np.asarray(origin_mm, float)
    P = P - origin
    area = face.nodal_area(P)
    normals = face.nodal_normals(P) @ R.T  # the face's normals are stored in the solver's frame
    if face.oriented:
        mean_n = (area[:, None] * normals).sum(axis=0)
        mean_n /= np.linalg.norm(mean_n)
        if mean_n[2] < 0.5:
            raise ValueError(f"axes={axes!r}: the face's mean outward normal is {np.round(mean_n, 3).tolist()} in the "
                             "optical frame, not +z; choose axes whose third entry is the face's outward normal "
                             "(e.g. 'x,-y,-z' for a face looking along -z)")
    else:  # a surface mesh has no outward side: take the side towards optical +z
        normals *= np.where(normals[:, 2] < 0, -1.0, 1.0)[:, None]
    rb = fit_rigid_body(P[idx], 1e3 * U[idx], area[idx], origin_mm=(0.0, 0.0, 0.0))
    resid = 1e3 * U - rigid_displacement_um(rb, P)
    sag = resid[:, 2] if sag_along == "z" else np.einsum("ij,ij->i", resid, normals)
    ptt, _ = remove_low_order(P[idx, 0], P[idx, 1], sag[idx], area[idx], ("piston", "tilt"))
    pttp, c = remove_low_order(P[idx, 0], P[idx, 1], sag[idx], area[idx], ("piston", "tilt", "power"))
    pv1, rms1 = pv_rms_um(ptt, area[idx])
    pv2, rms2 = pv_rms_um(pttp, area[idx])
    stats = {"pv_ptt_um": pv1, "rms_ptt_um": rms1, "pv_pttp_um": pv2, "rms_pttp_um": rms2,
             "power_um_per_mm2": c["power_um_per_mm2"]}
    lo, hi = P[idx, :2].min(axis=0), P[idx, :2].max(axis=0)
    gx = spacing_mm * np.arange(np.ceil(lo[0] / spacing_mm - 1e-9), np.floor(hi[0] / spacing_mm + 1e-9) + 1)
    gy = spacing_mm * np.arange(np.ceil(lo[1] / spacing_mm - 1e-9), np.floor(hi[1] / spacing_mm + 1e-9) + 1)
    if gx.size < 2 or gy.size < 2:
        raise ValueError(f"spacing_mm={spacing_mm:g} leaves fewer than two grid lines across the face, which spans "
                         f"{hi[0] - lo[0]:.4g} x {hi[1] - lo[1]:.4g} mm: give a smaller spacing_mm, or check the "
                         "model's length unit (a model in metres read as mm is 1000 times too small)")
    grid = interpolate_face(P[:, :2], sag, face, gx, gy)
    types = sorted({t for t, _ in face.blocks})
    meta = {"interpolation": ("quadratic" if face.order == 2 else "linear") + " shape functions of the face cells "
            f"({', '.join(types)})", "sag_along": sag_along, "axes": axes,
            "origin_solver_mm": (R.T @ origin).tolist(), "rigid_body_removed": True,
            **rb.as_dict("rigid_body_"), **stats}
    return FaceSagResult(SagMap(gx, gy, grid, label, meta), rb, stats, int(idx.size))
