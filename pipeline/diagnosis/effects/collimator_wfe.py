"""``collimator_wfe``: extra low-order spectrograph wavefront error on top of the default
collimator's."""

from __future__ import annotations

from optics.pupil import DEFAULT_COLLIMATOR_ZERNIKE_UM

from .. import effect_draws
from .base import Effect, Parameter, SummaryContext, vector_norm

__all__ = ["COLLIMATOR_WFE", "COLLIMATOR_PUPIL_RADIUS_MM"]

#: Radius (mm) of the collimator pupil over which ``collimator_wfe`` terms are RMS-normalised.
COLLIMATOR_PUPIL_RADIUS_MM = 55.0


def _summary(p: dict, ctx: SummaryContext) -> dict:
    return {"rms_um": vector_norm(p, ("coll_coma_um", "coll_defocus_um", "coll_astig45_um")),
            "aperture": f"disc r={COLLIMATOR_PUPIL_RADIUS_MM:g} mm (collimator pupil)", "surface": "wavefront"}


COLLIMATOR_WFE = Effect(
    "collimator_wfe", ("line_profile", "psf_image"),
    (Parameter("coll_coma_um", 0.0, -0.4, 0.4, floor=0.04, unit="µm",
               meaning="extra wavefront Zernike Z(3,1), RMS-normalised over the 110 mm pupil"),
     Parameter("coll_defocus_um", 0.0, -0.4, 0.4, floor=0.04, unit="µm",
               meaning="extra wavefront Zernike Z(2,0), RMS-normalised over the 110 mm pupil"),
     # the sign line profiles cannot tell is that of the total Z(2,-2), default included
     Parameter("coll_astig45_um", 0.0, -0.4, 0.4, floor=0.06, unit="µm",
               meaning="extra wavefront Zernike Z(2,-2), RMS-normalised over the 110 mm pupil",
               sign_origin=-DEFAULT_COLLIMATOR_ZERNIKE_UM[(2, -2)])),
    description="extra low-order spectrograph WFE (RMS-normalised Zernike over the 110 mm pupil)",
    vector=True, draw_truth=effect_draws.collimator_wfe, summary=_summary,
    pupil_zernike=(("coll_coma_um", (3, 1)), ("coll_defocus_um", (2, 0)), ("coll_astig45_um", (2, -2))))
