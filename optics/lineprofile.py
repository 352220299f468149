"""One-call SPIFFI line profiles and PSFs: grating + wavelength + pixel scale + sag map.

:func:`line_profile` and :func:`point_psf` are the public entry points used by the
``cryograting lsf`` / ``psf`` subcommands; they only assemble the pure functions of
:mod:`optics.pupil` and :mod:`optics.imaging`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from optics.grating import SPIFFI, Grating, PixelScale, Spectrograph, get_grating, get_pixel_scale
from optics.imaging import (PSF, Profile, detected_profile, partially_coherent_lsf, psf,
                            source_points)
from optics.pupil import (DEFAULT_COLLIMATOR_ZERNIKE_UM, centred_axis, circular_aperture,
                          collimator_opd_um, footprint_on_grating, grating_opd_um, pupil_field,
                          pupil_shift_along_slit)
from optics.sagmap import SagMap

__all__ = ["LsfSettings", "LineProfileResult", "line_profile", "line_profile_footprint_mm", "otf_cutoff_per_um",
           "point_psf", "pupil_rows"]


@dataclass(frozen=True)
class LsfSettings:
    """Numerical settings of :func:`line_profile` (defaults: <= 0.5 % L1 from converged,
    see ``benchmarks/results_lsf.md``).

    Parameters
    ----------
    detector_step_um : float
        Detector sampling of the FFT (µm).
    n_fft : int
        FFT length; the detector period is ``n_fft * detector_step_um`` and fixes the
        pupil step ``lambda f_cam anamorphic / period`` (anti-aliasing of the profile).
    source_step_mm : float
        Spacing of the incoherent source points in the pupil (mm); capped at
        ``source_radius / min_source_rows`` for small NA.
    min_source_rows : int
        Minimum number of source rows across the source radius.
    window_um : float
        Half width of the returned profile (µm).
    workers : int
        scipy.fft worker threads.
    """

    detector_step_um: float = 1.0
    n_fft: int = 512
    source_step_mm: float = 1.25
    min_source_rows: int = 8
    window_um: float = 200.0
    workers: int = 2

    def __post_init__(self) -> None:
        for name in ("detector_step_um", "source_step_mm", "window_um"):
            if not getattr(self, name) > 0:
                raise ValueError(f"LsfSettings.{name}={getattr(self, name)!r} must be > 0")
        if int(self.n_fft) != self.n_fft or self.n_fft < 64:
            raise ValueError(f"LsfSettings.n_fft={self.n_fft!r} must be an integer >= 64")
        if self.min_source_rows < 1 or self.workers < 1:
            raise ValueError("LsfSettings.min_source_rows and workers must be >= 1")
        if self.window_um > 0.5 * self.n_fft * self.detector_step_um:
            raise ValueError(
                f"LsfSettings.window_um={self.window_um} exceeds half the detector period "
                f"{0.5 * self.n_fft * self.detector_step_um} um (n_fft * detector_step_um / 2)"
            )


@dataclass(frozen=True)
class LineProfileResult:
    """Output of :func:`line_profile`: the detected profile, the profile before the
    pixel, and the numbers needed to interpret them (``info``)."""

    detected: Profile
    partially_coherent: Profile
    info: dict = field(default_factory=dict)


def _geometry(grating, wavelength_um, order, spectrograph):
    g = get_grating(grating)
    m = g.order if order is None else int(order)
    g.check_in_domain(wavelength_um, m)  # also refuses evanescent orders
    beta = float(g.beta_deg(wavelength_um, m))
    anam = float(g.anamorphic_factor(wavelength_um, m))
    return g, m, beta, anam


def otf_cutoff_per_um(grating: str | Grating, wavelength_um: float, order: int | None = None,
                      spectrograph: Spectrograph = SPIFFI) -> tuple[float, float]:
    """Incoherent cut-off frequencies (cycles/µm on the detector) along x and y.

    The OTF is the autocorrelation of the circular pupil of diameter D, and a pupil
    separation ``d_xi`` maps to ``d_xi / (wavelength f_cam anamorphic)`` on the detector
    x axis (``d_eta / (wavelength f_cam)`` on y), so the image of a point source has no
    power outside the ellipse with these semi-axes, whatever the aberrations, pupil
    shift or pixel integration (they only multiply the OTF).

    Returns
    -------
    (fx, fy) : float
        ``D / (wavelength f_cam anamorphic)`` and ``D / (wavelength f_cam)`` in 1/µm.
    """
    g, m, _, anam = _geometry(grating, wavelength_um, order, spectrograph)
    lam_f_um2 = wavelength_um * spectrograph.camera_focal_mm * 1e3  # µm * µm
    d_um = spectrograph.pupil_diameter_mm * 1e3
    return float(d_um / (lam_f_um2 * anam)), float(d_um / lam_f_um2)


def pupil_rows(grating: Grating, wavelength_um: float, xi_mm: np.ndarray, eta_mm: np.ndarray, beta_deg: float,
               sag: SagMap | None, shift_mm: tuple[float, float], collimator_zernike_um: dict | None,
               spectrograph: Spectrograph = SPIFFI, rim_step_mm: float | None = None) -> np.ndarray:
    """Complex pupil field on ``eta_mm`` × ``xi_mm``: aperture, grating OPD, collimator OPD."""
    R = 0.5 * spectrograph.pupil_diameter_mm
    amp = circular_aperture(xi_mm, eta_mm, spectrograph.pupil_diameter_mm, rim_step_mm)
    opd = collimator_opd_um(xi_mm, eta_mm, collimator_zernike_um, R)
    if sag is not None:
        opd = opd + grating_opd_um(sag, xi_mm, eta_mm, grating.incidence_deg, beta_deg, shift_mm, amp)
    return pupil_field(amp, opd, wavelength_um)


def _pupil_sampling(grating, wavelength_um, pixel_scale_mas, order, pupil_shift_mm, torsion_shift_x_mm,
                    slit_position, spectrograph, settings):
    """What :func:`line_profile` and :func:`line_profile_footprint_mm` share: the geometry
    ``(g, m, beta, anam)``, the pixel scale, the pupil shift at ``slit_position``, the pupil
    step and axis ``d_xi``, ``xi`` and the source points ``sx, sy, w``."""
    g, m, beta, anam = _geometry(grating, wavelength_um, order, spectrograph)
    ps = get_pixel_scale(pixel_scale_mas)
    shift = pupil_shift_along_slit(slit_position, tuple(pupil_shift_mm), torsion_shift_x_mm)
    s = settings
    R = 0.5 * spectrograph.pupil_diameter_mm
    # Pupil step chosen so the FFT lands exactly on detector_step_um for every wavelength.
    d_xi = wavelength_um * spectrograph.camera_focal_mm * anam / (s.n_fft * s.detector_step_um)
    xi = centred_axis(d_xi, R)
    if xi.size > s.n_fft:
        raise ValueError(f"LsfSettings.n_fft={s.n_fft} is smaller than the {xi.size} pupil samples at "
                         f"wavelength_um={wavelength_um:g}; a larger LsfSettings.n_fft (API) is needed")
    r_src = ps.relative_na * R
    sx, sy, w = source_points(r_src, min(s.source_step_mm, r_src / s.min_source_rows))
    return g, m, beta, anam, ps, shift, d_xi, xi, sx, sy, w


def line_profile_footprint_mm(grating: str | Grating, wavelength_um: float,
                              pixel_scale_mas: int | str | PixelScale, *, order: int | None = None,
                              pupil_shift_mm: tuple[float, float] = (0.0, 0.0), torsion_shift_x_mm: float = 0.0,
                              slit_position: float = 0.0, spectrograph: Spectrograph = SPIFFI,
                              settings: LsfSettings = LsfSettings()) -> tuple[float, float, float, float]:
    """The rectangle of the grating (mm, the sag map's frame) that holds every point at
    which :func:`line_profile` with the same arguments samples the sag map.

    A caller that deforms a large map for each profile can deform only this part of it
    (plus the bilinear stencil's neighbours): the profile reads nothing else.

    Returns
    -------
    (x_min_mm, x_max_mm, y_min_mm, y_max_mm) : float
        Extent of the footprint of the pupil axis ``xi`` over the source rows.
    """
    g, _, _, _, _, shift, _, xi, _, sy, _ = _pupil_sampling(
        grating, wavelength_um, pixel_scale_mas, order, pupil_shift_mm, torsion_shift_x_mm, slit_position,
        spectrograph, settings)
    xg, yg = footprint_on_grating(xi, sy, g.incidence_deg, shift)
    return float(xg.min()), float(xg.max()), float(yg.min()), float(yg.max())


def line_profile(grating: str | Grating, wavelength_um: float, pixel_scale_mas: int | str | PixelScale,
                 sag: SagMap | None = None, *, order: int | None = None,
                 pupil_shift_mm: tuple[float, float] = (0.0, 0.0), torsion_shift_x_mm: float = 0.0,
                 slit_position: float = 0.0,
                 collimator_zernike_um: dict | None = DEFAULT_COLLIMATOR_ZERNIKE_UM,
                 spectrograph: Spectrograph = SPIFFI, settings: LsfSettings = LsfSettings()) -> LineProfileResult:
    """Detected spectral line profile of a fully illuminated SPIFFI slit (paper §4.3).

    Parameters
    ----------
    grating : str or Grating
        "J", "H", "K", "HK" (see :data:`optics.grating.GRATINGS`).
    wavelength_um : float
        Line wavelength (µm).
    pixel_scale_mas : int, str or PixelScale
        25, 100 or 250 (relative illumination NA 0.1, 0.4, 1.0).
    sag : SagMap, optional
        Grating sag map (µm along +z, mm, grating frame); None = perfect grating.
    order : int, optional
        Diffraction order (default: the grating's blaze order).
    pupil_shift_mm : (float, float)
        Footprint shift on the grating (x, y) in mm at the slit centre.
    torsion_shift_x_mm, slit_position : float
        Slicer torsion: extra x shift ``torsion_shift_x_mm * slit_position`` with
        ``slit_position`` in [-1, 1] along the slitlet.
    collimator_zernike_um : dict {(n, m): µm} or None
        RMS-normalised Zernike OPD of the collimator over the 110 mm pupil; None or
        {} disables it. Default :data:`optics.pupil.DEFAULT_COLLIMATOR_ZERNIKE_UM`.
    settings : LsfSettings
        Numerical sampling.

    Returns
    -------
    LineProfileResult
        ``detected`` (pixel-convolved, unit area) and ``partially_coherent`` profiles
        on ``offset_um`` (µm, +x_g direction, see :mod:`optics.pupil`), and ``info``
        with wavelength_um, order, beta_deg, anamorphic, linear_dispersion_um_per_nm,
        slit_image_width_um, pixel_um, pixel_scale_mas, relative_na, pupil_shift_mm.
    """
    g, m, beta, anam, ps, shift, d_xi, xi, sx, sy, w = _pupil_sampling(
        grating, wavelength_um, pixel_scale_mas, order, pupil_shift_mm, torsion_shift_x_mm, slit_position,
        spectrograph, settings)
    s = settings
    f_cam, f_coll = spectrograph.camera_focal_mm, spectrograph.collimator_focal_mm
    rows = pupil_rows(g, wavelength_um, xi, sy, beta, sag, shift, collimator_zernike_um, spectrograph, d_xi)
    w_coll = g.slit_width_collimator_um(spectrograph)
    pc = partially_coherent_lsf(rows, xi, sx, w, wavelength_um, w_coll, f_coll, f_cam, anam, s.n_fft,
                                s.window_um, s.workers)
    info = {
        "grating": g.name, "wavelength_um": float(wavelength_um), "order": m, "beta_deg": beta,
        "anamorphic": anam, "linear_dispersion_um_per_nm": float(g.linear_dispersion_um_per_nm(wavelength_um, m, f_cam)),
        "slit_image_width_um": g.slit_image_width_at_um(wavelength_um, m, spectrograph),
        "slit_width_collimator_um": w_coll, "pixel_um": spectrograph.pixel_um, "pixel_scale_mas": ps.mas,
        "relative_na": ps.relative_na, "pupil_shift_mm": shift, "n_sources": pc.meta["n_sources"],
        "pupil_step_mm": d_xi, "sag": None if sag is None else sag.label,
        "collimator_zernike_um": {f"{k[0]},{k[1]}": v for k, v in (collimator_zernike_um or {}).items()},
    }
    pc = Profile(pc.offset_um, pc.intensity, pc.kind, {**pc.meta, **info})
    det = detected_profile(pc, spectrograph.pixel_um)
    return LineProfileResult(det, pc, info)


def _check_psf_sampling(airy_um: float, detector_step_um: float, window_um: float | None, n_fft: int) -> None:
    """Refuse a PSF sampling that the ``n_fft`` FFT cannot deliver, instead of cropping or
    aliasing silently.

    ``airy_um`` is ``lambda f_cam / D`` on the finer detector axis (µm). The pupil fits in
    the FFT only if ``detector_step_um <= airy_um`` (Nyquist for the field); the image
    spans ``n_fft * detector_step_um``, so ``window_um`` (the half width asked for) must
    be at most half of that, and at least two ``airy_um`` so the image holds the core.
    """
    for name, v in (("detector_step_um", detector_step_um), ("window_um", window_um)):
        if v is None and name == "window_um":
            continue
        if not (isinstance(v, (int, float, np.floating, np.integer)) and np.isfinite(v) and v > 0):
            raise ValueError(f"{name}={v!r} must be a finite number > 0 (µm)")
    if not (isinstance(n_fft, (int, np.integer)) and n_fft >= 64):
        raise ValueError(f"n_fft={n_fft!r} must be an integer >= 64")
    if detector_step_um > airy_um:
        raise ValueError(f"detector_step_um={detector_step_um:g} is coarser than the PSF's Nyquist step "
                         f"lambda f_cam / D = {airy_um:.3g} um; valid: 0 < detector_step_um <= {airy_um:.3g}")
    lo, hi = 2 * airy_um, 0.5 * n_fft * detector_step_um
    if hi < lo:
        raise ValueError(f"detector_step_um={detector_step_um:g} is so fine that an {n_fft}-point image spans "
                         f"only +-{hi:.3g} um, less than the PSF core; valid: {2 * lo / n_fft:.3g} <= "
                         f"detector_step_um <= {airy_um:.3g}")
    if window_um is not None and not lo <= window_um <= hi:
        raise ValueError(
            f"window_um={window_um:g} is outside {lo:.3g}..{hi:.3g} um: with detector_step_um="
            f"{detector_step_um:g} an {n_fft}-point image spans +-{hi:.3g} um, and the window must hold "
            f"the PSF core (2 lambda f_cam / D); change detector_step_um or window_um")


def point_psf(grating: str | Grating, wavelength_um: float, sag: SagMap | None = None, *,
              order: int | None = None, pupil_shift_mm: tuple[float, float] = (0.0, 0.0),
              collimator_zernike_um: dict | None = DEFAULT_COLLIMATOR_ZERNIKE_UM,
              spectrograph: Spectrograph = SPIFFI, detector_step_um: float = 0.5, n_fft: int = 1024,
              window_um: float | None = 150.0, workers: int = 2) -> PSF:
    """Point-source PSF (full 110 mm pupil) on the detector, intensity[y, x], unit volume.

    ``window_um`` is the half width (µm) of the image returned, at most half the FFT
    field ``n_fft * detector_step_um``; None returns the whole (periodic) FFT field.

    The pupil steps are chosen so the PSF is sampled at ``detector_step_um`` on both
    axes with an ``n_fft`` × ``n_fft`` FFT. ``offset_x_um`` is along dispersion
    (+x_g), ``offset_y_um`` along the slit (+y_g). Other parameters as :func:`line_profile`.
    """
    g, m, beta, anam = _geometry(grating, wavelength_um, order, spectrograph)
    R = 0.5 * spectrograph.pupil_diameter_mm
    f_cam = spectrograph.camera_focal_mm
    _check_psf_sampling(wavelength_um * f_cam * min(anam, 1.0) / (2 * R), detector_step_um, window_um, n_fft)
    d_xi = wavelength_um * f_cam * anam / (n_fft * detector_step_um)
    d_eta = wavelength_um * f_cam / (n_fft * detector_step_um)
    xi, eta = centred_axis(d_xi, R), centred_axis(d_eta, R)
    field2d = pupil_rows(g, wavelength_um, xi, eta, beta, sag, tuple(pupil_shift_mm), collimator_zernike_um,
                         spectrograph, min(d_xi, d_eta))
    p = psf(field2d, xi, eta, wavelength_um, f_cam, anam, (n_fft, n_fft), window_um, workers)
    meta = {**p.meta, "grating": g.name, "order": m, "beta_deg": beta, "anamorphic": anam,
            "linear_dispersion_um_per_nm": float(g.linear_dispersion_um_per_nm(wavelength_um, m, f_cam)),
            "slit_image_width_um": g.slit_image_width_at_um(wavelength_um, m, spectrograph),
            "pupil_shift_mm": tuple(pupil_shift_mm), "sag": None if sag is None else sag.label}
    return PSF(p.offset_x_um, p.offset_y_um, p.intensity, meta)
