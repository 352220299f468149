"""The verdict's tests of one finding (``docs/diagnosis.md``, step 9): which it fails, and so
whether it explains the gap. One list serves the engine's verdict and the report's words."""

from __future__ import annotations

from .criteria import Criteria
from .effects import LIBRARY, parameter_spec
from .finding import Finding
from .pupil_orders import OTHER_ORDERS_LABEL
from .wings import WINGS_LABEL

__all__ = ["TESTS", "OUTSIDE_ALTERNATIVES", "failed_tests", "explains", "own_parameters"]

#: The tests a finding must pass to explain the gap, by name.
TESTS = ("significant", "excess", "heldout", "prior", "alternative", "outside")

#: What a check puts in ``degenerate_with`` when something outside the library fits the data
#: as well as the finding (:mod:`.pupil_orders`, :mod:`.wings`).
OUTSIDE_ALTERNATIVES = (OTHER_ORDERS_LABEL, WINGS_LABEL)


def own_parameters(f: Finding) -> set:
    """Names of ``f``'s parameters that belong to its own effects, not to its companions
    (per-blank copies resolved by :func:`.effects.parameter_spec`)."""
    templates = {q for e in f.effects for q in LIBRARY[e].parameters}
    return {q for q in f.parameters if parameter_spec(q) in templates}


def failed_tests(f: Finding, c: Criteria) -> tuple:
    """The names (:data:`TESTS`) of the tests ``f`` fails under the thresholds ``c``:

    * ``significant``: its BIC is not ``min_delta_bic`` below the nominal's;
    * ``excess``: it takes up less than ``min_variance_explained`` of the residual beyond noise
      where it acts;
    * ``heldout``: fitted on part of the data it does not predict the rest (``overfit``);
    * ``prior``: every one of its own parameters ended at a bound of its prior range (the prior,
      not the data, stopped the fit: a map of zeros "explained" by an amplitude scale of 0.3);
    * ``alternative``: something outside the library fits the data as well (an
      :data:`OUTSIDE_ALTERNATIVES` label in ``degenerate_with``: pupil aberrations of other
      orders, :mod:`.pupil_orders`; the detector side, :mod:`.wings`);
    * ``outside``: the data need something outside the library beside it (``needs_outside``,
      :mod:`.wings`).
    """
    own = own_parameters(f)
    failed = {"significant": not f.significant,
              "excess": not f.excess_explained >= c.min_variance_explained,
              "heldout": bool(f.overfit),
              "prior": bool(own) and own <= set(f.at_bound),
              "alternative": any(e in OUTSIDE_ALTERNATIVES for e in f.degenerate_with),
              "outside": bool(f.needs_outside)}
    return tuple(t for t in TESTS if failed[t])


def explains(f: Finding, c: Criteria) -> bool:
    """Whether ``f`` passes every test of :func:`failed_tests`."""
    return not failed_tests(f, c)
