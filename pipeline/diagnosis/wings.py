"""Is a line-profile gap the grating's or the optics', or light the detector side adds? A
diagnostic alternative to every finding that explains line profiles.

Stray light and detector artefacts are not in the library, and they are not made
orthogonal to it: a scattered-light halo or a charge tail puts flux into a line's wings,
and a pupil shift, a rescaled quilt (whose satellites sit in the wings) or the quilt's
shape move flux there too. Measured on independent truths (``benchmarks/results_frozen_campaign.md``):
a Lorentzian halo of 3 % of the flux and a one-sided detector tail were each named
``temperature + pupil_shift`` (delta BIC -91 and -114) and called explained.

What tells them apart is where the light goes: the wing kernels of
:mod:`.effects.instrument_wings` are convolutions in detector µm, the same for every pixel
scale and wavelength, and they move no light between the two peaks of a quilted line,
while a grating or pupil effect acts through the pupil, differently per pixel scale.
The check asks whether the finding is still needed once the wings are free.

Decision rule (fixed before any campaign run)
---------------------------------------------
Only a top finding that would explain the gap, on data holding a line profile, is
checked. Two fits, both with every profile's nuisances:

* the **alternative**: the wings (:data:`WINGS_PARAMETERS`, grid-started over their
  ``Parameter.starts``) beside the background effects the data can see
  (``Effect.background``: ``quilt_shape``, present on every real grating) that are not the
  finding's own effect, and no other effect (a ``quilt_shape`` finding is checked against
  the wings alone);
* the **joint** fit: the finding's effects and companions, the background effects and the
  wings (the alternative's parameters and the finding's), started from the finding's
  values and the alternative's wings.

If the finding's effects improve on the alternative by less than
``Criteria.min_delta_bic`` (the BIC margin any finding must clear against the nominal to be
significant), the data cannot say the gap is the finding's rather than the detector
side's: the finding lists :data:`WINGS_LABEL` in ``degenerate_with``, it does not explain
the gap, and the verdict is ``unexplained`` with the reason in the report. Otherwise
nothing changes (the joint fit's wings are reported in the note). The joint fit is skipped
where the alternative's BIC exceeds the finding's by ``min_delta_bic`` plus the BIC penalty
of the joint fit's extra parameters: the joint fit can always hold the wings at zero and
the background at its null, so it would clear the margin anyway. Cost: one fit (two where
it is close) with four wing parameters, only where a profile finding explains.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from .criteria import Criteria
from .effects import applicable_effects
from .effects.instrument_wings import INSTRUMENT_WINGS
from .finding import Finding, all_effects
from .fitting import FitOutcome, Problem, fit
from .ranking import parameters_of

__all__ = ["WINGS_LABEL", "WINGS_PARAMETERS", "WingsCheck", "checks", "wings_check", "with_check"]

#: The wing kernels' parameters (:mod:`.effects.instrument_wings`).
WINGS_PARAMETERS = INSTRUMENT_WINGS.parameters

#: What a finding is degenerate with when the wings take its place.
WINGS_LABEL = "light added on the detector side (stray-light halo, detector tail)"

#: Grid starts of the wing parameters (a halo's width has no leverage at zero fraction; a
#: tail's side is a kink at zero fraction, so both sides are started).
_STARTS = {"halo_fraction": (0.03,), "halo_hwhm_um": (30.0,), "tail_fraction": (-0.03, 0.03),
           "tail_decay_um": (20.0,)}


@dataclass(frozen=True)
class WingsCheck:
    """Outcome of :func:`wings_check`: the BICs of the alternative and the joint fit (where
    the joint fit is skipped, the bound on it), the wings of each (the joint's empty where
    skipped), whether the finding is needed beside the wings, and the report's sentence."""

    bic_alternative: float
    bic_joint: float
    wings_alternative: dict
    wings_joint: dict
    ambiguous: bool
    note: str


def checks(prob: Problem, finding: Finding | None) -> bool:
    """Whether ``finding`` is one the check applies to: the data hold a line profile."""
    return finding is not None and any(f.kind == "line_profile" for f in prob.forwards)


def _wings(fo: FitOutcome) -> dict:
    return {q.name: float(fo.parameters[q.name]) for q in WINGS_PARAMETERS if q.name in fo.parameters}


def _text(w: dict) -> str:
    return (f"halo {w.get('halo_fraction', 0.0):.3f} of the flux, HWHM {w.get('halo_hwhm_um', 0.0):.0f} µm; "
            f"tail {w.get('tail_fraction', 0.0):+.3f}, {w.get('tail_decay_um', 0.0):.0f} µm")


def wings_check(prob: Problem, finding: Finding, fo: FitOutcome, c: Criteria) -> WingsCheck:
    """Fit the wings beside the background effects alone and beside ``finding`` (fit ``fo``)
    and compare the BICs (module docstring's decision rule)."""
    if not checks(prob, finding):
        raise ValueError(f"wings_check: finding {finding.effect!r} is not on data holding a line profile")
    background = tuple(e.name for e in applicable_effects({f.kind for f in prob.forwards}) if e.background)
    wings = tuple(replace(q, starts=_STARTS[q.name]) for q in WINGS_PARAMETERS)
    base = parameters_of(tuple(n for n in background if n not in finding.effects), prob.forwards)
    alt = fit(prob, base + wings, start={q.name: q.null for q in base} | {q.name: q.null for q in wings},
              regrid=tuple(q.name for q in wings))
    own = parameters_of(tuple(dict.fromkeys(all_effects(finding) + background)), prob.forwards)
    b_a, b_f = alt.bic(prob.weights), fo.bic(prob.weights)
    # the joint fit can hold the wings at zero and the background at its null, where it is
    # the finding with more parameters: its BIC is at most the finding's plus their penalty
    extra = len(own) + len(wings) - len(parameters_of(all_effects(finding), prob.forwards))
    bound = b_f + extra * math.log(max(sum(fo.counts.values()), 2.0))
    if b_a - bound >= c.min_delta_bic:  # needed beside the wings whatever the joint fit gives
        return WingsCheck(float(b_a), float(bound), _wings(alt), {}, False,
                          f"{finding.effect}: still needed beside light added on the detector side (the wings alone, "
                          f"{_text(_wings(alt))}, fit worse than the finding by {b_a - b_f:.1f} in BIC)")
    start = {q.name: fo.parameters[q.name] for q in own if q.name in fo.parameters}
    start.update({q.name: q.null for q in own if q.name not in start})
    start.update(_wings(alt))
    joint = fit(prob, own + wings, start=start)
    b_j = joint.bic(prob.weights)
    ambiguous = bool(b_a - b_j < c.min_delta_bic)
    if ambiguous:
        note = (f"{finding.effect} is not the explanation: light added on the detector side (for instance "
                f"{_text(_wings(alt))}; a halo's fraction and width trade off) fits the profiles with the background "
                f"effects alone; beside it {finding.effect} lowers the BIC by "
                f"{b_a - b_j:.1f} (needs at least {c.min_delta_bic:g}), so the data cannot say the gap is the "
                f"grating's or the optics'")
    else:
        note = (f"{finding.effect}: still needed beside light added on the detector side (BIC {b_a - b_j:.1f} better "
                f"than the wings alone; wings beside it: {_text(_wings(joint))})")
    return WingsCheck(float(b_a), float(b_j), _wings(alt), _wings(joint), ambiguous, note)


def with_check(finding: Finding, check: WingsCheck) -> Finding:
    """``finding`` with :data:`WINGS_LABEL` in ``degenerate_with`` if the check is ambiguous."""
    if not check.ambiguous or WINGS_LABEL in finding.degenerate_with:
        return finding
    return replace(finding, degenerate_with=finding.degenerate_with + (WINGS_LABEL,))
