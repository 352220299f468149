"""The two-part error model (``Criteria.error_model = "two_part"``): each measurement's
errors are white noise plus a smooth model mismatch, and the score is a chi^2 in them.

Why: the default model counts a residual's *effective samples* and profiles one common
variance factor out of a Gaussian likelihood. Where it counts them from (the nominal
residual, which carries the sought signal; or the best fit's) is a choice between a
conservative and an optimistic bound (``Criteria.n_eff_from``). Here the errors are
described instead: per measurement, the white-noise sigma ``sigma_w`` (from the data,
:mod:`.noise`, or the manifest) and a smooth mismatch of RMS ``sigma_m`` and correlation
length ``L_m`` measured from the post-fit residual's autocorrelation
(:func:`.noise.two_part_errors`). A smooth change of the model competes with the
mismatch's long-run variance ``V = sigma_w^2 + sigma_m^2 L_m`` per sample, so the
weights are ``1 / sqrt(V)`` (absolute: no common factor) and the score is
``sum_i RSS_i / V_i + k log N`` with ``N`` the residuals' independent samples.

The errors are first measured on the nominal residual (the conservative start: the
signal counts as mismatch), then on the residual of the best-ranked *single* effect
(:func:`error_source`), and the candidates are refitted and re-ranked with them until the
weights settle. A single's residual, not the best finding's: a pair ranked first would
take part of the mismatch into its second member, shrink the measured mismatch, raise the
weights and so favour pairs in the next pass; measured on the best single, the errors do
not depend on which pairs are tried, and a pair must beat what that single leaves.

A sign is claimed only where flipping it costs more than the errors could: the fitted
and the mirrored solutions differ by predictions ``d_i``; the errors change the cost
difference between them by ``2 <e, d>`` with standard deviation ``2 sqrt(D)``,
``D = sum_i |d_i|^2 / V_i`` (the smooth mismatch's projection on a smooth ``d`` is
bounded by its long-run variance), so the observed cost of the flip must exceed
``2 SIGN_Z sqrt(D)`` (:func:`sign_is_claimed`).

Measured (``benchmarks/bench_error_model.py``: the reduced campaign of the slow tests, 19
cases, seed 7; 2 workers on a shared machine):

==========  ===========  ==============  ================  ==============  ======
model       correct top  params in 20 %  OOL unexplained   truth in 2 sig  wall s
==========  ===========  ==============  ================  ==============  ======
n_eff       12/13        12/13           5/6               13/13           196
two_part    13/13        12/13           5/6               12/13           538
==========  ===========  ==============  ================  ==============  ======

``two_part`` explains a one-map temperature case that ``n_eff`` leaves ``unexplained`` and
recovers profile parameters closer (collimator WFE error 0.64 -> 0.38, pupil shift 0.09 ->
0.03), but its error bars are narrower (one truth beyond 2 sigma), it attributes a different
map's out-of-library bump to ``blank_bow`` (the same count), it costs 2.7x the time (every
candidate is refitted with the new weights), and it ranks pairs that take up a smooth part
of the truth's quilt mismatch first (``tests/test_diagnosis.py``: the astigmatism and
registration cases become ``astigmatism+amplitude_scale`` and a registration pair).

On independent truths (quilts 5-30 % from the FEA's, ``benchmarks/results_frozen_campaign.md``)
the balance differs by measurement kind. On maps alone ``two_part`` names the injected effect
less often (7 of 12 against 10 of 12, ``benchmarks/results_error_model_by_kind.md``), so
``"by_kind"`` (:func:`model_for_kinds`) scores with ``two_part`` wherever a line profile is
measured and with ``n_eff`` on maps and PSF images. On line profiles neither model is ahead on
every count: on one draw of 24 independent profile truths ``two_part`` names the injected
effect in 9 of 15 library cases against 11 for ``n_eff`` and reads it within 20 % in 10 against
9 (``benchmarks/results_error_model_same_seed.md``). On the paper's J scenario ``by_kind``
names the pupil shift with the amplitude as its rescaling companion
(``benchmarks/results_pairs.md``). The default stays ``n_eff``: it names more and costs about a
third of the time. With the wider pair search (``Criteria.pair_forward``: the best single also
paired with every other, :func:`.ranking.pairs_to_fit`), ``two_part`` names both
effects of the paper's J scenario (a larger quilt amplitude *and* a 4 mm pupil shift, its
section 5.3) and of 5 in 9 independent truths with two effects, against 3 in 9 for ``n_eff``
(``benchmarks/results_pairs.md``). But that wider search also names single-effect truths as
pairs (a pupil shift as amplitude + pupil shift; with no rescaling added, out-of-library
profiles as amplitude + pupil shift), so it is off by default too.
"""

from __future__ import annotations

import math
from dataclasses import asdict

import numpy as np

from .fitting import FitOutcome, Problem
from .noise import two_part_errors

__all__ = ["ERROR_MODELS", "SIGN_Z", "model_for_kinds", "error_source", "measure_errors", "two_part_problem", "weights_settled", "sign_is_claimed",
           "errors_summary"]

ERROR_MODELS = ("n_eff", "two_part", "by_kind")
#: Measurement kinds on which ``"by_kind"`` scores with the two-part model.
TWO_PART_KINDS = frozenset({"line_profile"})
#: Standard deviations by which a flip's cost must exceed what the errors could do.
SIGN_Z = 2.0


def model_for_kinds(error_model: str, kinds) -> str:
    """The error model a diagnosis of measurements of ``kinds`` is scored with:
    ``error_model`` itself, except ``"by_kind"``, which is ``"two_part"`` when a line
    profile is among the measurements and ``"n_eff"`` otherwise (maps, PSF images).

    Why: measured on independent truths, the two-part model names the injected effect on
    maps alone less often than the effective-sample counts (``benchmarks/results_error_model_by_kind.md``);
    on line profiles the two are close (``benchmarks/results_error_model_same_seed.md``)."""
    if error_model not in ERROR_MODELS:
        raise ValueError(f"error_model={error_model!r} must be one of {ERROR_MODELS}")
    if error_model != "by_kind":
        return error_model
    return "two_part" if TWO_PART_KINDS & set(kinds) else "n_eff"


def _residual(f, fo: FitOutcome) -> np.ndarray:
    return f.residual(fo.parameters, fo.deltas_um.get(f.name, f.delta0_um))


def error_source(findings):
    """The finding whose residual the two-part errors are measured on: the best-ranked
    one with a single library effect (companions allowed), else the best-ranked one.

    Parameters
    ----------
    findings : sequence of Finding
        Ranked best first.

    Returns
    -------
    Finding or None
        ``None`` for no findings.
    """
    return next((f for f in findings if len(f.effects) == 1), findings[0] if findings else None)


def measure_errors(prob: Problem, fo: FitOutcome) -> dict:
    """``{measurement: TwoPartErrors}`` of the residual ``fo`` leaves, white part ``prob.noise``."""
    return {f.name: two_part_errors(_residual(f, fo), f.x, f.y if f.kind != "line_profile" else None,
                                    prob.noise[f.name]) for f in prob.forwards}


def two_part_problem(prob: Problem, errors: dict) -> Problem:
    """``prob`` weighted by the errors' long-run sigma (absolute), counting their
    independent samples."""
    w = {m: 1.0 / math.sqrt(e.long_run_var) for m, e in errors.items()}
    n_eff = {m: float(np.clip(e.n_independent, min(10.0, e.n_samples), e.n_samples)) for m, e in errors.items()}
    return Problem(prob.forwards, w, n_eff, dict(prob.noise), None, absolute=True)


def weights_settled(old: Problem, new: Problem, rtol: float = 0.1) -> bool:
    """True if no measurement's weight changed by more than ``rtol``."""
    return all(abs(new.weights[m] / old.weights[m] - 1.0) <= rtol for m in new.weights)


def sign_is_claimed(prob: Problem, fo: FitOutcome, flip: FitOutcome, pred: dict, pred_flip: dict) -> bool:
    """Whether the flip's extra cost exceeds ``2 SIGN_Z sqrt(D)`` (module docstring);
    ``pred``/``pred_flip``: the two fits' predictions per measurement."""
    w = prob.weights
    D = sum(w[m] ** 2 * float(np.sum((pred_flip[m] - pred[m]) ** 2)) for m in pred)
    extra = flip.weighted_rss(w) - fo.weighted_rss(w)
    return bool(extra > 2.0 * SIGN_Z * math.sqrt(D)) and D > 0


def errors_summary(errors: dict) -> dict:
    """JSON-ready ``{measurement: {sigma_w, sigma_m, corr_samples, long_run_var, n_samples}}``."""
    return {m: asdict(e) for m, e in errors.items()} if errors else {}
