"""Geometry and meshing layer: validation, analytic volumes/areas, curved
P2 geometry, named boundaries, the on-disk cache and the verification cell.

Analytic references (r = hole radius, L = blank length along the axis):

* volume of the blank = box - pi r^2 (n_x L_y + n_y L_x) + n_x n_y 16 r^3/3
  (Steinmetz bicylinder of two equal perpendicular cylinders, subtracted
  twice); the default blank is symmetric under x, y, z -> -x, -y, -z, so an
  eighth holds exactly 1/8 of every volume and area;
* wall area of one hole family = n 2 pi r L - n_x n_y 8 r^2 (the Steinmetz
  surface, 16 r^2, is half on each cylinder);
* on the cut plane z = 0 the holes remove the strips |x - x_i| < r and
  |y - y_j| < r, so the remaining area is a product of 1-D lengths.
"""

import dataclasses
import math
import time
import warnings

import meshio
import numpy as np
import pytest
from skfem import (Basis, ElementTetP2, ElementVector, FacetBasis,
                   Functional)

from fea.verification.cell import cell_mesh, cell_volumes_mm3
from fea.geometry import Blank
from fea.mesh import MeshSpec, blank_mesh, blank_recipe, write_vtu
from fea.mesh_cache import reapply_python_sigpipe, recipe_key


@Functional
def _one(w):
    return 1.0 + 0.0 * w.x[0]


def volume_mm3(mesh, elements=None):
    return _one.assemble(Basis(mesh, ElementTetP2(), elements=elements))


def area_mm2(mesh, name):
    return _one.assemble(FacetBasis(mesh, ElementTetP2(),
                                    facets=mesh.boundaries[name]))


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    return tmp_path_factory.mktemp("mesh-cache")


@pytest.fixture(scope="module")
def eighth(cache):
    return blank_mesh(Blank(), MeshSpec.coarse(), cache_dir=cache)


# --- Blank -------------------------------------------------------------------
@pytest.mark.parametrize("kwargs, words", [
    (dict(size_x_mm=-1.0), ["size_x_mm", "-1.0", "> 0"]),
    (dict(thickness_mm=0.0), ["thickness_mm", "0.0", "> 0"]),
    (dict(hole_diameter_mm=19.5), ["hole_diameter_mm", "19.5", "<= 19",
                                   "0.5 mm"]),
    (dict(hole_axis_z_mm=2.5), ["hole_diameter_mm", "15.0",
                                "hole_axis_z_mm=2.5", "<= 14"]),
    (dict(pitch_x_mm=14.0), ["pitch_x_mm", "14.0", "> hole_diameter_mm"]),
    (dict(n_holes_x=9), ["n_holes_x", "9", "91.5", "80"]),
    (dict(n_holes_y=-1), ["n_holes_y", "-1", ">= 0"]),
    (dict(n_holes_y=7.0), ["n_holes_y", "7.0", "integer"]),
    (dict(pitch_y_mm=float("nan")), ["pitch_y_mm", "nan", "finite"]),
])
def test_blank_validation_names_field_value_range(kwargs, words):
    with pytest.raises(ValueError) as err:
        Blank(**kwargs)
    for w in words:
        assert w in str(err.value)


def test_blank_defaults_and_hole_positions():
    b = Blank()
    np.testing.assert_allclose(b.hole_x_positions_mm,
                               [-63, -42, -21, 0, 21, 42, 63])
    np.testing.assert_allclose(b.hole_y_positions_mm,
                               [-54, -36, -18, 0, 18, 36, 54])
    assert b.wall_front_mm == b.wall_back_mm == 2.5
    assert b.is_z_symmetric
    even = Blank(n_holes_x=4)
    np.testing.assert_allclose(even.hole_x_positions_mm,
                               [-31.5, -10.5, 10.5, 31.5])
    off = Blank(hole_axis_z_mm=1.0)
    assert (off.wall_front_mm, off.wall_back_mm) == (1.5, 3.5)
    assert not off.is_z_symmetric
    assert Blank(n_holes_x=0, n_holes_y=0).hole_x_positions_mm.size == 0


def test_blank_key_is_plain_and_stable():
    assert Blank().key() == Blank(size_x_mm=160).key()
    assert set(Blank().key()) == {f.name for f in dataclasses.fields(Blank)}


@pytest.mark.parametrize("kwargs, words", [
    (dict(size_mm=0.0), ["size_mm", "0.0", "> 0"]),
    (dict(size_mm=2.0, size_bulk_mm=1.0), ["size_bulk_mm", "1.0", ">="]),
    (dict(symmetry="half"), ["symmetry", "half", "eighth"]),
    (dict(order=1), ["order", "1", "2"]),
])
def test_meshspec_validation(kwargs, words):
    with pytest.raises(ValueError) as err:
        MeshSpec(**kwargs)
    for w in words:
        assert w in str(err.value)


def test_eighth_needs_z_symmetric_blank(tmp_path):
    with pytest.raises(ValueError, match="hole_axis_z_mm=1.0"):
        blank_mesh(Blank(hole_axis_z_mm=1.0), MeshSpec.coarse(),
                   cache_dir=tmp_path)


# --- blank mesh: geometry ------------------------------------------------
def test_eighth_volume_and_size(eighth):
    assert abs(volume_mm3(eighth) / (Blank().volume_mm3() / 8) - 1) < 1e-3
    assert 3 * eighth.doflocs.shape[1] < 30_000


def test_eighth_boundary_areas(eighth):
    b, r = Blank(), 7.5
    n_cross = b.n_holes_x * b.n_holes_y
    expected = {
        "front": 80 * 70,
        "side_x": (140 * 20 - b.n_holes_y * math.pi * r**2) * 2 / 8,
        "side_y": (160 * 20 - b.n_holes_x * math.pi * r**2) * 2 / 8,
        "holes_x": (b.n_holes_y * 2 * math.pi * r * 160
                    - n_cross * 8 * r**2) / 8,
        "holes_y": (b.n_holes_x * 2 * math.pi * r * 140
                    - n_cross * 8 * r**2) / 8,
        "sym_x": 70 * 2.5,   # the hole along y at x = 0 removes |z| < r
        "sym_y": 80 * 2.5,
        "sym_z": (80 - 7.5 - 3 * 15) * (70 - 7.5 - 3 * 15),
    }
    assert set(eighth.boundaries) == set(expected)
    for name, a in expected.items():
        assert abs(area_mm2(eighth, name) / a - 1) < 1e-3, name


def test_boundaries_disjoint_and_cover_the_surface(eighth):
    all_f = np.concatenate(list(eighth.boundaries.values()))
    assert len(np.unique(all_f)) == len(all_f)
    np.testing.assert_array_equal(np.sort(all_f),
                                  np.sort(eighth.boundary_facets()))


def test_hole_wall_nodes_lie_on_cylinders(eighth):
    b, r = Blank(), Blank().hole_radius_mm
    for name, axis_pos, other in (("holes_x", b.hole_y_positions_mm, 1),
                                  ("holes_y", b.hole_x_positions_mm, 0)):
        dofs = eighth.dofs.get_facet_dofs(eighth.boundaries[name]).flatten()
        x = eighth.doflocs[:, dofs]
        rho = np.hypot(x[other][:, None] - axis_pos[None, :],
                       x[2][:, None] - b.hole_axis_z_mm)
        assert np.abs(np.abs(rho - r).min(axis=1)).max() < 1e-9, name
    # and the curvature is real: straight chords would sag off the wall
    edges = eighth.edges
    mid = 0.5 * (eighth.doflocs[:, edges[0]] + eighth.doflocs[:, edges[1]])
    ed = eighth.doflocs[:, eighth.dofs.edge_dofs[0]]  # edge dof k <-> edge k
    assert np.abs(ed - mid).max() > 0.05


def test_p2_mapping_not_degenerate(eighth):
    basis = Basis(eighth, ElementTetP2())
    det = basis.mapping.detDF(basis.X)
    assert det.min() > 0
    assert (det.min(axis=1) / det.max(axis=1)).min() > 0.1


def test_quarter_consistent_with_eighth(eighth, cache):
    q = blank_mesh(Blank(), MeshSpec.coarse("quarter"), cache_dir=cache)
    assert "sym_z" not in q.boundaries and "back" in q.boundaries
    assert abs(volume_mm3(q) / (2 * volume_mm3(eighth)) - 1) < 1e-3
    for name in ("front", "back"):
        assert abs(area_mm2(q, name) / 5600 - 1) < 1e-9
    for name in ("holes_x", "holes_y", "side_x"):
        assert abs(area_mm2(q, name) / (2 * area_mm2(eighth, name)) - 1) \
            < 1e-3


def test_off_mid_plane_holes_quarter(tmp_path):
    b = Blank(hole_axis_z_mm=1.0)
    m = blank_mesh(b, MeshSpec.coarse("quarter"), cache_dir=tmp_path)
    # moving the holes in z leaves the volume unchanged
    assert abs(volume_mm3(m) / (b.volume_mm3() / 4) - 1) < 1e-3


def test_even_hole_counts_no_hole_on_the_cut(tmp_path):
    b, r = Blank(n_holes_x=6, n_holes_y=4), 7.5
    m = blank_mesh(b, MeshSpec.coarse(), cache_dir=tmp_path)
    assert abs(volume_mm3(m) / (b.volume_mm3() / 8) - 1) < 1e-3
    # cut planes now cross holes transversally: half discs are removed
    expected = {"sym_x": 70 * 10 - 2 * math.pi * r**2 / 2,
                "sym_y": 80 * 10 - 3 * math.pi * r**2 / 2,
                "sym_z": (80 - 3 * 15) * (70 - 2 * 15)}
    for name, a in expected.items():
        assert abs(area_mm2(m, name) / a - 1) < 1e-3, name


def test_solid_block(tmp_path):
    m = blank_mesh(Blank(n_holes_x=0, n_holes_y=0), MeshSpec.coarse(),
                   cache_dir=tmp_path)
    assert set(m.boundaries) == {"front", "side_x", "side_y", "sym_x",
                                 "sym_y", "sym_z"}
    assert abs(volume_mm3(m) - 80 * 70 * 10) < 1e-6


def test_write_vtu_roundtrip(eighth, tmp_path):
    ib = Basis(eighth, ElementVector(ElementTetP2()))
    # the documented u.reshape(-1, 3) convention
    np.testing.assert_array_equal(ib.doflocs[:, ::3], eighth.doflocs)
    n = ib.doflocs.shape[1]
    u = ib.doflocs[np.arange(n) % 3, np.arange(n)]  # the field u(x) = x
    path = tmp_path / "u.vtu"
    write_vtu(eighth, path, point_data={"u_mm": u.reshape(-1, 3)})
    back = meshio.read(path)
    t10 = back.cells_dict["tetra10"]
    assert t10.shape == (eighth.nelements, 10)
    np.testing.assert_allclose(back.point_data["u_mm"], back.points)
    # VTK edge order: mid nodes sit near the midpoints of their edges
    p = back.points
    for k, (i, j) in enumerate([(0, 1), (1, 2), (2, 0), (0, 3), (1, 3),
                                (2, 3)]):
        gap = np.linalg.norm(p[t10[:, 4 + k]] - 0.5 * (p[t10[:, i]]
                                                       + p[t10[:, j]]), axis=1)
        size = np.linalg.norm(p[t10[:, i]] - p[t10[:, j]], axis=1)
        assert np.all(gap < 0.3 * size)


# --- cache ---------------------------------------------------------------
def _same(a, b):
    assert np.array_equal(a.doflocs, b.doflocs)
    assert np.array_equal(a.t, b.t)
    assert a.boundaries.keys() == b.boundaries.keys()
    for k in a.boundaries:
        assert np.array_equal(a.boundaries[k], b.boundaries[k])


def test_cache_hit_is_fast_and_identical(tmp_path):
    t0 = time.perf_counter()
    first = blank_mesh(Blank(), MeshSpec.coarse(), cache_dir=tmp_path)
    build_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        second = blank_mesh(Blank(), MeshSpec.coarse(), cache_dir=tmp_path)
    load_s = time.perf_counter() - t0
    assert load_s < 0.5 * build_s
    _same(first, second)
    assert len(list(tmp_path.glob("*.npz"))) == 1
    assert len(list(tmp_path.glob("*.json"))) == 1
    assert not list(tmp_path.glob("*.tmp"))


@pytest.mark.parametrize("damage", ["truncate", "garble_json", "stale_key",
                                    "drop_json"])
def test_damaged_cache_is_rebuilt_with_warning(tmp_path, damage):
    spec = MeshSpec.coarse()
    good = blank_mesh(Blank(), spec, cache_dir=tmp_path)
    npz = next(tmp_path.glob("*.npz"))
    sidecar = npz.with_suffix(".json")
    if damage == "truncate":
        npz.write_bytes(npz.read_bytes()[: npz.stat().st_size // 2])
    elif damage == "garble_json":
        sidecar.write_text("{not json")
    elif damage == "stale_key":
        sidecar.write_text(sidecar.read_text().replace('"key": "',
                                                       '"key": "0'))
    else:
        sidecar.unlink()
    with pytest.warns(UserWarning, match="rebuilding"):
        rebuilt = blank_mesh(Blank(), spec, cache_dir=tmp_path)
    _same(good, rebuilt)  # single-threaded gmsh is deterministic
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        blank_mesh(Blank(), spec, cache_dir=tmp_path)


def test_cache_key_changes_with_every_parameter():
    base_b, base_s = Blank(), MeshSpec()
    keys = {recipe_key(blank_recipe(base_b, base_s))}
    changes = [dataclasses.replace(base_b, **{f.name: v}) for f, v in zip(
        dataclasses.fields(Blank),
        [161.0, 141.0, 21.0, 14.0, 22.0, 5, 19.0, 5, 0.5])]
    for b in changes:
        keys.add(recipe_key(blank_recipe(b, base_s)))
    for s in (MeshSpec(size_mm=1.5), MeshSpec(size_bulk_mm=3.0),
              MeshSpec(symmetry="quarter")):
        keys.add(recipe_key(blank_recipe(base_b, s)))
    assert len(keys) == 1 + len(changes) + 3
    recipe = blank_recipe(base_b, base_s)
    assert {"gmsh_version", "format_version"} <= set(recipe)


# --- verification cell -----------------------------------------------------
@pytest.mark.parametrize("film_hole_um, film_front_um", [(0.0, 0.0),
                                                         (150.0, 100.0)])
def test_cell_volumes_and_boundaries(tmp_path, film_hole_um, film_front_um):
    kw = dict(film_hole_um=film_hole_um, film_front_um=film_front_um)
    m = cell_mesh(**kw, size_mm=0.2, size_bulk_mm=0.8, cache_dir=tmp_path)
    sub, film = cell_volumes_mm3(**kw)
    assert abs(volume_mm3(m, m.subdomains["substrate"]) / sub - 1) < 1e-6
    names = {"sym_x0", "sym_xp", "sym_z", "y0", "y1", "front", "hole"}
    if film:
        names |= {"film_top", "film_bore"}
        assert abs(volume_mm3(m, m.subdomains["film"]) / film - 1) < 1e-6
    else:
        assert m.subdomains["film"].size == 0
    assert set(m.boundaries) == names
    assert abs(area_mm2(m, "front") - 10.5) < 1e-9
    assert abs(area_mm2(m, "hole") - math.pi / 2 * 7.5) < 1e-5
    both = np.concatenate([m.subdomains["substrate"], m.subdomains["film"]])
    np.testing.assert_array_equal(np.sort(both), np.arange(m.nelements))


def test_cell_film_resolved_and_curved(tmp_path):
    m = cell_mesh(film_hole_um=150.0, film_front_um=100.0, film_layers=2,
                  size_mm=0.2, size_bulk_mm=0.8, cache_dir=tmp_path)
    film_t = m.t[:, m.subdomains["film"]]
    x, z = m.doflocs[0, film_t.ravel()], m.doflocs[2, film_t.ravel()]
    ring = np.hypot(x, z) < 7.5 + 1e-9
    # >= 2 quadratic elements through each film: >= 3 vertex levels
    assert len(np.unique(np.round(np.hypot(x, z)[ring], 9))) >= 3
    assert len(np.unique(np.round(z[~ring], 9))) >= 3
    dofs = m.dofs.get_facet_dofs(m.boundaries["film_bore"]).flatten()
    rho = np.hypot(m.doflocs[0, dofs], m.doflocs[2, dofs])
    assert np.abs(rho - (7.5 - 0.15)).max() < 1e-9


def test_cell_validation():
    with pytest.raises(ValueError, match="film_layers=1.*>= 2"):
        cell_mesh(film_layers=1)
    with pytest.raises(ValueError, match="film_hole_um=-1.0"):
        cell_mesh(film_hole_um=-1.0)


def test_default_recipe_file_matches_the_code():
    import json
    from pathlib import Path
    path = (Path(__file__).parent.parent / "meshes" / "recipes"
            / "blank_default_eighth.json")
    stored = json.loads(path.read_text())["recipe"]
    current = blank_recipe(Blank(), MeshSpec())
    ignore = {"gmsh_version"}  # recorded; any gmsh version can rebuild it
    assert {k: v for k, v in stored.items() if k not in ignore} == \
        {k: v for k, v in current.items() if k not in ignore}
    assert Blank(**stored["blank"]) == Blank()
    assert MeshSpec(**stored["spec"]) == MeshSpec()


# --- gmsh state and failures -------------------------------------------------
def test_gmsh_is_left_clean(tmp_path):
    import gmsh
    blank_mesh(Blank(n_holes_x=0, n_holes_y=0), MeshSpec.coarse(),
               cache_dir=tmp_path)
    assert not gmsh.isInitialized()
    # a caller's own gmsh session and model survive our call
    gmsh.initialize(readConfigFiles=False, interruptible=False)
    reapply_python_sigpipe()  # this test process goes on to run sweeps whose workers die
    try:
        gmsh.model.add("callers-model")
        cell_mesh(size_mm=0.5, size_bulk_mm=1.0, cache_dir=tmp_path)
        assert gmsh.isInitialized()
        assert gmsh.model.getCurrent() == "callers-model"
    finally:
        gmsh.finalize()


SIGPIPE_CHECK = """
import os, sys, threading
sys.path.insert(0, {repo!r})
from fea.mesh_cache import gmsh_session

def closed_pipe_write():
    r, w = os.pipe()
    os.close(r)
    try:
        os.write(w, b"x")  # SIGPIPE at its default action ends the process here, status 141
    except BrokenPipeError:
        return "BrokenPipeError"

def open_and_close():
    with gmsh_session():
        pass

if sys.argv[1] == "thread":
    t = threading.Thread(target=open_and_close)
    t.start(); t.join()
else:
    open_and_close()
print(closed_pipe_write())
"""


@pytest.mark.parametrize("where", ["main", "thread"])
def test_gmsh_session_leaves_sigpipe_ignored(tmp_path, where):
    """gmsh.initialize sets SIGPIPE to terminate the process; after our session a write to a
    closed pipe must still raise BrokenPipeError (else a dying sweep worker kills its parent)."""
    import subprocess
    import sys
    from pathlib import Path
    script = tmp_path / "check.py"
    script.write_text(SIGPIPE_CHECK.format(repo=str(Path(__file__).resolve().parents[1])))
    run = subprocess.run([sys.executable, str(script), where], capture_output=True, text=True, timeout=120)
    assert (run.returncode, run.stdout.strip()) == (0, "BrokenPipeError"), run.stderr


def test_gmsh_failure_is_a_clear_runtime_error(tmp_path, monkeypatch):
    import gmsh
    import fea.mesh

    def broken(gmsh_module):
        raise Exception("simulated gmsh error")

    monkeypatch.setattr(fea.mesh, "generate_order2", broken)
    with pytest.raises(RuntimeError,
                       match=r"meshing the blank failed: simulated.*n_holes_x"):
        blank_mesh(Blank(), MeshSpec.coarse(), cache_dir=tmp_path)
    assert not gmsh.isInitialized()
    assert not list(tmp_path.glob("*.npz"))
