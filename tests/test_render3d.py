"""3-D render of the deformed blank (pipeline/study/render_geometry.py, render_scene.py, render3d.py):
surface, off-screen PNG, guard.

No skip when pyvista/VTK or OpenGL is missing: CI installs both (scripts/bootstrap →
scripts/offscreen-gl) and must actually render.
"""

from __future__ import annotations

import json

import matplotlib.image as mpimg
import numpy as np
import pytest

from fea.geometry import Blank
from fea.mesh import MeshSpec
from pipeline.study import render3d, render_geometry, render_scene

COARSE = MeshSpec(5.0, 10.0)


@pytest.fixture(scope="module")
def coarse_case(coarse_eighth):
    return coarse_eighth.model, coarse_eighth.solve(200, 0.75)


def _edges_twice(tri: np.ndarray) -> bool:
    """Closed, consistently oriented surface: every directed edge once, its reverse once."""
    e = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    fwd = {tuple(x) for x in e}
    return len(fwd) == len(e) and all((b, a) in fwd for a, b in e)


def _enclosed_volume(points: np.ndarray, tri: np.ndarray) -> float:
    a, b, c = points[tri[:, 0]], points[tri[:, 1]], points[tri[:, 2]]
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def _volume(mesh) -> float:
    """Volume of the curved (quadratic) tetrahedra."""
    import skfem

    basis = skfem.Basis(mesh, skfem.ElementTetP1(), intorder=4)
    return float(skfem.Functional(lambda w: 1.0 + 0.0 * w.x[0]).assemble(basis))


def test_mirrored_surface_is_the_closed_whole_blank(coarse_case):
    model, r = coarse_case
    mesh = model.mesh
    s = render_geometry.blank_surface(mesh, r.coords_mm, r.displacement_mm, r.info["symmetry_planes"])
    b = Blank()
    assert np.allclose(s.points_mm.min(axis=0), [-b.size_x_mm / 2, -b.size_y_mm / 2, -b.thickness_mm / 2])
    assert np.allclose(s.points_mm.max(axis=0), [b.size_x_mm / 2, b.size_y_mm / 2, b.thickness_mm / 2])
    assert _edges_twice(s.triangles), "whole-body surface has holes, seams or flipped triangles"
    # eighth model; flat triangles through the mid-edge nodes: within 1 % of the curved volume
    whole = 8 * _volume(mesh)
    assert _enclosed_volume(s.points_mm, s.triangles) == pytest.approx(whole, rel=1e-2)
    # displacement mirrored: u_x odd in x, u_z odd in z
    i = np.argmax(s.points_mm[:, 0])
    j = np.where(np.all(np.isclose(s.points_mm, s.points_mm[i] * [-1, 1, 1]), axis=1))[0][0]
    assert s.displacement_mm[j, 0] == pytest.approx(-s.displacement_mm[i, 0])
    assert s.displacement_mm[j, 2] == pytest.approx(s.displacement_mm[i, 2])
    # cut-away: still closed, three quarters of the volume
    c = render_geometry.blank_surface(mesh, r.coords_mm, r.displacement_mm, r.info["symmetry_planes"], cutaway=True)
    assert _edges_twice(c.triangles) and c.cut.any()
    assert _enclosed_volume(c.points_mm, c.triangles) == pytest.approx(0.75 * whole, rel=1e-2)


def test_render_png_offscreen(coarse_case, tmp_path):
    model, r = coarse_case
    size = (900, 420)
    info = render_scene.render_deformed_blank(model.mesh, r, tmp_path / "blank.png", window_size=size)
    assert info["exaggeration"] >= 100  # sub-µm quilting needs a large factor to be visible
    img = mpimg.imread(info["path"])[..., :3]
    assert img.shape[:2] == (size[1], size[0])
    white = (img > 0.97).all(axis=2)
    assert 0.15 < 1 - white.mean() < 0.9, "blank or all-covered image"
    rgb = img[~white]
    assert len(np.unique(np.round(rgb * 255).astype(np.uint8), axis=0)) > 500
    # the colour map is used: some strongly blue and some strongly red/orange pixels
    r_, g_, b_ = rgb.T
    assert ((b_ - r_) > 0.3).mean() > 0.01 and ((r_ - b_) > 0.3).mean() > 0.01
    # grey body (sides, hole walls) present too
    assert (np.ptp(rgb, axis=1) < 0.05).mean() > 0.05


def test_failed_render_is_a_warning_not_an_error(tmp_path, capsys, caplog):
    # a child that fails (here: an invalid mesh size) must not raise in the caller
    from types import SimpleNamespace

    cases = [SimpleNamespace(full={"coverage": "all", "t0_um": 200.0, "polish": 0.75}, is_paper_setup=True,
                             params={"coverage": "all", "t0_um": 200.0, "polish": 0.75, "mesh_size_mm": -1.0})]
    h = render3d.start_study_render(cases, tmp_path)
    res = h.result()
    assert res["error"] and "unavailable" in res["error"] and res["blank_3d.png"] is None
    assert "unavailable" in capsys.readouterr().err + caplog.text  # warned (log or stderr)
    figs = h.figures()  # the report gets a notice instead of the render
    (heading, path), = figs.values()
    assert "3-D" in heading and path.exists()
    # a study without the cases renders nothing
    assert render3d.start_study_render([], tmp_path) is None


@pytest.mark.slow
def test_study_figures_render_and_are_reused(tmp_path):
    res = render3d.render_study_figures(tmp_path, mesh_size_mm=COARSE.size_mm, mesh_bulk_mm=COARSE.size_bulk_mm)
    assert res["error"] is None
    for file in render3d.STUDY_RENDERS:
        assert res[file].exists() and res[file].stat().st_size > 20_000
        meta = tmp_path / "fea" / "render3d" / (res[file].stem + ".json")
        assert json.loads(meta.read_text())["exaggeration"] > 0
    mtime = res["blank_3d.png"].stat().st_mtime_ns
    again = render3d.render_study_figures(tmp_path, mesh_size_mm=COARSE.size_mm, mesh_bulk_mm=COARSE.size_bulk_mm)
    assert again["blank_3d.png"].stat().st_mtime_ns == mtime  # reused, not re-solved


def test_study_render_reuses_the_saved_field(coarse_case, tmp_path, monkeypatch):
    """A field kept by the study's FEA run is rendered without preparing or solving again."""
    from pipeline.sweeps.fea_cases import field_path, load_field, save_field

    model, res = coarse_case
    params = {"coverage": "all", "t0_um": 200.0, "polish": 0.75, "mesh_size_mm": COARSE.size_mm,
              "mesh_bulk_mm": COARSE.size_bulk_mm}
    path = field_path(tmp_path / "fea" / "fields", params)
    save_field(path, res)
    back = load_field(path)
    assert np.allclose(back.displacement_mm, res.displacement_mm, rtol=1e-6, atol=1e-12)
    assert back.info["symmetry_planes"] == res.info["symmetry_planes"]

    def no_solve(*a, **k):
        raise AssertionError("the render solved a case whose field was saved")

    monkeypatch.setattr(render3d, "PreparedBlank", no_solve)
    done = render3d._render_child(tmp_path, {"blank_3d.png": ("heading", [params], ["200/75"])})
    assert (tmp_path / "blank_3d.png").stat().st_size > 20_000 and "blank_3d.png" in done
