"""SPIFFI gratings, spectrograph constants and pixel scales (data + the grating equation).

Conventions
-----------
* Grating equation ``sin(alpha) + sin(beta) = m * lambda / d`` with the signs of the
  paper's Table 2: ``alpha`` (incidence) and ``beta`` (diffraction) in degrees from
  the grating normal, order ``m`` signed (the SPIFFI blaze orders are negative).
  With these signs ``beta - alpha = 45 deg`` at each band centre (e.g. J: ``beta =
  8.909 deg``).
* ``d beta / d lambda = m / (d cos beta)`` is *signed*: for the negative blaze orders
  beta decreases with wavelength. Linear dispersions are reported as magnitudes
  (µm on the detector per nm of wavelength) because they convert widths.
* The anamorphic factor ``cos(alpha) / cos(beta)`` is the ratio of the incident to
  the diffracted beam width along x (dispersion): it multiplies the slit magnification
  ``f_cam / f_coll`` along x and the detector scale of the incident-beam pupil
  frequencies (see :mod:`optics.pupil`).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

__all__ = [
    "MAX_GRATING_TURN_DEG",
    "Grating",
    "GRATINGS",
    "PixelScale",
    "PIXEL_SCALES",
    "Spectrograph",
    "SPIFFI",
    "get_grating",
    "get_pixel_scale",
]


@dataclass(frozen=True)
class Spectrograph:
    """Fixed optical constants of the SPIFFI spectrograph (paper §4.1).

    Parameters
    ----------
    collimator_focal_mm, camera_focal_mm : float
        Focal lengths (mm).
    pupil_diameter_mm : float
        Circular entrance-pupil (beam) diameter at the grating, measured in the
        incident collimated beam (mm).
    pixel_um : float
        Detector pixel pitch (µm).
    slit_length_um : float
        Slit image length on the detector used by the paper's 2D PPC runs (µm).
    """

    collimator_focal_mm: float = 2873.0
    camera_focal_mm: float = 342.0
    pupil_diameter_mm: float = 110.0
    pixel_um: float = 18.0
    slit_length_um: float = 400.0

    def __post_init__(self) -> None:
        for name in ("collimator_focal_mm", "camera_focal_mm", "pupil_diameter_mm", "pixel_um", "slit_length_um"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"Spectrograph.{name}={v!r} must be a finite number > 0")


#: The instrument as modelled in the paper.
SPIFFI = Spectrograph()

#: Largest grating rotation (deg) from the design angle for which the fixed-incidence
#: optical model is used. The paper measured off-band lines on other gratings turning
#: them "by no more than a few degrees" (appendix A): 1.25 µm needs 1.9 deg on the H
#: grating (order -3) and 2.0 deg on the K grating (order -4), a band edge 1.7 deg.
MAX_GRATING_TURN_DEG = 5.0


@dataclass(frozen=True)
class Grating:
    """One SPIFFI grating (paper Table 2, 80 K values).

    Parameters
    ----------
    name : str
        "J", "H", "K" or "HK".
    groove_spacing_um : float
        Groove spacing d (µm), > 0.
    order : int
        Blaze (working) diffraction order, non-zero, signed.
    incidence_deg : float
        Incidence angle alpha (deg), |alpha| < 90.
    band_um : (float, float, float)
        (short, centre, long) wavelengths of the band (µm), increasing.
    slit_image_width_um : float
        Geometric slit image width on the detector at the band centre in the blaze
        order (µm): 27 for J/H/K, 29 for H+K (paper §4.1).
    """

    name: str
    groove_spacing_um: float
    order: int
    incidence_deg: float
    band_um: tuple[float, float, float]
    slit_image_width_um: float = 27.0

    def __post_init__(self) -> None:
        if not (np.isfinite(self.groove_spacing_um) and self.groove_spacing_um > 0):
            raise ValueError(f"Grating {self.name!r}: groove_spacing_um={self.groove_spacing_um!r} must be > 0")
        if int(self.order) != self.order or self.order == 0:
            raise ValueError(f"Grating {self.name!r}: order={self.order!r} must be a non-zero integer")
        if not abs(self.incidence_deg) < 90:
            raise ValueError(f"Grating {self.name!r}: incidence_deg={self.incidence_deg!r} must be in (-90, 90)")
        b = tuple(float(v) for v in self.band_um)
        if len(b) != 3 or not (0 < b[0] < b[1] < b[2]):
            raise ValueError(f"Grating {self.name!r}: band_um={self.band_um!r} must be 3 increasing wavelengths > 0")
        if not self.slit_image_width_um > 0:
            raise ValueError(f"Grating {self.name!r}: slit_image_width_um={self.slit_image_width_um!r} must be > 0")
        object.__setattr__(self, "band_um", b)

    # ------------------------------------------------------------------ geometry
    @property
    def centre_um(self) -> float:
        return self.band_um[1]

    def _order(self, order: int | None) -> int:
        if order is None:
            return int(self.order)
        if int(order) != order or order == 0:
            raise ValueError(f"order={order!r} must be a non-zero integer")
        return int(order)

    def sin_beta(self, wavelength_um, order: int | None = None) -> np.ndarray:
        """``sin(beta) = m lambda / d - sin(alpha)`` (no range check)."""
        m = self._order(order)
        wl = np.asarray(wavelength_um, dtype=float)
        return m * wl / self.groove_spacing_um - math.sin(math.radians(self.incidence_deg))

    def valid_range_um(self, order: int | None = None) -> tuple[float, float]:
        """Wavelength interval (µm) with a propagating order ``|sin beta| <= 1``."""
        m = self._order(order)
        sa = math.sin(math.radians(self.incidence_deg))
        lims = sorted(((-1 + sa) * self.groove_spacing_um / m, (1 + sa) * self.groove_spacing_um / m))
        return max(lims[0], 0.0), lims[1]

    def beta_deg(self, wavelength_um, order: int | None = None) -> np.ndarray:
        """Diffraction angle beta (deg) for ``wavelength_um`` (µm, scalar or array).

        Raises
        ------
        ValueError
            If ``|sin beta| > 1`` (evanescent order) or the wavelength is not > 0; the
            message names the wavelength, order and valid wavelength range.
        """
        if isinstance(wavelength_um, (int, float)) and not isinstance(wavelength_um, bool):
            return _scalar_beta_deg(self, wavelength_um, self._order(order))
        return self._beta_deg(wavelength_um, order)

    def _beta_deg(self, wavelength_um, order: int | None = None) -> np.ndarray:
        m = self._order(order)
        wl = np.asarray(wavelength_um, dtype=float)
        s = self.sin_beta(wl, m)
        if np.any(~np.isfinite(wl)) or np.any(wl <= 0) or np.any(np.abs(s) > 1):
            lo, hi = self.valid_range_um(m)
            bad = wl[(~np.isfinite(wl)) | (wl <= 0) | (np.abs(s) > 1)] if wl.ndim else wl
            raise ValueError(
                f"grating {self.name}: wavelength_um={np.round(bad, 6).tolist()} has no propagating "
                f"order {m} (|sin beta| > 1); valid range for order {m} is {lo:.4f}..{hi:.4f} um"
            )
        return np.degrees(np.arcsin(s))

    def turn_deg(self, wavelength_um: float, order: int | None = None) -> float:
        """Grating rotation (deg) that brings ``wavelength_um`` in ``order`` onto the camera
        axis, i.e. diffracts it at the blaze-order band centre's deviation angle.

        The spectrograph fixes the deviation ``Delta = beta_c - alpha`` between collimator
        and camera; turned by ``t`` the grating sees ``alpha + t`` and must diffract at
        ``alpha + t + Delta``, so ``2 sin(alpha + t + Delta/2) cos(Delta/2) = m lambda / d``.
        """
        m = self._order(order)
        self.beta_deg(wavelength_um, m)  # refuses an evanescent order with its valid range
        alpha = self.incidence_deg
        half = 0.5 * (float(self.beta_deg(self.centre_um, self.order)) - alpha)
        s = m * float(wavelength_um) / (2 * self.groove_spacing_um * math.cos(math.radians(half)))
        if abs(s) > 1:
            return math.copysign(180.0, s)
        return math.degrees(math.asin(s)) - alpha - half

    def domain_um(self, order: int | None = None,
                  max_turn_deg: float | None = None) -> tuple[float, float]:
        """Wavelengths (µm) that ``order`` reaches with the grating turned by at most
        ``max_turn_deg`` (default :data:`MAX_GRATING_TURN_DEG`)."""
        m = self._order(order)
        t = MAX_GRATING_TURN_DEG if max_turn_deg is None else max_turn_deg
        alpha = self.incidence_deg
        half = 0.5 * (float(self.beta_deg(self.centre_um, self.order)) - alpha)
        c = 2 * self.groove_spacing_um * math.cos(math.radians(half)) / m
        lo, hi = sorted(c * math.sin(math.radians(alpha + half + k * t)) for k in (-1, 1))
        return max(lo, 0.0), hi

    def check_in_domain(self, wavelength_um: float, order: int | None = None,
                        max_turn_deg: float | None = None) -> None:
        """Refuse a wavelength/order that the fixed-incidence optical model does not describe.

        The optical model keeps the incidence angle of the blaze-order design (paper,
        Table 3). The paper's off-band measurements turned the gratings by no more than
        "a few degrees"; beyond ``max_turn_deg`` (default :data:`MAX_GRATING_TURN_DEG`)
        the model's geometry (beam footprint, anamorphic factor, camera field) is that of
        another instrument, so a number it gave (a resolving power, say) would be no
        prediction.

        Raises
        ------
        ValueError
            Naming the wavelength, the order, the turn it needs and the valid wavelength
            interval for that order.
        """
        m = self._order(order)
        t = MAX_GRATING_TURN_DEG if max_turn_deg is None else max_turn_deg
        turn = self.turn_deg(wavelength_um, m)
        if abs(turn) <= t:
            return
        lo, hi = self.domain_um(m, t)
        raise ValueError(
            f"grating {self.name}: wavelength_um={float(wavelength_um):g} in order {m} needs the grating "
            f"turned by {turn:+.1f} deg from its design angle; the optical model keeps the design "
            f"incidence and is valid for turns up to {t:g} deg: {lo:.4f}..{hi:.4f} um in order {m}")

    def angular_dispersion_rad_per_um(self, wavelength_um, order: int | None = None) -> np.ndarray:
        """Signed ``d beta / d lambda = m / (d cos beta)`` in rad per µm of wavelength."""
        m = self._order(order)
        cb = np.cos(np.radians(self.beta_deg(wavelength_um, m)))
        return m / (self.groove_spacing_um * cb)

    def linear_dispersion_um_per_nm(
        self, wavelength_um, order: int | None = None, camera_focal_mm: float = SPIFFI.camera_focal_mm
    ) -> np.ndarray:
        """|f_cam d beta / d lambda|: µm on the detector per nm of wavelength (> 0)."""
        return np.abs(self.angular_dispersion_rad_per_um(wavelength_um, order)) * camera_focal_mm * 1e3 * 1e-3

    def anamorphic_factor(self, wavelength_um, order: int | None = None) -> np.ndarray:
        """``cos(alpha) / cos(beta)``: incident / diffracted beam width along x (slit magnification factor)."""
        cb = np.cos(np.radians(self.beta_deg(wavelength_um, order)))
        return math.cos(math.radians(self.incidence_deg)) / cb

    def slit_width_collimator_um(self, spectrograph: Spectrograph = SPIFFI) -> float:
        """Physical slit width in the collimator focal plane (µm).

        Inverted from ``slit_image_width_um`` at the band centre in the blaze order
        with the magnification ``(f_cam / f_coll) * cos(alpha) / cos(beta)``.
        """
        mag = spectrograph.camera_focal_mm / spectrograph.collimator_focal_mm * self.anamorphic_factor(self.centre_um)
        return float(self.slit_image_width_um / mag)

    def slit_image_width_at_um(
        self, wavelength_um: float, order: int | None = None, spectrograph: Spectrograph = SPIFFI
    ) -> float:
        """Geometric slit image width (µm) at ``wavelength_um`` in ``order`` (the slit is fixed;
        the anamorphic magnification changes with beta)."""
        mag = spectrograph.camera_focal_mm / spectrograph.collimator_focal_mm * self.anamorphic_factor(wavelength_um, order)
        return float(self.slit_width_collimator_um(spectrograph) * mag)


@functools.lru_cache(maxsize=1024)
def _scalar_beta_deg(grating: Grating, wavelength_um: float, order: int):
    # Memoised for scalar wavelengths: every line profile of a diagnosis fit asks for the same
    # few angles several times (anamorphic factor, dispersion, domain check); the value is that
    # of Grating._beta_deg, an error is raised again on every call (lru_cache keeps no errors).
    return grating._beta_deg(wavelength_um, order)


#: Paper Table 2. Keys are the names accepted on the command line.
GRATINGS: dict[str, Grating] = {
    "J": Grating("J", 5.758, -2, -36.0908, (1.10, 1.25, 1.40)),
    "H": Grating("H", 7.747, -2, -35.8277, (1.45, 1.65, 1.85)),
    "K": Grating("K", 9.684, -2, -36.7344, (1.95, 2.20, 2.45)),
    "HK": Grating("HK", 9.961, -1, -28.5817, (1.45, 1.95, 2.45), slit_image_width_um=29.0),
}


def get_grating(name: str | Grating) -> Grating:
    """Look up a grating by name (case-insensitive; "H+K" is accepted for "HK")."""
    if isinstance(name, Grating):
        return name
    key = str(name).upper().replace("+", "")
    if key not in GRATINGS:
        raise ValueError(f"grating={name!r} is unknown; valid names are {sorted(GRATINGS)}")
    return GRATINGS[key]


@dataclass(frozen=True)
class PixelScale:
    """A SPIFFI pixel scale and the relative NA of the light filling the slit.

    Parameters
    ----------
    mas : int
        Pixel scale on the sky (milli-arcsec per pixel).
    relative_na : float
        Illumination NA relative to the 250 mas scale, in (0, 1]; the source fills a
        disc of radius ``relative_na * pupil_radius`` in the spectrograph pupil.
    """

    mas: int
    relative_na: float

    def __post_init__(self) -> None:
        if not self.mas > 0:
            raise ValueError(f"PixelScale.mas={self.mas!r} must be > 0")
        if not (0 < self.relative_na <= 1):
            raise ValueError(f"PixelScale.relative_na={self.relative_na!r} must be in (0, 1]")


#: Paper §4.3.2: relative NA [1.0, 0.4, 0.1] for [250, 100, 25] mas.
PIXEL_SCALES: dict[int, PixelScale] = {
    250: PixelScale(250, 1.0),
    100: PixelScale(100, 0.4),
    25: PixelScale(25, 0.1),
}


def get_pixel_scale(mas: int | str | PixelScale) -> PixelScale:
    """Look up a pixel scale by its mas value (int or string such as "25" or "25mas")."""
    if isinstance(mas, PixelScale):
        return mas
    try:
        key = int(float(str(mas).lower().replace("mas", "")))
    except ValueError:
        key = None
    if key not in PIXEL_SCALES or float(str(mas).lower().replace("mas", "")) != key:
        raise ValueError(f"pixel scale {mas!r} mas is unknown; valid values are {sorted(PIXEL_SCALES)}")
    return PIXEL_SCALES[key]
