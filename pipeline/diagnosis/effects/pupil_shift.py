"""``pupil_shift``: the beam footprint offset on the grating, seen by line profiles and images."""

from __future__ import annotations

from dataclasses import replace

from .. import effect_draws
from .base import Effect, Parameter, SpectrographOptics, SummaryContext, vector_norm

__all__ = ["PUPIL_SHIFT"]


def _optics(o: SpectrographOptics, p: dict) -> SpectrographOptics:
    x, y = o.pupil_shift_mm
    return replace(o, pupil_shift_mm=(x + p.get("pupil_x_mm", 0.0), y + p.get("pupil_y_mm", 0.0)))


def _summary(p: dict, ctx: SummaryContext) -> dict:
    return {"shift_mm": vector_norm(p, ("pupil_x_mm", "pupil_y_mm"))}


PUPIL_SHIFT = Effect(
    "pupil_shift", ("line_profile", "psf_image"),
    (Parameter("pupil_x_mm", 0.0, -10.0, 10.0, (-7.0, -3.5, 0.0, 3.5, 7.0), floor=1.0, unit="mm",
               meaning="beam footprint offset on the grating along x (dispersion)"),
     Parameter("pupil_y_mm", 0.0, -10.0, 10.0, (0.0, 4.5), floor=3.0, unit="mm",
               meaning="beam footprint offset on the grating along y (rulings)")),
    description="beam footprint offset on the grating (x dispersion, y ruling), common to all profiles",
    vector=True, draw_truth=effect_draws.pupil_shift, summary=_summary, optics=_optics)
