"""Forward models of each measurement as a function of the effect parameters.

Both models take a parameter dict (missing keys = null values, see :mod:`.effects`)
and return the prediction at the measured samples *before* the nuisance parameters;
:meth:`residual` then removes the nuisances the data need:

* surface maps: piston and x/y tilt (linear, projected out by least squares);
* line profiles: an offset shift ``delta_um`` (nonlinear, a fit parameter), a flux
  scale and a constant background (linear, projected out).

Speed: the nominal map is sampled once; amplitude and temperature are exact rescalings;
registration re-samples the map by bilinear interpolation; line profiles are recomputed
with coarser-than-default :class:`optics.lineprofile.LsfSettings` (≤ 0.5 % L1 from
the defaults, ~4x faster) and memoised on the physical parameters, so varying only
the offset shift costs an interpolation.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from dataclasses import replace

import numpy as np
from scipy.interpolate import CubicSpline, RegularGridInterpolator

from optics.lineprofile import LsfSettings, line_profile
from optics.pupil import DEFAULT_COLLIMATOR_ZERNIKE_UM
from optics.sagmap import SagMap
from optics.zernike import zernike_xy

from .effects import BOW_REF_RADIUS_MM, LIBRARY, NOMINAL_SLIT_UM, PLATING_GRADIENT_REF_MM, parameter_spec
from .manifest import ProfileData, SurfaceData
from .noise import estimate_noise
from .nominal import DEFAULT_MATERIALS, thermal_factor
from .quilt import QuiltComponents, quilt_components

__all__ = ["FIT_LSF_SETTINGS", "PROFILE_KEYS", "SurfaceForward", "SpectrographImageModel", "ProfileForward", "profile_curve", "collimator_terms", "plating_gradient_map", "bow_um",
           "blank_bow_map", "blank_shape_um",
           "quilt_parts"]

#: Line-profile sampling used while fitting (measured: 0.1-0.45 % L1 from the defaults).
FIT_LSF_SETTINGS = LsfSettings(detector_step_um=1.5, n_fft=256, source_step_mm=2.5, min_source_rows=5,
                               window_um=150.0, workers=1)


def _lstsq_residual(A: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    c, *_ = np.linalg.lstsq(A, d, rcond=None)
    return d - A @ c, c


def bow_um(x_mm: np.ndarray, y_mm: np.ndarray, defocus_um: float, spherical_um: float) -> np.ndarray:
    """``blank_bow`` surface (µm) at blank coordinates: Zernike (2,0) and (4,0),
    RMS-normalised over the ``BOW_REF_RADIUS_MM`` disc (:mod:`.effects`)."""
    out = np.zeros(np.broadcast(x_mm, y_mm).shape)
    if defocus_um:
        out = out + defocus_um * _bow_term(2, x_mm, y_mm)
    if spherical_um:
        out = out + spherical_um * _bow_term(4, x_mm, y_mm)
    return out


_BOW_TERMS: OrderedDict = OrderedDict()


def _bow_term(n: int, x_mm, y_mm) -> np.ndarray:
    """``zernike_xy(n, 0, x_mm, y_mm, BOW_REF_RADIUS_MM)`` (read-only), memoised on the
    coordinates' bytes: a fit with the bow free evaluates it on the same grid thousands of
    times (measured: 6 % of the CPU time of a diagnosis of profiles + map + PSF image); the
    values are those of a fresh evaluation."""
    x, y = np.asarray(x_mm, dtype=float), np.asarray(y_mm, dtype=float)
    key = (n, x.shape, y.shape, x.tobytes(), y.tobytes())
    z = _BOW_TERMS.get(key)
    if z is None:
        z = zernike_xy(n, 0, x, y, BOW_REF_RADIUS_MM)
        z.flags.writeable = False
        _BOW_TERMS[key] = z
        if len(_BOW_TERMS) > 16:
            _BOW_TERMS.popitem(last=False)
    else:
        _BOW_TERMS.move_to_end(key)
    return z


def quilt_parts(quilt: QuiltComponents | None, x_mm: np.ndarray, y_mm: np.ndarray) -> tuple | None:
    """``(F_y, H, C, F)`` of the nominal's quilt (µm) at blank coordinates (:mod:`.quilt`):
    the parts ``quilt_shape`` rescales and the whole fitted quilt ``F = F_x + F_y + H + C``
    (what separates the smooth figure from the map); None without a quilt fit."""
    if quilt is None:
        return None
    fy, hh, cc = quilt.fundamental_y_um(x_mm, y_mm), quilt.harmonics_um(x_mm, y_mm), quilt.cross_um(x_mm, y_mm)
    return fy, hh, cc, quilt.fundamental_x_um(x_mm, y_mm) + fy + hh + cc


def blank_shape_um(base_um: np.ndarray, x_mm: np.ndarray, y_mm: np.ndarray, p: dict,
                   quilt: tuple | None = None) -> np.ndarray:
    """Deformation ``base_um`` (µm, at blank coordinates ``x_mm``, ``y_mm``) changed by the
    blank effects in ``p``: the quilt's shape (``quilt`` = :func:`quilt_parts` at the same
    points: ``+ (rho - 1) F_y + (h - 1) H + (c - 1) C + (g - 1) R`` with ``R`` the smooth
    figure, ``base_um`` minus its quilt), then times
    ``1 + (plating_grad_x x + plating_grad_y y) / 70 mm`` (plating gradient: it scales the
    local deformation, quilt included), plus the blank bow (:func:`bow_um`). Shared by the
    map and the spectrograph-image models."""
    rho, h = p.get("quilt_fund_xy_ratio", 1.0), p.get("quilt_harmonics_ratio", 1.0)
    c, g = p.get("quilt_cross_ratio", 1.0), p.get("quilt_figure_ratio", 1.0)
    if quilt is not None and (rho != 1.0 or h != 1.0 or c != 1.0 or g != 1.0):
        fy, hh, cc, whole = quilt
        figure = base_um - whole
        base_um = base_um + (rho - 1.0) * fy + (h - 1.0) * hh + (c - 1.0) * cc + (g - 1.0) * figure
    gx, gy = p.get("plating_grad_x", 0.0), p.get("plating_grad_y", 0.0)
    if gx or gy:
        base_um = base_um * (1.0 + (gx * x_mm + gy * y_mm) / PLATING_GRADIENT_REF_MM)
    b2, b4 = p.get("bow_defocus_um", 0.0), p.get("bow_spherical_um", 0.0)
    if b2 or b4:
        base_um = base_um + bow_um(x_mm, y_mm, b2, b4)
    return base_um


def blank_bow_map(sag: SagMap, defocus_um: float, spherical_um: float) -> SagMap:
    """``sag`` plus the ``blank_bow`` surface (same grid)."""
    return sag.with_sag(blank_shape_um(sag.sag_um, *sag.grid(), {"bow_defocus_um": defocus_um,
                                                                   "bow_spherical_um": spherical_um}))


def plating_gradient_map(sag: SagMap, gx: float, gy: float) -> SagMap:
    """``sag`` times ``1 + (gx x + gy y) / 70 mm`` (blank coordinates): a linear NiP
    thickness gradient scales the local deformation (:mod:`.effects`, ``plating_gradient``)."""
    return sag.with_sag(blank_shape_um(sag.sag_um, *sag.grid(), {"plating_grad_x": gx, "plating_grad_y": gy}))


class SurfaceForward:
    """Cold-minus-warm surface map model: ``k * (g(q) * (S0(q) + Q(q)) + B(q)) + astigmatism``
    with ``q = R^-1(p - d)`` the blank coordinates of measured point ``p``, ``Q`` the
    quilt-shape change (:func:`blank_shape_um`),
    ``g(q) = 1 + (plating_grad_x q_x + plating_grad_y q_y) / 70 mm`` (plating gradient)
    and ``B`` the blank bow (:func:`bow_um`).

    ``k = thermal_factor(T_meas + temperature_offset_K, cold_K) * scale_<blank>``;
    ``S0`` is the nominal map at the simulation's ``cold_K``; the astigmatism is
    RMS-normalised Zernike (2, ±2) over the measurement aperture disc.
    """

    kind = "surface"
    #: nuisances solved inside :meth:`residual` (piston, x and y tilt); no position nuisance
    nuisance_count, n_shift, delta0_um = 3, 0, 0.0

    def __init__(self, data: SurfaceData, nominal: SagMap, cold_K: float, warm_K: float = 293.0,
                 materials: tuple[str, str] = DEFAULT_MATERIALS):
        m = data.measurement
        self.name, self.blank, self.data = m.name, m.blank, np.asarray(data.sag_um, float)
        self.x, self.y = np.asarray(data.x_mm, float), np.asarray(data.y_mm, float)
        self.n = self.data.size
        self.T_K, self.cold_K, self.warm_K = m.temperature_K, cold_K, warm_K
        self.materials = tuple(materials)  # (substrate, film): their mismatch sets the thermal factor
        self.radius_mm = 0.5 * m.aperture_diameter_mm
        s = np.where(np.isfinite(nominal.sag_um), nominal.sag_um, 0.0)
        self._interp = RegularGridInterpolator((nominal.y_mm, nominal.x_mm), s, bounds_error=False, fill_value=np.nan)
        self._valid = RegularGridInterpolator((nominal.y_mm, nominal.x_mm), np.isfinite(nominal.sag_um).astype(float),
                                              bounds_error=False, fill_value=0.0)
        self.base = self._sample(self.x, self.y)
        bad = ~np.isfinite(self.base)
        if bad.any():
            raise ValueError(f"measurement {m.name!r}: {int(bad.sum())} samples inside aperture_diameter_mm="
                             f"{m.aperture_diameter_mm} fall outside the nominal map")
        self.z22 = zernike_xy(2, 2, self.x, self.y, self.radius_mm)
        self.z2m2 = zernike_xy(2, -2, self.x, self.y, self.radius_mm)
        self.nuisance = np.column_stack([np.ones(self.n), self.x / self.radius_mm, self.y / self.radius_mm])
        self.noise_known = m.noise_um
        self.quilt = quilt_components(nominal)
        self._quilt_at = quilt_parts(self.quilt, self.x, self.y)

    def _sample(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        pts = np.column_stack([y, x])
        v = self._interp(pts)
        return np.where(self._valid(pts) > 0.999, v, np.nan)

    def factor(self, p: dict) -> float:
        k = thermal_factor(self.T_K + p.get("temperature_offset_K", 0.0), self.cold_K, self.warm_K, *self.materials)
        return k * p.get(f"scale_{self.blank}", 1.0)

    def predict(self, p: dict) -> np.ndarray:
        """Model sag (µm) at the measured points, before piston/tilt."""
        dx, dy, rot = p.get("reg_dx_mm", 0.0), p.get("reg_dy_mm", 0.0), p.get("reg_rot_deg", 0.0)
        if dx or dy or rot:
            c, s = math.cos(math.radians(rot)), math.sin(math.radians(rot))
            xr, yr = self.x - dx, self.y - dy
            qx, qy = c * xr + s * yr, -s * xr + c * yr
            base = self._sample(qx, qy)
            off = ~np.isfinite(base)
            base = np.where(off, 0.0, base)  # points moved off the map: no deformation there
            quilt = quilt_parts(self.quilt, qx, qy)
            quilt = None if quilt is None else tuple(np.where(off, 0.0, c) for c in quilt)
        else:
            base, qx, qy, quilt = self.base, self.x, self.y, self._quilt_at
        base = blank_shape_um(base, qx, qy, p, quilt)
        return self.factor(p) * base + p.get("astig_0_um", 0.0) * self.z22 + p.get("astig_45_um", 0.0) * self.z2m2

    def residual(self, p: dict, delta_um: float = 0.0, mask: np.ndarray | None = None) -> np.ndarray:
        """Data minus model with piston and tilt fitted on ``mask`` (µm); ``delta_um`` unused."""
        sel = slice(None) if mask is None else mask
        r, _ = _lstsq_residual(self.nuisance[sel], self.data[sel] - self.predict(p)[sel])
        return r

    def estimate_noise(self, nominal_residual: np.ndarray) -> float:
        """White-noise sigma (µm) from the map itself: cubic prediction along its rows."""
        return estimate_noise(self.x, self.data, rows=self.y)

    def fitted(self, p: dict, mask: np.ndarray | None = None) -> np.ndarray:
        """Full model (with the fitted piston/tilt) at all points (µm)."""
        sel = slice(None) if mask is None else mask
        m = self.predict(p)
        _, c = _lstsq_residual(self.nuisance[sel], self.data[sel] - m[sel])
        return m + self.nuisance @ c


#: Parameters that change the spectrograph image (profiles and PSF images) beyond the
#: deformation's overall factor: the memo key of the image models. Every parameter of a
#: library effect that changes a profile or an image and is not a rescaling (``Effect.rescales``).
PROFILE_KEYS = tuple(p.name for e in LIBRARY.values() if set(e.kinds) & {"line_profile", "psf_image"} and not e.rescales
                     for p in e.parameters)


#: Pupil Zernike terms of other orders than the collimator's, set only by the diagnostic
#: alternative of :mod:`.pupil_orders` (not a library effect): parameter -> (n, m),
#: RMS-normalised wavefront (µm) over the 110 mm pupil, null 0.
OTHER_ORDER_TERMS = {"pupil_spherical_um": (4, 0), "pupil_trefoil_0_um": (3, 3), "pupil_trefoil_30_um": (3, -3),
                     "pupil_coma2_um": (5, 1)}


def collimator_terms(p: dict) -> dict:
    """The spectrograph's pupil Zernike terms {(n, m): µm}: the default collimator plus the
    ``collimator_wfe`` effect's coma Z(3,1), defocus Z(2,0), oblique astigmatism Z(2,-2),
    plus any :data:`OTHER_ORDER_TERMS` in ``p``."""
    coll = dict(DEFAULT_COLLIMATOR_ZERNIKE_UM)
    for key, nm in (("coll_coma_um", (3, 1)), ("coll_defocus_um", (2, 0)), ("coll_astig45_um", (2, -2)),
                    *OTHER_ORDER_TERMS.items()):
        coll[nm] = coll.get(nm, 0.0) + p.get(key, 0.0)
    return coll


def profile_curve(grating: str, wavelength_um: float, order: int, pixel_scale_mas: int, sag: SagMap | None,
                  p: dict, slit_position: float = 0.0, settings: LsfSettings = FIT_LSF_SETTINGS):
    """Detected line profile (offset_um, unit-area intensity) for effect parameters ``p``.

    ``p`` may hold ``pupil_x_mm``, ``pupil_y_mm``, ``coll_coma_um``, ``coll_defocus_um``,
    ``coll_astig45_um`` and ``slit_image_width_um``; the sag is passed already scaled.
    """
    from optics.grating import get_grating

    g = get_grating(grating)
    w = p.get("slit_image_width_um", NOMINAL_SLIT_UM)
    if w != NOMINAL_SLIT_UM:
        g = replace(g, slit_image_width_um=g.slit_image_width_um * w / NOMINAL_SLIT_UM)
    r = line_profile(g, wavelength_um, pixel_scale_mas, sag, order=order,
                     pupil_shift_mm=(p.get("pupil_x_mm", 0.0), p.get("pupil_y_mm", 0.0)),
                     slit_position=slit_position, collimator_zernike_um=collimator_terms(p), settings=settings)
    return r.detected.offset_um, r.detected.intensity


class SpectrographImageModel:
    """What the spectrograph-image models (line profiles, PSF images) share: the
    deformation's overall factor and a memo of the model per physical parameter set
    (varying only the nuisances then costs an interpolation)."""

    _KEYS = PROFILE_KEYS + tuple(OTHER_ORDER_TERMS)

    def _setup(self, m, nominal: SagMap, cold_K: float, warm_K: float, settings, cache_size: int,
               materials: tuple[str, str] = DEFAULT_MATERIALS) -> None:
        self.m, self.name, self.blank = m, m.name, m.blank
        self.materials = tuple(materials)  # (substrate, film): their mismatch sets the thermal factor
        self.nominal, self.cold_K, self.warm_K, self.settings = nominal, cold_K, warm_K, settings
        self._grid = nominal.grid()
        self.quilt = quilt_components(nominal)
        self._quilt_at = quilt_parts(self.quilt, *self._grid)
        self._nulls = {q: parameter_spec(q).null if q in PROFILE_KEYS else 0.0 for q in self._KEYS}
        self._cache: OrderedDict = OrderedDict()
        self._cache_size = cache_size
        self.noise_known = m.noise_rel

    def factor(self, p: dict) -> float:
        k = thermal_factor(self.cold_K + p.get("temperature_offset_K", 0.0), self.cold_K, self.warm_K,
                           *self.materials)
        return k * p.get(f"scale_{self.blank}", 1.0)

    def _memo(self, p: dict, build):
        """``build(sag, p)`` for the grating's deformed sag, memoised on the physical parameters."""
        k = self.factor(p)
        key = (round(k, 12),) + tuple(round(float(p.get(q, self._nulls[q])), 12) for q in self._KEYS)
        hit = self._cache.get(key)
        if hit is not None:
            self._cache.move_to_end(key)
            return hit
        out = build(self.nominal.with_sag(k * blank_shape_um(self.nominal.sag_um, *self._grid, p, self._quilt_at)), p)
        self._cache[key] = out
        if len(self._cache) > self._cache_size:
            self._cache.popitem(last=False)
        return out


class ProfileForward(SpectrographImageModel):
    """Line-profile model: ``flux * P(u - delta_um; params) + background``."""

    kind = "line_profile"
    #: nuisances solved inside :meth:`residual` (flux, background) and position nuisances
    #: that are fit parameters (the offset shift ``delta_um``)
    nuisance_count, n_shift = 2, 1

    def __init__(self, data: ProfileData, nominal: SagMap, cold_K: float, warm_K: float = 293.0,
                 settings: LsfSettings = FIT_LSF_SETTINGS, cache_size: int = 512,
                 materials: tuple[str, str] = DEFAULT_MATERIALS):
        self._setup(data.measurement, nominal, cold_K, warm_K, settings, cache_size, materials)
        self.x = np.asarray(data.offset_um, float)
        self.data = np.asarray(data.intensity, float)
        self.n = self.data.size
        self.delta0_um = self._initial_shift()

    def curve(self, p: dict) -> CubicSpline:
        """Memoised spline of the model profile (unit area) for the physical parameters."""
        def build(sag, p):
            u, y = profile_curve(self.m.grating, self.m.wavelength_um, self.m.order, self.m.pixel_scale_mas, sag, p,
                                 self.m.slit_position, self.settings)
            return CubicSpline(u, y, extrapolate=False)

        return self._memo(p, build)

    def predict(self, p: dict, delta_um: float = 0.0) -> np.ndarray:
        """Model profile at the measured offsets shifted by ``delta_um`` (before flux/background)."""
        v = self.curve(p)(self.x - delta_um)
        return np.where(np.isfinite(v), v, 0.0)

    def _design(self, p, delta_um):
        return np.column_stack([self.predict(p, delta_um), np.ones(self.n)])

    def estimate_noise(self, nominal_residual: np.ndarray) -> float:
        """White-noise sigma (fraction of the data peak) from the profile itself."""
        return estimate_noise(self.x, self.data)

    def residual(self, p: dict, delta_um: float = 0.0, mask: np.ndarray | None = None) -> np.ndarray:
        """Data minus model with flux and background fitted on ``mask`` (fraction of the data peak)."""
        sel = slice(None) if mask is None else mask
        r, _ = _lstsq_residual(self._design(p, delta_um)[sel], self.data[sel])
        return r

    def fitted(self, p: dict, delta_um: float = 0.0, mask: np.ndarray | None = None) -> np.ndarray:
        sel = slice(None) if mask is None else mask
        A = self._design(p, delta_um)
        _, c = _lstsq_residual(A[sel], self.data[sel])
        return A @ c

    def _initial_shift(self) -> float:
        """Offset shift of the nominal model by a 1-µm grid search over ±40 µm (the data
        may be shifted by more than the fit's basin)."""
        grid = np.arange(-40.0, 40.5, 1.0)
        cost = [float(np.sum(self.residual({}, d) ** 2)) for d in grid]
        return float(grid[int(np.argmin(cost))])
