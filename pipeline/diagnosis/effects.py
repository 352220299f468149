"""The library of candidate unmodelled effects.

Each effect is a named set of parameters of the forward model (:mod:`.forward`) with a
physical meaning, a null value (the nominal model) and a prior range (fit bounds).
All effects act on the same parameter vector, so a pair of effects is simply the union
of their parameters.

==================  ===========================================  ============================
effect              parameters (null; prior)                     physical meaning
==================  ===========================================  ============================
astigmatism         astig_0_um, astig_45_um (0; ±1 µm)           mount-induced surface Zernike
                                                                 astigmatism Z(2,2), Z(2,-2)
                                                                 (RMS-normalised, aperture disc)
amplitude_scale     scale_<blank> (1; 0.3…3), one per blank      coating thickness / polish
                                                                 differ (e.g. re-polishing)
temperature         temperature_offset_K (0; -60…+80 K)           cold temperature differs from
                                                                 the stated one (all data)
registration        reg_dx_mm, reg_dy_mm (0; ±10 mm),            measured map shifted/rotated
                    reg_rot_deg (0; ±5°)                         against the model
pupil_shift         pupil_x_mm, pupil_y_mm (0; ±10 mm)           beam footprint offset on the
                                                                 grating
collimator_wfe      coll_coma_um Z(3,1), coll_defocus_um Z(2,0), extra spectrograph WFE on top
                    coll_astig45_um Z(2,-2) (0; ±0.4 µm)         of the default collimator
slit_width          slit_image_width_um (27; 15…45 µm)           slit image width ≠ 27 µm
                                                                 (29 µm grating HK scaled alike)
plating_gradient    plating_grad_x, plating_grad_y (0; ±0.1)     NiP thickness varies linearly
                    relative change of the deformation           across the blank: deformation
                    amplitude at x or y = +70 mm                 x (1 + gx x/70 + gy y/70)
                    (companion, below)
blank_bow           bow_defocus_um Z(2,0), bow_spherical_um      rotationally symmetric figure
                    Z(4,0) (0; ±0.2 µm), RMS-normalised over     change of the cold blank
                    a 70 mm radius disc in blank coordinates,    (front/back plating or polish
                    at the simulation's cold_K, scaled with the  imbalance bends it like a
                    deformation (companion, below)               bimetal; mount)
quilt_shape         quilt_fund_xy_ratio (1; 0.3…3; maps and      the quilt's harmonic content
                    PSF images only), quilt_harmonics_ratio,     differs from the FEA's
                    quilt_cross_ratio (1; -1…3; both 0 = pure    (:mod:`.quilt`, below;
                    sinusoid), quilt_figure_ratio (1; -1…3)      background companion)
==================  ===========================================  ============================

``quilt_shape`` changes the nominal map ``S`` into
``S + (rho - 1) F_y + (h - 1) H + (c - 1) C + (g - 1) R`` with ``F_x``, ``F_y`` the quilt's
fundamentals (21 mm along x, 18 mm along y), ``C`` its (1, ±1) egg-crate cross terms, ``H``
its other harmonics, from a Fourier fit of the nominal over the 82 x 72 mm centre
(:mod:`.quilt`), and ``R = S - F_x - F_y - H - C`` the smooth figure the fit leaves;
``rho = quilt_fund_xy_ratio``, ``h = quilt_harmonics_ratio``, ``c = quilt_cross_ratio``,
``g = quilt_figure_ratio``. The
fundamentals' amplitude is not a parameter of it: separate scales of ``F_x``, ``F_y`` and
``H`` would be degenerate with ``amplitude_scale`` on line profiles (measured, FEA map
200 µm / 75 % at 80 K, J 1.25 µm at 250/100/25 mas jointly: correlation -0.999 between
the scale of ``F_x`` and ``amplitude_scale``, -0.96 between ``H``'s scale and it, and a
scale of ``F_y`` has no leverage at all — a phase periodic along the rulings scatters
light along the slit, which a profile integrates). Held relative to the fundamentals,
``h`` and ``amplitude_scale`` correlate at 0.50 on those profiles and 0.21 on a 137 mm
map, so the amplitude of the quilt stays ``amplitude_scale``'s (or ``temperature``'s)
and ``quilt_shape`` says how its shape differs. ``rho`` scales ``F_y`` with ``F_x`` held;
it is only fitted where a map or a PSF image is in the data (``Parameter.kinds``).

``companion`` effects (``plating_gradient``, ``blank_bow``) are candidates on their own *and* are refitted
jointly with the best-ranked other candidates (:class:`~pipeline.diagnosis.criteria.Criteria`
``companion_top``); the joint fit replaces a finding only where the data support it
(BIC lower by ``companion_bic``). The finding keeps its own name and lists the companion in
``Finding.companions``. Reason: a plating-thickness gradient is present at some level on
every real blank (the scenarios' truths, and the campaign's with ``discrepancy="companions"``,
carry a random ±1.5–3 % one), so it is a
nuisance-like discrepancy that biases the other effects' parameters (collimator defocus,
the sign of pupil_y) unless it is fitted alongside them; it is not a nuisance of the
forward model (piston/tilt, offset shift, flux, background), because those are removed
from every fit including the nominal, while the gradient must be *tested* (it is a
physical claim about the blank and costs parameters in the BIC). A ``blank_bow`` is the same kind of discrepancy: the FEA
predicts the quilting and the edge roll-off of a symmetric plating well, but a small
front/back imbalance of the plating thickness or of the polished-off fraction bends the
blank like a bimetal strip, adding power and spherical aberration that the nominal
model does not have (measured in the campaign: a bow of 0.01 µm RMS biased the
temperature fitted on one 128 K map by 8–13 K, and collimator defocus on line profiles
by up to 0.09 µm). On line profiles alone the bow is degenerate with collimator defocus
(both curve the wavefront along the dispersion; measured: with the bow free, the
defocus error of a campaign case grew from 0.01 to 0.35 µm), so it is only tried where
a surface map is in the data (``requires``), which pins it down (on profiles alone the
finding that takes it up lists it in ``degenerate_with`` and reports how much of it its
parameters contain, ``Finding.absorbs``); it then acts on every
measurement (one bow for all blanks: a per-blank bow would need one map per blank).

``quilt_shape`` is a ``background`` companion: a real grating's quilt never has exactly the
FEA's shape (the paper's best J-band simulation is wider, with a shallower central dip,
than the measurement), so the shape is refitted beside every finding, as the plating
gradient and the bow are, and a finding is named for what it explains *beyond* the quilt's
shape. It is never half of a pair (``X + quilt_shape`` is the finding ``X`` fitted with
it). Its free ratios act on every periodic feature of a map and on the wings of every
line, so it takes up part of almost any gap (measured on independent truths: periodic
surface ripples and stray-light halos): read a ``quilt_shape`` verdict together with
``Diagnosis.unexplained_in`` and the finding's ``remaining_gap``.
Where several companions each lower the score, a larger set is adopted only if it beats
the best smaller one by ``companion_bic`` (each companion adopted must be supported).

``floor`` is the absolute tolerance used when judging parameter recovery
(relative error is ``|fit - true| / max(|true|, floor)``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

from optics.pupil import DEFAULT_COLLIMATOR_ZERNIKE_UM

from . import effect_draws

__all__ = ["Parameter", "Effect", "LIBRARY", "PLATING_GRADIENT_REF_MM", "BOW_REF_RADIUS_MM", "COLLIMATOR_PUPIL_RADIUS_MM",
           "draw_campaign_truth", "effect_parameters", "parameter_spec", "parameter_units", "applicable_effects", "NOMINAL_SLIT_UM",
           "SummaryContext", "physical_summary", "library_rows", "library_markdown"]

NOMINAL_SLIT_UM = 27.0


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
        Also refitted jointly with the best other candidates (module docstring).
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
        every finding and never half of a pair (module docstring).
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
        :class:`SummaryContext` (:func:`physical_summary`); None: none.
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

    def __post_init__(self) -> None:
        if self.truth_stage not in ("blank", "map"):
            raise ValueError(f"Effect {self.name!r}: truth_stage={self.truth_stage!r} must be 'blank' or 'map'")


@dataclass(frozen=True)
class SummaryContext:
    """What the physical summaries of a finding need from the data and the simulation:
    the simulation's cold temperature (K), the blanks seen, the surface maps' aperture
    radii (mm, where the astigmatism is normalised), the nominal quilt's RMS
    amplitudes (µm, :meth:`.quilt.QuiltComponents.amplitudes_um`; None: no quilt fit),
    its parts' shares of the nominal's projection (:func:`.quilt.projection_weights`;
    None: no quilt fit), and the warm temperature (K) and (substrate, film) that set the
    thermal factor."""

    cold_K: float
    blanks: tuple = ()
    surface_radii_mm: tuple = ()
    quilt_rms_um: dict | None = None
    quilt_weights: dict | None = None
    warm_K: float = 293.0
    materials: tuple = ("Al6061-T6", "NiP")


def _norm(p: dict, names) -> float:
    return math.sqrt(sum(p.get(n, 0.0) ** 2 for n in names))


def _disc(radii) -> str:
    r = sorted(set(round(float(v), 2) for v in radii))
    return "disc r=" + "/".join(f"{v:g}" for v in r) + " mm (map aperture)" if r else "map aperture disc"


def _summary_temperature(p, ctx):
    dT = p["temperature_offset_K"]
    return {"temperature_K": ctx.cold_K + dT, "temperature_offset_K": dT,
            "temperature_note": "simulation cold_K + offset; each map's own stated temperature + offset"}


def _summary_scale(p, ctx):
    scales = {k: v for k, v in p.items() if k.startswith("scale_")}
    return {"scale": next(iter(scales.values()))} if len(scales) == 1 else {}


def _summary_quilt(p, ctx):
    out = {"quilt_fund_xy_ratio": p.get("quilt_fund_xy_ratio", 1.0), "quilt_harmonics_ratio": p["quilt_harmonics_ratio"],
           "quilt_cross_ratio": p.get("quilt_cross_ratio", 1.0), "quilt_figure_ratio": p.get("quilt_figure_ratio", 1.0)}
    if ctx.quilt_rms_um:
        q = ctx.quilt_rms_um
        out.update({"fundamental_x_rms_um": q["fundamental_x"],
                    "fundamental_y_rms_um": q["fundamental_y"] * p.get("quilt_fund_xy_ratio", 1.0),
                    "harmonics_rms_um": q["harmonics"] * abs(p["quilt_harmonics_ratio"]),
                    "cross_rms_um": q["cross"] * abs(p.get("quilt_cross_ratio", 1.0)),
                    "quilt_note": f"RMS over a period at the simulation's {ctx.cold_K:g} K, before amplitude_scale "
                                  "and temperature; fitted over the 82 x 72 mm centre"})
    return out


def _summary_astigmatism(p, ctx):
    return {"rms_um": _norm(p, ("astig_0_um", "astig_45_um")), "aperture": _disc(ctx.surface_radii_mm),
            "surface": "grating surface"}


def _summary_registration(p, ctx):
    return {"shift_mm": _norm(p, ("reg_dx_mm", "reg_dy_mm")), "rotation_deg": p["reg_rot_deg"]}


def _summary_pupil(p, ctx):
    return {"shift_mm": _norm(p, ("pupil_x_mm", "pupil_y_mm"))}


def _summary_collimator(p, ctx):
    return {"rms_um": _norm(p, ("coll_coma_um", "coll_defocus_um", "coll_astig45_um")),
            "aperture": f"disc r={COLLIMATOR_PUPIL_RADIUS_MM:g} mm (collimator pupil)", "surface": "wavefront"}


def _summary_slit(p, ctx):
    return {"slit_image_width_um": p["slit_image_width_um"]}


def _summary_plating(p, ctx):
    return {"max_relative_change": _norm(p, ("plating_grad_x", "plating_grad_y")), "at_radius_mm": PLATING_GRADIENT_REF_MM}


def _summary_bow(p, ctx):
    return {"rms_um": _norm(p, ("bow_defocus_um", "bow_spherical_um")),
            "aperture": f"disc r={BOW_REF_RADIUS_MM:g} mm (blank coordinates)",
            "surface": "grating surface at the simulation's cold_K"}


_MAP_AND_IMAGE = ("surface", "psf_image")

LIBRARY: dict[str, Effect] = {e.name: e for e in (
    Effect("astigmatism", ("surface",),
           (Parameter("astig_0_um", 0.0, -1.0, 1.0, floor=0.02, unit="µm",
                      meaning="surface Zernike Z(2,2), RMS-normalised over the map's aperture disc"),
            Parameter("astig_45_um", 0.0, -1.0, 1.0, floor=0.02, unit="µm",
                      meaning="surface Zernike Z(2,-2), RMS-normalised over the map's aperture disc")),
           description="mount-induced surface astigmatism (Zernike (2,2) and (2,-2), RMS-normalised over the aperture)",
           vector=True, draw_truth=effect_draws.astigmatism, truth_stage="map", summary=_summary_astigmatism),
    Effect("amplitude_scale", ("surface", "line_profile", "psf_image"),
           (Parameter("scale", 1.0, 0.3, 3.0, floor=0.05, unit="1",
                      meaning="deformation amplitude of blank <blank> relative to the simulation's"),), per_blank=True,
           description="deformation amplitude differs (NiP thickness or polish; e.g. a re-polished blank)",
           rescales=True, draw_truth=effect_draws.amplitude_scale, summary=_summary_scale),
    Effect("temperature", ("surface", "line_profile", "psf_image"),
           (Parameter("temperature_offset_K", 0.0, -60.0, 80.0, floor=5.0, unit="K",
                      meaning="true cold temperature minus the stated one (all measurements)"),),
           description="true cold temperature = stated + offset (exact rescaling by the mismatch strain)",
           rescales=True, draw_truth=effect_draws.temperature, summary=_summary_temperature),
    Effect("registration", ("surface",),
           (Parameter("reg_dx_mm", 0.0, -10.0, 10.0, (-6.0, 0.0, 6.0), floor=0.5, unit="mm",
                      meaning="map shift d along x"),
            Parameter("reg_dy_mm", 0.0, -10.0, 10.0, (-5.0, 0.0, 5.0), floor=0.5, unit="mm",
                      meaning="map shift d along y"),
            Parameter("reg_rot_deg", 0.0, -5.0, 5.0, floor=0.3, unit="deg",
                      meaning="map rotation R against the model about the map origin (feature at p appears at R p + d)")),
           description="measured map shifted/rotated against the model (model feature at p appears at R p + d)",
           draw_truth=effect_draws.registration, truth_stage="map", summary=_summary_registration),
    Effect("pupil_shift", ("line_profile", "psf_image"),
           (Parameter("pupil_x_mm", 0.0, -10.0, 10.0, (-7.0, -3.5, 0.0, 3.5, 7.0), floor=1.0, unit="mm",
                      meaning="beam footprint offset on the grating along x (dispersion)"),
            Parameter("pupil_y_mm", 0.0, -10.0, 10.0, (0.0, 4.5), floor=3.0, unit="mm",
                      meaning="beam footprint offset on the grating along y (rulings)")),
           description="beam footprint offset on the grating (x dispersion, y ruling), common to all profiles",
           vector=True, draw_truth=effect_draws.pupil_shift, summary=_summary_pupil),
    Effect("collimator_wfe", ("line_profile", "psf_image"),
           (Parameter("coll_coma_um", 0.0, -0.4, 0.4, floor=0.04, unit="µm",
                      meaning="extra wavefront Zernike Z(3,1), RMS-normalised over the 110 mm pupil"),
            Parameter("coll_defocus_um", 0.0, -0.4, 0.4, floor=0.04, unit="µm",
                      meaning="extra wavefront Zernike Z(2,0), RMS-normalised over the 110 mm pupil"),
            # the sign line profiles cannot tell is that of the total Z(2,-2), default included
            Parameter("coll_astig45_um", 0.0, -0.4, 0.4, floor=0.06, unit="µm",
                      meaning="extra wavefront Zernike Z(2,-2), RMS-normalised over the 110 mm pupil",
                      sign_origin=-DEFAULT_COLLIMATOR_ZERNIKE_UM[(2, -2)])),
           description="extra low-order spectrograph WFE (RMS-normalised Zernike over the 110 mm pupil)",
           vector=True, draw_truth=effect_draws.collimator_wfe, summary=_summary_collimator),
    Effect("slit_width", ("line_profile",),
           (Parameter("slit_image_width_um", NOMINAL_SLIT_UM, 15.0, 45.0, floor=1.0, unit="µm",
                      meaning="geometric slit image width on the detector (J, H, K; HK scaled alike from 29 µm)"),),
           description="geometric slit image width differs from 27 µm (29 µm for HK, scaled alike)",
           draw_truth=effect_draws.slit_width, summary=_summary_slit),
    Effect("plating_gradient", ("surface", "line_profile", "psf_image"),
           (Parameter("plating_grad_x", 0.0, -0.1, 0.1, floor=0.01, unit="1",
                      meaning="relative deformation change at x = +70 mm (blank coordinates)"),
            Parameter("plating_grad_y", 0.0, -0.1, 0.1, floor=0.01, unit="1",
                      meaning="relative deformation change at y = +70 mm (blank coordinates)")),
           description="NiP thickness gradient across the blank: deformation x (1 + gx x/70 mm + gy y/70 mm) "
                       "(blank coordinates; gx, gy = relative amplitude change at the blank's half-width)",
           vector=True, companion=True, summary=_summary_plating),
    Effect("blank_bow", ("surface", "line_profile", "psf_image"),
           (Parameter("bow_defocus_um", 0.0, -0.2, 0.2, floor=0.01, unit="µm",
                      meaning="surface Zernike Z(2,0), RMS-normalised over a 70 mm radius disc, at cold_K"),
            Parameter("bow_spherical_um", 0.0, -0.2, 0.2, floor=0.01, unit="µm",
                      meaning="surface Zernike Z(4,0), RMS-normalised over a 70 mm radius disc, at cold_K")),
           description="rotationally symmetric figure change of the cold blank: Zernike (2,0) and (4,0), "
                       "RMS-normalised over a 70 mm radius disc in blank coordinates, at the simulation's cold_K "
                       "(scaled with the deformation)",
           vector=True, companion=True, requires=("surface",), summary=_summary_bow),
    Effect("quilt_shape", ("surface", "line_profile", "psf_image"),
           (Parameter("quilt_fund_xy_ratio", 1.0, 0.3, 3.0, (0.6, 1.0, 1.6), floor=0.05, unit="1",
                      meaning="y fundamental (18 mm) relative to the x fundamental (21 mm), over the nominal's "
                              "ratio (x fundamental held)", kinds=_MAP_AND_IMAGE),
            Parameter("quilt_harmonics_ratio", 1.0, -1.0, 3.0, (0.0, 1.0, 2.0), floor=0.2, unit="1",
                      meaning="quilt harmonics other than the (1, ±1) cross terms relative to the fundamentals, "
                              "over the nominal's ratio (0: none)"),
            Parameter("quilt_cross_ratio", 1.0, -1.0, 3.0, floor=0.2, unit="1",
                      meaning="the quilt's (1, ±1) egg-crate cross terms relative to the fundamentals, over the "
                              "nominal's ratio (0: a sum-form quilt)"),
            Parameter("quilt_figure_ratio", 1.0, -1.0, 3.0, floor=0.2, unit="1",
                      meaning="the smooth figure that is not quilt (edge roll-off, bending) relative to the "
                              "fundamentals, over the nominal's ratio")),
           description="the quilt's harmonic content differs from the simulation's: the y fundamental relative "
                       "to the x fundamental and the higher harmonics relative to both (the fundamentals' "
                       "amplitude stays amplitude_scale's)",
           companion=True, background=True, draw_truth=effect_draws.quilt_shape, summary=_summary_quilt),
)}

#: Half-width (mm) at which ``plating_grad_x/y`` are the relative amplitude change.
PLATING_GRADIENT_REF_MM = 70.0
#: Radius (mm, blank coordinates) of the disc over which the ``blank_bow`` Zernike terms
#: are RMS-normalised: half the blank's 140 mm height, independent of any measurement.
BOW_REF_RADIUS_MM = 70.0
#: Radius (mm) of the collimator pupil over which ``collimator_wfe`` terms are RMS-normalised.
COLLIMATOR_PUPIL_RADIUS_MM = 55.0


def draw_campaign_truth(effect: str, kind: str, rng, blank: str) -> dict:
    """The campaign's random truth of library ``effect`` for a case of measurement ``kind``
    on grating blank ``blank`` (``Effect.draw_truth``)."""
    if effect not in LIBRARY:
        raise ValueError(f"draw_campaign_truth: effect={effect!r} is not in the library; valid: {sorted(LIBRARY)}")
    e = LIBRARY[effect]
    if e.draw_truth is None:
        raise ValueError(f"draw_campaign_truth: effect={effect!r} has no campaign truth draw (Effect.draw_truth); "
                         f"valid: {sorted(n for n, x in LIBRARY.items() if x.draw_truth is not None)}")
    return e.draw_truth(rng, kind, blank)


def effect_parameters(effect: Effect, blanks: tuple[str, ...], kinds=None) -> tuple[Parameter, ...]:
    """The concrete parameters of ``effect`` for data seeing ``blanks``; with ``kinds`` (the
    measurement kinds in the data), only the parameters that change one of them."""
    params = effect.parameters
    if kinds is not None:
        params = tuple(p for p in params if set(p.kinds or effect.kinds) & set(kinds))
    if not effect.per_blank:
        return params
    from dataclasses import replace

    return tuple(replace(p, name=f"{p.name}_{b}") for p in params for b in blanks)


def parameter_spec(name: str) -> Parameter:
    """The library parameter called ``name`` (a per-blank copy ``scale_<blank>`` resolves to
    its template ``scale``)."""
    for e in LIBRARY.values():
        for p in e.parameters:
            if name == p.name or (e.per_blank and name.startswith(p.name + "_")):
                return p
    raise ValueError(f"parameter {name!r} is not in the effect library; valid: "
                     f"{[p.name for e in LIBRARY.values() for p in e.parameters]}")


def parameter_units(names) -> dict:
    """``{parameter name: unit}`` for library parameter names (per-blank copies included)."""
    return {n: parameter_spec(n).unit for n in names}


def applicable_effects(kinds: set[str], names: tuple[str, ...] | None = None) -> tuple[Effect, ...]:
    """Library effects that change at least one of the measurement ``kinds`` present."""
    unknown = set(names or ()) - set(LIBRARY)
    if unknown:
        raise ValueError(f"effects {sorted(unknown)} are unknown; valid: {sorted(LIBRARY)}")
    chosen = LIBRARY if names is None else {n: LIBRARY[n] for n in names}
    return tuple(e for e in chosen.values() if set(e.kinds) & kinds and set(e.requires) <= kinds)


def physical_summary(effects, parameters: dict, ctx: SummaryContext) -> dict:
    """Physically absolute summaries of a finding, per effect: ``{effect: {...}}`` (e.g.
    ``temperature_K`` beside the offset, ``scale`` where one blank is measured,
    ``rms_um`` of a Zernike-type effect with the ``aperture`` it refers to)."""
    out = {}
    for e in effects:
        own = {q.name: parameters[q.name] for q in effect_parameters(LIBRARY[e], ctx.blanks) if q.name in parameters}
        if own and LIBRARY[e].summary is not None:
            out[e] = LIBRARY[e].summary(own, ctx)
    if ctx.quilt_weights and "quilt_shape" in out:
        _add_projection(out, parameters, ctx)
    return out


def _add_projection(out: dict, parameters: dict, ctx: SummaryContext) -> None:
    """The amplitude in the other convention (``docs/diagnosis.md``, "Two meanings of the
    amplitude"): beside ``quilt_shape`` a fitted ``scale_<blank>`` or
    ``temperature_offset_K`` is the x fundamental's amplitude; times
    :func:`.quilt.projection_factor` it is the reshaped deformation's least-squares
    projection on the nominal over the centre."""
    from .quilt import projection_factor

    k = projection_factor(ctx.quilt_weights, parameters)
    q = out["quilt_shape"]
    q["projection_factor"] = k
    if "quilt_fund_xy_ratio" not in parameters:
        q["projection_note"] = ("y fundamental not measured (line profiles integrate along it): held at the "
                                f"nominal's ratio, whose share of the projection is {ctx.quilt_weights['fundamental_y']:.2f}")
    for name, v in parameters.items():
        if name.startswith("scale_") and "amplitude_scale" in out:
            out["amplitude_scale"][f"{name}_projection"] = v * k
    if "temperature_offset_K" in parameters and "temperature" in out:
        out["temperature"]["temperature_offset_K_projection"] = _offset_for_factor(
            parameters["temperature_offset_K"], k, ctx)


def _offset_for_factor(offset_K: float, k: float, ctx: SummaryContext) -> float:
    """The cold-temperature offset whose thermal factor at ``ctx.cold_K`` is ``k`` times that
    of ``offset_K`` (NaN where no temperature within both materials' data range, below the
    warm one, gives it)."""
    from scipy.optimize import brentq

    from fea.materials import get_material

    from .nominal import thermal_factor

    def f(dT):
        return thermal_factor(ctx.cold_K + dT, ctx.cold_K, ctx.warm_K, *ctx.materials)

    target = k * f(offset_K)
    coldest = max(get_material(m).valid_range_K[0] for m in ctx.materials)
    lo, hi = coldest - ctx.cold_K, ctx.warm_K - ctx.cold_K - 1e-6
    g = lambda dT: f(dT) - target  # noqa: E731
    if not g(lo) * g(hi) < 0:
        return float("nan")
    return float(brentq(g, lo, hi, xtol=1e-6))


def _prior_text(p: Parameter) -> str:
    return f"{p.lo:g} … {p.hi:g}"


def library_rows() -> list[dict]:
    """One row per library parameter: effect, parameter, unit, null, prior, measurement
    kinds and meaning (the README's parameter table and the report's are made from it)."""
    return [{"effect": e.name, "parameter": p.name + ("_<blank>" if e.per_blank else ""), "unit": p.unit,
             "null": p.null, "prior": _prior_text(p), "kinds": ", ".join(p.kinds or e.kinds), "meaning": p.meaning}
            for e in LIBRARY.values() for p in e.parameters]


def library_markdown() -> str:
    """The parameter table as Markdown. The README's diagnosis section holds this text
    (checked by a test); regenerate it with
    ``python -c "from pipeline.diagnosis.effects import library_markdown as m; print(m(), end='')"``."""
    out = ["| effect | parameter | unit | null | prior | measurements | meaning |", "|---|---|---|---|---|---|---|"]
    out += [f"| {r['effect']} | `{r['parameter']}` | {r['unit']} | {r['null']:g} | {r['prior']} | {r['kinds']} | "
            f"{r['meaning']} |" for r in library_rows()]
    return "\n".join(out) + "\n"
