"""The concepts of the effect library: a fit :class:`Parameter`, a candidate
unmodelled :class:`Effect`, the :class:`SpectrographOptics` its optics hook changes and
the :class:`SummaryContext` its report summary reads (the library itself and what it
means: :mod:`pipeline.diagnosis.effects`).

How an effect acts on the forward models (:mod:`pipeline.diagnosis.forward`, which loops
over the library and calls these hooks in this order; each hook reads only its own
parameters, a missing one at its null, and leaves the input unchanged there):

1. the deformation's overall factor ``k = thermal_factor(T) * prod(scale)``: ``temperature``
   maps the stated temperature to the true one, ``scale`` gives a factor;
2. a map's measured points to blank coordinates: ``coordinates``;
3. the blank's shape in blank coordinates, before ``k``: ``shape`` at its ``shape_stage``
   (:data:`SHAPE_STAGES`);
4. a map after ``k``: ``map_zernike`` terms over the map's aperture disc;
5. the spectrograph (line profiles, PSF images): ``pupil_zernike`` terms added to the
   collimator's wavefront, then ``optics``;
6. a detected line profile: ``detected`` (light the detector side adds).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

__all__ = ["Parameter", "Effect", "SHAPE_STAGES", "SpectrographOptics", "SummaryContext", "vector_norm"]

#: The order in which the ``shape`` transforms act on the blank's deformation: "reshape"
#: (changes the nominal's own parts, so it sees the unchanged nominal), "multiply"
#: (scales the local deformation, reshaped quilt included), "add" (adds a surface that
#: the others do not scale). Within a stage, the library's order.
SHAPE_STAGES = ("reshape", "multiply", "add")


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
    scale : callable or None
        Factor of the deformation, ``scale(parameters, blank) -> float`` for the
        measurement of grating blank ``blank``.
    temperature : callable or None
        The true temperature, ``temperature(temperature_K, parameters) -> K``, of a
        measurement stated at ``temperature_K`` (the thermal factor is taken there).
    coordinates : callable or None
        Blank coordinates of a map's measured points, ``coordinates(x_mm, y_mm,
        parameters) -> (qx_mm, qy_mm)``, or None where the parameters do not move them.
    shape : callable or None
        The blank's changed deformation, ``shape(sag_um, x_mm, y_mm, parameters, quilt) ->
        sag_um`` at blank coordinates (mm), before the overall factor; ``quilt`` is
        :func:`pipeline.diagnosis.forward.quilt_parts` of the nominal at the same points
        (None: no quilt fit).
    shape_stage : str
        When ``shape`` acts, one of :data:`SHAPE_STAGES`.
    map_zernike : tuple of (str, (int, int))
        ``(parameter, (n, m))``: surface Zernike terms added to a map after the overall
        factor, RMS-normalised over the map's aperture disc (µm).
    pupil_zernike : tuple of (str, (int, int))
        ``(parameter, (n, m))``: wavefront Zernike terms added to the collimator's,
        RMS-normalised over the 110 mm pupil (µm).
    optics : callable or None
        The spectrograph's changed optics, ``optics(SpectrographOptics, parameters) ->
        SpectrographOptics``.
    detected : callable or None
        The detected line profile changed after the optics, ``detected(offset_um,
        intensity, parameters) -> intensity`` on the model's uniform offset grid (µm).
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
    scale: Callable | None = None
    temperature: Callable | None = None
    coordinates: Callable | None = None
    shape: Callable | None = None
    shape_stage: str = "add"
    map_zernike: tuple = ()
    pupil_zernike: tuple = ()
    optics: Callable | None = None
    detected: Callable | None = None

    def __post_init__(self) -> None:
        if self.shape_stage not in SHAPE_STAGES:
            raise ValueError(f"Effect {self.name!r}: shape_stage={self.shape_stage!r} must be one of "
                             f"{list(SHAPE_STAGES)}")
        own = {p.name for p in self.parameters}
        for field_name in ("map_zernike", "pupil_zernike"):
            for name, nm in getattr(self, field_name):
                if name not in own or len(nm) != 2:
                    raise ValueError(f"Effect {self.name!r}: {field_name} entry ({name!r}, {nm!r}) must be (one of its "
                                     f"parameters {sorted(own)}, (n, m))")
        if self.truth_stage not in ("blank", "map"):
            raise ValueError(f"Effect {self.name!r}: truth_stage={self.truth_stage!r} must be 'blank' or 'map'")
        if self.rescales and (self.coordinates or self.shape or self.map_zernike or self.pupil_zernike or self.optics
                              or self.detected):
            # a rescaling acts only through the overall factor (never paired, not in the image memo key)
            raise ValueError(f"Effect {self.name!r}: rescales=True allows only the scale= and temperature= hooks")
        if self.projection is not None and not self.rescales:
            # the projection convention converts an overall factor of the deformation
            raise ValueError(f"Effect {self.name!r}: projection= is only for an effect with rescales=True "
                             f"(got rescales={self.rescales})")


@dataclass(frozen=True)
class SpectrographOptics:
    """What the ``optics`` hooks change: the grating (an :class:`optics.grating.Grating`,
    its slit image width included), the beam footprint's offset on it (mm; x dispersion,
    y rulings) and the collimator's pupil Zernike terms ``{(n, m): µm}``."""

    grating: object
    pupil_shift_mm: tuple[float, float]
    collimator_zernike_um: dict


@dataclass(frozen=True)
class SummaryContext:
    """What the physical summaries of a finding need from the data and the simulation:
    the simulation's cold temperature (K), the blanks seen, the surface maps' aperture
    radii (mm, where the astigmatism is normalised), the nominal quilt's RMS
    amplitudes (µm, :meth:`pipeline.diagnosis.quilt.QuiltComponents.amplitudes_um`; None: no quilt fit),
    its parts' shares of the nominal's projection (:func:`pipeline.diagnosis.quilt.projection_weights`;
    None: no quilt fit), and the warm temperature (K) and (substrate, film) that set the
    thermal factor, and the gratings of the line profiles (names, :data:`optics.grating.GRATINGS`)."""

    cold_K: float
    blanks: tuple = ()
    surface_radii_mm: tuple = ()
    quilt_rms_um: dict | None = None
    quilt_weights: dict | None = None
    warm_K: float = 293.0
    materials: tuple = ("Al6061-T6", "NiP")
    gratings: tuple = ()


def vector_norm(p: dict, names) -> float:
    """Euclidean norm of the parameters ``names`` of ``p`` (a missing one counts 0): the
    physical magnitude of a ``vector`` effect (RMS of orthonormal Zernike terms, a shift)."""
    return math.sqrt(sum(p.get(n, 0.0) ** 2 for n in names))
