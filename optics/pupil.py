"""Spectrograph pupil: sampling, beam footprint on the grating, OPD maps and the pupil field.

Frames and sign conventions (fixed here, pinned by ``tests/test_imaging.py``)
----------------------------------------------------------------------------
* **Pupil coordinates** ``(xi_mm, eta_mm)`` are measured in the *incident* collimated
  beam, where the 110 mm entrance pupil is a circle. ``xi`` is along dispersion,
  ``eta`` along the grooves (= along the slit). All pupil arrays are ``[eta, xi]``.
* **Footprint on the grating** (frame of :mod:`optics.sagmap`)::

      x_g = xi / cos(alpha) + shift_x_mm        y_g = eta + shift_y_mm

  so the footprint is 1/cos(alpha) longer along x, and a *positive pupil shift moves
  the footprint towards +x_g / +y_g on the sag map* (the sag sampled at pupil centre
  is ``h(shift_x, shift_y)``). The diffracted beam has ``x_beam = x_g cos(beta)``,
  i.e. ``x_beam = xi * cos(beta) / cos(alpha)``, same orientation as ``x_g``.
* **OPD** (µm) is the extra optical path a ray travels. The pupil field is
  ``A * exp(+2 pi i OPD / lambda)``. A surface displaced by ``h`` towards the light
  (positive sag) shortens the reflected path by ``(cos alpha + cos beta) h``::

      OPD_grating = -(cos alpha + cos beta) * h(x_g, y_g)

  (The brief quotes ``(cos a + cos b) h``; the magnitude is the same, the sign is the
  path-length one. Flipping it is equivalent to moving a symmetric quilt by half a
  period.)
* **Detector orientation**: :mod:`optics.imaging` uses a forward FFT, so an OPD tilt
  ``OPD = t * xi`` (µm per mm) moves the light to ``+offset_um = f_cam[mm] * t *
  cos(alpha)/cos(beta)`` µm, i.e. +offset_um is the image of +x_g. Because the SPIFFI
  blaze orders are negative, *longer wavelengths land at more negative offset_um*
  (d beta / d lambda < 0). "Left" in this package means negative offset_um.
* **Collimator WFE**: Zernike OPD over the incident pupil disc (radius 55 mm),
  ``theta`` from +xi towards +eta, RMS-normalised (Noll) coefficients in µm,
  ``(n, m)`` with m > 0 cosine, m < 0 sine (:mod:`optics.zernike`). Positive
  horizontal coma (3, 1) moves the bright core towards +offset and the flare (power
  in the shoulder) towards -offset ("left"); see :data:`DEFAULT_COLLIMATOR_ZERNIKE_UM`.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from optics.sagmap import SagMap
from optics.zernike import zernike_basis_xy

__all__ = [
    "DEFAULT_COLLIMATOR_ZERNIKE_UM",
    "centred_axis",
    "circular_aperture",
    "footprint_on_grating",
    "grating_opd_um",
    "collimator_opd_um",
    "pupil_field",
    "pupil_shift_along_slit",
    "check_sag_sampling",
]

#: Default collimator wavefront (RMS-normalised Zernike OPD, µm, over the 110 mm pupil).
#: The paper (§4.3.3) says "primarily horizontal coma and 45 deg astigmatism, P/V 1.31 µm,
#: RMS 0.31 µm". Those two terms cannot reach P/V/RMS = 4.23 (the minimum over their
#: ratio is 4.89, pure astigmatism; pure coma gives 5.66), so we honour the RMS and the
#: two named terms with an equal RMS split 0.31/sqrt(2) = 0.2192 µm each: RMS 0.310 µm,
#: P/V 2.02 µm (P/V/RMS 6.53) on the disc. The coma sign is chosen so that shoulder
#: power goes to the LEFT (-offset_um) as the paper reports (pinned by a test). For a
#: sag map symmetric in y the astigmatism sign cannot change the line profile
#: (eta -> -eta flips Z(2,-2) only); it is taken positive.
DEFAULT_COLLIMATOR_ZERNIKE_UM: dict[tuple[int, int], float] = {
    (3, 1): -0.31 / math.sqrt(2.0),
    (2, -2): 0.31 / math.sqrt(2.0),
}


def centred_axis(step_mm: float, half_width_mm: float) -> np.ndarray:
    """Odd-length axis ``k * step_mm`` covering ``[-half_width_mm, half_width_mm]``, with 0 at the centre."""
    if not step_mm > 0 or not half_width_mm > 0:
        raise ValueError(f"step_mm={step_mm} and half_width_mm={half_width_mm} must be > 0")
    k = int(math.ceil(half_width_mm / step_mm - 1e-9))
    return np.arange(-k, k + 1) * step_mm


def circular_aperture(xi_mm: np.ndarray, eta_mm: np.ndarray, diameter_mm: float, step_mm: float | None = None) -> np.ndarray:
    """Amplitude of a centred circular pupil on the grid ``xi_mm`` × ``eta_mm``, shape (n_eta, n_xi).

    With ``step_mm`` the rim is grey (linear ramp of one sample width, area-preserving
    to first order), which removes the staircase error of a binary disc; without it
    the disc is binary.
    """
    r = np.hypot(np.asarray(xi_mm)[None, :], np.asarray(eta_mm)[:, None])
    if step_mm is None:
        return (r <= 0.5 * diameter_mm).astype(float)
    return np.clip(0.5 + (0.5 * diameter_mm - r) / step_mm, 0.0, 1.0)


def footprint_on_grating(
    xi_mm: np.ndarray, eta_mm: np.ndarray, incidence_deg: float, shift_mm: tuple[float, float] = (0.0, 0.0)
) -> tuple[np.ndarray, np.ndarray]:
    """Grating coordinates ``(x_g, y_g)`` (mm) of pupil points, each shape (n_eta, n_xi)."""
    ca = math.cos(math.radians(incidence_deg))
    xg = np.asarray(xi_mm, float)[None, :] / ca + shift_mm[0]
    yg = np.asarray(eta_mm, float)[:, None] + shift_mm[1]
    return np.broadcast_arrays(xg, yg)


def check_sag_sampling(sag: SagMap, min_period_mm: float = 18.0, min_samples: float = 8.0) -> None:
    """Raise ValueError if the map spacing cannot resolve the quilt (``min_samples`` per period)."""
    step = max(sag.dx_mm, sag.dy_mm)
    if min_period_mm / step < min_samples - 1e-9:
        raise ValueError(
            f"sag map {sag.label!r} spacing dx={sag.dx_mm:g} mm, dy={sag.dy_mm:g} mm is too coarse: "
            f"{min_period_mm / step:.1f} samples per {min_period_mm:g} mm quilt period; need >= {min_samples:g} "
            f"(spacing <= {min_period_mm / min_samples:g} mm)"
        )


def grating_opd_um(
    sag: SagMap,
    xi_mm: np.ndarray,
    eta_mm: np.ndarray,
    incidence_deg: float,
    beta_deg: float,
    shift_mm: tuple[float, float] = (0.0, 0.0),
    aperture: np.ndarray | None = None,
) -> np.ndarray:
    """OPD (µm) added by the deformed grating, shape (n_eta, n_xi); 0 outside the aperture.

    ``-(cos alpha + cos beta) h(x_g, y_g)``, ``h`` bilinearly resampled from ``sag``
    at the footprint (:func:`footprint_on_grating`).

    Raises
    ------
    ValueError
        If the sag map is too coarse (:func:`check_sag_sampling`), has no valid
        samples inside the footprint, or has NaN / out-of-map points where
        ``aperture > 0``.
    """
    check_sag_sampling(sag)
    xg, yg = footprint_on_grating(xi_mm, eta_mm, incidence_deg, shift_mm)
    inside = np.ones(xg.shape, bool) if aperture is None else np.asarray(aperture) > 0
    h = np.zeros(xg.shape)
    h[inside] = sag.sample(xg[inside], yg[inside])
    bad = inside & ~np.isfinite(h)
    if bad.any():
        where = f"x_g {xg[inside].min():.1f}..{xg[inside].max():.1f} mm, y_g {yg[inside].min():.1f}..{yg[inside].max():.1f} mm"
        cover = f"map covers x {sag.x_mm[0]:.1f}..{sag.x_mm[-1]:.1f} mm, y {sag.y_mm[0]:.1f}..{sag.y_mm[-1]:.1f} mm"
        if bad.sum() == inside.sum():
            raise ValueError(f"sag map {sag.label!r} has no valid samples in the pupil footprint ({where}; {cover}, shift {shift_mm} mm)")
        raise ValueError(
            f"sag map {sag.label!r} has {int(bad.sum())} NaN/out-of-map points inside the pupil footprint "
            f"({where}; {cover}, shift {shift_mm} mm); fill or crop the map, or move the pupil"
        )
    ca, cb = math.cos(math.radians(incidence_deg)), math.cos(math.radians(beta_deg))
    return -(ca + cb) * h


def collimator_opd_um(
    xi_mm: np.ndarray, eta_mm: np.ndarray, coefficients_um: dict | None, radius_mm: float = 55.0
) -> np.ndarray:
    """Collimator OPD (µm) from RMS-normalised Zernike ``coefficients_um`` {(n, m): µm}, shape (n_eta, n_xi)."""
    shape = (np.size(eta_mm), np.size(xi_mm))
    if not coefficients_um:
        return np.zeros(shape)
    coeffs = dict(coefficients_um)
    terms = tuple(coeffs)
    xi = np.ascontiguousarray(xi_mm, dtype=float).ravel()
    eta = np.ascontiguousarray(eta_mm, dtype=float).ravel()
    basis = _collimator_basis(terms, xi.tobytes(), eta.tobytes(), float(radius_mm))
    c = np.array([coeffs[k] for k in terms], dtype=float)
    return np.tensordot(c, basis, axes=1) * np.ones(shape)


@functools.lru_cache(maxsize=16)
def _collimator_basis(terms: tuple, xi_bytes: bytes, eta_bytes: bytes, radius_mm: float) -> np.ndarray:
    """Zernike ``terms`` on the pupil grid (read-only), shape (len(terms), n_eta, n_xi).

    Memoised because a fit evaluates many line profiles on the same pupil grid with other
    coefficients only (a diagnosis of profiles + map + PSF image: 5085 of 5093 look-ups hit);
    keyed on the grid's bytes, so the values are those of a fresh evaluation."""
    xi, eta = np.frombuffer(xi_bytes), np.frombuffer(eta_bytes)
    basis = zernike_basis_xy(terms, xi[None, :], eta[:, None], radius_mm, norm=True)
    basis.flags.writeable = False
    return basis


def pupil_field(amplitude: np.ndarray, opd_um: np.ndarray, wavelength_um: float) -> np.ndarray:
    """Complex pupil field ``amplitude * exp(+2 pi i OPD / lambda)`` (same shape)."""
    return amplitude * np.exp(2j * np.pi * np.asarray(opd_um) / wavelength_um)


def pupil_shift_along_slit(
    slit_position: float, shift_mm: tuple[float, float] = (0.0, 0.0), torsion_shift_x_mm: float = 0.0
) -> tuple[float, float]:
    """Pupil shift (mm on the grating) at a position along the slit (slicer torsion model).

    ``shift_x = shift_mm[0] + torsion_shift_x_mm * slit_position``, ``slit_position``
    in [-1, 1] (slit ends), 0 at the slit centre; a torsion of the slicer mirror
    tilts the beam and moves the pupil linearly along the slitlet (paper §5.3,
    ~±10 mm for 2 HeNe fringes).
    """
    if not -1.0 <= slit_position <= 1.0:
        raise ValueError(f"slit_position={slit_position} must be in [-1, 1] (slit ends)")
    return (float(shift_mm[0]) + torsion_shift_x_mm * slit_position, float(shift_mm[1]))
