"""FE results from other solvers: meshes written here with numpy + meshio (or by hand, as
Abaqus/Nastran decks), an analytic displacement = known rigid-body motion + a known quilt.

Interpolation bounds used (f = A cos(kx x) cos(ky y), |f_xx| <= A kx², |f_yy| <= A ky²,
spectral norm of the Hessian <= A (kx² + ky²)):

* bilinear on an hx x hy rectangle: |e| <= (hx² |f_xx| + hy² |f_yy|) / 8;
* linear on a non-obtuse triangle with circumradius R: |e| <= R² max|f_ee| / 2
  (Waldron, SIAM J. Numer. Anal. 35, 1998); right triangles of legs hx, hy have
  R = sqrt(hx² + hy²) / 2.
"""

from __future__ import annotations

import numpy as np
import pytest

meshio = pytest.importorskip("meshio")

from pipeline.io.fe import import_fe  # noqa: E402

A_UM = 0.1  # quilt amplitude (µm)
DX, DY = 21.0, 18.0  # quilt periods (mm)
KX, KY = 2 * np.pi / DX, 2 * np.pi / DY
D_UM = np.array([3.0, -2.0, 5.0])  # rigid translation (µm)
TH_URAD = np.array([20.0, -15.0, 40.0])  # rigid rotation (µrad)


def quilt_um(x, y):
    return A_UM * np.cos(KX * x) * np.cos(KY * y)


def plate(h=3.0, nz=2, z=(-10.0, 0.0), order=1):
    """Structured hexahedra on an 84 x 72 mm plate (4 quilt periods each way), face at z=z[1].
    order=2: hexahedron20 on the lattice of half steps (face/body centres stay orphan points)."""
    s = 2 if order == 2 else 1
    xs = np.linspace(-42, 42, s * int(round(84 / h)) + 1)
    ys = np.linspace(-36, 36, s * int(round(72 / h)) + 1)
    zs = np.linspace(z[0], z[1], s * nz + 1)
    X, Y, Z = np.meshgrid(xs, ys, zs, indexing="ij")
    pts = np.column_stack([X.ravel(), Y.ravel(), Z.ravel()])
    ny, nzp = len(ys), len(zs)

    def n(i, j, k):
        return (i * ny + j) * nzp + k

    corners = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)]
    edges = [(0, 1), (1, 2), (2, 3), (3, 0), (4, 5), (5, 6), (6, 7), (7, 4), (0, 4), (1, 5), (2, 6), (3, 7)]
    cells = []
    for i in range(0, len(xs) - 1, s):
        for j in range(0, len(ys) - 1, s):
            for k in range(0, len(zs) - 1, s):
                c = [(i + s * a, j + s * b, k + s * d) for a, b, d in corners]
                conn = [n(*p) for p in c]
                if order == 2:
                    conn += [n(*((np.array(c[p]) + np.array(c[q])) // 2)) for p, q in edges]
                cells.append(conn)
    return pts, ("hexahedron20" if order == 2 else "hexahedron"), np.array(cells)


def hex_to_tets(cells):
    """Each hexahedron (VTK order) into 6 tetrahedra around its 0-6 diagonal (conforming)."""
    t = [(0, 1, 2, 6), (0, 2, 3, 6), (0, 3, 7, 6), (0, 7, 4, 6), (0, 4, 5, 6), (0, 5, 1, 6)]
    return np.concatenate([cells[:, list(q)] for q in t])


def field_um(pts, z_face=0.0):
    """Rigid motion about (0, 0, z_face) + quilt along z + a uniform in-plane expansion (not rigid)."""
    r = pts - np.array([0.0, 0.0, z_face])
    u = D_UM + 1e-3 * np.cross(np.broadcast_to(TH_URAD, r.shape), r)
    u[:, 2] += quilt_um(pts[:, 0], pts[:, 1])
    u[:, :2] += 0.3 * pts[:, :2] / 42  # 0.3 µm at the edge: even in x, y, orthogonal to rotations
    return u


def write_vtu(path, pts, ctype, cells, u_mm, name="displacement"):
    meshio.write(path, meshio.Mesh(pts, [(ctype, cells)], point_data={name: u_mm}))
    return path


def exact_on(sm):
    X, Y = sm.grid()
    return quilt_um(X, Y)


def test_hexahedral_plate_recovers_rigid_body_and_quilt(tmp_path):
    h = 3.0
    pts, ct, cells = plate(h)
    r = import_fe(write_vtu(tmp_path / "hex.vtu", pts, ct, cells, 1e-3 * field_um(pts)), "z=0")
    rb = r.rigid_body
    np.testing.assert_allclose([rb.dx_um, rb.dy_um, rb.dz_um], D_UM, atol=1e-9)
    np.testing.assert_allclose([rb.rx_urad, rb.ry_urad, rb.rz_urad], TH_URAD, atol=1e-9)
    bound = A_UM * (KX**2 * h**2 + KY**2 * h**2) / 8
    err = np.abs(r.sag_map.sag_um - exact_on(r.sag_map))
    assert np.isfinite(r.sag_map.sag_um).all()
    assert err.max() <= bound
    assert err.max() > 0.1 * bound  # the bound is the right order: linear interpolation really is used
    assert r.sag_map.meta["interpolation"].startswith("linear")
    assert r.sag_map.x_mm[0] == -42 and r.sag_map.y_mm[-1] == 36


def test_linear_tetrahedral_plate_recovers_rigid_body_and_quilt(tmp_path):
    h = 3.0
    pts, _, cells = plate(h)
    r = import_fe(write_vtu(tmp_path / "tet.vtu", pts, "tetra", hex_to_tets(cells), 1e-3 * field_um(pts)), "+z")
    rb = r.rigid_body
    np.testing.assert_allclose([rb.dx_um, rb.dy_um, rb.dz_um, rb.rx_urad, rb.ry_urad, rb.rz_urad],
                               [*D_UM, *TH_URAD], atol=1e-9)
    R = np.hypot(h, h) / 2
    bound = R**2 * A_UM * (KX**2 + KY**2) / 2
    assert np.nanmax(np.abs(r.sag_map.sag_um - exact_on(r.sag_map))) <= bound
    assert "triangle" in r.sag_map.meta["interpolation"]


def test_quadratic_faces_reproduce_a_quadratic_sag_exactly(tmp_path):
    """hexahedron20 -> quad8 faces: any quadratic sag is interpolated exactly; linear hexes are not."""
    pts, ct, cells = plate(6.0, nz=1, order=2)
    x, y = pts[:, 0], pts[:, 1]
    sag = 1e-4 * (x**2 - 0.5 * y**2 + 0.7 * x * y)  # µm: power, astigmatism, no piston/tilt over the face
    u = np.zeros_like(pts)
    u[:, 2] = 1e-3 * sag
    r = import_fe(write_vtu(tmp_path / "hex20.vtu", pts, ct, cells, u), "z=0")
    X, Y = r.sag_map.grid()
    want = 1e-4 * (X**2 - 0.5 * Y**2 + 0.7 * X * Y)
    c = r.rigid_body.dz_um  # the fit removes the map's mean as piston (no tilt by symmetry)
    assert abs(r.rigid_body.rx_urad) < 1e-9 and abs(r.rigid_body.ry_urad) < 1e-9
    np.testing.assert_allclose(r.sag_map.sag_um, want - c, atol=1e-10)
    assert r.sag_map.meta["interpolation"].startswith("quadratic")
    pts1, ct1, cells1 = plate(6.0, nz=1)
    u1 = np.zeros_like(pts1)
    u1[:, 2] = 1e-7 * (pts1[:, 0] ** 2 - 0.5 * pts1[:, 1] ** 2 + 0.7 * pts1[:, 0] * pts1[:, 1])
    r1 = import_fe(write_vtu(tmp_path / "hex8.vtu", pts1, ct1, cells1, u1), "z=0")
    assert np.abs(r1.sag_map.sag_um - (want - r1.rigid_body.dz_um)).max() > 1e-4


def test_sag_along_normal_equals_z_on_a_flat_face_with_in_plane_motion(tmp_path):
    """On a flat face the outward normal is +z: in-plane displacements must not leak into the sag."""
    pts, ct, cells = plate(6.0, nz=1)
    path = write_vtu(tmp_path / "p.vtu", pts, ct, cells, 1e-3 * field_um(pts))
    rz, rn = import_fe(path, "z=0"), import_fe(path, "z=0", sag_along="normal")
    np.testing.assert_allclose(rn.sag_map.sag_um, rz.sag_map.sag_um, atol=1e-12)
    assert rn.sag_map.meta["sag_along"] == "normal"


def test_face_looking_down_needs_axes_and_transforms_the_motion(tmp_path):
    """A face at the bottom (outward -z): optical frame x, -y, -z (a rotation by 180° about x)."""
    pts, ct, cells = plate(3.0, z=(0.0, 10.0))
    path = write_vtu(tmp_path / "down.vtu", pts, ct, cells, 1e-3 * field_um(pts))
    with pytest.raises(ValueError, match="axes"):
        import_fe(path, "z=0")
    r = import_fe(path, "z=0", axes="x,-y,-z")
    rb = r.rigid_body
    # the quilt moves the face along solver +z = optical -z: sag is -quilt; vectors and
    # rotations (axial vectors, proper rotation) map as (x, -y, -z)
    np.testing.assert_allclose([rb.dx_um, rb.dy_um, rb.dz_um], D_UM * [1, -1, -1], atol=1e-9)
    np.testing.assert_allclose([rb.rx_urad, rb.ry_urad, rb.rz_urad], TH_URAD * [1, -1, -1], atol=1e-9)
    X, Y = r.sag_map.grid()
    assert np.abs(r.sag_map.sag_um + quilt_um(X, -Y)).max() <= A_UM * (KX**2 + KY**2) * 9 / 8


def _inp_text(pts_m, cells, ids, front):
    lines = ["*HEADING", "plate written by hand, metres", "*NODE"]
    lines += [f"{i}, {p[0]:.9g}, {p[1]:.9g}, {p[2]:.9g}" for i, p in zip(ids, pts_m)]
    lines.append("*ELEMENT, TYPE=C3D8, ELSET=PLATE")
    lines += [f"{e + 1}, " + ", ".join(str(ids[v]) for v in c) for e, c in enumerate(cells)]
    lines.append("*NSET, NSET=FRONT")
    fr = [str(ids[v]) for v in front]
    lines += [", ".join(fr[k:k + 8]) for k in range(0, len(fr), 8)]
    return "\n".join(lines) + "\n"


def test_abaqus_deck_in_metres_with_displacement_csv(tmp_path):
    """Non-contiguous node IDs, CSV rows shuffled with a header, metres, face by node-set name."""
    pts, _, cells = plate(6.0, nz=1)
    ids = 1000 + 7 * np.arange(len(pts))
    front = np.flatnonzero(pts[:, 2] == 0)
    (tmp_path / "plate.inp").write_text(_inp_text(pts / 1e3, cells, ids, front))
    u_m = 1e-6 * field_um(pts)
    order = np.random.default_rng(1).permutation(len(pts))
    rows = ["node_id,ux,uy,uz"] + [f"{ids[i]},{u_m[i, 0]:.12e},{u_m[i, 1]:.12e},{u_m[i, 2]:.12e}" for i in order]
    (tmp_path / "u.csv").write_text("# displacements in m\n" + "\n".join(rows) + "\n")
    r = import_fe(tmp_path / "plate.inp", "FRONT", displacement_csv=tmp_path / "u.csv", length_unit="m")
    rb = r.rigid_body
    np.testing.assert_allclose([rb.dx_um, rb.dy_um, rb.dz_um, rb.rx_urad, rb.ry_urad, rb.rz_urad],
                               [*D_UM, *TH_URAD], atol=1e-6)
    assert np.abs(r.sag_map.sag_um - exact_on(r.sag_map)).max() <= A_UM * (KX**2 + KY**2) * 36 / 8


def test_nastran_deck_with_displacement_csv(tmp_path):
    pts, _, cells = plate(6.0, nz=1)
    ids = 5 + 3 * np.arange(len(pts))
    lines = ["BEGIN BULK"] + [f"GRID,{i},,{p[0]:.6f},{p[1]:.6f},{p[2]:.6f}" for i, p in zip(ids, pts)]
    lines += [f"CHEXA,{e + 1},1," + ",".join(str(ids[v]) for v in c) for e, c in enumerate(cells)]
    (tmp_path / "plate.bdf").write_text("\n".join(lines + ["ENDDATA"]) + "\n")
    u = 1e-3 * field_um(pts)
    (tmp_path / "u.csv").write_text("\n".join(f"{i},{a},{b},{c}" for i, (a, b, c) in zip(ids, u)) + "\n")
    r = import_fe(tmp_path / "plate.bdf", "z=0", displacement_csv=tmp_path / "u.csv")
    np.testing.assert_allclose(r.rigid_body.rz_urad, TH_URAD[2], atol=1e-6)
    assert np.abs(r.sag_map.sag_um - exact_on(r.sag_map)).max() <= A_UM * (KX**2 + KY**2) * 36 / 8


def test_exodus_with_component_arrays(tmp_path):
    """Exodus nodal variables DISPLX/DISPLY/DISPLZ are joined into one vector."""
    pts, ct, cells = plate(6.0, nz=1)
    u = 1e-3 * field_um(pts)
    mesh = meshio.Mesh(pts, [(ct, cells)], point_data={"DISPLX": u[:, 0], "DISPLY": u[:, 1], "DISPLZ": u[:, 2]})
    meshio.write(tmp_path / "plate.exo", mesh)
    r = import_fe(tmp_path / "plate.exo", "+z")
    np.testing.assert_allclose(r.rigid_body.dz_um, D_UM[2], atol=1e-9)


def test_xdmf(tmp_path):
    pytest.importorskip("h5py")
    pts, ct, cells = plate(6.0, nz=1)
    u = 1e-3 * field_um(pts)
    meshio.write(tmp_path / "plate.xdmf", meshio.Mesh(pts, [(ct, cells)], point_data={"Displacement": u}))
    r = import_fe(tmp_path / "plate.xdmf", "z=0")
    np.testing.assert_allclose(r.rigid_body.rz_urad, TH_URAD[2], atol=1e-9)


def test_gmsh_physical_group_names_the_face(tmp_path):
    """A gmsh mesh whose optical face is a physical surface group: selected by name, oriented
    by the volume cells; the other boundary faces (sides, back) are not taken."""
    from fea.fe_face import parse_surface, select_face

    pts, ct, cells = plate(6.0, nz=1)
    quads = select_face(pts, [(ct, cells)], parse_surface("z=0")).blocks[0][1]
    mesh = meshio.Mesh(pts, [(ct, cells), ("quad", quads)], point_data={"displacement": 1e-3 * field_um(pts)},
                       cell_data={"gmsh:physical": [np.full(len(cells), 1), np.full(len(quads), 2)],
                                  "gmsh:geometrical": [np.full(len(cells), 1), np.full(len(quads), 2)]},
                       field_data={"blank": np.array([1, 3]), "optical_face": np.array([2, 2])})
    meshio.write(tmp_path / "plate.msh", mesh, file_format="gmsh22", binary=True)
    r = import_fe(tmp_path / "plate.msh", "optical_face")
    assert r.n_face_nodes == np.count_nonzero(pts[:, 2] == 0)
    np.testing.assert_allclose([r.rigid_body.dz_um, r.rigid_body.rz_urad], [D_UM[2], TH_URAD[2]], atol=1e-9)


# ---------------------------------------------------------------------- bad inputs
def test_bad_inputs_name_parameter_value_and_options(tmp_path):
    pts, ct, cells = plate(6.0, nz=1)
    bare = tmp_path / "bare.vtu"
    meshio.write(bare, meshio.Mesh(pts, [(ct, cells)], point_data={"temperature": pts[:, 0]}))
    with pytest.raises(ValueError, match=r"field=None.*temperature"):
        import_fe(bare, "z=0")
    good = write_vtu(tmp_path / "good.vtu", pts, ct, cells, 1e-3 * field_um(pts))
    with pytest.raises(ValueError, match=r"field='U'.*\['displacement'\]"):
        import_fe(good, "z=0", field="U")
    with pytest.raises(ValueError, match=r"surface.*z=5.*-10 \.\. 0"):
        import_fe(good, "z=5")
    with pytest.raises(ValueError, match=r"surface.*normal"):
        import_fe(good, "normal:1,1,0")
    with pytest.raises(ValueError, match=r"surface='FRONT'.*valid names"):
        import_fe(good, "FRONT")
    with pytest.raises(ValueError, match=r"length_unit='ft'.*\['mm', 'm', 'in'\]"):
        import_fe(good, "z=0", length_unit="ft")
    with pytest.raises(ValueError, match=r"sag_along='y'.*\['z', 'normal'\]"):
        import_fe(good, "z=0", sag_along="y")
    with pytest.raises(ValueError, match=r"axes='x,x,z'"):
        import_fe(good, "z=0", axes="x,x,z")
    with pytest.raises(ValueError, match="does not exist"):
        import_fe(tmp_path / "missing.vtu", "z=0")


def test_cli_import_fe_writes_a_readable_map(tmp_path, capsys):
    from pipeline.cli import main
    from pipeline.io.registry import read_sag_map

    pts, ct, cells = plate(6.0, nz=1)
    good = write_vtu(tmp_path / "good.vtu", pts, ct, cells, 1e-3 * field_um(pts))
    assert main(["import-fe", str(good), "--surface", "z=0", "--out", str(tmp_path / "m.csv")]) == 0
    text = capsys.readouterr().out
    assert "rz" in text and "40.0" in text
    m = read_sag_map(tmp_path / "m.csv")
    assert np.nanmax(np.abs(m.sag_um - exact_on(m))) <= A_UM * (KX**2 + KY**2) * 36 / 8
    assert main(["import-fe", str(good), "--surface", "z=0", "--unit", "ft", "--out", str(tmp_path / "x.csv")]) == 2


# ---------------------------------------------------------------------- our own FEA, through VTU
def _enclosing_radius(tri_xy):
    """Radius of the smallest disc containing each triangle (n, 3, 2): half the longest edge if
    the triangle is not acute, else its circumradius."""
    a = np.linalg.norm(tri_xy[:, 1] - tri_xy[:, 2], axis=1)
    b = np.linalg.norm(tri_xy[:, 0] - tri_xy[:, 2], axis=1)
    c = np.linalg.norm(tri_xy[:, 0] - tri_xy[:, 1], axis=1)
    e = np.sort(np.stack([a, b, c], axis=1), axis=1)
    u, v = tri_xy[:, 1] - tri_xy[:, 0], tri_xy[:, 2] - tri_xy[:, 0]
    area = 0.5 * np.abs(u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0])
    circ = a * b * c / (4 * area)
    return np.where(e[:, 2] ** 2 >= e[:, 0] ** 2 + e[:, 1] ** 2, e[:, 2] / 2, circ)


@pytest.mark.slow  # 15-30 s on 2 shared cores: the coarse-mesh solve
def test_own_fea_written_to_vtu_reads_back_to_its_own_sag(tmp_path, coarse_eighth):
    """The coarse-mesh eighth model (P2 tetrahedra) written as tetra10 VTU and read back.

    (1) On the flat front face the tetra10 faces are straight-sided triangle6 cells, so the
    reader + face extraction + quadratic shape functions reproduce the FE field: at fea's own
    lattice samples (exact P2 values from scikit-fem's facet basis) they agree to round-off.
    (2) The imported map (rigid-body plane put back) and fea's own map (linear interpolation of
    the lattice samples on their Delaunay triangulation) differ by at most the linear
    interpolation bound r² M / 2 (Waldron 1998): r = the largest smallest-enclosing-disc radius
    of the Delaunay triangles holding grid points, M = the largest Frobenius norm of the sag's
    Hessian (>= its spectral norm), estimated by second differences of the imported map.
    """
    from scipy.spatial import Delaunay

    from fea.face_interp import evaluate_face
    from fea.fe_face import parse_surface, select_face
    from pipeline.io.fe import read_fe_result

    model = coarse_eighth.model
    r = coarse_eighth.solve(200, 0.5)
    path = write_vtu(tmp_path / "own.vtu", r.coords_mm.T, "tetra10", model.basis.element_dofs.T,
                     r.displacement_mm.T)
    z_front = float(r.coords_mm[2].max())
    # (1)
    data = read_fe_result(path)
    face = select_face(data.points_mm, data.blocks, parse_surface(f"z={z_front}"), tol=1e-6)
    s = r.sag
    q = (s.x_mm >= 0) & (s.y_mm >= 0)  # the modelled quarter of the mirrored face
    got = evaluate_face(data.points_mm[:, :2], 1e3 * data.displacement_mm[:, 2], face, s.x_mm[q], s.y_mm[q])
    np.testing.assert_allclose(got, s.sag_um[q], atol=1e-9 * np.abs(s.sag_um).max())
    # (2)
    imp = import_fe(path, f"z={z_front}", origin=(0.0, 0.0, z_front))
    assert imp.sag_map.meta["interpolation"].startswith("quadratic")
    m, rb = imp.sag_map, imp.rigid_body
    X, Y = m.grid()
    U = m.sag_um + rb.dz_um + 1e-3 * (rb.rx_urad * Y - rb.ry_urad * X)
    own = s.sag_map(0.5).resampled(m.x_mm, m.y_mm)
    d = U - own.sag_um
    ok = np.isfinite(d)
    assert ok.mean() > 0.95
    tri = Delaunay(np.column_stack([s.x_mm, s.y_mm]))
    hit = np.unique(tri.find_simplex(np.column_stack([X[ok], Y[ok]])))
    r_enc = _enclosing_radius(tri.points[tri.simplices[hit[hit >= 0]]]).max()
    h = m.dx_mm
    fxx = np.diff(U, 2, axis=1)[1:-1, :] / h**2
    fyy = np.diff(U, 2, axis=0)[:, 1:-1] / h**2
    fxy = np.diff(np.diff(U, axis=0), axis=1)[:-1, :-1] / h**2
    M = np.nanmax(np.sqrt(fxx**2 + fyy**2 + 2 * fxy[: fxx.shape[0], : fxx.shape[1]] ** 2))
    bound = r_enc**2 * M / 2
    err = np.abs(d[ok]).max()
    print(f"own FEA via VTU: max |import - fea map| = {err:.2e} um, bound {bound:.2e} um")
    assert err <= bound, (err, bound)


def _node_table(path, pts_mm, u_um, header, scale=1.0, delimiter=",", hole_r_mm=None, seed=3):
    """A nodal solution table as a post-processor exports it: coordinates and displacements
    in one unit, rows in any order, no elements."""
    keep = np.ones(len(pts_mm), bool)
    if hole_r_mm is not None:  # a hole through the face: no nodes there
        keep = np.hypot(pts_mm[:, 0] - 12.0, pts_mm[:, 1] - 6.0) > hole_r_mm
    rows = np.column_stack([np.arange(1, len(pts_mm) + 1), pts_mm / scale, 1e-3 * u_um / scale])[keep]
    rows = rows[np.random.default_rng(seed).permutation(len(rows))]
    np.savetxt(path, rows, delimiter=delimiter, header=header, comments="", fmt="%.12g")
    return path


def test_a_table_of_nodes_without_a_mesh_recovers_rigid_body_and_quilt(tmp_path):
    """A workbench-style nodal table in metres (``X Location (m)`` … ``UZ (m)``, rows shuffled,
    no elements): the face ``+z`` is the table's top plane, triangulated. Rigid body exact; the
    sag within the linear-triangle bound R² |f''| / 2 for right triangles of legs h (R² = h²/2)."""
    h = 3.0
    pts, _, _ = plate(h)
    path = _node_table(tmp_path / "nodes.csv", pts, field_um(pts),
                       "Node Number,X Location (m),Y Location (m),Z Location (m),UX (m),UY (m),UZ (m)", scale=1e3)
    r = import_fe(path, "+z", length_unit="m")
    rb = r.rigid_body
    # Delaunay picks each square's diagonal freely, so the nodal areas are not symmetric and the
    # quilt's area-weighted mean over the face is not exactly zero: 1e-3 of its 0.1 µm amplitude
    np.testing.assert_allclose([rb.dx_um, rb.dy_um, rb.dz_um], D_UM, atol=1e-3 * A_UM)
    np.testing.assert_allclose([rb.rx_urad, rb.ry_urad, rb.rz_urad], TH_URAD, atol=1e-2)  # of A / 42 mm = 2.4 µrad
    bound = (h**2 / 2) * A_UM * (KX**2 + KY**2) / 2
    err = np.abs(r.sag_map.sag_um - exact_on(r.sag_map))
    assert np.isfinite(r.sag_map.sag_um).all() and err.max() <= bound
    assert r.sag_map.meta["interpolation"].startswith("linear")
    same = import_fe(path, "z=0", length_unit="m")  # the plane named instead of the axis
    np.testing.assert_allclose(same.sag_map.sag_um, r.sag_map.sag_um, atol=1e-12)


def test_a_node_table_with_a_hole_in_its_face_is_not_bridged(tmp_path):
    """Nodes missing in a 10 mm disc of the face: the triangles Delaunay would lay across it
    are dropped, so the map has no values there, and keeps them around it."""
    pts, _, _ = plate(3.0)
    path = _node_table(tmp_path / "holed.txt", pts, field_um(pts), "node x y z ux uy uz", delimiter=" ",
                       hole_r_mm=10.0)
    sm = import_fe(path, "+z").sag_map
    X, Y = sm.grid()
    d = np.hypot(X - 12.0, Y - 6.0)
    assert np.isnan(sm.sag_um[d < 6.0]).all()
    assert np.isfinite(sm.sag_um[(d > 14.0) & (np.abs(X) < 40) & (np.abs(Y) < 34)]).all()


def test_node_table_refusals_name_what_is_wrong(tmp_path):
    pts, _, _ = plate(6.0)
    u = field_um(pts)
    bare = tmp_path / "bare.csv"
    np.savetxt(bare, np.column_stack([pts, 1e-3 * u]), delimiter=",")
    with pytest.raises(ValueError, match="needs a header naming its columns"):
        import_fe(bare, "+z")
    metres = _node_table(tmp_path / "m.csv", pts, u, "id,x_m,y_m,z_m,ux_m,uy_m,uz_m", scale=1e3)
    with pytest.raises(ValueError, match=r"lengths in \['m'\].*length_unit='mm'"):
        import_fe(metres, "+z")
    no_uz = _node_table(tmp_path / "nouz.csv", pts[:, :3], u, "id,x,y,z,ux,uy,temperature")
    with pytest.raises(ValueError, match=r"no column for \['uz'\]"):
        import_fe(no_uz, "+z")
    ok = _node_table(tmp_path / "ok.csv", pts, u, "id,x,y,z,ux,uy,uz")
    with pytest.raises(ValueError, match="no node or element sets"):
        import_fe(ok, "FRONT")
    with pytest.raises(ValueError, match=r"0 nodes lie on the plane z=5.*spans z = -10 .. 0"):
        import_fe(ok, "z=5")
