"""Forward models of each measurement as a function of the effect parameters.

Both models take a parameter dict (missing keys = null values, see :mod:`.effects`)
and return the prediction at the measured samples *before* the nuisance parameters;
:meth:`residual` then removes the nuisances the data need:

* surface maps: piston and x/y tilt (linear, projected out by least squares);
* line profiles: an offset shift ``delta_um`` (nonlinear, a fit parameter), a flux
  scale and a constant background (linear, projected out).

What each effect does is its own (the hooks of :class:`.effects.Effect`); the functions
here apply every effect of the library (and of its diagnostic alternatives) in the hooks'
order: :func:`deformation_factor`, :func:`blank_coordinates`, :func:`blank_shape_um`,
:func:`map_terms_um`, :func:`collimator_terms` and :func:`spectrograph_optics`.

Speed: the nominal map is sampled once; amplitude and temperature are exact rescalings;
moved map points (registration) re-sample the map by bilinear interpolation; line
profiles are recomputed with coarser-than-default :class:`optics.lineprofile.LsfSettings`
(≤ 0.5 % L1 from the defaults, ~4x faster) and memoised on the physical parameters, so
varying only the offset shift costs an interpolation.
"""

from __future__ import annotations

from collections import OrderedDict

import numpy as np
from scipy.interpolate import CubicSpline, RegularGridInterpolator

from optics.grating import SPIFFI
from optics.lineprofile import LsfSettings, line_profile, line_profile_footprint_mm
from optics.pupil import DEFAULT_COLLIMATOR_ZERNIKE_UM
from optics.sagmap import SagMap
from optics.zernike import zernike_xy

from .effects import LIBRARY, SHAPE_STAGES, SpectrographOptics, forward_effects
from .manifest import NOISE_RANGES, ProfileData, SurfaceData
from .noise import (SCATTERED_NOISE_REL_SD_SQRT_N, SIGNAL_DEPENDENT_NOISE_REL_SD_SQRT_N, estimate_noise,
                    WING_LEVEL, RssTraces, estimate_noise_signal_dependent)
from .nominal import DEFAULT_MATERIALS, thermal_factor
from .quilt import QuiltComponents, quilt_components

__all__ = ["FIT_LSF_SETTINGS", "FOOTPRINT_MARGIN_CELLS", "NOISE_LEAK_LIMIT", "PROFILE_KEYS", "SurfaceForward", "SpectrographImageModel", "OpticsCurve", "ProfileForward", "profile_curve",
           "true_temperature", "deformation_factor", "blank_coordinates", "blank_shape_um", "map_terms_um",
           "collimator_terms", "spectrograph_optics", "quilt_parts", "lstsq_residual", "MAX_COUPLING", "coupled_lstsq", "coupled_at"]

#: A profile's noise estimate is refused when the noise-free nominal line, sampled like
#: the data, reads as at least this fraction of it (:meth:`ProfileForward.estimate_noise`).
#: The measured line's own leakage can exceed the nominal's 2.5x (a quilted line with
#: deeper structure than the nominal, sampled once per pixel: 0.097 against 0.039), so at
#: this limit it may reach half the estimate (sigma then ~13 % high, beyond the
#: estimator's statistical error). Measured on profiles made outside the project, against
#: the signal-dependent estimate: 0.000-0.009 for 1-3 µm steps, 0.30-0.37 for 18 µm (one
#: sample per pixel).
NOISE_LEAK_LIMIT = 0.2

#: Line-profile sampling used while fitting (measured: 0.1-0.45 % L1 from the defaults).
FIT_LSF_SETTINGS = LsfSettings(detector_step_um=1.5, n_fft=256, source_step_mm=2.5, min_source_rows=5,
                               window_um=150.0, workers=1)


def lstsq_residual(A: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(d - A c, c)`` for the least-squares coefficients ``c`` of ``A c = d``."""
    c, *_ = np.linalg.lstsq(A, d, rcond=None)
    return d - A @ c, c


#: Grid cells kept around a spectrograph image's footprint on the map
#: (:meth:`SpectrographImageModel._window`): one holds the bilinear stencil of a point on
#: the footprint's edge, the second a point that rounding puts on the next node.
FOOTPRINT_MARGIN_CELLS = 2
#: Windows of the nominal's grid a spectrograph-image model keeps
#: (:meth:`SpectrographImageModel._part`): a fit that moves the pupil moves the window, and a
#: window costs a copy of a few arrays, small beside the image it serves.
PARTS_MEMO_SIZE = 8


#: Largest inter-pixel coupling a line-profile model fits (fraction of a pixel's signal
#: read in each neighbour along x). HAWAII-type arrays measure 1-2 %; 5 % leaves room for
#: another detector without letting the nuisance take up a broadened line.
MAX_COUPLING = 0.05


def coupled_lstsq(line: np.ndarray, neighbours: np.ndarray, d: np.ndarray,
                  max_coupling: float = MAX_COUPLING) -> tuple[np.ndarray, float, float, float]:
    """Least-squares ``d ~ flux * (line + c * neighbours) + background`` with the coupling
    ``c`` in ``[0, max_coupling]``.

    ``neighbours`` is what coupling moves: the line one pixel either side minus twice the
    line (the kernel ``[c, 1 - 2c, c]`` keeps the flux). With ``c`` free the model is linear
    in ``(flux, flux * c, background)``; where that optimum has ``c`` outside the range (or
    no positive flux), both faces ``c = 0`` and ``c = max_coupling`` are solved and the one
    of lower residual kept, which is the bounded optimum of the quadratic on that face.

    Returns
    -------
    (d - model, flux, c, background)
    """
    r, (a, b, bg) = lstsq_residual(np.column_stack([line, neighbours, np.ones_like(line)]), d)
    if a > 0 and 0.0 <= b / a <= max_coupling:
        return r, float(a), float(b / a), float(bg)
    faces = [coupled_at(line, neighbours, d, c) for c in (0.0, max_coupling)]
    return min(faces, key=lambda face: float(face[0] @ face[0]))


def coupled_at(line: np.ndarray, neighbours: np.ndarray, d: np.ndarray,
               c: float) -> tuple[np.ndarray, float, float, float]:
    """:func:`coupled_lstsq` with the coupling held at ``c``: ``(d - model, flux, c, background)``."""
    r, (flux, bg) = lstsq_residual(np.column_stack([line + c * neighbours, np.ones_like(line)]), d)
    return r, float(flux), c, float(bg)


def quilt_parts(quilt: QuiltComponents | None, x_mm: np.ndarray, y_mm: np.ndarray) -> dict | None:
    """The nominal's quilt (µm) at blank coordinates (:mod:`.quilt`): the parts ``quilt_shape``
    rescales, by part name (``fundamental_y``, ``cross``, ``harmonics``, ``x_harmonics``), and
    ``whole``, the whole fitted quilt ``F`` (those and ``F_x``: what separates the smooth
    figure from the map); None without a quilt fit."""
    if quilt is None:
        return None
    parts = quilt.parts_um(x_mm, y_mm)
    whole = sum(parts.values())
    del parts["fundamental_x"]  # its amplitude is the rescalings', not the shape's
    return {**parts, "whole": whole}


def true_temperature(temperature_K: float, p: dict) -> float:
    """The true temperature (K) of a measurement stated at ``temperature_K`` (``Effect.temperature``)."""
    for e in forward_effects():
        if e.temperature is not None:
            temperature_K = e.temperature(temperature_K, p)
    return temperature_K


def deformation_factor(p: dict, blank: str, temperature_K: float, cold_K: float, warm_K: float = 293.0,
                       materials: tuple[str, str] = DEFAULT_MATERIALS) -> float:
    """The deformation's overall factor for a measurement of ``blank`` stated at
    ``temperature_K`` against the nominal at ``cold_K``: the thermal factor at the true
    temperature times every ``Effect.scale``."""
    k = thermal_factor(true_temperature(temperature_K, p), cold_K, warm_K, *materials)
    for e in forward_effects():
        if e.scale is not None:
            k = k * e.scale(p, blank)
    return k


def blank_coordinates(x_mm: np.ndarray, y_mm: np.ndarray, p: dict) -> tuple | None:
    """Blank coordinates of a map's measured points (``Effect.coordinates``), None where no
    effect moves them."""
    moved = None
    for e in forward_effects():
        if e.coordinates is not None:
            q = e.coordinates(x_mm, y_mm, p)
            if q is not None:
                moved = x_mm, y_mm = q
    return moved


def blank_shape_um(base_um: np.ndarray, x_mm: np.ndarray, y_mm: np.ndarray, p: dict,
                   quilt: tuple | None = None) -> np.ndarray:
    """Deformation ``base_um`` (µm, at blank coordinates ``x_mm``, ``y_mm``) changed by the
    ``Effect.shape`` transforms of the parameters ``p``, stage by stage
    (:data:`.effects.SHAPE_STAGES`; ``quilt`` = :func:`quilt_parts` at the same points).
    Shared by the map and the spectrograph-image models and the synthetic truths."""
    for stage in SHAPE_STAGES:
        for e in forward_effects():
            if e.shape is not None and e.shape_stage == stage:
                base_um = e.shape(base_um, x_mm, y_mm, p, quilt)
    return base_um


def map_terms(x_mm: np.ndarray, y_mm: np.ndarray, radius_mm: float) -> tuple:
    """``((parameter, null, Z), ...)``: every ``Effect.map_zernike`` term, RMS-normalised
    over the ``radius_mm`` disc, at the points."""
    nulls = {q.name: q.null for e in forward_effects() for q in e.parameters}
    return tuple((name, nulls[name], zernike_xy(n, m, x_mm, y_mm, radius_mm)) for e in forward_effects()
                 for name, (n, m) in e.map_zernike)


def map_terms_um(x_mm: np.ndarray, y_mm: np.ndarray, radius_mm: float, p: dict):
    """The ``Effect.map_zernike`` surface (µm) of the parameters ``p`` at the points, over
    the ``radius_mm`` disc; None if ``p`` holds none of their parameters."""
    out = None
    for name, _, z in map_terms(x_mm, y_mm, radius_mm):
        if name in p:
            out = p[name] * z if out is None else out + p[name] * z
    return out


class SurfaceForward:
    """Cold-minus-warm surface map model: ``k * shape(S0(q), q) + Z`` with ``q`` the blank
    coordinates of the measured points (:func:`blank_coordinates`; e.g. ``q = R^-1(p - d)``
    of a registration), ``S0`` the nominal map at the simulation's ``cold_K``, ``shape`` the
    blank-shape effects (:func:`blank_shape_um`: quilt shape, plating gradient, bow), ``k``
    the overall factor at the map's stated temperature (:func:`deformation_factor`:
    temperature offset, ``scale_<blank>``) and ``Z`` the map terms (:func:`map_terms`:
    astigmatism, RMS-normalised over the measurement aperture disc).
    """

    kind = "surface"
    #: nuisances solved inside :meth:`residual` (piston, x and y tilt); no position nuisance
    nuisance_count, n_shift, delta0_um = 3, 0, 0.0
    #: a map's noise is white in the gap test (its smooth errors are the two-part model's)
    correlated_noise = None

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
        self._map_terms = map_terms(self.x, self.y, self.radius_mm)
        self.nuisance = np.column_stack([np.ones(self.n), self.x / self.radius_mm, self.y / self.radius_mm])
        self.noise_known = m.noise_um
        self.points_noise_um, self.n_points = data.points_noise_um, data.n_points
        self.scattered = data.scattered  # the samples are the file's scattered points themselves
        self.node_noise_factor, self.samples_noise_um = data.node_noise_factor, data.samples_noise_um
        self.quilt = quilt_components(nominal)
        self._quilt_at = quilt_parts(self.quilt, self.x, self.y)

    def _sample(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        pts = np.column_stack([y, x])
        v = self._interp(pts)
        return np.where(self._valid(pts) > 0.999, v, np.nan)

    def factor(self, p: dict) -> float:
        return deformation_factor(p, self.blank, self.T_K, self.cold_K, self.warm_K, self.materials)

    def predict(self, p: dict) -> np.ndarray:
        """Model sag (µm) at the measured points, before piston/tilt."""
        moved = blank_coordinates(self.x, self.y, p)
        if moved is not None:
            qx, qy = moved
            base = self._sample(qx, qy)
            off = ~np.isfinite(base)
            base = np.where(off, 0.0, base)  # points moved off the map: no deformation there
            quilt = quilt_parts(self.quilt, qx, qy)
            quilt = None if quilt is None else {k: np.where(off, 0.0, c) for k, c in quilt.items()}
        else:
            base, qx, qy, quilt = self.base, self.x, self.y, self._quilt_at
        out = self.factor(p) * blank_shape_um(base, qx, qy, p, quilt)
        for name, null, z in self._map_terms:
            out = out + p.get(name, null) * z
        return out

    def residual(self, p: dict, delta_um: float = 0.0, mask: np.ndarray | None = None) -> np.ndarray:
        """Data minus model with piston and tilt fitted on ``mask`` (µm); ``delta_um`` unused."""
        sel = slice(None) if mask is None else mask
        r, _ = lstsq_residual(self.nuisance[sel], self.data[sel] - self.predict(p)[sel])
        return r

    def estimate_noise(self, nominal_residual: np.ndarray) -> float:
        """White-noise sigma (µm) from the data: scattered points, the points' own (local
        2-D cubic, :func:`.noise.estimate_noise_scattered`); grid nodes interpolated from
        scattered points (a gridded map saved to a grid format), that times the nodes'
        interpolation factor (:attr:`.manifest.SurfaceData.samples_noise_um`: a node
        averages its triangle's three points, and its errors are correlated with its
        neighbours', which the row cubic reads as signal); else cubic prediction along the
        map's rows."""
        if self.samples_noise_um is not None:
            return self.samples_noise_um
        return estimate_noise(self.x, self.data, rows=self.y)

    @property
    def noise_rel_sd(self) -> float | None:
        """Relative standard deviation of the estimated noise when it comes from scattered
        points (:data:`.noise.SCATTERED_NOISE_REL_SD_SQRT_N` over the square root of their
        count; the nodes' factor is computed from the layout, without error), else None
        (:func:`.gap._noise_rel_sd` then uses the map's own)."""
        if self.points_noise_um is None or not self.n_points:
            return None
        return SCATTERED_NOISE_REL_SD_SQRT_N / np.sqrt(self.n_points)

    @property
    def noise_from(self) -> str:
        """Where the map's noise comes from, for the report."""
        if self.noise_known:
            return "manifest noise_um"
        if self.points_noise_um is not None:
            text = (f"the {self.n_points} points (local cubic over each point's 20 nearest; "
                    f"{1e3 * self.points_noise_um:.3g} nm)")
            if self.scattered:
                return text + f", fitted at the {self.n} points inside the aperture"
            if self.node_noise_factor is not None:
                text += f", times {self.node_noise_factor:.3f} for the grid nodes' interpolation weights"
            return text
        return "the map (cubic prediction along its rows)"

    def fitted(self, p: dict, mask: np.ndarray | None = None) -> np.ndarray:
        """Full model (with the fitted piston/tilt) at all points (µm)."""
        sel = slice(None) if mask is None else mask
        m = self.predict(p)
        _, c = lstsq_residual(self.nuisance[sel], self.data[sel] - m[sel])
        return m + self.nuisance @ c


#: Parameters that change the spectrograph image (profiles and PSF images) beyond the
#: deformation's overall factor: the memo key of the image models. Every parameter of a
#: library effect that changes a profile or an image and is not a rescaling (``Effect.rescales``).
PROFILE_KEYS = tuple(p.name for e in LIBRARY.values() if set(e.kinds) & {"line_profile", "psf_image"} and not e.rescales
                     for p in e.parameters)


def collimator_terms(p: dict) -> dict:
    """The spectrograph's pupil Zernike terms {(n, m): µm}: the default collimator plus
    every ``Effect.pupil_zernike`` term of the library and its alternatives in ``p``."""
    coll = dict(DEFAULT_COLLIMATOR_ZERNIKE_UM)
    for e in forward_effects():
        for key, nm in e.pupil_zernike:
            coll[nm] = coll.get(nm, 0.0) + p.get(key, 0.0)
    return coll


def spectrograph_optics(grating, p: dict) -> SpectrographOptics:
    """The spectrograph's optics for effect parameters ``p``: ``grating`` (name or
    :class:`optics.grating.Grating`), no footprint offset and :func:`collimator_terms`,
    changed by every ``Effect.optics``."""
    from optics.grating import get_grating

    o = SpectrographOptics(get_grating(grating), (0.0, 0.0), collimator_terms(p))
    for e in forward_effects():
        if e.optics is not None:
            o = e.optics(o, p)
    return o


def profile_curve(grating: str, wavelength_um: float, order: int, pixel_scale_mas: int, sag: SagMap | None,
                  p: dict, slit_position: float = 0.0, settings: LsfSettings = FIT_LSF_SETTINGS,
                  detected: bool = True):
    """Detected line profile (offset_um, unit-area intensity) for effect parameters ``p``
    (those of the spectrograph: :func:`spectrograph_optics`, then, with ``detected``, every
    ``Effect.detected``: :func:`detected_profile`); the sag is passed already scaled and shaped."""
    o = spectrograph_optics(grating, p)
    r = line_profile(o.grating, wavelength_um, pixel_scale_mas, sag, order=order, pupil_shift_mm=o.pupil_shift_mm,
                     slit_position=slit_position, collimator_zernike_um=o.collimator_zernike_um, settings=settings)
    u, y = r.detected.offset_um, r.detected.intensity
    return u, (detected_profile(u, y, p) if detected else y)


def detected_profile(offset_um: np.ndarray, intensity: np.ndarray, p: dict) -> np.ndarray:
    """The profile the optics form (on its uniform ``offset_um`` grid) changed by every
    ``Effect.detected`` of the parameters ``p`` (light the detector side adds)."""
    for e in forward_effects():
        if e.detected is not None:
            intensity = e.detected(offset_um, intensity, p)
    return intensity


class SpectrographImageModel:
    """What the spectrograph-image models (line profiles, PSF images) share: the
    deformation's overall factor and a memo of the model per physical parameter set
    (varying only the nuisances then costs an interpolation)."""

    #: a stated correlated noise (:class:`.noise.CorrelatedNoise`): line profiles only
    correlated_noise = None

    #: the memo key's parameters and their nulls: :data:`PROFILE_KEYS` and the alternatives' likewise,
    #: except those acting after the optics (``Effect.detected``), which the line-profile model
    #: applies to the memoised optics (a change of them then costs a convolution, not an image)
    _NULLS = {q.name: q.null for e in forward_effects() if set(e.kinds) & {"line_profile", "psf_image"}
              and not e.rescales and e.detected is None for q in e.parameters}
    _KEYS = tuple(_NULLS)
    _DETECTED_NULLS = {q.name: q.null for e in forward_effects() if e.detected is not None for q in e.parameters}

    def _setup(self, m, nominal: SagMap, cold_K: float, warm_K: float, settings, cache_size: int,
               materials: tuple[str, str] = DEFAULT_MATERIALS) -> None:
        self.m, self.name, self.blank = m, m.name, m.blank
        self.materials = tuple(materials)  # (substrate, film): their mismatch sets the thermal factor
        self.nominal, self.cold_K, self.warm_K, self.settings = nominal, cold_K, warm_K, settings
        self._grid = nominal.grid()
        self.quilt = quilt_components(nominal)
        self._quilt_at = quilt_parts(self.quilt, *self._grid)
        self._cache: OrderedDict = OrderedDict()
        self._cache_size = cache_size
        self._parts: dict = {}
        self.noise_known = m.noise_rel
        self.departure = None

    def carry_departure(self, departure) -> None:
        """Add a measured map's departure from the model's blank shape
        (:class:`.map_departure.MapDeparture`, per unit deformation factor on the nominal's
        grid) to the shape every image of this model is formed with."""
        self.departure = departure
        self._cache.clear()
        self._parts.clear()

    def factor(self, p: dict) -> float:
        # taken at the simulation's cold_K: spectrograph data are stated at it
        return deformation_factor(p, self.blank, self.cold_K, self.cold_K, self.warm_K, self.materials)

    def _key(self, p: dict) -> tuple:
        """``(memo key, deformation factor)`` of the parameters ``p``."""
        k = self.factor(p)
        return (round(k, 12),) + tuple(round(float(p.get(q, self._NULLS[q])), 12) for q in self._KEYS), k

    def _footprint_mm(self, p: dict) -> tuple[float, float, float, float] | None:
        """``(x_min, x_max, y_min, y_max)`` (mm) of the map points the model's image of the
        parameters ``p`` reads; None: the whole map."""
        return None

    def _window(self, p: dict) -> tuple[slice, slice] | None:
        """``(rows, columns)`` of the nominal's grid that hold :meth:`_footprint_mm` with
        :data:`FOOTPRINT_MARGIN_CELLS` cells to spare; None where that is not inside the map.

        Every shape effect and the departure act point by point, and the optics read the map
        by bilinear interpolation, so the image formed from this part of the map is the one
        formed from the whole map, while deforming the whole map for each image of a narrow
        pupil costs several times more."""
        box = self._footprint_mm(p)
        if box is None:
            return None
        x, y = self.nominal.x_mm, self.nominal.y_mm
        m = FOOTPRINT_MARGIN_CELLS
        i0, i1 = int(np.searchsorted(x, box[0], "right")) - 1 - m, int(np.searchsorted(x, box[1], "left")) + 1 + m
        j0, j1 = int(np.searchsorted(y, box[2], "right")) - 1 - m, int(np.searchsorted(y, box[3], "left")) + 1 + m
        if i0 < 0 or j0 < 0 or i1 > x.size or j1 > y.size:
            return None
        return slice(j0, j1), slice(i0, i1)

    def _part(self, window: tuple[slice, slice] | None) -> tuple:
        """``(nominal, grid, quilt parts, departure)`` on ``window`` of the nominal's grid
        (:meth:`_window`; None: the whole map), memoised so that the same window gives the
        same arrays (shape effects memoise terms on their coordinate arrays)."""
        departure = None if self.departure is None else self.departure.shape_um
        if window is None:
            return self.nominal, self._grid, self._quilt_at, departure
        ys, xs = window
        key = (ys.start, ys.stop, xs.start, xs.stop)
        hit = self._parts.get(key)
        if hit is not None:
            return hit
        n = self.nominal
        nominal = SagMap(n.x_mm[xs], n.y_mm[ys], np.ascontiguousarray(n.sag_um[ys, xs]), n.label, dict(n.meta))
        grid = tuple(np.ascontiguousarray(g[ys, xs]) for g in self._grid)
        quilt = None if self._quilt_at is None else {k: np.ascontiguousarray(v[ys, xs]) for k, v in self._quilt_at.items()}
        hit = nominal, grid, quilt, None if departure is None else np.ascontiguousarray(departure[ys, xs])
        self._parts[key] = hit
        if len(self._parts) > PARTS_MEMO_SIZE:
            self._parts.pop(next(iter(self._parts)))
        return hit

    def _image(self, p: dict, k: float, build, window: tuple[slice, slice] | None):
        """``build`` for the sag of the parameters ``p`` (deformation factor ``k``) deformed on
        ``window`` of the nominal's grid (:meth:`_window`)."""
        nominal, grid, quilt, departure = self._part(window)
        shape = blank_shape_um(nominal.sag_um, *grid, p, quilt)
        if departure is not None:
            shape = shape + departure
        return build(nominal.with_sag(k * shape), p)

    def _memo(self, p: dict, build):
        """``build(sag, p)`` for the grating's deformed sag, memoised on the physical parameters."""
        key, k = self._key(p)
        hit = self._cache.get(key)
        if hit is not None:
            self._cache.move_to_end(key)
            return hit
        try:
            window = self._window(p)
            out = None if window is None else self._image(p, k, build, window)
        except ValueError:
            out = None  # refused: the whole map's refusal is the one to raise (it names the map's extent)
        if out is None:
            out = self._image(p, k, build, None)
        self._cache[key] = out
        if len(self._cache) > self._cache_size:
            self._cache.popitem(last=False)
        return out


class OpticsCurve:
    """The line profile the optics form (offsets ``u`` µm, intensity ``y``) and its spline,
    built on first use: beside non-null detector terms the profile model is the spline of the
    detected curve instead (:meth:`ProfileForward.curve`), and a spline costs about a fifth of
    the optics' own evaluation (the wings check's fits build one detected spline per optics
    evaluation)."""

    __slots__ = ("u", "y", "_spline")

    def __init__(self, u: np.ndarray, y: np.ndarray):
        self.u, self.y, self._spline = u, y, None

    @property
    def spline(self) -> CubicSpline:
        if self._spline is None:
            self._spline = CubicSpline(self.u, self.y, extrapolate=False)
        return self._spline


class ProfileForward(SpectrographImageModel):
    """Line-profile model: ``flux * C_c[P](u - delta_um; params) + background``, ``C_c`` the
    detector's inter-pixel coupling: a fraction ``c`` of each pixel's signal read in each
    neighbour along x, ``C_c[P](u) = (1 - 2c) P(u) + c P(u - p) + c P(u + p)`` at the pixel
    pitch ``p`` (:func:`coupled_lstsq`).

    Why the coupling is a nuisance of every model, beside flux and background: every
    infrared array couples its pixels capacitively (HAWAII-type arrays: 1-2 % to each
    neighbour), so a measured line is broadened by it whatever the grating does, and the
    spectrograph's own optics cannot hold it. Left out, it is a gap in every profile that the
    library's broadening effects take up (``benchmarks/results_coupling.md``: independent
    truths with 1-3 % coupling, as the truth generator makes every profile). It is fitted,
    not stated, because it is rarely known per detector column at the line's position; it
    is linear in the fit (flux times coupling), so it costs one column of the nuisances'
    least squares. Where the manifest states it (``interpixel_coupling``, a characterised
    detector) the stated value is used and only flux and background are fitted."""

    kind = "line_profile"
    #: nuisances solved inside :meth:`residual` (flux, inter-pixel coupling, background) and
    #: position nuisances that are fit parameters (the offset shift ``delta_um``)
    nuisance_count, n_shift = 3, 1
    #: detector pixel pitch (µm) along x: the distance coupling moves light
    pixel_um = SPIFFI.pixel_um

    def __init__(self, data: ProfileData, nominal: SagMap, cold_K: float, warm_K: float = 293.0,
                 settings: LsfSettings = FIT_LSF_SETTINGS, cache_size: int = 512,
                 materials: tuple[str, str] = DEFAULT_MATERIALS):
        self._setup(data.measurement, nominal, cold_K, warm_K, settings, cache_size, materials)
        self._splines: OrderedDict = OrderedDict()
        self._footprints: dict = {}
        self.x = np.asarray(data.offset_um, float)
        self.data = np.asarray(data.intensity, float)
        self.n = self.data.size
        #: the coupling the manifest states (None: fitted with flux and background)
        self.stated_coupling = data.measurement.interpixel_coupling
        if self.stated_coupling is not None:
            self.nuisance_count = 2
        #: the correlated noise the manifest states (None: white noise only)
        self.correlated_noise = data.measurement.correlated_noise
        self._rss_traces = None  # RssTraces of the stated correlated noise, on first use
        self.delta0_um = self._initial_shift()

    def curve(self, p: dict) -> CubicSpline:
        """Memoised spline of the model profile (unit area) for the physical parameters: the
        optics' profile memoised on the parameters that change it, then the detector side's
        (:func:`detected_profile`)."""
        wings = tuple(round(float(p.get(q, n)), 12) for q, n in self._DETECTED_NULLS.items())
        if wings == tuple(self._DETECTED_NULLS.values()):
            return self._memo(p, self._build).spline
        key = self._key(p)[0] + wings
        hit = self._splines.get(key)
        if hit is None:
            c = self._memo(p, self._build)
            hit = self._splines[key] = CubicSpline(c.u, detected_profile(c.u, c.y, p), extrapolate=False)
            if len(self._splines) > self._cache_size:
                self._splines.popitem(last=False)
        else:
            self._splines.move_to_end(key)
        return hit

    def carry_departure(self, departure) -> None:
        super().carry_departure(departure)
        self._splines.clear()  # the detected curves too: memoised on the parameters only
        self._rss_traces = None  # the nuisances' design is the nominal line's

    def _footprint_mm(self, p: dict) -> tuple[float, float, float, float]:
        # the footprint at no pupil shift, moved by the shift: adding the shift to every
        # point keeps the extremes extreme (rounding is monotonic), so this is the extent
        # of the shifted points themselves, without recomputing the pupil for each shift
        o = spectrograph_optics(self.m.grating, p)
        box = self._footprints.get(o.grating)
        if box is None:
            box = self._footprints[o.grating] = line_profile_footprint_mm(
                o.grating, self.m.wavelength_um, self.m.pixel_scale_mas, order=self.m.order,
                slit_position=self.m.slit_position, settings=self.settings)
            if len(self._footprints) > PARTS_MEMO_SIZE:  # a fitted slit width makes a grating per value
                self._footprints.pop(next(iter(self._footprints)))
        sx, sy = o.pupil_shift_mm
        return box[0] + sx, box[1] + sx, box[2] + sy, box[3] + sy

    def _build(self, sag, p):
        """The profile the optics form for the deformed ``sag`` (:class:`OpticsCurve`)."""
        u, y = profile_curve(self.m.grating, self.m.wavelength_um, self.m.order, self.m.pixel_scale_mas, sag, p,
                             self.m.slit_position, self.settings, detected=False)
        return OpticsCurve(u, y)

    def predict(self, p: dict, delta_um: float = 0.0) -> np.ndarray:
        """Model profile at the measured offsets shifted by ``delta_um`` (before flux/background)."""
        return self._sampled(self.curve(p), delta_um)

    def _sampled(self, curve: CubicSpline, delta_um: float) -> np.ndarray:
        v = curve(self.x - delta_um)
        return np.where(np.isfinite(v), v, 0.0)

    def _line_and_neighbours(self, curve: CubicSpline, delta_um: float) -> tuple[np.ndarray, np.ndarray]:
        """The line at the samples and what inter-pixel coupling moves: the line one pixel
        either side minus twice the line (:func:`coupled_lstsq`)."""
        line = self._sampled(curve, delta_um)
        return line, (self._sampled(curve, delta_um + self.pixel_um) + self._sampled(curve, delta_um - self.pixel_um)
                      - 2.0 * line)

    def _nuisances(self, p, delta_um, mask):
        """(residual on ``mask``, model at every sample, coupling) with flux, coupling and
        background fitted on ``mask`` (:func:`coupled_lstsq`), the coupling held at the
        stated one where the manifest gives it."""
        # one memo lookup for the line and its two neighbours (the lookup, not the spline,
        # is most of a residual's cost once the line is built)
        line, neighbours = self._line_and_neighbours(self.curve(p), delta_um)
        sel = slice(None) if mask is None else mask
        if self.stated_coupling is None:
            r, flux, c, bg = coupled_lstsq(line[sel], neighbours[sel], self.data[sel])
        else:
            r, flux, c, bg = coupled_at(line[sel], neighbours[sel], self.data[sel], self.stated_coupling)
        return r, flux * (line + c * neighbours) + bg, c

    def coupling(self, p: dict, delta_um: float = 0.0, mask: np.ndarray | None = None) -> float:
        """The inter-pixel coupling (fraction to each x neighbour) fitted with the model of
        parameters ``p`` at offset shift ``delta_um``."""
        return self._nuisances(p, delta_um, mask)[2]

    def estimate_noise(self, nominal_residual: np.ndarray) -> float:
        """RMS noise (fraction of the data peak) from the profile itself, its variance growing
        with the signal (photon noise; :func:`.noise.estimate_noise_signal_dependent`): the
        wings' scatter alone misses an arc line's photon noise, ~14x larger at a
        20 000-count peak, and read a perfect nominal line as a gap.

        The estimator predicts each sample from its neighbours, which only sees noise where
        the line is smooth on the sample step. A profile sampled once per 18 µm pixel is
        not: the estimate is then the line's structure (measured 0.097 of the peak on a
        double-peaked J line whose noise was 0.0018, the nominal line sampled the same way
        and noise-free reading 0.039). Where the nominal's leakage reaches
        :data:`NOISE_LEAK_LIMIT` of the estimate, the noise is not measurable from the data
        and ``noise_rel`` is required (a noise read 50x too high makes a real gap ``no_gap``)."""
        sigma = estimate_noise_signal_dependent(self.x, nominal_residual, level=self.data)
        leak = estimate_noise(self.x, self.data - nominal_residual)
        if not leak < NOISE_LEAK_LIMIT * sigma:
            step = float(np.median(np.diff(np.sort(self.x))))
            wings = (self.data - nominal_residual) < WING_LEVEL
            hint = ""
            if wings.sum() >= 4:
                hint = (f"; the {int(wings.sum())} samples where the nominal line is below {100 * WING_LEVEL:g} % of its "
                        f"peak scatter "
                        f"about the fit by {float(np.sqrt(np.mean(nominal_residual[wings] ** 2))):.2g} of the peak "
                        "(a guide, not the noise: it holds any wing mismatch, and misses photon noise that grows "
                        "with the signal)")
            raise ValueError(
                f"measurement {self.name!r}: noise_rel is required: its {self.n} samples ({step:.3g} µm apart) are "
                f"too coarse for the noise to be told from the line (the nominal line sampled the same way, "
                f"noise-free, reads as noise {leak:.3g} of the peak against {sigma:.3g} from the data; the estimate "
                f"needs the first below {NOISE_LEAK_LIMIT:g} x the second); give noise_rel = the RMS noise over the "
                f"profile as a fraction of the line's peak above background (valid {NOISE_RANGES['noise_rel'][0]:g}.."
                f"{NOISE_RANGES['noise_rel'][1]:g}) in its [[measurement]], or noise_counts = the same in the "
                f"file's intensity units{hint}")
        return self._white_part(sigma)

    def _white_part(self, sigma: float) -> float:
        """The white part of an estimated noise ``sigma``: the estimator reads a stated
        correlated noise's share (:meth:`.noise.CorrelatedNoise.estimator_share`, nil for a
        correlation longer than a few sample steps) as white noise too."""
        cn = self.correlated_noise
        if cn is None:
            return sigma
        leak = cn.estimator_share(self.x) * cn.rms_rel**2
        if not leak < sigma**2:
            raise ValueError(
                f"measurement {self.name!r}: correlated_noise_rel={cn.rms_rel:.3g} over correlation_length_um="
                f"{cn.length_um:g} would scatter neighbouring samples by {np.sqrt(leak):.3g} of the peak, more than "
                f"the {sigma:.3g} the profile scatters by in all: the correlated noise stated is larger than these "
                "data allow (a longer correlation, or a smaller RMS)")
        return float(np.sqrt(sigma**2 - leak))

    def nuisance_design(self) -> np.ndarray:
        """The nuisances' columns at the nominal and the initial offset shift (n x k): flux,
        coupling (unless stated), background and the shift's derivative. A right model's
        residual is the noise less its projection on these (:meth:`noise_rss_moments`)."""
        curve, d = self.curve({}), self.delta0_um
        line, neighbours = self._line_and_neighbours(curve, d)
        h = 0.05  # µm: a central difference of the line's position, far below its width
        slope = (self._sampled(curve, d + h) - self._sampled(curve, d - h)) / (2.0 * h)
        flux = [line, neighbours] if self.stated_coupling is None else [line + self.stated_coupling * neighbours]
        return np.column_stack([*flux, np.ones_like(line), slope])

    def noise_rss_moments(self, sigma_w: float) -> tuple[float, float] | None:
        """Mean and variance of the residual sum of squares (fraction of the peak, squared)
        that white noise ``sigma_w`` and the stated correlated noise leave a right model over
        all samples (:func:`.noise.rss_moments`); None where no correlated noise is stated
        (the gap test's white-noise counting then holds exactly)."""
        cn = self.correlated_noise
        if cn is None:
            return None
        if self._rss_traces is None:
            self._rss_traces = RssTraces.of(cn.rms_rel**2 * cn.correlation(self.x), self.nuisance_design())
        return self._rss_traces.moments(sigma_w)

    @property
    def noise_rel_sd(self) -> float:
        """Relative standard deviation of the estimated noise
        (:func:`.noise.estimate_noise_signal_dependent`)."""
        return SIGNAL_DEPENDENT_NOISE_REL_SD_SQRT_N / np.sqrt(max(self.n, 1))

    def residual(self, p: dict, delta_um: float = 0.0, mask: np.ndarray | None = None) -> np.ndarray:
        """Data minus model with flux, coupling and background fitted on ``mask`` (fraction
        of the data peak)."""
        return self._nuisances(p, delta_um, mask)[0]

    def fitted(self, p: dict, delta_um: float = 0.0, mask: np.ndarray | None = None) -> np.ndarray:
        return self._nuisances(p, delta_um, mask)[1]

    def _initial_shift(self) -> float:
        """Offset shift of the nominal model by a 1-µm grid search over ±40 µm (the data
        may be shifted by more than the fit's basin)."""
        grid = np.arange(-40.0, 40.5, 1.0)
        cost = [float(np.sum(self.residual({}, d) ** 2)) for d in grid]
        return float(grid[int(np.argmin(cost))])
