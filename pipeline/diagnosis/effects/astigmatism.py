"""``astigmatism``: mount-induced surface astigmatism of the grating, seen on maps."""

from __future__ import annotations

from .. import effect_draws
from .base import Effect, Parameter, SummaryContext, vector_norm

__all__ = ["ASTIGMATISM"]


def _disc(radii) -> str:
    r = sorted(set(round(float(v), 2) for v in radii))
    if not r:
        return "disc of aperture_diameter_mm"
    return "disc r=" + "/".join(f"{v:g}" for v in r) + " mm (the measurement's aperture_diameter_mm)"


def _summary(p: dict, ctx: SummaryContext) -> dict:
    return {"rms_um": vector_norm(p, ("astig_0_um", "astig_45_um")), "aperture": _disc(ctx.surface_radii_mm),
            "surface": "grating surface"}


ASTIGMATISM = Effect(
    "astigmatism", ("surface",),
    (Parameter("astig_0_um", 0.0, -1.0, 1.0, floor=0.02, unit="µm",
               meaning="surface Zernike Z(2,2), RMS-normalised over the disc of the measurement's "
                       "aperture_diameter_mm (not the valid data's extent)"),
     Parameter("astig_45_um", 0.0, -1.0, 1.0, floor=0.02, unit="µm",
               meaning="surface Zernike Z(2,-2), RMS-normalised over the disc of the measurement's "
                       "aperture_diameter_mm (not the valid data's extent)")),
    description="mount-induced surface astigmatism (Zernike (2,2) and (2,-2), RMS-normalised over the aperture)",
    vector=True, draw_truth=effect_draws.astigmatism, truth_stage="map", summary=_summary,
    map_zernike=(("astig_0_um", (2, 2)), ("astig_45_um", (2, -2))))
