"""Line profiles by a literal 2-D finite-slit Abbe sum (numpy only; no project optics).

Physics (paper §4.1-4.3, written from the paper, not from :mod:`optics`):

* Grating equation ``sin(alpha) + sin(beta) = m lambda / d`` with the paper's table
  (:data:`GRATINGS`: spacing, order, incidence); anamorphic factor ``A = cos(alpha) /
  cos(beta)``.
* A slit of width ``w_c`` and length ``l_c`` in the collimator focal plane
  (``w_c = W / ((f_cam / f_coll) A_centre)`` for the geometric image width ``W`` = 27 µm
  at the band centre in the blaze order; ``l_c = L f_coll / f_cam`` for the image length
  ``L`` = 400 µm) is lit by mutually incoherent plane waves whose undiffracted light
  lands at source points ``s`` filling a disc of radius ``NA_rel * 55 mm`` of the
  110 mm pupil (NA_rel 1.0 / 0.4 / 0.1 at 250 / 100 / 25 mas).
* For one source the field in the pupil (incident-beam coordinates ``p`` along
  dispersion, ``q`` along the grooves, mm) is the 2-D spectrum of the lit slit times
  the pupil: ``sinc(w_c (p - s_p) / (lambda f_coll)) sinc(l_c (q - s_q) / (lambda f_coll))
  * aperture(p, q) * exp(i phi(p, q))``.
* ``phi`` = collimator (and camera) wavefront ``+2 pi W / lambda`` (RMS-normalised
  Zernike terms over the 55 mm pupil radius, own polynomials) plus the grating's
  ``-2 pi / lambda (cos alpha + cos beta) h(x_g, y_g)`` at the footprint
  ``x_g = p / cos(alpha) + shift_x``, ``y_g = q + shift_y``. The sign: a surface rising
  towards +x_g (``h = t x_g``) reflects the beam towards -x (ray reflection off the
  normal (-t, 0, 1)), and with the ``exp(-i k x sin(theta))`` far-field kernel used here
  a pupil phase ``+k_x x`` goes to +x, so the phase is ``-k (cos a + cos b) h``.
* Camera: Fraunhofer to the focal plane, ``x = lambda f_cam A nu_p``,
  ``y = lambda f_cam nu_q``. The detector field is evaluated by an FFT along ``p`` and
  a direct DFT along ``q`` at the rows of the detector column read out, so each source is
  a complete 2-D coherent propagation of the finite slit.
* Detector: the intensity is integrated over one 18 µm pixel column along the slit at
  the slit centre (``collapse_um``; the whole slit image for ``collapse_um = L``) and
  convolved with the 18 µm pixel along x (exact, by its transfer function sinc).

The incoherent sum runs over the illumination's source points; the slit is the object
those plane waves light, so its finite width and length enter through the coherent
propagation of each source (van Cittert-Zernike: the source disc sets the partial
coherence across the slit). Sources and pupil samples carry area weights from
sub-sampled cells (grey rims).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["GRATINGS", "F_COLL_MM", "F_CAM_MM", "PUPIL_D_MM", "PIXEL_UM", "RELATIVE_NA", "AbbeSettings",
           "beta_deg", "zernike_noll", "disc_cells", "abbe_line_profile", "point_image"]

#: Paper table of grating parameters (80 K): groove spacing µm, order, incidence deg,
#: band (short, centre, long) µm, geometric slit image width µm.
GRATINGS = {
    "J": (5.758, -2, -36.0908, (1.10, 1.25, 1.40), 27.0),
    "H": (7.747, -2, -35.8277, (1.45, 1.65, 1.85), 27.0),
    "K": (9.684, -2, -36.7344, (1.95, 2.20, 2.45), 27.0),
    "HK": (9.961, -1, -28.5817, (1.45, 1.95, 2.45), 29.0),
}
F_COLL_MM, F_CAM_MM, PUPIL_D_MM, PIXEL_UM = 2873.0, 342.0, 110.0, 18.0
#: Paper §4.3.2: relative illumination NA per pixel scale (mas).
RELATIVE_NA = {250: 1.0, 100: 0.4, 25: 0.1}


@dataclass(frozen=True)
class AbbeSettings:
    """Sampling of :func:`abbe_line_profile`.

    Parameters
    ----------
    pupil_step_mm : float
        Pupil sampling along dispersion (mm).
    pupil_step_q_mm : float
        Pupil sampling along the slit (mm); must resolve the slit-length spectrum
        (first zero ``lambda f_coll / l_c`` ~ 1 mm).
    n_fft : int
        FFT length along dispersion (detector step ``lambda f_cam A / (n_fft pupil_step_mm)``).
    source_step_mm : float
        Source grid step (mm in the pupil), capped at ``radius / min_source_rows``.
    min_source_rows : int
        Minimum source rows across the source radius.
    slit_length_um : float
        Slit image length on the detector (µm; paper: 400).
    collapse_um : float
        Along-slit extent integrated into the profile, centred on the slit (µm).
    collapse_step_um : float
        Largest step of the along-slit quadrature (µm).
    window_um : float
        Half width of the returned profile (µm).
    """

    pupil_step_mm: float = 0.5
    pupil_step_q_mm: float = 0.3
    n_fft: int = 1024
    source_step_mm: float = 1.0
    min_source_rows: int = 8
    slit_length_um: float = 400.0
    collapse_um: float = 18.0
    collapse_step_um: float = 3.0
    window_um: float = 150.0

    def __post_init__(self) -> None:
        for name in ("pupil_step_mm", "pupil_step_q_mm", "source_step_mm", "slit_length_um", "collapse_um",
                     "collapse_step_um", "window_um"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"AbbeSettings.{name}={v!r} must be a finite number > 0")
        if int(self.n_fft) != self.n_fft or self.n_fft < 2 * math.ceil(PUPIL_D_MM / self.pupil_step_mm):
            raise ValueError(f"AbbeSettings.n_fft={self.n_fft!r} must be an integer >= twice the pupil samples "
                             f"({2 * math.ceil(PUPIL_D_MM / self.pupil_step_mm)})")
        if self.min_source_rows < 1:
            raise ValueError(f"AbbeSettings.min_source_rows={self.min_source_rows!r} must be >= 1")


def _grating(name: str):
    key = str(name).upper().replace("+", "")
    if key not in GRATINGS:
        raise ValueError(f"grating={name!r} is unknown; valid: {sorted(GRATINGS)}")
    return GRATINGS[key]


def beta_deg(grating: str, wavelength_um: float, order: int) -> float:
    """Diffraction angle (deg) from ``sin(alpha) + sin(beta) = m lambda / d``."""
    d, _, alpha, _, _ = _grating(grating)
    s = order * wavelength_um / d - math.sin(math.radians(alpha))
    if not (math.isfinite(s) and abs(s) <= 1.0 and wavelength_um > 0):
        raise ValueError(f"wavelength_um={wavelength_um} has no propagating order {order} on grating {grating}")
    return math.degrees(math.asin(s))


def zernike_noll(n: int, m: int, rho: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """RMS-normalised (Noll) Zernike term (n, m) on the unit disc; m > 0 cosine, m < 0 sine."""
    if (n - abs(m)) % 2 or abs(m) > n or n < 0:
        raise ValueError(f"zernike_noll: (n, m)=({n}, {m}) is not a Zernike index (|m| <= n, n - |m| even)")
    k = abs(m)
    radial = sum((-1) ** j * math.factorial(n - j) / (math.factorial(j) * math.factorial((n + k) // 2 - j)
                                                       * math.factorial((n - k) // 2 - j)) * rho ** (n - 2 * j)
                 for j in range((n - k) // 2 + 1))
    norm = math.sqrt(n + 1) if m == 0 else math.sqrt(2 * (n + 1))
    ang = 1.0 if m == 0 else (np.cos(k * theta) if m > 0 else np.sin(k * theta))
    return norm * radial * ang


def disc_cells(radius_mm: float, step_mm: float, sub: int = 5) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cell-centred grid over a disc: axis (mm), axis (mm) and area fraction of each
    cell inside the disc (``sub`` x ``sub`` sub-samples per cell), shape (n, n)."""
    n = int(math.ceil(radius_mm / step_mm))
    ax = (np.arange(-n, n) + 0.5) * step_mm
    f = (np.arange(sub) + 0.5) / sub - 0.5
    fine = (ax[:, None] + f[None, :] * step_mm).ravel()
    inside = (fine[:, None] ** 2 + fine[None, :] ** 2) <= radius_mm ** 2
    w = inside.reshape(ax.size, sub, ax.size, sub).mean(axis=(1, 3))
    keep = w.any(axis=1)
    return ax[keep], ax[keep], w[np.ix_(keep, keep)]


def _wavefront_um(terms: dict | None, p: np.ndarray, q: np.ndarray, radius_mm: float) -> np.ndarray:
    out = np.zeros(np.broadcast(p, q).shape)
    if terms:
        rho, th = np.hypot(p, q) / radius_mm, np.arctan2(q, p)
        for (n, m), c in terms.items():
            if c:
                out = out + c * zernike_noll(n, m, rho, th)
    return out


def _pixel_box(x_um: np.ndarray, y: np.ndarray, width_um: float) -> np.ndarray:
    """Convolution with a ``width_um`` box by its transfer function (periodic, exact on the grid)."""
    f = np.fft.rfftfreq(y.size, d=x_um[1] - x_um[0])
    return np.fft.irfft(np.fft.rfft(y) * np.sinc(width_um * f), n=y.size)


def _pupil_field(grating: str, wavelength_um: float, order: int, sag_um, pupil_shift_mm, collimator_um,
                 camera_um, s: AbbeSettings):
    """The pupil samples ``p`` (dispersion) and ``q`` (grooves), mm, cell-centred; the field
    ``U = aperture * exp(i phi)`` on them, shape (n_q, n_p), grey rim from 4 x 4 sub-samples;
    and the anamorphic factor ``cos(alpha) / cos(beta)`` (module docstring)."""
    _, _, alpha, _, _ = _grating(grating)
    b = beta_deg(grating, wavelength_um, order)
    ca, cb = math.cos(math.radians(alpha)), math.cos(math.radians(b))
    R = 0.5 * PUPIL_D_MM
    p = (np.arange(-math.ceil(R / s.pupil_step_mm), math.ceil(R / s.pupil_step_mm)) + 0.5) * s.pupil_step_mm
    q = (np.arange(-math.ceil(R / s.pupil_step_q_mm), math.ceil(R / s.pupil_step_q_mm)) + 0.5) * s.pupil_step_q_mm
    sub = (np.arange(4) + 0.5) / 4 - 0.5
    pf = (p[:, None] + sub * s.pupil_step_mm).ravel()
    qf = (q[:, None] + sub * s.pupil_step_q_mm).ravel()
    amp = ((qf[:, None] ** 2 + pf[None, :] ** 2) <= R * R).reshape(q.size, 4, p.size, 4).mean(axis=(1, 3))
    P, Q = np.meshgrid(p, q)
    opd = _wavefront_um(collimator_um, P, Q, R) + _wavefront_um(camera_um, P, Q, R)
    phase = 2 * np.pi * opd / wavelength_um
    if sag_um is not None:
        xg, yg = P / ca + pupil_shift_mm[0], Q + pupil_shift_mm[1]
        h = np.zeros_like(P)
        inside = amp > 0
        h[inside] = sag_um(xg[inside], yg[inside])
        if not np.all(np.isfinite(h[inside])):
            raise ValueError("sag_um: the sag is not finite everywhere inside the pupil footprint "
                             f"(shift {pupil_shift_mm} mm)")
        phase = phase - 2 * np.pi / wavelength_um * (ca + cb) * h
    return p, q, amp * np.exp(1j * phase), ca / cb


def abbe_line_profile(grating: str, wavelength_um: float, order: int, relative_na: float, sag_um=None, *,
                      pupil_shift_mm: tuple[float, float] = (0.0, 0.0), collimator_um: dict | None = None,
                      camera_um: dict | None = None, slit_image_width_um: float | None = None,
                      settings: AbbeSettings = AbbeSettings(), pixel_um: float = PIXEL_UM):
    """Detected line profile at the slit centre by the 2-D finite-slit Abbe sum.

    Parameters
    ----------
    grating : str
        "J", "H", "K" or "HK" (:data:`GRATINGS`).
    wavelength_um : float
        Line wavelength (µm).
    order : int
        Diffraction order (signed).
    relative_na : float
        Illumination NA relative to the 250 mas scale, in (0, 1] (:data:`RELATIVE_NA`).
    sag_um : callable or None
        ``sag_um(x_g_mm, y_g_mm) -> µm`` (grating frame, +z towards the light); None:
        a perfect grating.
    pupil_shift_mm : (float, float)
        Footprint shift on the grating (mm).
    collimator_um, camera_um : dict {(n, m): µm} or None
        RMS-normalised Zernike wavefront (OPD) over the 55 mm pupil radius.
    slit_image_width_um : float, optional
        Geometric slit image width at the band centre in the blaze order (default: the
        grating's 27 / 29 µm).
    pixel_um : float
        Detector pixel (µm); 0 gives the profile before the pixel.

    Returns
    -------
    (offset_um, intensity) : ndarray
        Detector offset along dispersion (µm, 0 = undeviated image of the slit centre)
        and the profile normalised to unit area.
    """
    if not (0.0 < relative_na <= 1.0):
        raise ValueError(f"relative_na={relative_na!r} must be in (0, 1]")
    _, m_blaze, alpha, band, w_img = _grating(grating)
    s = settings
    ca = math.cos(math.radians(alpha))
    anam_c = ca / math.cos(math.radians(beta_deg(grating, band[1], m_blaze)))
    w_img = w_img if slit_image_width_um is None else slit_image_width_um
    w_c = w_img / (F_CAM_MM / F_COLL_MM * anam_c)          # µm, collimator focal plane
    l_c = s.slit_length_um * F_COLL_MM / F_CAM_MM            # µm
    lam_fcoll = wavelength_um * F_COLL_MM                   # µm * mm
    R = 0.5 * PUPIL_D_MM
    p, q, U, anam = _pupil_field(grating, wavelength_um, order, sag_um, pupil_shift_mm, collimator_um, camera_um, s)
    # Sources: disc of radius NA_rel R.
    r_src = relative_na * R
    sp, sq, sw = disc_cells(r_src, min(s.source_step_mm, r_src / s.min_source_rows))
    # Detector rows of the read-out column (midpoint rule over collapse_um).
    n_y = max(1, int(math.ceil(s.collapse_um / s.collapse_step_um)))
    y_um = (np.arange(n_y) + 0.5) / n_y * s.collapse_um - 0.5 * s.collapse_um
    Ey = np.exp(-2j * np.pi * np.outer(y_um, q) / (wavelength_um * F_CAM_MM))   # (n_y, n_q)
    Tx = np.sinc(w_c * (p[None, :] - sp[:, None]) / lam_fcoll)                   # (n_sp, n_p)
    acc = np.zeros(s.n_fft)
    for j, sqj in enumerate(sq):
        cols = np.nonzero(sw[j] > 0)[0]
        if cols.size == 0:
            continue
        Ty = np.sinc(l_c * (q - sqj) / lam_fcoll)                                # (n_q,)
        V = (Ey * Ty[None, :]) @ U                                               # (n_y, n_p)
        F = np.fft.fft(V[None, :, :] * Tx[cols, None, :], n=s.n_fft, axis=-1)    # (n_c, n_y, n_fft)
        acc += np.einsum("c,cyk->k", sw[j, cols], F.real ** 2 + F.imag ** 2)
    acc = np.fft.fftshift(acc)
    du = wavelength_um * F_CAM_MM * anam / (s.n_fft * s.pupil_step_mm)
    x = (np.arange(s.n_fft) - s.n_fft // 2) * du
    if pixel_um > 0:
        acc = _pixel_box(x, acc, pixel_um)
    keep = np.abs(x) <= s.window_um
    x, y = x[keep], acc[keep]
    return x, y / (y.sum() * du)


def point_image(grating: str, wavelength_um: float, order: int, sag_um=None, *,
                pupil_shift_mm: tuple[float, float] = (0.0, 0.0), collimator_um: dict | None = None,
                camera_um: dict | None = None, settings: AbbeSettings = AbbeSettings(),
                half_range_um: float = 32.0, step_y_um: float = 0.5):
    """Focal-plane image of a point at the slit centre (one plane wave filling the pupil).

    The pupil field is the line profiles' (:func:`abbe_line_profile`, same phase and
    sign), with no slit spectrum: the object is a point, so one coherent propagation is
    the whole image. Fraunhofer to the camera focal plane as there: an FFT along ``p``
    (step ``lambda f_cam A / (n_fft pupil_step_mm)``) and a direct DFT along ``q`` at
    rows ``step_y_um`` apart.

    Parameters
    ----------
    grating, wavelength_um, order, sag_um, pupil_shift_mm, collimator_um, camera_um, settings
        As :func:`abbe_line_profile`.
    half_range_um : float
        Half width of the returned image on both axes (µm).
    step_y_um : float
        Row step along the slit (µm).

    Returns
    -------
    x_um : ndarray, shape (n_x,)
        Detector offset along dispersion (µm, 0 = the undeviated image).
    y_um : ndarray, shape (n_y,)
        Detector offset along the slit (µm).
    image : ndarray, shape (n_y, n_x)
        Intensity normalised to unit volume (per µm²).
    """
    if not (math.isfinite(half_range_um) and half_range_um > 0 and math.isfinite(step_y_um) and step_y_um > 0):
        raise ValueError(f"half_range_um={half_range_um!r} and step_y_um={step_y_um!r} must be finite numbers > 0")
    s = settings
    p, q, U, anam = _pupil_field(grating, wavelength_um, order, sag_um, pupil_shift_mm, collimator_um, camera_um, s)
    n_y = int(math.floor(half_range_um / step_y_um))
    y_um = np.arange(-n_y, n_y + 1) * step_y_um
    Ey = np.exp(-2j * np.pi * np.outer(y_um, q) / (wavelength_um * F_CAM_MM))   # (n_y, n_q)
    F = np.fft.fftshift(np.fft.fft(Ey @ U, n=s.n_fft, axis=-1), axes=-1)       # (n_y, n_fft)
    du = wavelength_um * F_CAM_MM * anam / (s.n_fft * s.pupil_step_mm)
    x_um = (np.arange(s.n_fft) - s.n_fft // 2) * du
    keep = np.abs(x_um) <= half_range_um
    img = F.real[:, keep] ** 2 + F.imag[:, keep] ** 2
    return x_um[keep], y_um, img / (img.sum() * du * step_y_um)
