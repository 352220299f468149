"""The verdict's tests of one finding (``docs/diagnosis.md``, step 9): which it fails, and so
whether it explains the gap. One list serves the engine's verdict and the report's words."""

from __future__ import annotations

from .criteria import Criteria
from .effects import LIBRARY, parameter_spec
from .finding import Finding

__all__ = ["TESTS", "failed_tests", "explains", "own_parameters"]

#: The tests a finding must pass to explain the gap, by name.
TESTS = ("significant", "excess", "heldout", "prior", "outside")


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
    * ``outside``: the data need something outside the library beside it (``needs_outside``,
      :mod:`.wings`).
    """
    own = own_parameters(f)
    failed = {"significant": not f.significant,
              "excess": not f.excess_explained >= c.min_variance_explained,
              "heldout": bool(f.overfit),
              "prior": bool(own) and own <= set(f.at_bound),
              "outside": bool(f.needs_outside)}
    return tuple(t for t in TESTS if failed[t])


def explains(f: Finding, c: Criteria) -> bool:
    """Whether ``f`` passes every test of :func:`failed_tests`."""
    return not failed_tests(f, c)
