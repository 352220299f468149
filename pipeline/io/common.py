"""Small helpers shared by the interchange readers and writers.

* :func:`atomic_write`, :func:`atomic_path` — every writer goes through them, so a crash
  or a full disk never leaves a half-written file under the final name (tmp file in the
  same directory, then ``os.replace``); they live in :mod:`fea.atomic`, which the FEA
  layer's caches use too.
* :func:`parse_error` — one wording for malformed files: file, line number, what was
  found and what is valid.
* :func:`numbered_lines` — text lines with 1-based line numbers for those messages.
* :func:`read_text` / :func:`read_csv_columns` — a file's text (UTF-8, or UTF-16/32 with
  a byte-order mark) and the numeric columns of a delimited table with a header, errors by
  line; lines before the header (an export's title, date, exposure) are skipped. Tables other code writes are taken as they come: comma, semicolon, tab or
  whitespace delimited (told from the header line and the first data row), a header
  commented out (``# offset_um intensity``, as ``numpy.savetxt`` writes it), a column in
  another length unit than the one asked for (``x [m]``, ``sag_nm``, ``Offset (mm)``,
  ``Offset / µm``) converted to it, missing-value cells (:data:`MISSING_CELLS`) as NaN,
  Fortran exponents, a trailing delimiter or comment on a row, Windows-1252 text. Decimal
  commas (a European locale's export: ``-60,5;0,013``) are read where the delimiter is not a
  comma and the table says which separator it uses (:func:`decimal_commas`); a table where a
  comma could be a thousands separator (``1,250`` is 1.25 or 1250 by the writer's locale) is
  refused by name.
"""

from __future__ import annotations

import codecs
import csv
import io
import os
import uuid
import re
from pathlib import Path
from typing import Callable

import numpy as np

from fea.atomic import atomic_path, atomic_write
from pipeline.io.columns import ANY_UNIT, INTENSITY_UNITS, matches
from pipeline.io.gridding import SAG_UNITS_TO_UM, WAVE_UNITS

__all__ = ["atomic_write", "atomic_path", "ascii_label", "parse_error", "numbered_lines", "read_text",
           "decode_text", "read_csv_columns", "read_csv_choices", "decimal_commas", "PREAMBLE_LINES",
           "MISSING_CELLS", "split_fields"]


#: Spellings of the non-ASCII characters a label of ours or a user's may carry.
_ASCII_FOR = {"µ": "u", "μ": "u", "Δ": "d", "°": "deg", "Å": "A", "λ": "lambda", "±": "+-", "×": "x"}


def ascii_label(text: str, max_len: int) -> str:
    """``text`` as printable ASCII of at most ``max_len`` characters (bytes), whitespace and
    control characters collapsed to single spaces: for headers that formats define as ASCII
    records (a CODE V title line, a FITS card), which a label read from a file (``µ``, a
    newline) must not break."""
    import unicodedata

    t = "".join(_ASCII_FOR.get(c, c) for c in str(text))
    t = unicodedata.normalize("NFKD", t).encode("ascii", "ignore").decode("ascii")
    t = "".join(c if c.isprintable() else " " for c in t)
    return " ".join(t.split())[:max_len]


def parse_error(path: str | Path, line: int | None, message: str) -> ValueError:
    """A ``ValueError`` whose text starts with ``"<file>, line <n>: "``."""
    where = f"{path}, line {line}" if line is not None else f"{path}"
    return ValueError(f"{where}: {message}")


def read_text(path: str | Path, what: str) -> str:
    """Whole text of ``path``; a missing/unreadable file becomes a ``ValueError`` naming it."""
    path = Path(path)
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise ValueError(f"{what} {path}: file does not exist") from None
    except OSError as exc:
        raise ValueError(f"{what} {path}: cannot read ({exc.strerror or exc})") from None
    binary = _binary_kind(raw)
    if binary is not None:
        raise ValueError(f"{what} {path}: is a binary file ({binary}), not a text table; save it as delimited text "
                         "(CSV) with a header line")
    return decode_text(raw, path, what)


#: Leading bytes of binary files a text table is mistaken for, and what each is.
_BINARY_MAGIC = ((b"\x89HDF", "HDF5 or NetCDF-4"), (b"CDF\x01", "NetCDF-3"), (b"CDF\x02", "NetCDF-3"),
                 (b"PK\x03\x04", "a zip archive: an Excel .xlsx workbook or a NumPy .npz"),
                 (b"\xd0\xcf\x11\xe0", "an Excel .xls workbook"), (b"\x93NUMPY", "a NumPy .npy array"))


def _binary_kind(raw: bytes) -> str | None:
    """What a binary file is (:data:`_BINARY_MAGIC`, else "NUL bytes" where its first 8 KiB
    hold one), or None for text. UTF-16/32 text holds NULs too and starts with its
    byte-order mark."""
    kind = next((k for magic, k in _BINARY_MAGIC if raw.startswith(magic)), None)
    if kind is not None:
        return kind
    if raw.startswith((codecs.BOM_UTF16_LE, codecs.BOM_UTF16_BE)) or b"\x00" not in raw[:8192]:
        return None
    return "NUL bytes"


def decode_text(raw: bytes, path: str | Path, what: str, strict: bool = False) -> str:
    """Text of a file's bytes: UTF-8 (a byte-order mark is dropped), or UTF-16/32 when
    the file starts with their byte-order mark (Windows tools write these).

    A file that is not UTF-8 is read as Windows-1252 (a Windows export's code page, whose
    bytes all decode; Latin-1 text reads the same but for 0x80-0x9F) unless ``strict``,
    which raises a ``ValueError`` naming the file and the byte offset."""
    for bom, enc in ((codecs.BOM_UTF32_LE, "utf-32"), (codecs.BOM_UTF32_BE, "utf-32"),
                     (codecs.BOM_UTF8, "utf-8-sig"), (codecs.BOM_UTF16_LE, "utf-16"), (codecs.BOM_UTF16_BE, "utf-16")):
        if raw.startswith(bom):
            break
    else:
        enc = "utf-8"
    try:
        text = raw.decode(enc)
    except UnicodeDecodeError as exc:
        if strict:
            raise ValueError(f"{what} {path}: is not {enc.upper()} text (undecodable byte at offset {exc.start}); "
                             "save it as UTF-8") from None
        # not UTF-8: a Windows export in its code page ("Offset [µm]" with µ as byte 0xB5)
        text = raw.decode("cp1252" if enc == "utf-8" else enc, errors="replace")
    return text.replace("\r\n", "\n").replace("\r", "\n")  # universal newlines, as open() in text mode


def _delimiter(header_line: str, data_line: str | None = None) -> str | None:
    """The table's delimiter: tab, ``;`` or ``,``, the first that the header line and the
    first data row ``data_line`` both hold (a tab-delimited table may have a comma inside a
    column's name, ``Intensity, counts``); without one in both, the header's alone (``,``
    ``;`` tab, in that order); else None (runs of whitespace)."""
    if data_line is not None:
        for d in ("\t", ";", ","):
            if d in header_line and d in data_line:
                return d
    for d in (",", ";", "\t"):
        if d in header_line:
            return d
    return None


def split_fields(line: str) -> list[str]:
    """The stripped fields of one delimited line, split at the delimiter it holds
    (:func:`_delimiter`: comma, semicolon, tab, else runs of whitespace)."""
    return [f.strip() for f in _split(line, _delimiter(line))]


def _split(line: str, delimiter: str | None) -> list[str]:
    if delimiter is None:  # a unit in brackets stays with its name: "x [mm]  sag (nm)"
        return re.sub(r"\s+(?=[\[(])", "", line).split()
    return next(csv.reader([line], delimiter=delimiter), [])


def _canonical_header(h: str) -> str:
    """``"X [mm]"``, ``"x (mm)"``, ``"x mm"``, ``"x / mm"`` -> ``"x_mm"``; lower case, unit
    brackets, the quantity-calculus slash and spaces turned into one underscore."""
    h = h.strip().lower()
    h = re.sub(r"\s*[\[(]\s*([^\])]*?)\s*[\])]\s*$", r"_\1", h)
    h = re.sub(r"^([^\s/]+)\s+/\s+(\S+)$", r"\1_\2", h)  # "Offset / µm" (ISO 80000-1)
    h = re.sub(r"\s*,\s*", "_", h)  # "Intensity, counts" (a comma in a name: the table is not comma-delimited)
    return re.sub(r"\s+", "_", h)


#: Cells that mark a missing value (a bad pixel, a masked point): read as NaN, which each
#: reader then masks or refuses by name (a coordinate must be finite).
MISSING_CELLS = frozenset({"", "na", "n/a", "nan", "-", "--", "null", "none", "missing"})


def _number(cell: str) -> float:
    """A cell's number: a :data:`MISSING_CELLS` marker is NaN, a Fortran exponent
    (``1.5D+03``) is read as ``1.5E+03``; a ValueError otherwise."""
    c = cell.strip()
    if c.lower() in MISSING_CELLS:
        return float("nan")
    try:
        return float(c)
    except ValueError:
        if re.fullmatch(r"[+-]?(\d+\.?\d*|\.\d+)[dD][+-]?\d+", c):
            return float(c.replace("d", "e").replace("D", "E"))
        raise


def _column(header: list[str], name: str) -> tuple[int, float] | None:
    """Index of column ``name`` in ``header`` and the factor to ``name``'s unit: the name
    itself, or ``<base>_<unit>`` in another length unit when ``name`` is ``<base>_<unit>``."""
    if name in header:
        return header.index(name), 1.0
    if name.endswith("_" + ANY_UNIT):
        return next(((i, 1.0) for i, h in enumerate(header) if matches(name, h)), None)
    base, _, unit = name.rpartition("_")
    if not base or unit not in SAG_UNITS_TO_UM:
        return None
    for i, h in enumerate(header):
        b, _, u = h.rpartition("_")
        if b == base and u in SAG_UNITS_TO_UM:
            return i, SAG_UNITS_TO_UM[u] / SAG_UNITS_TO_UM[unit]
    return None


#: A number written with a decimal comma (``1,25``, ``-0,5e-3``).
_DECIMAL_COMMA = re.compile(r"^[+-]?\d*,\d+([eE][+-]?\d+)?$")
#: A decimal-comma number that cannot be one with a thousands separator: not three digits
#: after the comma, a zero or empty integer part, or an exponent.
_SURELY_DECIMAL = re.compile(r"^[+-]?(\d*,(\d{1,2}|\d{4,})|0?,\d+|\d*,\d+[eE][+-]?\d+)$")


def decimal_commas(fields: list[str]) -> bool | None:
    """Whether a table's numeric ``fields`` use decimal commas: True where some field can only
    be a decimal-comma number (``0,5``, ``12,25``, ``1,5e-3``) and no field has a decimal
    point; None where they could (every comma-number has three digits after the comma and a
    non-zero integer part: ``1,250`` is 1.25 or 1250 by the writer's locale); False without
    comma-numbers. A table with both separators is not a decimal-comma table."""
    commas = [f for f in fields if _DECIMAL_COMMA.match(f)]
    if not commas or any("." in f for f in fields):
        return False
    return True if any(_SURELY_DECIMAL.match(f) for f in commas) else None

#: Lines of preamble (before the header line) a table may have.
PREAMBLE_LINES = 50
#: A header-less row of this many numbers is a matrix (a map or image saved as a grid), not a
#: table the readers take: those have a few columns (a profile 2, a map or image 3, an FE
#: node table 7 with its number).
MATRIX_NUMBERS = 8


def _header(line: str, data_line: str | None = None) -> list[str]:
    """A header line's column names, canonical (:func:`_canonical_header`), split at the
    delimiter it shares with the data row after it (:func:`_delimiter`)."""
    return [_canonical_header(h) for h in _split(line, _delimiter(line, data_line))]


def _found(header: list[str], alts: tuple[str, ...]):
    """``(name, (index, factor))`` of the first of ``alts`` that ``header`` has, else None."""
    return next(((a, f) for a in alts if (f := _column(header, a)) is not None), None)


def _numeric(line: str, delimiter: str | None) -> bool:
    """Whether every field of ``line`` is a number (a data row, not a header); where the
    delimiter is not a comma, a decimal comma (``-118,19``) is a number too."""
    fields = [f.strip() for f in _split(line, delimiter) if f.strip()]
    try:
        for f in fields:
            float(f.replace(",", ".") if delimiter != "," and _DECIMAL_COMMA.match(f) else f)
    except ValueError:
        return False
    return bool(fields)


def _fast_csv_columns(text: str, names: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray] | None:
    """NumPy parse of a clean comma-separated file with the very column names (header on
    line 1, no blank or ragged lines); None means "use the line-by-line parser", which is
    the one that converts units, splits other delimiters and words the errors."""
    if "#" in text:
        return None  # comment lines: the line-by-line parser skips them
    head, _, body = text.partition("\n")
    header = [h.strip().lower() for h in head.split(",")]
    if not all(c in header for c in names) or not body.strip() or "\n\n" in body.rstrip("\n"):
        return None
    if any(line.count(",") != len(header) - 1 for line in body.rstrip("\n").split("\n")):
        return None  # ragged: let the slow parser name the line
    try:
        v = np.loadtxt(io.StringIO(body), delimiter=",", ndmin=2, dtype=float,
                       usecols=[header.index(c) for c in names])
    except ValueError:
        return None
    return v, np.arange(2, v.shape[0] + 2)


def read_csv_columns(path: Path, what: str, names: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray]:
    """Numeric columns ``names`` of a delimited table with a header; returns
    (values[n, k], line numbers[n]). Errors name the file and line.

    Names match case-insensitively, with ``[unit]``/``(unit)`` read as ``_unit``; a name
    ``<base>_<unit>`` with a length unit (nm, um, mm, m) also matches ``<base>`` in another
    length unit, converted. Other columns are ignored, ``#`` comment lines and blank lines
    skipped; the delimiter (comma, semicolon, tab or whitespace) is the header's. The header
    is the first line naming every column (within :data:`PREAMBLE_LINES` lines): a preamble
    before it (an export's title, date, exposure lines) is skipped. Units may also stand on a
    second header line, or in an astropy ECSV file's YAML header. A table without a
    header is refused, naming the header line to add."""
    v, lines, _ = read_csv_choices(path, what, tuple((n,) for n in names))
    return v, lines


def read_csv_choices(path: Path, what: str, choices: tuple[tuple[str, ...], ...],
                     hint: str | Callable[[list[str], list[str]], str] = ""
                     ) -> tuple[np.ndarray, np.ndarray, tuple[str, ...]]:
    """As :func:`read_csv_columns`, each column being the first of several alternative
    names that the header has (e.g. an offset in µm, else in pixels); returns (values[n, k]
    in the chosen names' units, line numbers[n], the chosen names). The file is read once.
    ``hint`` is added to the error when a column is missing: a text, or
    ``hint(missing, header)`` of the missing columns' first names and the header's names
    (:mod:`pipeline.io.columns` words what each quantity accepts)."""
    text = read_text(path, what)
    numbered = numbered_lines(text)
    # a data row's trailing comment ("-4.0,1.0  # hot pixel") is dropped
    lines_ = [(n, re.sub(r"\s+#.*$", "", t)) for n, t in numbered if t.strip() and not t.lstrip().startswith("#")]
    names = [alts[0] for alts in choices]
    if not lines_:
        raise parse_error(path, None, f"file is empty; expected a header with columns {names}")
    # The header is the first line naming every column: lines before it are a preamble
    # (an instrument's or a program's export: date, exposure, title lines), skipped.
    start = 0
    for k, (_, t) in enumerate(lines_[:PREAMBLE_LINES + 1]):
        after = lines_[k + 1][1] if k + 1 < len(lines_) else None
        if all(_found(_header(t, after), alts) is not None for alts in choices):
            start = k
            break
    hline, htext = lines_[start]
    if _numeric(htext, _delimiter(htext)):
        # no header line: numpy's savetxt and astropy's commented_header write it as the
        # last comment line before the data ("# offset_um intensity")
        commented = [(n, t.lstrip()[1:]) for n, t in numbered[:hline - 1] if t.lstrip().startswith("#")]
        if commented and all(_found(_header(commented[-1][1]), alts) is not None for alts in choices):
            hline, htext = commented[-1]
            lines_ = [(hline, htext)] + lines_[start:]
            start = 0
    delim = _delimiter(htext, lines_[start + 1][1] if len(lines_) > start + 1 else None)
    header = [_canonical_header(h) for h in _split(htext, delim)]
    units = _units_row(lines_[start + 1:start + 4], delim, len(header))
    if units is not None:  # a spreadsheet's second header line: "(um),(counts)" under "Offset,Intensity"
        units, drop = units
        lines_ = lines_[:start + 1] + lines_[start + 1 + drop:]
    else:  # astropy's ECSV: the units in the commented YAML header
        units = _ecsv_units(text, len(header))
    if units is not None:
        header = [h if "_" in h or not u else _canonical_header(f"{h} [{u}]") for h, u in zip(header, units)]
    found = [_found(header, alts) for alts in choices]
    missing = [n for n, f in zip(names, found) if f is None]
    if callable(hint):
        hint = hint(missing, header) if missing else ""
    if missing:
        n_numbers = len([f for f in _split(htext, delim) if f.strip()])
        if _numeric(htext, delim) and n_numbers >= MATRIX_NUMBERS:
            raise parse_error(path, hline, f"no header line, and {n_numbers} numbers on the row: a matrix of values "
                                           "(an image or map saved as a grid, without its coordinates and unit) is not "
                                           f"read; write the {what} as a table with a header line {','.join(names)}, or "
                                           "as a FITS image with its axes in a WCS")
        if _numeric(htext, delim):
            raise parse_error(path, hline, f"the table has no header line naming its columns; add a first line "
                                           f"{','.join(names)} (with the units in the names)"
                              + (f"; {hint}" if hint else ""))
        units = "; a length column may carry any of nm, um, mm, m (e.g. x [m], sag_nm)"
        raise parse_error(path, hline, f"missing column(s) {missing}; found header {header}, need {names}"
                          + (units if any(c.rpartition("_")[2] in SAG_UNITS_TO_UM for c in missing) else "")
                          + (f"; {hint}" if hint else ""))
    lines_ = lines_[start:]
    chosen = tuple(a for a, _ in found)
    fast = _fast_csv_columns(text, chosen) if start == 0 and all(f == 1.0 for _, (_, f) in found) else None
    if fast is not None:
        return (*fast, chosen)
    idx = [i for _, (i, _) in found]
    factor = np.array([f for _, (_, f) in found])
    rows = [(n, t, _split(t, delim)) for n, t in lines_[1:]]
    # A comma cannot split the numbers of a table delimited otherwise: there a comma is the
    # decimal separator when the table shows it can be nothing else.
    comma_decimal = delim != "," and decimal_commas([r[i].strip() for _, _, r in rows for i in idx if i < len(r)])
    vals, lines = [], []
    for n, t, r in rows:
        if comma_decimal:
            r = [f.replace(",", ".") for f in r]
        if len(r) == len(header) + 1 and not r[-1].strip():
            r = r[:-1]  # a delimiter after each row's last value
        if len(r) != len(header):
            extra = delim == "," and len(r) > len(header)
            comma = "; if the table uses decimal commas, they split its numbers: export with decimal points" if extra else ""
            raise parse_error(path, n, f"expected {len(header)} values like the header, found {len(r)}{comma}")
        try:
            vals.append([_number(r[i]) for i in idx])
        except ValueError:
            comma = next((f for f in r if _DECIMAL_COMMA.match(f.strip())), None)
            if comma is not None:
                # "1,250" is 1.25 or 1250 depending on the writer's locale: not guessed
                why = ("every comma-number could hold a thousands separator" if comma_decimal is None
                       else "the table also has decimal points" if delim != "," else "the comma is the delimiter")
                raise parse_error(path, n, f"decimal comma in {comma.strip()!r} ({t.strip()!r}): {why}; export the "
                                           "table with '.' as the decimal separator") from None
            raise parse_error(path, n, f"non-numeric value in {t.strip()!r}") from None
        lines.append(n)
    return np.array(vals, dtype=float).reshape(-1, len(choices)) * factor, np.array(lines, dtype=int), chosen


#: One column of an ECSV file's YAML header: ``# - {name: wavelength, unit: um, datatype: float64}``.
_ECSV_COLUMN = re.compile(r"^#\s*-\s*\{\s*name:\s*(?:'([^']*)'|\"([^\"]*)\"|([^,}]*))(.*)\}\s*$")
_ECSV_UNIT = re.compile(r"\bunit:\s*(?:'([^']*)'|\"([^\"]*)\"|([^,}]*))")


def _ecsv_units(text: str, n: int) -> list[str] | None:
    """The units (lower case, "" for none) of the ``n`` columns of an ECSV table (astropy's
    ``Table.write(..., format="ascii.ecsv")``), which its YAML header gives in column order,
    else None (not ECSV, or not ``n`` columns described)."""
    if not text.startswith("# %ECSV"):
        return None
    units = []
    for line in text.splitlines():
        if not line.startswith("#"):
            break
        m = _ECSV_COLUMN.match(line.strip())
        if m:
            u = _ECSV_UNIT.search(m.group(4))
            units.append("" if u is None else next(g for g in u.groups() if g is not None).strip().lower())
    return units if len(units) == n else None


#: Units a second header line may hold above a line of comments (OriginLab's export: long
#: names, units, comments): lengths, waves, pixels and intensity units.
_KNOWN_UNITS = frozenset((*SAG_UNITS_TO_UM, *WAVE_UNITS, *INTENSITY_UNITS, "px", "pix", "pixel", "pixels"))


def _units_row(after: list, delimiter: str | None, n: int) -> tuple[list[str], int] | None:
    """The units of a table's second header line, the first of ``after`` (the three lines
    after the header): ``n`` fields, none a number, each a unit or empty (``um``, ``(um)``,
    ``[counts]``), followed by a data row, or by one more line of text (comments) and a data
    row where every unit is one the readers know (:data:`_KNOWN_UNITS`); with the number of
    lines to drop before the data. Else None."""
    if len(after) < 2 or _numeric(after[0][1], delimiter):
        return None
    fields = [f.strip() for f in _split(after[0][1], delimiter)]
    if len(fields) != n or any(re.search(r"\d\.\d|^[+-]?\d+$", f) for f in fields):
        return None
    units = [re.sub(r"^[\[(]\s*(.*?)\s*[\])]$", r"\1", f).lower() for f in fields]
    if _numeric(after[1][1], delimiter):
        return units, 1
    if len(after) > 2 and _numeric(after[2][1], delimiter) and all(not u or u in _KNOWN_UNITS for u in units):
        return units, 2
    return None


def numbered_lines(text: str) -> list[tuple[int, str]]:
    """``(line_number, line)`` pairs (1-based), without line terminators."""
    return list(enumerate(text.splitlines(), start=1))


def ensure_writable_dir(path: str | Path, what: str = "output directory") -> Path:
    """Create directory ``path`` and prove it writable before anything is computed or written.

    Raises
    ------
    NotADirectoryError
        ``path`` exists and is not a directory.
    PermissionError
        It cannot be created or written (the message names the path and the reason).
    """
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise NotADirectoryError(f"{what} {str(path)!r} exists and is not a directory")
    try:
        path.mkdir(parents=True, exist_ok=True)
        probe = path / f".write-probe.{os.getpid()}.{uuid.uuid4().hex[:8]}"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        raise PermissionError(f"{what} {str(path)!r} is not a writable directory: "
                              f"{exc.strerror or exc}") from None
    return path
