"""FE results delivered as a table of nodes: coordinates and displacements, no mesh.

Solvers and their post-processors export nodal results as text (a workbench "nodal
solution" table, a spreadsheet of ``x, y, z, ux, uy, uz``). Without elements there is no
face to select by name or by outward normal, but the optical face of a blank is a plane
of nodes: the table's face is the nodes on a plane ``z=VALUE`` (or, for a normal ``+z`` /
``-x``, on the extreme plane of the table along that axis), triangulated in that plane
(Delaunay), so the face is a surface mesh of linear triangles like any other
(:mod:`fea.fe_face`). Triangles with an edge longer than :data:`MAX_EDGE_OVER_SPACING`
times the local node spacing are dropped: a hole or a re-entrant corner of the face is not
bridged.

The table needs a header naming its columns (:data:`COLUMNS`, any case; a unit written
into a name, ``x_mm`` or ``UZ (m)``, must agree with the solver unit given); delimiters as
:func:`pipeline.io.common.split_fields`; ``#`` comments; a node ID column is optional.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from fea.fe_face import FaceSpec
from pipeline.io.common import numbered_lines, read_text, split_fields

__all__ = ["COLUMNS", "DISPLACEMENT_COLUMNS", "NODE_TABLE_SUFFIXES", "MAX_EDGE_OVER_SPACING", "read_node_table",
           "face_triangles"]

#: Header names of a displacement's columns (lower case, spaces, dots and dashes read as
#: underscores): Abaqus's report ("U-U1"), Ansys's ("UX"), generic ones; a displacement CSV
#: beside a mesh (:mod:`pipeline.io.fe`) takes these too.
DISPLACEMENT_COLUMNS = {
    "ux": ("ux", "u_x", "u1", "u_u1", "dx", "disp_x", "displacement_x", "x_displacement"),
    "uy": ("uy", "u_y", "u2", "u_u2", "dy", "disp_y", "displacement_y", "y_displacement"),
    "uz": ("uz", "u_z", "u3", "u_u3", "dz", "disp_z", "displacement_z", "z_displacement"),
}
#: Column -> accepted header names of a node table (as above, the unit removed): coordinates,
#: and displacements also as a workbench names them ("X Deformation").
COLUMNS = {
    "x": ("x", "x_coord", "coord_x", "x_coordinate", "loc_x", "location_x", "x_location", "coor1", "x0"),
    "y": ("y", "y_coord", "coord_y", "y_coordinate", "loc_y", "location_y", "y_location", "coor2", "y0"),
    "z": ("z", "z_coord", "coord_z", "z_coordinate", "loc_z", "location_z", "z_location", "coor3", "z0"),
    **{k: v + (f"{k[1]}_deformation",) for k, v in DISPLACEMENT_COLUMNS.items()},
}
#: Suffixes of a result file read as a node table (no FE mesh format uses them).
NODE_TABLE_SUFFIXES = (".csv", ".txt", ".tsv")
#: A face triangle whose longest edge exceeds this many times its corners' local node spacing
#: (nearest-neighbour distance) spans a hole: dropped. A mesh's own triangles reach about 1.4
#: (half a square) to 2 (a graded mesh's transition); a chord across a hole of a few elements
#: is longer.
MAX_EDGE_OVER_SPACING = 3.0

_UNIT = re.compile(r"^(.+?)(?:[\s_]+|\s*[\[(])\s*(mm|m|in|meters?|millimeters?|inch(?:es)?)\s*[\])]?$")
_UNIT_NAMES = {"mm": "mm", "millimeter": "mm", "millimeters": "mm", "m": "m", "meter": "m", "meters": "m",
               "in": "in", "inch": "in", "inches": "in"}


def _column_name(text: str) -> tuple[str, str | None]:
    """(normalised name, unit written into it or None)."""
    t = text.strip().lower()
    unit = None
    m = _UNIT.match(t)
    if m:
        t, unit = m.group(1), _UNIT_NAMES[m.group(2)]
    return re.sub(r"[\s.\-()\[\]]+", "_", t).strip("_"), unit


def read_node_table(path, length_unit: str = "mm") -> tuple[np.ndarray, np.ndarray]:
    """(points (n, 3), displacements (n, 3)) of a node table, in ``length_unit``.

    Raises
    ------
    ValueError
        No header or a column missing (naming the accepted names), a unit in a header that
        is not ``length_unit``, a non-numeric or non-finite value (naming the line).
    """
    path = Path(path)
    cols, rows = None, []
    for lineno, line in numbered_lines(read_text(path, "node table")):
        s = line.split("#", 1)[0].strip()
        if not s:
            continue
        parts = split_fields(s)
        if cols is None:
            try:
                [float(p) for p in parts]
            except ValueError:
                pass
            else:
                raise ValueError(f"{path}:{lineno}: a node table needs a header naming its columns "
                                 f"({', '.join(COLUMNS)}); the first line is numbers")
            named = [_column_name(p) for p in parts]
            wrong = sorted({u for _, u in named if u is not None and u != length_unit})
            if wrong:
                raise ValueError(f"{path}:{lineno}: the header gives lengths in {wrong}, the solver unit is "
                                 f"length_unit={length_unit!r}; give the unit the file is in")
            names = [n for n, _ in named]
            cols = [next((i for i, n in enumerate(names) if n in alts), None) for alts in COLUMNS.values()]
            if None in cols:
                missing = [k for k, c in zip(COLUMNS, cols) if c is None]
                raise ValueError(f"{path}:{lineno}: header {parts} has no column for {missing}; accepted names: "
                                 + "; ".join(f"{k}: {', '.join(v)}" for k, v in COLUMNS.items()))
            continue
        try:
            values = [float(parts[i]) for i in cols]
        except (ValueError, IndexError):
            raise ValueError(f"{path}:{lineno}: expected numbers in columns {[c + 1 for c in cols]}, got {s!r}") from None
        if not np.all(np.isfinite(values)):
            raise ValueError(f"{path}:{lineno}: non-finite value in {s!r}")
        rows.append(values)
    if cols is None or not rows:
        raise ValueError(f"{path}: no node rows under a header naming {', '.join(COLUMNS)}")
    a = np.array(rows)
    return a[:, :3], a[:, 3:]


def face_triangles(points: np.ndarray, spec: FaceSpec, tol: float) -> tuple[list, FaceSpec]:
    """Linear triangles (global node indices) over the nodes of the face ``spec`` names, and
    the plane spec that selects them (:func:`fea.fe_face.select_face` on the triangles).

    ``spec`` is a plane, or an axis-aligned outward normal (the table's extreme plane along
    that axis); a set or an oblique normal needs elements and is refused.
    """
    from scipy.spatial import Delaunay, cKDTree

    points = np.asarray(points, float)
    if spec.kind == "normal":
        d = np.asarray(spec.direction)
        axis = int(np.argmax(np.abs(d)))
        if not np.isclose(abs(d[axis]), 1.0):
            raise ValueError(f"surface normal {tuple(d)}: a node table has no elements, so only a plane "
                             "('z=10') or an axis ('+z', '-x') selects its face")
        value = points[:, axis].max() if d[axis] > 0 else points[:, axis].min()
        spec = FaceSpec("plane", axis=axis, value=float(value))
    elif spec.kind != "plane":
        raise ValueError(f"surface={spec.name!r}: a node table has no node or element sets; give a plane such "
                         "as 'z=10' or an axis such as '+z'")
    on = np.flatnonzero(np.abs(points[:, spec.axis] - spec.value) <= tol)
    lo, hi = points[:, spec.axis].min(), points[:, spec.axis].max()
    if on.size < 3:
        raise ValueError(f"surface: {on.size} nodes lie on the plane {'xyz'[spec.axis]}={spec.value:g} within "
                         f"tol={tol:g} (the table spans {'xyz'[spec.axis]} = {lo:g} .. {hi:g}); a face needs 3")
    plane = np.delete(points[on], spec.axis, axis=1)
    try:
        tri = Delaunay(plane).simplices
    except Exception as exc:  # scipy's Qhull error: collinear or repeated nodes
        raise ValueError(f"surface: the {on.size} nodes on the plane cannot be triangulated ({exc}); "
                         "are they all on one line?") from None
    edges = np.stack([np.linalg.norm(plane[tri[:, i]] - plane[tri[:, (i + 1) % 3]], axis=1) for i in range(3)], 1)
    spacing = cKDTree(plane).query(plane, k=2)[0][:, 1]  # each node's nearest neighbour: the local mesh size
    keep = edges.max(axis=1) <= MAX_EDGE_OVER_SPACING * spacing[tri].max(axis=1)
    return [("triangle", on[tri[keep]])], spec
