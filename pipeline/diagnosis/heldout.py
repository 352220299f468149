"""Held-out validation: refit an effect on part of the data, measure the shrink on the rest.

Splits (chosen from the data, no tuning on the held-out part):

* one surface map: fit on the centre 82 x 72 mm, test on the edges of the aperture
  (alternate quilt cells if the aperture has no edges);
* one line profile: fit on one side of the line centre, test on the other, both ways;
* several measurements: leave one measurement out in turn (e.g. fit 250 + 100 mas,
  test 25 mas; fit H, test K …).

Only the effect parameters travel from the training to the test part; the nuisances
(piston/tilt, offset shift, flux, background) are refitted on the test data both
before and after, so the shrink is the effect's alone. A fold whose training part
does not pin down the change the effect predicts on the withheld part (prediction
uncertainty >= the predicted change, :func:`_prediction_spread`), or whose training fit
leaves a parameter at a bound of its prior range (the prior, not the training part, set it:
a plating-gradient companion that a map beside the profiles wants, fitted on the profiles
alone, went to both bounds and "predicted" a map change 2x its spread, so a pupil shift
that the six profile folds confirmed was called overfit), is reported but does not count.
Nor does a fold whose withheld measurement none of the finding's own effects change: it
could test only a companion's reading across kinds (a pupil shift does not change a map; its
bow companion, read from the profiles alone, made the map fold shrink -0.30 and the pooled
check fail while the six profile folds shrank +0.17 ... +0.81), and a companion is adopted on
all the data and the finding's evidence measured against it
(``benchmarks/results_heldout_own_effects.md``).
"""

from __future__ import annotations

import math

import numpy as np

from .finding import all_effects
from .fitting import Problem, fit
from .plausibility import at_prior_bound
from .ranking import parameters_of

__all__ = ["folds", "heldout_check", "untestable_reason"]


def folds(prob: Problem) -> list[tuple[dict, dict, str]]:
    """(train masks, test masks, label) for each fold of the data in ``prob``."""
    fws = prob.forwards
    if len(fws) == 1:
        f = fws[0]
        if f.kind == "surface":
            centre = (np.abs(f.x) <= 41.0) & (np.abs(f.y) <= 36.0)
            if (~centre).sum() < 50 or centre.sum() < 50:
                centre = (np.round(f.x / 21.0) + np.round(f.y / 18.0)) % 2 == 0
                return [({f.name: centre}, {f.name: ~centre}, "alternate cells")]
            return [({f.name: centre}, {f.name: ~centre}, "centre 82x72 -> edges")]
        w = np.clip(f.data, 0, None)
        u0 = float(np.sum(w * f.x) / np.sum(w))
        left = f.x < u0
        return [({f.name: left}, {f.name: ~left}, "left -> right"), ({f.name: ~left}, {f.name: left}, "right -> left")]
    out = []
    for f in fws:
        none = np.zeros(f.n, bool)
        out.append(({f.name: none}, {g.name: (np.ones(g.n, bool) if g is f else np.zeros(g.n, bool)) for g in fws},
                    f"others -> {f.name}"))
    return out


def _prediction_spread(prob: Problem, params, tr, test: dict) -> tuple[float, float]:
    """(RMS of the change the training fit predicts on the withheld samples, RMS of its
    one-sigma uncertainty), both before nuisances and summed over measurements.

    A fold only tests the effect if the training part pins down what it predicts for
    the withheld part: with three collimator-WFE parameters fitted on two of three
    profiles, the third profile's predicted change was uncertain by more than its size
    and the 'held-out shrink' (measured: -1.5) judged the noise of the extrapolation,
    not the effect. Uncertainty: parameters moved by their 1-sigma errors one at a time,
    added in quadrature (correlations ignored), kept inside the prior range; a parameter
    with an error as large as its prior range makes the fold untestable."""
    p = dict(tr.parameters)
    null = {}
    sig2 = spread2 = 0.0
    for f in prob.forwards:
        m = test.get(f.name)
        if m is None or not m.any():
            continue
        d = tr.deltas_um.get(f.name, f.delta0_um)

        def pred(q):
            return f.predict(q, d)[m] if f.n_shift else f.predict(q)[m]

        base = pred(p)
        sig2 += float(np.sum((base - pred(null)) ** 2))
        for q in params:
            e = tr.errors.get(q.name, math.inf)
            if not e < q.width:  # not constrained within its prior range
                return math.sqrt(sig2), math.inf
            v = p[q.name] + e if p[q.name] + e <= q.hi else p[q.name] - e  # stay inside the prior
            spread2 += float(np.sum((pred({**p, q.name: float(np.clip(v, q.lo, q.hi))}) - base) ** 2))
    return math.sqrt(sig2), math.sqrt(spread2)


def untestable_reason(signal: float, spread: float) -> str:
    """Why a fold does not test the effect, in words (the fold's numbers where they mean something)."""
    if not signal > 0:
        return "the training part's fit predicts no change on the withheld part"
    if not math.isfinite(spread):
        return "a parameter is left free within its prior by the training part"
    return f"the training part predicts the withheld change {signal:.3g} only to ±{spread:.3g}"


def _own_effects_act(prob: Problem, finding, test: dict) -> bool:
    """Whether the finding's own effects (not its companions) have parameters for a
    measurement of the withheld part ``test`` (masks by measurement name)."""
    withheld = [f for f in prob.forwards if np.any(test.get(f.name, False))]
    return bool(parameters_of(tuple(finding.effects), withheld))


def heldout_check(prob: Problem, finding, criteria) -> tuple[float | None, str]:
    """Held-out shrink fraction of ``finding`` (None if no fold constrains it) and a note."""
    params = parameters_of(all_effects(finding), prob.forwards)
    before = after = 0.0
    notes, used = [], 0
    bounds = {q.name: (q.lo, q.hi) for q in params}
    for train, test, label in folds(prob):
        if not _own_effects_act(prob, finding, test):  # only a companion could be carried there
            notes.append(f"{label}: untestable (the finding's own effects do not change the withheld part)")
            continue
        tr = fit(prob, params, masks=train)
        stopped = at_prior_bound(tr.parameters, bounds)
        if stopped:  # the prior, not the training part, set these: what they predict is the prior's
            notes.append(f"{label}: untestable (the training part leaves {', '.join(stopped)} at a bound of "
                         "its prior range)")
            continue
        signal, spread = _prediction_spread(prob, params, tr, test)
        if not spread < signal:
            notes.append(f"{label}: untestable ({untestable_reason(signal, spread)})")
            continue
        b = fit(prob, (), masks=test)
        a = fit(prob, (), masks=test, fixed=tr.parameters)
        wb = b.weighted_rss(prob.weights)
        wa = a.weighted_rss(prob.weights)
        before, after, used = before + wb, after + wa, used + 1
        notes.append(f"{label}: shrink {1 - math.sqrt(wa / wb) if wb > 0 else 0.0:+.2f}")
    if not used or before <= 0:
        return None, "; ".join(notes)
    return float(1 - math.sqrt(after / before)), "; ".join(notes)
