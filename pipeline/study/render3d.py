"""3-D render of the deformed blank: pyvista/VTK, off-screen, exaggerated deformation.

Units: mm for geometry, µm for displacement colours.

The FEA solves the symmetric part of the blank (eighth/quarter model); the render
mirrors its boundary surface through the symmetry planes to the whole body (the cut
faces on the planes are dropped, except where a cut-away exposes them), warps it by the
displacement times an exaggeration factor and colours it by u_z (µm, along the front
face's normal, relative to the substrate's uniform contraction; on the front face this
is the sag). Only the boundary surface is built: each quadratic boundary triangle
(6 nodes, curved on the hole walls) becomes 4 flat ones through its mid-edge nodes.

Off-screen rendering needs no display and no GPU: the VTK >= 9.4 wheels pick an OpenGL
back-end at run time (X11, EGL, OSMesa) and load it with dlopen. Without ``DISPLAY``
this module asks for EGL (``VTK_DEFAULT_OPENGL_WINDOW=vtkEGLRenderWindow``), which falls
back to OSMesa; both render in software with Mesa's llvmpipe. The Mesa libraries come
from the system (Debian: ``libegl1 libgl1-mesa-dri``, or ``libosmesa6``; installed by
``scripts/bootstrap`` when missing). Left to its default, VTK 9.7 tries X11 first and
segfaults when no X11 library is installed, and any back-end segfaults when none of
them can be loaded, so :func:`start_study_render` renders in a child process: a
machine without OpenGL gets a warning and no figure, never a crashed run.

Functions
---------
blank_surface        symmetric-part mesh + displacement → whole-body triangle surface
render_deformed_blank one case: oblique view of the whole blank and a cut-away view
render_comparison    several cases side by side, one exaggeration and one colour scale
start_study_render   the study's figures, solved and rendered in a guarded child process
"""

from __future__ import annotations

import json
import logging
import math
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["BlankSurface", "blank_surface", "auto_exaggeration", "render_deformed_blank",
           "render_comparison", "start_study_render", "render_study_figures", "study_renders",
           "configure_offscreen", "RenderUnavailable"]

log = logging.getLogger(__name__)

_PLANE_AXIS = {"sym_x": 0, "sym_y": 1, "sym_z": 2}
#: skfem's local edge order of a P2 tetrahedron (element_dofs rows 4..9)
_TET_EDGES = ((0, 1), (1, 2), (0, 2), (0, 3), (1, 3), (2, 3))


class RenderUnavailable(RuntimeError):
    """Off-screen rendering is not possible here (no pyvista/VTK, or no OpenGL back-end)."""


def configure_offscreen() -> None:
    """Choose VTK's OpenGL back-end before VTK is imported: EGL (→ OSMesa) without a display.

    A user's own ``VTK_DEFAULT_OPENGL_WINDOW`` is kept.
    """
    configure_offscreen_env(os.environ)


# ---------------------------------------------------------------------------- surface
@dataclass(frozen=True)
class BlankSurface:
    """Triangulated boundary of the whole blank with its nodal displacement.

    Attributes
    ----------
    points_mm : ndarray (n, 3)
    triangles : ndarray (m, 3) of int, counter-clockwise seen from outside
    displacement_mm : ndarray (n, 3)
    cut : ndarray (m,) of bool
        Triangles on a symmetry plane exposed by a cut-away.
    """

    points_mm: np.ndarray
    triangles: np.ndarray
    displacement_mm: np.ndarray
    cut: np.ndarray

    def front_mask(self, tol_mm: float = 1e-6) -> np.ndarray:
        """Nodes on the (undeformed) front face, the plane of the largest z."""
        z = self.points_mm[:, 2]
        return z > z.max() - tol_mm


def _edge_midnodes(mesh):
    """(sorted corner pair key → mid-edge node) lookup of a MeshTet2."""
    ed = mesh.dofs.element_dofs
    n = int(mesh.doflocs.shape[1])
    a = np.concatenate([ed[i] for i, _ in _TET_EDGES])
    b = np.concatenate([ed[j] for _, j in _TET_EDGES])
    mid = np.concatenate([ed[4 + k] for k in range(6)])
    keys = np.minimum(a, b).astype(np.int64) * n + np.maximum(a, b)
    keys, first = np.unique(keys, return_index=True)
    return keys, mid[first], n


def _facet_triangles(mesh, coords, facets):
    """Boundary facets → 4 flat triangles each (corners + mid-edge nodes), outward."""
    keys, mids, n = _edge_midnodes(mesh)
    F = mesh.facets[:, facets].astype(np.int64)
    # outward orientation: away from the owning tetrahedron's centroid
    owner = mesh.f2t[0, facets]
    tc = coords[:, mesh.t[:, owner]].mean(axis=1)
    fc = coords[:, F].mean(axis=1)
    nrm = np.cross((coords[:, F[1]] - coords[:, F[0]]).T, (coords[:, F[2]] - coords[:, F[0]]).T)
    flip = np.einsum("ij,ij->i", nrm, (fc - tc).T) < 0
    F[1, flip], F[2, flip] = F[2, flip], F[1, flip].copy()

    def mid(p, q):
        k = np.minimum(p, q) * n + np.maximum(p, q)
        i = np.searchsorted(keys, k)
        if not np.array_equal(keys[np.minimum(i, len(keys) - 1)], k):
            raise ValueError("a boundary edge has no mid-edge node: not a quadratic (MeshTet2) mesh")
        return mids[i]

    a, b, c = F
    ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
    return np.concatenate([np.stack(t, axis=1) for t in
                           ((a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca))])


def blank_surface(mesh, coords_mm, displacement_mm, symmetry_planes=None, *,
                  cutaway: bool = False) -> BlankSurface:
    """Whole-body boundary surface of a solved symmetric part.

    Parameters
    ----------
    mesh : skfem.MeshTet2
        The solved part (``PreparedBlank.mesh``), with ``sym_x/sym_y/sym_z`` boundaries.
    coords_mm, displacement_mm : ndarray (3, N)
        ``FEAResult.coords_mm`` and ``FEAResult.displacement_mm`` (nodes = ``mesh.doflocs``).
    symmetry_planes : sequence of str, optional
        Planes to mirror through; default: the ``sym_*`` boundaries of the mesh.
    cutaway : bool
        Leave out the quadrant x < 0, y < 0 and show the cut faces it exposes (needs the
        x and y symmetry planes; ignored otherwise).
    """
    coords = np.asarray(coords_mm, float)
    disp = np.asarray(displacement_mm, float)
    if coords.shape != disp.shape or coords.shape[0] != 3 or coords.shape[1] != mesh.doflocs.shape[1]:
        raise ValueError(f"coords {coords.shape} and displacement {disp.shape} must both be "
                         f"(3, {mesh.doflocs.shape[1]}) (one column per mesh node)")
    planes = [s for s in (symmetry_planes if symmetry_planes is not None else _PLANE_AXIS)
              if s in mesh.boundaries and s in _PLANE_AXIS]
    sym = {s: np.asarray(mesh.boundaries[s]) for s in planes}
    outer = np.setdiff1d(mesh.boundary_facets(), np.concatenate(list(sym.values())) if sym else [])
    cutaway = cutaway and "sym_x" in sym and "sym_y" in sym
    parts = [(_facet_triangles(mesh, coords, outer), None)]
    if cutaway:
        parts += [(_facet_triangles(mesh, coords, sym[s]), s) for s in ("sym_x", "sym_y")]
    pts, tris, us, cuts = [], [], [], []
    offset = 0
    axes = [_PLANE_AXIS[s] for s in planes]
    for signs in np.ndindex(*(2,) * len(axes)):
        sgn = np.ones(3)
        for ax, s in zip(axes, signs):
            sgn[ax] = -1.0 if s else 1.0
        for tri, plane in parts:
            if cutaway:
                sx, sy = sgn[0], sgn[1]
                if sx < 0 and sy < 0:
                    continue  # the removed quadrant
                # exposed cut faces: x = 0 of the (+x, -y) copy, y = 0 of the (-x, +y) copy
                if plane == "sym_x" and not (sx > 0 and sy < 0):
                    continue
                if plane == "sym_y" and not (sx < 0 and sy > 0):
                    continue
            used, inv = np.unique(tri, return_inverse=True)
            t = inv.reshape(tri.shape) + offset
            if np.prod(sgn) < 0:  # a reflection turns the triangles inside out
                t = t[:, [0, 2, 1]]
            pts.append(coords[:, used].T * sgn)
            us.append(disp[:, used].T * sgn)
            tris.append(t)
            cuts.append(np.full(len(t), plane is not None))
            offset += len(used)
    P, U, T = np.concatenate(pts), np.concatenate(us), np.concatenate(tris)
    # merge the copies' shared nodes on the symmetry planes (smooth shading across seams):
    # positions quantised to 21 bits per axis (< 0.1 µm for the default blank) in one int64
    lo = P.min(axis=0)
    res = max(float(np.ptp(P, axis=0).max()), 1e-12) / (2 ** 21 - 2)
    q = np.rint((P - lo) / res).astype(np.int64)
    key = (q[:, 0] << 42) | (q[:, 1] << 21) | q[:, 2]
    _, first, inv = np.unique(key, return_index=True, return_inverse=True)
    inv = inv.ravel()
    return BlankSurface(P[first], inv[T], U[first], np.concatenate(cuts))


def _nice(x: float) -> float:
    """The nearest (in ratio) of 1, 2 or 5 × 10^k."""
    if not (np.isfinite(x) and x > 0):
        return 1.0
    e = 10.0 ** math.floor(math.log10(x))
    return min((m * e for m in (1.0, 2.0, 5.0, 10.0)), key=lambda v: abs(math.log(v / x)))


def auto_exaggeration(surfaces, fraction: float = 0.02) -> float:
    """Factor that makes the front face's out-of-plane P/V ``fraction`` of the blank's size.

    The largest P/V over ``surfaces`` decides (a comparison shares one factor); the factor
    is rounded to the nearest 1, 2 or 5 × 10^k.
    """
    pv, size = 0.0, 0.0
    for s in surfaces:
        uz = s.displacement_mm[s.front_mask(), 2]
        pv = max(pv, float(uz.max() - uz.min()))
        size = max(size, float(np.ptp(s.points_mm, axis=0).max()))
    return _nice(fraction * size / pv) if pv > 0 else 1.0


# ---------------------------------------------------------------------------- plotting
def _pyvista():
    configure_offscreen()
    try:
        import pyvista as pv
    except Exception as exc:  # ImportError, or a broken VTK install
        raise RenderUnavailable(f"pyvista/VTK cannot be imported: {exc}") from exc
    pv.OFF_SCREEN = True
    return pv


def _polydata(pv, points, triangles, values=None):
    faces = np.column_stack([np.full(len(triangles), 3), triangles]).ravel()
    poly = pv.PolyData(points, faces)
    if values is not None:
        poly.point_data["u_z_um"] = values
    # split normals at the blank's sharp edges, smooth on the curved hole walls
    return poly.compute_normals(point_normals=True, cell_normals=False, split_vertices=True,
                                feature_angle=35.0, auto_orient_normals=False, consistent_normals=False)


def _parts(s: BlankSurface, exaggeration: float):
    """Warped points and the triangles of the front face, the cut faces and the rest."""
    P = s.points_mm + exaggeration * s.displacement_mm
    front_node = s.front_mask()
    front = front_node[s.triangles].all(axis=1)
    return P, {"front": s.triangles[front], "cut": s.triangles[s.cut & ~front],
               "body": s.triangles[~front & ~s.cut]}


def _front_box(s: BlankSurface, exaggeration: float, box_mm, n: int = 400):
    """The central box's outline on the warped front face (lifted 0.05 % of the size)."""
    from scipy.spatial import cKDTree

    hx, hy = box_mm[0] / 2, box_mm[1] / 2
    m = s.front_mask()
    xy = s.points_mm[m, :2]
    if len(xy) < 3 or hx > np.abs(xy[:, 0]).max() or hy > np.abs(xy[:, 1]).max():
        return None
    t = np.linspace(0.0, 1.0, n)
    corners = np.array([(-hx, -hy), (hx, -hy), (hx, hy), (-hx, hy), (-hx, -hy)])
    pts = np.concatenate([a + t[:, None] * (b - a) for a, b in zip(corners[:-1], corners[1:])])
    # inverse-distance weights of the 4 nearest front nodes: plenty for a drawn line
    d, i = cKDTree(xy).query(pts, k=4)
    w = 1.0 / np.maximum(d, 1e-9) ** 2
    u = np.einsum("pk,pkc->pc", w / w.sum(axis=1, keepdims=True), s.displacement_mm[m][i])
    z = s.points_mm[m, 2].max()
    lift = 5e-4 * float(np.ptp(s.points_mm, axis=0).max())
    line = np.column_stack([pts, np.full(len(pts), z + lift)]) + exaggeration * u
    # no line over a cut-away: split where the face is missing (no node near the point)
    on = d[:, 0] < 3.0 * float(np.median(d[:, 0])) + 1e-9
    runs, start = [], None
    for k, ok in enumerate(np.append(on, False)):
        if ok and start is None:
            start = k
        elif not ok and start is not None:
            if k - start > 1:
                runs.append(line[start:k])
            start = None
    return runs or None


def _clim(surfaces) -> tuple[float, float]:
    """Colour range: the front faces' u_z range (µm)."""
    v = np.concatenate([1e3 * s.displacement_mm[s.front_mask(), 2] for s in surfaces])
    lo, hi = float(v.min()), float(v.max())
    if hi - lo < 1e-9:
        lo, hi = lo - 0.5, hi + 0.5
    return lo, hi


_CMAP = "turbo"
#: the paper's central region of the front face (P/V_center), mm
CENTER_BOX_MM = (82.0, 72.0)


def _camera(plotter, s: BlankSurface, elevation_deg: float = 30.0, azimuth_deg: float = -120.0,
            zoom: float = 1.12):
    lo, hi = s.points_mm.min(axis=0), s.points_mm.max(axis=0)
    c = 0.5 * (lo + hi)
    el, az = np.radians(elevation_deg), np.radians(azimuth_deg)
    d = 4.0 * float(np.linalg.norm(hi - lo))
    pos = c + d * np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    plotter.camera_position = [tuple(pos), tuple(c), (0.0, 0.0, 1.0)]
    plotter.camera.view_angle = 25.0
    plotter.reset_camera()
    plotter.camera.zoom(zoom)
    # the title sits at the top and the colour bar at the bottom: move the blank up a little
    cam = plotter.camera
    fp, pos, up = (np.array(v, float) for v in (cam.focal_point, cam.position, cam.up))
    view = fp - pos
    up = up - view * (up @ view) / (view @ view)
    up /= np.linalg.norm(up)
    shift = -0.06 * float(np.linalg.norm(hi - lo)) * up
    cam.focal_point, cam.position = tuple(fp + shift), tuple(pos + shift)


def _view(plotter, pv, s: BlankSurface, exaggeration: float, clim, title: str, *,
          bar_title: str | None, box_mm=CENTER_BOX_MM):
    P, tris = _parts(s, exaggeration)
    bar = dict(title="", vertical=False, position_x=0.2, position_y=0.03, width=0.6,
               height=0.1, fmt="%.2f", label_font_size=16, n_labels=6,
               color="black", font_family="arial")
    if len(tris["front"]):
        plotter.add_mesh(_polydata(pv, P, tris["front"], 1e3 * s.displacement_mm[:, 2]), scalars="u_z_um",
                         cmap=_CMAP, clim=clim, smooth_shading=True, show_scalar_bar=bar_title is not None,
                         scalar_bar_args=bar, specular=0.3, specular_power=25.0, ambient=0.2, diffuse=0.8)
        if bar_title:  # the bar's own title collides with its labels: a centred text above them
            t = plotter.add_text(bar_title, position=(0.5, 0.12), viewport=True, font_size=12,
                                 color="black", font="arial")
            t.GetTextProperty().SetJustificationToCentered()
    if len(tris["body"]):
        plotter.add_mesh(_polydata(pv, P, tris["body"]), color="#b8bcc2", smooth_shading=True,
                         specular=0.2, specular_power=15.0, ambient=0.25, diffuse=0.75)
    if len(tris["cut"]):
        plotter.add_mesh(_polydata(pv, P, tris["cut"]), color="#d9c6a0", smooth_shading=False,
                         ambient=0.35, diffuse=0.65)
    allp = pv.PolyData(P, np.column_stack([np.full(len(s.triangles), 3), s.triangles]).ravel())
    edges = allp.extract_feature_edges(feature_angle=35.0, boundary_edges=False, manifold_edges=False,
                                       non_manifold_edges=False)
    if edges.n_points:
        plotter.add_mesh(edges, color="#30343a", line_width=1.0, opacity=0.7)
    if box_mm is not None:
        for line in _front_box(s, exaggeration, box_mm) or []:
            plotter.add_mesh(pv.lines_from_points(line), color="white", line_width=4.0)
    plotter.add_text(title, position="upper_left", font_size=13, color="black", font="arial")
    plotter.add_axes(xlabel="x", ylabel="y", zlabel="z", line_width=4, color="black",
                     viewport=(0.0, 0.0, 0.13, 0.22))
    _camera(plotter, s)


def _screenshot(plotter, path: Path) -> Path:
    from pipeline.io.common import atomic_path

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        with atomic_path(path) as tmp:
            plotter.screenshot(str(tmp))
    finally:
        plotter.close()
    return path


def _case_label(info: dict) -> str:
    cov = {"all": "all surfaces", "holes": "holes only", "surfaces": "outer surfaces only",
           "faces": "faces only", "none": "no film"}.get(info.get("coverage"), str(info.get("coverage")))
    t0, p = info.get("t0_um"), info.get("polish_front")
    s = f"NiP {t0:g} µm, {cov}" if t0 is not None else cov
    if p is not None:
        s += f", front polish {100 * p:g} %"
    if "warm_K" in info and "cold_K" in info:
        s += f", cooled {info['warm_K']:g} K to {info['cold_K']:g} K"
    return s


def _pv_text(result) -> str:
    try:
        return (f"P/V over the central {CENTER_BOX_MM[0]:g} x {CENTER_BOX_MM[1]:g} mm (white box): "
                f"{result.sag.pv_um('center'):.2f} µm")
    except Exception:  # a blank without that region: no P/V line
        return ""


def render_deformed_blank(mesh, result, path, *, exaggeration: float | None = None,
                          cutaway: bool = True, title: str | None = None,
                          window_size=(1800, 820)) -> dict:
    """Render one solved case to PNG: whole blank (oblique, front face up) + cut-away.

    Parameters
    ----------
    mesh : skfem.MeshTet2
        The solved part (``PreparedBlank.mesh``).
    result : fea.model.FEAResult
        The solved case (its ``info`` gives the symmetry planes and the case label).
    path : str or Path
        Output PNG (written atomically).
    exaggeration : float, optional
        Displacement scale factor; default :func:`auto_exaggeration` (front-face P/V
        shown as 2 % of the blank's size).
    cutaway : bool
        Add a second view with the quadrant x < 0, y < 0 removed (symmetric parts only).

    Returns
    -------
    dict
        ``path``, ``exaggeration``, ``clim_um`` and ``seconds``.

    Raises
    ------
    RenderUnavailable
        pyvista/VTK cannot be imported. (A machine without any OpenGL back-end may
        crash VTK itself: use :func:`start_study_render` for a guarded render.)
    """
    t0 = time.perf_counter()
    pv = _pyvista()
    planes = result.info.get("symmetry_planes")
    s = blank_surface(mesh, result.coords_mm, result.displacement_mm, planes)
    views = [(s, "whole blank")]
    if cutaway and planes and {"sym_x", "sym_y"} <= set(planes):
        views.append((blank_surface(mesh, result.coords_mm, result.displacement_mm, planes,
                                    cutaway=True), "cut-away: quadrant x<0, y<0 removed"))
    ex = float(exaggeration) if exaggeration is not None else auto_exaggeration([s])
    clim = _clim([s])
    head = title or _case_label(result.info)
    w, h = window_size
    p = pv.Plotter(off_screen=True, shape=(1, len(views)), window_size=(w if len(views) > 1 else w // 2, h),
                   border=False)
    p.set_background("white")
    p.enable_anti_aliasing("ssaa")
    pvt = _pv_text(result)
    for i, (sv, sub) in enumerate(views):
        p.subplot(0, i)
        last = i == len(views) - 1
        text = (f"{head}\n{pvt}\n{sub}, displacement exaggerated x{ex:g}" if i == 0
                else f"{sub}\n(cut faces beige, hole walls and sides grey)")
        _view(p, pv, sv, ex, clim, text, bar_title="front-face sag u_z [µm]" if last else None)
    out = _screenshot(p, path)
    return {"path": out, "exaggeration": ex, "clim_um": clim, "seconds": time.perf_counter() - t0}


def render_comparison(mesh, results: list, labels: list[str], path, *,
                      exaggeration: float | None = None, cutaway: bool = False,
                      title: str | None = None, window_size=(1800, 820)) -> dict:
    """Several solved cases on one mesh side by side, one exaggeration and one colour scale.

    Each view is coloured by u_z minus that case's mean front-face u_z (µm), so that
    cases with different pistons are comparable; the exaggeration is shared.
    """
    t0 = time.perf_counter()
    if len(results) != len(labels) or not results:
        raise ValueError(f"{len(results)} results and {len(labels)} labels: give one label per result")
    pv = _pyvista()
    surfs = []
    for r in results:
        s = blank_surface(mesh, r.coords_mm, r.displacement_mm, r.info.get("symmetry_planes"), cutaway=cutaway)
        d = s.displacement_mm.copy()
        d[:, 2] -= d[s.front_mask(), 2].mean()  # piston of the front face removed
        surfs.append(BlankSurface(s.points_mm, s.triangles, d, s.cut))
    ex = float(exaggeration) if exaggeration is not None else auto_exaggeration(surfs)
    lo, hi = _clim(surfs)
    m = max(abs(lo), abs(hi))
    p = pv.Plotter(off_screen=True, shape=(1, len(surfs)), window_size=window_size, border=False)
    p.set_background("white")
    p.enable_anti_aliasing("ssaa")
    for i, (s, lab) in enumerate(zip(surfs, labels)):
        p.subplot(0, i)
        head = f"{title}\n{lab}" if (title and i == 0) else lab
        _view(p, pv, s, ex, (-m, m), f"{head}\n{_pv_text(results[i])}\ndisplacement exaggerated x{ex:g}",
              bar_title="front-face sag u_z minus its mean [µm]" if i == len(surfs) - 1 else None)
    out = _screenshot(p, path)
    return {"path": out, "exaggeration": ex, "clim_um": (-m, m), "seconds": time.perf_counter() - t0}


# ---------------------------------------------------------------------------- guarded use
def probe(path=None, size: int = 64) -> bool:
    """Render a small shaded cube off-screen; True when the image is not blank.

    Run it in a child process (``python -m pipeline.study.render3d --probe``): without an
    OpenGL back-end VTK may crash the interpreter instead of raising.
    """
    pv = _pyvista()
    p = pv.Plotter(off_screen=True, window_size=(size, size))
    p.set_background("white")
    p.add_mesh(pv.Cube(), color="tab:red")
    img = p.screenshot(path, return_img=True)
    p.close()
    img = np.asarray(img)
    return img.shape[:2] == (size, size) and float(img.std()) > 1.0


#: the study's renders: PNG file -> (heading, cases, view labels); a case is
#: (coverage, t0_um, polish) of a paper-setup case; a figure is drawn when the study has
#: all its cases (their full parameters, mesh included, are used)
STUDY_RENDERS = {
    "blank_3d.png": ("3-D render of the deformed blank", [("all", 200.0, 0.75)], None),
    "blank_3d_holes_vs_surfaces.png": (
        "3-D render of the deformed blank",
        [("holes", 200.0, 1.0), ("surfaces", 200.0, 1.0)],
        ["NiP 200 µm only in the holes", "NiP 200 µm only on the outer surfaces"]),
}
#: payload format of a render entry (:mod:`pipeline.store`); bump when a render changes look
_RENDER_VERSION = 1
#: key of the child's answer that lists renders redone because their files did not verify
_REBUILT = "rebuilt"
_HEADING = "3-D render of the deformed blank"


def study_renders(cases) -> dict:
    """The :data:`STUDY_RENDERS` a study can draw: ``{file: (heading, [params], labels)}``.

    ``cases`` are the study's FEA cases (``.full`` and ``.params`` dicts, ``.is_paper_setup``).
    """
    found = {}
    for c in cases:
        full = getattr(c, "full", None) or {}
        if not getattr(c, "is_paper_setup", False):
            continue
        try:
            key = (str(full["coverage"]), float(full["t0_um"]), float(full["polish"]))
        except (KeyError, TypeError, ValueError):
            continue
        found.setdefault(key, dict(c.params))
    return {f: (h, [found[k] for k in keys], labels) for f, (h, keys, labels) in STUDY_RENDERS.items()
            if all(k in found for k in keys)}


def _entry(out: Path, file: str, params: list):
    """The render's store entry: the PNG in ``out``, its sidecar in ``out/fea/render3d``."""
    from pipeline import store
    from fea.case import model_namespace

    cases = [{k: (v if isinstance(v, (str, int, float, bool)) or v is None else str(v)) for k, v in p.items()}
             for p in params]
    return store.Entry(f"render3d-{model_namespace()}", {"file": file, "cases": cases}, out / file,
                       out / "fea" / "render3d" / (Path(file).stem + ".json"), format_version=_RENDER_VERSION)


def _is_current(entry, rebuilt: dict) -> bool:
    """True when the PNG of ``entry`` is the verified render of its cases; a PNG that is
    not (edited, truncated, another case's, a failure notice) is noted in ``rebuilt``."""
    from pipeline import store

    try:
        store.verify(entry)
        return True
    except FileNotFoundError:
        return False
    except store.CacheMiss as exc:
        rebuilt[entry.payload.name] = str(exc)
        return False


def _render_child(out: Path, renders: dict) -> dict:
    """Solve and render (runs inside the child process); returns {file: path}."""
    from fea.mesh import blank_mesh
    from fea.model import PreparedBlank
    from types import SimpleNamespace

    from fea.case import FEACase
    from pipeline.sweeps.fea_cases import field_path, load_field

    from pipeline import store

    done, models, rebuilt = {}, {}, {}
    for file, (_, params, labels) in renders.items():
        png, entry = out / file, _entry(out, file, params)
        if _is_current(entry, rebuilt):
            done[file] = str(png)
            continue
        t0 = time.perf_counter()
        results = []
        for c in params:
            case = FEACase.from_params(c)
            o = case.to_objects()
            blank, spec, substrate, coating, film, load, scale = (o.blank, o.mesh, case.substrate, o.coating,
                                                                  case.film, o.load, o.stress_scale)
            saved = load_field(field_path(out / "fea" / "fields", c))  # kept by the study's FEA run
            if saved is not None:
                results.append((SimpleNamespace(mesh=blank_mesh(blank, spec)), saved))
                continue
            mk = (blank, spec, substrate)
            if mk not in models:
                models = {mk: PreparedBlank(blank_mesh(blank, spec), substrate)}  # keep one: memory
            results.append((models[mk], models[mk].solve(coating, film, load, stress_scale=scale)))
        t_solve = time.perf_counter() - t0
        if len(results) == 1:
            info = render_deformed_blank(results[0][0].mesh, results[0][1], png)
        else:
            info = render_comparison(results[0][0].mesh, [r for _, r in results], labels, png)
        store.commit(entry, {"exaggeration": info["exaggeration"], "clim_um": list(info["clim_um"]),
                             "solve_s": round(t_solve, 1), "render_s": round(info["seconds"], 1)})
        done[file] = str(png)
    if rebuilt:
        done[_REBUILT] = rebuilt
    return done


def start_study_render(cases, out_dir, *, timeout_s: float = 1800.0, progress: bool = True):
    """Start the study's 3-D renders (:func:`study_renders`) in a child process.

    Returns a :class:`StudyRender` (``.figures()`` waits and returns ``{file: (heading,
    path)}``, a notice figure in place of the renders when they failed) or None when the
    study has none of the cases. The child solves its cases again (the sweep cache keeps
    sag maps, not displacement fields) with the study's parameters and mesh; finished
    renders are reused on re-run (key in ``fea/render3d/*.json``). A machine without
    OpenGL, where VTK can crash, loses only these figures, with a warning.
    """
    renders = study_renders(cases)
    if not renders:
        return None
    return StudyRender(Path(out_dir), renders, timeout_s, progress)


def render_study_figures(out_dir, cases=None, *, mesh_size_mm: float | None = None,
                         mesh_bulk_mm: float | None = None, timeout_s: float = 1800.0) -> dict:
    """:func:`start_study_render` and wait: ``{file: Path or None, ..., "error": str or None}``.

    ``cases`` default to the paper's (coverage, t0, polish) of :data:`STUDY_RENDERS` with
    the given element sizes.
    """
    if cases is None:
        from types import SimpleNamespace

        extra = {k: float(v) for k, v in (("mesh_size_mm", mesh_size_mm), ("mesh_bulk_mm", mesh_bulk_mm))
                 if v is not None}
        keys = dict.fromkeys(k for _, ks, _ in STUDY_RENDERS.values() for k in ks)
        cases = [SimpleNamespace(full={"coverage": c, "t0_um": t, "polish": p}, is_paper_setup=True,
                                 params={"coverage": c, "t0_um": t, "polish": p, **extra}) for c, t, p in keys]
    h = start_study_render(cases, out_dir, timeout_s=timeout_s, progress=False)
    return h.result() if h is not None else {"error": "no cases to render"}


class StudyRender:
    """A child process rendering the study's figures (see :func:`start_study_render`)."""

    def __init__(self, out: Path, renders: dict, timeout_s: float, progress: bool = True):
        self.out, self.renders, self.timeout_s, self.progress = out, renders, timeout_s, progress
        self.t0 = time.perf_counter()
        self._result = None
        out.mkdir(parents=True, exist_ok=True)
        env = dict(os.environ)
        configure_offscreen_env(env)
        root = str(Path(__file__).resolve().parents[2])  # the directory holding the pipeline package
        env["PYTHONPATH"] = root + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
        self._err = tempfile.TemporaryFile()
        spec = {f: [h, params, labels] for f, (h, params, labels) in renders.items()}
        self._spec = tempfile.NamedTemporaryFile("w", suffix=".json", delete=False)
        json.dump(spec, self._spec, default=str)
        self._spec.close()
        try:
            # The child works in the caller's directory, so a relative --out or cache path
            # means there what it means here; the output goes as an absolute path anyway.
            # -P keeps a 'pipeline' package in that directory from shadowing this one.
            self.proc = subprocess.Popen(
                [sys.executable, "-P", "-m", "pipeline.study.render3d", "--study", str(out.resolve()),
                 "--spec", self._spec.name],
                stdout=subprocess.PIPE, stderr=self._err, env=env, cwd=os.getcwd())
        except OSError as exc:
            self.proc = None
            self._result = self._fail(f"the render process could not start: {exc}")
        else:
            import atexit

            atexit.register(self._kill)  # a run that dies early does not leave the child behind

    def _kill(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.kill()

    def result(self) -> dict:
        """Wait; ``{file: Path or None, ..., "error": message or None}``."""
        if self._result is None:
            self._result = self._wait()
            try:
                os.unlink(self._spec.name)
            except OSError:
                pass
            if self.progress and self._result["error"] is None:
                print(f"3-D renders: {len(self.renders)} in {time.perf_counter() - self.t0:.0f} s", flush=True)
        return self._result

    def figures(self) -> dict:
        """Wait; ``{file: (heading, path)}`` for the study's report (a notice when rendering failed)."""
        res = self.result()
        if res["error"] is None:
            return {f: (h, res[f]) for f, (h, _, _) in self.renders.items()}
        path = _notice_png(self.out / next(iter(self.renders)), res["error"])
        return {path.name: (_HEADING, path)} if path is not None else {}

    def _wait(self) -> dict:
        try:
            stdout, _ = self.proc.communicate(timeout=self.timeout_s)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.communicate()
            return self._fail(f"timed out after {self.timeout_s:g} s")
        self._err.seek(0)
        err = self._err.read().decode(errors="replace")
        self._err.close()
        if self.proc.returncode != 0:
            rc = self.proc.returncode
            why = (f"signal {-rc} (VTK found no usable OpenGL back-end?)" if rc < 0 else f"exit code {rc}")
            msgs = _last_messages(err)
            gl = rc < 0 or any(k in msgs for k in ("OpenGL", "EGL", "OSMesa", "X11", "RenderUnavailable"))
            return self._fail(f"the render process failed with {why}: {msgs.rstrip('.')}", gl)
        try:
            done = json.loads(stdout.decode().strip().splitlines()[-1])
        except (ValueError, IndexError):
            return self._fail(f"the render process gave no result: {err[-300:]}")
        from pipeline.store import warn_rebuild

        for file, why in done.get(_REBUILT, {}).items():  # the child's stderr is not shown: warn here
            warn_rebuild(self.out / file, why, "3-D render", stacklevel=2)
        res = {f: (Path(done[f]) if f in done else None) for f in self.renders}
        res["error"] = None
        return res

    def _fail(self, why: str, opengl: bool = True) -> dict:
        msg = f"3-D render of the deformed blank unavailable: {why}. The rest of the run is unaffected."
        if opengl:
            msg += (" Off-screen rendering needs Mesa's EGL or OSMesa (Debian: apt-get install "
                    "libegl1 libgl1-mesa-dri; scripts/offscreen-gl), see pipeline/study/render3d.py.")
        if log.hasHandlers():
            log.warning(msg)
        else:
            print(f"warning: {msg}", file=sys.stderr, flush=True)
        res = {f: None for f in self.renders}
        res["error"] = msg
        return res


def _last_messages(err: str, n: int = 2) -> str:
    """The last distinct messages of a child's stderr, without VTK's log prefixes and colours."""
    import re

    out = []
    for line in err.splitlines():
        line = re.sub(r"\x1b\[[0-9;]*m", "", line).strip()
        if "WARN|" in line or "ERR|" in line:
            line = line.split("|", 1)[1].strip()
        if line and line not in out:
            out.append(line[:200])
    return " | ".join(out[-n:]) or "no message"


def _notice_png(path: Path, message: str):
    """A figure that says the render is unavailable (matplotlib, no OpenGL needed)."""
    import textwrap

    try:
        from pipeline.study.plots import plt, save

        fig, ax = plt.subplots(figsize=(9.0, 1.8))
        ax.axis("off")
        ax.text(0.0, 0.5, "\n".join(textwrap.wrap(message, 110)), va="center", ha="left", fontsize=9,
                color="#8a1c1c", transform=ax.transAxes)
        return save(fig, path)
    except Exception as exc:  # the notice is a courtesy; never fail the run over it
        log.warning("could not write the render notice %s: %s", path, exc)
        return None


def configure_offscreen_env(env) -> None:
    """Without a display, ask VTK for EGL (it falls back to OSMesa) in environment ``env``."""
    if not (env.get("DISPLAY") or env.get("WAYLAND_DISPLAY")):
        env.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")


def main(argv: list[str] | None = None) -> int:
    import argparse

    ap = argparse.ArgumentParser(prog="python -m pipeline.study.render3d",
                                 description="off-screen renders of the deformed blank")
    ap.add_argument("--probe", action="store_true", help="render a test cube; exit 0 when it works")
    ap.add_argument("--study", metavar="DIR", help="render figures into DIR (with --spec)")
    ap.add_argument("--spec", help="JSON file {png file: [heading, [case params], labels or null]}")
    a = ap.parse_args(argv)
    if a.probe:
        ok = probe()
        print("off-screen rendering works" if ok else "off-screen rendering gave a blank image")
        return 0 if ok else 1
    if a.study and a.spec:
        spec = json.loads(Path(a.spec).read_text())
        done = _render_child(Path(a.study), {f: tuple(v) for f, v in spec.items()})
        print(json.dumps(done), flush=True)
        return 0
    ap.print_help()
    return 2


if __name__ == "__main__":
    sys.exit(main())
