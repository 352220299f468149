"""``quilt_shape``: the quilt's harmonic content differs from the simulation's (a
background companion; the parts it rescales: :mod:`pipeline.diagnosis.quilt`; what its
ratios mean: :mod:`pipeline.diagnosis.effects`)."""

from __future__ import annotations

from .. import effect_draws
from .base import Effect, Parameter, SummaryContext

__all__ = ["QUILT_SHAPE", "PART_RATIOS", "part_ratios"]

#: The y fundamental runs along the rulings: only maps and PSF images see it.
_MAP_AND_IMAGE = ("surface", "psf_image")


#: The parts of the nominal's deformation (:mod:`pipeline.diagnosis.quilt`) and the ratio
#: that scales each; the x fundamental has none (its amplitude is the rescalings').
PART_RATIOS = {"fundamental_y": "quilt_fund_xy_ratio", "cross": "quilt_cross_ratio",
               "harmonics": "quilt_harmonics_ratio", "figure": "quilt_figure_ratio",
               "x_harmonics": "quilt_x_harmonics_ratio"}


def part_ratios(p: dict) -> dict:
    """Part name -> ratio for the ``quilt_shape`` parameters in ``p`` (a ratio not in ``p``
    is 1: the part keeps the nominal's share)."""
    return {part: p.get(name, 1.0) for part, name in PART_RATIOS.items()}


def _reshape(sag_um, x_mm, y_mm, p: dict, quilt):
    """``S + (rho - 1) F_y + (h - 1) H + (c - 1) C + (k - 1) H_x + (g - 1) R``
    (:mod:`pipeline.diagnosis.effects`), ``quilt`` the parts by name and ``whole = F``
    (:func:`pipeline.diagnosis.forward.quilt_parts`), ``R = S - F``; unchanged without a
    quilt fit."""
    r = part_ratios(p)
    if quilt is None or all(v == 1.0 for v in r.values()):
        return sag_um
    figure = sag_um - quilt["whole"]
    return sag_um + sum((v - 1.0) * (figure if part == "figure" else quilt[part]) for part, v in r.items())


def _summary(p: dict, ctx: SummaryContext) -> dict:
    out = {"quilt_fund_xy_ratio": p.get("quilt_fund_xy_ratio", 1.0), "quilt_harmonics_ratio": p["quilt_harmonics_ratio"],
           "quilt_x_harmonics_ratio": p.get("quilt_x_harmonics_ratio", 1.0),
           "quilt_cross_ratio": p.get("quilt_cross_ratio", 1.0), "quilt_figure_ratio": p.get("quilt_figure_ratio", 1.0)}
    if ctx.quilt_rms_um:
        q = ctx.quilt_rms_um
        out.update({"fundamental_x_rms_um": q["fundamental_x"],
                    "fundamental_y_rms_um": q["fundamental_y"] * p.get("quilt_fund_xy_ratio", 1.0),
                    "harmonics_rms_um": q["harmonics"] * abs(p["quilt_harmonics_ratio"]),
                    "x_harmonics_rms_um": q["x_harmonics"] * abs(p.get("quilt_x_harmonics_ratio", 1.0)),
                    "cross_rms_um": q["cross"] * abs(p.get("quilt_cross_ratio", 1.0)),
                    "quilt_note": f"RMS over a period at the simulation's {ctx.cold_K:g} K, before amplitude_scale "
                                  "and temperature; fitted over the 82 x 72 mm centre"})
    return out


QUILT_SHAPE = Effect(
    "quilt_shape", ("surface", "line_profile", "psf_image"),
    (Parameter("quilt_fund_xy_ratio", 1.0, 0.3, 3.0, (0.6, 1.0, 1.6), floor=0.05, unit="1",
               meaning="y fundamental (18 mm) relative to the x fundamental (21 mm), over the nominal's "
                       "ratio (x fundamental held)", kinds=_MAP_AND_IMAGE),
     Parameter("quilt_harmonics_ratio", 1.0, -1.0, 3.0, (0.0, 1.0, 2.0), floor=0.2, unit="1",
               meaning="quilt harmonics other than the (1, ±1) cross terms and the harmonics along x "
                       "relative to the fundamentals, over the nominal's ratio (0: none)"),
     Parameter("quilt_x_harmonics_ratio", 1.0, -1.0, 3.0, floor=0.2, unit="1",
               meaning="the quilt's harmonics along the dispersion, (2, 0) and (3, 0) (the rib profile "
                       "across x), relative to the fundamentals, over the nominal's ratio (negative: "
                       "their sign turned)"),
     Parameter("quilt_cross_ratio", 1.0, -1.0, 3.0, floor=0.2, unit="1",
               meaning="the quilt's (1, ±1) egg-crate cross terms relative to the fundamentals, over the "
                       "nominal's ratio (0: a sum-form quilt)"),
     Parameter("quilt_figure_ratio", 1.0, -1.0, 3.0, floor=0.2, unit="1",
               meaning="the smooth figure that is not quilt (edge roll-off, bending) relative to the "
                       "fundamentals, over the nominal's ratio")),
    description="the quilt's harmonic content differs from the simulation's: the y fundamental relative "
                "to the x fundamental, the cross terms, the harmonics along x and the other higher "
                "harmonics relative to both (the fundamentals' amplitude stays amplitude_scale's)",
    companion=True, background=True, draw_truth=effect_draws.quilt_shape, summary=_summary,
    shape=_reshape, shape_stage="reshape")
