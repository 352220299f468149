"""``plating_gradient``: a linear NiP thickness gradient across the blank (a companion:
:mod:`pipeline.diagnosis.effects`)."""

from __future__ import annotations

from .base import Effect, Parameter, SummaryContext, vector_norm

__all__ = ["PLATING_GRADIENT", "PLATING_GRADIENT_REF_MM"]

#: Half-width (mm) at which ``plating_grad_x/y`` are the relative amplitude change.
PLATING_GRADIENT_REF_MM = 70.0


def _shape(sag_um, x_mm, y_mm, p: dict, quilt):
    """``sag_um`` times ``1 + (gx x + gy y) / 70 mm``: the gradient scales the local deformation."""
    gx, gy = p.get("plating_grad_x", 0.0), p.get("plating_grad_y", 0.0)
    if not (gx or gy):
        return sag_um
    return sag_um * (1.0 + (gx * x_mm + gy * y_mm) / PLATING_GRADIENT_REF_MM)


def _summary(p: dict, ctx: SummaryContext) -> dict:
    return {"max_relative_change": vector_norm(p, ("plating_grad_x", "plating_grad_y")),
            "at_radius_mm": PLATING_GRADIENT_REF_MM}


PLATING_GRADIENT = Effect(
    "plating_gradient", ("surface", "line_profile", "psf_image"),
    (Parameter("plating_grad_x", 0.0, -0.1, 0.1, floor=0.01, unit="1",
               meaning="relative deformation change at x = +70 mm (blank coordinates)"),
     Parameter("plating_grad_y", 0.0, -0.1, 0.1, floor=0.01, unit="1",
               meaning="relative deformation change at y = +70 mm (blank coordinates)")),
    description="NiP thickness gradient across the blank: deformation x (1 + gx x/70 mm + gy y/70 mm) "
                "(blank coordinates; gx, gy = relative amplitude change at the blank's half-width)",
    vector=True, companion=True, summary=_summary, shape=_shape, shape_stage="multiply")
