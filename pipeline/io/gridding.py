"""Sag maps given as lists of points, and sag units: turning what instruments export
into the regular µm grid of :class:`optics.sagmap.SagMap`.

* :func:`grid_points` — points ``(x_mm, y_mm, sag_um)`` in any order. Points on a
  uniform grid with some nodes absent (a masked interferometer export lists only the
  points inside its aperture) are put back on that grid, absent nodes NaN. Otherwise
  the points are scattered: linear interpolation on their Delaunay triangulation
  (what ``scipy.interpolate.griddata(method="linear")`` does), NaN outside the convex
  hull, on a square grid with as many nodes in the hull as there are points
  (spacing ``sqrt(hull area / n)``) unless a spacing is given. A finer grid adds no
  information but many nodes interpolated from the same few points: their errors are
  correlated, so a noise or an effective sample count taken from the grid misreads the
  measurement (at the median nearest-neighbour distance, about half this spacing for
  random points, a 2 nm noise read 0.46 nm on the grid) and every fit costs more. The
  points' white noise is estimated before interpolation
  (:func:`pipeline.diagnosis.noise.estimate_noise_scattered`) and kept in
  ``meta["points_noise_um"]``; a node, the weighted mean ``sum_i w_i v_i`` of its
  triangle's three points, carries ``sqrt(sum_i w_i^2)`` of it, and the RMS of that over
  the map's nodes is kept in ``meta["node_noise_factor"]`` (:func:`node_noise_factor`).
  The map's ``meta["gridding"]`` says which, for the report. The grid serves what
  needs one (plots, exports, ``cryograting convert``); the diagnosis fits scattered
  points at the points themselves (:class:`ScatteredPoints`), so neither the nodes'
  correlated noise nor the interpolation's own error on a curved surface enters its fit.
* :func:`sag_unit_factor` — factor from a ``units`` string (nm, µm, mm, m, waves) to µm.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from optics.sagmap import is_uniform_axis
from optics.triangulation import linear_on_grid, weight_square_sums

__all__ = ["GRID_TOLERANCE", "MAX_GRID_NODES", "SAG_UNITS_TO_UM", "WAVE_UNITS", "LENGTH_UNITS_TO_MM", "grid_points",
           "detect_axis", "uniform_axis", "sag_unit_factor", "length_unit_factor", "GridUnknownError",
           "grid_from_options", "node_noise_factor", "ScatteredPoints", "scattered_points"]

#: A coordinate is on the grid if it lies within this fraction of the step of a node:
#: far above print noise (6 significant digits of a 100 mm coordinate: 5e-5 mm), far
#: below what random scatter gives (uniform in +-0.5 step).
GRID_TOLERANCE = 0.05
#: Largest grid built from points (nodes): 4e6 float64 = 32 MB per array.
MAX_GRID_NODES = 4_000_000

#: Accepted spellings of a sag unit and their factor to µm (``waves`` needs a wavelength).
SAG_UNITS_TO_UM = {"nm": 1e-3, "nanometer": 1e-3, "nanometers": 1e-3, "nanometre": 1e-3, "nanometres": 1e-3,
                   "um": 1.0, "µm": 1.0, "μm": 1.0, "micron": 1.0, "microns": 1.0, "micrometer": 1.0,
                   "micrometers": 1.0, "micrometre": 1.0, "micrometres": 1.0,
                   "mm": 1e3, "millimeter": 1e3, "millimeters": 1e3, "millimetre": 1e3, "millimetres": 1e3,
                   "m": 1e6, "meter": 1e6, "meters": 1e6, "metre": 1e6, "metres": 1e6,
                   # spectroscopy's unit: a wavelength axis "wavelength [A]", "Wavelength (Angstrom)"
                   "angstrom": 1e-4, "angstroms": 1e-4, "å": 1e-4, "aa": 1e-4, "a": 1e-4}
#: Spellings of a sag in waves (one wave is ``wavelength_um``).
WAVE_UNITS = ("waves", "wave", "wv", "lambda", "λ")
#: Accepted length units of coordinates and their factor to mm.
LENGTH_UNITS_TO_MM = {k: v * 1e-3 for k, v in SAG_UNITS_TO_UM.items()}


def sag_unit_factor(units: str, wavelength_um: float | None = None) -> float:
    """Factor that turns sag values in ``units`` into µm.

    Parameters
    ----------
    units : str
        ``nm``, ``um``/``µm``/``micron``, ``mm``, ``m`` (case-insensitive, long forms
        accepted) or ``waves``.
    wavelength_um : float, optional
        Wavelength (µm) of one wave; required for ``waves``.

    Raises
    ------
    ValueError
        Unknown unit (naming it and the accepted list), or ``waves`` without a
        positive finite wavelength.
    """
    u = str(units).strip().lower()
    if u in SAG_UNITS_TO_UM:
        return SAG_UNITS_TO_UM[u]
    if u in WAVE_UNITS:
        if wavelength_um is None or not (np.isfinite(wavelength_um) and wavelength_um > 0):
            raise ValueError(f"units={units!r} needs wavelength_um, the wavelength of one wave (µm, > 0: in a manifest "
                             f"the measurement's 'wavelength_um' key); got wavelength_um={wavelength_um!r}")
        return float(wavelength_um)
    raise ValueError(f"units={units!r} is not a known sag unit; valid: nm, um (µm, micron), mm, m, Angstrom, "
                     "waves (with wavelength_um)")


def length_unit_factor(units: str) -> float:
    """Factor that turns coordinates in ``units`` (nm, µm, mm, m) into mm."""
    u = str(units).strip().lower()
    if u not in LENGTH_UNITS_TO_MM:
        raise ValueError(f"units={units!r} is not a known length unit; valid: nm, um (µm), mm, m, Angstrom")
    return LENGTH_UNITS_TO_MM[u]


def detect_axis(v: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """Node coordinates and integer node index of coordinates ``v`` on a uniform axis.

    The step is first taken as the smallest gap between distinct values (gaps below
    1e-3 of the largest are print noise), then refined by a least-squares line through
    the distinct values against their node numbers. Whole missing columns are allowed.

    Returns
    -------
    (nodes, index) or None
        ``nodes`` are the distinct values themselves when every node occurs (so a
        file's coordinates come back bit for bit), else ``origin + step * k``. None when ``v`` has fewer than 2 distinct values or does not sit on a uniform
        axis within :data:`GRID_TOLERANCE` of the step.
    """
    s = np.sort(np.asarray(v, float))
    d = np.diff(s)
    if s.size < 2 or not d.max() > 0:
        return None
    big = d[d > 1e-3 * d.max()]
    h0 = float(big.min())
    if (s[-1] - s[0]) / h0 > np.sqrt(MAX_GRID_NODES) * 4:
        return None
    # distinct values: clusters of print noise merged (gaps below half a step)
    starts = np.concatenate([[0], np.flatnonzero(d > 0.5 * h0) + 1])
    centres = np.add.reduceat(s, starts) / np.diff(np.concatenate([starts, [s.size]]))
    k = np.round((centres - centres[0]) / h0)
    if k[-1] > 0:
        step, origin = np.polyfit(k, centres, 1)
    else:
        step, origin = h0, centres[0]
    idx = (np.asarray(v, float) - origin) / step
    ki = np.round(idx)
    if not step > 0 or np.max(np.abs(idx - ki)) > GRID_TOLERANCE:
        return None
    ki = ki.astype(int)
    n = int(ki.max()) + 1
    # the file's own values where they are a map's axis already; else the fitted uniform
    # axis (a 1/3 mm step printed to 6 digits, float32 coordinates: steps that differ by
    # more than a SagMap allows, though every value is on its node)
    nodes = centres if centres.size == n and is_uniform_axis(centres) else origin + step * np.arange(n)
    return nodes, ki


def uniform_axis(v: np.ndarray) -> np.ndarray:
    """Increasing 1-D coordinates ``v`` as a uniform axis: ``v`` itself where it is one
    (:func:`optics.sagmap.is_uniform_axis`), the least-squares uniform axis through it where
    every value lies within :data:`GRID_TOLERANCE` of a step of it (rounding, float32
    storage), else ``v`` unchanged (for :class:`optics.sagmap.SagMap` to refuse by name)."""
    v = np.asarray(v, float)
    if v.ndim != 1 or v.size < 3 or is_uniform_axis(v) or not np.all(np.diff(v) > 0):
        return v
    found = detect_axis(v)
    if found is None or found[0].size != v.size or not np.array_equal(found[1], np.arange(v.size)):
        return v
    return found[0]


@dataclass(frozen=True, eq=False)
class ScatteredPoints:
    """The measured points of a map given as scattered points, before any gridding.

    Attributes
    ----------
    x_mm, y_mm : ndarray, shape (n,)
        Point coordinates (mm), in the file's order.
    sag_um : ndarray, shape (n,)
        Sag (µm), finite (points without data are left out).
    """

    x_mm: np.ndarray
    y_mm: np.ndarray
    sag_um: np.ndarray


def scattered_points(x_mm: np.ndarray, y_mm: np.ndarray, sag_um: np.ndarray, meta: dict) -> ScatteredPoints | None:
    """The points with data of a point list that :func:`grid_points` found scattered (its
    ``meta``), else None (the points lie on a grid, which then holds them exactly)."""
    if not str(meta.get("gridding", "")).startswith("scattered"):
        return None
    x, y, s = (np.asarray(a, float).ravel() for a in (x_mm, y_mm, sag_um))
    ok = np.isfinite(s)
    return ScatteredPoints(x[ok], y[ok], s[ok])


def grid_points(x_mm: np.ndarray, y_mm: np.ndarray, sag_um: np.ndarray, *, spacing_mm: float | None = None,
                lines: np.ndarray | None = None, source: str = "points") -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
    """Regular grid from a list of points (see module docstring).

    Parameters
    ----------
    x_mm, y_mm : ndarray, shape (n,)
        Finite point coordinates (mm), any order.
    sag_um : ndarray, shape (n,)
        Sag (µm); NaN marks a point without data.
    spacing_mm : float, optional
        Grid spacing for scattered points (mm); default ``sqrt(A / n)`` for ``n`` points
        with data over a convex hull of area ``A`` (mm²): one node per point. Ignored when
        the points lie on a uniform grid.
    lines : ndarray of int, optional
        Source line of each point, for error messages.
    source : str
        Name of the source for error messages (the file).

    Returns
    -------
    x_mm, y_mm, sag_um, meta
        Axes (mm), ``sag_um[y, x]`` with NaN where there is no data, and a dict with
        ``gridding`` (``"uniform grid detected"`` or ``"scattered: linear ..."``) and
        the spacing; for scattered points also ``n_points``, ``points_noise_um``, the
        points' white-noise sigma (µm) before interpolation (None if too few points), and
        ``node_noise_factor`` (:func:`node_noise_factor`, dimensionless): the nodes' white
        noise is ``points_noise_um * node_noise_factor``.

    Raises
    ------
    ValueError
        Two points at the same grid node (naming their lines), fewer than 3 points
        with data, points on one line, or a grid larger than :data:`MAX_GRID_NODES`.
    """
    x, y, s = (np.asarray(a, float).ravel() for a in (x_mm, y_mm, sag_um))
    ax, ay = detect_axis(x), detect_axis(y)
    if ax is not None and ay is not None:
        (gx, ix), (gy, iy) = ax, ay
        nx, ny = gx.size, gy.size
        hx, hy = (float((g[-1] - g[0]) / max(g.size - 1, 1)) for g in (gx, gy))
        if nx < 2 or ny < 2:
            raise ValueError(f"{source}: all points lie on one line (x or y constant); a map needs >= 2 distinct "
                             "x_mm and y_mm")
        if nx * ny > MAX_GRID_NODES:
            raise ValueError(f"{source}: the points' grid would have {nx} x {ny} nodes (step {hx:g} x {hy:g} mm); "
                             f"at most {MAX_GRID_NODES} are supported")
        flat = iy * nx + ix
        order = np.argsort(flat, kind="stable")
        dup = np.flatnonzero(np.diff(flat[order]) == 0)
        if dup.size:
            a, b = order[dup[0]], order[dup[0] + 1]
            where = (f" (lines {lines[a]} and {lines[b]})" if lines is not None else "")
            raise ValueError(f"{source}: two points at the same grid node x_mm={x[b]:g}, y_mm={y[b]:g}{where}")
        sag = np.full((ny, nx), np.nan)
        sag[iy, ix] = s
        meta = {"gridding": "uniform grid detected", "spacing_mm": [hx, hy],
                "filled_fraction": float(np.isfinite(sag).mean())}
        return gx, gy, sag, meta
    return _scattered(x, y, s, spacing_mm, source)


def _scattered(x, y, s, spacing_mm, source):
    # imported here, not at the top: pipeline.diagnosis imports pipeline.io
    from pipeline.diagnosis.noise import estimate_noise_scattered

    ok = np.isfinite(s)
    x, y, s = x[ok], y[ok], s[ok]
    if x.size < 3:
        raise ValueError(f"{source}: scattered points need >= 3 finite sag values, found {x.size}")
    try:
        area_mm2 = float(ConvexHull(np.column_stack([x, y])).volume)  # a 2-D hull's "volume" is its area
    except QhullError:
        raise ValueError(f"{source}: the {x.size} points are collinear or coincident; cannot triangulate") from None
    if spacing_mm is None:
        spacing_mm = float(np.sqrt(area_mm2 / x.size))
        how = "sqrt(hull area / points): one node per point"
    else:
        how = "given"
    if not (np.isfinite(spacing_mm) and spacing_mm > 0):
        raise ValueError(f"{source}: spacing_mm={spacing_mm!r} must be a finite number > 0 (mm)")
    nx = int(np.floor((x.max() - x.min()) / spacing_mm + 1e-9)) + 1
    ny = int(np.floor((y.max() - y.min()) / spacing_mm + 1e-9)) + 1
    if nx < 2 or ny < 2:
        raise ValueError(f"{source}: the points span {x.max() - x.min():g} x {y.max() - y.min():g} mm, less than "
                         f"two grid steps of {spacing_mm:g} mm in x or y")
    if nx * ny > MAX_GRID_NODES and how == "given":
        raise ValueError(f"{source}: gridding at spacing_mm={spacing_mm:g} gives {nx} x {ny} nodes; at most "
                         f"{MAX_GRID_NODES} are supported (give a larger spacing_mm)")
    if nx * ny > MAX_GRID_NODES:  # no spacing given: name none (not every caller can give one)
        raise ValueError(f"{source}: gridding at the points' mean spacing sqrt(hull area / points) = {spacing_mm:g} mm "
                         f"gives {nx} x {ny} nodes; at most {MAX_GRID_NODES} are supported (the {x.size} points "
                         f"cover {area_mm2:g} mm² of a {x.max() - x.min():g} x {y.max() - y.min():g} mm box: "
                         "points along a line, or far apart from the rest?)")
    gx = x.min() + spacing_mm * np.arange(nx)
    gy = y.min() + spacing_mm * np.arange(ny)
    try:
        sag = linear_on_grid(x, y, s, gx, gy)
    except QhullError:
        raise ValueError(f"{source}: the {x.size} points are collinear or coincident; cannot triangulate") from None
    noise = estimate_noise_scattered(x, y, s)
    factor = node_noise_factor(x, y, gx, gy)
    meta = {"gridding": f"scattered: linear interpolation of {x.size} points on their Delaunay triangulation onto a "
                        f"{spacing_mm:.3g} mm grid (NaN outside the convex hull; spacing {how})",
            "spacing_mm": [spacing_mm, spacing_mm], "n_points": int(x.size),
            "points_noise_um": noise if np.isfinite(noise) else None, "node_noise_factor": factor}
    return gx, gy, sag, meta


def node_noise_factor(x_mm: np.ndarray, y_mm: np.ndarray, gx_mm: np.ndarray, gy_mm: np.ndarray) -> float:
    """White noise of the linearly interpolated grid nodes over that of the points: the RMS
    over the nodes inside the points' convex hull of ``sqrt(sum_i w_i^2)``, ``w_i`` a node's
    barycentric weights (:func:`optics.triangulation.weight_square_sums`).

    The nodes' mean noise variance is ``sigma_p^2 * factor^2`` exactly, for the given layout:
    the noise of the nodes when a gridded map is fitted as a grid (saved to a grid format;
    a map of scattered points is fitted at its points). The nodes also carry the linear
    interpolation's own error on a curved surface, which this factor does not cover. A node placed uniformly at random in a triangle has Dirichlet(1, 1, 1)
    barycentric weights whatever the triangle's shape, so ``E[sum w^2] = 3 E[w^2] = 1/2``
    with a standard deviation of ``sqrt(1/60) = 0.13`` per node (``sum w^2`` in [1/3, 1]): a
    grid laid over random points gives ``1/sqrt(2) = 0.707`` (0.7077, 0.7070 and 0.7069
    measured on three draws of 15 000 uniform random points in a 68 mm disc). The spread is
    per node, not across the map: on those draws the nodes within 60 mm of the centre give
    0.707, those at 60-66 mm 0.706-0.710, at 66-67.5 mm 0.696-0.705; only the ~130 nodes in
    the last 0.5 mm give 0.715-0.725 (next to a hull edge the opposite point's weight
    vanishes, so ``sum w^2 >= 1/2``), which moves the map's mean variance by 0.03 %. One
    factor therefore suffices: over 60 such draws with 0.01 µm noise, the nodes' noise
    (piston and tilt removed) gives a reduced chi^2 of 1.0027 +- 0.0023 against
    ``0.01 µm * factor`` (sd 0.018 per draw, 0.016 expected from the nodes' covariance
    ``sigma^2 W W^T``; ``tests/test_scattered_noise.py`` checks one draw). Points on a
    near-regular layout close to the grid put nodes near points and give a larger factor,
    hence the computation rather than the constant.

    Parameters
    ----------
    x_mm, y_mm : ndarray, shape (n,)
        Point coordinates (mm).
    gx_mm, gy_mm : ndarray
        Grid coordinates (mm), uniformly spaced and increasing.

    Returns
    -------
    float
        The factor (dimensionless, in [sqrt(1/3), 1]); NaN if no node lies in the hull.
    """
    sq = weight_square_sums(x_mm, y_mm, gx_mm, gy_mm)
    ok = np.isfinite(sq)
    return float(np.sqrt(np.mean(sq[ok]))) if ok.any() else float("nan")



class GridUnknownError(ValueError):
    """A sag-map file without a physical grid size (a CODE V INT without an EXTENT_MM
    title, a FITS image without a length WCS) and no reader option giving one.

    ``problem`` says so; the message adds the remedy of :func:`read_codev_int`'s caller
    (its ``extent_mm`` / ``spacing_mm`` options). Front ends that spell these otherwise
    (a manifest key, none on the command line) re-word it with :meth:`with_remedy`."""

    def __init__(self, problem: str):
        self.problem = problem
        super().__init__(f"{problem}; pass extent_mm=(xmin, xmax, ymin, ymax) or spacing_mm (mm)")

    def with_remedy(self, remedy: str) -> ValueError:
        return ValueError(f"{self.problem}; {remedy}")


def grid_from_options(nx: int, ny: int, extent_mm=None, spacing_mm=None) -> tuple | None:
    """Sample coordinates (mm) of an ``nx`` x ``ny`` grid whose file carries no lateral
    scale, from a reader's options: ``extent_mm = (x0, x1, y0, y1)`` (first and last
    sample centres) or ``spacing_mm`` (one value or ``(dx, dy)``, grid centred on 0).

    Returns
    -------
    (x_mm, y_mm, source) or None
        None when neither option is given (the caller then raises :class:`GridUnknownError`).
    """
    if extent_mm is not None:
        try:
            x0, x1, y0, y1 = (float(v) for v in extent_mm)
        except (TypeError, ValueError):
            raise ValueError(f"extent_mm={extent_mm!r} must be four numbers (xmin, xmax, ymin, ymax) in mm, the "
                             "first and last sample centres") from None
        if not (x1 > x0 and y1 > y0):
            raise ValueError(f"extent_mm={tuple(extent_mm)} must be (xmin, xmax, ymin, ymax) with max > min")
        return np.linspace(x0, x1, nx), np.linspace(y0, y1, ny), "extent_mm argument"
    if spacing_mm is not None:
        try:
            dx, dy = (float(spacing_mm),) * 2 if np.isscalar(spacing_mm) else (float(v) for v in spacing_mm)
        except (TypeError, ValueError):
            raise ValueError(f"spacing_mm={spacing_mm!r} must be a number > 0 or a pair (dx, dy) of them, "
                             "in mm") from None
        if not (np.isfinite(dx) and np.isfinite(dy) and dx > 0 and dy > 0):
            raise ValueError(f"spacing_mm={spacing_mm!r} must be > 0 (one value or (dx, dy))")
        hx, hy = 0.5 * (nx - 1) * dx, 0.5 * (ny - 1) * dy
        return np.linspace(-hx, hx, nx), np.linspace(-hy, hy, ny), "spacing_mm argument, centred"
    return None
