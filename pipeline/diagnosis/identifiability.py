"""Identifiability: what the data cannot tell apart. Findings with the same predictions
(degenerate), signed parameters whose sign the data do not fix, effects the data cannot
identify but a finding's parameters take up (absorbed), and parameters the data leave free
within their prior (unconstrained); ``docs/diagnosis.md``, steps 4, 6 and 7."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from fea.errors import ParameterError

from .criteria import Criteria
from .effects import LIBRARY
from .error_model import sign_is_claimed
from .finding import Finding, all_effects
from .fitting import FitOutcome, Problem, fit
from .ranking import in_library_order, parameters_of, predictions

__all__ = ["degeneracies", "swapped_rescalings", "sign_degeneracies", "absorbed", "unconstrained"]


def unconstrained(f: Finding, half_widths: dict) -> tuple:
    """Parameters of ``f`` whose 1-sigma uncertainty exceeds half their prior range
    (``half_widths``: name -> half width): the data leave them free within the prior, so
    their values are an arbitrary point of a flat valley, not a measurement (campaign,
    collimator WFE on line profiles alone: the oblique astigmatism, which the profiles see
    only through its square, came with 1-sigma 27-650 µm against a prior of ±0.4 µm)."""
    return tuple(k for k, v in f.uncertainties.items()
                 if k in half_widths and not v <= half_widths[k])


def degeneracies(findings, fits, prob, c: Criteria):
    """``findings`` with ``degenerate_with`` set: the other findings within ``c.degenerate_bic``
    whose fitted predictions differ by less than ``c.degenerate_prediction`` of the
    finding's remaining weighted residual (the data cannot tell them apart)."""
    preds = {f.effect: predictions(prob, fits[f.effect]) for f in findings}
    out = []
    for a in findings:
        deg = []
        for b in findings:
            if a is b or abs(a.score - b.score) > c.degenerate_bic:
                continue
            num = sum(prob.weights[m] ** 2 * np.sum((preds[a.effect][m] - preds[b.effect][m]) ** 2) for m in preds[a.effect])
            den = fits[a.effect].weighted_rss(prob.weights)
            if den > 0 and math.sqrt(num / den) < c.degenerate_prediction:
                deg.append(b.effect)
        out.append(a if not deg else replace(a, degenerate_with=tuple(deg)))
    return swapped_rescalings(out)


def swapped_rescalings(findings) -> list:
    """Pairs with a rescaling member also listed as degenerate with the pair that has the
    other rescaling in its place, where the two rescalings' singles were found degenerate.

    Why: the pair search forms only the better of two rescalings' pairs
    (:func:`.ranking.pair_singles`: on one blank a temperature offset and an amplitude scale
    are the same change of the quilt), so the other pair is never fitted and cannot be
    compared; that the data cannot tell the rescalings apart was measured on the singles,
    and a pair adds the same second member to either."""
    singles = {f.effects[0]: f for f in findings if len(f.effects) == 1}
    out = []
    for f in findings:
        extra = []
        if len(f.effects) > 1:
            for r in f.effects:
                if not LIBRARY[r].rescales or r not in singles:
                    continue
                for o in singles[r].degenerate_with:
                    if o not in LIBRARY or not LIBRARY[o].rescales or o in f.effects:  # pairs, labels
                        continue
                    swapped = "+".join(in_library_order(o if e == r else e for e in f.effects))
                    if swapped not in f.degenerate_with:
                        extra.append(swapped)
        out.append(replace(f, degenerate_with=tuple(dict.fromkeys(f.degenerate_with + tuple(extra)))) if extra else f)
    return out


def sign_degeneracies(prob: Problem, finding: Finding, fo: FitOutcome, c: Criteria, joint=None) -> tuple:
    """Signed parameters (null 0) whose sign the data cannot tell: with that parameter held
    at its mirror value
    ``2 o - v`` (``o`` = :attr:`.effects.Parameter.origin`, the value where its physical
    term vanishes; 0 unless the parameter adds to a default term) and the *other*
    parameters of the finding refitted from the mirrored start (nuisances too), the score
    is within ``degenerate_bic`` — a profile-likelihood test of the sign. The mirror may
    lie beyond the prior range; a parameter at a prior bound or within its error bar of
    the origin is tested all the same (a value consistent with no term has its sign
    undetermined too, and is reported so).

    Collimator oblique astigmatism on line profiles: the pupil mirror eta -> -eta flips
    Z(2,-2) only and the profile integrates along the slit, so the profiles depend on
    the *total* Z(2,-2) through its square — default collimator term included. Mirroring
    the extra term about 0 would compare two different magnitudes and never flag it, and
    a screen ``|v| > 2 sigma`` would skip the test where sigma is inf (at a bound) or the
    flipped total lies within its error bar: campaign profiles fit it at the +0.4 µm
    bound or with the wrong sign, and such fits must be flagged.

    Physical case: line profiles are integrals along the slit, and the blank and the
    pupil are mirror-symmetric in y, so a footprint shift +y and -y give (nearly) the same
    profiles; the residual asymmetry comes only from the collimator's oblique terms and
    the truth's own departures from symmetry. Holding the other parameters at their
    fitted values (the previous test) scored the mirror with the other parameters still
    tuned to the original sign: three pupil_y sign flips of the campaign went unflagged
    (fit -1.6 mm vs truth +1.5 mm). Such a parameter is reported with its sign
    undetermined (``sign_degenerate``) rather than with an arbitrary sign.

    ``joint`` = list of (effect names, fit) of the finding refitted with each set of
    companions (``plating_gradient``, ``blank_bow``), adopted or not: the test is then
    repeated with each set free on both sides (reference: the joint fit; mirror: the joint
    parameters refitted with the tested one held at ``-v``), and the sign counts as
    undetermined if either test says so. Reason: a plating gradient breaks the blank's
    y-mirror symmetry, so the asymmetry that picks pupil_y's sign may come from the
    blank rather than from the footprint; the sign is only claimed if it survives a
    plausible gradient (measured on a campaign case: truth pupil_y +1.47 mm, fitted
    -1.61 and unflagged; without the truth's gradient the fit gives +1.57). The joint fits
    are tested also when a companion was adopted (with a map beside the profiles the bow
    is adopted, and the gradient must still be free in some test). Measured limit: with a
    map in the data that case stays unflagged all the same — the map restrains the
    gradient, so the mirror solution costs too much, yet the sign stays wrong."""
    out = set(_sign_test(prob, finding, fo, c, all_effects(finding)))
    for names, jfo in joint or ():
        if jfo is fo:
            continue  # the adopted joint fit: tested above
        out |= set(_sign_test(prob, finding, jfo, c, names, start=jfo.parameters, settled=out))
    return tuple(n for n in finding.parameters if n in out)


def _sign_test(prob: Problem, finding: Finding, fo: FitOutcome, c: Criteria, effects: tuple,
               start: dict | None = None, settled=()) -> tuple:
    """Profile-likelihood sign test of ``finding``'s own signed parameters with the
    parameters of ``effects`` free (reference fit ``fo``); see :func:`sign_degeneracies`.
    Parameters in ``settled`` (already found undetermined by another test) are not tested
    again: one test saying so is enough, and each costs a full refit."""
    out = []
    start = finding.parameters if start is None else start
    cost = fo.weighted_rss(prob.weights)
    params = parameters_of(effects, prob.forwards)
    own = {q.name for q in parameters_of(finding.effects, prob.forwards)}
    for name in finding.parameters:
        if name not in own or name in settled:
            continue  # a companion's sign is not tested (it is refitted with the others), nor one already undetermined
        v = fo.parameters.get(name, finding.parameters[name])
        q = next((q for q in params if q.name == name), None)
        if q is None or q.null != 0.0:
            continue
        # The mirror is taken about the value where the physical term vanishes, and may lie
        # beyond the prior: the prior bounds the search, not what the data can tell apart.
        # No screen on the linearised sigma: where the data see a term through its square,
        # that sigma is meaningless near the origin (inf at a bound, small beside a flipped
        # sign), and the mirror's cost is the test.
        mirror = 2.0 * q.origin - v
        others = tuple(o for o in params if o.name != name)
        try:
            flip = fit(prob, others, fixed={name: mirror},
                       start={o.name: start[o.name] for o in others if o.name in start})
        except ParameterError:
            # The mirror has no physical state (a temperature offset mirrored below the
            # materials' data, a few K above absolute zero): no state of the other sign
            # can explain the data, so the sign stands.
            continue
        cflip = flip.weighted_rss(prob.weights)
        if prob.absolute:  # two-part error model: the flip must cost more than the errors could
            if not sign_is_claimed(prob, fo, flip, predictions(prob, fo), predictions(prob, flip)):
                out.append(name)
        elif cost > 0 and fo.score_change(cflip, prob.weights) < c.degenerate_bic:
            out.append(name)
    return tuple(out)


def absorbed(prob: Problem, finding: Finding, fo: FitOutcome, c: Criteria, kinds: set) -> tuple[dict, tuple]:
    """Parameters of effects the data cannot identify on their own (``Effect.requires``
    not met, so never fitted) that ``finding``'s parameters absorb: returns
    ``({absorbed parameter q: {own parameter: K}}, absorbed effects)`` where, to first
    order, the fitted own parameter = its true value + ``K (q - q_null)``.

    Profile-likelihood test per parameter ``q``: set ``q`` to a test value ``v`` at which
    its signature alone, with only the nuisances refitted on top of the finding's fit,
    would cost ``absorb_test_bic`` (very strong evidence: it would be seen if nothing
    could mimic it); then refit the finding's parameters too. If the cost drops back to
    within ``degenerate_bic`` of the finding's own fit, the finding's parameters take up
    the signature and their values contain any such ``q``: the finding is reported as
    degenerate with the effect, with ``K = (own - own(v)) / v`` (holding ``q`` at ``v``
    takes ``K v`` out of the own parameter).

    Physical case: a blank bow (Zernike (2,0) on the grating) on line profiles is
    collimator defocus in all but name — both curve the wavefront across the dispersion.
    On profiles alone the bow is therefore not fitted (``blank_bow.requires``), which
    left the collimator's defocus reported with a 0.01 µm error although the campaign's
    0.01 µm RMS bow moves it by up to 0.09 µm (in one case -0.295 +- 0.017 fitted,
    -0.202 injected). The move is reported, not added to the error: the library's prior
    range of the bow is a search range, not a measured spread."""
    own = parameters_of(finding.effects + tuple(finding.companions), prob.forwards)
    have = {q.name for q in own}
    untried = [e for e in LIBRARY.values() if set(e.kinds) & kinds and not set(e.requires) <= kinds]
    w = prob.weights
    cost0 = fo.weighted_rss(w)
    if not cost0 > 0:
        return {}, ()
    base = {**fo.parameters}
    start = {q.name: base[q.name] for q in own if q.name in base}

    def dbic(o):
        return fo.score_change(o.weighted_rss(w), w)

    out, effects = {}, []
    for e in untried:
        for q in parameters_of((e.name,), prob.forwards):
            if q.name in have:
                continue
            v1 = q.null + 0.25 * (q.hi - q.null)
            d1 = dbic(fit(prob, (), fixed={**base, q.name: v1}))
            if not d1 > 0:
                continue
            v = q.null + (v1 - q.null) * math.sqrt(c.absorb_test_bic / d1)
            if not q.lo <= v <= q.hi:
                continue  # too weak to be seen within its prior range: nothing to absorb
            if dbic(fit(prob, (), fixed={**base, q.name: v})) < 0.5 * c.absorb_test_bic:
                continue  # the response is not even roughly quadratic: no clean test
            refit = fit(prob, own, fixed={q.name: v}, start=start)
            if dbic(refit) <= c.degenerate_bic:
                out[q.name] = {n: (base[n] - refit.parameters[n]) / (v - q.null) for n in start}
                effects.append(e.name)
    return out, tuple(dict.fromkeys(effects))
