"""Truth grating deformations: an FEA map of another mesh mixed with analytic quilts.

Families (``benchmarks/truth_families.md``): ``sum_mix`` = ``(1 - m) F + m (a cos(2 pi
x / 21) + b cos(2 pi y / 18))`` and ``product_mix`` = ``(1 - m) F + m c cos(2 pi x / 21)
cos(2 pi y / 18)``, with the quilts' phases and amplitudes fitted to ``F`` over the
central region (so they sit on the FEA's quilt, not beside it). ``m`` is solved so that
the *harmonic distance* to the nominal (:func:`harmonic_distance`) equals a drawn value,
and the result is scaled so that the nominal's least-squares scale in it is 1.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.interpolate import RegularGridInterpolator

__all__ = ["PERIOD_X_MM", "PERIOD_Y_MM", "CENTRAL_HALF_MM", "GratingTruth", "central", "harmonic_distance",
           "fundamental_x_ratio",
           "fitted_quilts", "mix_to_distance", "mixed_grating", "sag_function"]

PERIOD_X_MM, PERIOD_Y_MM = 21.0, 18.0
#: Half-widths (mm) of the paper's central 82 x 72 mm region.
CENTRAL_HALF_MM = (41.0, 36.0)


@dataclass(frozen=True)
class GratingTruth:
    """A truth deformation on a grid (µm at 80 K; x, y in mm, blank frame) and how it was made:
    its ``family``, the weight ``mix`` of the family's shape against the FEA map, the
    harmonic ``distance`` to the nominal and the family's drawn ``params``."""

    x_mm: np.ndarray
    y_mm: np.ndarray
    sag_um: np.ndarray
    family: str
    mix: float
    distance: float
    params: dict = field(default_factory=dict)

    def scaled(self, factor: float) -> "GratingTruth":
        return GratingTruth(self.x_mm, self.y_mm, self.sag_um * factor, self.family, self.mix, self.distance,
                            self.params)


def central(x_mm: np.ndarray, y_mm: np.ndarray) -> np.ndarray:
    """Mask (n_y, n_x) of the central 82 x 72 mm region."""
    return (np.abs(x_mm)[None, :] <= CENTRAL_HALF_MM[0]) & (np.abs(y_mm)[:, None] <= CENTRAL_HALF_MM[1])


def harmonic_distance(truth_um: np.ndarray, nominal_um: np.ndarray, mask: np.ndarray) -> tuple[float, float]:
    """(distance, k): ``||t - k n|| / ||k n||`` over ``mask`` with ``k = <t, n> / <n, n>``
    (piston removed from both): the part of the truth's shape no amplitude change reaches."""
    t = truth_um[mask] - truth_um[mask].mean()
    n = nominal_um[mask] - nominal_um[mask].mean()
    k = float(t @ n / (n @ n))
    return float(np.linalg.norm(t - k * n) / np.linalg.norm(k * n)), k


def _low_harmonics(x_mm, y_mm, sag_um, mask) -> np.ndarray:
    """Least-squares coefficients of piston, tilts and the quilt's low harmonics (1, 0),
    (0, 1), (1, ±1), (2, 0), (0, 2) (cos and sin each) over ``mask``."""
    X, Y = np.meshgrid(x_mm, y_mm)
    kx, ky = 2 * np.pi / PERIOD_X_MM, 2 * np.pi / PERIOD_Y_MM
    cols = [np.ones_like(X), X, Y]
    for i, j in ((1, 0), (0, 1), (1, 1), (1, -1), (2, 0), (0, 2)):
        arg = i * kx * X + j * ky * Y
        cols += [np.cos(arg), np.sin(arg)]
    ok = mask & np.isfinite(sag_um)
    A = np.column_stack([c[ok] for c in cols])
    return np.linalg.lstsq(A, sag_um[ok], rcond=None)[0]


def fundamental_x_ratio(x_mm, y_mm, truth_um, nominal_um) -> float:
    """Amplitude of the truth's x fundamental (21 mm, along the dispersion) over the
    nominal's, the truth's component projected on the nominal's phase, over the central
    region: the quilt amplitude a line profile measures (the paper's conclusion), which
    the normalisation of the whole map to the nominal (``k = 1``) leaves free."""
    mask = central(np.asarray(x_mm), np.asarray(y_mm))
    t = _low_harmonics(x_mm, y_mm, np.asarray(truth_um, float), mask)[3:5]
    n = _low_harmonics(x_mm, y_mm, np.asarray(nominal_um, float), mask)[3:5]
    return float(t @ n / (n @ n))


def fitted_quilts(x_mm: np.ndarray, y_mm: np.ndarray, fea_um: np.ndarray) -> dict[str, np.ndarray]:
    """Sum- and product-form quilts on the grid, with phases and amplitudes least-squares
    fitted to ``fea_um`` over the central region."""
    X, Y = np.meshgrid(x_mm, y_mm)
    kx, ky = 2 * np.pi / PERIOD_X_MM, 2 * np.pi / PERIOD_Y_MM
    mask = central(x_mm, y_mm)
    cols = [np.ones_like(X), np.cos(kx * X), np.sin(kx * X), np.cos(ky * Y), np.sin(ky * Y)]
    A = np.column_stack([c[mask] for c in cols])
    c, *_ = np.linalg.lstsq(A, fea_um[mask], rcond=None)
    fx = c[1] * cols[1] + c[2] * cols[2]
    fy = c[3] * cols[3] + c[4] * cols[4]
    px, py = math.atan2(-c[2], c[1]), math.atan2(-c[4], c[3])
    prod = np.cos(kx * X + px) * np.cos(ky * Y + py)
    a = float(prod[mask] @ (fea_um[mask] - fea_um[mask].mean()) / (prod[mask] @ prod[mask]))
    return {"sum_x": fx, "sum_y": fy, "product": a * prod if abs(a) > 1e-9 else math.hypot(c[1], c[2]) * prod}


def mixed_grating(x_mm, y_mm, fea_um, nominal_um, family: str, distance: float, rng: np.random.Generator,
                  ) -> GratingTruth:
    """Truth of ``family`` ("sum_mix", "product_mix") at harmonic ``distance`` from the nominal.

    ``fea_um`` (the truth's FEA map) and ``nominal_um`` are on the same grid. For
    ``sum_mix`` the y fundamental is re-weighted by ``b/a`` drawn in 0.6-1.6. Raises
    ValueError when no mixing weight in [0, 1] reaches ``distance``.
    """
    if not 0.0 < distance < 1.0:
        raise ValueError(f"mixed_grating: distance={distance} must be in (0, 1)")
    q = fitted_quilts(x_mm, y_mm, fea_um)
    if family == "sum_mix":
        quilt = q["sum_x"] + rng.uniform(0.6, 1.6) * q["sum_y"]
    elif family == "product_mix":
        quilt = q["product"]
    else:
        raise ValueError(f"mixed_grating: family={family!r} is not one of ['product_mix', 'sum_mix']")
    return mix_to_distance(x_mm, y_mm, fea_um, quilt, nominal_um, family, distance)


def mix_to_distance(x_mm, y_mm, fea_um, quilt_um, nominal_um, family: str, distance: float,
                    params: dict | None = None) -> GratingTruth:
    """``(1 - m) fea + m quilt`` with ``m`` in [0, 1] solved (bisection) so that the harmonic
    distance to ``nominal_um`` is ``distance``, scaled so that the nominal's least-squares
    scale in it is 1. Raises ValueError when no ``m`` reaches ``distance``."""
    mask = central(x_mm, y_mm)
    fea0 = np.where(np.isfinite(fea_um), fea_um, 0.0)

    def dist(m):
        return harmonic_distance((1 - m) * fea0 + m * quilt_um, nominal_um, mask)[0]

    lo, hi = 0.0, 1.0
    if dist(hi) < distance:
        raise ValueError(f"mixed_grating: family {family} reaches only distance {dist(hi):.3f} < {distance}")
    if dist(lo) > distance:
        raise ValueError(f"mixed_grating: the FEA map alone is already at distance {dist(lo):.3f} > {distance}")
    for _ in range(50):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if dist(mid) < distance else (lo, mid)
    m = 0.5 * (lo + hi)
    t = (1 - m) * fea_um + m * quilt_um
    d, k = harmonic_distance(np.where(np.isfinite(t), t, 0.0), nominal_um, mask)
    return GratingTruth(np.asarray(x_mm), np.asarray(y_mm), t / k, family, m, d, dict(params or {}))


def sag_function(g: GratingTruth, extra=None):
    """``f(x_mm, y_mm) -> µm``: bilinear interpolation of ``g`` (NaN off the map) plus
    ``extra(x, y)`` (µm) if given."""
    itp = RegularGridInterpolator((g.y_mm, g.x_mm), g.sag_um, bounds_error=False, fill_value=np.nan)

    def f(x, y):
        x, y = np.broadcast_arrays(np.asarray(x, float), np.asarray(y, float))
        v = itp(np.column_stack([y.ravel(), x.ravel()])).reshape(x.shape)
        return v if extra is None else v + extra(x, y)

    return f
