"""The thresholds of the diagnosis's decision logic (see ``docs/diagnosis.md``)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from .error_model import ERROR_MODELS

__all__ = ["Criteria", "N_EFF_SOURCES", "PAIR_SECONDS", "WEIGHT_SCALES"]


N_EFF_SOURCES = ("nominal", "best_fit")
#: What a measurement's weight is normalised by (``Criteria.weight_scale``).
WEIGHT_SCALES = ("measurement", "kind")
#: Which further singles the forward pair step pairs with the best one (``Criteria.pair_second``).
PAIR_SECONDS = ("significant", "improving")


@dataclass(frozen=True)
class Criteria:
    """Thresholds of the decision logic (``docs/diagnosis.md``), passed explicitly."""

    min_delta_bic: float = 10.0
    min_variance_explained: float = 0.5
    heldout_ratio: float = 0.5
    pair_extra_bic: float = 10.0
    pair_from: int = 3
    #: Also pair the best single with every further significant one that is not a rescaling
    #: (one forward-selection step, :func:`.ranking.pairs_to_fit`) and grid-search a pair's
    #: weaker member beside the warm start. Off by default: measured on single-effect profile
    #: truths the weak second member it adds takes up what the library does not model (a
    #: rescaling beside the right effect; without rescalings, a pupil shift beside the
    #: amplitude on out-of-library profiles; ``benchmarks/results_pairs.md``).
    pair_forward: bool = False
    #: With ``pair_forward``: the further singles the best one is paired with, "significant"
    #: ones only, or every one that lowers the BIC at all ("improving") (a second effect whose
    #: signature is small beside the first's may not be significant alone, yet the pair is:
    #: the paper's J scenario under ``weight_scale = "kind"``, pupil shift alone delta BIC
    #: -4.6, with the amplitude -41.7 beyond the amplitude alone;
    #: ``benchmarks/results_weight_scale.md``).
    pair_second: str = "significant"
    degenerate_bic: float = 2.0
    degenerate_prediction: float = 0.2
    no_gap_ratio: float = 1.3
    no_gap_z: float = 5.0
    heldout_top: int = 3
    companion_top: int = 2
    companion_bic: float = 6.0
    #: The best rescaling single (``amplitude_scale`` or ``temperature``) is also tried as a
    #: companion of every finding that does not rescale (a real quilt's amplitude is never
    #: the simulation's, as its shape is not); a finding that adopts it ranks as a pair
    #: (:func:`.ranking.best_rescaling`; ``benchmarks/results_rescaling_companion.md``).
    rescaling_companion: bool = True
    absorb_test_bic: float = 25.0
    n_eff_from: str = "nominal"
    #: "n_eff": effective-sample counts (``n_eff_from``); "two_part": white noise plus a
    #: smooth mismatch measured from the post-fit residual (:mod:`.error_model`; then
    #: ``n_eff_from`` is not used); "by_kind": "two_part" when a line profile is among the
    #: measurements, "n_eff" otherwise (:func:`.error_model.model_for_kinds`).
    error_model: str = "n_eff"
    #: With ``error_model = "n_eff"``: "measurement" (default) normalises each measurement's
    #: weight by its own nominal residual (every measurement weighs ~its effective samples,
    #: however large its gap); "kind" shares one normalisation among the measurements of one
    #: kind (within a kind, weights go as one over the noise, so a profile with a large gap
    #: weighs more than one with a small gap). :func:`.fitting.nominal_weights`; measured on
    #: independent truths and the paper's J scenario in ``benchmarks/results_weight_scale.md``.
    weight_scale: str = "measurement"
    #: Where a map of a blank is measured beside its line profiles or PSF images, the image
    #: models carry the map's departure from the model's blank shape (the quilt the library
    #: cannot fit: :mod:`.map_departure`); False: they use the model's shape alone.
    map_in_optics: bool = True

    def __post_init__(self) -> None:
        if self.n_eff_from not in N_EFF_SOURCES:
            raise ValueError(f"Criteria: n_eff_from={self.n_eff_from!r} must be one of {N_EFF_SOURCES}")
        if self.weight_scale not in WEIGHT_SCALES:
            raise ValueError(f"Criteria: weight_scale={self.weight_scale!r} must be one of {WEIGHT_SCALES}")
        if self.pair_second not in PAIR_SECONDS:
            raise ValueError(f"Criteria: pair_second={self.pair_second!r} must be one of {PAIR_SECONDS}")
        if self.error_model not in ERROR_MODELS:
            raise ValueError(f"Criteria: error_model={self.error_model!r} must be one of {ERROR_MODELS}")
        ranges = {"min_delta_bic": (0.0, math.inf), "min_variance_explained": (0.0, 1.0),
                  "heldout_ratio": (0.0, 1.0), "pair_extra_bic": (0.0, math.inf), "pair_from": (0, 20),
                  "degenerate_bic": (0.0, math.inf), "degenerate_prediction": (0.0, 1.0),
                  "no_gap_ratio": (1.0, math.inf), "no_gap_z": (0.0, math.inf), "heldout_top": (0, 20),
                  "companion_top": (0, 20), "companion_bic": (0.0, math.inf), "absorb_test_bic": (0.0, math.inf)}
        if not isinstance(self.map_in_optics, bool):
            raise ValueError(f"Criteria: map_in_optics={self.map_in_optics!r} must be True or False")
        if not isinstance(self.rescaling_companion, bool):
            raise ValueError(f"Criteria: rescaling_companion={self.rescaling_companion!r} must be True or False")
        if not isinstance(self.pair_forward, bool):
            raise ValueError(f"Criteria: pair_forward={self.pair_forward!r} must be True or False")
        for name, (lo, hi) in ranges.items():
            v = getattr(self, name)
            integer = isinstance(lo, int)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or (integer and not float(v).is_integer()) \
                    or not lo <= v <= hi:
                kind = "an integer" if integer else "a number"
                raise ValueError(f"Criteria: {name}={v!r} must be {kind} in [{lo}, {hi}]")
