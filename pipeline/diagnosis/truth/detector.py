"""Detector effects of a measured super-sampled line profile (pure array functions).

A super-sampled profile is assembled from many detector columns in which the line falls
at different sub-pixel phases: each sample is one pixel's value at offset
``k * pixel + phase_j`` from the line centre. The pixel value is the pixel-integrated
profile (:func:`pixel_values`) coupled to its neighbours (:func:`coupled`), in counts
with Poisson and read noise, a background, correlated noise, and optionally the
background subtracted (negative noise) (:func:`measure_profile`).

A point-source image is sampled the way a microscope-relayed focal-plane image is dithered:
on a square lattice around a random sub-sample centre, in counts with Poisson and read
noise, a background and missing samples (:func:`measure_image`).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["coupling_kernel", "pixel_values", "coupled", "coupled_image", "correlated_noise", "subtract_background",
           "measure_profile", "measure_image", "image_reach_um", "box_along"]


def coupling_kernel(c: float) -> np.ndarray:
    """Inter-pixel coupling ``[c, 1 - 2c, c]`` (flux conserving), ``0 <= c < 1/3``."""
    if not (math.isfinite(c) and 0.0 <= c < 1.0 / 3.0):
        raise ValueError(f"coupling_kernel: c={c!r} must be in [0, 1/3)")
    return np.array([c, 1.0 - 2.0 * c, c])


def pixel_values(offset_um: np.ndarray, profile_um: np.ndarray, profile: np.ndarray,
                 centres_um: np.ndarray) -> np.ndarray:
    """Values of pixels centred at ``centres_um`` of a profile already integrated over the
    pixel (``profile`` on ``profile_um``; zero outside)."""
    return np.interp(centres_um, profile_um, profile, left=0.0, right=0.0)


def coupled(offset_um: np.ndarray, profile: np.ndarray, c: float, pixel_um: float) -> np.ndarray:
    """Pixel-integrated profile after inter-pixel coupling: ``(1-2c) P(u) + c P(u - pixel)
    + c P(u + pixel)`` on the same uniform grid (the pixel at ``u`` receives ``c`` of each
    neighbour's charge); zero beyond the grid."""
    k = coupling_kernel(c)
    left = np.interp(offset_um - pixel_um, offset_um, profile, left=0.0, right=0.0)
    right = np.interp(offset_um + pixel_um, offset_um, profile, left=0.0, right=0.0)
    return k[1] * profile + k[0] * left + k[2] * right


def coupled_image(image: np.ndarray, step_um: float, c: float, pixel_um: float) -> np.ndarray:
    """A pixel-integrated image (rows y, columns x, uniform ``step_um`` on both axes) after
    inter-pixel coupling to the four neighbours: ``(1 - 4c) I + c`` times the image one
    pixel away in each direction, by whole-sample shifts of the array (``pixel_um`` must be
    a whole number of steps; zero beyond the array). No interpolation, so it shares nothing
    with an image model that couples through its spline."""
    k = int(round(pixel_um / step_um))
    if not (k >= 1 and abs(k * step_um - pixel_um) <= 1e-6 * pixel_um):
        raise ValueError(f"coupled_image: pixel_um={pixel_um} must be a whole number >= 1 of step_um={step_um}")
    pad = np.pad(image, k)
    around = pad[k:-k, :-2 * k] + pad[k:-k, 2 * k:] + pad[:-2 * k, k:-k] + pad[2 * k:, k:-k]
    return (1.0 - 4.0 * c) * image + c * around


def correlated_noise(x_um: np.ndarray, sigma: float, length_um: float, rng: np.random.Generator) -> np.ndarray:
    """Gaussian-process noise at ``x_um`` with a squared-exponential covariance
    ``sigma^2 exp(-(dx / length_um)^2 / 2)``."""
    if not (length_um > 0 and sigma >= 0):
        raise ValueError(f"correlated_noise: length_um={length_um} must be > 0 and sigma={sigma} >= 0")
    if sigma == 0:
        return np.zeros(x_um.shape)
    d = x_um[:, None] - x_um[None, :]
    C = sigma**2 * np.exp(-0.5 * (d / length_um) ** 2) + 1e-10 * sigma**2 * np.eye(x_um.size)
    w, V = np.linalg.eigh(C)
    return V @ (np.sqrt(np.clip(w, 0.0, None)) * rng.normal(size=x_um.size))


def subtract_background(x_um: np.ndarray, y: np.ndarray, outer_fraction: float = 0.2) -> tuple[np.ndarray, float]:
    """``y`` minus the median of its samples in the outer ``outer_fraction`` of the
    offset range (as a reduction pipeline does); returns (subtracted, estimate)."""
    span = np.abs(x_um).max()
    outer = np.abs(x_um) >= (1.0 - outer_fraction) * span
    b = float(np.median(y[outer]))
    return y - b, b


def measure_profile(offset_um: np.ndarray, detected: np.ndarray, rng: np.random.Generator, *,
                    pixel_um: float = 18.0, n_pixels: int = 7, phases: tuple[int, int] = (6, 10),
                    max_centre_um: float = 5.0, coupling: tuple[float, float] = (0.01, 0.03),
                    peak_counts: tuple[float, float] = (5e3, 2e4), read_e: tuple[float, float] = (5.0, 20.0),
                    background_rel: tuple[float, float] = (0.01, 0.05), corr_rel: tuple[float, float] = (0.002, 0.006),
                    corr_len_um: tuple[float, float] = (6.0, 20.0), subtract_probability: float = 0.5,
                    distortion=None) -> tuple[np.ndarray, np.ndarray, dict]:
    """A measured super-sampled profile from a pixel-integrated unit-area ``detected``
    profile (on the uniform ``offset_um``).

    Pixels ``k = -n_pixels ... n_pixels``, each at 6-10 random sub-pixel phases; the line
    centred at a random offset within ±``max_centre_um``; inter-pixel coupling ``c``;
    counts (peak 5e3-2e4 e-, Poisson), read noise, background 1-5 % of the peak (Poisson),
    correlated noise; with probability ``subtract_probability`` the background is
    subtracted (negative samples). ``distortion(u, y) -> y`` acts on the coupled profile
    (out-of-library effects). Returns (offset_um, counts, info).
    """
    c = rng.uniform(*coupling)
    prof = coupled(offset_um, detected, c, pixel_um)
    if distortion is not None:
        prof = distortion(offset_um, prof)
    centre = rng.uniform(-max_centre_um, max_centre_um)
    x = []
    for k in range(-n_pixels, n_pixels + 1):
        x.extend(k * pixel_um + rng.uniform(-0.5, 0.5, rng.integers(phases[0], phases[1] + 1)) * pixel_um)
    x = np.sort(np.asarray(x))
    model = pixel_values(offset_um, offset_um, prof, x - centre)
    peak = rng.uniform(*peak_counts)
    scale = peak / detected.max()
    bg = rng.uniform(*background_rel) * peak
    signal = scale * model
    counts = rng.poisson(np.clip(signal + bg, 0.0, None)).astype(float)
    counts += rng.normal(0.0, rng.uniform(*read_e), x.size)
    corr_counts, corr_len = rng.uniform(*corr_rel) * peak, rng.uniform(*corr_len_um)
    counts += correlated_noise(x, corr_counts, corr_len, rng)
    subtracted = bool(rng.random() < subtract_probability)
    est = 0.0
    if subtracted:
        counts, est = subtract_background(x, counts)
    info = {"coupling": c, "centre_um": centre, "peak_counts": peak, "background_counts": bg,
            "background_subtracted": subtracted, "background_estimate": est,
            "correlated_noise_counts": corr_counts, "correlation_length_um": corr_len}
    return x, counts, info


def box_along(axis_um: np.ndarray, image: np.ndarray, width_um: float, axis: int) -> np.ndarray:
    """``image`` (2-D) convolved along ``axis`` with a ``width_um`` box by its transfer
    function, zero beyond the grid (padded by the box's width, so nothing wraps round)."""
    step = axis_um[1] - axis_um[0]
    pad = int(math.ceil(width_um / step)) + 1
    widths = [(0, 0), (0, 0)]
    widths[axis] = (pad, pad)
    padded = np.pad(image, widths)
    f = np.fft.rfftfreq(padded.shape[axis], d=step)
    shape = [1, 1]
    shape[axis] = f.size
    out = np.fft.irfft(np.fft.rfft(padded, axis=axis) * np.sinc(width_um * f).reshape(shape), n=padded.shape[axis],
                       axis=axis)
    return np.take(out, np.arange(pad, pad + image.shape[axis]), axis=axis)


def image_reach_um(pixel_um: float = 0.0, half_range_um: float = 30.0, max_centre_um: float = 5.0) -> float:
    """How far from the image's centre (µm, on both axes) :func:`measure_image` reads the
    image it is given: the lattice's half range, moved by the drawn centre, plus half the
    pixel it integrates over."""
    return half_range_um + max_centre_um + 0.5 * max(pixel_um, 0.0)


def measure_image(x_um: np.ndarray, y_um: np.ndarray, image: np.ndarray, rng: np.random.Generator, *,
                  step_um: float = 1.0, half_range_um: float = 30.0, pixel_um: float = 0.0,
                  max_centre_um: float = 5.0, peak_counts: tuple[float, float] = (5e3, 2e4),
                  read_e: tuple[float, float] = (5.0, 20.0), background_rel: tuple[float, float] = (0.01, 0.05),
                  dropout: float = 0.03) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
    """A measured point-source image from ``image`` (rows ``y_um``, columns ``x_um``, both
    uniform): integrated over a ``pixel_um`` square pixel if > 0 (0: a focal-plane image
    that resolves the core; the image must then reach ``pixel_um / 2`` beyond the lattice), sampled on a ``step_um`` lattice over ±``half_range_um``
    around a centre drawn within ±``max_centre_um`` on both axes (cubic interpolation of
    the image), in counts (peak 5e3-2e4 e-, Poisson) with read noise and a background of
    1-5 % of the peak (Poisson), a fraction ``dropout`` of the samples missing. Nothing is
    clipped: a sample can be negative. Returns (x_um, y_um, counts, info)."""
    from scipy.interpolate import RegularGridInterpolator

    if not (math.isfinite(step_um) and step_um > 0 and math.isfinite(half_range_um) and half_range_um >= step_um):
        raise ValueError(f"measure_image: step_um={step_um!r} must be > 0 and half_range_um={half_range_um!r} >= it")
    img = np.asarray(image, float)
    reach = image_reach_um(pixel_um, half_range_um, max_centre_um)
    extent = min(np.abs(x_um[[0, -1]]).min(), np.abs(y_um[[0, -1]]).min())
    if extent < reach:
        # a sample beyond the image would read zero where the true image has wings
        raise ValueError(f"measure_image: the image reaches ±{extent:.3g} µm; the lattice (half_range_um="
                         f"{half_range_um:g}) moved by up to max_centre_um={max_centre_um:g} and integrated over "
                         f"pixel_um={pixel_um:g} needs ±{reach:.3g} µm")
    if pixel_um > 0:
        img = box_along(y_um, box_along(x_um, img, pixel_um, 1), pixel_um, 0)
    lookup = RegularGridInterpolator((y_um, x_um), img, method="cubic", bounds_error=False, fill_value=0.0)
    g = np.arange(-half_range_um, half_range_um + 1e-9, step_um)
    X, Y = np.meshgrid(g, g)
    keep = rng.random(X.size) >= dropout
    x, y = X.ravel()[keep], Y.ravel()[keep]
    cx, cy = rng.uniform(-max_centre_um, max_centre_um, 2)
    model = lookup(np.column_stack([y - cy, x - cx]))
    peak = rng.uniform(*peak_counts)
    signal = peak / img.max() * model
    bg = rng.uniform(*background_rel) * peak
    counts = rng.poisson(np.clip(signal + bg, 0.0, None)).astype(float)
    counts += rng.normal(0.0, rng.uniform(*read_e), x.size)
    info = {"centre_um": (float(cx), float(cy)), "peak_counts": peak, "background_counts": bg}
    return x, y, counts, info
