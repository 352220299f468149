"""Plausibility of the measurements before any fit: can the nominal model produce them?

A fit always returns numbers, so nonsense in must be stopped before it: a profile of
random numbers fits some slit width, a map of zeros some amplitude at its prior bound,
and a map written in nm (1000x too large) is called "unexplained" with no hint about
its unit. Each check compares a measurement with the noise it carries and with what
the nominal model predicts for it:

* line profile: the offsets must span a plausible range for the nominal line (else the
  unit is named, e.g. mm instead of µm); there must be a line, a peak at least
  ``min_peak_sigma`` noise sigmas above the profile's median; its FWHM must lie within
  ``width_range`` times the nominal line's FWHM. A hot pixel or cosmic-ray hit taller than
  the line is one sample, not a line: where the raw FWHM is implausible but the profile's
  3-sample running median holds a line of plausible width, the profile is data with a
  spike (a non-fatal "spike" problem naming the samples), not a refusal;
* surface map: its lateral span must lie within ``max_orders`` decades of the blank's
  (coordinates in m or µm read as mm are named as a coordinate unit); its RMS about piston
  and tilt must exceed ``min_signal_ratio`` times its
  white noise ("no signal" otherwise), and lie within ``max_orders`` decades of the
  nominal's RMS at the measurement temperature (else "wrong unit (nm)?" / "(mm)?"); and it
  must not match the nominal better with its heights reversed or turned by 90° (a height or
  mount convention: :func:`orientation_problems`);
* PSF image: a peak at least ``min_peak_sigma`` noise sigmas above its median.

:func:`measurement_problems` lists the problems of every measurement;
:func:`check_measurements` raises one ``ValueError`` line with every problem that makes
the data undiagnosable (a profile without a line or of implausible width, a magnitude
off by ``max_orders`` decades, or no measurement with signal at all) and warns about the
rest (a map without signal beside measurements that have one is still data: it says
the deformation is below its noise). :func:`at_prior_bound` names fitted parameters
that sit at their prior bound: such a fit is the prior speaking, not the data.

Noise is the measurement's stated ``noise_um`` / ``noise_rel`` or else estimated from
the data (:func:`pipeline.diagnosis.noise.estimate_noise`; scattered points: the points'
own, :attr:`.manifest.SurfaceData.samples_noise_um`).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np

from .noise import estimate_noise

__all__ = ["Plausibility", "Problem", "line_fwhm", "peak_sigma", "running_median3", "profile_problems", "map_problems",
           "image_problems", "orientation_problems", "measurement_problems", "check_measurements", "at_prior_bound", "unit_hint"]


@dataclass(frozen=True)
class Plausibility:
    """Thresholds of the checks (see module docstring).

    Why these values: a real line profile or image is normalised to a unit peak and has
    noise of a few percent at most (the campaign uses 1 %: a peak 100 sigma above its
    median), so 10 sigma leaves an order of magnitude of margin while a flat profile
    (~3 sigma) or uniform random numbers (~2 sigma) fail by a factor of 3 or more.
    The library's slit width prior (15-45 µm against 27 µm) changes the FWHM by
    0.6-1.7x; 0.3-5x leaves room for any real line. A map's amplitude can change by
    0.3-3x (``amplitude_scale``) and its temperature by -60..+80 K, i.e. far less than a
    factor 100 (2 decades), while a unit error is a factor 1000.
    """

    min_peak_sigma: float = 10.0
    width_range: tuple = (0.3, 5.0)
    min_signal_ratio: float = 2.0
    max_orders: float = 2.0
    #: offsets must span [lo, hi] times the nominal FWHM
    span_range: tuple = (1.0, 100.0)
    #: a map that correlates with the nominal above this when reversed or turned by 90°,
    #: and better by ``orientation_margin`` than as given, is refused (:func:`orientation_problems`)
    min_orientation_correlation: float = 0.5
    orientation_margin: float = 0.3

    def __post_init__(self) -> None:
        lo, hi = self.width_range
        if not 0 < lo < 1 < hi:
            raise ValueError(f"Plausibility: width_range={self.width_range!r} must be (lo, hi) with 0 < lo < 1 < hi")
        lo, hi = self.span_range
        if not 0 < lo < hi:
            raise ValueError(f"Plausibility: span_range={self.span_range!r} must be (lo, hi) with 0 < lo < hi")
        for name in ("min_peak_sigma", "min_signal_ratio", "max_orders", "min_orientation_correlation", "orientation_margin"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"Plausibility: {name}={v!r} must be a finite number > 0")


@dataclass(frozen=True)
class Problem:
    """One implausibility of a measurement: ``code`` ("no_line", "width", "unit",
    "no_signal", "spike"), a one-line ``message``, and whether it makes the data undiagnosable."""

    measurement: str
    code: str
    message: str
    fatal: bool = True

    def __str__(self) -> str:
        return f"measurement {self.measurement!r}: {self.message}"


_UNITS = {3: ("nm", "mm"), 6: ("pm", "m")}  # decades above -> (too large unit), below -> (too small)


def unit_hint(orders: float, length_unit: str = "µm") -> str:
    """``"wrong unit (nm)?"`` for a value ~3 decades too large (a µm quantity written in
    nm), ``"(mm)?"`` ~3 decades too small, ``"(m)?"`` 6 decades; else ``"wrong unit?"``."""
    k = int(round(abs(orders)))
    if k in _UNITS and abs(abs(orders) - k) < 0.75 and length_unit == "µm":
        return f"wrong unit ({_UNITS[k][0 if orders > 0 else 1]})?"
    return "wrong unit?"


def peak_sigma(intensity: np.ndarray, sigma: float) -> float:
    """How many noise sigmas the maximum of ``intensity`` lies above its median
    (inf for noiseless data with a peak)."""
    y = np.asarray(intensity, float)
    h = float(np.max(y) - np.median(y))
    if sigma > 0:
        return h / sigma
    return math.inf if h > 0 else 0.0


def line_fwhm(offset_um: np.ndarray, intensity: np.ndarray) -> float:
    """Full width at half maximum (unit of ``offset_um``) of the line around the
    profile's maximum, the half level taken halfway between the median and the peak.

    The crossings are interpolated linearly between samples; where the profile does not
    drop below the half level before an end, that end counts (the width is then a lower
    bound).
    """
    o = np.argsort(offset_um)
    x, y = np.asarray(offset_um, float)[o], np.asarray(intensity, float)[o]
    i = int(np.argmax(y))
    half = 0.5 * (y[i] + float(np.median(y)))

    def crossing(step: int) -> float:
        j = i
        while 0 <= j + step < y.size and y[j + step] >= half:
            j += step
        k = j + step
        if not 0 <= k < y.size:
            return float(x[j])
        t = (y[j] - half) / (y[j] - y[k])  # y[j] >= half > y[k]
        return float(x[j] + t * (x[k] - x[j]))

    return crossing(1) - crossing(-1)


def profile_problems(name: str, offset_um: np.ndarray, intensity: np.ndarray, nominal_fwhm_um: float,
                     noise_rel: float | None = None, rules: Plausibility = Plausibility()) -> list[Problem]:
    """Problems of a line profile against the nominal line's FWHM (µm).

    Checked in this order, and the first failure ends the list (the later checks assume
    the earlier ones): the offsets' span (a unit error), a line above the noise, its width.
    """
    x, y = np.asarray(offset_um, float), np.asarray(intensity, float)
    span = float(np.ptp(x))
    lo, hi = rules.span_range[0] * nominal_fwhm_um, rules.span_range[1] * nominal_fwhm_um
    if not lo <= span <= hi:
        hint = unit_hint(math.log10(span / math.sqrt(lo * hi))) if span > 0 else "wrong unit?"
        return [Problem(name, "unit", f"offsets span {span:.3g} µm; expected {lo:.0f}..{hi:.0f} µm "
                        f"({rules.span_range[0]:g}-{rules.span_range[1]:g}x the nominal line's FWHM "
                        f"{nominal_fwhm_um:.1f} µm): {hint}")]
    sigma = noise_rel if noise_rel is not None else estimate_noise(x, y)
    missing = _no_peak(name, y, sigma, rules, "line")
    if missing:
        return missing
    w = line_fwhm(x, y)
    ratio = w / nominal_fwhm_um
    if rules.width_range[0] <= ratio <= rules.width_range[1]:
        return []
    spike = _spike_problem(name, x, y, nominal_fwhm_um, sigma, rules)
    if spike:
        return spike
    return [Problem(name, "width", f"line FWHM {w:.3g} µm is {ratio:.2g}x the nominal's "
                    f"{nominal_fwhm_um:.1f} µm; "
                    f"a line the model can produce has {rules.width_range[0]:g}-{rules.width_range[1]:g}x")]


def running_median3(offset_um: np.ndarray, intensity: np.ndarray) -> tuple:
    """``(offsets, intensity, its 3-sample running median)``, all sorted by offset; the end
    samples keep their value. A single-sample spike (hot pixel, cosmic ray) disappears from
    the median while a line sampled by two or more samples per FWHM keeps its width to
    within a sample."""
    o = np.argsort(offset_um)
    x, y = np.asarray(offset_um, float)[o], np.asarray(intensity, float)[o]
    m = y.copy()
    if y.size >= 3:
        m[1:-1] = np.median(np.stack([y[:-2], y[1:-1], y[2:]]), axis=0)
    return x, y, m


def _spike_problem(name, x, y, nominal_fwhm_um, sigma, rules) -> list:
    """``[non-fatal Problem "spike"]`` when the running median of the profile holds a line
    of plausible width ``min_peak_sigma`` noise sigmas (the raw profile's ``sigma``) above
    its median (the raw width was set by single samples), else ``[]``."""
    xs, ys, med = running_median3(x, y)
    if _no_peak(name, med, sigma, rules, "line"):
        return []
    w = line_fwhm(xs, med)
    if not rules.width_range[0] <= w / nominal_fwhm_um <= rules.width_range[1]:
        return []
    dev = np.abs(ys - med)
    where = ", ".join(f"{v:.1f}" for v in xs[dev >= 0.5 * dev.max()])
    return [Problem(name, "spike", f"single samples stand out of the line (at offsets {where} µm): a hot pixel or "
                    f"cosmic-ray hit? The line's FWHM without them is {w:.3g} µm; the samples are kept as data "
                    f"(no library effect makes a one-sample feature)", fatal=False)]


def _piston_tilt_residual(x: np.ndarray, y: np.ndarray, v: np.ndarray) -> np.ndarray:
    A = np.column_stack([np.ones_like(x), x, y])
    c, *_ = np.linalg.lstsq(A, v, rcond=None)
    return v - A @ c


def map_problems(name: str, x_mm: np.ndarray, y_mm: np.ndarray, sag_um: np.ndarray, nominal_sag_um: np.ndarray,
                 noise_um: float | None = None, rules: Plausibility = Plausibility(),
                 blank_span_mm: float | None = None) -> list[Problem]:
    """Problems of a surface map (valid samples at ``x_mm, y_mm``) against the nominal
    sag predicted at the same points and temperature (µm; nan where the nominal has none).

    "unit" if the map's lateral span (the larger of its x and y extents) is ``max_orders``
    decades or more from ``blank_span_mm`` (the nominal's, mm): coordinates in m or µm read
    as mm, which would otherwise reach the RMS check below with a sag unit named for what
    is a coordinate unit; "no_signal" (not fatal here: :func:`check_measurements` decides)
    if the RMS about piston and tilt is below ``min_signal_ratio`` noise sigmas; "unit" if
    it is ``max_orders`` decades or more away from the nominal's RMS.
    """
    x, y, v = (np.asarray(a, float) for a in (x_mm, y_mm, sag_um))
    span = max(float(np.ptp(x)), float(np.ptp(y))) if x.size else 0.0
    if blank_span_mm is not None and span > 0 and blank_span_mm > 0:
        orders = math.log10(span / blank_span_mm)
        if abs(orders) >= rules.max_orders:
            where = "above" if orders > 0 else "below"
            hint = {-3: "m", 3: "µm"}.get(round(orders), "another unit")
            return [Problem(name, "unit", f"map spans {np.ptp(x):.3g} x {np.ptp(y):.3g} mm, {abs(orders):.0f} orders "
                            f"{where} the blank's {blank_span_mm:.3g} mm: coordinates in {hint} read as mm? give "
                            "the coordinates' unit (a column x_m or 'X [um]', a NetCDF coordinate's units)")]
    rms = float(np.sqrt(np.mean(_piston_tilt_residual(x, y, v) ** 2)))
    sigma = noise_um if noise_um is not None else estimate_noise(x, v, rows=y)
    if not math.isfinite(sigma):
        sigma = 0.0
    if not (rms > rules.min_signal_ratio * sigma and rms > 0):
        ratio = rms / sigma if sigma > 0 else 0.0
        return [Problem(name, "no_signal", f"no signal: map RMS {rms:.3g} µm about piston and tilt is "
                        f"{ratio:.2f}x its noise {sigma:.3g} µm, "
                        f"need > {rules.min_signal_ratio:g}x", fatal=False)]
    nom = np.asarray(nominal_sag_um, float)
    ok = np.isfinite(nom)
    if ok.sum() < 10:
        return []
    nom_rms = float(np.sqrt(np.mean(_piston_tilt_residual(x[ok], y[ok], nom[ok]) ** 2)))
    if not nom_rms > 0:
        return []
    orders = math.log10(rms / nom_rms)
    if abs(orders) >= rules.max_orders:
        where = "above" if orders > 0 else "below"
        return [Problem(name, "unit", f"map RMS {rms:.2g} µm is {abs(orders):.0f} orders {where} the nominal's "
                        f"{nom_rms:.2g} µm: {unit_hint(orders)}")]
    return []


#: (label, how to read the file so it matches, blank coordinates of a map point (x, y))
_ORIENTATIONS = (("turned by +90°", "x_new = y, y_new = -x", lambda x, y: (y, -x)),
                 ("turned by -90°", "x_new = -y, y_new = x", lambda x, y: (-y, x)))


def _correlation(a: np.ndarray, b: np.ndarray) -> float:
    ok = np.isfinite(b)
    if ok.sum() < 10:
        return 0.0
    na, nb = float(np.linalg.norm(a[ok])), float(np.linalg.norm(b[ok]))
    return float(a[ok] @ b[ok] / (na * nb)) if na > 0 and nb > 0 else 0.0


def orientation_problems(name: str, x_mm: np.ndarray, y_mm: np.ndarray, sag_um: np.ndarray, nominal_at,
                         rules: Plausibility = Plausibility()) -> list[Problem]:
    """A map that matches the nominal only with its heights reversed or turned by 90°.

    The quilt prints through with one sign (set by the plating's and the substrate's
    contractions) and its pitches differ along x and y (21 and 18 mm), so a map
    anti-correlated with the nominal is a height convention (surface height along -z), and
    one that matches the nominal turned by 90° a mount or an axis convention; no library
    effect reaches either (``amplitude_scale`` stops at its 0.3 bound). Correlations are of
    the piston/tilt residuals; ``nominal_at(x_mm, y_mm)`` gives the nominal at the
    measurement's temperature. Fatal when another reading correlates above
    ``min_orientation_correlation`` and beats the map as given by ``orientation_margin``."""
    x, y, v = (np.asarray(a, float) for a in (x_mm, y_mm, sag_um))
    d = _piston_tilt_residual(x, y, v)

    def nominal(bx, by):
        n = np.asarray(nominal_at(bx, by), float)
        ok = np.isfinite(n)
        out = np.full(n.shape, np.nan)
        if ok.sum() >= 10:
            out[ok] = _piston_tilt_residual(x[ok], y[ok], n[ok])
        return out

    given = _correlation(d, nominal(x, y))
    readings = [(-given, "with its heights reversed", "give sag_sign = -1 (the file's heights along -z)")]
    for label, how, to_blank in _ORIENTATIONS:
        c = _correlation(d, nominal(*to_blank(x, y)))
        readings.append((abs(c), label + (" with its heights reversed" if c < 0 else ""),
                         f"read the file with {how}" + (" and sag_sign = -1" if c < 0 else "")))
    best, what, remedy = max(readings, key=lambda r: r[0])
    if best > rules.min_orientation_correlation and best - given > rules.orientation_margin:
        return [Problem(name, "orientation", f"the map matches the nominal {what} (correlation {best:.2f}, "
                        f"against {given:.2f} as given): the diagnosis takes the sag along +z, x along the dispersion "
                        f"(21 mm quilt pitch) and y along the rulings (18 mm); {remedy}")]
    return []


def image_problems(name: str, x_um: np.ndarray, y_um: np.ndarray, intensity: np.ndarray,
                   noise_rel: float | None = None, rules: Plausibility = Plausibility()) -> list[Problem]:
    """Problems of a point-source image: a peak ``min_peak_sigma`` noise sigmas above its
    median (noise along the image rows when not stated: biased high near the Airy rings,
    so the test errs towards accepting)."""
    v = np.asarray(intensity, float)
    sigma = noise_rel if noise_rel is not None else estimate_noise(np.asarray(x_um, float), v,
                                                                    rows=np.asarray(y_um, float))
    return _no_peak(name, v, sigma, rules, "point-source image")


def _no_peak(name: str, values, sigma: float, rules, what: str) -> list:
    """``[Problem]`` when the peak of ``values`` is less than ``rules.min_peak_sigma`` noise
    sigmas above their median (a non-finite sigma counts as 0), else ``[]``."""
    z = peak_sigma(values, sigma if math.isfinite(sigma) else 0.0)
    if not z >= rules.min_peak_sigma:
        return [Problem(name, "no_line", f"no {what} found: peak {z:.1f} sigma above the median, "
                        f"need >= {rules.min_peak_sigma:g}")]
    return []


def _nominal_at(nominal, x_mm: np.ndarray, y_mm: np.ndarray) -> np.ndarray:
    from scipy.interpolate import RegularGridInterpolator

    f = RegularGridInterpolator((nominal.y_mm, nominal.x_mm), nominal.sag_um, bounds_error=False, fill_value=np.nan)
    return f(np.column_stack([y_mm, x_mm]))


def _nominal_fwhm_um(m, nominal) -> float:
    from .forward import profile_curve

    u, y = profile_curve(m.grating, m.wavelength_um, m.order, m.pixel_scale_mas, nominal, {}, m.slit_position)
    return line_fwhm(u, y)


def measurement_problems(manifest, data: tuple, nominal, rules: Plausibility = Plausibility()) -> list[Problem]:
    """Problems of every measurement (``data`` from :func:`.manifest.load_data`) against
    the nominal sag map at ``manifest.simulation.cold_K`` (a :class:`optics.sagmap.SagMap`)."""
    from .manifest import ProfileData, PsfImageData, SurfaceData
    from .nominal import thermal_factor

    sim = manifest.simulation
    out: list[Problem] = []
    for d in data:
        m = d.measurement
        if isinstance(d, ProfileData):
            out += profile_problems(m.name, d.offset_um, d.intensity, _nominal_fwhm_um(m, nominal), m.noise_rel, rules)
        elif isinstance(d, SurfaceData):
            k = thermal_factor(m.temperature_K, sim.cold_K, sim.warm_K, *sim.materials)
            noise = m.noise_um if m.noise_um is not None else d.samples_noise_um  # scattered: the points' own
            blank_span = max(float(np.ptp(nominal.x_mm)), float(np.ptp(nominal.y_mm)))
            found = map_problems(m.name, d.x_mm, d.y_mm, d.sag_um, k * _nominal_at(nominal, d.x_mm, d.y_mm),
                                 noise, rules, blank_span)
            if not found:  # a map with signal and the right magnitude: is it the right way round?
                found = orientation_problems(m.name, d.x_mm, d.y_mm, d.sag_um,
                                             lambda bx, by, k=k: k * _nominal_at(nominal, bx, by), rules)
            out += found
        elif isinstance(d, PsfImageData):
            out += image_problems(m.name, d.x_um, d.y_um, d.intensity, m.noise_rel, rules)
    return out


def check_measurements(manifest, data: tuple, nominal, rules: Plausibility = Plausibility()) -> list[Problem]:
    """Refuse data the nominal model cannot have produced, before any fit.

    Raises
    ------
    ValueError
        One line naming every fatal problem (:func:`measurement_problems`), or "no
        signal" when no measurement carries any.

    Returns
    -------
    list of Problem
        The non-fatal problems (also issued as warnings).
    """
    probs = measurement_problems(manifest, data, nominal, rules)
    fatal = [p for p in probs if p.fatal]
    quiet = {p.measurement for p in probs if p.code == "no_signal"}
    if not fatal and quiet and quiet >= {d.measurement.name for d in data}:
        fatal = [p for p in probs if p.code == "no_signal"]
    if fatal:
        raise ValueError("implausible data, nothing diagnosed: " + "; ".join(str(p) for p in fatal))
    for p in probs:
        warnings.warn(str(p), stacklevel=2)
    return probs


def at_prior_bound(values: dict, bounds: dict, rel_tol: float = 1e-3) -> tuple:
    """Names of the parameters in ``values`` that lie within ``rel_tol`` of their prior
    range's width from a bound (``bounds``: name -> (lo, hi); names without bounds are
    skipped). A fit that ends there was stopped by the prior, not by the data, so its
    value cannot be the sole basis of an ``explained`` verdict.

    Raises
    ------
    ValueError
        If ``rel_tol`` is not in [0, 0.5) or a bound pair is not ``lo < hi``.
    """
    if not 0 <= rel_tol < 0.5:
        raise ValueError(f"at_prior_bound: rel_tol={rel_tol!r} must be in [0, 0.5)")
    out = []
    for name, v in values.items():
        if name not in bounds:
            continue
        lo, hi = bounds[name]
        if not lo < hi:
            raise ValueError(f"at_prior_bound: bounds[{name!r}]=({lo}, {hi}) must have lo < hi")
        tol = rel_tol * (hi - lo)
        if v <= lo + tol or v >= hi - tol:
            out.append(name)
    return tuple(out)
