"""What the numbers of a CODE V INT file mean: surface sag (``SUR``) or wavefront (``WFR``).

Converting between the two needs the geometry of the surface in the beam (for a
reflective grating ``OPD = -(cos alpha + cos beta) * sag``, :func:`optics.pupil.grating_opd_um`;
for a mirror at normal incidence ``OPD = -2 sag``), so no reader converts silently:
:func:`sag_factor` says by which factor the file's values become what the caller asked
for, or refuses with a message that says what to pass.
"""

from __future__ import annotations

import math

__all__ = ["QUANTITIES", "check_request", "sag_factor", "grating_wfr_to_sag_factor"]

#: what a reader may return
QUANTITIES = ("sag", "wavefront")


def grating_wfr_to_sag_factor(incidence_deg: float, diffraction_deg: float) -> float:
    """``sag = factor * OPD`` for a reflective grating: ``-1 / (cos alpha + cos beta)``.

    The inverse of the wavefront the study writes (:func:`optics.pupil.grating_opd_um`:
    ``OPD = -(cos alpha + cos beta) h``), on the grating-face grid.

    Parameters
    ----------
    incidence_deg, diffraction_deg : float
        Angles of incidence ``alpha`` and diffraction ``beta`` (degrees).
    """
    s = math.cos(math.radians(incidence_deg)) + math.cos(math.radians(diffraction_deg))
    if not (math.isfinite(s) and abs(s) > 1e-9):
        raise ValueError(f"incidence_deg={incidence_deg!r}, diffraction_deg={diffraction_deg!r}: "
                         "cos alpha + cos beta must be finite and non-zero")
    return -1.0 / s


def check_request(quantity: str, wfr_to_sag_factor: float | None) -> None:
    """Validate the caller's options before the file is read."""
    if quantity not in QUANTITIES:
        raise ValueError(f"quantity={quantity!r} is not valid; use one of {QUANTITIES}")
    if wfr_to_sag_factor is not None:
        if quantity != "sag":
            raise ValueError("wfr_to_sag_factor only applies with quantity='sag'")
        try:
            ok = math.isfinite(wfr_to_sag_factor) and wfr_to_sag_factor != 0
        except TypeError:
            ok = False
        if not ok:
            raise ValueError(f"wfr_to_sag_factor={wfr_to_sag_factor!r} must be a finite non-zero number")


def sag_factor(path, kind: str, quantity: str, wfr_to_sag_factor: float | None) -> float:
    """Factor that turns the file's values (data type ``kind``) into ``quantity``.

    Parameters
    ----------
    path : str or Path
        The file (named in messages).
    kind : {"SUR", "WFR"}
        The file's data type.
    quantity : {"sag", "wavefront"}
        What the caller wants.
    wfr_to_sag_factor : float or None
        ``sag = factor * OPD``; required to read ``WFR`` as sag, refused otherwise.

    Raises
    ------
    ValueError
        ``WFR`` as sag without a factor, ``SUR`` as a wavefront, or a factor for a
        ``SUR`` file (it would be ignored).
    """
    check_request(quantity, wfr_to_sag_factor)
    if wfr_to_sag_factor is not None and kind != "WFR":
        raise ValueError(f"{path}: wfr_to_sag_factor={wfr_to_sag_factor!r} given but the data type is {kind} "
                         "(already surface sag); drop the factor")
    if quantity == "wavefront":
        if kind != "WFR":
            raise ValueError(f"{path}: data type {kind} is surface sag, not a wavefront; read it with quantity='sag'")
        return 1.0
    if kind == "WFR":
        if wfr_to_sag_factor is None:
            raise ValueError(
                f"{path}: data type WFR is a wavefront (OPD), not surface sag; converting needs the "
                "geometry: pass wfr_to_sag_factor (sag = factor x OPD; a reflective grating: "
                "grating_wfr_to_sag_factor(alpha, beta) = -1/(cos alpha + cos beta)), "
                "or read it as a wavefront with quantity='wavefront'"
            )
        return float(wfr_to_sag_factor)
    return 1.0
