r"""Quasi-2-D verification slice through one lightweighting hole.

:func:`cell_mesh` meshes a thin slice (thickness ``slice_mm`` along y) of a
quarter of one lightweighting cell, optionally with *explicitly meshed* NiP
film layers, so that a thin-layer (membrane) film formulation can be checked
against a resolved film.

Cross-section in the x-z plane (all lengths mm, film thicknesses um)::

    z
    ^   film_front: T/2 <= z <= T/2 + t_front, 0 <= x <= pitch/2
    |______________________
    |                      |
    |_  substrate          |   substrate: 0 <= x <= pitch/2, 0 <= z <= T/2,
    |  `.                  |              rho = hypot(x, z) >= r
    |    \ film_hole       |   film_hole: r - t_hole <= rho <= r (inside the
    |     |                |              hole: adds material, the aluminium
    +-----+----------------+-> x          is unchanged)

Boundaries (``mesh.boundaries``): ``sym_x0`` (x = 0), ``sym_xp``
(x = pitch/2), ``sym_z`` (z = 0), ``y0``/``y1`` (y = 0 / y = slice_mm),
``front`` (aluminium face z = T/2; an interior interface when a front film
is meshed), ``hole`` (aluminium hole wall rho = r; an interface when a hole
film is meshed), ``film_top`` (z = T/2 + t_front, only with a front film),
``film_bore`` (free film surface rho = r - t_hole, only with a hole film).
The symmetry and slice boundaries include the film facets.
Subdomains: ``substrate`` and ``film`` (possibly empty) element indices.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from skfem import MeshTet2

from ..mesh import generate_order2, name_surfaces
from ..mesh_cache import (FORMAT_VERSION, cached_mesh, gmsh_session,
                         tet2_from_gmsh)

__all__ = ["cell_mesh", "cell_volumes_mm3"]


def _check(name, value, ok, valid):
    if isinstance(value, bool) or not isinstance(value, (int, float)) \
            or not math.isfinite(value) or not ok(value):
        raise ValueError(f"{name}={value!r}: valid range is {valid}")


def cell_volumes_mm3(pitch_mm=21.0, thickness_mm=20.0, hole_diameter_mm=15.0,
                     slice_mm=1.0, film_hole_um=0.0, film_front_um=0.0):
    """Analytic (substrate, film) volumes of the slice, mm^3."""
    r, t_h, t_f = hole_diameter_mm / 2, film_hole_um / 1e3, film_front_um / 1e3
    sub = pitch_mm / 2 * thickness_mm / 2 - math.pi * r**2 / 4
    film = math.pi / 4 * (r**2 - (r - t_h)**2) + pitch_mm / 2 * t_f
    return sub * slice_mm, film * slice_mm


def cell_mesh(pitch_mm: float = 21.0, thickness_mm: float = 20.0,
              hole_diameter_mm: float = 15.0, slice_mm: float = 1.0,
              film_hole_um: float = 0.0, film_front_um: float = 0.0, *,
              size_mm: float = 0.1, size_bulk_mm: float = 0.5,
              film_layers: int = 2, slice_layers: int = 1,
              cache_dir: Path | None = None,
              progress: bool = False) -> MeshTet2:
    """Curved P2 tet mesh of a quarter-cell slice, optionally with films.

    Parameters
    ----------
    pitch_mm : float
        Hole pitch along x; the slice spans 0 <= x <= pitch/2, mm.
    thickness_mm : float
        Blank thickness; the slice spans 0 <= z <= thickness/2, mm.
    hole_diameter_mm : float
        Diameter of the hole along y centred at x = z = 0, mm.
    slice_mm : float
        Extent along y, mm.
    film_hole_um, film_front_um : float
        Thickness of the explicitly meshed film inside the hole / on the
        front face, um; 0 = no film there.
    size_mm : float
        Element size along the films, the front face and the hole wall, mm.
    size_bulk_mm : float
        Element size far from them, mm.
    film_layers : int
        Quadratic elements through each film's thickness (>= 2).
    slice_layers : int
        Element layers along y.
    cache_dir : pathlib.Path, optional
        Mesh cache (see :func:`fea.mesh.blank_mesh`).
    progress : bool
        Show gmsh's terminal output.

    Returns
    -------
    skfem.MeshTet2
        Coordinates in mm; boundaries and subdomains as in the module
        docstring.
    """
    _check("pitch_mm", pitch_mm, lambda v: v > 0, "> 0 mm")
    _check("thickness_mm", thickness_mm, lambda v: v > 0, "> 0 mm")
    _check("slice_mm", slice_mm, lambda v: v > 0, "> 0 mm")
    r = hole_diameter_mm / 2
    lim = min(pitch_mm, thickness_mm) - 1.0
    _check("hole_diameter_mm", hole_diameter_mm, lambda v: 0 < v <= lim,
           f"0 < hole_diameter_mm <= min(pitch_mm, thickness_mm) - 1 = "
           f"{lim:g} mm (0.5 mm walls)")
    _check("film_hole_um", film_hole_um, lambda v: 0 <= v < 500 * r,
           f"0 <= film_hole_um < hole radius/2 = {500 * r:g} um")
    _check("film_front_um", film_front_um,
           lambda v: 0 <= v < 250 * thickness_mm,
           f"0 <= film_front_um < thickness/4 = {250 * thickness_mm:g} um")
    _check("size_mm", size_mm, lambda v: v > 0, "> 0 mm")
    _check("size_bulk_mm", size_bulk_mm, lambda v: v >= size_mm,
           f">= size_mm = {size_mm!r} mm")
    for name, v, lo in (("film_layers", film_layers, 2),
                        ("slice_layers", slice_layers, 1)):
        if isinstance(v, bool) or not isinstance(v, int) or v < lo:
            raise ValueError(f"{name}={v!r}: valid range is integers >= {lo}")
    params = dict(pitch_mm=pitch_mm, thickness_mm=thickness_mm,
                  hole_diameter_mm=hole_diameter_mm, slice_mm=slice_mm,
                  film_hole_um=film_hole_um, film_front_um=film_front_um,
                  size_mm=size_mm, size_bulk_mm=size_bulk_mm,
                  film_layers=film_layers, slice_layers=slice_layers)
    params = {k: (v if isinstance(v, int) and "layers" in k else float(v))
              for k, v in params.items()}
    import gmsh
    recipe = {"kind": "cell", "params": params,
              "gmsh_version": gmsh.__version__,
              "format_version": FORMAT_VERSION}

    def build():
        try:
            return _build_cell(progress=progress, **params)
        except Exception as exc:
            raise RuntimeError(f"meshing the cell slice failed: {exc} "
                               f"(parameters {params})") from exc

    return cached_mesh("cell", recipe, build, cache_dir)


def _build_cell(pitch_mm, thickness_mm, hole_diameter_mm, slice_mm,
                film_hole_um, film_front_um, size_mm, size_bulk_mm,
                film_layers, slice_layers, progress):
    half_p, half_t, r = pitch_mm / 2, thickness_mm / 2, hole_diameter_mm / 2
    t_h, t_f = film_hole_um / 1e3, film_front_um / 1e3
    tol = 1e-7 * max(half_p, half_t)
    with gmsh_session(progress) as gmsh:
        occ = gmsh.model.occ
        # drawn in the x-y plane (y standing for z), rotated afterwards
        sub, _ = occ.cut([(2, occ.addRectangle(0, 0, 0, half_p, half_t))],
                         [(2, occ.addDisk(0, 0, 0, r, r))])
        pieces = list(sub)
        if t_h > 0:
            ring, _ = occ.cut([(2, occ.addDisk(0, 0, 0, r, r))],
                              [(2, occ.addDisk(0, 0, 0, r - t_h, r - t_h))])
            ring, _ = occ.intersect(ring, [(2, occ.addRectangle(0, 0, 0,
                                                                r, r))])
            pieces += ring
        if t_f > 0:
            pieces.append((2, occ.addRectangle(0, half_t, 0, half_p, t_f)))
        if len(pieces) > 1:  # gmsh skips (returns []) a 1-shape fragment
            pieces, _ = occ.fragment(pieces, [])
        occ.rotate(pieces, 0, 0, 0, 1, 0, 0, math.pi / 2)  # y -> z
        occ.extrude(pieces, 0, slice_mm, 0, numElements=[slice_layers])
        occ.synchronize()
        # source faces keep their tags through the extrusion; their 2-D
        # mesh is copied layer by layer along y
        _structure_films(gmsh, pieces, r, t_h, half_t, t_f, size_mm,
                         film_layers, tol)
        vols = {"substrate": [], "film": []}
        for _, v in gmsh.model.getEntities(3):
            bb = np.array(gmsh.model.getBoundingBox(3, v)).reshape(2, 3)
            film = bb[0, 2] > half_t - tol or (bb[1, 0] < r + tol
                                               and bb[1, 2] < r + tol)
            vols["film" if film else "substrate"].append(v)
        surf = _classify(gmsh, half_p, half_t, r, t_h, t_f, slice_mm, tol)
        sgroups = {n: gmsh.model.addPhysicalGroup(2, tags, name=n)
                   for n, tags in sorted(surf.items())}
        vgroups = {n: gmsh.model.addPhysicalGroup(3, tags, name=n)
                   for n, tags in vols.items() if tags}
        _size_field(gmsh, surf, size_mm, size_bulk_mm)
        generate_order2(gmsh)
        mesh = tet2_from_gmsh(gmsh, sgroups, vgroups)
        if "film" not in mesh.subdomains:
            mesh.subdomains["film"] = np.zeros(0, dtype=np.int64)
        return mesh


def _structure_films(gmsh, pieces, r, t_h, half_t, t_f, size_mm,
                     film_layers, tol):
    """Structured (transfinite) triangles in the films: boundary-layer style,
    exactly ``film_layers`` elements through each film."""
    if t_h == 0 and t_f == 0:
        return
    for dim, s in pieces:
        bb = np.array(gmsh.model.getBoundingBox(dim, s)).reshape(2, 3)
        is_front = t_f > 0 and bb[0, 2] > half_t - tol
        is_ring = t_h > 0 and bb[1, 0] < r + tol and bb[1, 2] < r + tol
        if not (is_front or is_ring):
            continue
        # both arcs of the ring get the count of the outer one, so that
        # opposite sides of the transfinite patch match
        n_along = max(2, math.ceil((math.pi / 2 * r if is_ring else
                                    bb[1, 0] - bb[0, 0]) / size_mm))
        for _, c in gmsh.model.getBoundary([(dim, s)], oriented=False):
            cb = np.array(gmsh.model.getBoundingBox(1, c)).reshape(2, 3)
            ext = (cb[1] - cb[0])[[0, 2]]  # the faces lie in y = 0
            across = (ext.min() < tol) if is_ring else (ext[1] > tol)
            n = film_layers if across else n_along
            gmsh.model.mesh.setTransfiniteCurve(c, n + 1)
        gmsh.model.mesh.setTransfiniteSurface(s)


def _classify(gmsh, half_p, half_t, r, t_h, t_f, slice_mm, tol):
    planes = {(0, 0.0): "sym_x0", (0, half_p): "sym_xp", (2, 0.0): "sym_z",
              (1, 0.0): "y0", (1, slice_mm): "y1", (2, half_t): "front"}
    if t_f > 0:
        planes[(2, half_t + t_f)] = "film_top"

    def arc(tag, bb):
        rho = bb[1, [0, 2]].max()  # quarter arcs about the y-axis
        if abs(rho - r) < tol:
            return "hole"
        if t_h > 0 and abs(rho - (r - t_h)) < tol:
            return "film_bore"
        return None

    return name_surfaces(gmsh, planes, tol, arc, what="cell surface")


def _size_field(gmsh, surf, size_mm, size_bulk_mm):
    f = gmsh.model.mesh.field
    dist = f.add("Distance")
    f.setNumbers(dist, "SurfacesList", surf["front"] + surf["hole"])
    f.setNumber(dist, "Sampling", int(min(300, max(40, 40 / size_mm))))
    th = f.add("Threshold")
    f.setNumber(th, "InField", dist)
    f.setNumber(th, "SizeMin", size_mm)
    f.setNumber(th, "SizeMax", size_bulk_mm)
    f.setNumber(th, "DistMin", 2 * size_mm)
    f.setNumber(th, "DistMax", 2 * size_mm + 3 * size_bulk_mm)
    f.setAsBackgroundMesh(th)
    for opt in ("MeshSizeExtendFromBoundary", "MeshSizeFromPoints",
                "MeshSizeFromCurvature"):
        gmsh.option.setNumber(f"Mesh.{opt}", 0)
