"""CODE V grid interferogram files (``.int``, ``GRD`` type) for sag and wavefront maps.

File layout (as written and read here)
--------------------------------------
::

    ! optional comment lines start with '!'
    <title line, <= 80 characters>
    GRD <nx> <ny> SUR WVL <wvl_um> SSZ <ssz> NDA <nda> [XSC <x>] [YSC <y>]
    <nx * ny integers, free format, lines <= 80 characters>

Reading of the format (and where it comes from)
-----------------------------------------------
The CODE V Reference Manual itself was not in the searchable corpus; the reading
below is the brief's description cross-checked against public code that exchanges
these files (prysm ``read_codev_gridint`` and its hand-written test fixture
``GRD 2 2 SUR WVL 1.0 SSZ 1 NDA -32768``, two MATLAB/Python metalens writers that emit
``round(waves * ssz)`` under ``GRD n n WFR WVL <um> SSZ <ssz>``, and a Tcl converter
writing ``ZFR n WFR WVL 0.6328 SSZ 1.0``). Treat the items marked *(unverified)* as
assumptions to confirm against the manual before relying on them in CODE V:

* ``SSZ`` is the number of integer counts per wavelength ``WVL`` (µm). Hence
  ``value_um = count / SSZ * WVL``. (prysm's reader divides by WVL instead of
  multiplying; that is only right for WVL = 1 µm, which its fixture happens to use.)
* ``SUR``: the data are *surface* deviation (height, single pass) in those units;
  ``WFR``: *wavefront* (OPD) deviation. We do not convert between them (that needs
  the angles of incidence on the grating); a WFR map is returned as a SagMap whose
  ``sag_um`` holds wavefront µm, with ``meta["codev_type"] = "WFR"``.
* ``NDA`` is the integer that marks a sample without data.
* ``GRD nx ny``: ``nx`` columns (x) and ``ny`` rows (y). Data are row-major starting
  at the top row (+y), each row from -x to +x, rows going down to -y *(unverified;
  the brief's statement, consistent with interferometer image order)*. prysm
  reshapes ``(nx, ny)`` instead, which swaps rows and columns of non-square maps.
* ``XSC``/``YSC`` are accepted and kept in ``meta`` but do not change the grid we
  return *(their aperture-scaling meaning is not modelled here)*.
* The file has no physical spacing. We write the extent into the title line as
  ``EXTENT_MM x0 x1 y0 y1`` (centres of the first/last samples, mm) and read it back;
  for files without it the caller passes ``extent_mm`` or ``spacing_mm``.

SSZ choice
----------
A public writer picked a fixed scale that overflows 16-bit integers for maps above
~1 µm. Here ``SSZ = round(WVL / resolution_um)`` with ``resolution_um = 1e-5``
(0.01 nm per count, quantisation error <= 0.005 nm); if the largest ``|count|`` would
exceed ``MAX_COUNT = 10**9`` (well inside int32, so readers using 32-bit integers
are safe) SSZ is lowered until it fits. At 0.6328 µm that keeps 0.01 nm steps for
maps up to 10 mm. ``NDA = -2147483647`` (int32 min + 1) can never collide with data.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np

from optics.sagmap import SagMap
from pipeline.io_common import atomic_write, numbered_lines, parse_error, read_text

__all__ = ["write_codev_int", "read_codev_int", "MAX_COUNT", "CODEV_NDA"]

MAX_COUNT = 10**9
CODEV_NDA = -2147483647
_LINE_MAX = 80
_TYPES = ("SUR", "WFR")
_VALUED = {"WVL": float, "SSZ": float, "NDA": int, "XSC": float, "YSC": float}
_OTHER_FILE_TYPES = ("ZFR", "ZRN", "DEF", "FIL", "ZSD")  # other INT variants we do not read
_EXTENT_RE = re.compile(r"EXTENT_MM\s+(\S+)\s+(\S+)\s+(\S+)\s+(\S+)")


def _choose_ssz(max_abs_um: float, wavelength_um: float, resolution_um: float) -> int:
    ssz = max(1, int(round(wavelength_um / resolution_um)))
    if max_abs_um / wavelength_um * ssz > MAX_COUNT:
        ssz = int(math.floor(MAX_COUNT * wavelength_um / max_abs_um))
        if ssz < 1:
            raise ValueError(
                f"sag of {max_abs_um:g} um does not fit CODE V INT integers at WVL {wavelength_um} um "
                f"(needs |count| <= {MAX_COUNT} with SSZ >= 1)"
            )
    return ssz


def _title(label: str, x_mm: np.ndarray, y_mm: np.ndarray) -> str:
    for fmt in ("%.12g", "%.8g"):
        ext = "EXTENT_MM " + " ".join(fmt % v for v in (x_mm[0], x_mm[-1], y_mm[0], y_mm[-1]))
        if len(ext) <= _LINE_MAX - 2:
            break
    room = _LINE_MAX - len(ext) - 1
    # a leading '!' would turn the title into a comment line for CODE V and for our reader
    clean = " ".join((label or "cryograting").split()).lstrip("!").strip()[:room] or "cryograting"
    return f"{clean} {ext}".strip()


def write_codev_int(
    sagmap: SagMap,
    path: str | Path,
    kind: str = "SUR",
    wavelength_um: float = 0.6328,
    resolution_um: float = 1e-5,
) -> Path:
    """Write a map as a CODE V ``GRD`` interferogram file.

    Parameters
    ----------
    sagmap : SagMap
        Map to write; ``sag_um`` is surface height (``kind="SUR"``) or wavefront
        (``kind="WFR"``) in µm, NaN where invalid.
    path : str or Path
        Output file (written atomically).
    kind : {"SUR", "WFR"}
        CODE V data type keyword.
    wavelength_um : float
        ``WVL``: the wavelength the integer counts refer to (µm), > 0.
    resolution_um : float
        Target size of one count (µm), > 0; SSZ is ``round(WVL / resolution_um)``,
        lowered if the largest count would exceed :data:`MAX_COUNT`.

    Returns
    -------
    Path
        The written path. Quantisation error is at most ``0.5 * WVL / SSZ`` µm.
    """
    kind = str(kind).upper()
    if kind not in _TYPES:
        raise ValueError(f"kind={kind!r} is not a CODE V grid type; use one of {_TYPES}")
    for name, v in (("wavelength_um", wavelength_um), ("resolution_um", resolution_um)):
        if not (np.isfinite(v) and v > 0):
            raise ValueError(f"{name}={v!r} must be a finite number > 0")
    s = sagmap.sag_um
    ny, nx = s.shape
    ssz = _choose_ssz(float(np.nanmax(np.abs(s))), wavelength_um, resolution_um)
    valid = np.isfinite(s)
    counts = np.full(s.shape, CODEV_NDA, dtype=np.int64)
    counts[valid] = np.rint(s[valid] / wavelength_um * ssz).astype(np.int64)
    # file order: top row (+y) first, x increasing along a row; our arrays have y increasing
    tokens = counts[::-1].ravel().astype(str)
    width = int(np.char.str_len(tokens).max())
    per_line = max(1, (_LINE_MAX + 1) // (width + 1))
    padded = np.char.rjust(tokens, width)
    lines = [" ".join(padded[i:i + per_line]) for i in range(0, padded.size, per_line)]
    header = f"GRD {nx} {ny} {kind} WVL {wavelength_um:.10g} SSZ {ssz} NDA {CODEV_NDA}"
    path = Path(path)
    with atomic_write(path) as fh:
        fh.write(_title(sagmap.label, sagmap.x_mm, sagmap.y_mm) + "\n")
        fh.write(header + "\n")
        fh.write("\n".join(lines) + "\n")
    return path


def _axis(n: int, lo: float, hi: float) -> np.ndarray:
    return np.linspace(lo, hi, n)


def _grid_coordinates(path, nx, ny, title, extent_mm, spacing_mm):
    if extent_mm is not None:
        x0, x1, y0, y1 = (float(v) for v in extent_mm)
        if not (x1 > x0 and y1 > y0):
            raise ValueError(f"extent_mm={tuple(extent_mm)} must be (xmin, xmax, ymin, ymax) with max > min")
        return _axis(nx, x0, x1), _axis(ny, y0, y1), "extent_mm argument"
    if spacing_mm is not None:
        dx, dy = (spacing_mm, spacing_mm) if np.isscalar(spacing_mm) else tuple(spacing_mm)
        if not (dx > 0 and dy > 0):
            raise ValueError(f"spacing_mm={spacing_mm!r} must be > 0 (one value or (dx, dy))")
        hx, hy = 0.5 * (nx - 1) * dx, 0.5 * (ny - 1) * dy
        return _axis(nx, -hx, hx), _axis(ny, -hy, hy), "spacing_mm argument, centred"
    m = _EXTENT_RE.search(title)
    if m:
        try:
            x0, x1, y0, y1 = (float(g) for g in m.groups())
        except ValueError:
            raise parse_error(path, None, f"title EXTENT_MM {m.group(0)!r} is not four numbers") from None
        if not (x1 > x0 and y1 > y0):
            raise parse_error(path, None, f"title EXTENT_MM {m.group(0)!r} must have max > min")
        return _axis(nx, x0, x1), _axis(ny, y0, y1), "title EXTENT_MM"
    raise ValueError(
        f"{path}: CODE V INT files carry no physical grid size and the title has no EXTENT_MM; "
        "pass extent_mm=(xmin, xmax, ymin, ymax) or spacing_mm (mm)"
    )


def _parse_header(path, lineno: int, line: str) -> dict:
    tok = line.split()
    if not tok or tok[0].upper() != "GRD":
        if tok and tok[0].upper() in _OTHER_FILE_TYPES:
            raise parse_error(path, lineno, f"INT type {tok[0]!r} is not supported; only GRD grid files")
        raise parse_error(path, lineno, f"header must start with 'GRD nx ny', found {line.strip()[:40]!r}")
    try:
        nx, ny = int(tok[1]), int(tok[2])
    except (IndexError, ValueError):
        raise parse_error(path, lineno, f"'GRD' must be followed by two integers nx ny, found {tok[1:3]}") from None
    if nx < 2 or ny < 2:
        raise parse_error(path, lineno, f"GRD {nx} {ny}: need at least 2 x 2 samples")
    hdr: dict = {"nx": nx, "ny": ny, "type": None}
    i = 3
    while i < len(tok):
        key = tok[i].upper()
        if key in _TYPES:
            if hdr["type"] is not None:
                raise parse_error(path, lineno, f"two data types {hdr['type']!r} and {key!r}")
            hdr["type"] = key
            i += 1
            continue
        if key not in _VALUED:
            raise parse_error(
                path, lineno,
                f"unknown header keyword {tok[i]!r}; valid are {list(_TYPES)} and {sorted(_VALUED)}",
            )
        if i + 1 >= len(tok):
            raise parse_error(path, lineno, f"keyword {key} has no value")
        try:
            hdr[key] = _VALUED[key](tok[i + 1])
        except ValueError:
            kind = "an integer" if _VALUED[key] is int else "a number"
            raise parse_error(path, lineno, f"{key} value {tok[i + 1]!r} is not {kind}") from None
        i += 2
    if hdr["type"] is None:
        raise parse_error(path, lineno, f"header has no data type; expected one of {list(_TYPES)}")
    for key in ("WVL", "SSZ"):
        if key not in hdr:
            raise parse_error(path, lineno, f"header has no {key} (needed to convert counts to um)")
        if not hdr[key] > 0:
            raise parse_error(path, lineno, f"{key}={hdr[key]!r} must be > 0")
    return hdr


def read_codev_int(
    path: str | Path,
    extent_mm: tuple[float, float, float, float] | None = None,
    spacing_mm: float | tuple[float, float] | None = None,
) -> SagMap:
    """Read a CODE V ``GRD`` interferogram file into a :class:`SagMap`.

    Parameters
    ----------
    path : str or Path
        The ``.int`` file.
    extent_mm : (xmin, xmax, ymin, ymax), optional
        Coordinates of the first/last sample centres (mm). Overrides the title.
    spacing_mm : float or (dx, dy), optional
        Sample spacing (mm); the grid is then centred on the origin. Used when
        ``extent_mm`` is not given; overrides the title.

    Returns
    -------
    SagMap
        ``sag_um`` in µm (surface for SUR, wavefront for WFR), NaN at ``NDA``;
        ``meta`` holds ``codev_type``, ``wavelength_um``, ``ssz``, ``nda``, ``title``,
        ``xsc``/``ysc`` when present and ``grid_source``.

    Raises
    ------
    ValueError
        Naming the file and line for a bad header, a non-integer value, a truncated
        file or too many values; naming ``extent_mm``/``spacing_mm`` when the size is
        unknown.
    """
    path = Path(path)
    lines = [(n, s) for n, s in numbered_lines(read_text(path, "CODE V INT")) if s.strip() and not s.lstrip().startswith("!")]
    if len(lines) < 2:
        raise parse_error(path, lines[-1][0] if lines else None, "file ends before the GRD header line")
    title = lines[0][1].strip()
    hdr_line, hdr_text = lines[1]
    hdr = _parse_header(path, hdr_line, hdr_text)
    nx, ny = hdr["nx"], hdr["ny"]
    body = lines[2:]
    try:
        counts = np.array(" ".join(s for _, s in body).split()).astype(np.int64)
    except (ValueError, OverflowError):
        for n, s in body:  # slow path only to name the offending line
            for t in s.split():
                try:
                    v = int(t)
                except ValueError:
                    raise parse_error(path, n, f"data value {t!r} is not an integer") from None
                if abs(v) >= 2**63:
                    raise parse_error(path, n, f"data value {t} is outside the 64-bit integer range") from None
        raise parse_error(path, None, "data values could not be read as integers") from None
    expected = nx * ny
    if counts.size < expected:
        last = body[-1][0] if body else hdr_line
        raise parse_error(path, last, f"truncated: GRD {nx} {ny} needs {expected} values, found {counts.size}")
    if counts.size > expected:
        seen = 0
        for n, s in body:
            seen += len(s.split())
            if seen > expected:
                raise parse_error(path, n, f"wrong count: GRD {nx} {ny} needs {expected} values, found {counts.size}")
    nda = hdr.get("NDA")
    sag = counts.astype(float) / hdr["SSZ"] * hdr["WVL"]
    if nda is not None:
        sag[counts == nda] = np.nan
    sag = sag.reshape(ny, nx)[::-1]  # file is top row (+y) first
    x, y, source = _grid_coordinates(path, nx, ny, title, extent_mm, spacing_mm)
    meta = {"codev_type": hdr["type"], "wavelength_um": hdr["WVL"], "ssz": hdr["SSZ"], "nda": nda,
            "title": title, "grid_source": source, "format": "codev_int"}
    for key in ("XSC", "YSC"):
        if key in hdr:
            meta[key.lower()] = hdr[key]
    label = _EXTENT_RE.sub("", title).strip() or path.stem
    return SagMap(x, y, sag, label, meta)
