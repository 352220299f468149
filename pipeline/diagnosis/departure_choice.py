"""Do the spectrograph images fit better with the measured map's departure carried, or
without it? (:func:`departure_choice`)

Why: the departure (:mod:`.map_departure`) is the map's quilt beyond the library's shapes,
divided by the map's deformation factor, and it carries the map's errors with it: the
correlated ones (an interferometer's mid-spatial-frequency errors, the map's own noise
smoothed over a few mm) share the quilt's band and pass the Wiener gain, which knows only
the white noise, and a warm map (a small factor) magnifies them. Whether what the map
adds is the grating's quilt or the map's error is something the images themselves can
say: the images are formed through the quilt, not through the map's errors. Measured on
independent truths (two campaign draws, profiles + map cases where carrying the departure
changed the diagnosis): where it helped (pupil shifts on pocket-jitter quilts, a 26 %
amplitude named alone) the best finding fitted the profiles better with it by 5.5–157 in
BIC; a +69 K blank whose 197 K map (factor 0.53) read `temperature` beside a `blank_bow`
it did not need, a pupil shift and a collimator error left unexplained fitted better without
it by 3.6, 20.5 and 11.4 (``benchmarks/results_departure_choice.md``).

Rule: the best finding's effects and companions are refitted in the same weights with
every image model's departure removed, started at the finding's optimum (the same
parameters, so the BIC difference is the weighted residual's). If that fit's BIC is lower
than the finding's by more than ``Criteria.degenerate_bic`` (the margin within which two
fits are as good), the departure is not carried and the diagnosis is redone without it;
otherwise it stays (the default, where the images cannot tell). The redone ranking restarts
each fit whose parameters hold the finding's from that refit where it ends above it
(:func:`.ranking.rank`'s ``warm``): the redo's multi-start begins from the singles and can land
in a worse basin than the refit it is redone for (measured: a 7.53 mm pupil shift on a sum-form
quilt, refitted without the departure at 7.62 mm and BIC -200.3, was redone at 3.75 mm and
-161.1, read from there as the finding).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from .criteria import Criteria
from .finding import Finding, all_effects
from .fitting import FitOutcome, Problem, fit
from .ranking import parameters_of

__all__ = ["DepartureChoice", "carried_departures", "departure_choice"]


@dataclass(frozen=True)
class DepartureChoice:
    """Outcome of :func:`departure_choice`: the finding refitted, its BIC with the map's
    departure carried (the finding's own) and without it, and whether it stays carried."""

    finding: str
    bic_with: float
    bic_without: float
    carried: bool
    #: the finding's effects and companions fitted without the departures: where the
    #: departure is not carried, the ranking redone without it restarts from this fit
    #: (:func:`.ranking.rank`'s ``warm``)
    without: FitOutcome | None = field(default=None, compare=False, repr=False)

    @property
    def note(self) -> str:
        verb = "carried" if self.carried else "not carried"
        return (f"the map's departure is {verb}: {self.finding} fits the images with it at BIC {self.bic_with:.1f}, "
                f"without it at {self.bic_without:.1f}")

    def summary(self) -> dict:
        return {"finding": self.finding, "bic_with": round(self.bic_with, 2),
                "bic_without": round(self.bic_without, 2), "carried": self.carried, "note": self.note}


def carried_departures(prob: Problem) -> dict:
    """The departure each image model of ``prob`` carries, by measurement (None where none)."""
    return {f.name: getattr(f, "departure", None) for f in prob.forwards if f.kind != "surface"}


def departure_choice(prob: Problem, finding: Finding, fo: FitOutcome, c: Criteria) -> DepartureChoice:
    """Refit ``finding`` (fit ``fo``, with the departures ``prob``'s image models carry)
    without them and choose (module docstring's rule). The image models carry their
    departures again on return."""
    departures = carried_departures(prob)
    if not any(d is not None for d in departures.values()):
        raise ValueError("departure_choice: no image model of the problem carries a map's departure")
    params = parameters_of(tuple(dict.fromkeys(all_effects(finding))), prob.forwards)
    models = [f for f in prob.forwards if departures.get(f.name) is not None]  # others keep their memos
    try:
        for f in models:
            f.carry_departure(None)
        without = fit(prob, params, start=dict(fo.parameters))
    finally:
        for f in models:
            f.carry_departure(departures[f.name])
    b_with, b_without = fo.bic(prob.weights), without.bic(prob.weights)
    return DepartureChoice(finding.effect, float(b_with), float(b_without),
                           carried=bool(b_without >= b_with - c.degenerate_bic), without=without)
