"""ANSYS Mechanical APDL listings (``PRNSOL,U`` with ``NLIST``) read by ``import-fe``.

The listings are written here as APDL prints them (banner, title, ``LOAD STEP=`` and column
header repeated on every page, a ``MAXIMUM ABSOLUTE VALUES`` block, Fortran reals with five
significant digits, fields that touch when negative), in metres, for the face ``z = 0`` of
a 160 x 140 mm plate on a grid of pitch ``h`` with four through holes (radius ``R_HOLE`` at
``(±40, ±30)`` mm: the nodes inside removed). Displacement (µm):
``uz = P + SX x + SY y + q``, ``q = A cos(kx x) cos(ky y)``, and a rigid in-plane motion.

Expected values (the rigid-body fit is linear in the data, and exact for the linear part):
the plane ``P + SX x + SY y`` comes back as dz = P + <q>, ry = -1e3 SX, rx = 1e3 SY (µrad),
where <q> is q's mean over the holed plate in closed form (the plate and holes are symmetric
and q even, so q adds no tilt); dx, dy, rz exactly.

Tolerances, from the triangulation's analytic error (h = pitch, Waldron's bound for linear
triangles, R² = h²/2 for the grid's right triangles; ‖D²q‖ <= A K², |∇q| <= A K,
K² = kx² + ky²):

* the fit weighs the nodes with their lumped areas, i.e. integrates the *linear
  interpolant* of q, x q, y q over the triangulated face Ωh: pointwise
  |I(φ q) - φ q| <= h²/4 ‖D²(φ q)‖, with ‖D²(x q)‖ <= |x| A K² + 2 A K;
* Ωh differs from the holed plate only within √2 h of a hole's rim (a grid square with
  its four corners outside a hole is two Delaunay triangles, and the triangles across a
  hole are dropped): an annulus S of area 4√2 π R h per hole, where anything may differ
  by 2 A;
* PRNSOL's five digits: half a unit of the fifth, 5e-5 of |u|.

So |Δdz| <= h²/4 A K² + 2 A |S| / area (+ the printing), |Δslope_x| <= [h²/4 A (K² ∫|x| +
2 K area) + 2 A |S| max|x|_S] / ∫x² (likewise y), and the face's P/V moves by at most the
P/V of the error plane over the face (|Δslope_x| 160 + |Δslope_y| 140 mm). The map, away
from S, is the linear interpolant of the nodal sag: within h²/4 A K² of q plus the planes'
difference. The reported P/V is that of the nodal values written less the reported plane,
to the printing's round-off.
"""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from scipy.special import j1

from pipeline.io.ansys_listing import read_ansys_listing
from pipeline.io.fe import import_fe

A_UM = 0.1  # quilt amplitude (µm)
KX, KY = 2 * np.pi / 21.0, 2 * np.pi / 18.0
K2 = KX**2 + KY**2
P_UM, SX, SY = 0.6, 0.008, 0.012  # piston (µm), slopes (µm/mm): ry = -8 µrad, rx = +12 µrad
D_IN = (1.5, -0.8)  # rigid in-plane translation (µm)
RZ_URAD = 6.0
HALF = (80.0, 70.0)  # plate half-widths (mm)
R_HOLE = 8.0
HOLES = [(sx * 40.0, sy * 30.0) for sx in (-1, 1) for sy in (-1, 1)]

BANNER = [" *** ANSYS - ENGINEERING ANALYSIS SYSTEM  RELEASE 2021 R2          21.2     ***",
          " DISTRIBUTED Ansys Mechanical Enterprise", "",
          " 00000000  VERSION=LINUX x64     15:56:42  JAN 13, 2022 CP=      0.665", "", "", ""]


# ---------------------------------------------------------------------- the model and its listings
def quilt_um(x, y):
    return A_UM * np.cos(KX * x) * np.cos(KY * y)


def face_nodes(h):
    """(x, y) mm of the face's nodes: the plate's grid without the nodes inside the holes."""
    xs = np.linspace(-HALF[0], HALF[0], int(round(2 * HALF[0] / h)) + 1)
    ys = np.linspace(-HALF[1], HALF[1], int(round(2 * HALF[1] / h)) + 1)
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    xy = np.column_stack([X.ravel(), Y.ravel()])
    keep = np.all([np.hypot(xy[:, 0] - cx, xy[:, 1] - cy) >= R_HOLE for cx, cy in HOLES], axis=0)
    return xy[keep]


def field_um(xy, piston=P_UM, sx=SX, sy=SY):
    x, y = xy[:, 0], xy[:, 1]
    ux = D_IN[0] - 1e-3 * RZ_URAD * y
    uy = D_IN[1] + 1e-3 * RZ_URAD * x
    return np.column_stack([ux, uy, piston + sx * x + sy * y + quilt_um(x, y)])


def printed(v, digits=5):
    """``v`` rounded as APDL prints it (``digits`` significant)."""
    return np.array([float(f"{t:.{digits - 1}e}") for t in np.ravel(v)]).reshape(np.shape(v))


def fortran(v, digits=5, exp_digits=3):
    """A real as APDL prints it: 0.0000, 0.1 <= |v| < 1e5 fixed, else 0.ddddd with E and an
    exponent of ``exp_digits`` digits, or, for a larger exponent, the Fortran form without E."""
    if v == 0:
        return "0.0000"
    if 0.1 <= abs(v) < 1e5:
        return f"{v:.{max(digits - len(str(int(abs(v)))), 0)}f}"
    e = math.floor(math.log10(abs(v))) + 1
    m = round(v / 10.0**e, digits)
    if abs(m) >= 1.0:
        m, e = m / 10, e + 1
    mant = f"{m:.{digits}f}"
    return f"{mant}{e:+04d}" if abs(e) >= 10**exp_digits else f"{mant}E{e:+0{exp_digits + 1}d}"


def fortran_column(v, digits=5, exp_digits=3):
    """:func:`fortran` of every value of ``v`` (the same strings, computed for a whole column)."""
    v = np.asarray(v, float)
    big = (np.abs(v) >= 0.1) & (np.abs(v) < 1e5)
    if big.any() or not np.any(v):
        return [fortran(t, digits, exp_digits) for t in v]
    e = np.floor(np.log10(np.where(v == 0, 1.0, np.abs(v)))).astype(int) + 1
    m = np.round(v / 10.0**e, digits)
    over = np.abs(m) >= 1.0
    m, e = np.where(over, m / 10, m), e + over
    wide = np.abs(e) >= 10**exp_digits
    return ["0.0000" if a == 0 else f"{a:.{digits}f}{b:+04d}" if w else f"{a:.{digits}f}E{b:+0{exp_digits + 1}d}"
            for a, b, w in zip(m, e, wide)]


def prnsol_text(sets, comps=("UX", "UY", "UZ"), page=40, exp_digits=3):
    """``PRNSOL,U`` (``PRNSOL,U,Z`` for ``comps=("UZ",)``) as /OUTPUT writes it; ``sets`` is a
    list of (load step, substep, time, node ids, u in metres (n, 3))."""
    cols = list(comps) + (["USUM"] if len(comps) == 3 else [])
    out = []
    for ls, sub, t, ids, u in sets:
        vals = np.column_stack([u[:, "XYZ".index(c[1])] for c in comps]
                               + ([np.linalg.norm(u, axis=1)] if len(comps) == 3 else []))
        text = list(zip(*[fortran_column(c, exp_digits=exp_digits) for c in vals.T]))
        out += ["", " PRINT U    NODAL SOLUTION PER NODE", ""]
        for start in range(0, len(ids), page):
            out += BANNER + ["  ***** POST1 NODAL DEGREE OF FREEDOM LISTING *****", "",
                             f"  LOAD STEP= {ls:5d}  SUBSTEP= {sub:5d}", f"   TIME= {t:9.4f}      LOAD CASE=   0",
                             "", "  THE FOLLOWING DEGREE OF FREEDOM RESULTS ARE IN THE GLOBAL COORDINATE SYSTEM", "",
                             "    NODE" + "".join(f"       {c:<6}" for c in cols)]
            out += [f"{i:8d}" + "".join(f"{t:>13}" for t in row)
                    for i, row in zip(ids[start:start + page], text[start:start + page])]
        imax = np.abs(vals).argmax(axis=0)
        out += ["", " MAXIMUM ABSOLUTE VALUES", " NODE  " + "".join(f"{ids[k]:>13d}" for k in imax),
                " VALUE " + "".join(f"{fortran(vals[k, j], exp_digits=exp_digits):>13}" for j, k in enumerate(imax)),
                ""]
    return "\n".join(out) + "\n"


def nlist_text(ids, xyz_m, page=20, angles=True):
    """``NLIST`` as APDL prints it: the header every ``page`` nodes, the banner every third."""
    out = ["", " LIST ALL SELECTED NODES.   DSYS=      0", " SORT TABLE ON  NODE  NODE  NODE"]
    head = "    NODE        X                   Y                   Z" + ("             THXY     THYZ     THZX"
                                                                        if angles else "")
    order = np.argsort(ids)
    text = list(zip(*[fortran_column(c, digits=11, exp_digits=2) for c in np.asarray(xyz_m)[order].T]))
    for start in range(0, len(ids), page):
        if start and start % (3 * page) == 0:
            out += BANNER
        out += ["", head]
        for k, row in zip(order[start:start + page], text[start:start + page]):
            out.append(f"{ids[k]:8d}" + "".join(f"   {t:<17}" for t in row) + ("      0.00     0.00     0.00"
                                                                                  if angles else ""))
    return "\n".join(out) + "\n"


def plate_listings(tmp_path, h, comps=("UX", "UY", "UZ"), back=True, exp_digits=3, sets=None, name="u.lis",
                   angles=True):
    """Write ``nlist.lis`` (the face's nodes, numbered out of grid order, and a coarse back
    face at z = -25 mm that PRNSOL does not list) and the PRNSOL listing; returns the face's
    (x, y) mm, their ids and the displacement written (µm, as printed)."""
    xy = face_nodes(h)
    ids = 1000 + 3 * np.random.default_rng(7).permutation(len(xy))
    pts = np.column_stack([xy, np.zeros(len(xy))])
    all_ids, all_pts = ids, pts
    if back:
        bx, by = np.meshgrid(np.linspace(-80, 80, 17), np.linspace(-70, 70, 15), indexing="ij")
        bpts = np.column_stack([bx.ravel(), by.ravel(), np.full(bx.size, -25.0)])
        all_ids = np.concatenate([ids, np.arange(1, len(bpts) + 1)])
        all_pts = np.vstack([pts, bpts])
    (tmp_path / "nlist.lis").write_text(nlist_text(all_ids, all_pts / 1e3, angles=angles))
    order = np.argsort(ids)  # PRNSOL lists the nodes by number
    sets = sets or [(1, 1, 1.0, field_um(xy))]
    written = [printed(u_um * 1e-6) * 1e6 for *_, u_um in sets]
    (tmp_path / name).write_text(prnsol_text([(ls, sub, t, ids[order], 1e-6 * w[order])
                                              for (ls, sub, t, _), w in zip(sets, written)],
                                             comps=comps, exp_digits=exp_digits))
    return xy, ids, written


# ---------------------------------------------------------------------- the bounds
def mean_quilt_um():
    """q's mean over the holed plate, closed form (the rectangle less four discs,
    ∫_disc cos(kx x) cos(ky y) = cos(kx cx) cos(ky cy) 2π R J1(K R) / K)."""
    K = math.sqrt(K2)
    rect = A_UM * (2 * math.sin(KX * HALF[0]) / KX) * (2 * math.sin(KY * HALF[1]) / KY)
    discs = sum(A_UM * math.cos(KX * cx) * math.cos(KY * cy) * 2 * math.pi * R_HOLE * j1(K * R_HOLE) / K
                for cx, cy in HOLES)
    return (rect - discs) / face_area()


def face_area():
    return 4 * HALF[0] * HALF[1] - len(HOLES) * math.pi * R_HOLE**2


def bounds(h, quant_um):
    """(dz µm, slope_x, slope_y µm/mm, e_int µm) bounds of the module docstring."""
    K = math.sqrt(K2)
    e_int = h**2 / 4 * A_UM * K2
    strip = len(HOLES) * 4 * math.sqrt(2) * math.pi * R_HOLE * h
    area = face_area()
    dz = e_int + 2 * A_UM * strip / area + quant_um
    out = []
    for ax, half in enumerate(HALF):
        other = HALF[1 - ax]
        abs_int = 2 * other * half**2  # ∫|x| over the rectangle (>= over the face)
        reach = max(abs(c[ax]) for c in HOLES) + R_HOLE + math.sqrt(2) * h
        second = (2 * other * 2 * half**3 / 3 - sum(math.pi * R_HOLE**2 * (c[ax] ** 2 + R_HOLE**2 / 4)
                                                    for c in HOLES) - strip * reach**2)  # ∫x² over Ωh, from below
        out.append((h**2 / 4 * A_UM * (K2 * abs_int + 2 * K * area) + 2 * A_UM * strip * reach
                    + quant_um * abs_int) / second)
    centroid = strip * max(math.hypot(*c) for c in HOLES) / area  # Ωh's centroid: couples piston and tilt
    dz += centroid * (out[0] + out[1])
    return dz, out[0], out[1], e_int


def reported_plane_um(rb, x, y):
    return rb.dz_um + 1e-3 * (rb.rx_urad * y - rb.ry_urad * x)


# ---------------------------------------------------------------------- the face comes back
def test_listings_give_back_piston_tilt_and_pv(tmp_path):
    h = 1.25
    xy, ids, (u_w,) = plate_listings(tmp_path, h)
    res = import_fe(tmp_path / "u.lis", "z=0", nodes=tmp_path / "nlist.lis", length_unit="m")
    rb, m = res.rigid_body, res.sag_map
    assert res.n_face_nodes == len(xy)
    quant = 5e-5 * np.abs(u_w[:, 2]).max()
    bdz, bsx, bsy, e_int = bounds(h, quant)
    # the in-plane motion is rigid and linear: exact to the printing (5 digits of 1.5 µm)
    np.testing.assert_allclose([rb.dx_um, rb.dy_um], D_IN, atol=2e-4)
    assert rb.rz_urad == pytest.approx(RZ_URAD, abs=2e-4 / 70 * 1e3)
    assert abs(rb.dz_um - (P_UM + mean_quilt_um())) <= bdz
    assert abs(rb.ry_urad - (-1e3 * SX)) <= 1e3 * bsx
    assert abs(rb.rx_urad - 1e3 * SY) <= 1e3 * bsy
    # P/V: that of the nodal values written less the reported plane, and the quilt's own within
    # the error plane's P/V over the face
    resid = u_w[:, 2] - reported_plane_um(rb, xy[:, 0], xy[:, 1])
    assert res.stats["pv_ptt_um"] == pytest.approx(np.ptp(resid), abs=1e-9)
    pv_in = np.ptp(quilt_um(xy[:, 0], xy[:, 1]))
    assert abs(res.stats["pv_ptt_um"] - pv_in) <= 2 * HALF[0] * bsx + 2 * HALF[1] * bsy
    # the map away from the holes' rims: the quilt less the planes' difference, within the
    # linear triangles' bound; no values inside the holes
    X, Y = m.grid()
    d = np.min([np.hypot(X - cx, Y - cy) for cx, cy in HOLES], axis=0)
    away = d > R_HOLE + math.sqrt(2) * h
    want = quilt_um(X, Y) + P_UM + SX * X + SY * Y - reported_plane_um(rb, X, Y)
    err = np.abs(m.sag_um - want)[away]
    assert np.isfinite(err).all() and err.max() <= e_int + quant
    assert err.max() > 0.1 * e_int  # the bound is of the right order: the map is interpolated linearly
    assert np.isnan(m.sag_um[d < R_HOLE - math.sqrt(2) * h]).all()
    assert m.meta["result_set"] == "load step 1, substep 1 (time 1.0000)"
    assert m.meta["components"] == ["UX", "UY", "UZ"]
    assert m.meta["notes"] == ["255 nodes of nlist.lis are not in the displacement listing and not on the face: "
                               "left out (nodes 1, 2, 3, 4, 5, ...)"]
    print(f"ANSYS listings, h = {h} mm, {len(xy)} face nodes: dz {rb.dz_um - P_UM - mean_quilt_um():+.2e} um "
          f"(bound {bdz:.1e}), rx {rb.rx_urad - 1e3 * SY:+.2e} urad (bound {1e3 * bsy:.1e}), ry "
          f"{rb.ry_urad + 1e3 * SX:+.2e} urad (bound {1e3 * bsx:.1e}), P/V {res.stats['pv_ptt_um']:.5f} um "
          f"(in {pv_in:.5f}), map {err.max():.2e} um (bound {e_int:.2e})")


def test_uz_only_listing_gives_the_same_face(tmp_path):
    """``PRNSOL,U,Z`` in the older two-digit exponent style, ``NLIST`` without the angle
    columns: the same piston, tilt and map as the full listing; dx, dy, rz are 0 and a note
    says why."""
    h = 2.0
    plate_listings(tmp_path, h, name="full.lis")
    full = import_fe(tmp_path / "full.lis", "+z", nodes=tmp_path / "nlist.lis", length_unit="m")
    xy, ids, (u_w,) = plate_listings(tmp_path, h, comps=("UZ",), exp_digits=2, back=False, name="uz.lis",
                                     angles=False)
    text = (tmp_path / "uz.lis").read_text()
    assert "E-05" in text and "E-005" not in text and "    NODE       UZ    " in text
    assert "THXY" not in (tmp_path / "nlist.lis").read_text()
    uz = import_fe(tmp_path / "uz.lis", "+z", nodes=tmp_path / "nlist.lis", length_unit="m")
    a, b = full.rigid_body, uz.rigid_body
    np.testing.assert_allclose([b.dz_um, b.rx_urad, b.ry_urad], [a.dz_um, a.rx_urad, a.ry_urad], atol=1e-9)
    np.testing.assert_allclose([b.dx_um, b.dy_um, b.rz_urad], 0.0, atol=1e-12)  # a fit of zeros: round-off
    np.testing.assert_allclose(uz.sag_map.sag_um, full.sag_map.sag_um, atol=1e-9, equal_nan=True)
    bdz, bsx, bsy, _ = bounds(h, quant_um=5e-5 * np.abs(u_w[:, 2]).max())
    assert abs(b.dz_um - (P_UM + mean_quilt_um())) <= bdz
    assert abs(b.rx_urad - 1e3 * SY) <= 1e3 * bsy and abs(b.ry_urad + 1e3 * SX) <= 1e3 * bsx
    assert uz.sag_map.meta["components"] == ["UZ"]
    assert uz.sag_map.meta["notes"] == ["uz.lis lists UZ only: UX, UY read as 0, so the rigid-body motion is fitted "
                                        "to UZ alone (the parts of it that only move the face along x, y read 0)"]


def test_fortran_reals_as_apdl_prints_them(tmp_path):
    """Three-digit exponents with and without their E, fields that touch, D exponents, fixed
    reals; page headers and the MAXIMUM block are not rows; one /OUTPUT file holding both
    listings needs no nodes."""
    rows = ["       1   0.0000       0.0000       0.0000       0.0000",
            "       2  0.12345E-003-0.23456E-004 0.34567-100  0.12617E-003",
            "       3  1.5D-03      -4.5552      0.10000+101  4.8000",
            "       4 -0.98765E-05-0.11111-102  0.22222E-05  0.1E-04"]
    page = BANNER + ["  ***** POST1 NODAL DEGREE OF FREEDOM LISTING *****", "",
                     "  LOAD STEP=     1  SUBSTEP=     1", "   TIME=    1.0000      LOAD CASE=   0", "",
                     "  THE FOLLOWING DEGREE OF FREEDOM RESULTS ARE IN THE GLOBAL COORDINATE SYSTEM", "",
                     "    NODE       UX           UY           UZ           USUM"]
    text = (nlist_text(np.arange(1, 5), np.eye(4, 3) * 0.01) + "\n PRINT U    NODAL SOLUTION PER NODE\n"
            + "\n".join(page + rows[:2] + page + rows[2:]) + "\n\n MAXIMUM ABSOLUTE VALUES\n NODE          3    3    3"
            "    3\n VALUE   1.5000  -4.5552   0.1E+101  4.8000\n")
    (tmp_path / "both.out").write_text(text)
    lst = read_ansys_listing(tmp_path / "both.out")
    np.testing.assert_array_equal(lst.node_ids, [1, 2, 3, 4])
    np.testing.assert_array_equal(lst.points, np.eye(4, 3) * 0.01)
    np.testing.assert_array_equal(lst.displacement, [[0.0, 0.0, 0.0], [0.12345e-3, -0.23456e-4, 0.34567e-100],
                                                     [1.5e-3, -4.5552, 0.1e101], [-0.98765e-5, -0.11111e-102,
                                                                                  0.22222e-5]])
    assert fortran(1.2345e-101, exp_digits=2) == "0.12345-100" and fortran(1.2345e-101) == "0.12345E-100"
    assert fortran(-1.2345e-7, exp_digits=2) == "-0.12345E-06"


# ---------------------------------------------------------------------- load steps, the CLI
def test_several_load_steps_are_named_until_one_is_chosen(tmp_path, capsys):
    from pipeline.cli import main

    h = 2.0
    xy = face_nodes(h)
    sets = [(1, 1, 1.0, field_um(xy)), (2, 1, 2.0, field_um(xy, piston=0.9, sx=-0.005, sy=0.004))]
    _, _, written = plate_listings(tmp_path, h, sets=sets)
    nodes = tmp_path / "nlist.lis"
    with pytest.raises(ValueError, match=r"lists 2 result sets \(load step 1, substep 1 \(time 1\.0000\); load step "
                                         r"2, substep 1 \(time 2\.0000\)\); choose one with load_step=N"):
        import_fe(tmp_path / "u.lis", "z=0", nodes=nodes, length_unit="m")
    with pytest.raises(ValueError, match=r"load_step=3: .* does not list that result set; it lists load step 1"):
        import_fe(tmp_path / "u.lis", "z=0", nodes=nodes, length_unit="m", load_step=3)
    two = import_fe(tmp_path / "u.lis", "z=0", nodes=nodes, length_unit="m", load_step=2, substep=1, spacing_mm=1.0)
    bdz, bsx, bsy, _ = bounds(h, quant_um=5e-5 * np.abs(written[1][:, 2]).max())
    assert abs(two.rigid_body.dz_um - (0.9 + mean_quilt_um())) <= bdz
    assert abs(two.rigid_body.ry_urad - 5.0) <= 1e3 * bsx and abs(two.rigid_body.rx_urad - 4.0) <= 1e3 * bsy
    assert two.sag_map.meta["result_set"] == "load step 2, substep 1 (time 2.0000)"

    args = ["import-fe", str(tmp_path / "u.lis"), "--nodes", str(nodes), "--surface", "z=0", "--unit", "m",
            "--spacing-mm", "1", "--out", str(tmp_path / "face.npz")]
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "choose one with --load-step N (and --substep M" in err[0], err
    assert main(args + ["--load-step", "2"]) == 0
    out = capsys.readouterr().out
    assert "result set: load step 2, substep 1 (time 2.0000)" in out
    assert f"dz = {two.rigid_body.dz_um:+.4f} µm" in out and f"ry = {two.rigid_body.ry_urad:+.4f} µrad" in out
    assert "note: 255 nodes of nlist.lis are not in the displacement listing" in out

    from pipeline.io.registry import read_sag_map

    back = read_sag_map(tmp_path / "face.npz")
    np.testing.assert_allclose(back.sag_um, two.sag_map.sag_um, atol=1e-12, equal_nan=True)


def test_cli_refuses_a_displacement_listing_without_its_nodes(tmp_path, capsys):
    from pipeline.cli import main

    plate_listings(tmp_path, 4.0)
    args = ["import-fe", str(tmp_path / "u.lis"), "--surface", "z=0", "--unit", "m", "--out", str(tmp_path / "f.npz")]
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no node coordinates; give the NLIST listing of the same nodes as --nodes NLIST" in err[0]
    assert not (tmp_path / "f.npz").exists()


# ---------------------------------------------------------------------- refusals
def small(tmp_path, *, prnsol=None, nlist=None, n=5):
    """A 5 x 5 face of 10 mm pitch (nodes 1..25) with a uniform UZ; ``prnsol``/``nlist`` edit the text."""
    g = np.arange(n) * 0.01
    X, Y = np.meshgrid(g, g, indexing="ij")
    pts = np.column_stack([X.ravel(), Y.ravel(), np.zeros(X.size)])
    ids = np.arange(1, len(pts) + 1)
    u = np.tile([0.0, 0.0, 1e-6], (len(pts), 1))
    t_u, t_n = prnsol_text([(1, 1, 1.0, ids, u)]), nlist_text(ids, pts)
    (tmp_path / "u.lis").write_text(prnsol(t_u) if prnsol else t_u)
    (tmp_path / "n.lis").write_text(nlist(t_n) if nlist else t_n)
    return tmp_path / "u.lis", tmp_path / "n.lis"


def _drop_rows(text, nodes):
    return "\n".join(l for l in text.splitlines() if not (l[:8].strip().isdigit() and int(l[:8]) in nodes)) + "\n"


def _uz_then_ux_of_node_5():
    """PRNSOL,U,Z of the 25 nodes, then PRNSOL,U,X of node 5 alone, in one file."""
    u = np.tile([0.0, 0.0, 1e-6], (25, 1))
    return (prnsol_text([(1, 1, 1.0, np.arange(1, 26), u)], comps=("UZ",))
            + prnsol_text([(1, 1, 1.0, np.array([5]), u[:1])], comps=("UX",)))


def _edit_row(text, node, new):
    return "\n".join(new if l[:8].strip() == str(node) else l for l in text.splitlines()) + "\n"


REFUSALS = {
    "no coordinates": (dict(), dict(nodes=None), r"u\.lis holds displacements \(PRNSOL,U\) but no node coordinates; "
                       r"give the NLIST listing of the same nodes as nodes=NLIST"),
    "NLIST as the result": (dict(), dict(swap="nlist only"), r"n\.lis lists node coordinates \(NLIST\) but no "
                            r"displacements: give the PRNSOL,U listing as the result, with nodes=.*n\.lis"),
    "swapped": (dict(), dict(swap="both"), r"n\.lis is a node listing \(NLIST\) and nodes=.*u\.lis.* a displacement "
                r"listing \(PRNSOL,U\): give them the other way round"),
    "no coordinates for displaced nodes": (dict(nlist=lambda t: _drop_rows(t, {23, 24, 25})), dict(),
                                           r"u\.lis: 3 of the 25 nodes it lists \(load step 1, substep 1 \(time "
                                           r"1\.0000\)\) have no coordinates in .*n\.lis \(nodes 23, 24, 25\)"),
    "face nodes without displacement": (dict(prnsol=lambda t: _drop_rows(t, {7, 13})), dict(),
                                        r"u\.lis: no displacement for some nodes of the face 'z=0': 2 of its 25 nodes "
                                        r"\(nodes 7, 13\); list them with PRNSOL"),
    "asterisks": (dict(prnsol=lambda t: _edit_row(t, 9, "       9   0.0000       0.0000      ************  0.0000")),
                  dict(), r"u\.lis, line \d+: '\*+' is not a number"),
    "a value missing": (dict(prnsol=lambda t: _edit_row(t, 9, "       9   0.0000       0.0000       0.0000")), dict(),
                        r"u\.lis, line \d+: expected 4 values \(UX UY UZ USUM\) after the node number, got 3"),
    "node twice": (dict(prnsol=lambda t: t.replace(" MAXIMUM ABSOLUTE VALUES", "       4   0.0000       0.0000  "
                                                   "     0.5E-06      0.5E-06\n MAXIMUM ABSOLUTE VALUES")), dict(),
                   r"u\.lis: node 4 is listed twice in load step 1, substep 1 \(time 1\.0000\) with different UZ "
                   r"\(lines \d+ and \d+\)"),
    "local result system": (dict(prnsol=lambda t: t.replace("IN THE GLOBAL COORDINATE", "IN THE NODAL COORDINATE")),
                            dict(), r"u\.lis, line \d+: the displacements are listed in another than the global "
                            r"coordinate system .*; list them with RSYS,0"),
    "display system": (dict(nlist=lambda t: t.replace("DSYS=      0", "DSYS=     11")), dict(),
                       r"n\.lis, line 2: the nodes are listed in display coordinate system DSYS=11; list them in "
                       r"the global Cartesian system \(DSYS,0 before NLIST\)"),
    "not a displacement listing": (dict(prnsol=lambda t: re.sub(r"\bU(X|Y|Z|SUM)\b", r"S\1", t)), dict(),
                                   r"u\.lis: no PRNSOL,U displacement table"),
    "a component for some nodes": (dict(prnsol=lambda t: _uz_then_ux_of_node_5()), dict(),
                                   r"u\.lis: UX is listed for 1 of the 25 nodes of load step 1, substep 1 "
                                   r"\(time 1\.0000\) \(not for nodes 1, 2, 3, 4, 6, \.\.\.\)"),
    "an empty NLIST": (dict(nlist=lambda t: "\n".join(t.splitlines()[:3]) + "\n"), dict(),
                       r"nodes='.*n\.lis': no NLIST coordinate table"),
    "load step zero": (dict(), dict(load_step=0), r"load_step=0 must be a positive integer"),
    "a substep not listed": (dict(), dict(substep=2), r"substep=2: .*u\.lis does not list that result set; it lists "
                             r"load step 1, substep 1 \(time 1\.0000\)"),
    "a CSV beside the listings": (dict(), dict(displacement_csv="u.csv"),
                                  r"displacement_csv='u\.csv': an ANSYS listing's displacements are its PRNSOL,U table"),
    "an NLIST that does not exist": (dict(), dict(nodes="missing.lis"),
                                     r"NLIST listing missing\.lis: file does not exist"),
}


@pytest.mark.parametrize("case", sorted(REFUSALS))
def test_each_malformed_listing_gets_its_own_error(tmp_path, case):
    edit, call, match = REFUSALS[case]
    u, n = small(tmp_path, **edit)
    call = dict(call)
    swap = call.pop("swap", None)
    path, nodes = (n, None) if swap == "nlist only" else (n, u) if swap == "both" else (u, call.pop("nodes", n))
    with pytest.raises(ValueError, match=match):
        import_fe(path, "z=0", nodes=nodes, length_unit="m", **call)


def test_load_steps_belong_to_listings_only(tmp_path):
    table = tmp_path / "nodes.csv"
    table.write_text("x,y,z,ux,uy,uz\n0,0,0,0,0,1\n1,0,0,0,0,1\n0,1,0,0,0,1\n")
    with pytest.raises(ValueError, match=r"load_step=2: only an ANSYS listing has load steps; .*nodes\.csv is not one"):
        import_fe(table, "z=0", load_step=2)
