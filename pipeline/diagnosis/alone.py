"""What each kind of measurement, fitted alone, says about a finding's parameters.

A joint fit weighs each measurement (:func:`.fitting.nominal_weights`), so where two kinds
see one parameter (a map and line profiles of one blank share its deformation scale) the
joint value follows the kind that weighs more, and the other can be left with a residual
beyond its noise although, fitted alone, it reads nearly the same value. Measured on an
outside lab's map and profiles of a quilt 1.15x the nominal: the joint fit gave
``scale_J`` 1.1445 ± 0.0046, following the profiles (the map's weight 0.30), and left the
map 1.1x its noise; the map alone read 1.152. A user sees a "remaining gap" in the map and
cannot tell a missing effect from two readings of one parameter. This module refits the
finding on each kind alone (each measurement alone when all are of one kind) and states
the values, their errors and what gap each part still holds after its own fit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .criteria import Criteria
from .finding import Finding, all_effects
from .fitting import FitOutcome, Problem, fit
from .gap import gaps
from .ranking import parameters_of

__all__ = ["PartFit", "parts", "fits_alone", "KIND_WORDS"]

#: How a report names a group of measurements of one kind.
KIND_WORDS = {"surface": "surface maps", "line_profile": "line profiles", "psf_image": "PSF images"}


@dataclass(frozen=True)
class PartFit:
    """A finding's parameters fitted to one part of the data alone.

    ``parameters`` and ``uncertainties`` in the parameters' own units (1 sigma; ``inf``:
    not constrained by this part); ``tension`` is ``(alone - joint) / uncertainty`` of this
    part, per parameter; ``gap`` the part's measurements still beyond noise after its own
    fit (as :func:`.gap.gaps`: ``measurement``, ``rms_ratio``, ``z``)."""

    label: str
    measurements: tuple
    parameters: dict
    uncertainties: dict
    tension: dict
    gap: tuple

    def to_dict(self) -> dict:
        return {"label": self.label, "measurements": list(self.measurements), "parameters": dict(self.parameters),
                "uncertainties": dict(self.uncertainties), "tension": dict(self.tension), "gap": list(self.gap)}


def parts(prob: Problem) -> list[tuple[str, list]]:
    """The parts the data are split into: one per measurement kind where there are several
    kinds, else one per measurement (an empty list for a single measurement)."""
    kinds = list(dict.fromkeys(f.kind for f in prob.forwards))
    if len(kinds) > 1:
        return [(KIND_WORDS.get(k, k), [f for f in prob.forwards if f.kind == k]) for k in kinds]
    if len(prob.forwards) > 1:
        return [(f.name, [f]) for f in prob.forwards]
    return []


def fits_alone(prob: Problem, finding: Finding, joint: FitOutcome, criteria: Criteria) -> tuple[PartFit, ...]:
    """Refit ``finding``'s effects on each part of the data (:func:`parts`) alone, started at
    the joint fit ``joint`` (its parameters and positions), so each part's value is the one
    nearest the joint value that the part prefers. Parts that none of the finding's
    parameters act on are skipped.

    Returns
    -------
    tuple of PartFit
    """
    out = []
    for label, fws in parts(prob):
        sub = Problem(list(fws), prob.weights, prob.n_eff, prob.noise,
                      None if prob.n_count is None else {f.name: prob.n_count[f.name] for f in fws}, prob.absolute)
        params = parameters_of(all_effects(finding), sub.forwards)
        if not params:
            continue
        fo = fit(sub, params, start={q.name: joint.parameters[q.name] for q in params if q.name in joint.parameters},
                 start_deltas_um=joint.deltas_um)
        tension = {}
        for q in params:
            e = fo.errors.get(q.name, math.inf)
            v0 = joint.parameters.get(q.name)
            tension[q.name] = ((fo.parameters[q.name] - v0) / e if v0 is not None and 0 < e < math.inf
                               else float("nan"))
        out.append(PartFit(label, tuple(f.name for f in fws), fo.parameters, fo.errors, tension,
                           tuple(gaps(sub, fo, criteria))))
    return tuple(out)
