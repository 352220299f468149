"""FE results as ANSYS Mechanical APDL prints them: a ``PRNSOL,U`` listing with an ``NLIST`` listing.

APDL lists results as text pages rather than as a mesh file: ``PRNSOL,U`` prints the nodal
displacements (``NODE  UX  UY  UZ  USUM``; ``PRNSOL,U,Z`` only ``UZ``), ``NLIST`` the node
coordinates (``NODE  X  Y  Z  THXY  THYZ  THZX``). Both are read as they come off ``/OUTPUT``
or a listing window saved to a file:

* every page repeats the banner, the listing's title, ``LOAD STEP=``/``TIME=`` and the column
  header (``/PAGE``); a table's columns are found by its header's names, so a page of
  another listing in the same file (``PRNSOL,S``, ``PRNSOL,ROT``) is passed over;
* the ``MAXIMUM ABSOLUTE VALUES`` (``MINIMUM``/``MAXIMUM``/``TOTAL VALUES``) block that ends
  a listing is not data;
* numbers are Fortran's: ``0.12345E-03``, ``0.12345E-003``, ``0.12345-100`` (an exponent of
  three digits written without its ``E``), ``1.5D+03``, and two fields may touch
  (``0.24713E+007-0.73354E+006``);
* a listing with several result sets (load step, substep) is refused unless one is chosen;
* displacements in another than the global Cartesian system (``RSYS``) or coordinates in
  another display system (``DSYS``) are refused: the two listings are paired node by node
  and the face is found as a plane in global coordinates.

The two are paired by node number. The face is then found as for a table of nodes
(:mod:`pipeline.io.fe_nodes`): the nodes on a plane, Delaunay-triangulated. APDL has no
unit: positions and displacements are in the model's length unit, whatever it is; the
caller states it (``length_unit``, ``--unit``).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pipeline.io.common import numbered_lines, read_text

__all__ = ["ANSYS_LISTING_SUFFIXES", "AnsysListing", "is_ansys_listing", "read_ansys_listing"]

#: Suffixes APDL listings are usually saved under (``/OUTPUT``'s ``.out``, a listing window's
#: ``.lis``, a text file); any other name is read too when the content says it is a listing.
ANSYS_LISTING_SUFFIXES = (".lis", ".out", ".txt")

#: Words that only APDL's own output has, looked for at the head of a file.
_SNIFF = re.compile(rb"NODAL DEGREE OF FREEDOM LISTING|LIST ALL SELECTED NODES|PRINT U\s+NODAL SOLUTION|"
                    rb"ANSYS - ENGINEERING ANALYSIS SYSTEM", re.IGNORECASE)
_SNIFF_BYTES = 1 << 16

#: A Fortran real: the mantissa, then ``E``/``D`` and an exponent, or (exponents of three
#: digits, which do not fit ``Ew.d`` with its letter) a sign and three digits that are not
#: followed by more digits or a point (``0.1234-100`` is 0.1234e-100; ``0.5-12.5`` is two
#: numbers); it ends where a space or the sign of the next field begins, so a line that is not
#: numbers fails without trying every way of cutting its digits.
_FIELD = r"[+-]?(?:\d+\.\d*|\.\d+|\d+)(?:[EeDd][+-]?\d+|[+-]\d{3}(?![\d.]))?(?=[\s+-]|$)"
_FIELDS = re.compile(_FIELD)
_VALUES = re.compile(rf"(?:\s*{_FIELD})*\s*")
_FORTRAN = re.compile(r"^([+-]?[\d.]+)[EeDd]?([+-]\d+)$")
_ROW = re.compile(r"\s*(\d+)(?=[\s+-])")  # a node number filling its field touches a negative value
_HEADER = re.compile(r"\s*NODE((?:\s+[A-Z][A-Z0-9_]*)+)\s*$", re.IGNORECASE)
_LOAD_STEP = re.compile(r"LOAD\s+STEP\s*=\s*(\d+)\s+SUBSTEP\s*=\s*(\d+)", re.IGNORECASE)
_TIME = re.compile(r"^\s*(?:TIME|FREQ)\s*=\s*(\S+)", re.IGNORECASE)
_END = re.compile(r"^\s*(?:MAXIMUM ABSOLUTE VALUES|MAXIMUM VALUES|MINIMUM VALUES|TOTAL VALUES)\b", re.IGNORECASE)
_TITLE = re.compile(r"LISTING \*|LIST ALL SELECTED|^\s*PRINT\s+\w+\s", re.IGNORECASE)
_DSYS = re.compile(r"DSYS\s*=\s*(-?\d+)", re.IGNORECASE)
_FRAME = re.compile(r"RESULTS ARE IN\b(.*)COORDINATE", re.IGNORECASE)

_COORDS = ("X", "Y", "Z")
_DISP = ("UX", "UY", "UZ")


@dataclass(frozen=True)
class AnsysListing:
    """Nodes of an ``NLIST`` listing with their displacements from a ``PRNSOL,U`` listing.

    Attributes
    ----------
    node_ids : ndarray of int, shape (n,)
        The ``NLIST`` nodes, ascending.
    points : ndarray, shape (n, 3)
        Their global coordinates, in the model's length unit.
    displacement : ndarray, shape (n, 3)
        ``UX, UY, UZ`` in the model's length unit; a component the listing does not print is
        0, a node it does not list is NaN.
    components : tuple of str
        The components the listing prints (``("UZ",)`` for ``PRNSOL,U,Z``).
    result_set : str
        The result set read, e.g. ``"load step 1, substep 1 (time 1.0000)"``.
    notes : tuple of str
        What the reader assumed (components not printed, read as 0).
    """

    node_ids: np.ndarray
    points: np.ndarray
    displacement: np.ndarray
    components: tuple
    result_set: str
    notes: tuple = ()


def is_ansys_listing(path) -> bool:
    """Whether the head of ``path`` is APDL output (a listing's title or APDL's page banner);
    False for a file that does not exist or cannot be read."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(_SNIFF_BYTES)
    except (OSError, TypeError):
        return False
    return bool(_SNIFF.search(head))


def _real(field: str) -> float:
    try:
        return float(field)
    except ValueError:  # 1.5D-03, 0.1234-100
        return float("e".join(_FORTRAN.match(field).groups()))


def _numbers(text: str, path, lineno: int) -> list[float]:
    """The Fortran reals of ``text`` (the row after its node number)."""
    if _VALUES.fullmatch(text) is None:
        bad = next((t for t in text.split() if not re.fullmatch(f"(?:{_FIELD})+", t)), text.strip())
        raise ValueError(f"{path}, line {lineno}: {bad!r} is not a number (an APDL field too narrow for its "
                         "value prints as asterisks: list it with more digits, /FORMAT)")
    try:
        return [float(t) for t in text.split()]  # fields apart (a row is read twice as fast)
    except ValueError:  # fields that touch, D or E-less exponents
        return [_real(f) for f in _FIELDS.findall(text)]


@dataclass
class _Parsed:
    """What one file holds: its node coordinates and its displacement tables by result set."""

    coords: dict            # node -> (x, y, z)
    coord_lines: dict       # node -> line
    sets: dict              # (load step, substep) -> {node: [ux, uy, uz] (None: not printed)}
    set_lines: dict         # (load step, substep) -> {node: line}
    times: dict             # (load step, substep) -> time text


def _parse(path: Path, what: str) -> _Parsed:
    """One pass over an APDL listing file: the rows of every ``NODE ...`` table, the coordinate
    tables' (``X Y Z``) apart from the displacement tables' (``UX``/``UY``/``UZ``), which are
    filed under the load step and substep printed above them."""
    out = _Parsed({}, {}, {}, {}, {})
    key, kind, cols = (None, None), None, None
    for lineno, line in numbered_lines(read_text(path, what)):
        m = _ROW.match(line) if kind in ("coords", "disp") and "=" not in line else None
        if m is not None:  # a row of the table being read (no title, header or banner starts with a number)
            _row(out, kind, cols, key, int(m.group(1)), _numbers(line[m.end():], path, lineno), line, path, lineno)
            continue
        if _TITLE.search(line) or _END.search(line):
            kind = None  # a new listing or page title, or a listing's summary block: no rows until a header
            m = _DSYS.search(line)
            if m and int(m.group(1)) != 0:
                raise ValueError(f"{path}, line {lineno}: the nodes are listed in display coordinate system "
                                 f"DSYS={m.group(1)}; list them in the global Cartesian system (DSYS,0 before NLIST)")
            continue
        m = _LOAD_STEP.search(line)
        if m:
            key = (int(m.group(1)), int(m.group(2)))
            kind = None
            continue
        m = _TIME.match(line)  # at the start of its line: a note's "CP= 0.75  TIME= 15:29:15" is a clock
        if m:
            out.times[key] = m.group(1)
            continue
        m = _FRAME.search(line)
        if m:
            if "GLOBAL" not in m.group(1).upper():
                raise ValueError(f"{path}, line {lineno}: the displacements are listed in another than the global "
                                 f"coordinate system ({line.strip()!r}); list them with RSYS,0")
            continue
        m = _HEADER.match(line)
        if m:
            cols = m.group(1).upper().split()
            kind = "coords" if all(c in cols for c in _COORDS) else "disp" if set(_DISP) & set(cols) else "other"
            continue
        # anything else (page banners, notes, "PowerGraphics Is Currently Enabled", rows of listings
        # not read here) is passed over
    return out


def _row(out: _Parsed, kind: str, cols: list, key, node: int, values: list, line: str, path, lineno: int) -> None:
    """File one table row under the node's coordinates or its result set's displacements."""
    if len(values) != len(cols):
        raise ValueError(f"{path}, line {lineno}: expected {len(cols)} values ({' '.join(cols)}) after the node "
                         f"number, got {len(values)}: {line.strip()!r}")
    if kind == "coords":
        xyz = tuple(values[cols.index(c)] for c in _COORDS)
        if node in out.coords and out.coords[node] != xyz:
            raise ValueError(f"{path}: node {node} is listed twice with different coordinates (lines "
                             f"{out.coord_lines[node]} and {lineno})")
        out.coords[node], out.coord_lines[node] = xyz, lineno
        return
    rows, lines = out.sets.setdefault(key, {}), out.set_lines.setdefault(key, {})
    u = rows.setdefault(node, [None, None, None])
    for i, c in enumerate(_DISP):
        if c in cols:
            v = values[cols.index(c)]
            if u[i] is not None and u[i] != v:
                raise ValueError(f"{path}: node {node} is listed twice in {_describe(key, out.times)} with "
                                 f"different {c} (lines {lines[node]} and {lineno})")
            u[i] = v
    lines[node] = lineno


def _describe(key, times: dict) -> str:
    if key == (None, None):
        return "the listing's one result set (no LOAD STEP line)"
    t = times.get(key)
    return f"load step {key[0]}, substep {key[1]}" + (f" (time {t})" if t else "")


def _positive_int(name: str, value):
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise ValueError(f"{name}={value!r} must be a positive integer, a {name.replace('_', ' ')} number printed in "
                         "the listing's LOAD STEP= line")
    return int(value)


def _choose_set(parsed: _Parsed, path: Path, load_step, substep):
    keys = list(parsed.sets)
    listed = "; ".join(_describe(k, parsed.times) for k in keys)
    chosen = [k for k in keys if (load_step is None or k[0] == load_step) and (substep is None or k[1] == substep)]
    if not chosen:
        asked = ", ".join(f"{n}={v}" for n, v in (("load_step", load_step), ("substep", substep)) if v is not None)
        raise ValueError(f"{asked}: {path} does not list that result set; it lists {listed}")
    if len(chosen) > 1:
        sets = "; ".join(_describe(k, parsed.times) for k in chosen)
        raise ValueError(f"{path} lists {len(chosen)} result sets ({sets}); choose one with load_step=N (and "
                         "substep=M where a load step has several)")
    return chosen[0]


def read_ansys_listing(path, nodes=None, *, load_step: int | None = None,
                       substep: int | None = None) -> AnsysListing:
    """Pair a ``PRNSOL,U`` listing's displacements with an ``NLIST`` listing's coordinates.

    Parameters
    ----------
    path : str or Path
        The ``PRNSOL,U`` listing (any components of ``U``; other listings in the file are passed over).
    nodes : str or Path, optional
        The ``NLIST`` listing of the model's nodes; default: ``path`` itself, when one
        ``/OUTPUT`` file holds both.
    load_step, substep : int, optional
        The result set to read, where the listing holds several.

    Returns
    -------
    AnsysListing
        Every ``NLIST`` node, its coordinates and (NaN where ``PRNSOL`` does not list it) its
        displacement, in the model's length unit.

    Raises
    ------
    ValueError
        No displacement table or no coordinates (naming which file and what to give), several
        result sets and none chosen (naming them), displacements of nodes without coordinates
        (how many, and a few of them), a malformed row (file and line), displacements not
        in global Cartesian coordinates.
    """
    path = Path(path)
    load_step, substep = _positive_int("load_step", load_step), _positive_int("substep", substep)
    res = _parse(path, "PRNSOL,U listing")
    nod = _parse(Path(nodes), "NLIST listing") if nodes is not None else None
    if not res.sets:
        if nod is not None and nod.sets and res.coords:
            raise ValueError(f"{path} is a node listing (NLIST) and nodes={str(nodes)!r} a displacement listing "
                             "(PRNSOL,U): give them the other way round")
        if res.coords:
            raise ValueError(f"{path} lists node coordinates (NLIST) but no displacements: give the PRNSOL,U listing "
                             f"as the result, with nodes={path}")
        raise ValueError(f"{path}: no PRNSOL,U displacement table (a 'NODE  UX  UY  UZ' header followed by rows of "
                         "node numbers and values)")
    coords, source = (nod.coords, nodes) if nod is not None else (res.coords, path)
    if not coords:
        if nod is None:
            raise ValueError(f"{path} holds displacements (PRNSOL,U) but no node coordinates; give the NLIST listing "
                             "of the same nodes as nodes=NLIST")
        raise ValueError(f"nodes={str(nodes)!r}: no NLIST coordinate table (a 'NODE  X  Y  Z' header followed by rows "
                         "of node numbers and coordinates)")
    key = _choose_set(res, path, load_step, substep)
    rows = res.sets[key]
    ids = np.array(sorted(coords), dtype=np.int64)
    pts = np.array([coords[i] for i in ids], float)
    u_ids = np.array(sorted(rows), dtype=np.int64)
    pos = np.minimum(np.searchsorted(ids, u_ids), ids.size - 1)
    orphan = u_ids[ids[pos] != u_ids]
    if orphan.size:
        raise ValueError(f"{path}: {orphan.size} of the {u_ids.size} nodes it lists ({_describe(key, res.times)}) have "
                         f"no coordinates in {source} (nodes {', '.join(map(str, orphan[:5]))}"
                         f"{', ...' if orphan.size > 5 else ''}); list the nodes with NLIST under the same selection "
                         "as PRNSOL (ALLSEL before both)")
    comps = tuple(c for i, c in enumerate(_DISP) if any(rows[n][i] is not None for n in rows))
    for i, c in enumerate(_DISP):
        if c in comps:
            missing = [n for n in rows if rows[n][i] is None]
            if missing:
                raise ValueError(f"{path}: {c} is listed for {len(rows) - len(missing)} of the {len(rows)} nodes of "
                                 f"{_describe(key, res.times)} (not for nodes {', '.join(map(str, missing[:5]))}"
                                 f"{', ...' if len(missing) > 5 else ''})")
    u = np.full((ids.size, 3), np.nan)
    u[pos] = np.array([[0.0 if v is None else v for v in rows[n]] for n in u_ids])
    notes = ()
    absent = [c for c in _DISP if c not in comps]
    if absent:
        notes = (f"{path.name} lists {', '.join(comps)} only: {', '.join(absent)} read as 0, so the rigid-body "
                 f"motion is fitted to {', '.join(comps)} alone (the parts of it that only move the face along "
                 f"{', '.join(c[1].lower() for c in absent)} read 0)",)
    return AnsysListing(ids, pts, u, comps, _describe(key, res.times), notes)
