"""The concepts of the effect library: a fit :class:`Parameter`, a candidate
unmodelled :class:`Effect` and the :class:`SummaryContext` its report summary reads
(the library itself and what it means: :mod:`pipeline.diagnosis.effects`)."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

__all__ = ["Parameter", "Effect", "SummaryContext", "vector_norm"]


@dataclass(frozen=True)
class Parameter:
    """One fit parameter: name (with unit), null value, prior bounds, start values for a
    coarse grid search, the absolute recovery tolerance ``floor``, its ``unit`` (as
    written in reports; "1" for a dimensionless ratio), a one-line ``meaning`` and the
    measurement ``kinds`` it changes (empty: every kind of its effect; a parameter none
    of whose kinds is in the data is not fitted: it has no leverage there).
    ``sign_origin``: the value at which the physical term the parameter adds to vanishes,
    if not its null (an extra term added to a default one: the sign the data may not tell
    is that of ``value - sign_origin``, and its mirror value is ``2 sign_origin - value``)."""

    name: str
    null: float
    lo: float
    hi: float
    starts: tuple[float, ...] = ()
    floor: float = 0.0
    unit: str = "1"
    meaning: str = ""
    kinds: tuple[str, ...] = ()
    sign_origin: float | None = None

    def __post_init__(self) -> None:
        if not self.lo <= self.null <= self.hi:
            raise ValueError(f"Parameter {self.name!r}: null={self.null} outside [{self.lo}, {self.hi}]")

    @property
    def width(self) -> float:
        return self.hi - self.lo

    @property
    def origin(self) -> float:
        """Value about which the parameter's sign is defined (``sign_origin``, else ``null``)."""
        return self.null if self.sign_origin is None else self.sign_origin


@dataclass(frozen=True)
class Effect:
    """A candidate unmodelled effect.

    Parameters
    ----------
    name : str
        Library key.
    kinds : tuple of str
        Measurement kinds it changes ("surface", "line_profile", "psf_image").
    parameters : tuple of Parameter
        Its parameters; for ``per_blank`` effects a template whose name gets ``_<blank>``.
    per_blank : bool
        One copy of the parameter per grating blank in the data.
    description : str
        Physical meaning, for reports.
    companion : bool
        Also refitted jointly with the best other candidates (:mod:`pipeline.diagnosis.effects`).
    vector : bool
        The parameters are the components of one vector in a common unit whose norm is
        the effect's physical magnitude: coefficients of RMS-normalised (orthonormal)
        Zernike terms, whose norm is the RMS of the added surface or wavefront error, or a
        displacement in mm. The campaign also judges recovery on the vector
        (:func:`pipeline.diagnosis.campaign.recovery_errors`).
    requires : tuple of str
        Measurement kinds that must be in the data for the effect to be tried: the kinds
        that can identify it (it still changes every kind in ``kinds``).
    background : bool
        Present at some level on every real grating (a ``companion`` too): refitted beside
        every finding and never half of a pair (:mod:`pipeline.diagnosis.effects`).
    draw_truth : callable or None
        The injection-recovery campaign's random truth, ``draw_truth(rng, kind, blank) ->
        {parameter: value}`` for a case of measurement ``kind`` on grating blank ``blank``
        (:mod:`.effect_draws`); None: the campaign does not inject the effect.
    truth_stage : str
        When a campaign map case draws the truth: "blank" (before the truth's model
        discrepancy, which multiplies the deformation the effect reshapes) or "map" (after
        it: the effect is added to, or moves, the measured map). Line-profile cases draw
        every truth before the discrepancy.
    rescales : bool
        Acts only through the deformation's overall factor (an exact rescaling of the
        nominal): it changes a spectrograph image only through that factor, and two such
        effects in one fit are redundant (the per-blank scales absorb a common factor;
        exactly, for one cold temperature per blank), so they are never paired.
    summary : callable or None
        The finding's physically absolute summary for reports, ``summary(parameters,
        ctx) -> dict`` with the effect's own fitted parameters and a
        :class:`SummaryContext` (:func:`.library.physical_summary`); None: none.
    projection : callable or None
        Only for a ``rescales`` effect: its fitted amplitude in the other convention
        beside ``quilt_shape`` (``docs/diagnosis.md``, "Two meanings of the amplitude"),
        ``projection(parameters, k, ctx) -> dict`` of entries added to its summary, with
        every fitted parameter of the finding, the projection factor ``k``
        (:func:`pipeline.diagnosis.quilt.projection_factor`) and the
        :class:`SummaryContext`; None: none.
    """

    name: str
    kinds: tuple[str, ...]
    parameters: tuple[Parameter, ...]
    per_blank: bool = False
    description: str = ""
    vector: bool = False
    companion: bool = False
    requires: tuple[str, ...] = ()
    background: bool = False
    draw_truth: Callable | None = None
    truth_stage: str = "blank"
    rescales: bool = False
    summary: Callable | None = None
    projection: Callable | None = None

    def __post_init__(self) -> None:
        if self.truth_stage not in ("blank", "map"):
            raise ValueError(f"Effect {self.name!r}: truth_stage={self.truth_stage!r} must be 'blank' or 'map'")
        if self.projection is not None and not self.rescales:
            # the projection convention converts an overall factor of the deformation
            raise ValueError(f"Effect {self.name!r}: projection= is only for an effect with rescales=True "
                             f"(got rescales={self.rescales})")


@dataclass(frozen=True)
class SummaryContext:
    """What the physical summaries of a finding need from the data and the simulation:
    the simulation's cold temperature (K), the blanks seen, the surface maps' aperture
    radii (mm, where the astigmatism is normalised), the nominal quilt's RMS
    amplitudes (µm, :meth:`pipeline.diagnosis.quilt.QuiltComponents.amplitudes_um`; None: no quilt fit),
    its parts' shares of the nominal's projection (:func:`pipeline.diagnosis.quilt.projection_weights`;
    None: no quilt fit), and the warm temperature (K) and (substrate, film) that set the
    thermal factor."""

    cold_K: float
    blanks: tuple = ()
    surface_radii_mm: tuple = ()
    quilt_rms_um: dict | None = None
    quilt_weights: dict | None = None
    warm_K: float = 293.0
    materials: tuple = ("Al6061-T6", "NiP")


def vector_norm(p: dict, names) -> float:
    """Euclidean norm of the parameters ``names`` of ``p`` (a missing one counts 0): the
    physical magnitude of a ``vector`` effect (RMS of orthonormal Zernike terms, a shift)."""
    return math.sqrt(sum(p.get(n, 0.0) ** 2 for n in names))
