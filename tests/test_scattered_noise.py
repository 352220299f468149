"""Maps given as scattered points: the grid they are interpolated onto (for display and
exports), the diagnosis fitting the points themselves with their own noise, and the report
naming the gridding. Points, surfaces and noise are made here with plain numpy; files are
read through the public readers. A genuine grid with holes keeps the row-cubic noise."""

from __future__ import annotations

import json

import numpy as np
import pytest

from optics.sagmap import SagMap
from pipeline.diagnosis import diagnose
from pipeline.diagnosis.engine import build_problem
from pipeline.diagnosis.manifest import load_data, load_manifest
from pipeline.diagnosis.noise import estimate_noise, estimate_noise_scattered
from pipeline.diagnosis.nominal import thermal_factor
from pipeline.diagnosis.report import write_report
from pipeline.io.registry import read_sag_map, read_sag_map_points, write_sag_map

from diagnosis_cases import nominal_map, surface_manifest

R_MM = 68.0
NOISE_UM = 0.002
N_POINTS = 15_000
#: Relative standard deviation of estimate_noise_scattered times sqrt(n), from a Monte Carlo
#: of 200 draws of this very layout (uniform points in the disc): 1.13 for white noise alone,
#: 1.30 under the quilt below (its leakage varies with the draw).
REL_SD_SQRT_N = 1.3


def surface_um(x, y):
    """A quilt (0.05 µm, 21 x 18 mm periods) plus astigmatism (µm)."""
    return (0.05 * np.cos(2 * np.pi * x / 21) * np.cos(2 * np.pi * y / 18)
            + 0.04 * (x**2 - y**2) / R_MM**2 + 0.06 * 2 * x * y / R_MM**2)


def disc_points(rng, n):
    r, t = R_MM * np.sqrt(rng.uniform(0, 1, n)), rng.uniform(0, 2 * np.pi, n)
    return r * np.cos(t), r * np.sin(t)


def write_points(path, x, y, sag_um):
    np.savetxt(path, np.column_stack([x, y, sag_um]), delimiter=",", header="x_mm,y_mm,sag_um", comments="",
               fmt=["%.4f", "%.4f", "%.7f"])
    return path


def test_scattered_points_noise_and_grid_size(tmp_path):
    rng = np.random.default_rng(11)
    x, y = disc_points(rng, N_POINTS)
    f = write_points(tmp_path / "scattered.csv", x, y, surface_um(x, y) + rng.normal(0, NOISE_UM, N_POINTS))
    m = read_sag_map(f)
    # statistical error 1.3/sqrt(15 000) = 1.1 %; the quilt's leakage adds 0.12 nm in quadrature
    # on 2 nm (+0.2 %): 5 sd plus 0.5 % bias = 6 %
    tol = 5 * REL_SD_SQRT_N / np.sqrt(N_POINTS) + 0.005
    assert m.meta["points_noise_um"] == pytest.approx(NOISE_UM, rel=tol)
    # one node per point over the hull: a disc fills pi/4 of its bounding box
    assert m.sag_um.size <= 2 * N_POINTS
    assert 0.9 * N_POINTS < int(m.mask.sum()) < 1.1 * N_POINTS
    # the reason for the points' own estimate: interpolated nodes share their points' noise,
    # and the row cubic on the grid reads only part of it
    X, Y = m.grid()
    assert estimate_noise(X[m.mask], m.sag_um[m.mask], rows=Y[m.mask]) < 0.8 * NOISE_UM


def test_points_reader_returns_scattered_points_and_none_for_a_grid(tmp_path):
    """Scattered points come back as printed (finite sag only), beside the same map
    :func:`read_sag_map` gives; a masked grid export and a grid format give no points."""
    rng = np.random.default_rng(4)
    x, y = disc_points(rng, 2000)
    sag = surface_um(x, y)
    sag[:10] = np.nan
    f = write_points(tmp_path / "s.csv", x, y, sag)
    m, pts = read_sag_map_points(f)
    xp, yp, sp = np.loadtxt(f, delimiter=",", skiprows=1).T
    ok = np.isfinite(sp)
    np.testing.assert_array_equal(pts.x_mm, xp[ok])
    np.testing.assert_array_equal(pts.y_mm, yp[ok])
    np.testing.assert_array_equal(pts.sag_um, sp[ok])
    np.testing.assert_array_equal(m.sag_um, read_sag_map(f).sag_um)
    g = np.arange(-10.0, 10.01, 1.0)
    X, Y = np.meshgrid(g, g)
    keep = X**2 + Y**2 <= 81
    grid_csv = write_points(tmp_path / "g.csv", X[keep], Y[keep], surface_um(X, Y)[keep])
    assert read_sag_map_points(grid_csv)[1] is None
    np.savez(tmp_path / "g.npz", x_mm=g, y_mm=g, sag_um=surface_um(X, Y))
    assert read_sag_map_points(tmp_path / "g.npz")[1] is None


def test_scattered_noise_is_white_noise_sigma_whatever_the_layout():
    """Prediction errors are scaled per point by their own weights: white noise of sigma
    gives sigma on random points, along scan lines (neighbourhoods on one line) and with
    coincident twins."""
    rng = np.random.default_rng(5)
    n = 4000
    tol = 5 * REL_SD_SQRT_N / np.sqrt(n)
    x, y = rng.uniform(-50, 50, (2, n))
    assert estimate_noise_scattered(x, y, rng.normal(0, 1.0, n)) == pytest.approx(1.0, rel=tol)
    xs, ys = np.meshgrid(np.arange(-20, 20, 0.1), np.arange(-5, 5, 1.0))  # 400 x 10 scan lines
    xs = xs + rng.uniform(-0.01, 0.01, xs.shape)
    v = 0.05 * np.cos(xs / 5.0) + rng.normal(0, 0.002, xs.shape)
    assert estimate_noise_scattered(xs.ravel(), ys.ravel(), v.ravel()) == pytest.approx(0.002, rel=tol)
    pts = rng.uniform(-50, 50, (n // 2, 2))
    twins = np.vstack([pts, pts])
    assert estimate_noise_scattered(twins[:, 0], twins[:, 1], rng.normal(0, 1.0, n)) == pytest.approx(1.0, rel=tol)


@pytest.mark.parametrize("kwargs, needle", [
    ({"order": 5}, "order=5 must be an integer in 1..4"),
    ({"neighbours": 10}, "neighbours=10 must be an integer > 10"),
    ({"max_centres": 2}, "max_centres=2 must be an integer >= 5"),
])
def test_scattered_noise_options_refused(kwargs, needle):
    x = np.arange(50.0)
    with pytest.raises(ValueError, match=needle.replace("(", r"\(").replace(".", r"\.")):
        estimate_noise_scattered(x, x[::-1], x, **kwargs)


def test_diagnosis_fits_the_points_with_their_own_noise(tmp_path):
    """A map of scattered points that matches the nominal within 5 nm noise: the
    diagnosis fits the points inside the aperture themselves (not the grid they are
    interpolated onto) with the points' own noise, finds no gap, and its JSON and report
    say how the points were gridded for display and where the noise came from."""
    nom = nominal_map(tmp_path)
    cold = nom.scaled(thermal_factor(128, 80))
    rng = np.random.default_rng(7)
    x, y = disc_points(rng, N_POINTS)
    write_points(tmp_path / "scattered.csv", x, y, cold.sample(x, y) + rng.normal(0, 0.005, N_POINTS))
    man = load_manifest(surface_manifest(tmp_path, file="scattered.csv"))
    data = load_data(man)
    (d0,) = data
    assert d0.scattered and d0.node_noise_factor is None
    # every point lies inside the 137 mm aperture (disc of 68 mm): the samples are the points as printed
    xp, yp, sp = np.loadtxt(tmp_path / "scattered.csv", delimiter=",", skiprows=1).T
    np.testing.assert_array_equal(d0.x_mm, xp)
    np.testing.assert_array_equal(d0.sag_um, sp)
    prob, _ = build_problem(man, data, nom)
    assert prob.noise["scattered"] == d0.points_noise_um
    assert d0.points_noise_um == pytest.approx(0.005, rel=5 * REL_SD_SQRT_N / np.sqrt(N_POINTS) + 0.005)
    d = diagnose(man, nominal=nom, heldout=False)
    assert d.verdict == "no_gap"
    (entry,) = d.measurements
    assert entry["gridding"].startswith(f"scattered: linear interpolation of {N_POINTS} points")
    assert "mm grid" in entry["gridding"]
    assert entry["noise_from"].startswith(f"the {N_POINTS} points (local cubic")
    assert entry["noise_from"].endswith(f"fitted at the {N_POINTS} points inside the aperture")
    assert entry["read"]["points_used"] == entry["read"]["points_valid_in_file"] == N_POINTS
    jpath, hpath = write_report(d, tmp_path / "out")
    (saved,) = json.loads(jpath.read_text())["measurements"]
    assert saved["gridding"] == entry["gridding"] and saved["noise_from"] == entry["noise_from"]
    html = hpath.read_text()
    assert "<h3>What was read</h3>" in html and entry["gridding"] in html


@pytest.mark.parametrize("suffix", ["npz", "csv"])
def test_grid_with_holes_keeps_the_row_cubic_noise(tmp_path, suffix):
    """A genuine 1 mm grid with NaN outside the disc and dropouts, as NumPy arrays or as a
    masked point list: no points' noise, and the noise the diagnosis uses is the row-cubic
    estimate of the grid's own samples inside the aperture."""
    nom = nominal_map(tmp_path)
    rng = np.random.default_rng(9)
    g = np.arange(-68.0, 68.0 + 1e-9, 1.0)
    X, Y = np.meshgrid(g, g)
    Z = surface_um(X, Y) + rng.normal(0, NOISE_UM, X.shape)
    Z[X**2 + Y**2 > R_MM**2] = np.nan
    for i, j in rng.integers(10, 126, (20, 2)):
        Z[i:i + 3, j:j + 3] = np.nan
    if suffix == "npz":
        np.savez(tmp_path / "grid.npz", x_mm=g, y_mm=g, sag_um=Z)
    else:
        ok = np.isfinite(Z)
        write_points(tmp_path / "grid.csv", X[ok], Y[ok], Z[ok])
    man = load_manifest(surface_manifest(tmp_path, file=f"grid.{suffix}"))
    data = load_data(man)
    assert data[0].points_noise_um is None and not data[0].scattered
    prob, _ = build_problem(man, data, nom)
    inside = np.isfinite(Z) & (X**2 + Y**2 <= (0.5 * 137) ** 2)
    # rows taken in the file's order (y ascending), as the reader keeps them; sag printed to 1e-7 µm in the CSV
    expected = estimate_noise(X[inside], Z[inside], rows=Y[inside])
    assert prob.noise["grid"] == pytest.approx(expected, rel=1e-12 if suffix == "npz" else 1e-3)
    assert prob.noise["grid"] == pytest.approx(NOISE_UM, rel=0.15)
    assert prob.forwards[0].noise_from == "the map (cubic prediction along its rows)"


# --- grid nodes interpolated from the points (what a saved gridded map holds) ---------------

#: Tolerance in standard deviations for the factor's check below.
Z_TOL = 4.0


def barycentric_matrix(px, py, qx, qy):
    """Sparse matrix W (queries x points) of the linear interpolant on the points' Delaunay
    triangulation, from scipy's point location and affine transform: row i holds query i's
    barycentric weights on its triangle's three points."""
    from scipy.sparse import csr_matrix
    from scipy.spatial import Delaunay

    tri = Delaunay(np.column_stack([px, py]))
    q = np.column_stack([qx, qy])
    s = tri.find_simplex(q)
    assert (s >= 0).all()
    T = tri.transform[s]
    b = np.einsum("nij,nj->ni", T[:, :2], q - T[:, 2])
    w = np.column_stack([b, 1.0 - b.sum(axis=1)])
    return csr_matrix((w.ravel(), (np.repeat(np.arange(q.shape[0]), 3), tri.simplices[s].ravel())),
                      shape=(q.shape[0], px.size))


def test_node_noise_factor_is_the_rms_barycentric_weight():
    """The map's node-noise factor is the RMS over its nodes of sqrt(sum w^2), ``w`` the
    barycentric weights, computed here with scipy's own point location; and it is
    1/sqrt(2) within its statistical error: a node placed uniformly in a triangle has
    Dirichlet(1, 1, 1) weights whatever the triangle's shape, E[w^2] = 2 / (3^2 4) + 1/9 =
    1/6, so E[sum w^2] = 1/2, with variance 3 E[w^4] + 6 E[w_i^2 w_j^2] - 1/4 = 3/15 + 6/90
    - 1/4 = 1/60 per node."""
    from pipeline.io.gridding import grid_points

    rng = np.random.default_rng(21)
    x, y = disc_points(rng, N_POINTS)
    gx, gy, sag, meta = grid_points(x, y, rng.normal(0, 1.0, N_POINTS))
    X, Y = np.meshgrid(gx, gy)
    ok = np.isfinite(sag)
    W = barycentric_matrix(x, y, X[ok], Y[ok])
    sq = np.asarray(W.multiply(W).sum(axis=1)).ravel()
    assert meta["node_noise_factor"] == pytest.approx(np.sqrt(sq.mean()), rel=1e-12)
    # mean of sum w^2 over n nodes: sd sqrt(1/60 / n); the factor is its square root (d sqrt(m) = dm / (2 sqrt(m)))
    sd = np.sqrt(1 / 60 / ok.sum()) / (2 * np.sqrt(0.5))
    assert meta["node_noise_factor"] == pytest.approx(np.sqrt(0.5), abs=Z_TOL * sd)


def test_gridded_map_saved_to_a_grid_format_keeps_the_nodes_noise(tmp_path):
    """Scattered points converted to a NetCDF grid (``cryograting convert``) are grid nodes,
    not points: the diagnosis fits the nodes, with the points' noise times the nodes'
    interpolation factor the map's meta carries (a node averages its triangle's points)."""
    nom = nominal_map(tmp_path)
    rng = np.random.default_rng(3)
    x, y = disc_points(rng, N_POINTS)
    f = write_points(tmp_path / "points.csv", x, y, nom.scaled(thermal_factor(128, 80)).sample(x, y)
                     + rng.normal(0, 0.005, N_POINTS))
    write_sag_map(read_sag_map(f), tmp_path / "grid.nc")
    man = load_manifest(surface_manifest(tmp_path, file="grid.nc"))
    data = load_data(man)
    (d0,) = data
    assert not d0.scattered
    assert d0.node_noise_factor == pytest.approx(np.sqrt(0.5), abs=0.01)
    prob, _ = build_problem(man, data, nom)
    assert prob.noise["grid"] == pytest.approx(d0.points_noise_um * d0.node_noise_factor, rel=1e-12)
    assert "times" in prob.forwards[0].noise_from and "grid nodes' interpolation weights" in prob.forwards[0].noise_from


# --- the diagnosis on the points: a perfect model, and a small mismatch ----------------------

#: The aperture's radius (mm): the points fill the 137 mm aperture disc.
R_AP_MM = 68.5
POINTS_NOISE_UM = 0.002


def quilt_um(x, y):
    """A smooth quilt (0.05 µm, 21 x 18 mm periods) plus astigmatism, µm."""
    return (0.05 * np.cos(2 * np.pi * x / 21) * np.cos(2 * np.pi * y / 18)
            + 0.04 * (x**2 - y**2) / R_AP_MM**2 + 0.06 * 2 * x * y / R_AP_MM**2)


def astigmatism_um(x, y, rms_um):
    """Astigmatism of RMS ``rms_um`` over the aperture disc of radius R_AP_MM, the
    diagnosis's ``astig_0_um`` convention (Zernike (2, 2) RMS-normalised): for uniform
    points in a disc E[(x^2 - y^2)^2] / R^4 = E[r^4] E[cos^2 2t] / R^4 = (1/3)(1/2), so the
    shape (x^2 - y^2) / R^2 has RMS 1/sqrt(6)."""
    return rms_um * np.sqrt(6.0) * (x**2 - y**2) / R_AP_MM**2


def quilt_case(tmp_path, seed, astig_rms_um=0.0):
    """15 000 uniform points in the aperture disc of the quilt (plus astigmatism) with
    2 nm white noise, against a nominal that is the noise-free quilt on a 0.2 mm grid, at
    the nominal's temperature (thermal factor 1). Returns the problem and its nominal fit,
    the manifest, the nominal and the expectation computed here: the points as printed,
    the reduced chi^2 a nominal fit adds beyond noise (the injected astigmatism plus the
    nominal grid's bilinear sampling error, both at the points with piston and tilt
    removed) and the reduced chi^2's standard deviation.

    The standard deviation: with ``n`` independent points and 3 nuisances, ``rss /
    sigma^2`` is chi^2 with ``dof = n - 3`` (variance ``2 dof``) plus the mismatch ``d``'s
    cross term (variance ``4 sigma^2 |d|^2``); the sigma the diagnosis divides by is
    estimated with a relative sd of 1.3 / sqrt(n) (REL_SD_SQRT_N), which enters the ratio
    twice: sd = sqrt(2 / dof + 4 |d|^2 / (dof sigma)^2 + (2 * 1.3 / sqrt(n))^2) = 0.024
    without mismatch."""
    from scipy.interpolate import RegularGridInterpolator

    g = np.arange(-70.0, 70.0 + 1e-9, 0.2)
    G = np.meshgrid(g, g)
    nominal = SagMap(g, g, quilt_um(*G))
    write_sag_map(nominal, tmp_path / "nominal.npz")
    rng = np.random.default_rng(seed)
    r, t = R_AP_MM * np.sqrt(rng.uniform(0, 1, N_POINTS)), rng.uniform(0, 2 * np.pi, N_POINTS)
    x, y = r * np.cos(t), r * np.sin(t)
    clean = quilt_um(x, y) + astigmatism_um(x, y, astig_rms_um)
    np.savetxt(tmp_path / "quilt.csv", np.column_stack([x, y, clean + rng.normal(0, POINTS_NOISE_UM, N_POINTS)]),
               delimiter=",", header="x_mm,y_mm,sag_um", comments="", fmt="%.6f,%.6f,%.8f")
    x, y = np.loadtxt(tmp_path / "quilt.csv", delimiter=",", skiprows=1, usecols=(0, 1)).T  # as printed
    (tmp_path / "m.toml").write_text('[simulation]\nsag_file = "nominal.npz"\ncold_K = 80\n\n[[measurement]]\n'
                                     'kind = "surface"\nfile = "quilt.csv"\ntemperature_K = 80\n'
                                     'aperture_diameter_mm = 137\n')
    man = load_manifest(tmp_path / "m.toml")
    prob, nom = build_problem(man, load_data(man), nominal)
    # the model samples the nominal grid bilinearly: its own small error at the points
    bilinear = RegularGridInterpolator((g, g), nominal.sag_um)(np.column_stack([y, x]))
    clean = quilt_um(x, y) + astigmatism_um(x, y, astig_rms_um)
    A = np.column_stack([np.ones(x.size), x, y])
    d = clean - bilinear
    d = d - A @ np.linalg.lstsq(A, d, rcond=None)[0]
    dof = x.size - 3
    sd = np.sqrt(2 / dof + 4 * (d @ d) / (dof * POINTS_NOISE_UM) ** 2 + (2 * REL_SD_SQRT_N / np.sqrt(x.size)) ** 2)
    expected = {"x": x, "y": y, "mismatch_chi2": float(d @ d) / (dof * POINTS_NOISE_UM**2), "sd": sd, "dof": dof}
    return prob, nom, man, nominal, expected


def test_perfect_model_on_scattered_points_leaves_reduced_chi2_of_one(tmp_path):
    """A model equal to the surface leaves the points' noise alone: reduced chi^2 1 within
    4 of its standard deviations (0.024, :func:`quilt_case`; the nominal grid's bilinear
    error adds about 1e-4), no gap, and every point counted as an independent sample
    (n_eff within the correlation estimator's noise of n). Fitting the grid instead gave
    1.80 and 1.72 (z +33, +30) on these layouts: the interpolation's own 1.2 nm error on
    the quilt counted as mismatch."""
    prob, nom, man, nominal, exp = quilt_case(tmp_path, seed=1)
    m = "quilt"
    (f,) = prob.forwards
    np.testing.assert_array_equal(f.x, exp["x"])
    assert prob.noise[m] == pytest.approx(POINTS_NOISE_UM, rel=5 * REL_SD_SQRT_N / np.sqrt(N_POINTS))
    chi2_red = nom.rss[m] / (exp["dof"] * prob.noise[m] ** 2)
    assert exp["mismatch_chi2"] < 0.01
    assert chi2_red == pytest.approx(1.0 + exp["mismatch_chi2"], abs=4 * exp["sd"])
    assert prob.n_eff[m] > 0.85 * N_POINTS
    assert diagnose(man, nominal=nominal, heldout=False).verdict == "no_gap"


def test_astigmatism_at_half_the_noise_is_a_gap_and_is_fitted(tmp_path):
    """Astigmatism of 0.5 x the points' noise RMS (1 nm) on 15 000 points: the nominal
    fit's reduced chi^2 is 1 + 0.25 within its standard deviation (z about +10: a gap),
    and the astigmatism fitted at the points is the injected one within 3 standard errors
    of a least-squares amplitude under white noise, ``sigma / sqrt(sum z^2)`` with ``z``
    the RMS-normalised term after piston and tilt (about 2 nm / sqrt(15 000) = 0.016 nm)."""
    from pipeline.diagnosis.criteria import Criteria
    from pipeline.diagnosis.effects import LIBRARY
    from pipeline.diagnosis.fitting import fit
    from pipeline.diagnosis.gap import gap_statistics, gaps

    injected = 0.5 * POINTS_NOISE_UM
    prob, nom, _, _, exp = quilt_case(tmp_path, seed=1, astig_rms_um=injected)
    m = "quilt"
    chi2_red = nom.rss[m] / (exp["dof"] * prob.noise[m] ** 2)
    assert exp["mismatch_chi2"] == pytest.approx(0.25, rel=0.05)
    assert chi2_red == pytest.approx(1.0 + exp["mismatch_chi2"], abs=4 * exp["sd"])
    assert gap_statistics(prob, nom)[m]["z"] > Criteria().no_gap_z
    assert [g["measurement"] for g in gaps(prob, nom, Criteria())] == [m]
    fo = fit(prob, LIBRARY["astigmatism"].parameters)
    x, y = exp["x"], exp["y"]
    A = np.column_stack([np.ones(x.size), x, y])
    z = astigmatism_um(x, y, 1.0)
    z = z - A @ np.linalg.lstsq(A, z, rcond=None)[0]
    se = POINTS_NOISE_UM / np.sqrt(z @ z)
    assert fo.parameters["astig_0_um"] == pytest.approx(injected, abs=3 * se)
    assert fo.parameters["astig_45_um"] == pytest.approx(0.0, abs=3 * se)


def test_effective_samples_of_independent_scattered_points_is_their_count():
    """White noise on scattered points: successive points along a strip share no error,
    so the effective count is the points' own (within the correlation estimator's noise:
    the autocorrelation's first lags are summed while positive, about +-1/sqrt(n) each)."""
    from pipeline.diagnosis.noise import effective_samples

    rng = np.random.default_rng(2)
    x, y = disc_points(rng, N_POINTS)
    assert effective_samples(rng.normal(0, 1.0, N_POINTS), x, y) > 0.85 * N_POINTS
