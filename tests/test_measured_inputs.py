"""Readers on data shaped the way measurements come, written here with plain numpy/text
(never with the project's own writers): masked point lists, scattered clouds, NetCDF
in other units, background-subtracted and counted line profiles, foreign CODE V files,
and manifests with mistakes. Expected values come from the analytic surfaces used to
write the files; interpolation bounds from the grid geometry."""

from __future__ import annotations

import math

import numpy as np
import pytest

from optics.sagmap import quilt_sag_map
from pipeline.io import registry as ic
from pipeline.io.measured import read_line_profile
from pipeline.diagnosis.forward import ProfileForward
from pipeline.diagnosis.manifest import ProfileData, load_data, load_manifest, parse_manifest, recentre

A_UM, PX_MM, PY_MM = 0.3, 21.0, 18.0  # analytic quilt 0.3 cos(2 pi x / 21) cos(2 pi y / 18)


def quilt(x, y):
    return A_UM * np.cos(2 * np.pi * x / PX_MM) * np.cos(2 * np.pi * y / PY_MM)


#: bound of the quilt's Hessian spectral norm (<= Frobenius norm <= A (a^2 + b^2))
HESSIAN_UM_PER_MM2 = A_UM * ((2 * np.pi / PX_MM) ** 2 + (2 * np.pi / PY_MM) ** 2)


def _write_points(path, x, y, s, header="x_mm,y_mm,sag_um", extra=None, fmt="%.6g"):
    cols = [x, y, s] + ([extra] if extra is not None else [])
    np.savetxt(path, np.column_stack(cols), delimiter=",", header=header, comments="", fmt=fmt)
    return path


# ------------------------------------------------------------------ surface maps
def test_masked_grid_csv_inside_137mm_circle(tmp_path):
    """Only the points inside a 137 mm circle, rows shuffled, printed to 6 digits, an
    extra column and a header in other case: read back on the original grid."""
    h, x0, y0 = 0.7, 0.13, -0.21  # step and origin chosen so nothing is a round number
    gx, gy = x0 + h * np.arange(-100, 101), y0 + h * np.arange(-100, 101)
    X, Y = np.meshgrid(gx, gy)
    inside = X**2 + Y**2 <= 68.5**2
    rng = np.random.default_rng(1)
    o = rng.permutation(int(inside.sum()))
    x, y = X[inside][o], Y[inside][o]
    f = _write_points(tmp_path / "masked.csv", x, y, quilt(x, y), header="X_mm, Y_mm, sag_um, quality",
                      extra=np.ones(x.size))
    m = ic.read_sag_map(f)
    assert m.meta["gridding"] == "uniform grid detected"
    assert m.dx_mm == pytest.approx(h, rel=1e-6) and m.dy_mm == pytest.approx(h, rel=1e-6)
    assert int(m.mask.sum()) == x.size  # every listed point is a node, every other node NaN
    Xm, Ym = m.grid()
    np.testing.assert_array_equal(m.mask, Xm**2 + Ym**2 <= 68.5**2 + 1e-3)
    # 6 significant digits: coordinates to 5e-5 mm, sag to 5e-7 um -> |dS| <= |grad S| 5e-5 + 5e-7
    grad = A_UM * 2 * np.pi * math.hypot(1 / PX_MM, 1 / PY_MM)
    err = np.abs(m.sag_um - quilt(Xm, Ym))[m.mask]
    assert err.max() <= grad * 5e-5 + 5e-7


def test_scattered_cloud_interpolated_within_taylor_bound(tmp_path):
    """Random points in a 137 mm disc: linear interpolation on the Delaunay triangles;
    at each node the error is <= (M/2) max_i |v_i - p|^2 (Taylor about p, barycentric
    weights), M the Hessian bound, v_i the vertices of the triangle holding p."""
    from scipy.spatial import ConvexHull, Delaunay

    rng = np.random.default_rng(2)
    n = 3000
    r, t = 68.5 * np.sqrt(rng.random(n)), 2 * np.pi * rng.random(n)
    x, y = r * np.cos(t), r * np.sin(t)
    m = ic.read_sag_map(_write_points(tmp_path / "cloud.csv", x, y, quilt(x, y), fmt="%.12g"))
    assert m.meta["gridding"].startswith("scattered: linear")
    # one node per point over their hull: a finer grid only adds correlated nodes
    assert m.dx_mm == pytest.approx(np.sqrt(ConvexHull(np.column_stack([x, y])).volume / n), rel=1e-9)
    X, Y = m.grid()
    p = np.column_stack([X[m.mask], Y[m.mask]])
    tri = Delaunay(np.column_stack([x, y]))
    simplex = tri.find_simplex(p)
    assert (simplex >= 0).all()  # valid nodes are inside the hull; outside is NaN
    vert = tri.points[tri.simplices[simplex]]  # (k, 3, 2)
    reach2 = np.max(np.sum((vert - p[:, None, :]) ** 2, axis=2), axis=1)
    err = np.abs(m.sag_um[m.mask] - quilt(*p.T))
    assert np.all(err <= 0.5 * HESSIAN_UM_PER_MM2 * reach2 + 1e-9)
    assert m.mask.mean() > 0.7  # a disc fills pi/4 of its bounding box


@pytest.mark.parametrize("name,text,pattern", [
    ("bad.csv", "x_mm,y_mm,sag_um\n0,0,1\n1,0,2\n0,nan,3\n1,1,4\n", r"bad\.csv, line 4: .*coordinates must be finite"),
    ("dup.csv", "x_mm,y_mm,sag_um\n0,0,1\n1,0,2\n0,1,3\n1,1,4\n1,0,5\n",
     r"same grid node x_mm=1, y_mm=0 \(lines 3 and 6\)"),
], ids=["nonfinite_coordinate_named_with_line", "duplicate_node_named"])
def test_csv_point_list_refused(tmp_path, name, text, pattern):
    f = tmp_path / name
    f.write_text(text)
    with pytest.raises(ValueError, match=pattern):
        ic.read_sag_map(f)


def _netcdf(path, sag, units, y_descending=True, dims=("y", "x")):
    import netCDF4

    x = np.arange(-40.0, 40.01, 2.0)
    y = np.arange(-30.0, 30.01, 1.5)
    X, Y = np.meshgrid(x, y)
    values = sag(X, Y)
    if y_descending:
        y, values = y[::-1], values[::-1]
    with netCDF4.Dataset(path, "w") as ds:
        ds.createDimension(dims[0], y.size)
        ds.createDimension(dims[1], x.size)
        vy = ds.createVariable(dims[0], "f8", (dims[0],))
        vx = ds.createVariable(dims[1], "f8", (dims[1],))
        vy[:], vx[:] = y, x
        vx.units = vy.units = "mm"
        v = ds.createVariable("sag", "f8", dims, fill_value=-9999.0)
        v[:] = np.ma.masked_invalid(values)
        if units is not None:
            v.units = units
    return path


@pytest.mark.parametrize("units,factor,options", [("nm", 1e3, {}), ("um", 1.0, {}), ("µm", 1.0, {}),
                                                  ("mm", 1e-3, {}), ("m", 1e-6, {}),
                                                  ("waves", 1 / 0.6328, {"wavelength_um": 0.6328})])
def test_netcdf_units_and_holes(tmp_path, units, factor, options):
    """A NetCDF written with netCDF4 directly: variable 'sag' in another unit, y
    descending, a _FillValue hole outside a 60 mm circle -> µm, ascending, NaN."""
    def sag(X, Y):
        return np.where(X**2 + Y**2 < 30**2, quilt(X, Y) * factor, np.nan)

    m = ic.read_sag_map(_netcdf(tmp_path / "m.nc", sag, units), **options)
    X, Y = m.grid()
    assert m.y_mm[0] < m.y_mm[-1]
    np.testing.assert_array_equal(m.mask, X**2 + Y**2 < 30**2)
    np.testing.assert_allclose(m.sag_um[m.mask], quilt(X, Y)[m.mask], rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("units,options,pattern", [
    ("furlongs", {}, r"units='furlongs' is not a known sag unit; valid: nm, um"),
    ("waves", {}, r"units='waves' needs wavelength_um"),
    (None, {}, r"'sag' has no 'units' attribute"),
])
def test_netcdf_bad_units_refused(tmp_path, units, options, pattern):
    f = _netcdf(tmp_path / "u.nc", quilt, units)
    with pytest.raises(ValueError, match=r"u\.nc: .*" + pattern):
        ic.read_sag_map(f, **options)


def test_npz_complex_and_garbage_refused(tmp_path):
    x, y = np.arange(5.0), np.arange(4.0)
    np.savez(tmp_path / "c.npz", x_mm=x, y_mm=y, sag_um=np.ones((4, 5)) * (1 + 1j))
    with pytest.raises(ValueError, match=r"c\.npz: 'sag_um' is complex"):
        ic.read_sag_map(tmp_path / "c.npz")
    (tmp_path / "g.npz").write_bytes(b"not a zip file at all")
    with pytest.raises(ValueError, match=r"g\.npz: not a readable \.npz"):
        ic.read_sag_map(tmp_path / "g.npz")
    (tmp_path / "e.npz").write_bytes(b"")
    with pytest.raises(ValueError, match=r"e\.npz: not a readable \.npz"):
        ic.read_sag_map(tmp_path / "e.npz")


def test_npz_holes_meshgrid_and_descending_axes(tmp_path):
    x, y = np.linspace(30, -30, 31), np.linspace(-20, 20, 21)
    X, Y = np.meshgrid(x, y)
    s = np.where(X**2 + Y**2 < 20**2, quilt(X, Y), np.nan)
    np.savez(tmp_path / "h.npz", x_mm=X, y_mm=Y, sag_um=s)
    m = ic.read_sag_map(tmp_path / "h.npz")
    Xm, Ym = m.grid()
    assert m.x_mm[0] == -30.0
    np.testing.assert_allclose(m.sag_um[m.mask], quilt(Xm, Ym)[m.mask], atol=1e-15)
    np.testing.assert_array_equal(m.mask, Xm**2 + Ym**2 < 20**2)


# ------------------------------------------------------------------ line profiles
def _profile_file(path, u, y, fmt="%.9g"):
    np.savetxt(path, np.column_stack([u, y]), delimiter=",", header="offset_um,intensity", comments="", fmt=fmt)
    return path


def _profile_entry(file, **extra):
    return {"kind": "line_profile", "file": str(file), "grating": "J", "wavelength_um": 1.25,
            "pixel_scale_mas": 250, **extra}


def test_background_subtracted_profile_with_negative_noise(tmp_path):
    rng = np.random.default_rng(4)
    u = np.linspace(-60, 60, 121)
    y = np.exp(-0.5 * (u / 8.0) ** 2) + rng.normal(0, 0.02, u.size)
    assert (y < 0).sum() > 20  # the wings are noise about zero
    off, inten = read_line_profile(_profile_file(tmp_path / "p.csv", u, y), normalise=False)
    np.testing.assert_allclose(off, u)
    np.testing.assert_allclose(inten, y, rtol=1e-8, atol=1e-10)


def test_counts_pedestal_nonuniform_shifted_unsorted(tmp_path):
    """ADU counts on a 500-count pedestal, offsets non-uniform and shifted by 7.3 µm,
    rows shuffled: read sorted, values as written; the manifest reader removes the floor
    (20th percentile) and scales to unit line peak."""
    rng = np.random.default_rng(5)
    u = np.sort(rng.uniform(-80, 80, 150)) + 7.3
    line = 3000.0 * np.exp(-0.5 * ((u - 7.3) / 9.0) ** 2)
    y = 500.0 + line + rng.normal(0, 15.0, u.size)
    o = rng.permutation(u.size)
    f = _profile_file(tmp_path / "adu.csv", u[o], y[o])
    off, inten = read_line_profile(f, normalise=False)
    np.testing.assert_allclose(off, u, atol=1e-6)
    np.testing.assert_allclose(inten, y, rtol=1e-8)
    _, unit_area = read_line_profile(f)
    assert np.trapezoid(unit_area, off) == pytest.approx(1.0)
    (pd,) = load_data(parse_manifest({"measurement": [_profile_entry(f)]}))
    floor = np.percentile(y, 20)
    np.testing.assert_allclose(pd.intensity, (y - floor) / (y.max() - floor), atol=1e-8)  # 9 digits of ~3500 / 3000
    assert pd.intensity.min() < 0  # noise below the floor stays negative


def _j_line_on_quilt(seed):
    """A quilt nominal and its J-band line profile (-2nd order, 250 mas) sampled at 140
    random offsets in +-60 µm."""
    from pipeline.diagnosis.forward import profile_curve

    nominal = quilt_sag_map(0.6, "sum", spacing_mm=1.0)
    u, y = profile_curve("J", 1.25, -2, 250, nominal, {})
    x = np.sort(np.random.default_rng(seed).uniform(-60, 60, 140))
    return nominal, x, np.interp(x, u, y)


def _best_shift(fw):
    """Line position (µm) and sum of squared residuals of the best fit of a profile
    model, searched within 1.5 µm of its starting position."""
    from scipy.optimize import minimize_scalar

    r = minimize_scalar(lambda d: float(np.sum(fw.residual({}, d) ** 2)),
                        bounds=(fw.delta0_um - 1.5, fw.delta0_um + 1.5), method="bounded",
                        options={"xatol": 1e-4})
    return r.x, r.fun


def test_profile_forward_fits_pedestal_counts_and_shift():
    """The line-profile model on a quilt nominal: data transformed to counts + pedestal
    + 7.3 µm shift on a non-uniform grid give the same best residual, at a shift 7.3 µm
    larger (flux and background are linear nuisances, the shift a fit parameter)."""
    nominal, x, clean = _j_line_on_quilt(6)
    meas = parse_manifest({"measurement": [_profile_entry(__file__)]}).measurements[0]
    peak = clean.max()
    a = ProfileForward(ProfileData(meas, x, clean / peak), nominal, 80.0)
    b = ProfileForward(ProfileData(meas, x + 7.3, (40.0 * clean + 500.0 * peak) / (40.0 * peak)), nominal, 80.0)
    (da, ca), (db, cb) = _best_shift(a), _best_shift(b)
    assert db - da == pytest.approx(7.3, abs=0.02)
    # residual in fraction of the peak: both ~ the model's own interpolation error
    assert cb == pytest.approx(ca, rel=0.05, abs=1e-8)


def test_profile_in_detector_coordinates_is_recentred(tmp_path):
    """A line at 1023.7 µm (detector coordinates, far outside the fit's +-45 µm shift
    range) is moved to the origin on loading; the fit then finds the same line position
    and residual as for the profile written about 0."""
    nominal, x, clean = _j_line_on_quilt(7)
    clean = clean * 1e4 + 200.0
    fws = []
    for name, off in (("near", 0.0), ("far", 1023.7)):
        f = _profile_file(tmp_path / f"{name}.csv", x + off, clean)
        (pd,) = load_data(parse_manifest({"measurement": [_profile_entry(f)]}))
        fws.append((ProfileForward(pd, nominal, 80.0), pd.origin_um))
        if name == "near":  # its half-maximum centre, left in place (within 20 µm of 0)
            c_near = recentre(pd.offset_um, pd.intensity, 0.0)
    (near, o_near), (far, o_far) = fws
    assert o_near == 0.0 and abs(c_near) < 20 and o_far == pytest.approx(1023.7 + c_near, abs=0.051)
    (dn, cn), (df, cf) = _best_shift(near), _best_shift(far)
    assert df + o_far - 1023.7 == pytest.approx(dn, abs=0.02)
    assert cf == pytest.approx(cn, rel=0.05, abs=1e-8)


# ------------------------------------------------------------------ manifests
def _surface_entry(file, **extra):
    return {"kind": "surface", "file": str(file), "temperature_K": 128, **extra}


def test_misspelled_key_refused_with_suggestion(tmp_path):
    f = _profile_file(tmp_path / "p.csv", np.arange(20.0), np.exp(-0.5 * (np.arange(20.0) - 10) ** 2))
    entry = {"kind": "line_profile", "file": str(f), "grating": "J", "wavelenght_um": 1.25,
             "wavelength_um": 1.25, "pixel_scale_mas": 250}
    with pytest.raises(ValueError, match=r"measurement 'p' \(kind 'line_profile'\): unknown field\(s\) "
                                         r"'wavelenght_um' \(did you mean 'wavelength_um'\?\); valid: \["):
        parse_manifest({"measurement": [entry]})
    with pytest.raises(ValueError, match=r"unknown field\(s\) 'noise_rel'.*valid:.*'noise_um'"):
        parse_manifest({"measurement": [_surface_entry(f, noise_rel=0.01)]})
    with pytest.raises(ValueError, match=r"manifest: unknown field\(s\) 'measurements' \(did you mean 'measurement'\?\)"):
        parse_manifest({"measurements": [entry]})
    with pytest.raises(ValueError, match=r"\[simulation\]: unknown field\(s\) 'cold_k' \(did you mean 'cold_K'\?\)"):
        parse_manifest({"simulation": {"cold_k": 80}, "measurement": [entry]})


def _foreign_codev_int(path, crlf=False):
    """A CODE V GRD file as another tool writes it: no EXTENT_MM title, 1e-5 µm per count."""
    gx = np.arange(-70.0, 70.01, 2.0)
    X, Y = np.meshgrid(gx, gx[::-1])  # first data row = top (+y)
    counts = np.where(X**2 + Y**2 <= 68.5**2, np.round(quilt(X, Y) / 1e-5), -32768).astype(int)
    nl = "\r\n" if crlf else "\n"
    body = nl.join(" ".join(str(c) for c in row) for row in counts)
    path.write_bytes(f"Interferogram from a metrology tool{nl}GRD {gx.size} {gx.size} SUR WVL 1.0 SSZ 100000 "
                     f"NDA -32768{nl}{body}{nl}".encode())
    return path


def test_manifest_grid_keys_reach_codev_reader(tmp_path):
    f = _foreign_codev_int(tmp_path / "tool.int")
    with pytest.raises(ValueError, match=r"measurement 'tool'.*extent_mm.*spacing_mm"):
        load_data(parse_manifest({"measurement": [_surface_entry(f)]}))
    for extra in ({"spacing_mm": 2.0}, {"extent_mm": [-70, 70, -70, 70]}):
        (s,) = load_data(parse_manifest({"measurement": [_surface_entry(f, **extra)]}))
        np.testing.assert_allclose(s.sag_um, quilt(s.x_mm, s.y_mm), atol=0.5e-5 + 1e-12)  # half a count
        g = np.arange(-70.0, 70.01, 2.0)
        assert s.x_mm.size == np.sum(np.hypot(*np.meshgrid(g, g)) <= 68.5)
    with pytest.raises(ValueError, match=r"spacing_mm=\[1, 2, 3\] must be a number or a list of 2 numbers"):
        parse_manifest({"measurement": [_surface_entry(f, spacing_mm=[1, 2, 3])]})
    npz = tmp_path / "m.npz"
    np.savez(npz, x_mm=np.arange(3.0), y_mm=np.arange(3.0), sag_um=np.zeros((3, 3)))
    with pytest.raises(ValueError, match=r"option\(s\) \['spacing_mm'\] are not valid for read_sag_npz"):
        load_data(parse_manifest({"measurement": [_surface_entry(npz, spacing_mm=1.0)]}))


def test_utf16_and_undecodable_manifest_named(tmp_path):
    text = '[[measurement]]\nkind = "surface"\nfile = "x.npz"\ntemperature_K = 128\n'
    p = tmp_path / "m16.toml"
    p.write_bytes(text.encode("utf-16"))
    with pytest.raises(ValueError, match=r"manifest .*m16\.toml: is UTF-16 text; a TOML manifest must be UTF-8"):
        load_manifest(p)
    q = tmp_path / "latin.toml"
    q.write_bytes(("# r\xe9sum\xe9\n" + text).encode("latin-1"))
    with pytest.raises(ValueError, match=r"manifest .*latin\.toml: is not UTF-8 text \(undecodable byte 0xe9"):
        load_manifest(q)


def test_tables_as_other_code_writes_them(tmp_path):
    """Semicolon, tab and whitespace tables, columns in other length units with the unit
    in brackets, and a profile with two exposures merged (samples at one offset averaged)."""
    from pipeline.io.measured import read_line_profile
    from pipeline.io.plain import read_sag_csv

    g = np.arange(-3.0, 3.01, 1.0)
    X, Y = np.meshgrid(g, g)
    sag_um = 0.1 * X - 0.05 * Y**2
    rows = np.column_stack([X.ravel() * 1e-3, Y.ravel() * 1e-3, sag_um.ravel() * 1e3])  # m, m, nm
    for name, delim in (("semi.csv", ";"), ("tab.txt", "\t"), ("space.dat", "  ")):
        p = tmp_path / name
        p.write_text(delim.join(["X [m]", "Y [m]", "height_nm"]).replace("height_nm", "sag (nm)") + "\n"
                     + "\n".join(delim.join(f"{v:.9g}" for v in r) for r in rows) + "\n")
        m = read_sag_csv(p)
        np.testing.assert_allclose(m.x_mm, g, atol=1e-12)
        np.testing.assert_allclose(m.sag_um, sag_um, atol=1e-9)
    off = np.arange(-10.0, 10.01, 1.0)
    a = np.exp(-0.5 * (off / 3) ** 2)
    b = a + 0.1 * np.cos(off)  # a second exposure at the same offsets
    p = tmp_path / "merged.csv"
    p.write_text("Offset (mm),Intensity\n" + "".join(f"{o * 1e-3:.12g},{v:.12g}\n" for o, v in
                                                      zip(np.r_[off, off], np.r_[a, b])))
    x, y = read_line_profile(p, normalise=False)
    np.testing.assert_allclose(x, off, atol=1e-9)
    np.testing.assert_allclose(y, 0.5 * (a + b), atol=1e-12)
    bad = tmp_path / "nounit.csv"
    bad.write_text("x,y,sag\n0,0,1\n1,0,1\n0,1,1\n")
    with pytest.raises(ValueError, match=r"missing column\(s\) \['x_mm', 'y_mm', 'sag_um'\].*any of nm, um, mm, m"):
        read_sag_csv(bad)


def test_a_profile_in_detector_pixels_is_read_at_the_models_pixel(tmp_path):
    """A spectrum extracted on the detector: offsets in pixels (column ``Pixel``, the line
    near pixel 1024), counts. The reader needs the pitch; the manifest gives the model's."""
    from optics.grating import SPIFFI
    from pipeline.io.measured import read_line_profile

    px = np.arange(1010.0, 1040.0, 0.25)
    counts = 200 + 5000 * np.exp(-0.5 * ((px - 1024.3) / 1.1) ** 2)
    f = tmp_path / "extracted.csv"
    f.write_text("Pixel,Counts,intensity\n" + "".join(f"{p:g},{c:.3f},{c:.3f}\n" for p, c in zip(px, counts)))
    with pytest.raises(ValueError, match=r"detector pixels \(column 'pixel'\) need pixel_um"):
        read_line_profile(f)
    x, _ = read_line_profile(f, pixel_um=18.0)
    np.testing.assert_allclose(x, px * 18.0)
    (p,) = load_data(parse_manifest({"measurement": [_profile_entry(f)]}))
    assert SPIFFI.pixel_um == 18.0
    # recentred on the line: the peak sits at offset 0 within a quarter pixel
    assert abs(p.offset_um[np.argmax(p.intensity)]) <= 0.25 * SPIFFI.pixel_um
    np.testing.assert_allclose(np.diff(p.offset_um), 0.25 * SPIFFI.pixel_um)
    none = tmp_path / "none.csv"
    none.write_text("wavelength,intensity\n" + "".join(f"{p:g},1\n" for p in px))
    with pytest.raises(ValueError, match=r"missing column\(s\) \['offset_um'\].*'offset_px' or 'pixel'"):
        read_line_profile(none)


def test_a_profile_on_a_wavelength_axis_lands_on_the_models_detector_axis(tmp_path):
    """An extracted spectrum in nm: converted with the grating equation's dispersion at the
    line, computed here from the grating's constants, signed (the J order is negative, so a
    shoulder on the short-wavelength side is at +offset)."""
    from optics.grating import GRATINGS, SPIFFI

    g, wl_um, order = GRATINGS["J"], 1.25, -2
    sin_b = order * wl_um / g.groove_spacing_um - np.sin(np.radians(g.incidence_deg))
    d_um_per_um = SPIFFI.camera_focal_mm * 1e3 * order / (g.groove_spacing_um * np.sqrt(1 - sin_b**2))
    assert d_um_per_um < 0
    o = np.arange(-60.0, 60.01, 1.5)
    shape = np.exp(-0.5 * (o / 8) ** 2) + 0.3 * np.exp(-0.5 * ((o - 15) / 5) ** 2)  # shoulder at +15 µm
    lam_nm = (wl_um + o / d_um_per_um) * 1e3
    f = tmp_path / "spectrum.csv"
    f.write_text("Wavelength [nm],intensity\n" + "".join(f"{lm:.9f},{1e4 * v:.6f}\n" for lm, v in zip(lam_nm, shape)))
    (p,) = load_data(parse_manifest({"measurement": [_profile_entry(f, order=order)]}))
    np.testing.assert_allclose(np.diff(p.offset_um), 1.5, rtol=1e-5)
    k = int(np.argmax(p.intensity))
    shoulder = p.intensity[k + 10] - p.intensity[k - 10]  # +15 µm against -15 µm
    assert shoulder > 0.2


def test_a_spectrum_window_not_centred_on_its_line_is_read_about_the_lines_wavelength(tmp_path):
    """One sample per 18 µm pixel at a 0.37-pixel phase, the window running 7 pixels short and
    8 long of the line (an outside lab's 1-D spectrum): the offsets are about the line's
    stated wavelength, not the window's median (which put every offset 6.7 µm off); a line
    outside the file's wavelength axis is refused naming both."""
    from optics.grating import GRATINGS, SPIFFI

    g, wl_um, order = GRATINGS["J"], 1.25, -2
    sin_b = order * wl_um / g.groove_spacing_um - np.sin(np.radians(g.incidence_deg))
    d_um_per_um = SPIFFI.camera_focal_mm * 1e3 * order / (g.groove_spacing_um * np.sqrt(1 - sin_b**2))
    o = (np.arange(-7, 9) + 0.37) * 18.0
    lam_um = wl_um + o / d_um_per_um
    f = tmp_path / "spectrum.csv"
    f.write_text("wavelength_um,counts\n" + "".join(f"{a:.10f},{1e4 * np.exp(-0.5 * (b / 20) ** 2) + 30:.4f}\n"
                                                      for a, b in zip(lam_um, o)))
    x, _ = read_line_profile(f, normalise=False, dispersion_um_per_um=d_um_per_um, line_wavelength_um=wl_um)
    np.testing.assert_allclose(x, o, atol=1e-4)
    x_median, _ = read_line_profile(f, normalise=False, dispersion_um_per_um=d_um_per_um)
    assert abs(np.mean(x_median - o)) > 5.0  # the window's median is not the line
    (p,) = load_data(parse_manifest({"measurement": [_profile_entry(f, order=order)]}))
    np.testing.assert_allclose(np.sort(p.offset_um + p.origin_um), o, atol=1e-4)
    with pytest.raises(ValueError, match=r"wavelength_um=1.3 lies outside the file's wavelength axis.*1.24.*1.25"):
        read_line_profile(f, dispersion_um_per_um=d_um_per_um, line_wavelength_um=1.3)


def test_a_profile_export_with_a_preamble_is_read(tmp_path):
    """Lab and program exports put title, date and exposure lines before the table."""
    u = np.linspace(-120.0, 120.0, 61)
    body = "\n".join(f"{a:.1f}\t{1000 * np.exp(-a * a / 900) + 40:.3f}" for a in u)
    p = tmp_path / "arc_1250nm.txt"
    p.write_text("Line profile export\nDate: 2026-11-20 14:02\nExposure, 10 s\n\n"
                 "Offset [um]\tIntensity\n" + body + "\n")
    x, y = read_line_profile(p, normalise=False)
    np.testing.assert_allclose(x, u)
    assert y.max() == pytest.approx(1040.0, abs=1e-3)


def test_a_table_without_a_header_names_the_header_to_add(tmp_path):
    p = tmp_path / "bare.txt"
    p.write_text("\n".join(f"{a} {np.exp(-a * a / 900):.4f}" for a in range(-60, 61, 5)) + "\n")
    with pytest.raises(ValueError, match=r"line 1: the table has no header line.*offset_um,intensity"):
        read_line_profile(p)


def test_a_psf_image_with_masked_pixels_is_read(tmp_path):
    """A bad pixel exported as nan is a masked point, not an error; an infinite one is."""
    from pipeline.io.measured import read_psf_image

    yy, xx = np.mgrid[-5:6, -5:6] * 2.0
    v = 1e3 * np.exp(-(xx**2 + yy**2) / 20.0)
    rows = [f"{a},{b},{c}" for a, b, c in zip(xx.ravel(), yy.ravel(), v.ravel())]
    rows[7] = rows[7].rsplit(",", 1)[0] + ",nan"
    p = tmp_path / "img.csv"
    p.write_text("x_um,y_um,intensity\n" + "\n".join(rows) + "\n")
    x, y, i = read_psf_image(p)
    assert x.size == 120 and np.isfinite(i).all()
    rows[7] = rows[7].rsplit(",", 1)[0] + ",inf"
    p.write_text("x_um,y_um,intensity\n" + "\n".join(rows) + "\n")
    with pytest.raises(ValueError, match="line 9: .*intensity finite or nan"):
        read_psf_image(p)


def test_a_line_profile_with_masked_samples_is_read(tmp_path):
    """A background-subtracted profile whose pipeline masked two bad pixels as nan: the
    other samples are read, unit area over them (the trapezoid flux of the kept samples);
    an infinite intensity or a nan offset is still refused, naming the line."""
    x = np.arange(-60.0, 60.01, 3.0)
    y = 800.0 * np.exp(-x * x / 600.0) - 4.0
    rows = [f"{a},{float(b)!r}" for a, b in zip(x, y)]
    rows[5], rows[30] = f"{x[5]},nan", f"{x[30]},NaN"
    p = tmp_path / "p.csv"
    p.write_text("offset_um,intensity\n" + "\n".join(rows) + "\n")
    xs, ys = read_line_profile(p)
    keep = np.ones(x.size, bool)
    keep[[5, 30]] = False
    assert np.array_equal(xs, x[keep])
    assert np.allclose(ys, y[keep] / np.trapezoid(y[keep], x[keep]), rtol=1e-12)
    for bad, line in ((f"{x[9]},inf", 11), (f"nan,{float(y[9])!r}", 11)):
        rows2 = list(rows)
        rows2[9] = bad
        p.write_text("offset_um,intensity\n" + "\n".join(rows2) + "\n")
        with pytest.raises(ValueError, match=rf"line {line}: .*intensity finite or nan"):
            read_line_profile(p)
