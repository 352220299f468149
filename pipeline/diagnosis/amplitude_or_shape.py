"""Amplitude or shape: whether the data tell a change of the quilt's shape (``quilt_shape``
alone) from a change of the deformation's amplitude (``temperature``, ``amplitude_scale``)
(:func:`amplitude_degeneracies`; ``docs/diagnosis.md``, step 4).

Where the information is. ``quilt_shape`` rescales the y fundamental, the (1, ±1) cross
terms, the other harmonics and the smooth figure *relative to the x fundamental*, which it
holds (:mod:`.quilt`). Beside it, a rescaling effect adds exactly one freedom: the x
fundamental's amplitude. So on one map of one blank at one temperature, everything the data
say about the amplitude once the shape is free is the amplitude of the 21 mm fundamental
along x. A common rescaling of all the parts is therefore never a ``quilt_shape``-alone
finding (the x fundamental would be left over; a rule naming such a finding an amplitude
change would test what the BIC already tests), but the converse is the real limit: when the
x fundamental's amplitude is poorly measured (a map whose residual is dominated by shape
the library does not reach has few effective samples), a ``quilt_shape``-alone finding
states "amplitude as simulated" by holding it, not by measuring it.

And that amplitude is a convention. A real quilt's shape can change its x fundamental
too: an amplitude change of a blank whose quilt prints through sharper than the FEA's
(the campaign's ``sharp_ribs`` truth: x fundamental 1.06 of the nominal's at the same
least-squares projection) raises the fundamental while the temperature lowers it, and
one map only sees the product. Measured, two campaign maps at 128 K (+22 K and +32 K
warmer, i.e. 0.91 and 0.86 of the amplitude in the projection's convention): temperature
beside quilt_shape fits +11 ± 33 K and +15 ± 32 K (x fundamental 0.95 and 0.93, sigma
0.16), temperature alone +43 K and +54 K, and quilt_shape alone (amplitude held at 1)
ranks first by a delta BIC of 2-4. Beside the shape, the amplitude's interval holds both
no change and what the rescaling alone reads: naming the shape change alone would claim
an amplitude the data do not measure.

The rule: the top finding, a ``quilt_shape``-alone one, is degenerate with a rescaling
finding when (1) the rescaling effect fitted alone (the shape held at the simulation's)
claims a change (its parameter more than two of its standard deviations from the null:
the pattern of the sign test, :func:`.identifiability.sign_degeneracies`) and (2) beside
the shape (the rescaling and ``quilt_shape`` fitted jointly), the amplitude's two-sigma
interval holds both the null (what the shape-alone finding states) and that claim. Then
the gap has two readings the data do not tell apart: a pure shape change, and the
amplitude change the rescaling reads in it (with some shape change beside it); both
findings list each other in ``degenerate_with``, and the report does not claim either as
the single answer. The two-sigma interval is the engine's own (Birge and long-run
inflated, :mod:`.fitting`): a profile of the score alone, which counts the nominal
residual's effective samples, excluded the +43 K case above at 1.9 "sigma" while the
reported uncertainty of the joint fit was twice that, and it is the reported one that
the verdict must agree with. Where the x fundamental is measured the interval is
narrow: a map whose quilt harmonics changed at the simulated amplitude stays a shape
change, and a map 20-40 % lower in amplitude is named a rescaling outright (it beats
the shape alone). No new threshold: two sigma, as the sign test.
"""

from __future__ import annotations

import math
from dataclasses import replace

from .effects import LIBRARY
from .finding import Finding
from .fitting import FitOutcome, Problem, fit
from .ranking import parameters_of

__all__ = ["amplitude_degeneracies", "shape_only", "rescaling_only"]


def shape_only(f: Finding) -> bool:
    """Whether ``f`` is ``quilt_shape``-like: every effect a ``background`` one, no companion."""
    return bool(f.effects) and all(LIBRARY[e].background for e in f.effects) and not f.companions


def rescaling_only(f: Finding) -> bool:
    """Whether ``f``'s own effect is one rescaling of the deformation (``Effect.rescales``:
    temperature, amplitude_scale), with or without companions."""
    return len(f.effects) == 1 and LIBRARY[f.effects[0]].rescales


def amplitude_degeneracies(prob: Problem, findings: list) -> list:
    """``findings`` (best first) with ``degenerate_with`` extended where the top finding is
    a shape change alone (:func:`shape_only`) that the data cannot tell from the amplitude
    change a rescaling finding claims (module docstring). Only the top finding is tested:
    it is the one the verdict names. Where the rescaling finding adopted the shape as
    companion, that finding is the joint fit and its reported uncertainty (which adds the
    move to the companions it did not adopt, :func:`.ranking.mismatch_errors`) is the
    interval; elsewhere the joint fit's own. Costs one or two fits per rescaling finding
    (alone; beside the shape where it did not adopt it), only where a shape change alone
    tops the ranking."""
    if not findings or not shape_only(findings[0]):
        return findings
    shape = findings[0]
    out, flagged = list(findings), []
    for i, r in enumerate(findings[1:], start=1):
        if not rescaling_only(r):
            continue
        own = parameters_of(r.effects, prob.forwards)
        alone = fit(prob, own, start=r.parameters)
        if tuple(r.companions) == tuple(shape.effects):  # its own finding is the joint fit
            beside, sigma = r.parameters, r.uncertainties
        else:
            joint = fit(prob, parameters_of(r.effects + shape.effects, prob.forwards),
                        start={**shape.parameters, **alone.parameters})
            beside, sigma = joint.parameters, joint.errors
        if own and all(_claims_change(q, alone) and _admits(q, beside, sigma, (q.null, alone.parameters[q.name]))
                       for q in own):
            flagged.append(i)
    # temperature and amplitude_scale are one rescaling of one blank (each lists the other as
    # degenerate): what one shares with the shape, the other does too, although their
    # two-sigma intervals, linear in kelvin and in scale, can fall either side of a value
    for i, r in enumerate(findings[1:], start=1):
        if i not in flagged and rescaling_only(r) and any(findings[j].effect in r.degenerate_with for j in flagged):
            flagged.append(i)
    for i in flagged:
        out[i] = replace(out[i], degenerate_with=tuple(dict.fromkeys(out[i].degenerate_with + (shape.effect,))))
        out[0] = replace(out[0], degenerate_with=tuple(dict.fromkeys(out[0].degenerate_with + (out[i].effect,))))
    return out


def _claims_change(q, fo: FitOutcome) -> bool:
    """Whether ``fo`` puts parameter ``q`` more than two standard deviations from its null."""
    return abs(fo.parameters[q.name] - q.null) > 2.0 * fo.errors.get(q.name, math.inf)


def _admits(q, parameters: dict, sigma: dict, values) -> bool:
    """Whether every value in ``values`` lies within two standard deviations (``sigma``) of
    the fitted ``parameters``' ``q``."""
    v, s = parameters[q.name], sigma.get(q.name, math.inf)
    return all(abs(x - v) <= 2.0 * s for x in values)
