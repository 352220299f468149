"""One candidate explanation (an effect, a pair, with any companions) fitted to all the data."""

from __future__ import annotations

from dataclasses import dataclass, field

__all__ = ["Finding", "all_effects"]


@dataclass(frozen=True)
class Finding:
    """One candidate (effect or pair) fitted to all data; RMS in the data units
    (µm for maps, fraction of the peak for profiles), overall values weighted."""

    effect: str
    effects: tuple
    parameters: dict
    uncertainties: dict
    score: float
    delta_bic: float
    residual_rms_before: float
    residual_rms_after: float
    shrink_fraction: float
    variance_explained: float
    excess_explained: float = float("nan")
    excess_explained_overall: float = float("nan")
    heldout_shrink_fraction: float | None = None
    heldout_note: str = ""
    overfit: bool = False
    degenerate_with: tuple = ()
    sign_degenerate: tuple = ()
    per_measurement: tuple = ()
    significant: bool = False
    companions: tuple = ()
    absorbs: dict = field(default_factory=dict)
    unconstrained: tuple = ()
    #: ``{parameter: unit}`` of every parameter in ``parameters`` (from :mod:`.effects`).
    parameter_units: dict = field(default_factory=dict)
    #: Physically absolute summaries per effect (:func:`.effects.physical_summary`):
    #: ``temperature_K`` beside the offset, ``scale`` where one blank is measured,
    #: ``rms_um`` of Zernike-type effects with the ``aperture`` it refers to, the quilt's
    #: component amplitudes.
    summary: dict = field(default_factory=dict)
    #: Fitted parameters of the finding's own effects that ended at a bound of their prior
    #: range (:func:`.plausibility.at_prior_bound`): stopped by the prior, not the data.
    at_bound: tuple = ()
    #: Measurements still beyond their noise after this finding (:func:`.gap.gaps`).
    remaining_gap: tuple = ()
    #: What outside the library the data need *beside* this finding (light added on the
    #: detector side, :mod:`.wings`): the finding takes up part of the gap, not all of it.
    needs_outside: tuple = ()


def all_effects(f: Finding) -> tuple:
    """The effects whose parameters a finding holds: its own plus its companions."""
    return tuple(f.effects) + tuple(f.companions)
