"""CODE V grid interferogram files (``.int``, ``GRD`` type) for sag and wavefront maps.

File layout (as written and read here)
--------------------------------------
::

    ! comment: '!' starts a comment anywhere on a line (CODE V command syntax)
    <title line, <= 80 characters>
    GRD <nx> <ny> SUR|WFR WVL <wvl_um> SSZ <ssz> [NDA <nda>] [XSC <x>] [YSC <y>] [NNB [<n>]]
    <nx * ny integers, any number per line, lines <= 80 characters>

Reading of the format (and where it comes from)
-----------------------------------------------
The CODE V Reference Manual is not in the searchable corpus; the reading below is
public code that exchanges these files (prysm ``read_codev_gridint``, whose comment
cites the manual's 80-character records and ``!`` comments, and its hand-written
fixture ``GRD 2 2 SUR WVL 1.0 SSZ 1 NDA -32768``; MATLAB/Python metalens writers that
emit ``round(waves * ssz)`` under ``GRD n n WFR WVL <um> SSZ <ssz>`` without ``NDA``),
plus the customary 16-bit conventions of interferometer exports. Items marked
*(unverified)* are assumptions to confirm against the manual:

* Counts are 16-bit integers: data within ``-32767..32767``; the customary no-data
  value is ``32767``. **A file without ``NDA`` is read with no-data = 32767**
  *(unverified default)*; in such a file a count outside ``-32767..32767`` (for
  example a ``-32768`` marker of another writer) is refused, naming the line and
  suggesting ``NDA -32768``. In a 16-bit file the marker values ``32767`` and
  ``-32768`` are never read as sag unless declared by ``NDA``: a marker that is not
  the declared ``NDA`` is refused. A file with an explicit ``NDA`` whose counts exceed
  16 bits (older 32-bit writers) is read, with ``meta["counts_16bit"] = False``.
* ``SSZ`` is the number of counts per wavelength ``WVL`` (µm):
  ``value_um = count / SSZ * WVL`` (prysm divides by WVL, right only for WVL = 1 µm).
  SSZ may be a decimal number (a public writer emits ``SSZ 1.0``).
* ``SUR``: surface deviation (height, single pass); ``WFR``: wavefront (OPD).
  Converting between them needs the geometry (for a reflective grating
  ``OPD = -(cos alpha + cos beta) * sag``), so a reader never does it silently:
  :func:`read_codev_int` with ``quantity="sag"`` refuses a ``WFR`` file unless the
  caller passes ``wfr_to_sag_factor`` (``sag = factor * OPD``; see
  :mod:`pipeline.io.codev_quantity`), and ``quantity="wavefront"`` refuses ``SUR``.
* ``GRD nx ny``: ``nx`` columns (x), ``ny`` rows (y), row-major from the top row (+y),
  each row from -x to +x *(unverified; interferometer image order)*.
* ``XSC``/``YSC`` (aperture scaling) and ``NNB`` (with or without a value) are read
  and kept in ``meta``; they do not change the grid we return.
* The file has no physical spacing. We write the extent into the title line as
  ``EXTENT_MM x0 x1 y0 y1`` (centres of the first/last samples, mm) and read it back;
  for files without it the caller passes ``extent_mm`` or ``spacing_mm``.
* Lines may end in LF or CRLF.

SSZ choice and quantisation
---------------------------
The writer picks ``SSZ`` so that the largest ``|value|`` of the map maps to
:data:`MAX_COUNT` = 32766 counts (one below the no-data value, so no count can equal
``NDA`` = 32767): ``SSZ = MAX_COUNT * WVL / max|value|``, rounded *down* to 6
significant digits. One count is then ``WVL / SSZ ≈ max|value| / 32766`` µm and the
quantisation error at most half of that (a 1 µm map: 0.015 nm). ``ssz=`` overrides it
(for instance to force an integer SSZ); counts past 32766 are then refused.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np

from optics.sagmap import SagMap
from pipeline.io.codev_header import DATA_TYPES, parse_keywords, split_int_file
from pipeline.io.codev_quantity import check_request, grating_wfr_to_sag_factor, sag_factor
from pipeline.io.common import ascii_label, atomic_write, parse_error
from pipeline.io.gridding import GridUnknownError, grid_from_options

__all__ = ["GridUnknownError", "write_codev_int", "read_codev_int", "grating_wfr_to_sag_factor", "choose_ssz",
           "MAX_COUNT", "CODEV_NDA"]

#: Largest |count| written: one below the no-data value.
MAX_COUNT = 32766
#: No-data value written, and assumed for files without ``NDA``.
CODEV_NDA = 32767
_MARKERS = (32767, -32768)  # 16-bit values that only ever mean "no data"
#: Wavelengths (µm) a test interferometer works at: UV to thermal infrared. A WVL outside is
#: a unit slip (632.8 for a HeNe's 0.6328 µm), which would scale every height 1000 times.
WVL_RANGE_UM = (0.1, 30.0)
_LINE_MAX = 80
_VALUED = {"WVL": float, "SSZ": float, "NDA": int, "XSC": float, "YSC": float}
_OTHER_FILE_TYPES = ("ZFR", "ZRN", "DEF", "FIL", "ZSD")  # other INT variants, not grids
_EXTENT_RE = re.compile(r"EXTENT_MM\s+(\S+)\s+(\S+)\s+(\S+)\s+(\S+)")


def choose_ssz(max_abs: float, wavelength_um: float) -> float:
    """SSZ that maps ``max_abs`` (µm) to :data:`MAX_COUNT` counts, rounded down to 6 digits.

    Returns 1 for an all-zero map (any SSZ is exact there).
    """
    if not (np.isfinite(max_abs) and max_abs > 0):
        return 1.0
    ideal = MAX_COUNT * wavelength_um / max_abs
    scale = 10.0 ** (5 - math.floor(math.log10(ideal)))
    ssz = math.floor(ideal * scale) / scale
    return float(f"{ssz:.6g}")  # the exact value the header will carry


def _title(label: str, x_mm: np.ndarray, y_mm: np.ndarray) -> str:
    for fmt in ("%.12g", "%.8g"):
        ext = "EXTENT_MM " + " ".join(fmt % v for v in (x_mm[0], x_mm[-1], y_mm[0], y_mm[-1]))
        if len(ext) <= _LINE_MAX - 2:
            break
    room = _LINE_MAX - len(ext) - 1
    # '!' starts a comment for CODE V and for our reader: never put one in the title
    clean = ascii_label((label or "cryograting").replace("!", " "), room) or "cryograting"  # 80-byte records
    return f"{clean} {ext}".strip()


def write_codev_int(
    sagmap: SagMap,
    path: str | Path,
    kind: str = "SUR",
    wavelength_um: float = 0.6328,
    ssz: float | None = None,
) -> Path:
    """Write a map as a 16-bit CODE V ``GRD`` interferogram file (``NDA 32767``).

    Parameters
    ----------
    sagmap : SagMap
        Map to write; ``sag_um`` is surface height (``kind="SUR"``) or wavefront
        (``kind="WFR"``) in µm, NaN where invalid (written as ``NDA``).
    path : str or Path
        Output file (written atomically).
    kind : {"SUR", "WFR"}
        CODE V data type keyword.
    wavelength_um : float
        ``WVL``: the wavelength the counts refer to (µm), > 0.
    ssz : float, optional
        Counts per wavelength. Default :func:`choose_ssz` (largest |value| ->
        32766 counts). An explicit value must keep every count within ±32766.

    Returns
    -------
    Path
        The written path. One count is ``WVL / SSZ`` µm; the quantisation error is
        at most half a count.
    """
    kind = str(kind).upper()
    if kind not in DATA_TYPES:
        raise ValueError(f"kind={kind!r} is not a CODE V grid type; use one of {DATA_TYPES}")
    if not (np.isfinite(wavelength_um) and wavelength_um > 0):
        raise ValueError(f"wavelength_um={wavelength_um!r} must be a finite number > 0")
    s = np.asarray(sagmap.sag_um, float)
    if np.isinf(s).any():
        raise ValueError(f"map {sagmap.label!r} has infinite values; CODE V INT holds finite data or NDA")
    valid = np.isfinite(s)
    max_abs = float(np.abs(s[valid]).max()) if valid.any() else 0.0
    if ssz is None:
        ssz = choose_ssz(max_abs, wavelength_um)
    else:
        if not (np.isfinite(ssz) and ssz > 0):
            raise ValueError(f"ssz={ssz!r} must be a finite number > 0")
        ssz = float(f"{float(ssz):.10g}")
    counts = np.full(s.shape, CODEV_NDA, dtype=np.int64)
    counts[valid] = np.rint(s[valid] / wavelength_um * ssz).astype(np.int64)
    top = int(np.abs(counts[valid]).max()) if valid.any() else 0
    if top > MAX_COUNT:
        raise ValueError(
            f"ssz={ssz:g} gives counts up to {top} for max |value| {max_abs:g} um; CODE V INT "
            f"counts must stay within +-{MAX_COUNT}: use ssz <= {MAX_COUNT * wavelength_um / max_abs:.6g}"
        )
    ny, nx = s.shape
    # file order: top row (+y) first, x increasing along a row; our arrays have y increasing
    tokens = counts[::-1].ravel().astype(str)
    width = int(np.char.str_len(tokens).max())
    per_line = max(1, (_LINE_MAX + 1) // (width + 1))
    padded = np.char.rjust(tokens, width)
    lines = [" ".join(padded[i:i + per_line]) for i in range(0, padded.size, per_line)]
    header = f"GRD {nx} {ny} {kind} WVL {wavelength_um:.10g} SSZ {ssz:.10g} NDA {CODEV_NDA}"
    path = Path(path)
    with atomic_write(path) as fh:
        fh.write(_title(sagmap.label, sagmap.x_mm, sagmap.y_mm) + "\n")
        fh.write(header + "\n")
        fh.write("\n".join(lines) + "\n")
    return path


def _grid_coordinates(path, nx, ny, title, extent_mm, spacing_mm):
    given = grid_from_options(nx, ny, extent_mm, spacing_mm)
    m = _EXTENT_RE.search(title)
    try:
        own = None if m is None else [float(g) for g in m.groups()]
    except ValueError:
        own = None
    if given is not None:
        if own is not None:  # the file says its grid too: a contradiction is not settled by silently taking one
            steps = [(own[1] - own[0]) / (nx - 1), (own[3] - own[2]) / (ny - 1)]
            got = [given[0][1] - given[0][0], given[1][1] - given[1][0]]
            if not np.allclose(steps, got, rtol=1e-6):
                raise parse_error(path, None, f"the title's {m.group(0)!r} gives a {steps[0]:g} x {steps[1]:g} mm "
                                              f"step but the {given[2]} gives {got[0]:g} x {got[1]:g} mm; leave "
                                              "the option out, or correct the file's title")
        return given
    if m:
        if own is None:
            raise parse_error(path, None, f"title EXTENT_MM {m.group(0)!r} is not four numbers")
        x0, x1, y0, y1 = own
        if not (x1 > x0 and y1 > y0):
            raise parse_error(path, None, f"title EXTENT_MM {m.group(0)!r} must have max > min")
        return np.linspace(x0, x1, nx), np.linspace(y0, y1, ny), "title EXTENT_MM"
    raise GridUnknownError(f"{path}: CODE V INT files carry no physical grid size and the title has no EXTENT_MM")


def _parse_header(path, lineno: int, line: str) -> dict:
    tok = line.split()
    if not tok or tok[0].upper() != "GRD":
        if tok and tok[0].upper() in _OTHER_FILE_TYPES:
            hint = " (a Zernike deck: read it with pipeline.io.codev_zfr.read_codev_zernike)" \
                if tok[0].upper() == "ZFR" else ""
            raise parse_error(path, lineno, f"INT type {tok[0]!r} is not a grid; only GRD grid files{hint}")
        raise parse_error(path, lineno, f"header must start with 'GRD nx ny', found {line.strip()[:40]!r}")
    try:
        nx, ny = int(tok[1]), int(tok[2])
    except (IndexError, ValueError):
        raise parse_error(path, lineno, f"'GRD' must be followed by two integers nx ny, found {tok[1:3]}") from None
    if nx < 2 or ny < 2:
        raise parse_error(path, lineno, f"GRD {nx} {ny}: need at least 2 x 2 samples")
    # NNB: a flag for some writers, keyword + value for others
    hdr = {"nx": nx, "ny": ny, **parse_keywords(path, lineno, tok[3:], _VALUED, flags=("NNB",))}
    for key in ("WVL", "SSZ"):
        if key not in hdr:
            raise parse_error(path, lineno, f"header has no {key} (needed to convert counts to um)")
    if not WVL_RANGE_UM[0] <= hdr["WVL"] <= WVL_RANGE_UM[1]:
        raise parse_error(path, lineno, f"WVL {hdr['WVL']:g} is outside {WVL_RANGE_UM[0]:g}..{WVL_RANGE_UM[1]:g}: "
                                        "the wavelength is in µm (a 632.8 is nm, 0.6328 µm)")
    return hdr


def _line_of(body, index: int) -> int:
    """File line number of the ``index``-th data value."""
    seen = 0
    for n, s in body:
        seen += len(s.split())
        if seen > index:
            return n
    return body[-1][0]


def _read_counts(path, hdr_line, body, nx, ny):
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
        raise parse_error(path, _line_of(body, expected),
                          f"wrong count: GRD {nx} {ny} needs {expected} values, found {counts.size}")
    return counts


def _no_data_mask(path, body, counts, nda):
    """NaN mask from ``NDA`` (or the customary 32767), refusing ambiguous markers."""
    if nda is None:
        bad = np.flatnonzero(np.abs(counts) > 32767)
        if bad.size:
            v = int(counts[bad[0]])
            raise parse_error(path, _line_of(body, bad[0]),
                              f"count {v} is outside the 16-bit data range -32767..32767 and the header "
                              f"has no NDA; if {v} marks missing data, add 'NDA {v}' to the GRD line")
        return counts == CODEV_NDA
    wide = np.abs(counts[counts != nda]) > 32767
    if not wide.any():  # a 16-bit file: the customary markers can only mean "no data"
        stray = np.flatnonzero(np.isin(counts, [m for m in _MARKERS if m != nda]))
        if stray.size:
            v = int(counts[stray[0]])
            raise parse_error(path, _line_of(body, stray[0]),
                              f"count {v} is a 16-bit no-data marker but the header declares NDA {nda}; "
                              "fix NDA (or the data) so no-data has one value")
    return counts == nda


def _read_grid(path):
    path = Path(path)
    title, (hdr_line, hdr_text), body = split_int_file(path, "CODE V INT", "GRD nx ny")
    hdr = _parse_header(path, hdr_line, hdr_text)
    nx, ny = hdr["nx"], hdr["ny"]
    counts = _read_counts(path, hdr_line, body, nx, ny)
    nda = hdr.get("NDA")
    nodata = _no_data_mask(path, body, counts, nda)
    values = counts.astype(float) / hdr["SSZ"] * hdr["WVL"]
    values[nodata] = np.nan
    values = values.reshape(ny, nx)[::-1]  # file is top row (+y) first
    valid = counts[~nodata]
    meta = {"codev_type": hdr["type"], "wavelength_um": hdr["WVL"], "ssz": hdr["SSZ"],
            "nda": CODEV_NDA if nda is None else nda, "nda_declared": nda is not None,
            "counts_16bit": bool(valid.size == 0 or np.abs(valid).max() <= 32767),
            "title": title, "format": "codev_int"}
    for key in ("XSC", "YSC", "NNB"):
        if key in hdr:
            meta[key.lower()] = hdr[key]
    label = _EXTENT_RE.sub("", title).strip() or path.stem
    return values, label, meta


def read_codev_int(
    path: str | Path,
    extent_mm: tuple[float, float, float, float] | None = None,
    spacing_mm: float | tuple[float, float] | None = None,
    quantity: str = "sag",
    wfr_to_sag_factor: float | None = None,
) -> SagMap:
    """Read a CODE V ``GRD`` interferogram file into a :class:`SagMap`.

    Parameters
    ----------
    path : str or Path
        The ``.int`` file.
    extent_mm : (xmin, xmax, ymin, ymax), optional
        Coordinates of the first/last sample centres (mm), for a file whose title has no
        ``EXTENT_MM``; where it has one, its step must agree (the origin is the option's).
    spacing_mm : float or (dx, dy), optional
        Sample spacing (mm); the grid is then centred on the origin. Used when
        ``extent_mm`` is not given; a title's ``EXTENT_MM`` step must agree with it.
    quantity : {"sag", "wavefront"}
        What the returned ``sag_um`` holds. ``"sag"`` (default): surface height; a
        ``WFR`` file is refused unless ``wfr_to_sag_factor`` is given.
        ``"wavefront"``: OPD in µm; a ``SUR`` file is refused.
    wfr_to_sag_factor : float, optional
        Only with ``quantity="sag"`` and a ``WFR`` file: ``sag = factor * OPD``
        (for a reflective grating :func:`grating_wfr_to_sag_factor`; for a mirror
        at normal incidence ``-0.5``). Recorded in ``meta``.

    Returns
    -------
    SagMap
        Values in µm, NaN at no-data (``NDA``, or 32767 when the header has none);
        ``meta`` holds ``codev_type``, ``wavelength_um``, ``ssz``, ``nda``,
        ``nda_declared``, ``counts_16bit``, ``title``, ``grid_source`` and
        ``xsc``/``ysc``/``nnb`` when present.

    Raises
    ------
    ValueError
        Naming the file and line for a bad header, a non-integer value, a truncated
        file, too many values, a count outside 16 bits without ``NDA`` or a stray
        no-data marker; naming ``extent_mm``/``spacing_mm`` when the size is unknown;
        naming ``quantity``/``wfr_to_sag_factor`` when the data type does not match.
    """
    check_request(quantity, wfr_to_sag_factor)
    values, label, meta = _read_grid(path)
    factor = sag_factor(path, meta["codev_type"], quantity, wfr_to_sag_factor)
    if wfr_to_sag_factor is not None:
        values = values * factor
        meta.update(wfr_to_sag_factor=factor, converted_from="WFR")
    meta["quantity"] = quantity
    ny, nx = values.shape
    x, y, meta["grid_source"] = _grid_coordinates(path, nx, ny, meta["title"], extent_mm, spacing_mm)
    return SagMap(x, y, values, label, meta)
