"""Is a line-profile gap the grating's or the optics', or the detector side's? A diagnostic
alternative to every finding that explains line profiles.

Stray light and detector artefacts are not in the library, and they are not made
orthogonal to it: a scattered-light halo or a charge tail puts flux into a line's wings,
and a pupil shift, a rescaled quilt (whose satellites sit in the wings) or the quilt's
shape move flux there too. Measured on independent truths (``benchmarks/results_frozen_campaign.md``):
a Lorentzian halo of 3 % of the flux and a one-sided detector tail were each named
``temperature + pupil_shift`` (delta BIC -91 and -114) and called explained; halos of 3 and
5 % on quilts whose fundamental was also 9 % stronger were named ``amplitude_scale`` alone.

What tells them apart is where the light goes: the wing kernels of
:mod:`.effects.instrument_wings` are convolutions in detector µm, the same for every pixel
scale and wavelength, and a non-linear response depends on the signal alone; none moves
light between the two peaks of a quilted line through the pupil, while a grating or pupil
effect acts through the pupil, differently per pixel scale.

Decision rule
-------------
Only a top finding that would explain the gap, on data holding a line profile, is
checked. Three fits, all with every profile's nuisances:

* the **alternative**: the detector terms (:data:`WINGS_PARAMETERS`, grid-started over
  their ``Parameter.starts``) beside the background effects the data can see
  (``Effect.background``: ``quilt_shape``, present on every real grating) that are not the
  finding's own effect, the rescaling the finding adopted as a companion (the quilt's
  amplitude, not the finding's), and no other effect (a ``quilt_shape`` finding is checked
  against the detector terms alone);
* the **reference**: the finding's effects and companions with the background effects (the
  finding's own fit where it already holds them);
* the **joint** fit: the reference's parameters and the detector terms, started from the
  optimum it nests (the reference's or the finding's, whichever has the lower objective) with
  the detector terms at their nulls or at the alternative's values, whichever fits better there,
  with a budget of function evaluations (:data:`_JOINT_NFEV_PER_PARAMETER`).

If the finding's effects improve on the alternative by less than
``Criteria.min_delta_bic`` (the BIC margin any finding must clear against the nominal to be
significant), the data cannot say the gap is the finding's rather than the detector
side's: the finding lists :data:`WINGS_LABEL` in ``degenerate_with``. If the finding is
needed but the detector terms lower the reference's BIC by ``min_delta_bic`` or more, the
data hold the finding *and* something the library does not: the finding lists
:data:`WINGS_LABEL` in ``needs_outside``. Either way it does not explain the gap and the
verdict is ``unexplained`` with the reason in the report. Otherwise nothing changes (the
joint fit's detector terms are reported in the note). The joint fit's BIC is held at the
reference's plus the penalty of its extra parameters where a local fit ends above that (it
could hold the detector terms at zero). Cost: two or three fits with five detector
parameters, only where a profile finding explains.

Measured on the profile cases of a development draw of independent truths (seed 20261134,
15 library and 9 out-of-library cases): beside the 13 library findings that explained, the
detector terms raised the BIC by 13.0-26.6 (never needed); of the two halos (3.4, 5.2 % of the
flux) and two non-linearities (4.6, 5.6 %) on quilts with a 3-9 % stronger fundamental, all named
``amplitude_scale``, one halo and one non-linearity are no longer explained (the detector terms
alone fit within 10 of the finding); beside the others the detector terms lower the BIC by 9.1
and raise it by 13.5.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace

from .criteria import Criteria
from .effects import applicable_effects
from .effects.instrument_wings import INSTRUMENT_WINGS
from .finding import Finding, all_effects
from .fitting import FitOutcome, Problem, fit, objective
from .ranking import parameters_of, rescaling_companions

__all__ = ["WINGS_LABEL", "WINGS_PARAMETERS", "WingsCheck", "checks", "wings_check", "with_check"]

#: The detector terms' parameters (:mod:`.effects.instrument_wings`).
WINGS_PARAMETERS = INSTRUMENT_WINGS.parameters

#: Budget of the joint fit's function evaluations per free parameter. Where the detector terms
#: are not needed their shapes (a halo's width, a tail's length at a small fraction) are flat
#: directions a trust region started away from the nested optimum wanders along: measured on
#: profiles + map + PSF image of a bowed blank, started at the alternative's terms, 800
#: evaluations (165 s) for a BIC that the reference's plus the penalty bounds anyway. Started
#: at the nested optimum it stops within a few (7 on that case,
#: ``benchmarks/results_wings_joint_start.md``); the budget only bounds the worst case.
_JOINT_NFEV_PER_PARAMETER = 10

#: What a finding is degenerate with when the wings take its place.
WINGS_LABEL = "the detector side (stray-light halo, detector tail, blur, non-linear response)"

#: Grid starts of the wing parameters (a halo's width has no leverage at zero fraction; a
#: tail's side is a kink at zero fraction, so both sides are started).
_STARTS = {"halo_fraction": (0.03,), "halo_hwhm_um": (30.0,), "tail_fraction": (-0.03, 0.03),
           "tail_decay_um": (20.0,), "nonlinearity": (0.0, 0.05), "blur_um": (0.0, 6.0)}


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
    #: How much the wings beside the finding lower the BIC of the finding with the
    #: background effects (> 0: the data prefer the detector terms beside it).
    wings_gain_bic: float = 0.0
    #: The wings lower it by ``Criteria.min_delta_bic`` or more: the finding is needed and so
    #: is light the library does not hold.
    needed_beside: bool = False

    def summary(self) -> dict:
        """The outcome as plain numbers for ``diagnosis.json`` (the note is in the ranking note)."""
        return {k: v for k, v in asdict(self).items() if k != "note"}


def checks(prob: Problem, finding: Finding | None) -> bool:
    """Whether ``finding`` is one the check applies to: the data hold a line profile."""
    return finding is not None and any(f.kind == "line_profile" for f in prob.forwards)


def _wings(fo: FitOutcome) -> dict:
    return {q.name: float(fo.parameters[q.name]) for q in WINGS_PARAMETERS if q.name in fo.parameters}


def _text(w: dict) -> str:
    t = w.get('tail_fraction', 0.0)
    side = "towards +offset" if t > 0 else "towards −offset" if t < 0 else ""
    return (f"halo {w.get('halo_fraction', 0.0):.3f} of the flux, HWHM {w.get('halo_hwhm_um', 0.0):.0f} µm; "
            f"tail {abs(t):.3f} of the flux{' ' + side if side else ''}, decay {w.get('tail_decay_um', 0.0):.0f} µm; "
            f"blur {w.get('blur_um', 0.0):.1f} µm; non-linearity {w.get('nonlinearity', 0.0):.3f} at the peak")


def wings_check(prob: Problem, finding: Finding, fo: FitOutcome, c: Criteria) -> WingsCheck:
    """Fit the wings beside the background effects alone and beside ``finding`` (fit ``fo``)
    and compare the BICs (module docstring's decision rule)."""
    if not checks(prob, finding):
        raise ValueError(f"wings_check: finding {finding.effect!r} is not on data holding a line profile")
    background = tuple(e.name for e in applicable_effects({f.kind for f in prob.forwards}) if e.background)
    wings = tuple(replace(q, starts=_STARTS[q.name]) for q in WINGS_PARAMETERS)
    # a rescaling the finding adopted as a companion is the quilt's, not the finding's: the
    # detector side gets it too, so both are judged beside the same rescaled, reshaped quilt
    rescaled = rescaling_companions(finding)
    base = parameters_of(tuple(n for n in background + rescaled if n not in finding.effects), prob.forwards)
    kept = {q.name for q in parameters_of(rescaled, prob.forwards)} & set(fo.parameters)
    alt_start = {q.name: fo.parameters[q.name] if q.name in kept else q.null for q in base}
    alt = fit(prob, base + wings, start=alt_start | {q.name: q.null for q in wings},
              regrid=tuple(q.name for q in wings))
    own = parameters_of(tuple(dict.fromkeys(all_effects(finding) + background)), prob.forwards)
    b_a, b_f = alt.bic(prob.weights), fo.bic(prob.weights)
    start = {q.name: fo.parameters[q.name] for q in own if q.name in fo.parameters}
    start.update({q.name: q.null for q in own if q.name not in start})
    # the finding beside the background effects, without wings: what the wings' own gain is
    # measured against (the finding may not have adopted the background as a companion)
    ref = fo if len(own) == len(fo.parameters) else fit(prob, own, start=start, start_deltas_um=fo.deltas_um)
    b_ref = ref.bic(prob.weights)
    b_r = min(b_ref, b_f)
    # The joint fit nests the reference and the finding: it starts at the lower-objective of
    # their optima (parameters and position nuisances), with the detector terms at their nulls
    # or at the alternative's, whichever fits better there. The fit only descends, so it never
    # ends above the fit it nests (measured before: started at the alternative's terms, a
    # 15 % detector tail at its bound, on a slit width with a bow and a PSF image, it spent
    # its whole budget of 160 evaluations, 78 s, and ended 1.2 % above the reference).
    nested = min((ref, fo), key=lambda o: o.weighted_rss(prob.weights))
    start.update({q.name: nested.parameters[q.name] for q in own if q.name in nested.parameters})
    starts = [{**start, **{q.name: q.null for q in wings}}, {**start, **_wings(alt)}]
    start = min(starts, key=lambda s: objective(prob, s, nested.deltas_um))
    joint = fit(prob, own + wings, start=start, start_deltas_um=nested.deltas_um,
                max_nfev=_JOINT_NFEV_PER_PARAMETER * (len(own) + len(wings) + 1))
    # the joint fit can hold the detector terms at zero and the background at its null, where
    # it is the finding with more parameters: its BIC is at most the finding's plus their penalty
    extra = len(own) + len(wings) - len(fo.parameters)
    b_j = min(joint.bic(prob.weights), b_f + extra * math.log(max(sum(fo.counts.values()), 2.0)))
    ambiguous = bool(b_a - b_j < c.min_delta_bic)
    gain = b_r - b_j
    beside = bool(not ambiguous and gain >= c.min_delta_bic)
    if ambiguous:
        note = (f"{finding.effect} is not the explanation: the detector side (for instance "
                f"{_text(_wings(alt))}; a halo's fraction and width trade off) fits the profiles with the background "
                f"effects alone; beside it {finding.effect} lowers the BIC by "
                f"{b_a - b_j:.1f} (needs at least {c.min_delta_bic:g}), so the data cannot say the gap is the "
                f"grating's or the optics'")
    elif beside:
        note = (f"{finding.effect} explains part of the gap, not all of it: beside it the detector side "
                f"({_text(_wings(joint))}) lowers the BIC by a further {gain:.1f} (a finding needs "
                f"{c.min_delta_bic:g}), and the library holds nothing of the kind")
    else:
        change = f"lower the BIC by {gain:.1f}" if gain > 0 else f"raise the BIC by {-gain:.1f}"
        note = (f"{finding.effect}: still needed beside the detector side (BIC {b_a - b_j:.1f} better than the "
                f"detector terms alone); beside it the detector terms ({_text(_wings(joint))}) {change}, and would "
                f"need to lower it by {c.min_delta_bic:g}")
    return WingsCheck(float(b_a), float(b_j), _wings(alt), _wings(joint), ambiguous, note, float(gain), beside)


def with_check(finding: Finding, check: WingsCheck) -> Finding:
    """``finding`` with :data:`WINGS_LABEL` in ``degenerate_with`` if the check is ambiguous,
    in ``needs_outside`` if the wings are needed beside it."""
    if check.ambiguous and WINGS_LABEL not in finding.degenerate_with:
        return replace(finding, degenerate_with=finding.degenerate_with + (WINGS_LABEL,))
    if check.needed_beside and WINGS_LABEL not in finding.needs_outside:
        return replace(finding, needs_outside=finding.needs_outside + (WINGS_LABEL,))
    return finding
