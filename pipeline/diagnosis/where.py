"""Where the gap lies: partitions of a residual into named parts with their shares.

Every decomposition is a partition of the residual sum of squares (shares add to 1
within one ``decomposition``):

* surface ``basis``: sequential least squares over the aperture — low-order Zernike
  groups (defocus, astigmatism, coma, trefoil, spherical, secondary astigmatism,
  tetrafoil; piston/tilt are nuisances and already removed), then the quilt Fourier
  components at (i/Dx, j/Dy) (``quilt_fundamental``: |i|,|j| <= 1; ``quilt_harmonics``:
  up to 2), then ``noise`` (n sigma^2) and ``other_structure`` (the rest);
* surface ``region``: centre 82 x 72 mm vs edges; ``cells``: the 21 x 18 mm cells
  (the three largest are listed, the rest pooled);
* profile ``profile_region``: core (|u - u0| <= 20 µm), shoulders/satellites (out to
  20 µm + 2.5 satellite spacings ``f_cam lambda / (Dx cos beta)``), wings beyond;
* profile ``symmetry``: odd (left/right asymmetric) vs even part about the line centre;
* PSF image ``image_region``: core (within 15 µm of the image centre), halo (15-40 µm:
  the first quilt satellites and the Airy rings), outer;
* PSF image ``image_symmetry``: parity about the image centre on the samples whose three
  mirror images are also sampled — even, odd in x (left/right: coma, footprint shift
  along the dispersion), odd in y (up/down: footprint shift along the rulings), odd in
  both (oblique: astigmatism at 45°, the term a line profile cannot see);
* ``measurements``: each measurement's share of the weighted total (across gratings,
  wavelengths and pixel scales).
"""

from __future__ import annotations

import math

import numpy as np

from optics.zernike import zernike_xy

__all__ = ["ZERNIKE_GROUPS", "surface_parts", "profile_parts", "psf_image_parts", "measurement_parts", "satellite_spacing_um"]

ZERNIKE_GROUPS = (
    ("defocus", ((2, 0),)), ("astigmatism", ((2, 2), (2, -2))), ("coma", ((3, 1), (3, -1))),
    ("trefoil", ((3, 3), (3, -3))), ("spherical", ((4, 0),)), ("secondary_astigmatism", ((4, 2), (4, -2))),
    ("tetrafoil", ((4, 4), (4, -4))),
)
PERIOD_X_MM, PERIOD_Y_MM = 21.0, 18.0


def _fourier(x, y, comps):
    cols = []
    for i, j in comps:
        ph = 2 * np.pi * (i * x / PERIOD_X_MM + j * y / PERIOD_Y_MM)
        cols += [np.cos(ph), np.sin(ph)]
    return np.column_stack(cols)


def _entry(name, comp, share, dec):
    return {"measurement": name, "component": comp, "share": float(share), "decomposition": dec}


def surface_parts(name: str, x: np.ndarray, y: np.ndarray, r: np.ndarray, radius_mm: float,
                  noise_um: float) -> list[dict]:
    """Partitions of a surface residual ``r`` (µm) at points ``x, y`` (mm)."""
    r = np.asarray(r, float)
    total = float(np.sum(r**2))
    out = []
    if total <= 0:
        return out
    base = [np.ones_like(x), x, y]  # piston/tilt are nuisances: keep them in every step
    fund = [(1, 0), (0, 1), (1, 1), (1, -1)]
    harm = [(2, 0), (0, 2), (2, 1), (2, -1), (1, 2), (1, -2), (2, 2), (2, -2)]
    steps = [(g, [zernike_xy(n, m, x, y, radius_mm) for n, m in t]) for g, t in ZERNIKE_GROUPS]
    steps += [("quilt_fundamental", list(_fourier(x, y, fund).T)), ("quilt_harmonics", list(_fourier(x, y, harm).T))]
    cols, prev = list(base), float(np.sum((r - np.column_stack(base) @ np.linalg.lstsq(np.column_stack(base), r, rcond=None)[0]) ** 2))
    out.append(_entry(name, "piston_tilt", (total - prev) / total, "basis"))
    for label, new in steps:
        cols += new
        A = np.column_stack(cols)
        rss = float(np.sum((r - A @ np.linalg.lstsq(A, r, rcond=None)[0]) ** 2))
        out.append(_entry(name, label, max(prev - rss, 0.0) / total, "basis"))
        prev = rss
    noise = min(r.size * noise_um**2, prev) if np.isfinite(noise_um) else 0.0
    out.append(_entry(name, "noise", noise / total, "basis"))
    out.append(_entry(name, "other_structure", (prev - noise) / total, "basis"))
    centre = (np.abs(x) <= 41.0) & (np.abs(y) <= 36.0)
    out.append(_entry(name, "center_82x72", np.sum(r[centre] ** 2) / total, "region"))
    out.append(_entry(name, "edges", np.sum(r[~centre] ** 2) / total, "region"))
    ix = np.round(x / PERIOD_X_MM).astype(int)
    iy = np.round(y / PERIOD_Y_MM).astype(int)
    cells = {}
    for a, b, v in zip(ix, iy, r**2):
        cells[(a, b)] = cells.get((a, b), 0.0) + v
    ranked = sorted(cells.items(), key=lambda kv: -kv[1])
    for (a, b), v in ranked[:3]:
        out.append(_entry(name, f"cell({a:+d},{b:+d})", v / total, "cells"))
    out.append(_entry(name, f"other_{max(len(ranked) - 3, 0)}_cells", sum(v for _, v in ranked[3:]) / total, "cells"))
    return out


def satellite_spacing_um(grating: str, wavelength_um: float, order: int) -> float:
    """Detector distance (µm) of the first quilt satellite, ``f_cam lambda / (Dx cos beta)``."""
    from optics.grating import SPIFFI, get_grating

    beta = math.radians(float(get_grating(grating).beta_deg(wavelength_um, order)))
    return SPIFFI.camera_focal_mm * 1e3 * wavelength_um * 1e-3 / (PERIOD_X_MM * math.cos(beta))


def profile_parts(name: str, u: np.ndarray, r: np.ndarray, centre_um: float, spacing_um: float) -> list[dict]:
    """Partitions of a profile residual ``r`` at offsets ``u`` (µm) about ``centre_um``."""
    r = np.asarray(r, float)
    total = float(np.sum(r**2))
    if total <= 0:
        return []
    a = np.abs(u - centre_um)
    core, sh = a <= 20.0, (a > 20.0) & (a <= 20.0 + 2.5 * spacing_um)
    out = [_entry(name, "core", np.sum(r[core] ** 2) / total, "profile_region"),
           _entry(name, "shoulders_satellites", np.sum(r[sh] ** 2) / total, "profile_region"),
           _entry(name, "wings", np.sum(r[~core & ~sh] ** 2) / total, "profile_region")]
    mirror = np.interp(2 * centre_um - u, u, r, left=np.nan, right=np.nan)
    ok = np.isfinite(mirror)
    odd = 0.5 * (r[ok] - mirror[ok])
    tot_ok = float(np.sum(r[ok] ** 2))
    if tot_ok > 0:
        f = float(np.sum(odd**2)) / tot_ok
        out += [_entry(name, "asymmetric_left_right", f, "symmetry"), _entry(name, "symmetric", 1 - f, "symmetry")]
    return out


def psf_image_parts(name: str, x: np.ndarray, y: np.ndarray, r: np.ndarray, centre_um: tuple[float, float]) -> list[dict]:
    """Partitions of a PSF-image residual ``r`` at detector points ``x, y`` (µm) about the
    image centre ``centre_um`` (snapped to the sample lattice, so mirror images are samples)."""
    r = np.asarray(r, float)
    total = float(np.sum(r**2))
    if total <= 0:
        return []
    rho = np.hypot(x - centre_um[0], y - centre_um[1])
    core, halo = rho <= 15.0, (rho > 15.0) & (rho <= 40.0)
    out = [_entry(name, "core", np.sum(r[core] ** 2) / total, "image_region"),
           _entry(name, "halo", np.sum(r[halo] ** 2) / total, "image_region"),
           _entry(name, "outer", np.sum(r[~core & ~halo] ** 2) / total, "image_region")]
    steps = [np.min(np.diff(np.unique(np.round(v, 6)))) if np.unique(np.round(v, 6)).size > 1 else 0.0 for v in (x, y)]
    if not min(steps) > 0:
        return out
    # mirror about a lattice point or a half-step point, whichever is nearest the centre
    c = [round((c - v.min()) / (0.5 * h)) * 0.5 * h + v.min() for c, v, h in zip(centre_um, (x, y), steps)]
    key = {(round(a / steps[0] * 2), round(b / steps[1] * 2)): i for i, (a, b) in enumerate(zip(x, y))}

    def at(a, b):
        return np.array([key.get((round(u / steps[0] * 2), round(v / steps[1] * 2)), -1) for u, v in zip(a, b)])

    ix, iy, ixy = at(2 * c[0] - x, y), at(x, 2 * c[1] - y), at(2 * c[0] - x, 2 * c[1] - y)
    ok = (ix >= 0) & (iy >= 0) & (ixy >= 0)
    if ok.sum() < 16:
        return out
    a, bx, by, bxy = r[ok], r[ix[ok]], r[iy[ok]], r[ixy[ok]]
    parts = {"even": a + bx + by + bxy, "odd_x_left_right": a - bx + by - bxy,
             "odd_y_up_down": a + bx - by - bxy, "odd_xy_oblique": a - bx - by + bxy}
    tot_ok = float(np.sum(a**2))
    for label, v in parts.items():
        out.append(_entry(name, label, float(np.sum((v / 4) ** 2)) / tot_ok if tot_ok > 0 else 0.0, "image_symmetry"))
    return out


def measurement_parts(weighted_rss: dict) -> list[dict]:
    """Each measurement's share of the weighted residual sum of squares."""
    total = sum(weighted_rss.values())
    return [_entry("*", m, v / total if total > 0 else 0.0, "measurements") for m, v in weighted_rss.items()]
