"""``instrument_wings``: light a line profile gains on the detector side of the grating, the
diagnostic alternative a line-profile finding is checked against
(:mod:`pipeline.diagnosis.wings`). Not a library effect: never ranked or reported as an
explanation, so it is not in :data:`.library.LIBRARY`, but the line-profile model takes its
parameters (:data:`.library.ALTERNATIVES`).

Two kernels act on the detected profile ``P(u)`` (unit area, detector offset ``u`` in µm),
each keeping the flux (the flux scale is a nuisance anyway):

* a symmetric **halo**, ``(1 - f) P + f (P * L_w)`` with ``L_w`` a Lorentzian of half width
  ``w``: the far wings of scatter off the grating's and the optics' micro-roughness fall
  as ``1/u^2`` (the Lorentzian's wings) in the dispersion direction;
* a one-sided **tail**, ``(1 - |t|) P + |t| (P * E_tau)`` with ``E_tau`` a decaying
  exponential of length ``tau`` towards ``+u`` where ``t > 0`` (towards ``-u`` where
  ``t < 0``): charge trailing or persistence along the read-out direction.

* a symmetric **blur**, ``P * G_s`` with ``G_s`` a Gaussian of standard deviation ``s``:
  charge diffusion between pixels, a detector's MTF, a read-out's smearing (the inter-pixel
  coupling nuisance moves light to the next pixel only, at most 5 %: an outside lab's profiles
  broadened by an 18 µm box were otherwise taken for a collimator error);

and one pointwise response:

* a **non-linearity**, ``P (1 - b P / max P)``: the first-order loss of gain towards a pixel's
  full well (infrared arrays lose a few per cent of their gain at the levels an arc line's peak
  is exposed to), which flattens a line's peaks against its dip and wings.

The kernels are convolutions of the profile the optics form, so they change every pixel scale's
profile by the same kernel in detector µm, while a grating or pupil effect changes them
through the pupil (its size and illumination differ per pixel scale). Each kernel spans
twice the model's window (±150 µm) and is normalised there; what it scatters beyond the
window is lost, as it is off a detector row's cut-out.

Prior ranges: a blur of up to 15 µm (less than a pixel of 18 µm; charge diffusion in an
infrared array is a few µm), a halo or tail of up to 15 % of the flux (a spectrograph with more than that
outside its line core is broken, not subtly off), a halo half width of 10-150 µm (from
about half the line's FWHM to its window) and a tail length of 5-60 µm (a fraction of a
pixel to three pixels of 18 µm); a non-linearity of 0-15 % at the line's peak (gain only
lost towards the full well).
"""

from __future__ import annotations

import numpy as np

from .base import Effect, Parameter

__all__ = ["INSTRUMENT_WINGS", "wings_profile"]


def _kernel_convolve(y: np.ndarray, kernel: np.ndarray) -> np.ndarray:
    """``y`` convolved with ``kernel`` (odd length, centred, unit sum), same length as ``y``."""
    from scipy.signal import convolve

    return convolve(y, kernel, mode="same")


def _halo_kernel(step_um: float, n: int, hwhm_um: float) -> np.ndarray:
    u = (np.arange(2 * n + 1) - n) * step_um
    k = hwhm_um / (u * u + hwhm_um * hwhm_um)
    return k / k.sum()


def _tail_kernel(step_um: float, n: int, decay_um: float, side: float) -> np.ndarray:
    u = (np.arange(2 * n + 1) - n) * step_um * side
    k = np.where(u >= 0, np.exp(-np.clip(u, 0.0, None) / decay_um), 0.0)
    return k / k.sum()


def _blur_kernel(step_um: float, n: int, sigma_um: float) -> np.ndarray:
    u = (np.arange(2 * n + 1) - n) * step_um
    k = np.exp(-0.5 * (u / sigma_um) ** 2)
    return k / k.sum()


def wings_profile(offset_um: np.ndarray, intensity: np.ndarray, p: dict) -> np.ndarray:
    """The profile ``intensity`` (on the uniform grid ``offset_um``, µm) with the blur, the
    halo, the tail and the non-linearity of the parameters ``p`` (module docstring);
    unchanged where all four are 0.

    Raises
    ------
    ValueError
        If ``offset_um`` is not a uniform grid of at least 3 samples.
    """
    f = float(p.get("halo_fraction", 0.0))
    t = float(p.get("tail_fraction", 0.0))
    b = float(p.get("nonlinearity", 0.0))
    g = float(p.get("blur_um", 0.0))
    y = np.asarray(intensity, float)
    if f == 0.0 and t == 0.0 and b == 0.0 and g == 0.0:
        return y
    u = np.asarray(offset_um, float)
    d = np.diff(u)
    if u.size < 3 or not np.allclose(d, d[0], rtol=1e-6, atol=0.0) or not d[0] > 0:
        raise ValueError(f"wings_profile: offset_um must be a uniform increasing grid of >= 3 samples "
                         f"(steps {d.min() if d.size else None}..{d.max() if d.size else None})")
    n = u.size - 1
    out = y
    if g > 0.0:
        out = _kernel_convolve(out, _blur_kernel(d[0], n, g))
    if f != 0.0:
        out = (1.0 - f) * out + f * _kernel_convolve(out, _halo_kernel(d[0], n, float(p.get("halo_hwhm_um", 40.0))))
    if t != 0.0:
        k = _tail_kernel(d[0], n, float(p.get("tail_decay_um", 20.0)), 1.0 if t > 0 else -1.0)
        out = (1.0 - abs(t)) * out + abs(t) * _kernel_convolve(out, k)
    if b != 0.0:
        peak = float(np.max(out))
        out = out * (1.0 - b * out / peak) if peak > 0 else out
    return out


INSTRUMENT_WINGS = Effect(
    "instrument_wings", ("line_profile",),
    (Parameter("halo_fraction", 0.0, 0.0, 0.15, floor=0.01, unit="1", kinds=("line_profile",),
               meaning="fraction of the line's flux scattered into a Lorentzian halo"),
     Parameter("halo_hwhm_um", 40.0, 10.0, 150.0, floor=5.0, unit="µm", kinds=("line_profile",),
               meaning="half width at half maximum of the halo on the detector"),
     Parameter("tail_fraction", 0.0, -0.15, 0.15, floor=0.01, unit="1", kinds=("line_profile",),
               meaning="fraction of the flux trailed into a one-sided exponential tail (sign: towards +u or -u)"),
     Parameter("tail_decay_um", 20.0, 5.0, 60.0, floor=3.0, unit="µm", kinds=("line_profile",),
               meaning="decay length of the tail on the detector"),
     Parameter("blur_um", 0.0, 0.0, 15.0, floor=0.5, unit="µm", kinds=("line_profile",),
               meaning="standard deviation of a Gaussian blur on the detector (charge diffusion, MTF)"),
     Parameter("nonlinearity", 0.0, 0.0, 0.15, floor=0.01, unit="1", kinds=("line_profile",),
               meaning="fraction of the gain lost at the line's peak (detector non-linearity)")),
    description="what the detector side does to a line: a scattered-light halo, a one-sided detector tail, a blur "
                "and a non-linear response",
    detected=wings_profile)
