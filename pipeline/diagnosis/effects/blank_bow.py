"""``blank_bow``: a rotationally symmetric figure change of the cold blank (a companion
tried only where a map is in the data: :mod:`pipeline.diagnosis.effects`)."""

from __future__ import annotations

from .base import Effect, Parameter, SummaryContext, vector_norm

__all__ = ["BLANK_BOW", "BOW_REF_RADIUS_MM"]

#: Radius (mm, blank coordinates) of the disc over which the ``blank_bow`` Zernike terms
#: are RMS-normalised: half the blank's 140 mm height, independent of any measurement.
BOW_REF_RADIUS_MM = 70.0


def _summary(p: dict, ctx: SummaryContext) -> dict:
    return {"rms_um": vector_norm(p, ("bow_defocus_um", "bow_spherical_um")),
            "aperture": f"disc r={BOW_REF_RADIUS_MM:g} mm (blank coordinates)",
            "surface": "grating surface at the simulation's cold_K"}


BLANK_BOW = Effect(
    "blank_bow", ("surface", "line_profile", "psf_image"),
    (Parameter("bow_defocus_um", 0.0, -0.2, 0.2, floor=0.01, unit="µm",
               meaning="surface Zernike Z(2,0), RMS-normalised over a 70 mm radius disc, at cold_K"),
     Parameter("bow_spherical_um", 0.0, -0.2, 0.2, floor=0.01, unit="µm",
               meaning="surface Zernike Z(4,0), RMS-normalised over a 70 mm radius disc, at cold_K")),
    description="rotationally symmetric figure change of the cold blank: Zernike (2,0) and (4,0), "
                "RMS-normalised over a 70 mm radius disc in blank coordinates, at the simulation's cold_K "
                "(scaled with the deformation)",
    vector=True, companion=True, requires=("surface",), summary=_summary)
