"""CODE V Zernike interferogram decks (``.int``, ``ZFR`` type): Fringe coefficients.

File layout (as written and read here)
--------------------------------------
::

    ! comment: '!' starts a comment anywhere on a line
    <title line>                       we write "... NRADIUS_MM <r>"
    ZFR <n> SUR|WFR WVL <wvl_um> SSZ <ssz>
    <c1>
    <c2>
    ...                                n coefficients, Fringe order Z1..Zn

* Order: University of Arizona **Fringe** order (Z1 piston, Z2/Z3 tilt x/y, Z4
  defocus, ...; :data:`optics.zernike.FRINGE_NM`), up to 37 terms.
* Normalisation: Fringe terms are **unnormalised** (peak 1 at the rim).
* Units: ``value / SSZ`` waves at ``WVL`` µm, i.e. ``c_um = value / SSZ * WVL``.
  We write ``SSZ 1`` and the coefficients in waves with 12 significant digits
  (a public converter writes ``ZFR n WFR WVL 0.6328 SSZ 1.0`` followed by one
  ``%15.8f`` value per line).
* Normalisation radius: the deck does not carry one; CODE V scales it to the
  aperture of the surface it is attached to, so that aperture (the radius of the
  fit) must be set when loading. We write it into the title as ``NRADIUS_MM r``
  and read it back; for decks without it the caller passes ``radius_mm``.
* ``SUR`` coefficients describe surface sag, ``WFR`` a wavefront: as for grid
  files (:mod:`pipeline.io.codev`) the reader never turns one into the other
  silently (``quantity`` / ``wfr_to_sag_factor``).

The reader accepts any number of values per line, LF or CRLF line ends, and
refuses non-finite values naming the term.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Mapping

import numpy as np

from optics.zernike import fringe_to_nm, nm_to_fringe
from pipeline.io.codev_header import DATA_TYPES, parse_keywords, split_int_file
from pipeline.io.codev_quantity import check_request, sag_factor
from pipeline.io.common import atomic_write, parse_error
from pipeline.io.zernike import coefficients_for_file, convert_normalisation, parse_coefficients

__all__ = ["write_codev_zernike", "read_codev_zernike", "MAX_FRINGE_TERMS"]

MAX_FRINGE_TERMS = 37
_RADIUS_RE = re.compile(r"NRADIUS_MM\s+(\S+)")


def write_codev_zernike(
    coeffs: Mapping[tuple[int, int], float],
    path: str | Path,
    radius_mm: float,
    coeffs_normalised: bool,
    kind: str = "SUR",
    wavelength_um: float = 0.6328,
    n_terms: int = MAX_FRINGE_TERMS,
    title: str = "cryograting Zernike fit",
) -> Path:
    """Write Zernike coefficients as a CODE V ``ZFR`` deck.

    Parameters
    ----------
    coeffs : mapping (n, m) -> float
        Coefficients in µm (sag for ``SUR``, OPD for ``WFR``); each (n, m) must be one
        of the first ``n_terms`` Fringe terms. Missing terms are written as 0.
    path : str or Path
        Output file (written atomically).
    radius_mm : float
        Normalisation radius (mm), > 0; written into the title (``NRADIUS_MM``).
    coeffs_normalised : bool
        Whether ``coeffs`` multiply RMS-normalised terms (converted to the deck's
        unnormalised Fringe terms).
    kind : {"SUR", "WFR"}
        CODE V data type.
    wavelength_um : float
        ``WVL`` (µm), > 0; coefficients are written in waves of it (``SSZ 1``).
    n_terms : int
        Number of Fringe terms in the deck, 1..37.
    title : str
        Free text for the title line ('!' removed).
    """
    kind = str(kind).upper()
    if kind not in DATA_TYPES:
        raise ValueError(f"kind={kind!r} is not a CODE V Zernike data type; use one of {DATA_TYPES}")
    if not (np.isfinite(wavelength_um) and wavelength_um > 0):
        raise ValueError(f"wavelength_um={wavelength_um!r} must be a finite number > 0")
    if not (isinstance(n_terms, (int, np.integer)) and 1 <= n_terms <= MAX_FRINGE_TERMS):
        raise ValueError(f"n_terms={n_terms!r} must be an integer in 1..{MAX_FRINGE_TERMS}")
    c = coefficients_for_file(coeffs, "fringe", radius_mm, coeffs_normalised, file_normalised=False)
    values = np.zeros(n_terms)
    for (n, m), v in c.items():
        j = nm_to_fringe(n, m)  # refuses terms outside the 37 Fringe terms
        if j > n_terms:
            raise ValueError(f"term (n, m)=({n}, {m}) is Fringe Z{j}, beyond n_terms={n_terms}")
        values[j - 1] = v / wavelength_um
    clean = " ".join(str(title).replace("!", " ").split())[:50]
    path = Path(path)
    with atomic_write(path) as fh:
        fh.write(f"{clean} NRADIUS_MM {radius_mm:.12g}".strip() + "\n")
        fh.write(f"ZFR {n_terms} {kind} WVL {wavelength_um:.10g} SSZ 1\n")
        fh.write("".join(f"{v:.12g}\n" for v in values))
    return path


def _parse_header(path, lineno: int, line: str) -> dict:
    tok = line.split()
    if not tok or tok[0].upper() != "ZFR":
        found = tok[0] if tok else ""
        hint = " (a grid file: read it with read_codev_int)" if found.upper() == "GRD" else ""
        raise parse_error(path, lineno, f"header must start with 'ZFR <n>', found {found!r}{hint}")
    try:
        n = int(tok[1])
    except (IndexError, ValueError):
        raise parse_error(path, lineno, f"'ZFR' must be followed by the number of terms, found {tok[1:2]}") from None
    if not 1 <= n <= MAX_FRINGE_TERMS:
        raise parse_error(path, lineno, f"ZFR {n}: number of Fringe terms must be in 1..{MAX_FRINGE_TERMS}")
    hdr = {"n": n, **parse_keywords(path, lineno, tok[2:], {"WVL": float, "SSZ": float})}
    if "WVL" not in hdr:
        raise parse_error(path, lineno, "header has no WVL (needed to convert coefficients to um)")
    hdr.setdefault("SSZ", 1.0)  # decks from other writers carry SSZ 1.0; absent means waves
    return hdr


def read_codev_zernike(
    path: str | Path,
    normalised: bool,
    radius_mm: float | None = None,
    quantity: str = "sag",
    wfr_to_sag_factor: float | None = None,
) -> tuple[dict, dict]:
    """Read a CODE V ``ZFR`` deck.

    Parameters
    ----------
    path : str or Path
        The deck.
    normalised : bool
        Return coefficients for RMS-normalised (True) or unnormalised (False) terms.
    radius_mm : float, optional
        Normalisation radius (mm); overrides the title's ``NRADIUS_MM``. Required for
        decks without it.
    quantity : {"sag", "wavefront"}
        As in :func:`pipeline.io.codev.read_codev_int`: a ``WFR`` deck is refused as
        sag unless ``wfr_to_sag_factor`` is given; a ``SUR`` deck is refused as a
        wavefront.
    wfr_to_sag_factor : float, optional
        ``sag = factor * OPD`` for a ``WFR`` deck read as sag.

    Returns
    -------
    coeffs : dict (n, m) -> float
        Coefficients in µm.
    info : dict
        ``codev_type``, ``wavelength_um``, ``ssz``, ``n_terms``, ``radius_mm``,
        ``normalised``, ``title`` (and ``wfr_to_sag_factor`` when used).
    """
    check_request(quantity, wfr_to_sag_factor)
    path = Path(path)
    title, (hdr_line, hdr_text), body = split_int_file(path, "CODE V Zernike deck", "ZFR n")
    hdr = _parse_header(path, hdr_line, hdr_text)
    values: list[tuple[int, str]] = [(n, t) for n, s in body for t in s.split()]
    if len(values) != hdr["n"]:
        where = values[hdr["n"]][0] if len(values) > hdr["n"] else (body[-1][0] if body else hdr_line)
        raise parse_error(path, where, f"ZFR {hdr['n']} needs {hdr['n']} coefficients, found {len(values)}")
    coeffs = parse_coefficients(path, values, fringe_to_nm, "Fringe", lambda v: v / hdr["SSZ"] * hdr["WVL"])
    if radius_mm is None:
        m = _RADIUS_RE.search(title)
        try:
            radius_mm = float(m.group(1)) if m else None
        except ValueError:
            radius_mm = float("nan")
        if radius_mm is None:
            raise ValueError(f"{path}: the deck carries no normalisation radius (no NRADIUS_MM in the title); "
                             "pass radius_mm (the aperture radius the deck refers to, mm)")
    if not (np.isfinite(radius_mm) and radius_mm > 0):
        raise ValueError(f"{path}: normalisation radius {radius_mm!r} mm must be a finite number > 0")
    kind = hdr["type"]
    info = {"codev_type": kind, "wavelength_um": hdr["WVL"], "ssz": hdr["SSZ"], "n_terms": hdr["n"],
            "radius_mm": float(radius_mm), "normalised": bool(normalised), "title": title, "quantity": quantity}
    factor = sag_factor(path, kind, quantity, wfr_to_sag_factor)
    if wfr_to_sag_factor is not None:
        coeffs = {k: v * factor for k, v in coeffs.items()}
        info["wfr_to_sag_factor"] = factor
    if normalised:
        coeffs = convert_normalisation(coeffs, to_normalised=True)
    return coeffs, info
