"""``registration``: a measured map shifted and rotated against the model."""

from __future__ import annotations

from .. import effect_draws
from .base import Effect, Parameter, SummaryContext, vector_norm

__all__ = ["REGISTRATION"]


def _summary(p: dict, ctx: SummaryContext) -> dict:
    return {"shift_mm": vector_norm(p, ("reg_dx_mm", "reg_dy_mm")), "rotation_deg": p["reg_rot_deg"]}


REGISTRATION = Effect(
    "registration", ("surface",),
    (Parameter("reg_dx_mm", 0.0, -10.0, 10.0, (-6.0, 0.0, 6.0), floor=0.5, unit="mm",
               meaning="map shift d along x"),
     Parameter("reg_dy_mm", 0.0, -10.0, 10.0, (-5.0, 0.0, 5.0), floor=0.5, unit="mm",
               meaning="map shift d along y"),
     Parameter("reg_rot_deg", 0.0, -5.0, 5.0, floor=0.3, unit="deg",
               meaning="map rotation R against the model about the map origin (feature at p appears at R p + d)")),
    description="measured map shifted/rotated against the model (model feature at p appears at R p + d)",
    draw_truth=effect_draws.registration, truth_stage="map", summary=_summary)
