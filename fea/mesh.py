"""Curved quadratic tetrahedral meshes of the grating blank (gmsh OCC).

:func:`blank_mesh` builds the blank of :class:`fea.geometry.Blank` with the
OpenCASCADE kernel (box minus both families of cylinders, then, for a
symmetric part, intersected with the part box), meshes it with 10-node
tetrahedra whose mid-edge nodes lie on the curved hole walls, and returns a
``skfem.MeshTet2`` with named boundaries.  Meshes are cached on disk
(:mod:`fea.mesh_cache`).

Boundary names (``mesh.boundaries``; a name is present iff that surface
exists in the part):

======== =====================================================
front    ruled face, z = +thickness/2
back     z = -thickness/2 (absent for "eighth")
side_x   faces at x = +-size_x/2
side_y   faces at y = +-size_y/2
holes_x  walls of the holes whose axis runs along x
holes_y  walls of the holes whose axis runs along y
sym_x    symmetry cut x = 0 ("eighth", "quarter")
sym_y    symmetry cut y = 0 ("eighth", "quarter")
sym_z    symmetry cut z = 0 ("eighth")
======== =====================================================
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from skfem import MeshTet2

from .geometry import Blank
from .errors import ParameterError
from .mesh_cache import (FORMAT_VERSION, cached_mesh, gmsh_session,
                         tet2_from_gmsh)

__all__ = ["MeshSpec", "blank_mesh", "blank_recipe", "write_vtu",
           "SYMMETRIES", "name_surfaces", "generate_order2"]

#: Part of the blank that is meshed -> (x >= 0, y >= 0, z >= 0) cuts.
SYMMETRIES = {"eighth": (True, True, True), "quarter": (True, True, False),
              "full": (False, False, False)}

# Worst accepted minimum scaled Jacobian of a curved tet after gmsh's
# high-order optimisation; below this the P2 map is near-degenerate.
_MIN_SCALED_JACOBIAN = 0.05


@dataclass(frozen=True)
class MeshSpec:
    """How to mesh the blank.

    Parameters
    ----------
    size_mm : float
        Element size within ``fine_depth`` of the front/back faces and the
        hole walls (so the 2.5 mm walls between hole and face), mm.
    size_bulk_mm : float
        Element size far from those surfaces, mm; graded linearly in between
        over a distance of ``2 * size_bulk_mm``.
    symmetry : {"eighth", "quarter", "full"}
        Meshed part: "eighth" = x, y, z >= 0 (needs a z-symmetric blank),
        "quarter" = x, y >= 0, "full" = the whole blank.
    order : int
        Geometric order; only 2 (10-node tets with mid-edge nodes on the
        curved surfaces) is supported.
    hole_segments : int
        Minimum number of elements around a hole's circumference (caps the
        size on hole walls at ``2 pi r / hole_segments``).  Below 12, the
        curved elements of coarse meshes made skfem's ``FacetBasis`` fail
        ("Newton iteration didn't converge").

    Notes
    -----
    ``fine_depth`` = max(size_mm, half the thinner hole-to-face wall), so
    every point of the walls is meshed at ``size_mm``.
    """

    size_mm: float = 1.4
    size_bulk_mm: float = 2.8
    symmetry: str = "eighth"
    order: int = 2
    hole_segments: int = 12

    def __post_init__(self):
        for name in ("size_mm", "size_bulk_mm"):
            v = getattr(self, name)
            if not isinstance(v, (int, float)) or isinstance(v, bool) \
                    or not math.isfinite(v) or v <= 0:
                raise ParameterError(name, v, f"{name}={v!r}: valid range is a finite "
                                 "number > 0 mm")
        if self.size_bulk_mm < self.size_mm:
            raise ParameterError("size_bulk_mm", self.size_bulk_mm, f"size_bulk_mm={self.size_bulk_mm!r}: valid "
                             f"range is >= size_mm={self.size_mm!r}")
        if self.symmetry not in SYMMETRIES:
            raise ValueError(f"symmetry={self.symmetry!r}: valid values are "
                             f"{sorted(SYMMETRIES)}")
        if isinstance(self.hole_segments, bool) or not isinstance(
                self.hole_segments, int) or self.hole_segments < 8:
            raise ValueError(f"hole_segments={self.hole_segments!r}: valid "
                             "range is integers >= 8 (12 recommended)")
        if self.order != 2:
            raise ValueError(f"order={self.order!r}: only 2 is supported "
                             "(curved quadratic tetrahedra)")

    @classmethod
    def coarse(cls, symmetry: str = "eighth") -> "MeshSpec":
        """Fast mesh for tests: ~25 k P2 DOFs, ~1 s for the default eighth."""
        return cls(size_mm=5.0, size_bulk_mm=10.0, symmetry=symmetry)

    @classmethod
    def fine(cls, symmetry: str = "eighth") -> "MeshSpec":
        """Convergence-check mesh (several times the default DOFs)."""
        return cls(size_mm=0.8, size_bulk_mm=1.6, symmetry=symmetry)

    def key(self) -> dict:
        """All fields as a plain, JSON-able dict."""
        return dataclasses.asdict(self)


def _part_bounds(blank: Blank, symmetry: str):
    """(lo, hi) corners of the meshed part, mm."""
    half = np.array([blank.size_x_mm, blank.size_y_mm,
                     blank.thickness_mm]) / 2
    lo = np.where(SYMMETRIES[symmetry], 0.0, -half)
    return lo, half


def name_surfaces(gmsh, planes: dict, tol: float, name_curved, what: str = "surface") -> dict[str, list[int]]:
    """Boundary name -> OCC surface tags of the current gmsh model, from each face's geometry.

    Parameters
    ----------
    gmsh : module
        An open gmsh session with a synchronised OCC model.
    planes : dict (axis, coordinate_mm) -> str
        Names of the axis-aligned planes a flat face may lie in.
    tol : float
        Geometric tolerance (mm).
    name_curved : callable (tag, bounding box (2, 3)) -> str or None
        Name of a face that is not flat in one axis.
    what : str
        How the error message calls a face.

    Raises
    ------
    RuntimeError
        A face that gets no name (a modelling error, not bad input).
    """
    groups: dict[str, list[int]] = {}
    for _, tag in gmsh.model.getEntities(2):
        bb = np.array(gmsh.model.getBoundingBox(2, tag)).reshape(2, 3)
        flat = np.nonzero(bb[1] - bb[0] < tol)[0]
        if len(flat) == 1:
            c = bb[:, flat[0]].mean()
            name = next((n for (ax, v), n in planes.items() if ax == flat[0] and abs(c - v) < tol), None)
        else:
            name = name_curved(tag, bb)
        if name is None:
            raise RuntimeError(f"{what} {tag} (bounding box {bb.tolist()}) matches no named boundary")
        groups.setdefault(name, []).append(tag)
    return groups


def _classify_surfaces(gmsh, blank: Blank, symmetry: str) -> dict:
    """Boundary name -> list of OCC surface tags, from each face's geometry."""
    lo, hi = _part_bounds(blank, symmetry)
    scale = max(blank.size_x_mm, blank.size_y_mm, blank.thickness_mm)
    tol = 1e-6 * scale
    planes = {  # (axis, coordinate) -> name
        (2, hi[2]): "front", (2, -hi[2]): "back", (0, hi[0]): "side_x",
        (0, -hi[0]): "side_x", (1, hi[1]): "side_y", (1, -hi[1]): "side_y"}
    for axis, cut in enumerate(SYMMETRIES[symmetry]):
        if cut:
            planes[(axis, 0.0)] = "sym_" + "xyz"[axis]
    r, z0 = blank.hole_radius_mm, blank.hole_axis_z_mm

    def hole_wall(tag, bb):
        # sample the face; a wall of a hole along x has normals with
        # zero x-component and lies at distance r from an x-axis
        umin, umax = gmsh.model.getParametrizationBounds(2, tag)
        uv = np.array([[umin[0] + f * (umax[0] - umin[0]),
                        umin[1] + g * (umax[1] - umin[1])]
                       for f in (0.2, 0.5, 0.8) for g in (0.3, 0.7)])
        pts = gmsh.model.getValue(2, tag, uv.ravel()).reshape(-1, 3)
        nrm = np.abs(gmsh.model.getNormal(tag, uv.ravel())).reshape(-1, 3)
        name = None
        for name_, ax, other, axes_pos in (
                ("holes_x", 0, 1, blank.hole_y_positions_mm),
                ("holes_y", 1, 0, blank.hole_x_positions_mm)):
            if len(axes_pos) == 0 or nrm[:, ax].max() > 1e-6:
                continue
            rho = np.hypot(pts[:, other][:, None] - axes_pos[None, :],
                           pts[:, 2][:, None] - z0)
            if np.all(np.abs(rho - r).min(axis=1) < tol):
                name = name_
        return name

    return name_surfaces(gmsh, planes, tol, hole_wall)


def _add_size_field(gmsh, blank: Blank, spec: MeshSpec, groups: dict):
    """Fine near the faces z = +-T/2 and the hole walls, coarse elsewhere."""
    walls = [blank.wall_front_mm, blank.wall_back_mm]
    fine_depth = max(spec.size_mm, 0.5 * min(walls))
    f = gmsh.model.mesh.field
    half_t = blank.thickness_mm / 2
    # exact distance to the front/back planes (a sampled Distance field
    # would be coarse on the 160 x 140 mm faces)
    plane = f.add("MathEval")
    f.setString(plane, "F", f"{half_t} - Fabs(z)")
    sources = [plane]
    hole_tags = groups.get("holes_x", []) + groups.get("holes_y", [])
    if hole_tags:
        dist = f.add("Distance")
        f.setNumbers(dist, "SurfacesList", hole_tags)
        # ~ size/3 sample spacing on a 21 mm long, 12 mm wide wall piece
        f.setNumber(dist, "Sampling",
                    int(min(200, max(20, 60 / spec.size_mm))))
        sources.append(dist)
    # cap the size on the hole walls: with fewer than ~12 elements per turn
    # the P2 elements are so curved that skfem's FacetBasis (Newton inverse
    # of the element map, started outside the reference tet) can fail
    hole_size = min(spec.size_mm,
                    2 * math.pi * blank.hole_radius_mm / spec.hole_segments)
    thresholds = []
    for src in sources:
        th = f.add("Threshold")
        f.setNumber(th, "InField", src)
        f.setNumber(th, "SizeMin", spec.size_mm if src == plane else hole_size)
        f.setNumber(th, "SizeMax", spec.size_bulk_mm)
        f.setNumber(th, "DistMin", fine_depth)
        f.setNumber(th, "DistMax", fine_depth + 2 * spec.size_bulk_mm)
        thresholds.append(th)
    fmin = f.add("Min")
    f.setNumbers(fmin, "FieldsList", thresholds)
    f.setAsBackgroundMesh(fmin)
    for opt in ("MeshSizeExtendFromBoundary", "MeshSizeFromPoints",
                "MeshSizeFromCurvature"):
        gmsh.option.setNumber(f"Mesh.{opt}", 0)
    gmsh.option.setNumber("Mesh.MeshSizeMax", spec.size_bulk_mm)


def generate_order2(gmsh) -> None:
    """Mesh in 3-D, elevate to curved order 2, reject invalid elements."""
    gmsh.option.setNumber("Mesh.Algorithm3D", 10)  # HXT: fewest elements
    gmsh.option.setNumber("Mesh.Optimize", 1)
    gmsh.model.mesh.generate(3)
    gmsh.model.mesh.setOrder(2)
    tags, _ = gmsh.model.mesh.getElementsByType(11)
    q = gmsh.model.mesh.getElementQualities(tags, "minSJ")
    if q.min() < _MIN_SCALED_JACOBIAN:
        gmsh.option.setNumber("Mesh.HighOrderOptimize", 2)
        gmsh.model.mesh.optimize("HighOrder")
        tags, _ = gmsh.model.mesh.getElementsByType(11)
        q = gmsh.model.mesh.getElementQualities(tags, "minSJ")
        if q.min() <= 0.0:
            raise RuntimeError(f"{np.sum(q <= 0)} curved tetrahedra are "
                               f"inverted (min scaled Jacobian {q.min():.3g})")


def _build_blank(blank: Blank, spec: MeshSpec, progress: bool) -> MeshTet2:
    with gmsh_session(progress) as gmsh:
        occ = gmsh.model.occ
        lx, ly, lt = blank.size_x_mm, blank.size_y_mm, blank.thickness_mm
        body = [(3, occ.addBox(-lx / 2, -ly / 2, -lt / 2, lx, ly, lt))]
        r, z0 = blank.hole_radius_mm, blank.hole_axis_z_mm
        # cylinders overhang the blank so no face is left coincident
        over_x, over_y = 0.1 * lx + 1.0, 0.1 * ly + 1.0
        tools = [(3, occ.addCylinder(x, -ly / 2 - over_y, z0,
                                     0, ly + 2 * over_y, 0, r))
                 for x in blank.hole_x_positions_mm]
        tools += [(3, occ.addCylinder(-lx / 2 - over_x, y, z0,
                                      lx + 2 * over_x, 0, 0, r))
                  for y in blank.hole_y_positions_mm]
        if tools:
            body, _ = occ.cut(body, tools)
        if spec.symmetry != "full":
            lo, hi = _part_bounds(blank, spec.symmetry)
            part = occ.addBox(*lo, *(hi - lo))
            body, _ = occ.intersect(body, [(3, part)])
        occ.synchronize()
        if len(body) != 1:
            raise RuntimeError(f"boolean gave {len(body)} volumes, expected 1")
        groups = _classify_surfaces(gmsh, blank, spec.symmetry)
        surface_groups = {name: gmsh.model.addPhysicalGroup(2, tags, name=name)
                          for name, tags in sorted(groups.items())}
        vol = gmsh.model.addPhysicalGroup(3, [body[0][1]], name="blank")
        _add_size_field(gmsh, blank, spec, groups)
        generate_order2(gmsh)
        return tet2_from_gmsh(gmsh, surface_groups, {"blank": vol})


def blank_recipe(blank: Blank, spec: MeshSpec) -> dict:
    """Everything that determines the mesh; its sha256 is the cache key."""
    import gmsh
    return {"kind": "blank", "blank": blank.key(), "spec": spec.key(),
            "gmsh_version": gmsh.__version__,
            "format_version": FORMAT_VERSION}


def blank_mesh(blank: Blank, spec: MeshSpec = MeshSpec(),
               cache_dir: Path | None = None,
               progress: bool = False) -> MeshTet2:
    """Curved quadratic tetrahedral mesh of (a symmetric part of) the blank.

    Parameters
    ----------
    blank : Blank
        Geometry, mm.
    spec : MeshSpec
        Element sizes, mm, and the meshed part.
    cache_dir : pathlib.Path, optional
        Mesh cache; default ``$CRYOGRATING_MESH_CACHE`` or
        ``<repo>/meshes/cache``.
    progress : bool
        Show gmsh's terminal output.

    Returns
    -------
    skfem.MeshTet2
        Coordinates in mm.  ``boundaries``: see the module docstring;
        ``subdomains``: {"blank": all elements}.

    Raises
    ------
    ValueError
        ``symmetry="eighth"`` with a blank that is not z-symmetric.
    RuntimeError
        If gmsh fails; the message names the parameters.
    """
    if spec.symmetry == "eighth" and not blank.is_z_symmetric:
        raise ValueError(
            f"symmetry='eighth' needs a z-symmetric blank, but hole_axis_z_mm"
            f"={blank.hole_axis_z_mm!r}; valid: hole_axis_z_mm == 0, or use "
            "symmetry='quarter' or 'full'")
    recipe = blank_recipe(blank, spec)

    def build():
        try:
            return _build_blank(blank, spec, progress)
        except Exception as exc:
            raise RuntimeError(f"meshing the blank failed: {exc} "
                               f"(blank={blank}, spec={spec})") from exc

    return cached_mesh("blank", recipe, build, cache_dir)


def write_vtu(mesh: MeshTet2, path, point_data: dict | None = None) -> None:
    """Write a quadratic mesh (tetra10) and nodal fields for ParaView.

    Parameters
    ----------
    mesh : skfem.MeshTet2
    path : str or pathlib.Path
        Output ``.vtu`` file.
    point_data : dict[str, ndarray], optional
        Fields at the nodes ``mesh.doflocs``, each of shape (n_nodes,) or
        (n_nodes, k).  A displacement ``u`` on
        ``Basis(mesh, ElementVector(ElementTetP2()))`` is passed as
        ``u.reshape(-1, 3)`` (skfem interleaves x, y, z per node).
    """
    import meshio
    t10 = mesh.dofs.element_dofs  # skfem: 4 vertices then 6 edges
    # skfem local edges (0,1),(1,2),(0,2),(0,3),(1,3),(2,3) coincide with
    # VTK's quadratic-tetra edge order
    cells = [("tetra10", np.ascontiguousarray(t10.T))]
    point_data = {k: np.asarray(v) for k, v in (point_data or {}).items()}
    for k, v in point_data.items():
        if v.shape[0] != mesh.doflocs.shape[1]:
            raise ValueError(f"point_data[{k!r}] has {v.shape[0]} rows; "
                             f"valid: {mesh.doflocs.shape[1]} (one per node)")
    meshio.write(str(path), meshio.Mesh(mesh.doflocs.T, cells,
                                        point_data=point_data))
