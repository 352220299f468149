"""Scalar descriptors of a line profile (width, resolving power, peaks, asymmetry).

Definitions (all on a uniformly sampled profile ``offset_um`` / ``intensity``):

* **FWHM** (µm): distance between the *outermost* crossings of half the global
  maximum, linearly interpolated. For a double-peaked profile this is the full width
  of the pair, which is what a Gaussian-free spectroscopic width means.
* **FWHM (nm)** = FWHM_um / linear dispersion (µm per nm); **resolving power**
  ``R = lambda / Delta lambda_FWHM`` of the profile given (normally the detected
  one). ``resolving_power_2px`` is the design-style ``lambda / (2 pixels /
  dispersion)`` (Nyquist-sampled resolution element); this is the definition under
  which SPIFFI's "R ~ 4000" holds, the FWHM one gives ~5200-6900 for a perfect grating.
* **Centroid** (µm): first moment.
* **Peaks**: :func:`scipy.signal.find_peaks` with ``prominence >= 5 %`` of the global
  maximum (:data:`PEAK_PROMINENCE`), which ignores numerical ripple and the weak
  slit-edge ringing left after the pixel convolution but keeps satellite shoulders
  that form a local maximum. ``peak_spacing_um`` is the distance between the two
  highest peaks (NaN if fewer than 2); ``double_peak`` is True when the two highest
  peaks are both >= 50 % of the maximum and the dip between them is <= 95 % of the
  lower one.
* **Asymmetry** about the geometric slit centre (offset 0): ``(F_left - F_right) /
  (F_left + F_right)`` with F the flux at negative / positive offset (> 0 = more light
  to the left). ``shoulder_asymmetry`` is the same for the flux *outside* the
  geometric slit image only.
* **Flux outside the slit**: fraction of the flux at ``|offset| > slit_width / 2``.
"""

from __future__ import annotations

import numpy as np
from scipy.signal import find_peaks

from optics.imaging import Profile

__all__ = ["PEAK_PROMINENCE", "fwhm_um", "centroid_um", "find_profile_peaks", "profile_metrics", "l1_distance"]

#: Minimum peak prominence, as a fraction of the profile maximum.
PEAK_PROMINENCE = 0.05


def fwhm_um(offset_um: np.ndarray, intensity: np.ndarray) -> float:
    """Full width at half maximum (µm) between the outermost half-maximum crossings."""
    x, y = np.asarray(offset_um, float), np.asarray(intensity, float)
    half = 0.5 * y.max()
    above = np.nonzero(y >= half)[0]
    i0, i1 = above[0], above[-1]
    if i0 == 0 or i1 == y.size - 1:
        # no option of any command sets the window: name what is wrong, and the API setting
        raise ValueError(f"the profile does not fall below half its maximum inside its {x[0]:g}..{x[-1]:g} um "
                         "window, so its FWHM is undefined: the line is broader than the window "
                         "(API: a larger LsfSettings.window_um)")
    xl = np.interp(half, [y[i0 - 1], y[i0]], [x[i0 - 1], x[i0]])
    xr = np.interp(half, [y[i1 + 1], y[i1]], [x[i1 + 1], x[i1]])
    return float(xr - xl)


def centroid_um(offset_um: np.ndarray, intensity: np.ndarray) -> float:
    """First moment of the profile (µm)."""
    y = np.asarray(intensity, float)
    return float(np.sum(np.asarray(offset_um) * y) / np.sum(y))


def find_profile_peaks(offset_um: np.ndarray, intensity: np.ndarray, prominence: float = PEAK_PROMINENCE) -> dict:
    """Peaks with prominence >= ``prominence * max``, sorted by decreasing height.

    Returns a dict of lists: ``offset_um``, ``height`` (relative to the maximum),
    ``prominence`` (relative), and ``peak_spacing_um`` / ``double_peak`` (module doc).
    A refined position uses a parabola through the top three samples.
    """
    x, y = np.asarray(offset_um, float), np.asarray(intensity, float)
    ymax = y.max()
    idx, props = find_peaks(y, prominence=prominence * ymax)
    order = np.argsort(-y[idx])
    idx, prom = idx[order], props["prominences"][order]
    pos = []
    for i in idx:
        if 0 < i < y.size - 1:
            a, b, c = y[i - 1], y[i], y[i + 1]
            den = a - 2 * b + c
            pos.append(float(x[i] + (0.5 * (a - c) / den if den != 0 else 0.0) * (x[1] - x[0])))
        else:
            pos.append(float(x[i]))
    out = {"offset_um": pos, "height": (y[idx] / ymax).tolist(), "prominence": (prom / ymax).tolist(),
           "peak_spacing_um": float("nan"), "double_peak": False}
    if idx.size >= 2:
        i, j = sorted(idx[:2])
        out["peak_spacing_um"] = abs(pos[0] - pos[1])
        lo = min(y[i], y[j])
        out["double_peak"] = bool(lo >= 0.5 * ymax and y[i:j + 1].min() <= 0.95 * lo)
    return out


def l1_distance(a: Profile, b: Profile) -> float:
    """L1 distance between two unit-area profiles (0..2), ``b`` interpolated onto ``a``'s grid."""
    an, bn = a.normalised(), b.normalised()
    yb = np.interp(an.offset_um, bn.offset_um, bn.intensity, left=0.0, right=0.0)
    return float(np.sum(np.abs(an.intensity - yb)) * an.step_um)


def profile_metrics(p: Profile, wavelength_um: float | None = None, linear_dispersion_um_per_nm: float | None = None,
                    slit_image_width_um: float | None = None) -> dict:
    """All metrics of the module docstring as a JSON-ready dict.

    ``wavelength_um``, ``linear_dispersion_um_per_nm`` and ``slit_image_width_um``
    default to ``p.meta`` (set by :func:`optics.lineprofile.line_profile`); without a
    dispersion the nm/R entries are omitted, without a slit width 27 µm is used.
    """
    wl = p.meta.get("wavelength_um") if wavelength_um is None else wavelength_um
    disp = p.meta.get("linear_dispersion_um_per_nm") if linear_dispersion_um_per_nm is None else linear_dispersion_um_per_nm
    slit = p.meta.get("slit_image_width_um", 27.0) if slit_image_width_um is None else slit_image_width_um
    x, y = p.offset_um, p.intensity
    total = float(np.sum(y))
    w = fwhm_um(x, y)
    out = {"fwhm_um": w, "centroid_um": centroid_um(x, y)}
    if disp:
        out["fwhm_nm"] = w / disp
        if wl:
            out["resolving_power"] = wl * 1e3 / out["fwhm_nm"]
            if p.meta.get("pixel_um"):
                out["resolving_power_2px"] = wl * 1e3 * disp / (2 * p.meta["pixel_um"])
    left, right = float(np.sum(y[x < 0])), float(np.sum(y[x > 0]))
    out["asymmetry"] = (left - right) / (left + right)
    outside = np.abs(x) > 0.5 * slit
    lo, ro = float(np.sum(y[outside & (x < 0)])), float(np.sum(y[outside & (x > 0)]))
    out["outside_slit_fraction"] = (lo + ro) / total
    out["shoulder_asymmetry"] = (lo - ro) / (lo + ro) if lo + ro > 0 else 0.0
    out["slit_image_width_um"] = float(slit)
    out["peaks"] = find_profile_peaks(x, y)
    out["peak_prominence_threshold"] = PEAK_PROMINENCE
    return out
