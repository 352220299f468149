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
leaves every effect parameter unconstrained is reported but does not count.
"""

from __future__ import annotations

import math

import numpy as np

from .effects import LIBRARY, effect_parameters
from .fitting import Problem, fit

__all__ = ["folds", "heldout_check"]


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


def heldout_check(prob: Problem, finding, criteria) -> tuple[float | None, str]:
    """Held-out shrink fraction of ``finding`` (None if no fold constrains it) and a note."""
    params = tuple(q for n in finding.effects
                   for q in effect_parameters(LIBRARY[n], tuple(dict.fromkeys(
                       f.blank for f in prob.forwards if f.kind in LIBRARY[n].kinds))))
    before = after = 0.0
    notes, used = [], 0
    for train, test, label in folds(prob):
        tr = fit(prob, params, masks=train)
        constrained = [q.name for q in params if math.isfinite(tr.errors.get(q.name, math.inf))
                       and tr.errors[q.name] < q.width]
        if not constrained:
            notes.append(f"{label}: untestable (training part does not constrain {finding.effect})")
            continue
        b = fit(prob, (), masks=test)
        a = fit(prob, (), masks=test, fixed=tr.parameters)
        wb = sum(prob.weights[m] ** 2 * b.rss[m] for m in b.rss)
        wa = sum(prob.weights[m] ** 2 * a.rss[m] for m in a.rss)
        before, after, used = before + wb, after + wa, used + 1
        notes.append(f"{label}: shrink {1 - math.sqrt(wa / wb) if wb > 0 else 0.0:+.2f}")
    if not used or before <= 0:
        return None, "; ".join(notes)
    return float(1 - math.sqrt(after / before)), "; ".join(notes)
