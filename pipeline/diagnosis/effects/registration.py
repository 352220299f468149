"""``registration``: a measured map shifted and rotated against the model."""

from __future__ import annotations

import math

from .. import effect_draws
from .base import Effect, Parameter, SummaryContext, vector_norm

__all__ = ["REGISTRATION"]


def _coordinates(x_mm, y_mm, p: dict):
    """Blank coordinates ``q = R^-1 (x - d)`` of measured points ``x`` (None: not moved)."""
    dx, dy, rot = p.get("reg_dx_mm", 0.0), p.get("reg_dy_mm", 0.0), p.get("reg_rot_deg", 0.0)
    if not (dx or dy or rot):
        return None
    c, s = math.cos(math.radians(rot)), math.sin(math.radians(rot))
    xr, yr = x_mm - dx, y_mm - dy
    return c * xr + s * yr, -s * xr + c * yr


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
    draw_truth=effect_draws.registration, truth_stage="map", summary=_summary, coordinates=_coordinates)
