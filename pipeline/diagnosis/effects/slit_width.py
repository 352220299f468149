"""``slit_width``: the geometric slit image width on the detector, seen by line profiles.

The spectrograph has one slit (the image slicer's), shared by every grating; a grating
only sets the anamorphic magnification that images it on the detector, so the nominal
slit image is 27 µm wide for the J, H and K gratings and 29 µm for the H+K grating
(:data:`optics.grating.GRATINGS`). A slit wider or narrower than designed therefore
changes every grating's slit image by the same factor, and a manifest may hold line
profiles of several gratings: the effect is one parameter for all of them, the slit image
width of the 27 µm gratings, ``slit_image_width_um``, which sets the factor
``slit_image_width_um / 27``. Its physical summary gives, per grating measured, that
grating's own slit image width (``slit_image_width_<grating>_um``, e.g. 29 µm for H+K at
the null), and the factor.
"""

from __future__ import annotations

from dataclasses import replace

from .. import effect_draws
from .base import Effect, Parameter, SpectrographOptics, SummaryContext

__all__ = ["SLIT_WIDTH", "NOMINAL_SLIT_UM", "grating_slit_image_width_um"]

#: The nominal geometric slit image width (µm) of the J, H and K gratings: the unit of the
#: shared ``slit_image_width_um`` (the H+K grating's own nominal is 29 µm).
NOMINAL_SLIT_UM = 27.0


def grating_slit_image_width_um(grating: str, slit_image_width_um: float) -> float:
    """The geometric slit image width (µm) on the detector of ``grating`` when the shared
    parameter ``slit_image_width_um`` (the J, H and K gratings' width, µm) has the given value.

    Parameters
    ----------
    grating : str
        Grating name (:data:`optics.grating.GRATINGS`).
    slit_image_width_um : float
        The shared parameter (µm), nominal :data:`NOMINAL_SLIT_UM`.

    Returns
    -------
    float
        The grating's own slit image width (µm), its nominal (27 or 29 µm) times
        ``slit_image_width_um / 27``.
    """
    from optics.grating import get_grating

    return get_grating(grating).slit_image_width_um * slit_image_width_um / NOMINAL_SLIT_UM


def _optics(o: SpectrographOptics, p: dict) -> SpectrographOptics:
    # one slit for every grating: the parameter sets the factor on each grating's own width
    w = p.get("slit_image_width_um", NOMINAL_SLIT_UM)
    if w == NOMINAL_SLIT_UM:
        return o
    g = o.grating
    return replace(o, grating=replace(g, slit_image_width_um=g.slit_image_width_um * w / NOMINAL_SLIT_UM))


def _summary(p: dict, ctx: SummaryContext) -> dict:
    w = p["slit_image_width_um"]
    out = {"slit_image_width_um": w, "slit_width_factor": w / NOMINAL_SLIT_UM}
    for g in ctx.gratings:
        out[f"slit_image_width_{g}_um"] = grating_slit_image_width_um(g, w)
    return out


SLIT_WIDTH = Effect(
    "slit_width", ("line_profile",),
    (Parameter("slit_image_width_um", NOMINAL_SLIT_UM, 15.0, 45.0, floor=1.0, unit="µm",
               meaning="geometric slit image width of the J, H and K gratings (one slit for every grating: the H+K "
                       "grating's is 29/27 of it; the summary gives each measured grating's own)"),),
    description="geometric slit image width differs from the nominal (27 µm J, H, K; 29 µm HK)",
    draw_truth=effect_draws.slit_width, summary=_summary, optics=_optics)
