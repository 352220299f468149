"""FE results from other solvers: read a mesh with nodal displacements, return the face's sag map.

Formats (read with meshio): VTU/VTK, XDMF (XML data; HDF5 data needs h5py), Exodus II
(``.exo``/``.e``), gmsh ``.msh`` — with the displacement as point data — and Abaqus
``.inp`` / Nastran ``.bdf``/``.nas`` meshes with the displacements in a CSV
``node_id,ux,uy,uz`` (columns found by their header names, other columns ignored; without
a header exactly these four; ``#`` comments) keyed by the solver's node IDs.
A CSV next to another format is keyed by 1-based point number. A ``.csv``/``.txt``/``.tsv``
result without a mesh is a table of nodes with coordinates and displacements
(:mod:`pipeline.io.fe_nodes`): its face is the nodes on a plane, triangulated. An ANSYS
Mechanical APDL ``PRNSOL,U`` listing, with the ``NLIST`` listing of its nodes (``nodes``),
is paired by node number into such a table (:mod:`pipeline.io.ansys_listing`).

The displacement field is the point-data array named ``field``, or, by default, the one
3-component array called displacement/displacements/disp/u/depl (any case); three
scalar arrays ``NAMEX, NAMEY, NAMEZ`` (or ``NAME_x`` …, as Exodus writes them) are
joined. Positions, displacements and plane values are in ``length_unit`` (mm, m, in).
"""

from __future__ import annotations

import contextlib
import io
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fea.external import face_sag_map
from fea.fe_face import parse_surface, select_face
from pipeline.io.ansys_listing import is_ansys_listing, read_ansys_listing
from pipeline.io.common import numbered_lines, read_text, split_fields
from pipeline.io.fe_nodes import DISPLACEMENT_COLUMNS, NODE_TABLE_SUFFIXES, face_triangles, read_node_table

__all__ = ["LENGTH_UNITS_MM", "FEResultData", "read_fe_result", "import_fe"]

#: Solver length units -> mm.
LENGTH_UNITS_MM = {"mm": 1.0, "m": 1000.0, "in": 25.4}
_DISP_NAMES = ("displacement", "displacements", "disp", "u", "depl", "displ")
_ID_SUFFIXES = (".inp", ".bdf", ".nas")


@dataclass(frozen=True)
class FEResultData:
    """A mesh with nodal displacements, in mm (meshio's cell blocks and sets kept).

    Attributes
    ----------
    points_mm, displacement_mm : ndarray, shape (n, 3)
    blocks : list of (str, ndarray)
    point_sets, cell_sets, cell_data, field_data : dict
        As meshio reads them (for face selection by name).
    source : str
    node_ids : ndarray of int, optional
        The solver's node numbers of the points, where the reader knows them (for errors).
    """

    points_mm: np.ndarray
    displacement_mm: np.ndarray
    blocks: list
    point_sets: dict = field(default_factory=dict)
    cell_sets: dict = field(default_factory=dict)
    cell_data: dict = field(default_factory=dict)
    field_data: dict = field(default_factory=dict)
    source: str = ""
    node_ids: np.ndarray | None = None


def _unit_scale(length_unit: str) -> float:
    try:
        return LENGTH_UNITS_MM[length_unit]
    except (KeyError, TypeError):
        raise ValueError(f"length_unit={length_unit!r} is unknown; valid units are {list(LENGTH_UNITS_MM)}") from None


def _node_ids(path: Path) -> np.ndarray | None:
    """Solver node IDs in meshio's point order (Abaqus first *NODE block, Nastran GRID cards)."""
    suffix = path.suffix.lower()
    if suffix not in _ID_SUFFIXES:
        return None
    ids = []
    with path.open(encoding="utf-8", errors="replace") as fh:
        if suffix == ".inp":
            inside = False
            for line in fh:
                s = line.strip()
                if s.startswith("**"):
                    continue
                if s.startswith("*"):
                    if inside:
                        break  # meshio keeps the first *NODE block's order
                    inside = s.partition(",")[0].replace("*", "").strip().upper() == "NODE"
                    continue
                if inside and s:
                    ids.append(int(s.split(",")[0]))
        else:
            for line in fh:
                if line.upper().startswith("GRID"):
                    if "," in line:
                        ids.append(int(line.split(",")[1]))
                    elif line.upper().startswith("GRID*"):
                        ids.append(int(line[8:24]))
                    else:
                        ids.append(int(line[8:16]))
    return np.array(ids, dtype=np.int64)


#: Header names of a displacement CSV's columns: the node ID (Abaqus's report "Node Label",
#: generic ones) and the displacement's (:data:`pipeline.io.fe_nodes.DISPLACEMENT_COLUMNS`).
_CSV_COLUMNS = {
    "node_id": ("node_id", "node", "id", "nodeid", "node_label", "label", "node_number", "nid"),
    **DISPLACEMENT_COLUMNS,
}


#: Why meshio's Abaqus reader fails with a KeyError on a node ID, and what to do.
_INP_HINT = ("meshio's Abaqus reader takes the nodes of one *NODE block (several blocks, or an *INCLUDE, leave "
             "elements referring to nodes it has not read): merge the *NODE blocks into one")


def _xdmf_last_step(path: Path):
    """The last time step of an XDMF time series (dolfinx ``write_function``, meshio's
    ``TimeSeriesWriter``) as one mesh with its point data, or None if ``path`` is not one."""
    import meshio

    try:
        with meshio.xdmf.TimeSeriesReader(path) as reader:
            points, cells = reader.read_points_cells()
            if reader.num_steps < 1:
                return None
            _, point_data, _ = reader.read_data(reader.num_steps - 1)
    except Exception:  # not a time series either: the caller's error stands
        return None
    return meshio.Mesh(points, cells, point_data=point_data)


def _read_csv(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """(node IDs, displacements (n, 3)) of a displacement CSV: columns found by their
    header names (:data:`_CSV_COLUMNS`, other columns such as a magnitude or the
    coordinates ignored), or, without a header or with four columns of other names, exactly
    ``node_id,ux,uy,uz``; comma, semicolon, tab or whitespace delimited
    (:func:`pipeline.io.common.split_fields`); a node listed twice is refused."""
    rows, lines, cols = [], [], None
    for lineno, line in numbered_lines(read_text(path, "displacement CSV")):
        s = line.split("#", 1)[0].strip()
        if not s:
            continue
        parts = split_fields(s)
        try:
            values = [float(p) for p in parts]
        except ValueError:
            if rows or cols is not None:  # one header line, before the data
                raise ValueError(f"{path}:{lineno}: non-numeric value in {s!r}") from None
            names = [re.sub(r"[\s.\-]+", "_", p.lower()) for p in parts]
            cols = [next((i for i, n in enumerate(names) if n in alts), None) for alts in _CSV_COLUMNS.values()]
            if None in cols and len(parts) == 4:  # names of its own ("n,dx_mm,dy_mm,dz_mm"): by position
                cols = [0, 1, 2, 3]
            if None in cols:
                missing = [k for k, c in zip(_CSV_COLUMNS, cols) if c is None]
                raise ValueError(f"{path}:{lineno}: header {parts} has no column for {missing}; accepted names: "
                                 + "; ".join(f"{k}: {', '.join(v)}" for k, v in _CSV_COLUMNS.items())) from None
            continue
        if cols is None and len(values) != 4:
            raise ValueError(f"{path}:{lineno}: {len(values)} values and no header line; a CSV without a header "
                             "must hold exactly node_id,ux,uy,uz (add a header naming the columns)")
        take = cols if cols is not None else [0, 1, 2, 3]
        if max(take) >= len(values):
            raise ValueError(f"{path}:{lineno}: expected {max(take) + 1} values, got {s!r}")
        rows.append([values[i] for i in take])
        lines.append(lineno)
    if not rows:
        raise ValueError(f"{path}: no rows 'node_id,ux,uy,uz'")
    a = np.array(rows)
    ids = a[:, 0].astype(np.int64)
    order = np.argsort(ids, kind="stable")
    dup = np.flatnonzero(np.diff(ids[order]) == 0)
    if dup.size:
        i, j = order[dup[0]], order[dup[0] + 1]
        raise ValueError(f"{path}: node {ids[i]} is listed twice (lines {lines[i]} and {lines[j]})")
    return ids, a[:, 1:4]


def _pick_field(point_data: dict, name: str | None, source: str) -> np.ndarray:
    vectors = {k: np.asarray(v, float) for k, v in point_data.items()
               if np.ndim(v) == 2 and np.shape(v)[1] in (2, 3)}
    scalars = {k: np.asarray(v, float).ravel() for k, v in point_data.items()
               if np.ndim(v) == 1 or (np.ndim(v) == 2 and np.shape(v)[1] == 1)}
    for base, comps in ((b, tuple(b + s for s in sfx)) for b in {re.sub(r"_?[xyzXYZ]$", "", k) for k in scalars}
                        for sfx in (("x", "y", "z"), ("X", "Y", "Z"), ("_x", "_y", "_z"), ("_X", "_Y", "_Z"))):
        if all(c in scalars for c in comps):
            vectors.setdefault(base, np.column_stack([scalars[c] for c in comps]))
    if name is not None:
        if name not in vectors:
            raise ValueError(f"field={name!r} is not a nodal vector of {source}; valid names are {sorted(vectors)} "
                             f"(point data present: {sorted(point_data)})")
        v = vectors[name]
    else:
        hits = [k for k in vectors if k.lower() in _DISP_NAMES]
        if len(hits) != 1:
            raise ValueError(f"field=None: {source} has {'no' if not hits else 'several'} nodal displacement "
                             f"array(s) named {list(_DISP_NAMES)} (any case); nodal vectors present: "
                             f"{sorted(vectors)}, point data present: {sorted(point_data)}; give field=NAME, "
                             "or displacement_csv for a mesh without results")
        v = vectors[hits[0]]
    if v.shape[1] == 2:
        v = np.column_stack([v, np.zeros(len(v))])
    return v


def read_fe_result(path, *, displacement_csv=None, field: str | None = None,
                   length_unit: str = "mm") -> FEResultData:
    """Read a mesh and its nodal displacements (module docstring), converted to mm.

    Parameters
    ----------
    path : str or Path
        Mesh or result file.
    displacement_csv : str or Path, optional
        ``node_id,ux,uy,uz`` in ``length_unit``; required for meshes without results.
    field : str, optional
        Point-data name of the displacement.
    length_unit : {"mm", "m", "in"}
        Length unit of the solver model.
    """
    import meshio

    scale = _unit_scale(length_unit)
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{path}: file does not exist")
    said = io.StringIO()  # meshio prints its complaint before exiting: keep it for the one-line error
    try:
        with contextlib.redirect_stdout(said), contextlib.redirect_stderr(said):
            mesh = meshio.read(path)
    except ModuleNotFoundError as exc:  # e.g. h5py for XDMF with HDF5 data
        raise ValueError(f"{path}: reading this format needs the Python package {exc.name!r} "
                         "(pip install 'cryograting[xdmf]' for h5py)") from None
    except Exception as exc:  # meshio raises many types (ReadError, KeyError, ...) for files it cannot read
        mesh = _xdmf_last_step(path) if path.suffix.lower() == ".xdmf" else None
        if mesh is None:
            raise ValueError(f"{path}: meshio cannot read it as an FE mesh ({type(exc).__name__}: {exc})"
                             + (f"; {_INP_HINT}" if path.suffix.lower() == ".inp" and isinstance(exc, KeyError)
                                else "")) from None
    except SystemExit:  # meshio ends the process (sys.exit(1)) when no reader of the suffix can read the file
        mesh = _xdmf_last_step(path) if path.suffix.lower() == ".xdmf" else None
        if mesh is None:
            why = " ".join(said.getvalue().split()) or "no reader of its suffix's format could read it"
            raise ValueError(f"{path}: meshio cannot read it as an FE mesh ({why})") from None
    points = np.asarray(mesh.points, float)
    if points.shape[1] == 2:
        points = np.column_stack([points, np.zeros(len(points))])
    if displacement_csv is not None:
        ids, u = _read_csv(Path(displacement_csv))
        known = _node_ids(path)
        if known is None:
            known = np.arange(1, len(points) + 1)
        if known.size != len(points):
            raise ValueError(f"{path}: read {known.size} node IDs but meshio has {len(points)} points")
        order = np.argsort(known)
        pos = np.searchsorted(known[order], ids)
        bad = (pos >= known.size) | (known[order][np.minimum(pos, known.size - 1)] != ids)
        if bad.any():
            raise ValueError(f"{displacement_csv}: node_id(s) {ids[bad][:10].tolist()} are not nodes of {path}")
        disp = np.full((len(points), 3), np.nan)
        disp[order[pos]] = u
    else:
        disp = _pick_field(mesh.point_data, field, str(path))
    return FEResultData(points * scale, disp * scale, [(c.type, np.asarray(c.data)) for c in mesh.cells],
                        dict(mesh.point_sets), dict(mesh.cell_sets), dict(mesh.cell_data),
                        dict(mesh.field_data), str(path))


def _plane_tol(points: np.ndarray, tol: float | None) -> float:
    """``tol``, or by default 1e-6 of the model's largest extent (its own length unit)."""
    return 1e-6 * float(np.ptp(points, axis=0).max() or 1.0) if tol is None else tol


def import_fe(path, surface: str, *, displacement_csv=None, nodes=None, load_step: int | None = None,
              substep: int | None = None, field: str | None = None, length_unit: str = "mm",
              tol: float | None = None, angle_tol_deg: float = 1.0, sag_along: str = "z",
              axes: str = "x,y,z", origin=None, spacing_mm: float = 0.5):
    """The optical face's sag map and rigid-body motion of an FE result from any solver.

    Parameters
    ----------
    path, displacement_csv, field, length_unit
        See :func:`read_fe_result`.
    surface : str
        Face selection (:func:`fea.fe_face.parse_surface`): a set/physical-group name,
        a plane ``z=VALUE`` (``length_unit``) or an outward normal ``+z``/``normal:nx,ny,nz``.
    nodes : str or Path, optional
        The ANSYS ``NLIST`` listing of the nodes when ``path`` is a ``PRNSOL,U`` listing
        (:func:`pipeline.io.ansys_listing.read_ansys_listing`); not needed when ``path``
        holds both.
    load_step, substep : int, optional
        The result set of an ANSYS listing that holds several.
    tol : float, optional
        Plane tolerance (``length_unit``); default 1e-6 of the model's size.
    angle_tol_deg : float
        Tolerance of a normal-direction selection (degrees).
    sag_along : {"z", "normal"}
    axes : str
        Optical x, y, z as signed solver axes (:func:`fea.external.axes_matrix`).
    origin : (3,) sequence, optional
        Optical origin in the solver's frame (``length_unit``); default the face centre.
    spacing_mm : float
        Grid spacing of the map (mm).

    Returns
    -------
    fea.external.FaceSagResult
        ``.sag_map`` (a SagMap for fits, exports, optics), ``.rigid_body``, ``.stats``;
        ``sag_map.meta["notes"]`` says what was assumed or left out, where anything was.
    """
    scale = _unit_scale(length_unit)
    spec = parse_surface(surface)
    notes, extra = [], {}
    listing = nodes is not None or is_ansys_listing(path)  # told by content: listings come under any name
    table = not listing and Path(path).suffix.lower() in NODE_TABLE_SUFFIXES and displacement_csv is None
    given = [f"{n}={v!r}" for n, v in (("load_step", load_step), ("substep", substep)) if v is not None]
    if given and not listing:
        raise ValueError(f"{', '.join(given)}: only an ANSYS listing has load steps; {path} is not one "
                         "(a PRNSOL,U listing is read with nodes=NLIST)")
    if listing:
        if displacement_csv is not None or field is not None:
            which = "displacement_csv" if displacement_csv is not None else "field"
            raise ValueError(f"{which}={str(displacement_csv or field)!r}: an ANSYS listing's displacements are its "
                             "PRNSOL,U table, its node coordinates come from nodes=NLIST")
        lst = read_ansys_listing(path, nodes, load_step=load_step, substep=substep)
        pts, u, ids = lst.points, lst.displacement, lst.node_ids  # paired by node: a table of nodes
        notes += lst.notes
        extra = {"nodes": str(nodes or path), "result_set": lst.result_set, "components": list(lst.components)}
    elif table:
        if field is not None:
            raise ValueError(f"field={field!r}: a node table's displacement is its ux, uy, uz columns")
        pts, u = read_node_table(path, length_unit)
        ids = None
    if listing or table:  # no mesh: the face's nodes triangulated in their plane
        tol = _plane_tol(pts, tol)
        blocks, spec = face_triangles(pts, spec, tol)
        data = FEResultData(pts * scale, u * scale, blocks, source=str(path), node_ids=ids)
    else:
        data = read_fe_result(path, displacement_csv=displacement_csv, field=field, length_unit=length_unit)
        pts = data.points_mm / scale  # selection in the solver's own unit
        tol = _plane_tol(pts, tol)
    face = select_face(pts, data.blocks, spec, tol=tol, angle_tol_deg=angle_tol_deg,
                       point_sets=data.point_sets, cell_sets=data.cell_sets, cell_data=data.cell_data,
                       field_data=data.field_data)
    unknown = ~np.isfinite(data.displacement_mm).all(axis=1)
    bad = face.node_index[unknown[face.node_index]]
    if bad.size:
        named = (f"nodes {', '.join(map(str, data.node_ids[bad[:5]]))}" if data.node_ids is not None
                 else f"points {', '.join(map(str, bad[:5] + 1))}") + (", ..." if bad.size > 5 else "")
        raise ValueError(f"{displacement_csv or path}: no displacement for some nodes of the face {surface!r}: "
                         f"{bad.size} of its {face.node_index.size} nodes ({named})"
                         + ("; list them with PRNSOL under the same selection as NLIST (ALLSEL before both)"
                            if listing else ""))
    if listing and unknown.any():
        left = np.flatnonzero(unknown)
        notes.append(f"{left.size} nodes of {Path(nodes or path).name} are not in the displacement listing and not "
                     f"on the face: left out (nodes {', '.join(map(str, data.node_ids[left[:5]]))}"
                     f"{', ...' if left.size > 5 else ''})")
    res = face_sag_map(data.points_mm, np.nan_to_num(data.displacement_mm), face, axes=axes,
                       origin_mm=None if origin is None else scale * np.asarray(origin, float),
                       sag_along=sag_along, spacing_mm=spacing_mm, label=f"{Path(path).name} {surface}")
    res.sag_map.meta.update({"source": str(path), "surface": surface, "length_unit": length_unit, **extra})
    if notes:
        res.sag_map.meta["notes"] = notes
    return res
