"""Plausibility of measurements before any fit (pipeline.diagnosis.plausibility).

Every measurement here is written with numpy, not by the forward model: a flat profile
with noise, uniform random numbers, a Gaussian line of plausible width (in µm and in mm),
a map of zeros, a pure-noise map, an analytic quilt map in µm and in nm. The expected
outcome of each is fixed by the rules in the module docstring before any run: a line
100 sigma above its median passes the 10-sigma test, a flat profile (~3 sigma) and
uniform numbers (~2 sigma) fail it; a factor of 1000 in a map's RMS or a profile's
offsets is three decades, past the two the model's priors can reach. The nominal is the
analytic sum quilt (no FEA)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from optics.sagmap import SagMap, quilt_sag_map
from pipeline.diagnosis import diagnose
from pipeline.diagnosis.campaign import CampaignConfig
from pipeline.diagnosis.cli import main
from pipeline.diagnosis.manifest import load_data, load_manifest
from pipeline.diagnosis.plausibility import (Plausibility, at_prior_bound, check_measurements, image_problems,
                                             line_fwhm, measurement_problems, profile_problems, unit_hint)
from pipeline.io.registry import write_sag_map

SCEN = Path(__file__).resolve().parents[1] / "pipeline" / "scenarios"
OFFSETS_UM = np.arange(-120.0, 120.01, 1.5)


def _gauss(x, fwhm_um, rng, noise=0.01, background=0.02):
    s = fwhm_um / (2 * np.sqrt(2 * np.log(2)))
    y = background + np.exp(-0.5 * (x / s) ** 2) + rng.normal(0, noise, x.size)
    return np.clip(y, 0, None)


def _nominal(tmp_path):
    m = quilt_sag_map(0.6, "sum", spacing_mm=0.5)
    write_sag_map(m, tmp_path / "nominal.npz")
    return m


def _profile_manifest(tmp_path, x, y, extra_entries=""):
    np.savetxt(tmp_path / "p.csv", np.column_stack([x, y]), delimiter=",", header="offset_um,intensity", comments="")
    text = ('[simulation]\nsag_file = "nominal.npz"\ncold_K = 80\n\n[[measurement]]\nkind = "line_profile"\n'
            'file = "p.csv"\ngrating = "J"\norder = -2\nwavelength_um = 1.25\npixel_scale_mas = 25\n' + extra_entries)
    (tmp_path / "m.toml").write_text(text)
    return tmp_path / "m.toml"


def _map_entry(file="map.npz"):
    return f'\n[[measurement]]\nkind = "surface"\nfile = "{file}"\ntemperature_K = 128\naperture_diameter_mm = 137\n'


def _map_manifest(tmp_path, sag_um, step_mm=0.5):
    x = np.arange(-80.0, 80.01, step_mm)
    y = np.arange(-70.0, 70.01, step_mm)
    write_sag_map(SagMap(x, y, sag_um(*np.meshgrid(x, y))), tmp_path / "map.npz")
    text = '[simulation]\nsag_file = "nominal.npz"\ncold_K = 80\n' + _map_entry()
    (tmp_path / "m.toml").write_text(text)
    return tmp_path / "m.toml"


def _analytic_quilt_um(X, Y):
    """An out-of-model quilt (product form, other periods) at 128 K's amplitude, with noise."""
    rng = np.random.default_rng(7)
    q = 0.25 * np.cos(2 * np.pi * X / 21.4) * np.cos(2 * np.pi * Y / 17.6) + 0.03 * (X**2 + Y**2) / 70.0**2
    return q + rng.normal(0, 0.01, X.shape)


def _problems(path, nominal):
    man = load_manifest(path)
    return measurement_problems(man, load_data(man), nominal)


# --- line profiles -----------------------------------------------------------------------


def test_gaussian_line_of_plausible_width_passes(tmp_path):
    nom = _nominal(tmp_path)
    y = _gauss(OFFSETS_UM, 40.0, np.random.default_rng(1))
    assert line_fwhm(OFFSETS_UM, y) == pytest.approx(40.0, rel=0.1)
    assert _problems(_profile_manifest(tmp_path, OFFSETS_UM, y), nom) == []


@pytest.mark.parametrize("make", ["flat", "uniform"])
def test_profile_without_a_line_is_refused(tmp_path, make):
    nom = _nominal(tmp_path)
    rng = np.random.default_rng(2)
    y = 0.5 + rng.normal(0, 0.01, OFFSETS_UM.size) if make == "flat" else rng.uniform(0, 1, OFFSETS_UM.size)
    path = _profile_manifest(tmp_path, OFFSETS_UM, y)
    (p,) = _problems(path, nom)
    assert p.code == "no_line" and p.fatal
    assert "no line found: peak" in p.message and "sigma above the median, need >= 10" in p.message
    with pytest.raises(ValueError, match=r"'p': no line found: peak \d\.\d sigma above the median, need >= 10"):
        diagnose(path)


def test_profile_offsets_in_mm_are_named(tmp_path):
    nom = _nominal(tmp_path)
    y = _gauss(OFFSETS_UM, 40.0, np.random.default_rng(3))
    (p,) = _problems(_profile_manifest(tmp_path, OFFSETS_UM / 1000.0, y), nom)
    assert p.code == "unit" and "offsets span 0.24 µm" in p.message and p.message.endswith("wrong unit (mm)?")
    (p,) = _problems(_profile_manifest(tmp_path, OFFSETS_UM * 1000.0, y), nom)
    assert p.code == "unit" and p.message.endswith("wrong unit (nm)?")


@pytest.mark.parametrize("fwhm_um, ok", [(5.0, False), (40.0, True), (400.0, False)])
def test_line_width_against_the_nominal(fwhm_um, ok):
    x = np.arange(-1500.0, 1500.01, 1.5)
    probs = profile_problems("p", x, _gauss(x, fwhm_um, np.random.default_rng(4)), nominal_fwhm_um=40.0)
    assert (probs == []) == ok
    if not ok:
        assert probs[0].code == "width" and "x the nominal's 40.0 µm" in probs[0].message


def test_stated_noise_is_used():
    """A stated noise_rel replaces the estimate: a clean line with a large stated noise has no line."""
    y = _gauss(OFFSETS_UM, 40.0, np.random.default_rng(5), noise=0.0)
    assert profile_problems("p", OFFSETS_UM, y, 40.0) == []
    (p,) = profile_problems("p", OFFSETS_UM, y, 40.0, noise_rel=0.2)
    # peak 1 above a median at the 0.02 background (+0.002 of line wing at |x| = 60 µm): 0.998 / 0.2
    assert p.code == "no_line" and "peak 5.0 sigma" in p.message


def test_point_source_image_needs_a_peak():
    """A 2-D Gaussian spot (3 µm sigma, 1 % noise, 1 µm steps) passes; pure noise is refused."""
    rng = np.random.default_rng(9)
    X, Y = np.meshgrid(np.arange(-30.0, 30.01, 1.0), np.arange(-30.0, 30.01, 1.0))
    spot = np.exp(-(X**2 + Y**2) / (2 * 3.0**2)) + rng.normal(0, 0.01, X.shape)
    assert image_problems("img", X.ravel(), Y.ravel(), spot.ravel()) == []
    (p,) = image_problems("img", X.ravel(), Y.ravel(), rng.normal(0, 0.01, X.size))
    assert p.code == "no_line" and "no point-source image found" in p.message


# --- surface maps ------------------------------------------------------------------------


def test_analytic_quilt_map_in_um_passes_and_in_nm_is_named(tmp_path):
    nom = _nominal(tmp_path)
    assert _problems(_map_manifest(tmp_path, _analytic_quilt_um), nom) == []
    path = _map_manifest(tmp_path, lambda X, Y: 1000.0 * _analytic_quilt_um(X, Y))
    (p,) = _problems(path, nom)
    assert p.code == "unit" and p.fatal
    assert " µm is 3 orders above the nominal's " in p.message and p.message.endswith("wrong unit (nm)?")
    with pytest.raises(ValueError, match=r"wrong unit \(nm\)\?"):
        diagnose(path)


def test_map_in_mm_is_named(tmp_path):
    nom = _nominal(tmp_path)
    (p,) = _problems(_map_manifest(tmp_path, lambda X, Y: 1e-3 * _analytic_quilt_um(X, Y)), nom)
    assert "3 orders below" in p.message and p.message.endswith("wrong unit (mm)?")


def test_map_with_coordinates_in_metres_read_as_mm_names_the_coordinates(tmp_path):
    """A NetCDF map whose coordinates are in metres without a ``units`` attribute is read in
    mm (the documented default): a 0.16 x 0.14 mm patch. That is a coordinate unit, not a
    sag unit, and the refusal says so (the sag check would name nm or mm for the sag)."""
    import xarray as xr

    nom = _nominal(tmp_path)
    x, y = np.arange(-80.0, 80.01, 1.0), np.arange(-70.0, 70.01, 1.0)
    X, Y = np.meshgrid(x, y)
    xr.Dataset({"sag_um": (("y", "x"), _analytic_quilt_um(X, Y), {"units": "um"})},
               coords={"x": x * 1e-3, "y": y * 1e-3}).to_netcdf(tmp_path / "map.nc")
    text = '[simulation]\nsag_file = "nominal.npz"\ncold_K = 80\n' + _map_entry("map.nc")
    (tmp_path / "m.toml").write_text(text)
    (p,) = _problems(tmp_path / "m.toml", nom)
    assert p.code == "unit" and p.fatal
    assert "map spans 0.16 x 0.14 mm, 3 orders below the blank's 160 mm" in p.message
    assert "coordinates in m read as mm?" in p.message
    # a sub-aperture map a tenth of the blank's size is data, not a unit error
    xs, ys = np.arange(-8.0, 8.01, 0.5), np.arange(-7.0, 7.01, 0.5)
    write_sag_map(SagMap(xs, ys, _analytic_quilt_um(*np.meshgrid(xs, ys))), tmp_path / "small.npz")
    (tmp_path / "small.toml").write_text('[simulation]\nsag_file = "nominal.npz"\ncold_K = 80\n' + _map_entry("small.npz"))
    assert all(p.code != "unit" or "spans" not in p.message for p in _problems(tmp_path / "small.toml", nom))


@pytest.mark.parametrize("make", ["zeros", "noise"])
def test_map_without_signal_says_no_signal(tmp_path, make):
    nom = _nominal(tmp_path)
    rng = np.random.default_rng(6)
    sag = (lambda X, Y: np.zeros(X.shape)) if make == "zeros" else (lambda X, Y: rng.normal(0, 0.01, X.shape))
    path = _map_manifest(tmp_path, sag)
    (p,) = _problems(path, nom)
    assert p.code == "no_signal" and p.message.startswith("no signal: map RMS")
    with pytest.raises(ValueError, match="no signal"):
        diagnose(path)


def test_quiet_map_beside_a_line_is_a_warning_not_a_refusal(tmp_path):
    """A map below its noise beside a good profile is data (the blank did not deform
    beyond the noise): a warning, and the check does not refuse."""
    nom = _nominal(tmp_path)
    x = np.arange(-80.0, 80.01, 0.5)
    write_sag_map(SagMap(x, x, np.zeros((x.size, x.size))), tmp_path / "map.npz")
    path = _profile_manifest(tmp_path, OFFSETS_UM, _gauss(OFFSETS_UM, 40.0, np.random.default_rng(8)), _map_entry())
    man = load_manifest(path)
    with pytest.warns(UserWarning, match="'map': no signal"):
        probs = check_measurements(man, load_data(man), nom)
    assert [p.code for p in probs] == ["no_signal"]


def test_bundled_scenarios_are_plausible():
    """Only the check on the scenarios' loaded data; nominal: the analytic quilt (the
    FEA nominal gives the same verdict, see the module's report)."""
    nom = quilt_sag_map(0.6, "sum", spacing_mm=0.5)
    paths = sorted(SCEN.glob("*/manifest.toml"))
    assert len(paths) >= 3
    for path in paths:
        man = load_manifest(path)
        assert measurement_problems(man, load_data(man), nom) == [], path.parent.name


# --- helpers, rules, campaign size -------------------------------------------------------


def test_at_prior_bound():
    bounds = {"scale_J": (0.3, 3.0), "astig_0_um": (-1.0, 1.0)}
    assert at_prior_bound({"scale_J": 0.3, "astig_0_um": 0.2}, bounds) == ("scale_J",)
    assert at_prior_bound({"scale_J": 2.9999, "astig_0_um": -0.9999}, bounds) == ("scale_J", "astig_0_um")
    assert at_prior_bound({"scale_J": 1.2, "other": 5.0}, bounds) == ()
    assert at_prior_bound({"scale_J": 0.31}, bounds, rel_tol=0.01) == ("scale_J",)
    with pytest.raises(ValueError, match="rel_tol=0.6 must be in"):
        at_prior_bound({}, bounds, rel_tol=0.6)


def test_unit_hint():
    assert unit_hint(3.1) == "wrong unit (nm)?" and unit_hint(-2.9) == "wrong unit (mm)?"
    assert unit_hint(-6.0) == "wrong unit (m)?" and unit_hint(2.0) == "wrong unit?"


@pytest.mark.parametrize("kw, fragment", [({"width_range": (2.0, 5.0)}, "width_range"),
                                          ({"min_peak_sigma": 0}, "min_peak_sigma=0"),
                                          ({"span_range": (5.0, 1.0)}, "span_range")])
def test_rules_checked(kw, fragment):
    with pytest.raises(ValueError, match=fragment):
        Plausibility(**kw)


@pytest.mark.parametrize("n", [0, -3])
def test_campaign_size_at_least_one(n, tmp_path, capsys):
    with pytest.raises(ValueError, match=f"n_cases={n} must be an integer in the valid range 1\\.\\."):
        CampaignConfig(n_cases=n)
    assert main(["diagnose", "--validate", f"--cases={n}", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and f"--cases {n}" in err


@pytest.mark.parametrize("offset_um, height", [(54.0, 1.2), (-36.0, 1.5)])
def test_a_hot_pixel_taller_than_the_line_is_data_not_a_refusal(offset_um, height):
    """A profile sampled every 3 µm with one hot sample (1.2-1.5x the line's peak, in the
    wing): the raw FWHM is one sample (implausible), the 3-sample running median
    holds the 40 µm line; the spike is named, non-fatal. Without the line the same spike
    on noise is still refused (no line in the running median)."""
    x = np.arange(-180.0, 180.01, 3.0)
    rng = np.random.default_rng(21)
    y = _gauss(x, 40.0, rng)
    i = int(np.argmin(np.abs(x - offset_um)))
    y[i] += height
    assert line_fwhm(x, y) < 6.0
    (p,) = profile_problems("p", x, y, nominal_fwhm_um=40.0)
    assert p.code == "spike" and not p.fatal
    assert f"at offsets {x[i]:.1f} µm" in p.message and "hot pixel" in p.message
    flat = 0.02 + rng.normal(0, 0.01, x.size)
    flat[i] += height
    (q,) = profile_problems("p", x, flat, nominal_fwhm_um=40.0)
    assert q.fatal and q.code in ("no_line", "width")
