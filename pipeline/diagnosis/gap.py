"""The gap and its noise: whether a measurement's residual is beyond its noise, how much of
the excess over noise a fit removes, and how many independent samples a residual holds.

``excess_explained = sum_i max(B_i - max(A_i, N_i), 0) / sum_i max(B_i - N_i, 0)``, with
``B_i``, ``A_i`` measurement i's weighted residual sums of squares before and after and
``N_i = w_i^2 (n_i - k_i) sigma_i^2`` what noise alone leaves (``k_i`` its nuisances; an
estimated ``sigma_i`` taken at its one-sigma lower bound): the part of each measurement's
residual beyond its noise that the fit removes. Taken per measurement, a profile whose noise
is overstated (residual below it) neither cancels another's excess nor counts a fit into its
noise as explanation (a stated peak-level photon noise put a 25 mas profile at
chi^2_red 0.4 and a fit that took the 250 mas profile from chi^2_red 2.8 to its noise read as
0 % explained). Where the manifest states a profile's correlated noise, ``N_i`` is the mean
and the z-test's spread the variance of what white and correlated noise leave a right model
(:meth:`.forward.ProfileForward.noise_rss_moments`). The decision logic that uses these is
described in ``docs/diagnosis.md``.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from .criteria import Criteria
from .effects import LIBRARY
from .fitting import FitOutcome, Problem
from .noise import effective_samples

__all__ = ["NOISE_ESTIMATE_REL_SD_SQRT_N", "has_gap", "noise_per_dof", "gap_statistics", "gaps", "excess_explained", "excesses",
           "acting_on", "residual_n_eff", "post_fit_n_eff", "recounted", "recount"]


def residual_n_eff(f, r) -> float:
    """Effective samples of measurement ``f``'s residual ``r`` (maps and images: correlation
    along both axes)."""
    return effective_samples(r, f.x, f.y if f.kind != "line_profile" else None)


def post_fit_n_eff(prob: Problem, fo: FitOutcome) -> dict:
    """Effective sample count of each measurement's residual after the fit ``fo``.

    The score should count the independent samples of the *errors* (noise plus what the
    model does not describe). The nominal residual also carries the signal being looked
    for, whose correlation length is the effect's, not the errors': a 128 K map whose
    nominal residual is a smooth temperature signal sits at the floor (10) and one map
    then gives at most ~10 ln(1/(1 - shrink)^2) of evidence. Measured on campaign
    cases: after the temperature fit, which leaves the unmodelled trefoil and the noise,
    40-60 (four temperatures recovered within 3-14 % were at delta BIC -7.6 … -9.4);
    line profiles 10-20 -> 100-160 after a good fit; a map of an out-of-library bump,
    which no candidate takes up, 10 -> 12-23."""
    return {f.name: residual_n_eff(f, f.residual(fo.parameters, fo.deltas_um.get(f.name, f.delta0_um)))
            for f in prob.forwards}


def recounted(prob: Problem, n_count: dict) -> Problem:
    """``prob`` whose score counts ``n_count`` effective samples; weights and the error
    bars' sample count (``n_eff``) unchanged, so every fit is the same and only the
    evidence changes (Criteria.n_eff_from)."""
    return Problem(prob.forwards, prob.weights, prob.n_eff, prob.noise, dict(n_count))


def recount(prob: Problem, fo: FitOutcome) -> FitOutcome:
    """``fo`` (a fit of ``prob``'s weights) scored with ``prob``'s counts."""
    return replace(fo, n_count=prob.counts_for(fo.n))


#: Relative standard deviation of :func:`.noise.estimate_noise` times sqrt(n): measured by
#: Monte Carlo on white noise at the campaign's sparse random sampling (n = 80/160/320:
#: 1.79/1.69/1.64; larger than i.i.d. MAD's 1.17 because neighbouring prediction errors
#: share samples).
NOISE_ESTIMATE_REL_SD_SQRT_N = 1.7


def _nuisances(f) -> int:
    """Nuisance parameters of one measurement's fit: piston + 2 tilts (map) | offset shift +
    flux + background (profile) | position (2) + flux + background (PSF image)."""
    return f.nuisance_count + f.n_shift


def _noise_rel_sd(f) -> float:
    """Relative standard deviation of a measurement's noise: 0 if the manifest gives it; the
    estimator's own if the model states one (a map's scattered points), else that of
    :func:`.noise.estimate_noise` over the measurement's samples."""
    if f.noise_known:
        return 0.0
    own = getattr(f, "noise_rel_sd", None)
    return own if own is not None else NOISE_ESTIMATE_REL_SD_SQRT_N / math.sqrt(max(f.n, 1))


def _noise_cost(prob: Problem, n: dict) -> float:
    """Weighted residual sum of squares that white noise alone would leave, with a noise
    *estimated* from the data taken at its one-sigma lower bound: the excess over noise
    is then an upper bound and ``excess_explained`` a conservative (lower) one. Without
    this, a gap of 1.1-1.4 sigma (an out-of-library profile distortion mostly absorbed
    by the offset shift) was half 'explained' by noise in the noise estimate."""
    out = 0.0
    for f in prob.forwards:
        if f.name in n:
            sigma = prob.noise[f.name] * max(1.0 - _noise_rel_sd(f), 0.5)
            if f.correlated_noise is None:
                out += prob.weights[f.name] ** 2 * max(n[f.name] - _nuisances(f), 0) * sigma**2
            else:
                out += prob.weights[f.name] ** 2 * f.noise_rss_moments(sigma)[0] * n[f.name] / f.n
    return out


def noise_per_dof(prob: Problem, f) -> float:
    """The residual RMS per degree of freedom that noise alone leaves measurement ``f``: its
    white noise, or with a stated correlated noise the square root of the mean residual sum
    of squares both leave over the degrees of freedom."""
    sigma = prob.noise[f.name]
    if f.correlated_noise is None or not sigma >= 0:
        return sigma
    return math.sqrt(f.noise_rss_moments(sigma)[0] / max(f.n - _nuisances(f), 1))


def has_gap(prob: Problem, nom: FitOutcome, c: Criteria) -> bool:
    """Whether any measurement's nominal residual is beyond its noise.

    Either its RMS exceeds ``no_gap_ratio`` times the noise, an estimated noise taken at its
    one-sigma upper bound ``sigma (1 + r)``, or its reduced chi^2 exceeds 1 by more than
    ``no_gap_z`` standard deviations: ``sd^2 = 2 / dof + (2 r)^2``; ``r`` is the relative
    standard deviation of an estimated noise (:func:`_noise_rel_sd`: 0 when the manifest
    gives it). The bound mirrors the explained-excess test's (:func:`_noise_cost`, the
    lower bound): a profile's noise estimated from 89 samples is 24 % uncertain, and
    against the estimate itself the ratio alone called about a fifth of three-profile
    nominal cases a gap (photon-noise profiles, ``benchmarks/gap_noise_bound.py``: 63 of
    300 draws, 2 of 300 against the bound). The RMS ratio alone misses a gap spread over
    many samples: a map's residual at 1.18 x its noise over 14 295 samples is a chi^2
    excess of 12 such standard deviations (a campaign ghost case, map + PSF image: delta BIC of
    the best finding -214, called ``no_gap`` by the ratio alone).
    """
    return bool(gaps(prob, nom, c))


def gap_statistics(prob: Problem, fo: FitOutcome) -> dict:
    """Per measurement, the residual of ``fo`` against the noise: ``rms_ratio`` (RMS over
    noise), ``z`` (excess of the reduced chi^2 over 1 in standard deviations, as in
    :func:`has_gap`) and ``noise_rel_sd`` (the noise's relative uncertainty, 0 where stated)."""
    out = {}
    for f in prob.forwards:
        m = f.name
        sigma, r = prob.noise[m], _noise_rel_sd(f)
        if not sigma > 0:
            out[m] = {"rms_ratio": math.inf, "z": math.inf, "noise_rel_sd": r}
            continue
        dof = max(fo.n[m] - _nuisances(f), 1)
        if f.correlated_noise is None:
            out[m] = {"rms_ratio": math.sqrt(fo.rss[m] / fo.n[m]) / sigma,
                      "z": (fo.rss[m] / (dof * sigma**2) - 1.0) / math.sqrt(2.0 / dof + (2.0 * r) ** 2),
                      "noise_rel_sd": r}
            continue
        # the stated correlated noise's share of the mean and of the spread; the white
        # part's estimate keeps its own uncertainty
        mean, var = (v * fo.n[m] / f.n for v in f.noise_rss_moments(sigma))
        white = dof * sigma**2
        out[m] = {"rms_ratio": math.sqrt(fo.rss[m] / fo.n[m]) / math.sqrt(mean / dof),
                  "z": (fo.rss[m] / mean - 1.0) / math.sqrt(var / mean**2 + (2.0 * r * white / mean) ** 2),
                  "noise_rel_sd": r * white / mean}
    return out


def gaps(prob: Problem, fo: FitOutcome, c: Criteria) -> list:
    """The measurements whose residual under ``fo`` is beyond noise (:func:`has_gap`'s
    test), as ``{"measurement", "rms_ratio", "z", "noise_rel_sd"}``."""
    return [{"measurement": m, **g} for m, g in gap_statistics(prob, fo).items()
            if g["rms_ratio"] > c.no_gap_ratio * (1.0 + g["noise_rel_sd"]) or g["z"] > c.no_gap_z]


def acting_on(prob: Problem, effects) -> tuple:
    """Names of the measurements whose kind any of ``effects`` changes (a slit width
    changes line profiles, not a surface map or a point-source image)."""
    kinds = {k for e in effects for k in LIBRARY[e].kinds}
    return tuple(f.name for f in prob.forwards if f.kind in kinds)


def excess_explained(prob: Problem, nom: FitOutcome, fo: FitOutcome, measurements=None) -> float:
    """Fraction of the residual *beyond noise* of ``nom`` that ``fo`` removes (module
    docstring), over ``measurements`` (names; default all)."""
    names = [m for m in nom.rss if measurements is None or m in measurements]
    w = prob.weights
    excess = removed = 0.0
    for m in names:
        before, after = w[m] ** 2 * nom.rss[m], w[m] ** 2 * fo.rss[m]
        noise = _noise_cost(prob, {m: nom.n[m]})
        excess += max(before - noise, 0.0)
        removed += max(before - max(after, noise), 0.0)
    if not excess > 0:
        return 0.0
    return float(np.clip(removed / excess, 0.0, 1.0))


def excesses(prob: Problem, ref: FitOutcome, fo: FitOutcome, effects) -> dict:
    """``excess_explained`` over the measurements ``effects`` act on, and over all."""
    return {"excess_explained": excess_explained(prob, ref, fo, acting_on(prob, effects)),
            "excess_explained_overall": excess_explained(prob, ref, fo)}
