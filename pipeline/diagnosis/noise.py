"""Noise of a measurement from the data alone, and its effective number of samples.

* :func:`estimate_noise` — white-noise sigma of a profile or a map: robust scatter
  about a local cubic through each sample's four neighbours (along rows for a map).
* :func:`estimate_noise_scattered` — the same for scattered points ``(x, y)`` *before*
  they are interpolated onto a grid: robust scatter about a local 2-D cubic fitted to
  each point's nearest neighbours. Interpolated grid nodes share their points' noise,
  so the row cubic sees only a fraction of it.
* :func:`estimate_noise_band_limited` — the same for a focal-plane image sampled finer
  than its optical cut-off: the power at frequencies the optics cannot pass.
* :class:`CorrelatedNoise` — a stated correlated noise (a detector's flat-field or
  fringing residual, characterised beforehand): what it adds to a right model's residual
  (:func:`rss_moments`) and how much of it the estimators above read as white noise.
* :func:`effective_samples` — ``n / L`` with ``L`` the integral correlation length of a
  residual in samples (per axis for a map or image; scattered points are read along
  thin strips and counted as a grid of their density would be): how many independent
  samples a smooth model discrepancy amounts to.

Units are those of the values passed (µm for maps, fraction of the data peak for
profiles and images); positions in µm or mm, only their spacing matters.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["CorrelatedNoise", "RssTraces", "rss_moments", "effective_samples", "estimate_noise", "estimate_noise_band_limited", "estimate_noise_scattered",
           "estimate_noise_signal_dependent", "SIGNAL_DEPENDENT_NOISE_REL_SD_SQRT_N", "WING_LEVEL",
           "SCATTERED_NOISE_REL_SD_SQRT_N", "TwoPartErrors", "two_part_errors"]


def _cubic_stencil(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(i, nb, L)``: each interior sample ``i`` of the sorted ``x``, its two neighbours on
    each side ``nb`` (4 x m) and the Lagrange weights ``L`` of the cubic through them that
    predicts it."""
    i = np.arange(2, x.size - 2)
    nb = np.stack([i - 2, i - 1, i + 1, i + 2])
    xs, x0 = x[nb], x[i]
    L = np.ones_like(xs)
    for a in range(4):
        for b in range(4):
            if a != b:
                L[a] *= (x0 - xs[b]) / (xs[a] - xs[b])
    return i, nb, L


def _standardised_errors(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    if x.size < 5:
        return np.empty(0)
    i, nb, L = _cubic_stencil(x)
    return (y[i] - np.sum(L * y[nb], axis=0)) / np.sqrt(1.0 + np.sum(L**2, axis=0))


#: Median of a chi-square variable with one degree of freedom: the median of e^2 / var for
#: Gaussian errors e of variance var.
_CHI2_1_MEDIAN = 0.454936

#: Samples below this fraction of a profile's peak are its wings, where read and background
#: noise alone set the scatter (:func:`estimate_noise_signal_dependent`).
WING_LEVEL = 0.05


#: Relative standard deviation of :func:`estimate_noise_signal_dependent` times sqrt(n):
#: measured by Monte Carlo (150 draws each) on a double-peaked line at 140/500/2000 random
#: offsets over ±130 µm: 3.0/3.0/3.25 with photon noise (peak 5e3-2e4 counts, 300 counts of
#: background, 10 read), 2.3/2.1/1.8 with white noise; its mean 1.00-1.03 and 1.02-1.07.
SIGNAL_DEPENDENT_NOISE_REL_SD_SQRT_N = 3.2


def estimate_noise_signal_dependent(x: np.ndarray, y: np.ndarray, level: np.ndarray | None = None) -> float:
    """RMS noise of a line profile whose variance grows with its signal (photon noise on
    top of read and background noise), from the data alone: ``sqrt(mean(a + b y))``.

    An arc line's counts are Poisson: at a 20 000-count peak its noise is ~14x that of its
    wings, and the scatter of most samples, which lie in the wings, misses it. The local
    cubic's standardised prediction errors ``e`` (:func:`estimate_noise`) are modelled as
    having variance ``a + b max(y, 0)``: ``a`` from the wings (``y`` below
    :data:`WING_LEVEL` of the peak, robustly by their MAD), ``b >= 0`` so that the median of
    ``e^2 / (a + b y)`` over the line's samples is that of a chi-square with one degree of
    freedom. White noise gives ``b ~ 0`` and the wings' sigma. The mean variance is what an
    unweighted residual sum over the profile compares with (the gap test, the explained
    excess). ``y`` in units of the line's peak above background; fewer than 10 wing or 10
    line samples: the white-noise estimate of all samples.

    ``level``: the signal (same units) where ``y`` is a residual: the prediction errors are
    then those of the residual, whose line has been fitted away, so a line that is not
    smooth on the sample step (a narrow 25 mas line at 4.5 µm steps) does not leak into the
    photon term; its signal sets the variance model. Default: ``y`` is the data."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    lev = y if level is None else np.asarray(level, float)
    o = np.argsort(x)
    x, y, lev = x[o], y[o], lev[o]
    e = _standardised_errors(x, y)
    white = estimate_noise(x, y)
    if e.size < 20:
        return white
    level = np.clip(lev[2:-2], 0.0, None)
    wings, line = level < WING_LEVEL, level >= WING_LEVEL
    if wings.sum() < 10 or line.sum() < 10:
        return white
    ew = e[wings]
    a = float((1.4826 * np.median(np.abs(ew - np.median(ew)))) ** 2)
    if not a > 0:
        return white
    e2, s = e[line] ** 2, level[line]

    def excess(b):  # > 0 while b is too small to explain the line's scatter
        return float(np.median(e2 / (a + b * s))) - _CHI2_1_MEDIAN

    b = 0.0
    if excess(0.0) > 0:
        hi = max(float(np.max(e2 / s)), a)
        while excess(hi) > 0:
            hi *= 2.0
        lo = 0.0
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if excess(mid) > 0 else (lo, mid)
        b = 0.5 * (lo + hi)
    return float(np.sqrt(np.mean(a + b * np.clip(lev, 0.0, None))))


def estimate_noise(x: np.ndarray, y: np.ndarray, rows: np.ndarray | None = None) -> float:
    """White-noise sigma of samples ``y(x)`` (same unit as y), from the data alone.

    Each interior sample is predicted by the cubic through its two neighbours on each
    side; prediction errors are standardised by ``sqrt(1 + sum L_j^2)`` and their
    MAD gives sigma. Smooth signal leaks in only at fourth order in the sample spacing.
    For a map pass ``rows`` (e.g. the y coordinate): the cubic runs along each row.
    """
    x, y = np.asarray(x, float), np.asarray(y, float)
    if rows is None:
        o = np.argsort(x)
        e = _standardised_errors(x[o], y[o])
    else:
        rq = np.round(np.asarray(rows, float), 6)
        parts = []
        for v in np.unique(rq):
            sel = np.flatnonzero(rq == v)
            sel = sel[np.argsort(x[sel])]
            parts.append(_standardised_errors(x[sel], y[sel]))
        e = np.concatenate(parts) if parts else np.empty(0)
    if e.size < 5:
        return float("nan")
    return float(1.4826 * np.median(np.abs(e - np.median(e))))


#: Relative standard deviation of :func:`estimate_noise_scattered` times sqrt(n) (n the
#: points used as centres), measured by Monte Carlo on uniform random points in a 136 mm
#: disc, 200 draws each: white noise alone 1.26 (n = 3 000) and 1.13 (n = 15 000); under a
#: 0.05 µm quilt plus astigmatism 1.30 (n = 15 000), the quilt's leakage varying with the draw.
SCATTERED_NOISE_REL_SD_SQRT_N = 1.3


def _poly_terms(dx: np.ndarray, dy: np.ndarray, order: int) -> np.ndarray:
    """Monomials ``dx^i dy^(d-i)`` for ``d <= order``, stacked on a new last axis (constant first)."""
    return np.stack([dx**i * dy**(d - i) for d in range(order + 1) for i in range(d + 1)], axis=-1)


def estimate_noise_scattered(x: np.ndarray, y: np.ndarray, values: np.ndarray, neighbours: int = 20,
                             order: int = 3, max_centres: int = 100_000) -> float:
    """White-noise sigma of values at scattered points ``(x, y)`` (unit of ``values``).

    Each point is predicted from its ``neighbours`` nearest points (itself excluded) by a
    least-squares 2-D polynomial of degree ``order`` about it: the prediction is a linear
    combination ``sum_j L_j v_j`` of the neighbours' values, so its error has variance
    ``sigma^2 (1 + sum_j L_j^2)`` under white noise whatever the layout of the points;
    errors divided by that root have sigma ``sigma`` and their MAD (times 1.4826) gives it.
    Neighbourhoods that do not span two dimensions (points along a scan line) fall back
    to the polynomial along the line (minimum-norm least squares), still correctly scaled.

    Smooth signal leaks in at order + 1 in the neighbourhood radius: with 20 neighbours
    at one point per mm² a 0.08 µm quilt of 21 x 18 mm periods adds 0.12 nm in quadrature
    (2 nm noise comes out 2.004 nm); at one point per 7 mm² (about 7 points per period)
    the same quilt reads as twice the noise, as on any grid that samples it that coarsely.

    Parameters
    ----------
    x, y : ndarray, shape (n,)
        Point coordinates (any length unit, e.g. mm; only distances matter).
    values : ndarray, shape (n,)
        Values at the points (e.g. sag in µm); only finite values are used.
    neighbours : int
        Points in each local fit, > the polynomial's term count ((order+1)(order+2)/2).
    order : int
        Degree of the local polynomial, 1 to 4.
    max_centres : int
        At most this many points (evenly strided through the input) are predicted; every
        point still serves as a neighbour. 100 000 gives a relative error of 0.4 %.

    Returns
    -------
    float
        Sigma, or nan with fewer than ``neighbours + 5`` finite points.

    Raises
    ------
    ValueError
        ``order`` outside 1-4, ``neighbours`` not above the term count, ``max_centres`` < 5,
        or ``x``, ``y``, ``values`` of different lengths.
    """
    from scipy.spatial import cKDTree

    if not (isinstance(order, (int, np.integer)) and 1 <= order <= 4):
        raise ValueError(f"estimate_noise_scattered: order={order!r} must be an integer in 1..4")
    n_terms = (order + 1) * (order + 2) // 2
    if not (isinstance(neighbours, (int, np.integer)) and neighbours > n_terms):
        raise ValueError(f"estimate_noise_scattered: neighbours={neighbours!r} must be an integer > {n_terms} "
                         f"(the terms of a degree-{order} polynomial in x and y)")
    if not (isinstance(max_centres, (int, np.integer)) and max_centres >= 5):
        raise ValueError(f"estimate_noise_scattered: max_centres={max_centres!r} must be an integer >= 5")
    x, y, v = (np.asarray(a, float).ravel() for a in (x, y, values))
    if not x.size == y.size == v.size:
        raise ValueError(f"estimate_noise_scattered: x, y and values have lengths {x.size}, {y.size}, {v.size}; "
                         "they must be equal")
    ok = np.isfinite(x) & np.isfinite(y) & np.isfinite(v)
    x, y, v = x[ok], y[ok], v[ok]
    if x.size < neighbours + 5:
        return float("nan")
    pts = np.column_stack([x, y])
    centres = np.unique(np.linspace(0, x.size - 1, min(x.size, max_centres)).round().astype(int))
    _, nb = cKDTree(pts).query(pts[centres], k=neighbours + 1)
    # drop each centre from its own neighbours (normally column 0; not so for a coincident twin)
    keep = nb != centres[:, None]
    keep[keep.all(axis=1), -1] = False
    nb = nb[keep].reshape(centres.size, neighbours)
    parts = []
    for lo in range(0, centres.size, 20_000):  # bounds memory: 20 000 x neighbours x terms floats per block
        c, j = centres[lo:lo + 20_000], nb[lo:lo + 20_000]
        dx, dy = x[j] - x[c, None], y[j] - y[c, None]
        scale = np.sqrt(np.mean(dx**2 + dy**2, axis=1))[:, None]  # conditioning: unit-radius neighbourhoods
        scale = np.where(scale > 0, scale, 1.0)
        A = _poly_terms(dx / scale, dy / scale, order)
        # weights of the fitted constant (the value at the centre): first row of pinv(A);
        # normal equations where well conditioned (5x faster), pinv where not (a scan line)
        AtA = A.transpose(0, 2, 1) @ A
        eig = np.linalg.eigvalsh(AtA)
        good = eig[:, 0] > 1e-10 * eig[:, -1]
        L = np.empty(j.shape)
        e0 = np.zeros((int(good.sum()), n_terms, 1))
        e0[:, 0] = 1.0
        L[good] = np.einsum("nkj,nj->nk", A[good], np.linalg.solve(AtA[good], e0)[..., 0])
        if not good.all():
            L[~good] = np.linalg.pinv(A[~good], rcond=1e-6)[:, 0, :]
        parts.append((v[c] - np.sum(L * v[j], axis=1)) / np.sqrt(1.0 + np.sum(L**2, axis=1)))
    e = np.concatenate(parts)
    return float(1.4826 * np.median(np.abs(e - np.median(e))))


def _regular_grid(x: np.ndarray, y: np.ndarray, tol: float = 1e-3):
    """Integer grid indices ``(i, j)`` and steps of samples on a regular x/y grid (some
    nodes may be missing), or None if the samples are not on one."""
    out = []
    for v in (x, y):
        u = np.unique(np.round(v, 9))
        if u.size < 8:
            return None
        step = float(np.min(np.diff(u)))
        k = (v - u[0]) / step
        if not step > 0 or np.max(np.abs(k - np.round(k))) > tol:
            return None
        out.append((np.round(k).astype(int), step))
    (i, sx), (j, sy) = out
    if i.max() + 1 > 4096 or j.max() + 1 > 4096 or np.unique(j * (i.max() + 1) + i).size != i.size:
        return None
    return i, j, sx, sy


def estimate_noise_band_limited(x: np.ndarray, y: np.ndarray, values: np.ndarray,
                                cutoff_per_um: tuple[float, float], margin: float = 1.1,
                                min_fraction: float = 0.1, max_missing: float = 0.25) -> float:
    """White-noise sigma of an image from its power outside the optics' pass band.

    An incoherent image cannot hold spatial frequencies beyond the OTF cut-off
    (:func:`optics.lineprofile.otf_cutoff_per_um`, an ellipse with semi-axes ``fx, fy``),
    so on a grid finer than ``1 / (2 f)`` the power there is the noise's alone. Missing
    grid nodes are filled with the band-limited interpolant (Gerchberg-Papoulis
    iteration: a zero there would spread the in-band signal it cuts out over all
    frequencies — measured 1.7-3.6x sigma with 1-3 % of the nodes missing under a strong
    residual); each filled node then cancels about one degree of freedom of out-of-band
    noise, so ``sigma^2 = sum_out |FFT|^2 / (n N_out - N n_missing)`` for ``n`` samples on
    an ``N``-node grid with ``N_out`` out-of-band frequencies. Pass a residual (data minus
    a fitted model) rather than the data: the interpolant of a strong signal is less
    accurate than that of its residual.

    Why not :func:`estimate_noise`: its cubic prediction along a row needs the signal to
    be smooth on the sample step, but a focal-plane image sampled at 1 µm has Airy rings
    of ~4 µm period (the campaign's J image: sigma overestimated by 26 %, which made the
    noise floor exceed the residual a bow fit leaves).

    Parameters
    ----------
    x, y : ndarray
        Sample positions (µm) on a regular grid, nodes may be missing.
    values : ndarray
        Residual at the samples.
    cutoff_per_um : (float, float)
        OTF cut-off along x and y (cycles/µm).
    margin : float
        Frequencies beyond ``margin`` times the cut-off ellipse count as noise only.
    min_fraction : float
        Least fraction of the grid's frequencies that must lie beyond it.
    max_missing : float
        Largest fraction of missing grid nodes.

    Returns
    -------
    float
        Sigma (unit of ``values``), or nan if the samples are not on a regular grid, too
        many nodes are missing, or the grid is too coarse to leave ``min_fraction`` of its
        frequencies out of band.
    """
    x, y, v = (np.asarray(a, float) for a in (x, y, values))
    g = _regular_grid(x, y)
    if g is None or v.size < 64:
        return float("nan")
    i, j, sx, sy = g
    field = np.zeros((j.max() + 1, i.max() + 1))
    present = np.zeros(field.shape, bool)
    field[j, i], present[j, i] = v - np.mean(v), True
    n_grid, n_miss = field.size, field.size - v.size
    fy, fx = np.meshgrid(np.fft.fftfreq(field.shape[0], sy), np.fft.fftfreq(field.shape[1], sx), indexing="ij")
    out = (fx / cutoff_per_um[0]) ** 2 + (fy / cutoff_per_um[1]) ** 2 > margin**2
    n_out = int(out.sum())
    dof = v.size * n_out / n_grid - n_miss
    if n_out < min_fraction * n_grid or n_miss > max_missing * n_grid or dof < 32:
        return float("nan")
    missing = ~present
    for _ in range(200):
        spec = np.fft.fft2(field)
        spec[out] = 0.0
        fill = np.fft.ifft2(spec).real[missing]
        step = fill - field[missing]
        field[missing] = fill
        if not n_miss or np.sqrt(np.mean(step**2)) < 1e-8 * np.sqrt(np.mean(field**2)):
            break
    power = np.abs(np.fft.fft2(field)) ** 2
    return float(np.sqrt(np.sum(power[out]) / (n_grid * dof)))


def _integral_scale(rows: list[np.ndarray], max_lag: int = 200) -> float:
    """1 + 2 sum of the autocorrelation up to its first non-positive value, in samples."""
    den = sum(float(np.sum(r * r)) for r in rows)
    if den <= 0:
        return 1.0
    total = 1.0
    for k in range(1, max_lag):
        num, cnt, cnt0 = 0.0, 0, 0
        for r in rows:
            if r.size > k:
                num += float(np.sum(r[:-k] * r[k:]))
                cnt += r.size - k
                cnt0 += r.size
        if cnt < 10:
            break
        rho = (num / cnt) / (den / max(cnt0, 1))
        if rho <= 0:
            break
        total += 2 * rho
    return total


def effective_samples(residual: np.ndarray, x: np.ndarray, y: np.ndarray | None = None) -> float:
    """Effective number of independent samples of a residual on points ``x`` (profile)
    or ``x, y`` (a map or image: correlation taken along rows and columns).

    Samples on a regular grid (rows of equal ``y``) are read along their rows and columns:
    ``L = L_x L_y`` in nodes. Scattered points (fewer than two samples per distinct ``y``
    on average) are read along strips as wide as their mean spacing
    :func:`_scattered_correlation_area`, which counts them as a grid of the same density
    would be counted."""
    r = np.asarray(residual, float) - np.mean(residual)
    if y is None:
        L = _integral_scale([r[np.argsort(x)]])
        return float(np.clip(r.size / L, min(10.0, r.size), r.size))
    x, y = np.asarray(x, float), np.asarray(y, float)
    if r.size >= 10 and 2 * np.unique(np.round(y, 6)).size > r.size:
        L = _scattered_correlation_area(r, x, y)
        return float(np.clip(r.size / L, min(10.0, r.size), r.size))
    rows, cols = [], []
    for key, other, bucket in ((y, x, rows), (x, y, cols)):
        kq = np.round(key, 6)
        for v in np.unique(kq):
            sel = np.flatnonzero(kq == v)
            bucket.append(r[sel[np.argsort(other[sel])]])
    L = _integral_scale(rows) * _integral_scale(cols)
    return float(np.clip(r.size / L, min(10.0, r.size), r.size))


def _scattered_correlation_area(r: np.ndarray, x: np.ndarray, y: np.ndarray) -> float:
    """Correlation area, in points, of a residual ``r`` at scattered points ``(x, y)``.

    The points are cut into strips of width ``h = sqrt(hull area / n)`` (their mean
    spacing) along x and along y, and each strip is read in order as a row of samples:
    :func:`_integral_scale` gives ``1 + S`` with ``S = 2 sum_k rho(k g)`` over lags of
    ``g``, the mean gap between successive points of a strip. Independent points give
    ``S = 0`` whatever their layout (successive points of a strip share no error). A grid
    of the same density has a node spacing ``h_e = sqrt(g h)`` (density ``1 / (g h)``),
    and a correlation reaching ``l`` gives ``S = l / g`` along a strip against
    ``l / h_e`` along the grid's rows, so each ``S`` is rescaled by ``sqrt(g / h)``:
    ``L = (1 + S_x sqrt(g_x / h)) (1 + S_y sqrt(g_y / h))``, the grid estimator's
    ``L_x L_y`` at the points' density, independent of the strip width while the strips
    are narrow against the correlation."""
    from scipy.spatial import ConvexHull, QhullError

    try:
        area = float(ConvexHull(np.column_stack([x, y])).volume)  # a 2-D hull's "volume" is its area
    except QhullError:
        area = float(np.ptp(x) * np.ptp(y))
    h = np.sqrt(area / r.size) if area > 0 else 0.0
    if not h > 0:
        return 1.0
    L = 1.0
    for key, along in ((y, x), (x, y)):
        strip = np.floor((key - key.min()) / h).astype(int)
        order = np.lexsort((along, strip))
        cuts = np.flatnonzero(np.diff(strip[order])) + 1
        rows = np.split(r[order], cuts)
        pos = np.split(along[order], cuts)
        span = sum(float(p[-1] - p[0]) for p in pos if p.size > 1)
        steps = sum(p.size - 1 for p in pos)
        g = span / steps if steps else h
        L *= 1.0 + (_integral_scale(rows) - 1.0) * np.sqrt(g / h)
    return L


@dataclass(frozen=True)
class TwoPartErrors:
    """A residual's errors as white noise plus a smooth mismatch.

    ``sigma_w`` white-noise sigma (given or estimated from the data); ``sigma_m`` the
    mismatch's RMS, ``sqrt(max(var(r) - sigma_w^2, 0))``; ``corr_samples`` its integral
    correlation length ``L_m`` in samples (an area in samples for a map or image: the
    product of the lengths along rows and columns), from the residual's autocorrelation
    at non-zero lags, where white noise does not contribute; ``long_run_var`` =
    ``sigma_w^2 + sigma_m^2 L_m``: the variance per sample that a *smooth* change of the
    model competes with (a change rough on the scale of ``L_m`` competes with ``sigma_w``
    only, so this is the conservative one); ``n_samples`` the residual's size."""

    sigma_w: float
    sigma_m: float
    corr_samples: float
    long_run_var: float
    n_samples: int

    @property
    def n_independent(self) -> float:
        """Samples worth of independent information: ``n (sigma_w^2 + sigma_m^2) / long_run_var``."""
        return self.n_samples * (self.sigma_w**2 + self.sigma_m**2) / self.long_run_var


def two_part_errors(residual: np.ndarray, x: np.ndarray, y: np.ndarray | None, sigma_w: float) -> TwoPartErrors:
    """Split a residual's errors into white noise ``sigma_w`` and a smooth mismatch
    (:class:`TwoPartErrors`). The total residual's integral correlation length ``L``
    (:func:`effective_samples`) gives its long-run variance ``var(r) L``; white noise
    contributes ``sigma_w^2`` to it, the mismatch the rest, so ``L_m = (var(r) L -
    sigma_w^2) / sigma_m^2`` (floored at 1 sample)."""
    r = np.asarray(residual, float)
    if not (np.isfinite(sigma_w) and sigma_w >= 0):
        raise ValueError(f"two_part_errors: sigma_w={sigma_w} must be a finite number >= 0")
    n = r.size
    var = float(np.mean((r - np.mean(r)) ** 2)) if n else 0.0
    L = n / effective_samples(r, x, y) if n else 1.0
    sm2 = max(var - sigma_w**2, 0.0)
    lrv = max(var * L, sigma_w**2, 1e-300)
    Lm = max((lrv - sigma_w**2) / sm2, 1.0) if sm2 > 0 else 1.0
    return TwoPartErrors(float(sigma_w), float(np.sqrt(sm2)), float(Lm), float(sigma_w**2 + sm2 * Lm), int(n))


@dataclass(frozen=True)
class CorrelatedNoise:
    """A correlated noise along a line profile's offset axis, stated by the user: Gaussian,
    RMS ``rms_rel`` (fraction of the line's peak above background, as ``noise_rel``) and a
    squared-exponential correlation ``exp(-(dx / length_um)^2 / 2)`` between samples ``dx``
    µm apart.

    Why stated, not estimated: a noise smooth on the sample step is what a broad model
    mismatch or a halo also is, so on one profile it cannot be told from them by where its
    power lies (``benchmarks/results_nominal_floor.md``); a detector's flat-field residual
    or fringing is characterised on flats, as its read noise is."""

    rms_rel: float
    length_um: float

    def __post_init__(self):
        if not (np.isfinite(self.rms_rel) and self.rms_rel >= 0):
            raise ValueError(f"CorrelatedNoise: rms_rel={self.rms_rel!r} must be a finite number >= 0")
        if not (np.isfinite(self.length_um) and self.length_um > 0):
            raise ValueError(f"CorrelatedNoise: length_um={self.length_um!r} must be a finite number > 0 µm")

    def correlation(self, x_um: np.ndarray) -> np.ndarray:
        """Correlation matrix between the samples at ``x_um`` (µm)."""
        x = np.asarray(x_um, float)
        return np.exp(-0.5 * ((x[:, None] - x[None, :]) / self.length_um) ** 2)

    def estimator_share(self, x_um: np.ndarray) -> float:
        """The fraction of this noise's variance that the local-cubic noise estimators
        (:func:`estimate_noise`, :func:`estimate_noise_signal_dependent`) read as white noise
        on samples at ``x_um``: the mean over interior samples of ``l^T R l / l^T l``, ``l``
        a sample's prediction-error weights ``(1, -L_j)`` and ``R`` the correlation of its
        five samples. 1 for a correlation much shorter than the sample step (white noise),
        0 for one much longer (a constant is predicted exactly by the cubic)."""
        x = np.sort(np.asarray(x_um, float))
        if x.size < 5:
            return 1.0
        i, nb, L = _cubic_stencil(x)
        pts = np.vstack([i[None, :], nb])  # 5 x m: the sample and its four neighbours
        w = np.vstack([np.ones((1, i.size)), -L])
        d = (x[pts][:, None, :] - x[pts][None, :, :]) / self.length_um
        quad = np.einsum("am,abm,bm->m", w, np.exp(-0.5 * d * d), w)
        return float(np.mean(quad / np.sum(w * w, axis=0)))


def rss_moments(covariance: np.ndarray, design: np.ndarray) -> tuple[float, float]:
    """Mean and variance of the residual sum of squares that Gaussian errors of
    ``covariance`` leave after a least-squares fit of ``design``'s columns.

    The residual is ``M e`` with ``M = I - Q Q^T`` (``Q`` an orthonormal basis of the
    columns), so ``E[RSS] = tr(M C)`` and ``Var[RSS] = 2 tr(M C M C)``. For white noise
    ``C = s^2 I`` these are ``(n - k) s^2`` and ``2 (n - k) s^4``; a correlated noise puts
    more of its variance into the smooth directions the nuisances take up (a background
    takes the noise's mean) and gives a wider spread (fewer independent samples)."""
    C = np.asarray(covariance, float)
    D = np.asarray(design, float)
    if C.ndim != 2 or C.shape[0] != C.shape[1] or D.ndim != 2 or D.shape[0] != C.shape[0]:
        raise ValueError(f"rss_moments: covariance {C.shape} must be n x n and design {D.shape} n x k")
    MC = _residual_maker_times(C, D)
    return float(np.trace(MC)), float(2.0 * np.sum(MC * MC.T))


def _residual_maker_times(C: np.ndarray, D: np.ndarray) -> np.ndarray:
    """``M C`` with ``M = I - Q Q^T`` the projector off ``D``'s columns."""
    Q = np.linalg.qr(D)[0] if D.shape[1] else np.zeros((C.shape[0], 0))
    return C - Q @ (Q.T @ C)


@dataclass(frozen=True)
class RssTraces:
    """The residual sum of squares' moments (:func:`rss_moments`) for white noise of any
    level beside one fixed correlated covariance ``K``, after one design's least squares:
    with ``C = s^2 I + K`` and ``M`` idempotent, ``tr(MC) = s^2 tr M + tr(MK)`` and
    ``tr(MCMC) = s^4 tr M + 2 s^2 tr(MK) + tr(MKMK)``. A profile's noise is estimated once
    but its moments are asked at every gap test; these three numbers replace an n x n
    product per call.

    Attributes
    ----------
    free : float
        ``tr M = n - min(n, k)``, the samples left after the design's ``k`` columns (the reduced
        QR's ``Q`` has ``min(n, k)`` orthonormal columns).
    mk, mkmk : float
        ``tr(MK)`` and ``tr(MKMK)`` (the correlated noise's units squared and to the fourth).
    """

    free: float
    mk: float
    mkmk: float

    @classmethod
    def of(cls, correlated: np.ndarray, design: np.ndarray) -> "RssTraces":
        """The traces of the correlated covariance ``correlated`` (n x n) after ``design`` (n x k)."""
        K = np.asarray(correlated, float)
        D = np.asarray(design, float)
        if K.ndim != 2 or K.shape[0] != K.shape[1] or D.ndim != 2 or D.shape[0] != K.shape[0]:
            raise ValueError(f"RssTraces.of: correlated {K.shape} must be n x n and design {D.shape} n x k")
        MK = _residual_maker_times(K, D)
        return cls(float(K.shape[0] - min(D.shape)), float(np.trace(MK)), float(np.sum(MK * MK.T)))

    def moments(self, sigma_w: float) -> tuple[float, float]:
        """(mean, variance) of the residual sum of squares with white noise ``sigma_w`` added."""
        s2 = float(sigma_w) ** 2
        return s2 * self.free + self.mk, 2.0 * (s2 * s2 * self.free + 2.0 * s2 * self.mk + self.mkmk)
