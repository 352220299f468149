"""The two rescalings of the nominal deformation: ``amplitude_scale`` (one factor per
blank) and ``temperature`` (the cold temperature's offset). Both act only through the
deformation's overall factor (``Effect.rescales``), so each also gives its amplitude in
the projection convention beside ``quilt_shape`` (``Effect.projection``)."""

from __future__ import annotations

from .. import effect_draws
from .base import Effect, Parameter, SummaryContext

__all__ = ["AMPLITUDE_SCALE", "TEMPERATURE", "offset_for_factor"]


def _scale(p: dict, blank: str) -> float:
    return p.get(f"scale_{blank}", 1.0)


def _true_temperature(temperature_K: float, p: dict) -> float:
    return temperature_K + p.get("temperature_offset_K", 0.0)


def _summary_scale(p: dict, ctx: SummaryContext) -> dict:
    scales = {k: v for k, v in p.items() if k.startswith("scale_")}
    return {"scale": next(iter(scales.values()))} if len(scales) == 1 else {}


def _projection_scale(parameters: dict, k: float, ctx: SummaryContext) -> dict:
    # a per-blank scale is the x fundamental's amplitude; times k, the reshaped
    # deformation's projection on the nominal
    return {f"{name}_projection": v * k for name, v in parameters.items() if name.startswith("scale_")}


def _summary_temperature(p: dict, ctx: SummaryContext) -> dict:
    dT = p["temperature_offset_K"]
    return {"temperature_K": ctx.cold_K + dT, "temperature_offset_K": dT,
            "temperature_note": "simulation cold_K + offset; each map's own stated temperature + offset"}


def _projection_temperature(parameters: dict, k: float, ctx: SummaryContext) -> dict:
    if "temperature_offset_K" not in parameters:
        return {}
    return {"temperature_offset_K_projection": offset_for_factor(parameters["temperature_offset_K"], k, ctx)}


def offset_for_factor(offset_K: float, k: float, ctx: SummaryContext) -> float:
    """The cold-temperature offset whose thermal factor at ``ctx.cold_K`` is ``k`` times that
    of ``offset_K`` (NaN where no temperature within both materials' data range, below the
    warm one, gives it)."""
    from scipy.optimize import brentq

    from fea.materials import get_material

    from ..nominal import thermal_factor

    def f(dT):
        return thermal_factor(ctx.cold_K + dT, ctx.cold_K, ctx.warm_K, *ctx.materials)

    target = k * f(offset_K)
    coldest = max(get_material(m).valid_range_K[0] for m in ctx.materials)
    lo, hi = coldest - ctx.cold_K, ctx.warm_K - ctx.cold_K - 1e-6
    g = lambda dT: f(dT) - target  # noqa: E731
    if not g(lo) * g(hi) < 0:
        return float("nan")
    return float(brentq(g, lo, hi, xtol=1e-6))


AMPLITUDE_SCALE = Effect(
    "amplitude_scale", ("surface", "line_profile", "psf_image"),
    (Parameter("scale", 1.0, 0.3, 3.0, floor=0.05, unit="1",
               meaning="deformation amplitude of blank <blank> relative to the simulation's"),), per_blank=True,
    description="deformation amplitude differs (NiP thickness or polish; e.g. a re-polished blank)",
    rescales=True, draw_truth=effect_draws.amplitude_scale, summary=_summary_scale, projection=_projection_scale,
    scale=_scale)

TEMPERATURE = Effect(
    "temperature", ("surface", "line_profile", "psf_image"),
    (Parameter("temperature_offset_K", 0.0, -60.0, 80.0, floor=5.0, unit="K",
               meaning="true cold temperature minus the stated one (all measurements)"),),
    description="true cold temperature = stated + offset (exact rescaling by the mismatch strain)",
    rescales=True, draw_truth=effect_draws.temperature, summary=_summary_temperature,
    projection=_projection_temperature, temperature=_true_temperature)
