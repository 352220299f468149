"""The optical face of any FE mesh: boundary faces, face selection, normals, nodal areas.

Works on plain arrays as meshio gives them: ``points`` (n, 3) and cell blocks
``[(cell_type, connectivity (m, k)), ...]`` in meshio (VTK) node order. Volume cells
(``tetra``, ``tetra10``, ``hexahedron``, ``hexahedron20``, ``hexahedron27``, ``wedge``,
``wedge15``) give their boundary faces with an outward normal; surface cells
(``triangle``, ``triangle6``, ``quad``, ``quad8``, ``quad9``) are faces themselves,
without a known outward side.

A face is selected by a :class:`FaceSpec`, parsed from text by :func:`parse_surface`:

* a name: a node set (Abaqus NSET, Exodus node set), a cell set of surface cells
  (Abaqus ELSET) or a gmsh physical group — the boundary faces whose corner nodes
  are all in the set;
* a plane ``z=10`` (also ``x=…``, ``y=…``; value in the mesh's length unit) with a
  tolerance: the boundary faces whose corners all lie within the tolerance;
* an outward normal ``+z`` / ``-x`` / ``normal:0,0.2,1``: the boundary faces whose
  outward normal is within ``angle_tol_deg`` of it.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

__all__ = ["FaceSpec", "FaceMesh", "parse_surface", "boundary_faces", "select_face", "FACE_TYPES",
           "VOLUME_TYPES"]

#: Face cell types: number of corners, total nodes, polynomial order.
FACE_TYPES = {"triangle": (3, 3, 1), "triangle6": (3, 6, 2), "quad": (4, 4, 1), "quad8": (4, 8, 2),
              "quad9": (4, 9, 2)}

_TET_EDGES = {(0, 1): 4, (1, 2): 5, (0, 2): 6, (0, 3): 7, (1, 3): 8, (2, 3): 9}
_HEX_EDGES = {(0, 1): 8, (1, 2): 9, (2, 3): 10, (0, 3): 11, (4, 5): 12, (5, 6): 13, (6, 7): 14,
              (4, 7): 15, (0, 4): 16, (1, 5): 17, (2, 6): 18, (3, 7): 19}
_WEDGE_EDGES = {(0, 1): 6, (1, 2): 7, (0, 2): 8, (3, 4): 9, (4, 5): 10, (3, 5): 11, (0, 3): 12,
                (1, 4): 13, (2, 5): 14}
_TET_FACES = [(0, 1, 2), (0, 1, 3), (1, 2, 3), (0, 2, 3)]
_HEX_FACES = [(0, 1, 2, 3), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)]
_WEDGE_FACES = [(0, 1, 2), (3, 4, 5), (0, 1, 4, 3), (1, 2, 5, 4), (2, 0, 3, 5)]

#: Volume cell types: (n corners, faces as corner tuples, edge -> mid-node or None).
#: Hexahedron27 faces are used as 8-node (serendipity) faces: the face centre is dropped.
VOLUME_TYPES = {
    "tetra": (4, _TET_FACES, None), "tetra10": (4, _TET_FACES, _TET_EDGES),
    "hexahedron": (8, _HEX_FACES, None), "hexahedron20": (8, _HEX_FACES, _HEX_EDGES),
    "hexahedron27": (8, _HEX_FACES, _HEX_EDGES),
    "wedge": (6, _WEDGE_FACES, None), "wedge15": (6, _WEDGE_FACES, _WEDGE_EDGES),
}


@dataclass(frozen=True)
class FaceSpec:
    """How to find the optical face.

    Attributes
    ----------
    kind : {"set", "plane", "normal"}
    name : str
        Set or physical-group name (``kind="set"``).
    axis : int
        0, 1, 2 for a plane ``x``, ``y``, ``z`` = ``value``.
    value : float
        Plane position (mesh length unit).
    direction : tuple of float
        Outward normal (``kind="normal"``), normalised.
    """

    kind: str
    name: str = ""
    axis: int = 2
    value: float = 0.0
    direction: tuple = (0.0, 0.0, 1.0)


_PLANE = re.compile(r"^\s*([xyzXYZ])\s*=\s*([-+0-9.eE]+)\s*$")
_AXIS = re.compile(r"^\s*([+-])\s*([xyzXYZ])\s*$")


def parse_surface(text: str) -> FaceSpec:
    """``"z=10"`` -> plane, ``"+z"``/``"normal:0,0,1"`` -> normal, ``"set:NAME"`` or ``"NAME"`` -> set."""
    t = str(text).strip()
    if not t:
        raise ValueError("surface='' is empty; give a set name, a plane such as 'z=10' or a normal such as '+z'")
    if m := _PLANE.match(t):
        try:
            return FaceSpec("plane", axis="xyz".index(m.group(1).lower()), value=float(m.group(2)))
        except ValueError:
            raise ValueError(f"surface={text!r}: {m.group(2)!r} is not a number") from None
    if m := _AXIS.match(t):
        d = np.zeros(3)
        d["xyz".index(m.group(2).lower())] = 1.0 if m.group(1) == "+" else -1.0
        return FaceSpec("normal", direction=tuple(d))
    if t.lower().startswith("normal:"):
        try:
            d = np.array([float(v) for v in t[7:].split(",")])
        except ValueError:
            d = np.zeros(0)
        if d.shape != (3,) or not np.linalg.norm(d) > 0:
            raise ValueError(f"surface={text!r}: expected 'normal:NX,NY,NZ' with a non-zero vector")
        return FaceSpec("normal", direction=tuple(d / np.linalg.norm(d)))
    return FaceSpec("set", name=t[4:] if t.lower().startswith("set:") else t)


@dataclass(frozen=True)
class FaceMesh:
    """Selected face cells of one mesh.

    Attributes
    ----------
    blocks : tuple of (str, ndarray (m, k))
        Face cell type (:data:`FACE_TYPES`) and connectivity into the mesh points.
    normals : tuple of ndarray (m, 3)
        Unit normal per face cell: outward when ``oriented``.
    oriented : bool
        Whether the faces came from volume cells (so that "outward" is known).
    """

    blocks: tuple
    normals: tuple
    oriented: bool

    @property
    def node_index(self) -> np.ndarray:
        """Sorted indices of every node on the face."""
        return np.unique(np.concatenate([c.ravel() for _, c in self.blocks]))

    @property
    def order(self) -> int:
        """2 when every face cell is quadratic, else 1."""
        return 2 if all(FACE_TYPES[t][2] == 2 for t, _ in self.blocks) else 1

    def nodal_area(self, points: np.ndarray) -> np.ndarray:
        """Area per mesh point (zero off the face): each cell's area shared equally by its nodes."""
        w = np.zeros(len(points))
        for (t, c), _ in zip(self.blocks, self.normals):
            a = _cell_area(points, t, c)
            np.add.at(w, c.ravel(), np.repeat(a / c.shape[1], c.shape[1]))
        return w

    def nodal_normals(self, points: np.ndarray) -> np.ndarray:
        """Area-weighted mean unit normal per mesh point (zero off the face)."""
        n = np.zeros((len(points), 3))
        for (t, c), nrm in zip(self.blocks, self.normals):
            a = _cell_area(points, t, c)
            np.add.at(n, c.ravel(), np.repeat(nrm * a[:, None], c.shape[1], axis=0))
        norm = np.linalg.norm(n, axis=1, keepdims=True)
        return np.divide(n, norm, out=np.zeros_like(n), where=norm > 0)


def _cell_normal_area(points, t, conn):
    """Unnormalised normal (length = area for triangles, ~area for planar quads)."""
    nc = FACE_TYPES[t][0]
    p = points[conn[:, :nc]]
    if nc == 3:
        return 0.5 * np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    return 0.5 * np.cross(p[:, 2] - p[:, 0], p[:, 3] - p[:, 1])


def _cell_area(points, t, conn):
    return np.linalg.norm(_cell_normal_area(points, t, conn), axis=1)


def _face_type(n_corners: int, quadratic: bool) -> str:
    return {(3, False): "triangle", (3, True): "triangle6", (4, False): "quad", (4, True): "quad8"}[
        (n_corners, quadratic)]


def boundary_faces(points: np.ndarray, blocks) -> FaceMesh:
    """Every boundary face of the volume cells in ``blocks`` (faces owned by one cell), oriented outward.

    A mesh without volume cells returns its surface cells, unoriented. Cell types that
    are neither (lines, vertices) are ignored; a mesh with none of either raises.
    """
    points = np.asarray(points, float)
    groups: dict = {}  # face type -> list of (sorted corner key, connectivity, owner centroid)
    vol = [(t, np.asarray(c)) for t, c in blocks if t in VOLUME_TYPES]
    if not vol:
        surf = [(t, np.asarray(c)) for t, c in blocks if t in FACE_TYPES]
        if not surf:
            raise ValueError(f"the mesh has no volume or surface cells of a supported type (cell types: "
                             f"{sorted({t for t, _ in blocks})}; supported: {sorted(VOLUME_TYPES)} and "
                             f"{sorted(FACE_TYPES)})")
        normals = []
        for t, c in surf:
            n = _cell_normal_area(points, t, c)
            normals.append(n / np.linalg.norm(n, axis=1, keepdims=True))
        return FaceMesh(tuple(surf), tuple(normals), False)
    for t, conn in vol:
        nc, faces, edges = VOLUME_TYPES[t]
        centroid = points[conn[:, :nc]].mean(axis=1)
        for f in faces:
            cols = list(f)
            if edges is not None:
                cols += [edges[tuple(sorted((f[i], f[(i + 1) % len(f)])))] for i in range(len(f))]
            ft = _face_type(len(f), edges is not None)
            groups.setdefault(ft, []).append((conn[:, cols], centroid))
    # a face shared by two cells is interior: count sorted corner keys over all face types
    keyed = []
    for ft, parts in groups.items():
        c = np.concatenate([p[0] for p in parts])
        cen = np.concatenate([p[1] for p in parts])
        nc = FACE_TYPES[ft][0]
        key = np.full((len(c), 4), -1, dtype=np.int64)
        key[:, :nc] = np.sort(c[:, :nc], axis=1)
        keyed.append((ft, c, cen, key))
    allkeys = np.concatenate([k for *_, k in keyed])
    _, inv, counts = np.unique(allkeys, axis=0, return_inverse=True, return_counts=True)
    inv = inv.ravel()
    out_blocks, out_normals, start = [], [], 0
    for ft, c, cen, key in keyed:
        once = counts[inv[start:start + len(c)]] == 1
        start += len(c)
        c, cen = c[once], cen[once]
        if not len(c):
            continue
        n = _cell_normal_area(points, ft, c)
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        fc = points[c[:, :FACE_TYPES[ft][0]]].mean(axis=1)
        n *= np.sign(np.einsum("ij,ij->i", n, fc - cen))[:, None]
        out_blocks.append((ft, c))
        out_normals.append(n)
    return FaceMesh(tuple(out_blocks), tuple(out_normals), True)


def _keep(face: FaceMesh, masks) -> FaceMesh:
    blocks = tuple((t, c[m]) for (t, c), m in zip(face.blocks, masks) if m.any())
    normals = tuple(n[m] for n, m in zip(face.normals, masks) if m.any())
    return FaceMesh(blocks, normals, face.oriented)


def _named_sets(point_sets, cell_sets, field_data):
    names = set(point_sets or {}) | set(cell_sets or {})
    names |= {k for k, v in (field_data or {}).items() if len(np.atleast_1d(v)) > 1 and int(v[1]) == 2}
    return sorted(names)


def select_face(points: np.ndarray, blocks, spec: FaceSpec, *, tol: float = 1e-6, angle_tol_deg: float = 1.0,
                point_sets=None, cell_sets=None, cell_data=None, field_data=None) -> FaceMesh:
    """The face cells matched by ``spec`` (see the module docstring).

    Parameters
    ----------
    points : ndarray, shape (n, 3)
        Mesh points (any length unit; ``tol`` and plane values in the same unit).
    blocks : list of (str, ndarray)
        Cell blocks as meshio's ``[(c.type, c.data) for c in mesh.cells]``.
    spec : FaceSpec
    tol : float
        Plane tolerance (mesh length unit), > 0.
    angle_tol_deg : float
        Normal-direction tolerance (degrees), in (0, 90).
    point_sets, cell_sets, cell_data, field_data : dict, optional
        meshio's sets and (for gmsh physical groups) ``cell_data["gmsh:physical"]``/``field_data``.
    """
    points = np.asarray(points, float)
    if spec.kind == "plane" and not tol > 0:
        raise ValueError(f"tol={tol} must be > 0 (plane tolerance in the mesh's length unit)")
    if spec.kind == "normal" and not 0 < angle_tol_deg < 90:
        raise ValueError(f"angle_tol_deg={angle_tol_deg} must be in (0, 90) degrees")
    face = boundary_faces(points, blocks)
    if spec.kind == "set":
        on = np.zeros(len(points), bool)
        if spec.name in (point_sets or {}):
            on[np.asarray(point_sets[spec.name], dtype=np.int64)] = True
            what = f"node set {spec.name!r} ({int(on.sum())} nodes)"
        else:
            cells = _cells_of_set(blocks, spec.name, cell_sets, cell_data, field_data)
            if cells is None:
                raise ValueError(f"surface={spec.name!r} is not a node set, cell set or physical group of the "
                                 f"mesh; valid names are {_named_sets(point_sets, cell_sets, field_data)}, or a "
                                 "plane such as 'z=10' or a normal such as '+z'")
            if not face.oriented:  # a surface mesh: the set's cells are the face
                return boundary_faces(points, cells)
            for t, c in cells:  # the volume's boundary faces on the set's nodes keep their outward side
                on[c.ravel()] = True
            what = f"cell set {spec.name!r} ({int(on.sum())} nodes)"
        masks = [on[c[:, :FACE_TYPES[t][0]]].all(axis=1) for t, c in face.blocks]
    elif spec.kind == "plane":
        on = np.abs(points[:, spec.axis] - spec.value) <= tol
        masks = [on[c[:, :FACE_TYPES[t][0]]].all(axis=1) for t, c in face.blocks]
        lo, hi = points[:, spec.axis].min(), points[:, spec.axis].max()
        what = (f"plane {'xyz'[spec.axis]}={spec.value:g} with tol={tol:g} (mesh spans "
                f"{'xyz'[spec.axis]} = {lo:g} .. {hi:g})")
    elif spec.kind == "normal":
        if not face.oriented:
            raise ValueError("surface given as a normal direction needs volume cells (a surface-only mesh has no "
                             "outward side); give a set name or a plane such as 'z=10'")
        cosmin = np.cos(np.radians(angle_tol_deg))
        masks = [n @ np.asarray(spec.direction) >= cosmin for n in face.normals]
        what = f"outward normal {tuple(round(v, 4) for v in spec.direction)} within {angle_tol_deg:g}°"
    else:
        raise ValueError(f"FaceSpec.kind={spec.kind!r} is unknown; valid kinds are 'set', 'plane', 'normal'")
    if not any(m.any() for m in masks):
        raise ValueError(f"surface: no boundary face of the mesh matches {what}")
    return _keep(face, masks)


def _cells_of_set(blocks, name, cell_sets, cell_data, field_data):
    """Surface cells of a cell set / gmsh physical group called ``name``, or None if no such set."""
    if cell_sets and name in cell_sets:
        picked = [(t, np.asarray(c)[np.asarray(idx, dtype=np.int64)])
                  for (t, c), idx in zip(blocks, cell_sets[name]) if idx is not None and len(idx)]
    elif field_data and name in field_data and cell_data and "gmsh:physical" in cell_data:
        tag = int(np.atleast_1d(field_data[name])[0])
        picked = [(t, np.asarray(c)[np.asarray(tags) == tag])
                  for (t, c), tags in zip(blocks, cell_data["gmsh:physical"])]
    else:
        return None
    picked = [(t, c) for t, c in picked if len(c)]
    if not picked:
        raise ValueError(f"surface={name!r}: the set holds no cells")
    if any(t in VOLUME_TYPES for t, _ in picked):
        raise ValueError(f"surface={name!r} is a set of volume cells; give a set of surface cells, a node set, "
                         "a plane such as 'z=10' or a normal such as '+z'")
    return [(t, c) for t, c in picked if t in FACE_TYPES]
