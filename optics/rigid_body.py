"""Rigid-body motion and low-order figure of a deformed optical face (point-cloud arrays).

Conventions (the optical frame of :mod:`optics.sagmap`: x dispersion, y rulings, z the
outward normal of the face):

* Small-displacement rigid-body motion about a reference point ``p0``:
  ``u(p) = d + theta x (p - p0)`` with ``d = (dx, dy, dz)`` and
  ``theta = (rx, ry, rz)``. ``rx`` turns +y towards +z, ``ry`` turns +z towards +x
  and ``rz`` turns +x towards +y: ``rz`` is the clocking of the grooves.
* Translations in µm, rotations in µrad (:attr:`RigidBodyMotion.rz_arcsec` etc. in arcsec).
* Least squares over points with weights (area or volume per point); a flat face
  determines all six values when its points span two directions.

Low-order figure: :func:`remove_low_order` removes piston, tilt and optionally power
(``x² + y²``, i.e. Zernike defocus together with piston) from sag samples by weighted
least squares over the same samples; the P/V and RMS of the residual are what SigFit
and OpticStudio call "P/V, RMS with piston/tilt(/power) removed".
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["RigidBodyMotion", "fit_rigid_body", "rigid_displacement_um", "remove_low_order", "pv_rms_um",
           "LOW_ORDER_TERMS", "URAD_PER_ARCSEC"]

#: µrad in one arcsecond.
URAD_PER_ARCSEC = np.pi / (180 * 3600) * 1e6
#: Terms :func:`remove_low_order` can remove.
LOW_ORDER_TERMS = ("piston", "tilt", "power")


@dataclass(frozen=True)
class RigidBodyMotion:
    """Six rigid-body degrees of freedom of a face (small rotations).

    Attributes
    ----------
    dx_um, dy_um, dz_um : float
        Translation of the reference point (µm).
    rx_urad, ry_urad, rz_urad : float
        Rotations about x, y, z (µrad, right-handed; ``rz`` = groove clocking).
    origin_mm : tuple of float
        Reference point ``p0`` (mm) in the frame the motion is expressed in.
    """

    dx_um: float
    dy_um: float
    dz_um: float
    rx_urad: float
    ry_urad: float
    rz_urad: float
    origin_mm: tuple = (0.0, 0.0, 0.0)

    @property
    def rx_arcsec(self) -> float:
        return self.rx_urad / URAD_PER_ARCSEC

    @property
    def ry_arcsec(self) -> float:
        return self.ry_urad / URAD_PER_ARCSEC

    @property
    def rz_arcsec(self) -> float:
        return self.rz_urad / URAD_PER_ARCSEC

    def as_dict(self, prefix: str = "rb_") -> dict:
        """Flat dict ``{prefix}dx_um ... {prefix}rz_urad`` (for tables)."""
        return {f"{prefix}{k}": float(getattr(self, k))
                for k in ("dx_um", "dy_um", "dz_um", "rx_urad", "ry_urad", "rz_urad")}

    def minus(self, other: "RigidBodyMotion") -> "RigidBodyMotion":
        """This motion relative to ``other`` (same reference point required)."""
        if not np.allclose(self.origin_mm, other.origin_mm):
            raise ValueError(f"origin_mm differ: {self.origin_mm} vs {other.origin_mm}")
        v = np.array(list(self.as_dict("").values())) - np.array(list(other.as_dict("").values()))
        return RigidBodyMotion(*map(float, v), origin_mm=self.origin_mm)


def _design(points_mm: np.ndarray, origin_mm) -> np.ndarray:
    """Rows (3n, 6): u = d + theta x r, r = p - p0; columns dx, dy, dz, rx, ry, rz."""
    r = np.asarray(points_mm, float) - np.asarray(origin_mm, float)[None, :]
    n = r.shape[0]
    A = np.zeros((n, 3, 6))
    A[:, 0, 0] = A[:, 1, 1] = A[:, 2, 2] = 1.0
    # theta x r = (ry rz_ - rz ry_, rz rx_ - rx rz_, rx ry_ - ry rx_)
    A[:, 0, 4], A[:, 0, 5] = r[:, 2], -r[:, 1]
    A[:, 1, 3], A[:, 1, 5] = -r[:, 2], r[:, 0]
    A[:, 2, 3], A[:, 2, 4] = r[:, 1], -r[:, 0]
    return A


def fit_rigid_body(points_mm: np.ndarray, displacement_um: np.ndarray, weights=None,
                   origin_mm=(0.0, 0.0, 0.0)) -> RigidBodyMotion:
    """Weighted least-squares rigid-body motion of a point cloud.

    Parameters
    ----------
    points_mm : ndarray, shape (n, 3)
        Undeformed positions (mm).
    displacement_um : ndarray, shape (n, 3)
        Displacements (µm).
    weights : ndarray, shape (n,), optional
        Non-negative weight per point (area or volume); equal weights by default.
    origin_mm : (3,) sequence
        Reference point about which rotations are taken (mm).

    Returns
    -------
    RigidBodyMotion
        Rotations in µrad (µm / mm = mrad, so the fitted value is scaled by 1e3).
    """
    p = np.asarray(points_mm, float)
    u = np.asarray(displacement_um, float)
    if p.ndim != 2 or p.shape[1] != 3 or u.shape != p.shape:
        raise ValueError(f"points_mm and displacement_um must both have shape (n, 3); got {p.shape}, {u.shape}")
    w = np.ones(p.shape[0]) if weights is None else np.asarray(weights, float)
    if w.shape != (p.shape[0],) or np.any(w < 0) or not np.isfinite(w).all():
        raise ValueError(f"weights must be {p.shape[0]} finite values >= 0")
    A = _design(p, origin_mm) * np.sqrt(w)[:, None, None]
    A = A.reshape(-1, 6)
    b = (u * np.sqrt(w)[:, None]).ravel()
    c, _, rank, _ = np.linalg.lstsq(A, b, rcond=None)
    if rank < 6:
        raise ValueError(f"the {p.shape[0]} points do not determine 6 rigid-body values (rank {rank}): "
                         "they must span a plane (>= 3 non-collinear points)")
    c[3:] *= 1e3  # µm/mm = 1e-3 rad -> µrad
    return RigidBodyMotion(*map(float, c), origin_mm=tuple(float(v) for v in origin_mm))


def rigid_displacement_um(motion: RigidBodyMotion, points_mm: np.ndarray) -> np.ndarray:
    """Displacement (µm, shape (n, 3)) of ``points_mm`` under ``motion``."""
    A = _design(np.asarray(points_mm, float), motion.origin_mm)
    c = np.array([motion.dx_um, motion.dy_um, motion.dz_um,
                  1e-3 * motion.rx_urad, 1e-3 * motion.ry_urad, 1e-3 * motion.rz_urad])
    return A @ c


def remove_low_order(x_mm, y_mm, sag_um, weights=None, remove=("piston", "tilt")):
    """Sag minus its weighted least-squares piston, tilt (and power) over the samples.

    Parameters
    ----------
    x_mm, y_mm, sag_um : ndarray, shape (n,)
    weights : ndarray, shape (n,), optional
        Area per sample (equal by default).
    remove : sequence of {"piston", "tilt", "power"}
        ``power`` is ``x² + y²`` about the origin of the coordinates.

    Returns
    -------
    residual_um : ndarray, shape (n,)
    coefficients : dict
        ``piston_um``, ``tilt_x_um_per_mm``, ``tilt_y_um_per_mm``, ``power_um_per_mm2`` as removed.
    """
    bad = sorted(set(remove) - set(LOW_ORDER_TERMS))
    if bad:
        raise ValueError(f"remove={list(remove)!r}: unknown term(s) {bad}; valid terms are {list(LOW_ORDER_TERMS)}")
    x, y, s = (np.asarray(v, float).ravel() for v in (x_mm, y_mm, sag_um))
    w = np.ones_like(s) if weights is None else np.asarray(weights, float).ravel()
    cols, names = [], []
    if "piston" in remove:
        cols.append(np.ones_like(x)), names.append("piston_um")
    if "tilt" in remove:
        cols += [x, y]
        names += ["tilt_x_um_per_mm", "tilt_y_um_per_mm"]
    if "power" in remove:
        cols.append(x**2 + y**2), names.append("power_um_per_mm2")
    if not cols:
        return s.copy(), {}
    A = np.column_stack(cols)
    sw = np.sqrt(w)
    c, *_ = np.linalg.lstsq(A * sw[:, None], s * sw, rcond=None)
    return s - A @ c, dict(zip(names, map(float, c)))


def pv_rms_um(values_um, weights=None) -> tuple[float, float]:
    """P/V and weighted RMS about the weighted mean (µm)."""
    v = np.asarray(values_um, float).ravel()
    w = np.ones_like(v) if weights is None else np.asarray(weights, float).ravel()
    mean = np.sum(w * v) / np.sum(w)
    return float(v.max() - v.min()), float(np.sqrt(np.sum(w * (v - mean) ** 2) / np.sum(w)))

