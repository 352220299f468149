"""Forward model of a PSF image: a point source (a pinhole at the slit centre) imaged
through the spectrograph and one grating, integrated over the detector pixel.

Why a second kind of spectrograph measurement: a line profile is the image integrated
along the slit, and the blank and the pupil are mirror-symmetric in y (along the
rulings), so terms that are odd in y — the collimator's oblique astigmatism Z(2,-2),
the sign of a footprint shift along the rulings — reach a profile only through their
square (the marginal of ``|FT(P e^{i a xy})|^2`` along y is even in ``a``). On the
campaign's J-band profiles the oblique astigmatism is therefore known to ±0.04-0.11 µm
only, and six of its eleven collimator misses are that term
(``benchmarks/results_diagnosis.md``). A 2-D image sees these terms at first order
(an oblique astigmatism tilts the PSF's elongation; its sign is the tilt's sign).

Units: detector µm (x along the dispersion, y along the slit), intensity as a fraction
of the data's peak. Nuisances: the image position (dx, dy) µm — nonlinear, two fit
parameters like a profile's offset shift (an inner solve per residual evaluation was
measured 4x slower) — and a flux and a constant background (linear, projected out). An
image read by a detector (``pixel_um > 0``) also has its inter-pixel coupling: the fraction
``c`` of each pixel's signal read in each of its four neighbours, fitted in 0-5 % like a
profile's (linear in flux times ``c``, :func:`.forward.coupled_lstsq`) unless the manifest
states it. Held at 0, a 2 % coupling blurs the image by about 1 % of its peak (RMS), more
than its noise: a nominal image coupled 2 % with 0.5 % noise is then ``unexplained``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.interpolate import RectBivariateSpline

from optics.imaging import box_convolve_bandlimited
from optics.lineprofile import otf_cutoff_per_um, point_psf
from optics.sagmap import SagMap

from .forward import SpectrographImageModel, coupled_lstsq, spectrograph_optics
from .manifest import PsfImageData
from .nominal import DEFAULT_MATERIALS
from .noise import estimate_noise, estimate_noise_band_limited

__all__ = ["PsfImageSettings", "FIT_PSF_SETTINGS", "FIT_PSF_SETTINGS_FINE", "covering", "psf_image_model",
           "PsfImageForward"]


@dataclass(frozen=True)
class PsfImageSettings:
    """Sampling of the model image: FFT step (µm) and length, half window (µm)."""

    detector_step_um: float = 0.5
    n_fft: int = 1024
    window_um: float = 100.0

    def __post_init__(self) -> None:
        if not self.detector_step_um > 0 or not self.window_um > 0 or int(self.n_fft) != self.n_fft or self.n_fft < 64:
            raise ValueError(f"PsfImageSettings: detector_step_um={self.detector_step_um} (> 0), n_fft={self.n_fft} "
                             f"(integer >= 64), window_um={self.window_um} (> 0)")
        if self.window_um > 0.5 * self.n_fft * self.detector_step_um:
            raise ValueError(f"PsfImageSettings.window_um={self.window_um} exceeds half the detector period "
                             f"{0.5 * self.n_fft * self.detector_step_um} um")


#: Sampling while fitting a pixel-integrated image (1.5 µm over a 384 µm period: the
#: 18 µm pixel smooths the ~4 µm diffraction core).
FIT_PSF_SETTINGS = PsfImageSettings(detector_step_um=1.5, n_fft=256, window_um=90.0)
#: ... and an image that resolves the diffraction core (``pixel_um`` below 6 µm, e.g. a
#: microscope-relayed focal-plane image): 0.5 µm steps.
FIT_PSF_SETTINGS_FINE = PsfImageSettings(detector_step_um=0.5, n_fft=512, window_um=60.0)


#: How far the fit may move the image (µm) beyond the data's extent: the initial position
#: search spans ±20 µm (:meth:`PsfImageForward._initial_shift`).
_SHIFT_MARGIN_UM = 24.0


def covering(settings: PsfImageSettings, x_um: np.ndarray, y_um: np.ndarray,
             pixel_um: float = 0.0) -> PsfImageSettings:
    """``settings`` with a window that holds every sample of an image at ``x_um``, ``y_um``
    moved by up to :data:`_SHIFT_MARGIN_UM` and read a pixel away (the coupling's
    neighbours), the FFT lengthened (doubled) until its period holds the window.

    A sample beyond the model's window would be compared with the image spline's
    extrapolation: a focal-plane image of ±80 µm against the 60 µm window left 1.6 % of the
    peak in the residual of the nominal's own image and the fit took the quilt's harmonics
    along x 11 % low (0.888 on a noise-free image made by ``cryograting psf``).
    """
    half = float(max(np.max(np.abs(x_um)), np.max(np.abs(y_um)))) + _SHIFT_MARGIN_UM + float(pixel_um)
    if half <= settings.window_um:
        return settings
    n = settings.n_fft
    while 0.5 * n * settings.detector_step_um < half:
        n *= 2
    return replace(settings, n_fft=n, window_um=float(np.ceil(half)))


def psf_image_model(grating: str, wavelength_um: float, order: int, sag: SagMap | None, p: dict,
                    pixel_um: float = 18.0, settings: PsfImageSettings = PsfImageSettings()):
    """Pixel-integrated point-source image for effect parameters ``p``.

    Parameters
    ----------
    grating, wavelength_um, order
        As :func:`optics.lineprofile.point_psf`.
    sag : SagMap or None
        Grating sag (µm), already scaled and shaped (amplitude, temperature, gradient, bow).
    p : dict
        Effect parameters of the spectrograph (:func:`.forward.spectrograph_optics`;
        missing = null).
    pixel_um : float
        Detector pixel (µm) the image is integrated over on both axes (0: none).

    Returns
    -------
    x_um, y_um : ndarray
        Detector axes (µm; x dispersion, y along the slit).
    image : ndarray, shape (y, x)
        Unit-volume intensity before the pixel; after it, same normalisation.
    """
    o = spectrograph_optics(grating, p)
    ps = point_psf(o.grating, wavelength_um, sag, order=order, pupil_shift_mm=o.pupil_shift_mm,
                   collimator_zernike_um=o.collimator_zernike_um, detector_step_um=settings.detector_step_um,
                   n_fft=settings.n_fft, window_um=settings.window_um, workers=1)
    img = ps.intensity
    if pixel_um > 0:
        # the image is band-limited: its pixel integral is the pixel MTF's product with its
        # spectrum (the trapezoid rule was 0.53 % of the peak off at the fitting grid)
        img = box_convolve_bandlimited(ps.offset_y_um, box_convolve_bandlimited(ps.offset_x_um, img, pixel_um, 1),
                                       pixel_um, 0)
    return ps.offset_x_um, ps.offset_y_um, img


class PsfImageForward(SpectrographImageModel):
    """PSF-image model: ``flux * I(x - dx, y - dy; params) + background`` (module docstring)."""

    kind = "psf_image"
    #: nuisances solved inside :meth:`residual` (flux, background; and the coupling where it
    #: is fitted: 3) and position nuisances that are fit parameters (dx, dy: ``delta_um``)
    nuisance_count, n_shift = 2, 2

    def __init__(self, data: PsfImageData, nominal: SagMap, cold_K: float, warm_K: float = 293.0,
                 settings: PsfImageSettings | None = None, cache_size: int = 256,
                 materials: tuple[str, str] = DEFAULT_MATERIALS):
        m = data.measurement
        if settings is None:
            settings = covering(FIT_PSF_SETTINGS if m.pixel_um >= 6.0 else FIT_PSF_SETTINGS_FINE,
                                data.x_um, data.y_um, m.pixel_um)
        self._setup(m, nominal, cold_K, warm_K, settings, cache_size, materials)
        self.x, self.y = np.asarray(data.x_um, float), np.asarray(data.y_um, float)
        self.data = np.asarray(data.intensity, float)
        self.n = self.data.size
        #: the detector's inter-pixel coupling the manifest states (fraction to each of the
        #: four neighbours; None: fitted, or none for a focal-plane image) and the pixel pitch
        #: (µm) it acts over
        self.stated_coupling, self.pixel_um = m.interpixel_coupling, float(m.pixel_um)
        #: a detector's image fits its coupling unless the manifest states it; a focal-plane
        #: image (``pixel_um = 0``) has none
        self.fits_coupling = self.stated_coupling is None and self.pixel_um > 0
        if self.fits_coupling:
            self.nuisance_count = 3
        self.delta0_um = self._initial_shift()
        self.cutoff_per_um = otf_cutoff_per_um(m.grating, m.wavelength_um, m.order)

    def estimate_noise(self, nominal_residual: np.ndarray) -> float:
        """White-noise sigma (fraction of the data peak): the residual's power beyond the
        OTF cut-off where the image is sampled finely enough to have any
        (:func:`.noise.estimate_noise_band_limited`), else the cubic-prediction scatter
        along rows, which overestimates the noise of an image whose Airy rings are not
        smooth on the sample step (then give ``noise_rel`` in the manifest)."""
        sigma = estimate_noise_band_limited(self.x, self.y, nominal_residual, self.cutoff_per_um)
        return sigma if np.isfinite(sigma) else estimate_noise(self.x, self.data, rows=self.y)

    def image(self, p: dict) -> RectBivariateSpline:
        """Memoised cubic spline of the model image for the physical parameters."""
        def build(sag, p):
            ux, uy, img = psf_image_model(self.m.grating, self.m.wavelength_um, self.m.order, sag, p,
                                          self.m.pixel_um, self.settings)
            return RectBivariateSpline(uy, ux, img, kx=3, ky=3)

        return self._memo(p, build)

    def _views(self, spl, shift, sel):
        """(the image at the samples ``sel`` displaced by ``shift`` (dx, dy µm), the sum of the
        image one pixel away in each of the four directions, or None where no coupling acts)."""
        x, y = self.x[sel] - shift[0], self.y[sel] - shift[1]
        out = spl.ev(y, x)
        if not (self.stated_coupling or self.fits_coupling):
            return out, None
        p = self.pixel_um
        return out, spl.ev(y, x - p) + spl.ev(y, x + p) + spl.ev(y - p, x) + spl.ev(y + p, x)

    def _stated(self, image, around):
        """The image read through the stated coupling: ``(1 - 4c) I + c`` times the image one
        pixel away in each direction (what each dithered sample's pixel reads)."""
        c = self.stated_coupling
        return (1.0 - 4.0 * c) * image + c * around if c else image

    def _model(self, spl, shift, sel):
        """The image at the samples ``sel`` displaced by ``shift``, through the stated
        coupling where the manifest gives one (a fitted one is not applied: before flux,
        coupling and background)."""
        return self._stated(*self._views(spl, shift, sel))

    @staticmethod
    def _linear(model, d):
        A = np.column_stack([model, np.ones_like(model)])
        c, *_ = np.linalg.lstsq(A, d, rcond=None)
        return d - A @ c, c

    def _nuisances(self, spl, shift, mask):
        """(residual on ``mask``, the model at every sample, coupling) with flux, background
        and, unless stated, the coupling fitted on ``mask``."""
        sel = slice(None) if mask is None else mask
        image, around = self._views(spl, shift, slice(None))
        if self.fits_coupling:
            neighbours = around - 4.0 * image
            r, flux, c, bg = coupled_lstsq(image[sel], neighbours[sel], self.data[sel])
            return r, flux * (image + c * neighbours) + bg, c
        model = self._stated(image, around)
        r, (flux, bg) = self._linear(model[sel], self.data[sel])
        return r, flux * model + bg, float(self.stated_coupling or 0.0)

    def residual(self, p: dict, delta_um=None, mask: np.ndarray | None = None) -> np.ndarray:
        """Data minus model at position ``delta_um`` = (dx, dy) µm (None: the nominal's)
        with flux, background and coupling fitted on ``mask`` (fraction of the data peak)."""
        return self._nuisances(self.image(p), self.delta0_um if delta_um is None else delta_um, mask)[0]

    def fitted(self, p: dict, delta_um=None, mask: np.ndarray | None = None) -> np.ndarray:
        """Full model (position ``delta_um``, fitted flux, coupling and background) at all samples."""
        return self._nuisances(self.image(p), self.delta0_um if delta_um is None else delta_um, mask)[1]

    def coupling(self, p: dict, delta_um=None, mask: np.ndarray | None = None) -> float:
        """The inter-pixel coupling (fraction to each of the four neighbours) fitted with the
        model of parameters ``p`` at position ``delta_um`` (the stated one where given, 0 for
        a focal-plane image)."""
        return self._nuisances(self.image(p), self.delta0_um if delta_um is None else delta_um, mask)[2]

    def predict(self, p: dict, delta_um=None) -> np.ndarray:
        """Model image at the samples at position ``delta_um`` (before flux/background)."""
        return self._model(self.image(p), self.delta0_um if delta_um is None else delta_um, slice(None))

    def _initial_shift(self) -> np.ndarray:
        """Position of the nominal model by a 2-µm grid search over ±20 µm (the fit's basin
        is about the PSF core's half width)."""
        spl = self.image({})
        g = np.arange(-20.0, 20.5, 2.0)
        best = min(((float(np.sum(self._nuisances(spl, (a, b), None)[0] ** 2)), a, b) for a in g for b in g))
        return (float(best[1]), float(best[2]))
