"""``blank_bow``: a rotationally symmetric figure change of the cold blank (a companion
tried only where a map is in the data: :mod:`pipeline.diagnosis.effects`)."""

from __future__ import annotations

import numpy as np

from optics.zernike import zernike_xy

from .base import Effect, Parameter, SummaryContext, vector_norm

__all__ = ["BLANK_BOW", "BOW_REF_RADIUS_MM", "bow_um"]

#: Radius (mm, blank coordinates) of the disc over which the ``blank_bow`` Zernike terms
#: are RMS-normalised: half the blank's 140 mm height, independent of any measurement.
BOW_REF_RADIUS_MM = 70.0


def bow_um(x_mm: np.ndarray, y_mm: np.ndarray, defocus_um: float, spherical_um: float) -> np.ndarray:
    """The bow's surface (µm) at blank coordinates (mm): Zernike (2,0) and (4,0),
    RMS-normalised over the ``BOW_REF_RADIUS_MM`` disc."""
    out = np.zeros(np.broadcast(x_mm, y_mm).shape)
    if defocus_um:
        out = out + defocus_um * _bow_term(2, x_mm, y_mm)
    if spherical_um:
        out = out + spherical_um * _bow_term(4, x_mm, y_mm)
    return out


def _bow_term(n: int, x_mm, y_mm) -> np.ndarray:
    """``zernike_xy(n, 0, x_mm, y_mm, BOW_REF_RADIUS_MM)`` (read-only), memoised on the
    coordinate arrays themselves.

    Why: a fit with the bow free evaluates it on the same grid thousands of times (measured:
    6 % of the CPU time of a diagnosis of profiles + map + PSF image). The memo is keyed on
    the arrays' identity and checked against a copy of their values taken when stored, so an
    array changed in place since is evaluated afresh; keying on the values' bytes instead cost
    0.3 ms a call on the 0.5 mm grid (hashing 1.4 MB), 8 % of the same diagnosis."""
    x, y = np.asarray(x_mm, dtype=float), np.asarray(y_mm, dtype=float)
    for i, (n_c, x_c, y_c, x_v, y_v, z) in enumerate(_BOW_MEMO):
        if n_c == n and x_c is x and y_c is y:
            if np.array_equal(x, x_v) and np.array_equal(y, y_v):
                _BOW_MEMO.append(_BOW_MEMO.pop(i))
                return z
            break
    z = zernike_xy(n, 0, x, y, BOW_REF_RADIUS_MM)
    z.flags.writeable = False
    _BOW_MEMO.append((n, x, y, x.copy(), y.copy(), z))
    del _BOW_MEMO[:-_BOW_MEMO_SIZE]
    return z


#: Entries ``(n, x, y, x values, y values, Z)`` of :func:`_bow_term`'s memo, most recent last.
_BOW_MEMO: list = []
_BOW_MEMO_SIZE = 16


def _shape(sag_um, x_mm, y_mm, p: dict, quilt):
    b2, b4 = p.get("bow_defocus_um", 0.0), p.get("bow_spherical_um", 0.0)
    if not (b2 or b4):
        return sag_um
    return sag_um + bow_um(x_mm, y_mm, b2, b4)


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
    vector=True, companion=True, requires=("surface",), summary=_summary, shape=_shape, shape_stage="add")
