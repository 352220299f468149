"""What every CODE V INT file shares, grid (``GRD``) or Zernike deck (``ZFR``).

::

    ! comment: '!' starts a comment anywhere on a line
    <title line>
    <GRD nx ny | ZFR n> SUR|WFR WVL <wvl_um> SSZ <ssz> [keyword value ...]
    <data values>

:func:`split_int_file` drops the comments and separates title, header and data lines;
:func:`parse_keywords` reads the header after its sizes: the data type and the
keyword values. The sizes and what the data mean are the format modules' own
(:mod:`pipeline.io.codev`, :mod:`pipeline.io.codev_zfr`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Mapping

import numpy as np

from pipeline.io.common import numbered_lines, parse_error, read_text

__all__ = ["DATA_TYPES", "split_int_file", "parse_keywords"]

#: ``SUR`` surface deviation (sag), ``WFR`` wavefront (OPD)
DATA_TYPES = ("SUR", "WFR")


def split_int_file(path: str | Path, what: str, header_form: str) -> tuple[str, tuple[int, str], list]:
    """Title, header line and data lines of a CODE V INT file, comments dropped.

    Parameters
    ----------
    path : str or Path
        The file.
    what : str
        What the file is, for the message when it cannot be read.
    header_form : str
        How the header line starts, e.g. ``"GRD nx ny"``; its first word is the
        file type (named in messages about a missing header or title).

    Returns
    -------
    title : str
    header : (int, str)
        Line number and text of the header line.
    body : list of (int, str)
        Numbered data lines (blank and comment-only lines left out).
    """
    lines = []
    for n, s in numbered_lines(read_text(path, what)):
        s = s.split("!", 1)[0].rstrip()
        if s.strip():
            lines.append((n, s))
    keyword = header_form.split()[0]
    if len(lines) < 2:
        raise parse_error(path, lines[-1][0] if lines else None, f"file ends before the {keyword} header line")
    title = lines[0][1].strip()
    if title.split()[0].upper() == keyword and lines[1][1].split()[0].upper() != keyword:
        # CODE V's layout opens with a title line, but some writers leave it out: the
        # header is then the first line (a title that itself starts with the keyword is
        # told apart by the header on the next line)
        return "", lines[0], lines[1:]
    return title, lines[1], lines[2:]


def parse_keywords(path, lineno: int, tokens: list[str], valued: Mapping[str, type],
                   flags: tuple[str, ...] = ()) -> dict:
    """The data type and keyword values of a header line after its sizes.

    Parameters
    ----------
    path : str or Path
        The file (named in messages).
    lineno : int
        The header's line number.
    tokens : list of str
        The header's words after the file type and sizes.
    valued : mapping keyword -> int or float
        Keywords followed by a value, and the value's type.
    flags : tuple of str
        Keywords that stand alone or are followed by a number (written both ways).

    Returns
    -------
    dict
        ``"type"`` (one of :data:`DATA_TYPES`) and each keyword found; ``WVL`` and
        ``SSZ`` (they scale every value), when present, are finite numbers > 0.
    """
    hdr: dict = {"type": None}
    i = 0
    while i < len(tokens):
        key = tokens[i].upper()
        if key in DATA_TYPES:
            if hdr["type"] is not None:
                raise parse_error(path, lineno, f"two data types {hdr['type']!r} and {key!r}")
            hdr["type"] = key
            i += 1
            continue
        if key in flags:
            if i + 1 < len(tokens) and _is_number(tokens[i + 1]):
                hdr[key] = float(tokens[i + 1])
                i += 2
            else:
                hdr[key] = True
                i += 1
            continue
        if key not in valued:
            valid = ", ".join([*DATA_TYPES, *sorted(valued), *flags])
            raise parse_error(path, lineno, f"unknown header keyword {tokens[i]!r}; valid are {valid}")
        if i + 1 >= len(tokens):
            raise parse_error(path, lineno, f"keyword {key} has no value")
        try:
            hdr[key] = valued[key](tokens[i + 1])
        except ValueError:
            kind = "an integer" if valued[key] is int else "a number"
            raise parse_error(path, lineno, f"{key} value {tokens[i + 1]!r} is not {kind}") from None
        i += 2
    if hdr["type"] is None:
        raise parse_error(path, lineno, f"header has no data type; expected one of {list(DATA_TYPES)}")
    for key in ("WVL", "SSZ"):
        if key in hdr and not (np.isfinite(hdr[key]) and hdr[key] > 0):
            raise parse_error(path, lineno, f"{key}={hdr[key]!r} must be a finite number > 0")
    return hdr


def _is_number(tok: str) -> bool:
    try:
        float(tok)
    except ValueError:
        return False
    return True
