"""Fraunhofer imaging of the spectrograph pupil: PSF, basic LSF, partially coherent LSF.

All functions are array -> array and take the pupil coordinates (mm, incident beam,
see :mod:`optics.pupil` for frames and signs). Detector coordinates are µm:
``offset_um = f_cam * angle``; along dispersion the incident-pupil frequencies are
scaled by the anamorphic factor ``cos(alpha)/cos(beta)``::

    offset_um = wavelength_um * camera_focal_mm * anamorphic * nu_xi      (nu_xi in 1/mm)

so an FFT of length ``n`` over a pupil step ``d`` mm gives a detector step
``wavelength_um * camera_focal_mm * anamorphic / (n d)`` µm and a detector period
``n`` times that. A forward FFT is used, so an OPD tilt ``+t xi`` lands at +offset.

Partially coherent (Abbe) line profile of a long, fully illuminated slit
------------------------------------------------------------------------
The slit (width ``w`` in the collimator focal plane) is lit by mutually incoherent
plane waves whose undiffracted light hits the pupil at source points ``s`` filling a
disc of radius ``NA_rel * R``. For one source the pupil field is
``P(xi, eta) T(xi - s_x) L(eta - s_y)`` with ``T(xi) = sinc(w xi / (lambda f_coll))``
the slit spectrum across and ``L`` the (much narrower) spectrum along the slit;
the detector intensity is the sum over sources of ``|FT{...}|^2``.

*Infinite-slit limit.* The slit image is 400 µm long vs a PSF of ~20 µm, i.e. the
slit is ~20 resolution elements long and the profile is read at its centre, ~10
elements from either end. ``L`` is then ~``lambda f_coll / l`` ≈ 1 mm wide in the
pupil, far narrower than any pupil structure (18–21 mm quilt, >= 11 mm illuminated
footprint, 110 mm aperture), so ``L -> delta(eta - s_y)``: each source lights one pupil
row ``eta = s_y`` and the detector field is, up to a phase linear in the along-slit
coordinate, the 1-D FT of ``P(xi, s_y) T(xi - s_x)``. The intensity does not depend on
the along-slit position (a uniform infinite slit is translation invariant), so the
Abbe sum becomes one batch of 1-D FFTs, one per coherent mode of each row's
illumination (:mod:`optics.slit_modes`: the sources' overlapping slit spectra hold far
fewer modes than sources). ``tests/test_imaging.py`` checks this against a literal 2-D
slit -> pupil -> detector computation with a finite slit, ``tests/test_slit_modes.py``
the modes against the sum over sources.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np
import scipy.fft as sfft

from optics.slit_modes import slit_modes

__all__ = [
    "Profile",
    "PSF",
    "detector_axis_um",
    "box_convolve",
    "box_convolve_bandlimited",
    "psf",
    "basic_lsf",
    "source_points",
    "partially_coherent_lsf",
    "detected_profile",
]


@dataclass(frozen=True)
class Profile:
    """A line profile on the detector.

    Parameters
    ----------
    offset_um : ndarray, shape (n,)
        Uniform, increasing detector coordinate along dispersion (µm).
    intensity : ndarray, shape (n,)
        Intensity (arbitrary unit unless ``normalised``).
    kind : str
        "basic", "partially_coherent", "detected", ...
    meta : dict
        Provenance (wavelength, grating, settings...).
    """

    offset_um: np.ndarray
    intensity: np.ndarray
    kind: str = ""
    meta: dict = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        x, y = np.asarray(self.offset_um, float), np.asarray(self.intensity, float)
        if x.ndim != 1 or x.shape != y.shape or x.size < 3:
            raise ValueError(f"Profile offset_um {x.shape} and intensity {y.shape} must be equal 1-D shapes (n >= 3)")
        object.__setattr__(self, "offset_um", x)
        object.__setattr__(self, "intensity", y)

    @property
    def step_um(self) -> float:
        return float(self.offset_um[1] - self.offset_um[0])

    def area(self) -> float:
        return float(np.sum(self.intensity) * self.step_um)

    def normalised(self) -> "Profile":
        """Copy with unit area (sum * step = 1)."""
        return Profile(self.offset_um, self.intensity / self.area(), self.kind, dict(self.meta))


@dataclass(frozen=True)
class PSF:
    """A 2-D point-spread function, intensity[y, x] with unit volume (sum * dx * dy = 1)."""

    offset_x_um: np.ndarray
    offset_y_um: np.ndarray
    intensity: np.ndarray
    meta: dict = field(default_factory=dict, compare=False)


def detector_axis_um(n: int, pupil_step_mm: float, wavelength_um: float, camera_focal_mm: float,
                     anamorphic: float = 1.0) -> np.ndarray:
    """Detector coordinates (µm) of an fftshifted length-``n`` FFT, 0 at index ``n // 2``."""
    du = wavelength_um * camera_focal_mm * anamorphic / (n * pupil_step_mm)
    return (np.arange(n) - n // 2) * du


def _intensity_fft(field: np.ndarray, n: int, axes, workers: int) -> np.ndarray:
    """|FFT|^2 zero-padded to ``n`` along ``axes``, fftshifted. The pupil's origin
    offset is a linear phase on the detector and drops out of the intensity."""
    spec = sfft.fftn(field, s=n, axes=axes, workers=workers)
    return np.fft.fftshift(spec.real**2 + spec.imag**2, axes=axes)


def _box_input(offset_um, intensity, width_um: float) -> tuple[np.ndarray, np.ndarray]:
    """``(offset_um, intensity)`` as float arrays, or ValueError for a negative box width."""
    if width_um < 0:
        raise ValueError(f"width_um={width_um} must be >= 0")
    return np.asarray(offset_um, float), np.asarray(intensity, float)


def box_convolve(offset_um: np.ndarray, intensity: np.ndarray, width_um: float) -> np.ndarray:
    """Running mean over a window ``width_um`` (exact for piecewise-linear data).

    ``out(u) = (1/w) * integral_{u-w/2}^{u+w/2} I``, from the cumulative trapezoid
    integral interpolated at ``u ± w/2``; zero outside the input range. ``width_um = 0``
    returns a copy.
    """
    x, y = _box_input(offset_um, intensity, width_um)
    if width_um == 0:
        return y.copy()
    c = np.concatenate([[0.0], np.cumsum(0.5 * (y[1:] + y[:-1]) * np.diff(x))])
    hi = np.interp(x + width_um / 2, x, c, left=0.0, right=c[-1])
    lo = np.interp(x - width_um / 2, x, c, left=0.0, right=c[-1])
    return (hi - lo) / width_um


def box_convolve_bandlimited(offset_um: np.ndarray, intensity: np.ndarray, width_um: float,
                             axis: int = -1) -> np.ndarray:
    """Running mean over a window ``width_um`` along ``axis`` of samples of a band-limited
    intensity on the uniform grid ``offset_um``: the spectrum times the box's transfer
    function ``sinc(width_um f)`` (the pixel MTF), zero outside the input range.

    Why beside :func:`box_convolve`: an image formed by an FFT is band-limited, and its
    samples determine it between them; the trapezoid rule integrates the straight lines
    between samples instead. For an 18 µm pixel over a J-band point image sampled every
    1.5 µm (the diagnosis's fitting grid, a ~4 µm diffraction core) the trapezoid is 0.53 %
    of the peak RMS (1.7 % at worst) from the converged image, this 0.08 % (0.31 %)
    (``tests/test_diagnosis_psf.py``; an analytic case: ``tests/test_imaging.py``)."""
    x, y = _box_input(offset_um, intensity, width_um)
    if width_um == 0:
        return y.copy()
    n = y.shape[axis]
    if x.size != n or n < 2:
        raise ValueError(f"offset_um has {x.size} samples; intensity has {n} along axis {axis} (need >= 2)")
    pad = n + int(np.ceil(width_um / (x[1] - x[0]))) + 1  # no wrap-around of the box
    f = np.fft.rfftfreq(n + pad, x[1] - x[0])
    shape = [1] * y.ndim
    shape[axis] = f.size
    out = np.fft.irfft(np.fft.rfft(y, n=n + pad, axis=axis) * np.sinc(width_um * f).reshape(shape), n=n + pad,
                       axis=axis)
    return np.take(out, np.arange(n), axis=axis)


def psf(field: np.ndarray, xi_mm: np.ndarray, eta_mm: np.ndarray, wavelength_um: float,
        camera_focal_mm: float, anamorphic: float = 1.0, n_fft: tuple[int, int] = (1024, 1024),
        window_um: float | None = None, workers: int = 2) -> PSF:
    """Point-source PSF: 2-D FFT of a pupil field.

    Parameters
    ----------
    field : complex ndarray, shape (n_eta, n_xi)
        Pupil field on the uniform grid ``eta_mm`` × ``xi_mm`` (mm).
    wavelength_um, camera_focal_mm : float
        Wavelength (µm) and camera focal length (mm).
    anamorphic : float
        ``cos(alpha)/cos(beta)``, scales the x axis (1 for a plain pupil).
    n_fft : (int, int)
        FFT size (n_y, n_x); must be >= the pupil size.
    window_um : float, optional
        Crop to |offset| <= window_um on both axes.

    Returns
    -------
    PSF with unit volume.
    """
    ny, nx = n_fft
    if ny < field.shape[0] or nx < field.shape[1]:
        raise ValueError(f"n_fft={n_fft} must be >= the pupil shape {field.shape}")
    img = _intensity_fft(field, (ny, nx), (0, 1), workers)
    ux = detector_axis_um(nx, xi_mm[1] - xi_mm[0], wavelength_um, camera_focal_mm, anamorphic)
    uy = detector_axis_um(ny, eta_mm[1] - eta_mm[0], wavelength_um, camera_focal_mm, 1.0)
    if window_um is not None:
        kx, ky = np.abs(ux) <= window_um, np.abs(uy) <= window_um
        img, ux, uy = img[np.ix_(ky, kx)], ux[kx], uy[ky]
    img = img / (img.sum() * (ux[1] - ux[0]) * (uy[1] - uy[0]))
    return PSF(ux, uy, img, {"wavelength_um": wavelength_um})


def basic_lsf(p: PSF, slit_width_um: float) -> Profile:
    """The paper's "basic LSF": PSF summed along the slit (y), then a rect of the
    geometric slit image width (µm; 0 = infinitely thin slit). Unit area."""
    dy = p.offset_y_um[1] - p.offset_y_um[0]
    line = p.intensity.sum(axis=0) * dy
    out = box_convolve(p.offset_x_um, line, slit_width_um)
    return Profile(p.offset_x_um, out, "basic", {**p.meta, "slit_width_um": slit_width_um}).normalised()


def source_points(radius_mm: float, step_mm: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Midpoint grid of an incoherent disc source in pupil coordinates.

    Returns ``s_x (n_x,)``, ``s_y (n_y,)`` (mm, symmetric about 0, cell-centred) and
    ``weights (n_y, n_x)`` = cell area fraction inside the disc (grey rim, so the sum
    converges smoothly with ``step_mm``).
    """
    if not radius_mm > 0 or not step_mm > 0:
        raise ValueError(f"radius_mm={radius_mm} and step_mm={step_mm} must be > 0")
    return _source_grid(float(radius_mm), float(step_mm))


@functools.lru_cache(maxsize=64)
def _source_grid(radius_mm: float, step_mm: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`source_points`, computed once per illumination and shared read-only: a fit asks
    for the same grid at every forward call (a profile per call, thousands per diagnosis)."""
    n = max(1, int(np.ceil(2 * radius_mm / step_mm)))
    s = (np.arange(n) - (n - 1) / 2) * step_mm
    r = np.hypot(s[None, :], s[:, None])
    w = np.clip(0.5 + (radius_mm - r) / step_mm, 0.0, 1.0)
    keep_y = w.any(axis=1)
    keep_x = w.any(axis=0)
    out = s[keep_x], s[keep_y], w[np.ix_(keep_y, keep_x)]
    for a in out:
        a.flags.writeable = False
    return out


def partially_coherent_lsf(rows: np.ndarray, xi_mm: np.ndarray, s_x_mm: np.ndarray, weights: np.ndarray,
                           wavelength_um: float, slit_width_coll_um: float, collimator_focal_mm: float,
                           camera_focal_mm: float, anamorphic: float = 1.0, n_fft: int = 512,
                           window_um: float | None = None, workers: int = 2, batch: int = 256) -> Profile:
    """LSF at the centre of a long, incoherently illuminated slit (Abbe sum, infinite-slit limit).

    Parameters
    ----------
    rows : complex ndarray, shape (n_rows, n_xi)
        Pupil field ``P(xi, s_y)`` on the source rows ``eta = s_y`` (see
        :func:`source_points`), on the uniform grid ``xi_mm``.
    s_x_mm : ndarray, shape (n_sx,)
        Source positions along xi (mm).
    weights : ndarray, shape (n_rows, n_sx)
        Source weights (0 = no source).
    slit_width_coll_um : float
        Slit width in the collimator focal plane (µm).
    collimator_focal_mm, camera_focal_mm, anamorphic : float
        Focal lengths (mm) and ``cos(alpha)/cos(beta)``.
    n_fft : int
        FFT length along xi (>= n_xi); sets the detector step.
    window_um : float, optional
        Crop to |offset| <= window_um.
    batch : int
        Mode fields per FFT call (memory bound).

    Returns
    -------
    Profile (kind "partially_coherent"), unit area.
    """
    rows = np.asarray(rows)
    if rows.shape[0] != weights.shape[0] or weights.shape[1] != np.size(s_x_mm):
        raise ValueError(f"weights {weights.shape} must be (n_rows={rows.shape[0]}, n_sx={np.size(s_x_mm)})")
    if n_fft < rows.shape[1]:
        raise ValueError(f"n_fft={n_fft} must be >= the pupil width {rows.shape[1]} samples")
    # Slit spectrum in the pupil: first zero at xi = lambda f_coll / w. The sources of one
    # pupil row add as that row's coherent modes (optics.slit_modes): the same sum, with far
    # fewer FFTs than sources.
    scale = (slit_width_coll_um * 1e-3) / (wavelength_um * 1e-3 * collimator_focal_mm)
    modes = slit_modes(xi_mm, s_x_mm, weights, scale)
    acc = np.zeros(n_fft)
    for a in range(0, modes.row.size, batch):
        f = rows[modes.row[a:a + batch]] * modes.field[a:a + batch]
        spec = sfft.fft(f, n=n_fft, axis=-1, workers=workers)
        acc += (spec.real**2 + spec.imag**2).sum(axis=0)
    acc = np.fft.fftshift(acc)
    u = detector_axis_um(n_fft, xi_mm[1] - xi_mm[0], wavelength_um, camera_focal_mm, anamorphic)
    if window_um is not None:
        k = np.abs(u) <= window_um
        u, acc = u[k], acc[k]
    return Profile(u, acc, "partially_coherent", {"wavelength_um": wavelength_um, "n_sources": modes.n_sources,
                                                  "n_modes": int(modes.row.size)}).normalised()


def detected_profile(p: Profile, pixel_um: float = 18.0) -> Profile:
    """Super-sampled detected profile: ``p`` convolved with the pixel (rect, µm), unit area."""
    out = box_convolve(p.offset_um, p.intensity, pixel_um)
    return Profile(p.offset_um, out, "detected", {**p.meta, "pixel_um": pixel_um}).normalised()
