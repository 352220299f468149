"""Is a pupil aberration the collimator's? A diagnostic alternative to ``collimator_wfe``.

``collimator_wfe`` fits three pupil Zernike terms of the collimator (coma Z(3,1), defocus
Z(2,0), oblique astigmatism Z(2,-2)). A real spectrograph's camera (or any other optic in
the beam) adds aberrations of other orders to the same pupil wavefront, and the library
has no effect for them; the three collimator terms then take up what they can of them and
the finding would blame the collimator. This module refits the finding with the
collimator's terms held at zero and a basis of other pupil orders free instead (not a
library effect: it is never ranked or reported as an explanation) and asks whether the
data can tell the two apart.

Which terms leave a trace in a line profile
-------------------------------------------
Pupil coordinates ``xi`` (dispersion) and ``eta`` (along the slit), normalised to the
55 mm pupil radius, and ``rho``, ``theta``. The slit is long and incoherently illuminated along ``eta``, so the
detected profile is the intensity integrated along the slit, which by Parseval along
``eta`` is the sum over pupil rows ``eta`` of ``|FT_xi(P(xi, eta))|^2``. A wavefront term
that depends on ``eta`` alone is a constant phase on each row: it leaves **no trace**
in a line profile and cannot be tested from profiles. Two terms whose difference depends
on ``eta`` alone give the same profiles whatever else is in the pupil:

* Z(2,2) ``= sqrt(6)(xi^2 - eta^2)`` and defocus Z(2,0): ``Z(2,0) - sqrt(2) Z(2,2) =
  sqrt(3)(4 eta^2 - 1)``. 0-degree astigmatism is *exactly* the collimator's defocus on
  profiles, so it is not in the basis (a defocus-only collimator finding can never be told
  from a 0-degree astigmatism by profiles; only a focal-plane image could).
* Z(3,-1) and Z(3,-3): their difference ``sqrt(8)(4 eta^3 - 2 eta)`` has no trace; one of
  them (Z(3,-3)) stands for both.
* A term ``xi g(eta)`` shifts row ``eta`` by ``g(eta)``; a term ``xi^2 h(eta)`` odd in
  ``eta`` defocuses the rows ``+eta`` and ``-eta`` oppositely and broadens the profile only
  to second order. Both fade with the illuminated pupil height (relative NA 0.1 at
  25 mas): the 250 mas profiles carry most of the information on them.
* Z(3,1) and 3 Z(3,3) differ on a row by ``sqrt(8)(12 xi eta^2 - 2 xi)``: a tilt (the
  profile's offset, a nuisance) plus a row-dependent shift that needs a tall illuminated
  pupil. On 25 mas profiles alone coma and trefoil are nearly the same thing.

The basis (:data:`OTHER_ORDER_PARAMETERS`) is the lowest orders a well-corrected camera
leaves, other than the collimator's, that leave a trace and are not exactly a collimator
term: primary spherical Z(4,0), trefoil Z(3,3) and Z(3,-3), secondary coma Z(5,1). Prior
±0.4 µm RMS each, the ``collimator_wfe`` prior (the spectrograph's own WFE is 0.31 µm RMS).

Decision rule (fixed before any campaign run)
---------------------------------------------
Only a top finding that would explain the gap and holds ``collimator_wfe`` (alone, in a
pair, or as a companion) is checked. Its alternative is the same fit with
``collimator_wfe``'s parameters held at zero (the instrument's default collimator stays)
and the four other-order terms free, the finding's other effects free too, started from
the finding's values. If the alternative's BIC is no worse than the finding's by more than
``Criteria.degenerate_bic`` (the engine's own "the data cannot tell them apart" margin;
the alternative pays for its extra parameter in the BIC), the data cannot say the
aberration is the collimator's: the finding lists :data:`OTHER_ORDERS_LABEL` in
``degenerate_with``, it does not explain the gap, and the verdict is ``unexplained`` with
the reason in the report. Otherwise nothing changes. The alternative is a single local fit
(no grid search): a missed better minimum only leaves the finding unchanged.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace

from .criteria import Criteria
from .effects.pupil_other_orders import PUPIL_OTHER_ORDERS
from .finding import Finding, all_effects
from .fitting import FitOutcome, Problem, fit
from .ranking import parameters_of

__all__ = ["OTHER_ORDER_PARAMETERS", "OTHER_ORDERS_LABEL", "PupilOrdersCheck", "checks", "other_orders_check",
           "with_check"]

#: The diagnostic basis of pupil terms of other orders (module docstring), µm RMS over the
#: 110 mm pupil: the parameters of the alternative's effect unit, which declares their
#: Zernike terms (:mod:`.effects.pupil_other_orders`).
OTHER_ORDER_PARAMETERS = PUPIL_OTHER_ORDERS.parameters

#: What a finding is degenerate with when the other orders fit as well.
OTHER_ORDERS_LABEL = ("pupil aberration of other orders (spherical Z(4,0), trefoil Z(3,±3), "
                      "secondary coma Z(5,1))")

_COLLIMATOR = "collimator_wfe"


@dataclass(frozen=True)
class PupilOrdersCheck:
    """Outcome of :func:`other_orders_check`: the two BICs, the alternative's fitted
    parameters, whether the data cannot tell them apart, and the sentence for the report."""

    bic_finding: float
    bic_other_orders: float
    parameters: dict
    ambiguous: bool
    note: str
    #: The alternative's score minus the finding's, were both charged the finding's parameter
    #: count (the fits' likelihoods alone; > 0: the alternative fits worse). The BIC difference
    #: also charges the alternative its one parameter more, one log N_eff.
    score_equal_count: float = 0.0

    def summary(self) -> dict:
        """The outcome as plain numbers for ``diagnosis.json`` (the note is in the ranking note)."""
        return {k: v for k, v in asdict(self).items() if k != "note"}


def checks(finding: Finding | None) -> bool:
    """Whether ``finding`` is one the check applies to: it holds ``collimator_wfe``."""
    return finding is not None and _COLLIMATOR in all_effects(finding)


def other_orders_check(prob: Problem, finding: Finding, fo: FitOutcome, c: Criteria) -> PupilOrdersCheck:
    """Refit ``finding`` (fit ``fo``) with ``collimator_wfe`` replaced by the other-order
    pupil basis and compare the BICs (module docstring's decision rule)."""
    if not checks(finding):
        raise ValueError(f"other_orders_check: finding {finding.effect!r} does not hold {_COLLIMATOR!r}")
    others = tuple(e for e in all_effects(finding) if e != _COLLIMATOR)
    params = parameters_of(others, prob.forwards) + OTHER_ORDER_PARAMETERS
    start = {q.name: fo.parameters[q.name] for q in params if q.name in fo.parameters}
    start.update({q.name: q.null for q in OTHER_ORDER_PARAMETERS})
    alt = fit(prob, params, start=start)
    b_f, b_a = fo.bic(prob.weights), alt.bic(prob.weights)
    equal = fo.score_change(alt.weighted_rss(prob.weights), prob.weights)
    ambiguous = bool(b_a <= b_f + c.degenerate_bic)
    terms = ", ".join(f"{q.name} {alt.parameters[q.name]:+.3f}" for q in OTHER_ORDER_PARAMETERS)
    if ambiguous:
        note = (f"{finding.effect} is not the explanation: a pupil aberration of other orders than the collimator's "
                f"({terms} µm RMS; collimator terms held at zero) fits the data as well (BIC {b_a - b_f:+.1f} against "
                f"the finding, margin {c.degenerate_bic:g}), so the data cannot say the aberration is the collimator's")
    else:
        note = (f"{finding.effect}: a pupil aberration of other orders fits worse (BIC {b_a - b_f:+.1f}; {terms} µm)")
    return PupilOrdersCheck(float(b_f), float(b_a), dict(alt.parameters), ambiguous, note, float(equal))


def with_check(finding: Finding, check: PupilOrdersCheck) -> Finding:
    """``finding`` with :data:`OTHER_ORDERS_LABEL` in ``degenerate_with`` if the check is ambiguous."""
    if not check.ambiguous or OTHER_ORDERS_LABEL in finding.degenerate_with:
        return finding
    return replace(finding, degenerate_with=finding.degenerate_with + (OTHER_ORDERS_LABEL,))
