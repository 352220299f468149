"""The 3-D scene of the deformed blank: pyvista/VTK, off-screen, exaggerated deformation.

Units: mm for geometry, µm for displacement colours.

The surface (:mod:`pipeline.study.render_geometry`) is warped by the displacement times
an exaggeration factor and coloured by u_z (µm, along the front face's normal, relative
to the substrate's uniform contraction; on the front face this is the sag).

Off-screen rendering needs no display and no GPU: the VTK >= 9.4 wheels pick an OpenGL
back-end at run time (X11, EGL, OSMesa) and load it with dlopen. Without ``DISPLAY``
this module asks for EGL (``VTK_DEFAULT_OPENGL_WINDOW=vtkEGLRenderWindow``), which falls
back to OSMesa; both render in software with Mesa's llvmpipe. The Mesa libraries come
from the system (Debian: ``libegl1 libgl1-mesa-dri``, or ``libosmesa6``; installed by
``scripts/bootstrap`` when missing). A machine without any back-end may crash VTK
itself, so the study renders through the guard of :mod:`pipeline.study.render3d`.

Functions
---------
render_deformed_blank one case: oblique view of the whole blank and a cut-away view
render_comparison    several cases side by side, one exaggeration and one colour scale
probe                render a test cube (run it in a child process)
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from pipeline.io.common import atomic_path
from pipeline.study.render_geometry import BlankSurface, auto_exaggeration, blank_surface

__all__ = ["RenderUnavailable", "configure_offscreen", "configure_offscreen_env", "render_deformed_blank",
           "render_comparison", "probe", "CENTER_BOX_MM"]

class RenderUnavailable(RuntimeError):
    """Off-screen rendering is not possible here (no pyvista/VTK, or no OpenGL back-end)."""


def configure_offscreen() -> None:
    """Choose VTK's OpenGL back-end before VTK is imported: EGL (→ OSMesa) without a display.

    A user's own ``VTK_DEFAULT_OPENGL_WINDOW`` is kept.
    """
    configure_offscreen_env(os.environ)


def configure_offscreen_env(env) -> None:
    """Without a display, ask VTK for EGL (it falls back to OSMesa) in environment ``env``."""
    if not (env.get("DISPLAY") or env.get("WAYLAND_DISPLAY")):
        env.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")


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
