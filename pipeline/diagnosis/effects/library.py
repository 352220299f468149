"""The effect library (:data:`LIBRARY`, in ranking order) and the questions asked of it:
an effect's concrete parameters, a parameter's spec and unit, the effects the data can
see, a finding's physical summary, the campaign's truth draw and the parameter table."""

from __future__ import annotations

from .astigmatism import ASTIGMATISM
from .base import Effect, Parameter, SummaryContext
from .blank_bow import BLANK_BOW
from .collimator_wfe import COLLIMATOR_WFE
from .instrument_wings import INSTRUMENT_WINGS
from .plating_gradient import PLATING_GRADIENT
from .pupil_other_orders import PUPIL_OTHER_ORDERS
from .pupil_shift import PUPIL_SHIFT
from .quilt_shape import QUILT_SHAPE, part_ratios
from .registration import REGISTRATION
from .rescaling import AMPLITUDE_SCALE, TEMPERATURE
from .slit_width import SLIT_WIDTH

__all__ = ["LIBRARY", "ALTERNATIVES", "forward_effects", "draw_campaign_truth", "effect_parameters", "parameter_spec", "parameter_units",
           "applicable_effects", "physical_summary", "library_rows", "library_markdown"]

#: Every effect by name. The order is the library's order everywhere (a pair's name, ties
#: in the ranking: ``list(LIBRARY).index``, the parameter table): append a new effect.
LIBRARY: dict[str, Effect] = {e.name: e for e in (
    ASTIGMATISM, AMPLITUDE_SCALE, TEMPERATURE, REGISTRATION, PUPIL_SHIFT, COLLIMATOR_WFE, SLIT_WIDTH,
    PLATING_GRADIENT, BLANK_BOW, QUILT_SHAPE)}

#: Effects that are not candidates (never ranked or reported as an explanation) but whose
#: parameters the forward models take: the diagnostic alternatives a check fits instead
#: of a library effect (:mod:`pipeline.diagnosis.pupil_orders`, :mod:`pipeline.diagnosis.wings`).
ALTERNATIVES: dict[str, Effect] = {e.name: e for e in (PUPIL_OTHER_ORDERS, INSTRUMENT_WINGS)}


def forward_effects() -> tuple[Effect, ...]:
    """Every effect whose hooks the forward models call: the library's, in its order, then
    the :data:`ALTERNATIVES`."""
    return (*LIBRARY.values(), *ALTERNATIVES.values())


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
    amplitude"): beside ``quilt_shape`` a fitted rescaling (``scale_<blank>``,
    ``temperature_offset_K``) is the x fundamental's amplitude; its ``Effect.projection``
    at :func:`pipeline.diagnosis.quilt.projection_factor` gives the reshaped deformation's
    least-squares projection on the nominal over the centre."""
    from ..quilt import projection_factor

    k = projection_factor(ctx.quilt_weights, part_ratios(parameters))
    q = out["quilt_shape"]
    q["projection_factor"] = k
    if "quilt_fund_xy_ratio" not in parameters:
        q["projection_note"] = ("y fundamental not measured (line profiles integrate along it): held at the "
                                f"nominal's ratio, whose share of the projection is {ctx.quilt_weights['fundamental_y']:.2f}")
    for name, e in LIBRARY.items():
        if e.projection is not None and name in out:
            out[name].update(e.projection(parameters, k, ctx))


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
