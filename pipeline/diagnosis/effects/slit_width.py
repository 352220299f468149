"""``slit_width``: the geometric slit image width on the detector, seen by line profiles."""

from __future__ import annotations

from dataclasses import replace

from .. import effect_draws
from .base import Effect, Parameter, SpectrographOptics, SummaryContext

__all__ = ["SLIT_WIDTH", "NOMINAL_SLIT_UM"]

#: The nominal geometric slit image width (µm) of the J, H and K gratings (HK: 29 µm, scaled alike).
NOMINAL_SLIT_UM = 27.0


def _optics(o: SpectrographOptics, p: dict) -> SpectrographOptics:
    # the parameter is the 27 µm gratings' width; other gratings (HK: 29 µm) scale alike
    w = p.get("slit_image_width_um", NOMINAL_SLIT_UM)
    if w == NOMINAL_SLIT_UM:
        return o
    g = o.grating
    return replace(o, grating=replace(g, slit_image_width_um=g.slit_image_width_um * w / NOMINAL_SLIT_UM))


def _summary(p: dict, ctx: SummaryContext) -> dict:
    return {"slit_image_width_um": p["slit_image_width_um"]}


SLIT_WIDTH = Effect(
    "slit_width", ("line_profile",),
    (Parameter("slit_image_width_um", NOMINAL_SLIT_UM, 15.0, 45.0, floor=1.0, unit="µm",
               meaning="geometric slit image width on the detector (J, H, K; HK scaled alike from 29 µm)"),),
    description="geometric slit image width differs from 27 µm (29 µm for HK, scaled alike)",
    draw_truth=effect_draws.slit_width, summary=_summary, optics=_optics)
