"""Zernike coefficient lists in the two conventions optical design codes exchange.

* ``"fringe"`` — University of Arizona Fringe order (CODE V ``ZFR``, Zemax "Zernike
  Fringe"), 37 terms, *unnormalised*: each term has peak 1 at the rim.
* ``"noll"`` — Noll order (Zemax "Zernike Standard"), *RMS-normalised*: each term
  has unit RMS over the disc.

In memory a list is a dict ``{(n, m): coefficient_um}`` plus a flag saying whether the
coefficients multiply normalised or unnormalised terms. The same surface has
``c_unnormalised = c_normalised * N(n, m)`` with the Noll factor
``N = sqrt(2 (n + 1) / (1 + delta_m0))`` (:func:`optics.zernike.norm_factor`), because
``Z_normalised = N * Z_unnormalised``.

File layout (plain text)::

    # cryograting Zernike coefficients
    # convention: fringe
    # normalised: false
    # normalisation_radius_mm: 62.5
    # units: um
    index,n,m,coefficient_um
    1,0,0,0.0123
    ...
"""

from __future__ import annotations

from pathlib import Path
from typing import Mapping

import numpy as np

from optics.zernike import fringe_to_nm, nm_to_fringe, nm_to_noll, noll_to_nm, norm_factor
from pipeline.io.common import atomic_write, numbered_lines, parse_error, read_text

__all__ = ["ZERNIKE_CONVENTIONS", "convert_normalisation", "write_zernike_list", "read_zernike_list",
           "check_coefficients", "coefficients_for_file", "parse_coefficients", "parse_radius"]

#: convention -> (index -> (n, m), (n, m) -> index, coefficients normalised in the file)
ZERNIKE_CONVENTIONS = {
    "fringe": (fringe_to_nm, nm_to_fringe, False),
    "noll": (noll_to_nm, nm_to_noll, True),
}
_COLUMNS = ["index", "n", "m", "coefficient_um"]


def _check_convention(convention: str) -> str:
    c = str(convention).lower()
    if c not in ZERNIKE_CONVENTIONS:
        raise ValueError(f"convention={convention!r} is unknown; valid are {sorted(ZERNIKE_CONVENTIONS)}")
    return c


def check_coefficients(coeffs: Mapping[tuple[int, int], float], convention: str) -> dict:
    """``{(n, m): float}`` copy of ``coeffs``; a non-finite or non-numeric coefficient is a
    ``ValueError`` naming the term (its index in ``convention`` when it has one, and (n, m))."""
    convention = _check_convention(convention)
    to_index = ZERNIKE_CONVENTIONS[convention][1]
    out = {}
    for (n, m), v in coeffs.items():
        try:
            f = float(v)
        except (TypeError, ValueError):
            f = float("nan")
        if not np.isfinite(f):
            try:
                where = f"{convention} term {to_index(int(n), int(m))} "
            except ValueError:
                where = ""
            raise ValueError(f"Zernike coefficient {where}(n, m)=({n}, {m}) is {v!r}; coefficients must be finite numbers")
        out[(int(n), int(m))] = f
    return out


def convert_normalisation(coeffs: Mapping[tuple[int, int], float], to_normalised: bool) -> dict:
    """Re-express coefficients for RMS-normalised (``True``) or unnormalised terms.

    Parameters
    ----------
    coeffs : mapping (n, m) -> float
        Coefficients (µm) of the *other* normalisation.
    to_normalised : bool
        True: unnormalised -> normalised (divide by ``N``); False: the reverse.
    """
    out = {}
    for (n, m), c in coeffs.items():
        f = norm_factor(n, m)
        out[(int(n), int(m))] = float(c) / f if to_normalised else float(c) * f
    return out


def coefficients_for_file(coeffs: Mapping[tuple[int, int], float], convention: str, radius_mm: float,
                          coeffs_normalised: bool, file_normalised: bool) -> dict:
    """What every Zernike writer does first: check the radius and the coefficients, and
    re-express the coefficients in the file's normalisation.

    Parameters
    ----------
    coeffs : mapping (n, m) -> float
        Coefficients in µm.
    convention : {"fringe", "noll"}
        Index convention naming a bad term in messages.
    radius_mm : float
        Normalisation radius (mm); must be finite and > 0.
    coeffs_normalised, file_normalised : bool
        Whether ``coeffs`` / the file's coefficients multiply RMS-normalised terms.

    Returns
    -------
    dict (n, m) -> float
        Coefficients (µm) for the file's normalisation.
    """
    if not (np.isfinite(radius_mm) and radius_mm > 0):
        raise ValueError(f"radius_mm={radius_mm!r} must be a finite number > 0")
    c = check_coefficients(coeffs, convention)
    if coeffs_normalised != file_normalised:
        c = convert_normalisation(c, to_normalised=file_normalised)
    return c


def parse_coefficients(path, tokens: list[tuple[int, str]], to_nm, label: str, to_um) -> dict:
    """Coefficients of a file that lists them in index order 1, 2, ... without (n, m).

    Parameters
    ----------
    path : str or Path
        The file (named in messages).
    tokens : list of (int, str)
        Line number and text of each coefficient, term 1 first.
    to_nm : callable
        Index -> (n, m) of the file's convention.
    label : str
        The convention as messages name it (``"Fringe"``, ``"standard"``).
    to_um : callable
        File value -> µm.

    Returns
    -------
    dict (n, m) -> float
        Coefficients in µm; a non-numeric or non-finite one is refused naming its
        line and term.
    """
    coeffs = {}
    for j, (n, t) in enumerate(tokens, start=1):
        try:
            v = float(t)
        except ValueError:
            v = float("nan")
        if not np.isfinite(v):
            raise parse_error(path, n, f"{label} Z{j} {to_nm(j)}: coefficient {t!r} is not a finite number")
        coeffs[to_nm(j)] = to_um(v)
    return coeffs


def parse_radius(path, lineno: int | None, text: str, what: str) -> float:
    """A normalisation radius (mm) read from a file: a finite number > 0, or a
    ``ValueError`` naming the file, the line and ``what`` the value is."""
    try:
        radius = float(text)
    except ValueError:
        radius = float("nan")
    if not (np.isfinite(radius) and radius > 0):
        raise parse_error(path, lineno, f"{what} {text!r} must be a finite number > 0 (mm)")
    return radius


def write_zernike_list(
    coeffs: Mapping[tuple[int, int], float],
    path: str | Path,
    convention: str,
    radius_mm: float,
    coeffs_normalised: bool,
) -> Path:
    """Write Zernike coefficients in the file convention's order and normalisation.

    Parameters
    ----------
    coeffs : mapping (n, m) -> float
        Coefficients in µm.
    path : str or Path
        Output file (written atomically).
    convention : {"fringe", "noll"}
        File convention (see module docstring); fixes order and normalisation.
    radius_mm : float
        Normalisation radius (mm), > 0.
    coeffs_normalised : bool
        Whether ``coeffs`` multiply RMS-normalised terms; converted if the file
        convention differs.
    """
    convention = _check_convention(convention)
    to_index, file_norm = ZERNIKE_CONVENTIONS[convention][1], ZERNIKE_CONVENTIONS[convention][2]
    c = coefficients_for_file(coeffs, convention, radius_mm, coeffs_normalised, file_norm)
    rows = sorted((to_index(n, m), n, m, v) for (n, m), v in c.items())
    path = Path(path)
    with atomic_write(path) as fh:
        fh.write("# cryograting Zernike coefficients\n")
        fh.write(f"# convention: {convention}\n")
        fh.write(f"# normalised: {'true' if file_norm else 'false'}\n")
        fh.write(f"# normalisation_radius_mm: {radius_mm:.12g}\n")
        fh.write("# units: um\n")
        fh.write(",".join(_COLUMNS) + "\n")
        for j, n, m, v in rows:
            fh.write(f"{j},{n},{m},{v:.15g}\n")
    return path


def read_zernike_list(path: str | Path, normalised: bool) -> tuple[dict, dict]:
    """Read a Zernike list written by :func:`write_zernike_list`.

    Parameters
    ----------
    path : str or Path
        The file.
    normalised : bool
        Return coefficients for RMS-normalised (True) or unnormalised (False) terms,
        whatever the file convention.

    Returns
    -------
    coeffs : dict (n, m) -> float
        Coefficients in µm.
    info : dict
        ``convention``, ``radius_mm``, ``normalised`` (of the returned dict).

    Raises
    ------
    ValueError
        Naming file and line for a missing/unknown convention, radius or units, a
        bad column header, a non-numeric value, or an index that disagrees with (n, m).
    """
    path = Path(path)
    header: dict[str, tuple[int, str]] = {}
    coeffs: dict[tuple[int, int], float] = {}
    columns_seen = False
    last = None
    for n, s in numbered_lines(read_text(path, "Zernike list")):
        last = n
        t = s.strip()
        if not t:
            continue
        if t.startswith("#"):
            if ":" in t:
                k, v = t[1:].split(":", 1)
                header[k.strip().lower()] = (n, v.strip())
            continue
        if not columns_seen:
            if [c.strip() for c in t.split(",")] != _COLUMNS:
                raise parse_error(path, n, f"column header must be {','.join(_COLUMNS)!r}, found {t!r}")
            columns_seen = True
            for key in ("convention", "normalisation_radius_mm", "units"):
                if key not in header:
                    raise parse_error(path, n, f"missing '# {key}: ...' line before the column header")
            conv_line, conv = header["convention"]
            try:
                conv = _check_convention(conv)
            except ValueError as exc:
                raise parse_error(path, conv_line, str(exc)) from None
            to_nm, to_index, file_norm = ZERNIKE_CONVENTIONS[conv]
            radius = parse_radius(path, *header["normalisation_radius_mm"], "normalisation_radius_mm")
            u_line, units = header["units"]
            if units.lower() not in ("um", "µm"):
                raise parse_error(path, u_line, f"units {units!r} not supported; expected 'um'")
            continue
        parts = [p.strip() for p in t.split(",")]
        if len(parts) != 4:
            raise parse_error(path, n, f"expected 4 comma-separated values {_COLUMNS}, found {len(parts)}")
        try:
            j, nn, mm = (int(p) for p in parts[:3])
            v = float(parts[3])
        except ValueError:
            raise parse_error(path, n, f"index, n, m must be integers and the coefficient a number: {t!r}") from None
        if not np.isfinite(v):
            raise parse_error(path, n, f"{conv} term {j}: coefficient {parts[3]!r} is not a finite number")
        try:
            nm = to_nm(j)
        except ValueError as exc:
            raise parse_error(path, n, str(exc)) from None
        if nm != (nn, mm):
            raise parse_error(path, n, f"{conv} index {j} is (n, m)={nm}, but the line says ({nn}, {mm})")
        if nm in coeffs:
            raise parse_error(path, n, f"duplicate term {conv} index {j}")
        coeffs[nm] = v
    if not columns_seen:
        raise parse_error(path, last, f"no column header {','.join(_COLUMNS)!r} found")
    if normalised != file_norm:
        coeffs = convert_normalisation(coeffs, to_normalised=normalised)
    return coeffs, {"convention": conv, "radius_mm": radius, "normalised": bool(normalised)}
