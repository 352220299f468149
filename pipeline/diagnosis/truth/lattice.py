"""Truth deformations built on the blank's hole lattice: ``pocket_jitter`` and ``sharp_ribs``.

The blank is lightweighted by cross-drilled holes (:class:`fea.geometry.Blank`): holes
along y centred at ``x = 21 i`` mm, holes along x centred at ``y = 18 j`` mm (7 + 7,
centred on the blank's axis), 15 mm in diameter, so the walls between holes are centred
at ``x = 10.5 + 21 i`` (6 mm wide) and ``y = 9 + 18 j`` (3 mm wide). The front face
prints this lattice through as the quilt. Both families change the quilt in ways that
no rescaling of the nominal's quilt parts reaches (``benchmarks/truth_families.md``):

* ``pocket_jitter``: every lattice cell (one hole crossing, bounded by walls) has its
  own face-to-hole wall thickness (drill wander, hole-diameter tolerance) and its own
  plating thickness inside the holes, so its print-through amplitude differs: the FEA
  map's quilt part (the map minus its smooth figure, :func:`smooth_figure`) is
  multiplied by ``1 + eps_cell`` (:func:`cell_field`), ``eps ~ N(0, sigma)``;
* ``sharp_ribs``: the walls print through sharper than a sinusoid (a thin face skin over
  the holes bends, the walls hold): a sum of rib profiles ``|cos(pi (u - u_wall) / P)|^p``
  along x and y (:func:`rib_profile`, analytic series :func:`rib_harmonics`), fitted to
  the FEA map and mixed with it at a drawn harmonic distance.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.ndimage import convolve1d, gaussian_filter
from scipy.special import gammaln, rgamma

from .gratings import PERIOD_X_MM, PERIOD_Y_MM, GratingTruth, central, harmonic_distance, mix_to_distance

__all__ = ["WALL_X_MM", "WALL_Y_MM", "BLEND_SIGMA_MM", "JITTER_SIGMA", "RIB_POWER", "smooth_figure", "cell_index",
           "cell_field", "pocket_jitter", "rib_profile", "rib_harmonics", "sharp_ribs"]

#: Centre of the wall between two holes (mm): half a pitch from the hole axes at 0.
WALL_X_MM, WALL_Y_MM = 0.5 * PERIOD_X_MM, 0.5 * PERIOD_Y_MM
#: Gaussian sigma (mm) of the blend of the jitter field across a cell edge: the walls are
#: 3-6 mm wide and the print-through of two neighbouring cells meets over the wall.
BLEND_SIGMA_MM = 1.5
#: Range of the per-cell amplitude scatter's sigma (pocket_jitter).
JITTER_SIGMA = (0.05, 0.15)
#: Range of the rib profile's power p (sharp_ribs): p = 2 is a pure sinusoid; p = 4 gives
#: a rib print-through 0.36 pitch wide at half height, p = 16 0.19 pitch (4 mm along x,
#: 3.4 mm along y: the wall widths).
RIB_POWER = (4.0, 16.0)


def _step_mm(a: np.ndarray, name: str) -> float:
    a = np.asarray(a, float)
    if a.ndim != 1 or a.size < 2 or not np.allclose(np.diff(a), a[1] - a[0], rtol=1e-9, atol=1e-9) or a[1] <= a[0]:
        raise ValueError(f"smooth_figure: {name} must be a uniform increasing grid (mm)")
    return float(a[1] - a[0])


def _period_kernel(period_mm: float, step_mm: float, name: str) -> np.ndarray:
    """Moving average over exactly one period: trapezoid weights over ``n + 1`` samples."""
    n = period_mm / step_mm
    if abs(n - round(n)) > 1e-6 or round(n) < 2:
        raise ValueError(f"smooth_figure: the {name} spacing {step_mm} mm must divide the period {period_mm} mm")
    k = np.ones(int(round(n)) + 1)
    k[0] = k[-1] = 0.5
    return k / k.sum()


def smooth_figure(x_mm: np.ndarray, y_mm: np.ndarray, sag_um: np.ndarray) -> np.ndarray:
    """The map's smooth figure (µm): its moving average over exactly one lattice period
    along x and along y (NaN-aware; NaN where the map is NaN).

    Why a period average: it removes every harmonic of the 21 x 18 mm lattice exactly
    (sum form, product form, any order) and keeps a plane exactly, so ``sag - figure`` is
    the quilt without assuming its shape. Within half a period of the map's edge the
    window is truncated, so the figure there carries some quilt (outside the central
    region)."""
    kx = _period_kernel(PERIOD_X_MM, _step_mm(x_mm, "x_mm"), "x")
    ky = _period_kernel(PERIOD_Y_MM, _step_mm(y_mm, "y_mm"), "y")
    valid = np.isfinite(sag_um)
    z = np.where(valid, sag_um, 0.0)
    w = valid.astype(float)
    for k, ax in ((kx, 1), (ky, 0)):
        z = convolve1d(z, k, axis=ax, mode="constant")
        w = convolve1d(w, k, axis=ax, mode="constant")
    with np.errstate(invalid="ignore", divide="ignore"):
        out = z / w
    return np.where(valid, out, np.nan)


def cell_index(x_mm: np.ndarray, y_mm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(i, j): the lattice cell of each grid column and row, cell ``(i, j)`` centred on
    the hole crossing ``(21 i, 18 j)`` mm and bounded by the walls."""
    return (np.round(np.asarray(x_mm, float) / PERIOD_X_MM).astype(int),
            np.round(np.asarray(y_mm, float) / PERIOD_Y_MM).astype(int))


def cell_field(x_mm: np.ndarray, y_mm: np.ndarray, eps: np.ndarray, blend_sigma_mm: float = BLEND_SIGMA_MM,
               ) -> np.ndarray:
    """``1 + eps[j - j0, i - i0]`` in each cell (grid (n_y, n_x)), blended across the cell
    edges by a Gaussian of ``blend_sigma_mm``; ``(i0, j0)`` the lowest cell of the grid.
    ``eps`` has shape (number of cells along y, along x) of the grid."""
    i, j = cell_index(x_mm, y_mm)
    shape = (j.max() - j.min() + 1, i.max() - i.min() + 1)
    if np.shape(eps) != shape:
        raise ValueError(f"cell_field: eps has shape {np.shape(eps)}, the grid has {shape} cells")
    field = 1.0 + np.asarray(eps, float)[(j - j.min())[:, None], (i - i.min())[None, :]]
    sx = blend_sigma_mm / _step_mm(x_mm, "x_mm")
    sy = blend_sigma_mm / _step_mm(y_mm, "y_mm")
    return gaussian_filter(field, (sy, sx), mode="nearest")


def pocket_jitter(x_mm, y_mm, fea_um, nominal_um, rng: np.random.Generator,
                  sigma_range: tuple[float, float] = JITTER_SIGMA) -> GratingTruth:
    """Truth ``pocket_jitter``: ``figure + (1 + eps_cell) (fea - figure)``, ``eps ~ N(0,
    sigma)`` per lattice cell with ``sigma`` drawn in ``sigma_range``, scaled so that the
    nominal's least-squares scale in it is 1. Its harmonic distance to the nominal
    follows from the draw (about ``sigma`` times the quilt's share of the map's norm)."""
    sigma = float(rng.uniform(*sigma_range))
    i, j = cell_index(x_mm, y_mm)
    eps = rng.normal(0.0, sigma, (j.max() - j.min() + 1, i.max() - i.min() + 1))
    fig = smooth_figure(x_mm, y_mm, fea_um)
    t = fig + cell_field(x_mm, y_mm, eps) * (fea_um - fig)
    mask = central(x_mm, y_mm)
    d, k = harmonic_distance(np.where(np.isfinite(t), t, 0.0), nominal_um, mask)
    params = {"sigma": sigma, "eps": eps.tolist(), "cell_i0": int(i.min()), "cell_j0": int(j.min()), "scale": 1.0 / k}
    return GratingTruth(np.asarray(x_mm), np.asarray(y_mm), t / k, "pocket_jitter", 1.0, d, params)


def rib_profile(u_mm, period_mm: float, p: float, wall_mm: float) -> np.ndarray:
    """``|cos(pi (u - wall) / period)|^p``: 1 on the walls ``wall + n period``, 0 midway."""
    return np.abs(np.cos(np.pi * (np.asarray(u_mm, float) - wall_mm) / period_mm)) ** p


def rib_harmonics(p: float, n_max: int) -> np.ndarray:
    """Fourier cosine coefficients ``a_0 ... a_n_max`` of ``|cos t|^p = a_0 + sum a_n cos(2 n t)``
    (so ``a_n`` is the n-th harmonic of :func:`rib_profile`'s period, about the wall):
    ``a_n = c_n Gamma(p + 1) / (2^p Gamma(1 + p/2 + n) Gamma(1 + p/2 - n))``, ``c_0 = 1``,
    ``c_n = 2`` (Gradshteyn & Ryzhik 3.631.9); zero for ``n > p/2`` when ``p`` is even."""
    if not (math.isfinite(p) and p > 0):
        raise ValueError(f"rib_harmonics: p={p!r} must be a finite number > 0")
    n = np.arange(n_max + 1, dtype=float)
    # Gamma(p+1) / (2^p Gamma(1+p/2+n)) in logs (no overflow for large p); 1/Gamma(1+p/2-n) keeps its sign
    a = np.exp(gammaln(p + 1) - p * math.log(2.0) - gammaln(1 + p / 2 + n)) * rgamma(1 + p / 2 - n)
    a[1:] *= 2.0
    return a


def sharp_ribs(x_mm, y_mm, fea_um, nominal_um, distance: float, rng: np.random.Generator,
               power_range: tuple[float, float] = RIB_POWER) -> GratingTruth:
    """Truth ``sharp_ribs``: ``(1 - m) fea + m q`` with ``q = c + a R_x(x) + b R_y(y)``,
    ``R`` the rib profiles on the walls with powers ``p_x``, ``p_y`` drawn in
    ``power_range``, ``c, a, b`` least-squares fitted to ``fea`` over the central region
    (so the ribs print through with the FEA's sign and strength), ``m`` solved for the
    harmonic ``distance`` (:func:`.gratings.mix_to_distance`)."""
    p_x, p_y = (float(v) for v in rng.uniform(*power_range, 2))
    X, Y = np.meshgrid(np.asarray(x_mm, float), np.asarray(y_mm, float))
    rx, ry = rib_profile(X, PERIOD_X_MM, p_x, WALL_X_MM), rib_profile(Y, PERIOD_Y_MM, p_y, WALL_Y_MM)
    mask = central(x_mm, y_mm) & np.isfinite(fea_um)
    A = np.column_stack([np.ones(mask.sum()), rx[mask], ry[mask]])
    c, *_ = np.linalg.lstsq(A, fea_um[mask], rcond=None)
    quilt = c[0] + c[1] * rx + c[2] * ry
    params = {"p_x": p_x, "p_y": p_y, "rib_x_um": float(c[1]), "rib_y_um": float(c[2])}
    return mix_to_distance(x_mm, y_mm, fea_um, quilt, nominal_um, "sharp_ribs", distance, params)
