"""Zemax OpticStudio files: Grid Sag (``.dat``) sag maps and Zernike Standard/Fringe Sag coefficients.

Format (OpticStudio help, "Grid Sag" surface, "Importing Grid Data"; the Zemax
knowledge-base articles "How to use the Grid Sag surface type" and "How to write a
Grid Sag DAT file programmatically" show the same layout)::

    nx ny delx dely unitflag xdec ydec
    z dz/dx dz/dy d2z/dxdy nodata        <- nx * ny lines

* ``unitflag``: 0 mm, 1 cm, 2 in, 3 m. Sag and the cross derivative have dimensions
  and are in these units (OpticStudio rescales them); first derivatives are
  dimensionless. We write mm (flag 0); the reader accepts all four.
* ``xdec``, ``ydec``: decentre of the grid centre relative to the base surface. The
  grid is centred on the decentre: ``x_i = xdec + (i - (nx - 1)/2) delx``. We write
  the centre of our grid there, so off-centre maps keep their coordinates.
* Order: the first point is the (-x, +y) corner; x varies fastest along a row, rows
  go from +y down to -y.
* ``nodata`` = 1 marks a point without data (NaN here); its other values are 0.
* OpticStudio requires nx, ny >= 5 (checked by the writer).

Derivatives
-----------
OpticStudio uses them only for bicubic interpolation. We write finite differences
of the map, NaN-aware: central differences where both neighbours are valid,
one-sided where only one is, 0 where neither is (an isolated valid sample). The
cross derivative is the NaN-aware y difference of ``dz/dx``. On reading they are
ignored (the sag column is the data).

Values are written with 12 significant digits (``%.12g``), i.e. a relative round-off
of up to 5e-12: far below anything physical.

Zernike Standard Sag / Zernike Fringe Sag coefficient files
-----------------------------------------------------------
:func:`write_zemax_zernike` writes the surface's extra data as a plain list, one
value per line, in the order of OpticStudio's Extra Data Editor for these surfaces::

    <number of terms N>
    <normalisation radius, lens units (mm)>
    <Z1 coefficient, mm>
    ...
    <ZN coefficient, mm>

* ``convention="standard"`` -> surface type **Zernike Standard Sag**: Noll order
  (Z1 piston, Z2 tilt x, Z3 tilt y, Z4 defocus, ...), **RMS-normalised** terms.
* ``convention="fringe"`` -> surface type **Zernike Fringe Sag**: Fringe order
  (Z4 defocus, Z9 spherical, ..., at most 37 terms), **peak-normalised** terms
  (value 1 at the rim).
* Coefficients are sag in mm (lens units mm); the radius is the fit's radius.
The order (terms, radius, coefficients) is the layout those surfaces list in the
Extra Data Editor *(unverified against an OpticStudio installation: after import,
check that "Number of Terms" and "Norm Radius" show the first two values)*. A cross-check
inside OpticStudio: its File > Convert File Formats > "INT Zernike to OpticStudio DAT"
turns our CODE V ZFR deck (:mod:`pipeline.io.codev_zfr`) into its own Fringe list.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from optics.sagmap import SagMap
from optics.zernike import fringe_to_nm, nm_to_fringe, nm_to_noll, noll_to_nm
from pipeline.io.common import atomic_write, numbered_lines, parse_error, read_text
from pipeline.io.zernike import coefficients_for_file, convert_normalisation, parse_coefficients, parse_radius

__all__ = ["write_zemax_grid_sag", "read_zemax_grid_sag", "nan_gradient", "ZEMAX_UNITS_MM",
           "write_zemax_zernike", "read_zemax_zernike", "ZEMAX_ZERNIKE"]

#: Zemax ``unitflag`` -> millimetres per unit.
ZEMAX_UNITS_MM: dict[int, float] = {0: 1.0, 1: 10.0, 2: 25.4, 3: 1000.0}
_MIN_POINTS = 5


def nan_gradient(z: np.ndarray, step: float, axis: int) -> np.ndarray:
    """Finite-difference derivative of ``z`` along ``axis`` that never reads a NaN.

    Central difference where both neighbours are finite, one-sided where one is,
    0 where neither is; NaN where ``z`` itself is NaN.
    """
    z = np.moveaxis(np.asarray(z, float), axis, 0)
    out = np.zeros_like(z)
    fwd = np.full_like(z, np.nan)
    bwd = np.full_like(z, np.nan)
    fwd[:-1] = (z[1:] - z[:-1]) / step
    bwd[1:] = (z[1:] - z[:-1]) / step
    both = np.isfinite(fwd) & np.isfinite(bwd)
    out[both] = 0.5 * (fwd[both] + bwd[both])
    only_f = np.isfinite(fwd) & ~np.isfinite(bwd)
    only_b = np.isfinite(bwd) & ~np.isfinite(fwd)
    out[only_f] = fwd[only_f]
    out[only_b] = bwd[only_b]
    out[~np.isfinite(z)] = np.nan
    return np.moveaxis(out, 0, axis)


def write_zemax_grid_sag(sagmap: SagMap, path: str | Path) -> Path:
    """Write a map as a Zemax Grid Sag ``.dat`` file in mm (``unitflag`` 0).

    Parameters
    ----------
    sagmap : SagMap
        Map to write (sag µm along +z, coordinates mm); NaN becomes ``nodata = 1``.
    path : str or Path
        Output file (written atomically).

    Returns
    -------
    Path
        The written path.
    """
    ny, nx = sagmap.sag_um.shape
    if nx < _MIN_POINTS or ny < _MIN_POINTS:
        raise ValueError(f"Zemax Grid Sag needs nx, ny >= {_MIN_POINTS}; map {sagmap.label!r} is {nx} x {ny}")
    dx, dy = sagmap.dx_mm, sagmap.dy_mm
    z = sagmap.sag_um * 1e-3  # lens units: mm
    dzdx = nan_gradient(z, dx, axis=1)
    dzdy = nan_gradient(z, dy, axis=0)
    d2 = nan_gradient(dzdx, dy, axis=0)
    nodata = ~np.isfinite(z)
    cols = [np.where(nodata, 0.0, a) for a in (z, dzdx, dzdy, d2)]
    # file rows from +y (top) to -y, x increasing along a row; our arrays have y increasing
    table = np.column_stack([c[::-1].ravel() for c in cols])
    flags = nodata[::-1].ravel().astype(int)
    xdec = 0.5 * (sagmap.x_mm[0] + sagmap.x_mm[-1])
    ydec = 0.5 * (sagmap.y_mm[0] + sagmap.y_mm[-1])
    path = Path(path)
    with atomic_write(path) as fh:
        fh.write(f"{nx} {ny} {dx:.12g} {dy:.12g} 0 {xdec:.12g} {ydec:.12g}\n")
        # one %-format per row over Python floats: the same text as np.savetxt, 2x faster
        line = "%.12g %.12g %.12g %.12g %d\n"
        fh.write("".join(map(line.__mod__, zip(*(table.T.tolist() + [flags.tolist()])))))
    return path


def _uncommented(text: str) -> list[tuple[int, str]]:
    """``(line number, line)`` of a Zemax data file with ``!`` comments (a writer's title
    line: ``! Grid sag written by MATLAB``) removed."""
    return [(n, s.split("!", 1)[0]) for n, s in numbered_lines(text)]


def read_zemax_grid_sag(path: str | Path) -> SagMap:
    """Read a Zemax Grid Sag ``.dat`` file into a :class:`SagMap`.

    Parameters
    ----------
    path : str or Path
        The ``.dat`` file (any ``unitflag``; converted to mm and µm).

    Returns
    -------
    SagMap
        ``meta`` holds ``unitflag``, ``xdec_mm``, ``ydec_mm``.

    Raises
    ------
    ValueError
        Naming file and line for a bad header, a non-numeric value, a wrong number of
        columns, a bad ``nodata`` flag, or a truncated / over-long file.
    """
    path = Path(path)
    lines = [(n, s) for n, s in _uncommented(read_text(path, "Zemax grid sag")) if s.strip()]
    if not lines:
        raise parse_error(path, None, "file is empty; expected header 'nx ny delx dely unitflag xdec ydec'")
    n0, head = lines[0]
    tok = head.split()
    if len(tok) == 1 and len(lines) > 2 and all(len(t.split()) == 1 for _, t in lines[:3]):
        raise parse_error(path, n0, "one value per line: this looks like a Zernike Standard/Fringe Sag "
                                    "coefficient list; read it with read_zemax_zernike")
    if len(tok) != 7:
        raise parse_error(path, n0, f"header needs 7 values 'nx ny delx dely unitflag xdec ydec', found {len(tok)}")
    try:
        nx, ny, unit = int(tok[0]), int(tok[1]), int(tok[4])
        delx, dely, xdec, ydec = (float(tok[i]) for i in (2, 3, 5, 6))
    except ValueError:
        raise parse_error(path, n0, f"header {head.strip()!r}: nx, ny, unitflag must be integers and "
                                    "delx, dely, xdec, ydec numbers") from None
    if nx < 2 or ny < 2:
        raise parse_error(path, n0, f"nx={nx}, ny={ny} must be >= 2")
    if unit not in ZEMAX_UNITS_MM:
        raise parse_error(path, n0, f"unitflag={unit} is not valid; use 0 (mm), 1 (cm), 2 (in) or 3 (m)")
    delx, dely = abs(delx), abs(dely)  # Zemax takes absolute values of the increments
    if not (delx > 0 and dely > 0):
        raise parse_error(path, n0, f"delx={delx}, dely={dely} must be non-zero")
    body = lines[1:]
    expected = nx * ny
    if len(body) < expected:
        last = body[-1][0] if body else n0
        raise parse_error(path, last, f"truncated: {nx} x {ny} grid needs {expected} data lines, found {len(body)}")
    if len(body) > expected:
        raise parse_error(path, body[expected][0], f"wrong count: {nx} x {ny} grid needs {expected} data lines, "
                                                   f"found {len(body)}")
    sag = np.empty(expected)
    bad = np.zeros(expected, dtype=bool)
    for k, (n, s) in enumerate(body):
        t = s.split()
        if len(t) not in (4, 5):
            raise parse_error(path, n, f"expected 4 or 5 values 'z dz/dx dz/dy d2z/dxdy [nodata]', found {len(t)}")
        try:
            v = [float(a) for a in t[:4]]
        except ValueError:
            raise parse_error(path, n, f"non-numeric value in {s.strip()!r}") from None
        if len(t) == 5:
            if t[4] not in ("0", "1"):
                raise parse_error(path, n, f"nodata flag {t[4]!r} must be 0 or 1")
            bad[k] = t[4] == "1"
        sag[k] = v[0]
    scale = ZEMAX_UNITS_MM[unit]
    sag_um = np.where(bad, np.nan, sag * scale * 1e3).reshape(ny, nx)[::-1]  # file is top row first
    dx, dy = delx * scale, dely * scale
    x = xdec * scale + (np.arange(nx) - 0.5 * (nx - 1)) * dx
    y = ydec * scale + (np.arange(ny) - 0.5 * (ny - 1)) * dy
    meta = {"format": "zemax_grid_sag", "unitflag": unit, "xdec_mm": xdec * scale, "ydec_mm": ydec * scale}
    return SagMap(x, y, sag_um, path.stem, meta)


#: convention -> (surface type, index -> (n, m), (n, m) -> index, RMS-normalised terms, max terms)
ZEMAX_ZERNIKE = {
    "standard": ("Zernike Standard Sag", noll_to_nm, nm_to_noll, True, 231),
    "fringe": ("Zernike Fringe Sag", fringe_to_nm, nm_to_fringe, False, 37),
}


def _zernike_convention(convention: str) -> str:
    c = str(convention).lower()
    if c not in ZEMAX_ZERNIKE:
        raise ValueError(f"convention={convention!r} is unknown; valid are {sorted(ZEMAX_ZERNIKE)}")
    return c


def write_zemax_zernike(
    coeffs,
    path: str | Path,
    convention: str,
    radius_mm: float,
    coeffs_normalised: bool,
) -> Path:
    """Write Zernike sag coefficients as an OpticStudio extra-data list (see module docstring).

    Parameters
    ----------
    coeffs : mapping (n, m) -> float
        Sag coefficients in µm; missing terms up to the highest one are written as 0.
    path : str or Path
        Output file (written atomically).
    convention : {"standard", "fringe"}
        Zernike Standard Sag (Noll, RMS-normalised) or Zernike Fringe Sag (Fringe,
        peak-normalised, <= 37 terms).
    radius_mm : float
        Normalisation radius (mm), > 0.
    coeffs_normalised : bool
        Whether ``coeffs`` multiply RMS-normalised terms (converted as needed).

    Raises
    ------
    ValueError
        A non-finite coefficient (naming the term), a term outside the convention,
        a bad radius.
    """
    convention = _zernike_convention(convention)
    _, _, to_index, file_norm, max_terms = ZEMAX_ZERNIKE[convention]
    c = coefficients_for_file(coeffs, "noll" if convention == "standard" else "fringe", radius_mm,
                              coeffs_normalised, file_norm)
    index = {to_index(n, m): v for (n, m), v in c.items()}
    n_terms = max(index, default=1)
    if n_terms > max_terms:
        raise ValueError(f"{convention} term {n_terms} exceeds the {max_terms} terms of {ZEMAX_ZERNIKE[convention][0]}")
    values = [index.get(j, 0.0) * 1e-3 for j in range(1, n_terms + 1)]  # um -> mm (lens units)
    path = Path(path)
    with atomic_write(path) as fh:
        fh.write(f"{n_terms}\n{radius_mm:.12g}\n")
        fh.write("".join(f"{v:.12g}\n" for v in values))
    return path


def read_zemax_zernike(path: str | Path, convention: str, normalised: bool) -> tuple[dict, dict]:
    """Read an OpticStudio Zernike Standard/Fringe Sag extra-data list (lens units mm).

    Parameters
    ----------
    path : str or Path
        The file: number of terms, normalisation radius (mm), then the coefficients
        (mm), one value per line (several per line are accepted).
    convention : {"standard", "fringe"}
        The surface type the file is for (the file does not say).
    normalised : bool
        Return coefficients for RMS-normalised (True) or unnormalised (False) terms.

    Returns
    -------
    coeffs : dict (n, m) -> float
        Sag coefficients in µm.
    info : dict
        ``convention``, ``surface_type``, ``n_terms``, ``radius_mm``, ``normalised``.
    """
    convention = _zernike_convention(convention)
    surface, to_nm, _, file_norm, max_terms = ZEMAX_ZERNIKE[convention]
    path = Path(path)
    values = [(n, t) for n, s in _uncommented(read_text(path, f"{surface} coefficients")) for t in s.split()]
    if len(values) < 2:
        raise parse_error(path, values[-1][0] if values else None,
                          "file ends early; expected the number of terms, the normalisation radius and coefficients")
    (n0, t0), (n1, t1) = values[:2]
    try:
        n_terms = float(t0)  # "9" or, as some writers print every number, "9.000000E+000"
    except ValueError:
        n_terms = None
    if n_terms is None or not n_terms.is_integer():
        raise parse_error(path, n0, f"number of terms {t0!r} is not an integer")
    n_terms = int(n_terms)
    if not 1 <= n_terms <= max_terms:
        raise parse_error(path, n0, f"number of terms {n_terms} must be in 1..{max_terms} for {surface}")
    radius = parse_radius(path, n1, t1, "normalisation radius")
    body = values[2:]
    if len(body) != n_terms:
        where = body[n_terms][0] if len(body) > n_terms else values[-1][0]
        raise parse_error(path, where, f"{n_terms} terms declared, found {len(body)} coefficients")
    coeffs = parse_coefficients(path, body, to_nm, convention, lambda v: v * 1e3)  # mm -> um
    if normalised != file_norm:
        coeffs = convert_normalisation(coeffs, to_normalised=normalised)
    return coeffs, {"convention": convention, "surface_type": surface, "n_terms": n_terms,
                    "radius_mm": radius, "normalised": bool(normalised)}
