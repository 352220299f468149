"""Synthetic measurements (scenarios and the injection-recovery campaign).

A synthetic measurement is what an instrument would deliver from a *truth* that is a
different model from the one diagnosed: the truth map comes from another FEA mesh
(and/or case) with a small smooth shape discrepancy (:func:`unmodelled_shape`, which no
library effect describes, or :func:`shape_discrepancy`, the library's companions
bow and plating gradient); it is sampled on the
measurement's own grid, with piston/tilt (maps) or an offset shift, flux scale and
background (profiles), an image position, flux and background (PSF images), white
noise, dropouts and sparse sampling.
"""

from __future__ import annotations

import math

import numpy as np

from optics.lineprofile import LsfSettings
from optics.sagmap import SagMap
from optics.zernike import zernike_xy

from .effects import SHAPE_STAGES, forward_effects
from .forward import blank_shape_um, profile_curve, quilt_parts
from .quilt import quilt_components

__all__ = ["blank_shape_map", "quilt_shape_map", "shape_discrepancy", "unmodelled_shape", "FOIL_TERMS", "synthetic_surface", "synthetic_profile", "synthetic_psf_image"]


def quilt_shape_map(sag: SagMap, fund_xy_ratio: float = 1.0, harmonics_ratio: float = 1.0,
                    cross_ratio: float = 1.0, x_harmonics_ratio: float = 1.0) -> SagMap:
    """``sag`` with its own quilt reshaped (the ``quilt_shape`` effect, :mod:`.quilt`): the y
    fundamental times ``fund_xy_ratio`` (x held), the (1, ±1) cross terms times
    ``cross_ratio``, the harmonics along x ((2, 0), (3, 0)) times ``x_harmonics_ratio`` and
    the other harmonics times ``harmonics_ratio``, decomposed from ``sag`` itself (a truth
    map from another mesh has its own harmonic content)."""
    for name, v in (("fund_xy_ratio", fund_xy_ratio), ("harmonics_ratio", harmonics_ratio),
                    ("cross_ratio", cross_ratio), ("x_harmonics_ratio", x_harmonics_ratio)):
        if not math.isfinite(v):
            raise ValueError(f"quilt_shape_map: {name}={v} must be finite")
    q = quilt_components(sag)
    if q is None:
        raise ValueError(f"quilt_shape_map: map {sag.label!r} does not cover the 82 x 72 mm centre the quilt is fitted on")
    p = {"quilt_fund_xy_ratio": fund_xy_ratio, "quilt_harmonics_ratio": harmonics_ratio, "quilt_cross_ratio": cross_ratio,
         "quilt_x_harmonics_ratio": x_harmonics_ratio}
    return blank_shape_map(sag, p, q)


def blank_shape_map(sag: SagMap, p: dict, quilt=None) -> SagMap:
    """``sag`` changed by the blank-shape effects (``Effect.shape``) of the parameters ``p``
    (:func:`~pipeline.diagnosis.forward.blank_shape_um`); a "reshape"-stage effect's parts
    are decomposed from ``sag`` itself (``quilt``: :func:`~pipeline.diagnosis.quilt.quilt_components`
    of it, if already made). ``sag`` itself where ``p`` holds no parameter of such an effect."""
    def names(stages):
        return {q.name for e in forward_effects() if e.shape is not None and e.shape_stage in stages
                for q in e.parameters}

    if not names(SHAPE_STAGES) & set(p):
        return sag
    X, Y = sag.grid()
    if quilt is None and names(("reshape",)) & set(p):
        quilt = quilt_components(sag)
    return sag.with_sag(blank_shape_um(sag.sag_um, X, Y, p, quilt_parts(quilt, X, Y)), label=f"{sag.label} + blank shape")


def shape_discrepancy(sag: SagMap, rng: np.random.Generator, gradient: float = 0.03, bow_um: float = 0.01) -> SagMap:
    """``sag`` times a random linear amplitude gradient (±``gradient`` across ±70 mm:
    plating thickness varies over the blank) plus a random low-order bow of RMS
    ~``bow_um`` (Zernike (2,0) and (4,0) over an 80 mm disc). Both are in the effect
    library as companions (``plating_gradient``, ``blank_bow``, over a 70 mm disc), so
    wherever the data resolve them they are found, not left as unmodelled mismatch: on
    line profiles alone they are below what the data identify; a map or a focal-plane
    PSF image sees the bow at delta BIC -200 … -500."""
    X, Y = sag.grid()
    ang = rng.uniform(0, 2 * np.pi)
    g = gradient * rng.uniform(0.5, 1.0)
    factor = 1.0 + g * (np.cos(ang) * X + np.sin(ang) * Y) / 70.0
    bow = bow_um * (rng.normal() * zernike_xy(2, 0, X, Y, 80.0) + rng.normal() * zernike_xy(4, 0, X, Y, 80.0))
    return sag.with_sag(sag.sag_um * factor + bow, label=f"{sag.label} + discrepancy")


#: Zernike terms of :func:`unmodelled_shape`: trefoil, tetrafoil, pentafoil. Their
#: azimuthal orders (3-5) are orthogonal on any centred disc to every surface term of the
#: library (piston, tilt, bow and the registration's rigid motion: m = 0, 1; astigmatism:
#: m = 2), and the odd ones to anything with the blank's mirror symmetries (the nominal
#: deformation, hence amplitude_scale and temperature).
FOIL_TERMS = ((3, 3), (3, -3), (4, 4), (4, -4), (5, 5), (5, -5))


def unmodelled_shape(sag: SagMap, rng: np.random.Generator, rms_um: float = 0.01,
                     radius_mm: float = 68.5) -> SagMap:
    """``sag`` plus a random smooth surface error that no library effect describes: the
    :data:`FOIL_TERMS` with independent normal coefficients, so that its mean-square over
    the ``radius_mm`` disc is ``rms_um**2`` (µm). Stands for the part of the model
    discrepancy a diagnosis must tolerate, not explain (the campaign's default); the
    bow and plating gradient of :func:`shape_discrepancy` are library companions, and
    a diagnosis that finds them is right, not fooled."""
    if not (math.isfinite(rms_um) and rms_um >= 0.0):
        raise ValueError(f"unmodelled_shape: rms_um={rms_um} must be a finite number >= 0 µm")
    if not (math.isfinite(radius_mm) and radius_mm > 0.0):
        raise ValueError(f"unmodelled_shape: radius_mm={radius_mm} must be a finite number > 0 mm")
    X, Y = sag.grid()
    c = rng.normal(size=len(FOIL_TERMS)) * rms_um / np.sqrt(len(FOIL_TERMS))
    extra = sum(ci * zernike_xy(n, m, X, Y, radius_mm) for ci, (n, m) in zip(c, FOIL_TERMS))
    return sag.with_sag(sag.sag_um + extra, label=f"{sag.label} + unmodelled shape")


def synthetic_surface(truth: SagMap, rng: np.random.Generator, *, aperture_diameter_mm: float = 137.0,
                      spacing_mm: float = 1.0, noise_um: float = 0.01, dropout: float = 0.03,
                      extra_um: np.ndarray | None = None, label: str = "synthetic map") -> SagMap:
    """Measured map on a ``spacing_mm`` grid over the aperture (NaN outside / dropouts).

    ``truth`` is the cold-minus-warm deformation at the measurement temperature;
    ``extra_um(X, Y)`` (callable) adds e.g. an injected astigmatism. A random piston
    (±0.5 µm) and tilt (±2 µrad) stand for the interferometer alignment.
    """
    half = 0.5 * aperture_diameter_mm
    ax = np.arange(-np.floor(half / spacing_mm), np.floor(half / spacing_mm) + 1) * spacing_mm
    X, Y = np.meshgrid(ax, ax)
    s = truth.sample(X, Y)
    if extra_um is not None:
        s = s + extra_um(X, Y)
    s = s + rng.uniform(-0.5, 0.5) + rng.uniform(-2e-3, 2e-3) * X + rng.uniform(-2e-3, 2e-3) * Y
    s = s + rng.normal(0.0, noise_um, s.shape)
    s[(X**2 + Y**2 > half**2) | (rng.random(s.shape) < dropout)] = np.nan
    return SagMap(ax, ax, s, label)


def synthetic_profile(grating: str, wavelength_um: float, order: int, pixel_scale_mas: int, truth: SagMap,
                      rng: np.random.Generator, *, params: dict | None = None, slit_position: float = 0.0,
                      noise_rel: float = 0.01, n_samples: int = 160, half_range_um: float = 120.0,
                      max_shift_um: float = 5.0, background: float = 0.03,
                      distortion=None, settings: LsfSettings = LsfSettings()) -> tuple[np.ndarray, np.ndarray, dict]:
    """A measured line profile: sparse random offsets, shifted, scaled, background, noise.

    ``params`` are effect parameters for the truth (pupil shift, collimator WFE, slit
    width; see :func:`~pipeline.diagnosis.forward.profile_curve`); ``truth`` is already
    scaled. ``distortion(u, y) -> y`` (callable) applies an out-of-library change.
    Computed with the default (converged) LSF settings — a different discretisation
    from the one the diagnosis fits with. Returns (offset_um, intensity, truth info).
    """
    u, y = profile_curve(grating, wavelength_um, order, pixel_scale_mas, truth, params or {}, slit_position, settings)
    if distortion is not None:
        y = distortion(u, y)
    shift = rng.uniform(-max_shift_um, max_shift_um)
    flux = 10 ** rng.uniform(2, 4)
    grid = np.arange(-half_range_um, half_range_um + 0.01, 0.5)
    x = np.sort(rng.choice(grid, size=n_samples, replace=False))
    model = np.interp(x - shift, u, y, left=0.0, right=0.0)
    peak = float(y.max())
    meas = flux * (model + background * peak + rng.normal(0.0, noise_rel * peak, x.size))
    return x, np.clip(meas, 0.0, None), {"shift_um": shift, "flux": flux}


def synthetic_psf_image(grating: str, wavelength_um: float, order: int, truth: SagMap, rng: np.random.Generator, *,
                        params: dict | None = None, noise_rel: float = 0.01, half_range_um: float = 40.0,
                        step_um: float = 2.0, max_shift_um: float = 5.0, background: float = 0.03,
                        pixel_um: float = 18.0, dropout: float = 0.03) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
    """A measured point-source image: a dithered image of the pixel-integrated PSF on a
    ``step_um`` lattice over ±``half_range_um`` (x dispersion, y along the slit), shifted,
    scaled, with background, white noise (fraction ``noise_rel`` of the peak) and a
    fraction ``dropout`` of missing samples (bad pixels).

    Computed with the default (finer) :class:`~pipeline.diagnosis.psf_image.PsfImageSettings`,
    not the fit's. ``params``: pupil shift and collimator WFE of the truth. Returns
    (x_um, y_um, intensity, truth info).
    """
    from scipy.interpolate import RectBivariateSpline

    from .psf_image import psf_image_model

    ux, uy, img = psf_image_model(grating, wavelength_um, order, truth, params or {}, pixel_um)
    spl = RectBivariateSpline(uy, ux, img)
    g = np.arange(-half_range_um, half_range_um + 1e-9, step_um)
    X, Y = np.meshgrid(g, g)
    keep = rng.random(X.size) >= dropout
    x, y = X.ravel()[keep], Y.ravel()[keep]
    sx, sy = rng.uniform(-max_shift_um, max_shift_um, 2)
    flux = 10 ** rng.uniform(2, 4)
    model = spl.ev(y - sy, x - sx)
    peak = float(img.max())
    meas = flux * (model + background * peak + rng.normal(0.0, noise_rel * peak, x.size))
    return x, y, np.clip(meas, 0.0, None), {"shift_um": (float(sx), float(sy)), "flux": flux}
