"""Fitting effects to the data: weighted least squares, uncertainties, information criterion.

Noise model. Measured residuals are rarely white: besides the measurement noise they
carry smooth model discrepancy. Each measurement ``i`` therefore gets

* ``sigma_i``: the noise estimated from the data alone (:mod:`.noise`), unless given;
* ``n_eff_i``: the number of effectively independent samples of the *nominal*
  residual, ``n / L`` with ``L`` the integral correlation length in samples (per axis
  for maps, :func:`.noise.effective_samples`);
* weight ``w_i = sqrt(n_eff_i / n_i) / s_i`` with ``s_i`` the nominal residual RMS, so
  every measurement contributes ~``n_eff_i`` to the objective whatever its units
  (:func:`nominal_weights`; ``Criteria.weight_scale = "kind"`` instead normalises the
  measurements of one kind together, ``w_i = c_K / sigma_i``).

Score: ``BIC = N_eff log(sum_i w_i^2 RSS_i / N_eff) + k log N_eff`` with
``N_eff = sum_i n_eff_i``: a Gaussian likelihood whose per-measurement variances are
proportional to the nominal residual variances (one common factor profiled out),
counted over effective samples — the same weighted sum of squares the fit minimises,
so the score ranks what the fit optimises (``Problem.n_count``, if set, replaces the
``n_eff_i`` the score counts, not the weights: see ``Criteria.n_eff_from``). Lower is
better; ``delta_bic`` below -10 is "very strong" evidence (Kass & Raftery 1995).
Uncertainties: ``s^2 (J^T J)^-1`` at the optimum with ``s^2`` the weighted residual per
effective degree of freedom — i.e. inflated by the residual correlation. Because the
weights are normalised by the nominal residual, not by the noise, ``s^2`` is already the
reduced chi^2 of the fit (Birge-ratio scaling: errors grow with any misfit, noise or model
mismatch) counted over the nominal residual's effective samples. Model mismatch left in
the *post-fit* residual is correlated over its own length, which can exceed the
nominal residual's: ``s^2`` is therefore the larger of the above and the residual's
long-run variance ``sum_i w_i^2 RSS_i L_i / (N - k)`` (``L_i`` the integral correlation
length of measurement i's post-fit residual in samples, a Newey-West-type estimate;
:func:`long_run_s2`). The curvature sees one basin only: where another start of the
multi-start fit ends in a second minimum whose cost is within ``s^2`` of the best (inside
the one-parameter 68 % region of the profile likelihood, ``delta chi^2 <= 1``), each
parameter's uncertainty also spans the distance to it, added in quadrature
(:data:`OTHER_BASIN_CHI2`). Mismatch absorbed *into* the parameters is invisible to any
residual-based estimate; the engine adds in quadrature how far the parameters move when
a known mismatch the data do not rule out is modelled (the ``plating_gradient`` and
``blank_bow`` companions; :func:`pipeline.diagnosis.ranking.mismatch_errors`). Measured
and not used: the spread of the leave-one-measurement-out fits the held-out check already
makes (a jackknife over measurements). On two independent-truth pupil shifts whose
``pupil_y`` came out 1.1 mm off (a quilt with pocket-to-pocket amplitude jitter, and a
sum-form mixture), the six leave-one-out fits agreed to a jackknife spread of 0.17 and
0.27 mm, below the reported 0.25 and 1.27 mm: the profiles of one grating share its quilt's
mismatch, which no spread between them can show. The jackknife did grow for a wrong model
(``collimator_wfe`` fitted to a pupil shift: coma 0.002 -> 0.08 µm).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from .effects import Parameter
from .noise import effective_samples

__all__ = ["FitOutcome", "Problem", "fit", "fd_steps", "grouped_fd_jacobian", "DIFF_STEP", "objective", "nominal_weights", "long_run_s2", "other_basin_moves", "OTHER_BASIN_CHI2"]

_DELTA_SCALE_UM = 10.0  # normalisation of the profile offset-shift nuisance
_DELTA_BOUND_UM = 45.0
# The local fit stops when a step lowers the weighted cost by less than this fraction of it.
# The BIC is N_eff log(cost / N_eff) + k log N_eff, so a relative change d of the cost moves
# it by N_eff d: at most about 1e-3 for the campaign's data (N_eff 10-1207), against the
# 10 a finding needs and the 1 in chi-square of a parameter's sigma. A tighter tolerance only
# lets the trust region crawl along directions the data barely constrain (quilt_shape's
# ratios beside a map's registration: 560 evaluations at 1e-8, 14 at 1e-6; measured on
# benchmarks/results_fit_tolerance.md).
_FTOL = 1e-6
# A local minimum of the multi-start fit that costs at most this many s^2 more than the
# best lies inside the one-parameter 68 % profile-likelihood region (Wilks: delta chi^2 = 1).
# Measured: J profiles of a 6 mm pupil shift (Abbe-sum truth) have minima at 4.0 and
# 6.6 mm that differ by 0.002 in cost against s^2 = 0.44, and which one wins depended on the
# machine's floating point, while the curvature alone gave +-0.6 mm.
OTHER_BASIN_CHI2 = 1.0


def long_run_s2(problem, fws, masks: dict, resid: dict, k: int) -> float:
    """Weighted post-fit residual variance per degree of freedom with each measurement's
    samples counted ``L_i`` times (``L_i`` = its post-fit residual's integral correlation
    length): the long-run variance that the projection ``J^T r`` of a correlated residual
    has (white noise: ``L = 1``)."""
    tot, n_all = 0.0, 0
    for f in fws:
        r = resid[f.name]
        if r.size < 5:
            continue
        m = masks.get(f.name)
        x = f.x if m is None else f.x[m]
        y = getattr(f, "y", None)  # maps and images: correlation along rows and columns
        y = y if m is None or y is None else y[m]
        L = r.size / effective_samples(r, x, y)
        tot += problem.weights[f.name] ** 2 * float(np.sum(r**2)) * L
        n_all += r.size
    return tot / max(n_all - k, 1.0)


@dataclass(eq=False)
class Problem:
    """The forward models of all measurements with their weights and effective sizes."""

    forwards: list
    weights: dict = field(default_factory=dict)
    n_eff: dict = field(default_factory=dict)
    noise: dict = field(default_factory=dict)
    n_count: dict | None = None  # samples counted by the score, if not n_eff (gap.post_fit_n_eff)
    #: The weights are absolute (1 / the errors' long-run sigma, :mod:`.error_model`): the
    #: score is then a chi^2, not a likelihood with a common variance factor profiled out.
    absolute: bool = False

    @property
    def names(self) -> list[str]:
        return [f.name for f in self.forwards]

    def counts_for(self, n: dict) -> dict | None:
        """The score's counts of a fit that used ``n[m]`` samples of measurement m (``None``
        when the score counts ``n_eff``)."""
        if self.n_count is None:
            return None
        size = {f.name: f.n for f in self.forwards}
        return {m: self.n_count[m] * n[m] / size[m] for m in n}


@dataclass(frozen=True, eq=False)
class FitOutcome:
    """Best-fit effect parameters (physical units), 1-sigma errors, per-measurement RSS."""

    parameters: dict
    errors: dict
    deltas_um: dict
    rss: dict
    n: dict
    n_eff: dict
    k: int
    success: bool
    nfev: int
    weighted_cost: float
    n_count: dict | None = None
    absolute: bool = False

    @property
    def counts(self) -> dict:
        """Effective samples per measurement that the score counts (``n_count``, else ``n_eff``)."""
        return self.n_eff if self.n_count is None else self.n_count

    def weighted_rss(self, weights: dict) -> float:
        """``sum_i w_i^2 RSS_i``: the objective the fit minimises, over the measurements fitted."""
        return float(sum(weights[m] ** 2 * self.rss[m] for m in self.rss))

    def bic(self, weights: dict) -> float:
        """``N_eff log(sum_i w_i^2 RSS_i / N_eff) + k log N_eff`` (consistent with the fit's
        objective); with absolute weights ``sum_i w_i^2 RSS_i + k log N_eff`` (a chi^2)."""
        neff = max(sum(self.counts.values()), 2.0)
        cost = self.weighted_rss(weights)
        if self.absolute:
            return float(cost + self.k * math.log(neff))
        return float(neff * math.log(max(cost, 1e-300) / neff) + self.k * math.log(neff))

    def score_change(self, other_cost: float, weights: dict) -> float:
        """How much worse the score would be with the weighted cost ``other_cost`` (same
        parameter count): ``N_eff log(other / cost)``, or ``other - cost`` with absolute weights."""
        cost = self.weighted_rss(weights)
        if self.absolute:
            return float(other_cost - cost)
        neff = max(sum(self.counts.values()), 2.0)
        return float(neff * math.log(max(other_cost, 1e-300) / max(cost, 1e-300)))


def nominal_weights(kinds: dict, n: dict, rss: dict, n_eff: dict, noise: dict, scale: str = "measurement") -> dict:
    """Each measurement's weight from its nominal residual.

    Parameters
    ----------
    kinds, n, rss, n_eff, noise : dict {measurement name: value}
        Kind, sample count, nominal residual sum of squares, effective samples and white
        noise sigma (the data's units) of every measurement.
    scale : {"measurement", "kind"}
        "measurement": ``w_i = sqrt(n_eff_i / n_i) / s_i`` with ``s_i`` the nominal RMS, so
        every measurement contributes ``n_eff_i`` to the objective at the nominal. "kind":
        the measurements of one kind contribute the same total, shared as their nominal
        chi^2 (``RSS_i / sigma_i^2``) are: ``w_i = c / sigma_i`` with
        ``c^2 = sum n_eff_i / sum RSS_i / sigma_i^2`` over the kind.

    Returns
    -------
    dict {measurement name: weight}

    Why "kind": normalised one by one, a profile whose nominal residual is 86 times its noise
    weighs as much as one at twice its noise, so several well-fitting profiles outvote one
    with a large gap (measured: a 38 K warmer blank's 100 mas profile against four 25 mas
    ones on a quilt with pocket-to-pocket amplitude jitter; the fit stayed at the nominal).
    Within one kind the measurements share an instrument and a noise model, so one common
    variance factor over the noise is the likelihood's own assumption; between kinds (a map in
    µm, a profile in counts) there is no common noise scale and each kind keeps its own."""
    s = {m: max(math.sqrt(rss[m] / n[m]), 1e-12) for m in n}
    if scale == "measurement":
        return {m: math.sqrt(n_eff[m] / n[m]) / s[m] for m in n}
    if scale != "kind":
        raise ValueError(f"nominal_weights: scale={scale!r} must be 'measurement' or 'kind'")
    out = {}
    for k in set(kinds.values()):
        group = [m for m in n if kinds[m] == k]
        sig = {m: max(noise[m], 1e-6 * s[m]) for m in group}
        chi2 = sum(rss[m] / sig[m] ** 2 for m in group)
        c = math.sqrt(sum(n_eff[m] for m in group) / max(chi2, 1e-300))
        out.update({m: c / sig[m] for m in group})
    return out


def other_basin_moves(minima, s2: float, chi2: float = OTHER_BASIN_CHI2) -> np.ndarray:
    """Per parameter, the largest distance from the best local minimum to any other whose
    cost is within ``chi2 * s2`` of it (0 where there is none).

    Parameters
    ----------
    minima : list of (float, array)
        ``(weighted cost, parameter vector)`` of every local fit of one multi-start, the
        cost as the sum of squared weighted residuals; the vectors in any common units.
    s2 : float
        Variance scale of the weighted residual (the reduced chi^2 of the best fit).
    chi2 : float
        Cost difference, in units of ``s2``, inside which a minimum is as good as the best.

    Returns
    -------
    numpy.ndarray
        Distances in the units of the vectors, one per parameter.
    """
    costs = np.array([c for c, _ in minima], dtype=float)
    z = np.array([np.asarray(v, dtype=float) for _, v in minima])
    if z.size == 0:
        return np.zeros(0)
    b = int(np.argmin(costs))
    near = costs - costs[b] <= chi2 * s2
    return np.max(np.abs(z[near] - z[b]), axis=0)


#: Relative step of the forward differences (``least_squares``' ``diff_step``).
DIFF_STEP = 1e-4


def fd_steps(z: np.ndarray, lo: np.ndarray, hi: np.ndarray, rel_step: float = DIFF_STEP) -> np.ndarray:
    """The forward-difference step of every parameter, as ``scipy.optimize.least_squares``
    takes it with ``diff_step=rel_step``: ``rel_step * |z|`` signed as ``z`` (``z = 0``
    counts as positive), ``sqrt(eps) * max(1, |z|)`` where that step is lost to rounding
    (``z = 0``), and turned inward, or shortened to the room left, where it would cross a
    bound."""
    z, lo, hi = (np.asarray(a, dtype=float) for a in (z, lo, hi))
    sign = (z >= 0).astype(float) * 2 - 1
    h = rel_step * sign * np.abs(z)
    h = np.where((z + h) - z == 0, np.finfo(float).eps ** 0.5 * sign * np.maximum(1.0, np.abs(z)), h)
    lower, upper = z - lo, hi - z
    crosses = ((z + h) < lo) | ((z + h) > hi)
    fits = np.abs(h) <= np.maximum(lower, upper)
    h = np.where(crosses & fits, -h, h)
    h = np.where(~fits & (upper >= lower), upper, h)
    return np.where(~fits & (upper < lower), -lower, h)


def grouped_fd_jacobian(fun, z: np.ndarray, f0: np.ndarray, h: np.ndarray, groups: list) -> np.ndarray:
    """Forward-difference Jacobian ``(fun(z + h_j e_j) - f0) / dx_j`` with the columns of a
    group perturbed in one evaluation (Curtis, Powell & Reid 1974).

    Parameters
    ----------
    fun : callable
        Residual vector of the parameters.
    z, f0, h : numpy.ndarray
        Parameters, ``fun(z)`` and the steps (:func:`fd_steps`).
    groups : list of list of (int, slice or None)
        Each group's columns with the rows each one changes (``None``: every row). Columns
        of one group must change disjoint rows; a column with ``None`` must be alone.

    Returns
    -------
    numpy.ndarray
        The Jacobian (rows x columns): column by column the numbers a one-column-at-a-time
        difference with the same steps gives, since a column's rows do not depend on the
        other columns of its group.

    Raises
    ------
    ValueError
        If ``h`` and ``z`` differ in size, or a group holds a column acting on every row beside
        others or columns whose rows overlap (their differences would mix).
    """
    if np.size(h) != np.size(z):
        raise ValueError(f"grouped_fd_jacobian: h has {np.size(h)} steps for {np.size(z)} parameters")
    for group in groups:
        spans = sorted((rows.indices(f0.size)[:2] for _, rows in group if rows is not None))
        if (len(group) > 1 and any(rows is None for _, rows in group)) or any(
                a[1] > b[0] for a, b in zip(spans, spans[1:])):
            raise ValueError(f"grouped_fd_jacobian: group {[j for j, _ in group]} perturbs columns whose rows overlap; "
                             "a group's columns must change disjoint rows, a column acting on every row stands alone")
    jt = np.zeros((z.size, f0.size))
    for group in groups:
        z1 = z.copy()
        for j, _ in group:
            z1[j] = z[j] + h[j]
        df = fun(z1) - f0
        for j, rows in group:
            dx = (z[j] + h[j]) - z[j]
            if rows is None:
                jt[j] = df / dx
            else:
                jt[j, rows] = df[rows] / dx
    return jt.T


def _shift_slots(fws) -> list:
    """(forward, component) of every position nuisance that is a fit parameter: a line
    profile's offset shift (1), a PSF image's position (2)."""
    return [(f, k) for f in fws for k in range(f.n_shift)]


def _unpack(z, params, slots, fixed=None):
    p = dict(fixed or {})
    p.update({q.name: q.null + zi * q.width for q, zi in zip(params, z)})
    d = {}
    for (f, _), zi in zip(slots, z[len(params):]):
        d.setdefault(f.name, []).append(zi * _DELTA_SCALE_UM)
    return p, {k: (v[0] if len(v) == 1 else tuple(v)) for k, v in d.items()}


def _best_starts(starts, z0, n_par, params, slots, fixed, problem, masks, fws, n_local):
    """The ``n_local`` grid points with the lowest cost, each profile's offset shift
    profiled by a 0.5-µm grid search within ±15 µm of its nominal value (the profile
    model is memoised on the physical parameters, so each shift costs an interpolation).
    A PSF image's position is not grid-searched: it is ranked at its nominal position."""
    shifts = np.arange(-15.0, 15.01, 0.5)
    ranked = []
    for s in starts:
        z = z0.copy()
        z[:n_par] = s
        p, d = _unpack(z, params, slots, fixed)
        cost = 0.0
        for f in fws:
            m = masks.get(f.name)
            if f.kind == "line_profile":
                c = [float(np.sum(f.residual(p, d[f.name] + ds, m) ** 2)) for ds in shifts]
                j = int(np.argmin(c))
                z[n_par + slots.index((f, 0))] = np.clip((d[f.name] + shifts[j]) / _DELTA_SCALE_UM,
                                                       -_DELTA_BOUND_UM / _DELTA_SCALE_UM, _DELTA_BOUND_UM / _DELTA_SCALE_UM)
                cost += problem.weights[f.name] ** 2 * c[j]
            else:
                cost += problem.weights[f.name] ** 2 * float(np.sum(f.residual(p, d.get(f.name, 0.0), m) ** 2))
        ranked.append((cost, z))
    ranked.sort(key=lambda t: t[0])
    return [z for _, z in ranked[:max(n_local, 1)]]


def objective(problem: Problem, values: dict, deltas_um: dict | None = None) -> float:
    """The fit's objective, ``sum_i w_i^2 RSS_i``, at one point: the effect parameters
    ``values`` (every other at its null), each measurement's position nuisances at
    ``deltas_um`` (``FitOutcome.deltas_um``; the measurement's initial one where missing),
    the linear nuisances (flux, coupling, background; piston and tilt) solved as in a fit.
    Used to choose between warm starts of one fit without running it from each."""
    deltas_um = deltas_um or {}
    return float(sum(problem.weights[f.name] ** 2
                     * np.sum(f.residual(values, deltas_um.get(f.name, f.delta0_um)) ** 2) for f in problem.forwards))


def fit(problem: Problem, params: tuple[Parameter, ...], masks: dict | None = None,
        max_starts: int = 30, max_nfev: int | None = None, fixed: dict | None = None,
        start: dict | None = None, n_local: int = 3, regrid: tuple = (),
        start_deltas_um: dict | None = None) -> FitOutcome:
    """Fit ``params`` (plus every profile's offset shift) to the data under ``masks``.

    Parameters
    ----------
    problem : Problem
        Forward models with weights (:func:`~pipeline.diagnosis.engine.build_problem`).
    params : tuple of Parameter
        Effect parameters to free; all others stay at their null values.
    masks : dict {measurement name: bool array}, optional
        Samples to fit (held-out validation); measurements missing from the dict or
        with an empty mask are left out.
    max_starts : int
        Cap on the coarse grid of start values (product of ``Parameter.starts``).
    fixed : dict, optional
        Values of parameters held fixed (not fitted), e.g. applying a training fit to
        held-out data with only the nuisances free.
    start : dict, optional
        Warm start for some of ``params`` (skips the grid search, except over ``regrid``).
    regrid : tuple of str
        With ``start``: parameters also grid-searched (their ``Parameter.starts``, the
        others at the warm start), the ``n_local`` best grid points run beside the warm
        start. Why: a pair is started from its members' single fits, and a member fitted
        alone can sit in the wrong basin that the other member would have left (measured:
        the paper's J scenario under the two-part weights, a 4 mm pupil shift fitted alone
        at the -10 mm bound, and the pair with the amplitude kept it there).
    start_deltas_um : dict {measurement name: µm or (µm, µm)}, optional
        With ``start``: the position nuisances' warm start (``FitOutcome.deltas_um`` of the
        fit ``start`` comes from), so the local fit starts at that fit's optimum, not at
        the nominal positions.
    n_local : int
        Multi-start: the local least-squares fit is run from the ``n_local`` best grid
        points and the lowest cost wins. Grid points are ranked with every profile's
        offset shift re-optimised (a pupil shift moves the line, so ranking them at
        the nominal's shift favours the wrong basin: measured in the campaign, a
        7.6 mm shift was fitted as 3.0 mm from a single start).
    """
    masks = masks or {}
    fws = [f for f in problem.forwards if f.name not in masks or masks[f.name].any()]
    slots = _shift_slots(fws)
    z0 = np.concatenate([np.zeros(len(params)), [np.ravel(f.delta0_um)[k] / _DELTA_SCALE_UM for f, k in slots]])
    lo = np.concatenate([[(q.lo - q.null) / q.width for q in params], np.full(len(slots), -_DELTA_BOUND_UM / _DELTA_SCALE_UM)])
    hi = np.concatenate([[(q.hi - q.null) / q.width for q in params], np.full(len(slots), _DELTA_BOUND_UM / _DELTA_SCALE_UM)])

    last: dict = {}  # the latest residual vector, by parameters: the Jacobian's f0
    groups: list = []  # the Jacobian's column groups (grouped_fd_jacobian), from the first residual

    def residuals(z):
        p, d = _unpack(z, params, slots, fixed)
        out = [problem.weights[f.name] * f.residual(p, d.get(f.name, 0.0), masks.get(f.name)) for f in fws]
        last.clear()
        last[z.tobytes()] = vec = np.concatenate(out)
        if not groups:
            edges = np.cumsum([0] + [r.size for r in out])
            blocks = {f.name: slice(int(a), int(b)) for f, a, b in zip(fws, edges[:-1], edges[1:])}
            # A position nuisance changes only its own measurement's rows, so the nuisances of
            # different measurements share one evaluation (the i-th component of each); an
            # effect parameter changes every row and has one of its own.
            shift_groups = [[(len(params) + j, blocks[f.name]) for j, (f, k) in enumerate(slots) if k == c]
                            for c in range(max((k + 1 for _, k in slots), default=0))]
            groups[:] = [[(i, None)] for i in range(len(params))] + shift_groups
        return vec

    def jacobian(z):
        f0 = last.get(z.tobytes())
        if f0 is None:
            f0 = residuals(z)
        return grouped_fd_jacobian(residuals, z, f0, fd_steps(z, lo, hi), groups)

    grids = [[(s - q.null) / q.width for s in (q.starts or (q.null,))] for q in params]
    starts = list(itertools.product(*grids))
    inits = [z0]
    if start:
        for i, q in enumerate(params):
            if q.name in start:
                z0[i] = np.clip((start[q.name] - q.null) / q.width, lo[i], hi[i])
        for j, (f, k) in enumerate(slots):
            if start_deltas_um and f.name in start_deltas_um:
                i = len(params) + j
                z0[i] = np.clip(np.ravel(start_deltas_um[f.name])[k] / _DELTA_SCALE_UM, lo[i], hi[i])
        if regrid:
            warm = [[z0[i]] if q.name not in regrid else g for i, (q, g) in enumerate(zip(params, grids))]
            inits = [z0.copy()] + _best_starts(list(itertools.product(*warm))[:max_starts], z0, len(params), params,
                                               slots, fixed, problem, masks, fws, n_local)
    elif len(starts) > 1 or any(f.kind == "line_profile" for f in fws):
        # Also with nothing to grid (no free effect parameter, e.g. applying a training
        # fit to withheld data): the profiles' offset shifts are still grid-searched. The
        # effect held fixed can move a line by more than the local fit's basin (a coma
        # shifts it), and a shift stuck in the wrong basin made a held-out fold's
        # "after" residual 19x its "before" (measured: a campaign case with a map and a
        # PSF image, fold "others -> J_1.175_25mas", shrink -3.41).
        inits = _best_starts(starts[:max_starts], z0, len(params), params, slots, fixed, problem, masks, fws,
                             n_local)
    nfree = z0.size
    if nfree == 0:
        res_vec = residuals(z0)
        z, jac, success, nfev = z0, np.zeros((res_vec.size, 0)), True, 1
    else:
        sols = [least_squares(residuals, zi, jac=jacobian, bounds=(lo, hi), method="trf", x_scale=1.0,
                              max_nfev=max_nfev or 40 * (nfree + 1), xtol=1e-6, ftol=_FTOL) for zi in inits]
        best = min(sols, key=lambda sol: sol.cost)
        z, jac, success, nfev, res_vec = best.x, best.jac, bool(best.success), int(best.nfev), best.fun
    p, d = _unpack(z, params, slots, fixed)
    rss, n, neff, resid = {}, {}, {}, {}
    for f in fws:
        m = masks.get(f.name)
        r = f.residual(p, d.get(f.name, 0.0), m)
        rss[f.name], n[f.name] = float(np.sum(r**2)), int(r.size)
        neff[f.name] = problem.n_eff[f.name] * r.size / f.n
        resid[f.name] = r
    n_lin = sum(f.nuisance_count for f in fws)
    k = len(params) + len(slots) + n_lin
    errors = {}
    if params:
        cost_w = float(np.sum(res_vec**2))
        s2 = max(cost_w / max(sum(neff.values()) - k, 1.0), long_run_s2(problem, fws, masks, resid, k))
        J = np.asarray(jac)[:, :len(params)]
        JtJ = J.T @ J
        # Columns with no leverage (the parameter does not touch these data) are unconstrained.
        ok = np.diag(JtJ) > 1e-12 * max(float(np.max(np.diag(JtJ))), 1e-300)
        cov = np.full((len(params), len(params)), np.inf)
        if ok.any():
            cov_ok = s2 * np.linalg.pinv(JtJ[np.ix_(ok, ok)])
            cov[np.ix_(ok, ok)] = cov_ok
        moves = other_basin_moves([(2.0 * sol.cost, sol.x[:len(params)]) for sol in sols], s2)
        for i, q in enumerate(params):
            e = float(math.sqrt(max(cov[i, i], 0.0))) if np.isfinite(cov[i, i]) else float("inf")
            errors[q.name] = float(math.hypot(e, moves[i]) * q.width)
    return FitOutcome({q.name: float(p[q.name]) for q in params}, errors, d, rss, n, neff, k, success, nfev,
                      float(np.sum(res_vec**2)), problem.counts_for(n), problem.absolute)
