"""What the diagnosis reads, what it says it read, and where it asks instead of guessing:
a map counted from a corner, a profile sampled once per detector pixel. Every file is
written here by numpy from analytic shapes (no project forward model makes the data)."""

from __future__ import annotations

import re

import numpy as np
import pytest

from optics.sagmap import quilt_sag_map
from pipeline.diagnosis.forward import NOISE_LEAK_LIMIT, ProfileForward
from pipeline.diagnosis.manifest import load_data, parse_manifest, read_summary


def quilt_um(x, y):
    return 0.05 * np.cos(2 * np.pi * x / 21.0) * np.cos(2 * np.pi * y / 18.0) + 0.02 * (x * y) / 68.0**2


def _map_csv(path, x0_mm, y0_mm):
    """Points of a 1 mm grid inside a 136 mm circle about (x0, y0), the sag a function of
    the blank's coordinates (x - x0, y - y0)."""
    g = np.arange(-68.0, 68.5, 1.0)
    X, Y = np.meshgrid(g, g)
    inside = X**2 + Y**2 <= 68.0**2
    x, y = X[inside], Y[inside]
    np.savetxt(path, np.column_stack([x + x0_mm, y + y0_mm, quilt_um(x, y)]), delimiter=",",
               header="x_mm,y_mm,sag_um", comments="", fmt="%.6f")
    return path, int(inside.sum())


def _surface(path, **extra):
    return parse_manifest({"measurement": [{"kind": "surface", "file": str(path), "temperature_K": 128,
                                            "aperture_diameter_mm": 136, **extra}]})


def test_a_map_counted_from_a_corner_needs_its_centre(tmp_path):
    """An export whose coordinates run 0..136 mm would be read mostly off the blank: it is
    refused with the centre to give, and read as the centred map once it is given."""
    f, n = _map_csv(tmp_path / "corner.csv", 68.0, 68.0)
    with pytest.raises(ValueError, match=r"measurement 'corner': centre_mm=None puts the blank off the map: with no "
                                         r"centre_mm, only (\d+) of the \d+ valid points of corner.csv fall inside "
                                         r".*centred at x 68.0, y 68.0 mm.*centre_mm = \[68.0, 68.0\]") as exc:
        load_data(_surface(f))
    # inside: the lens where two 68 mm discs 96.2 mm apart overlap, at one point per mm^2
    r, dist = 68.0, 68.0 * np.sqrt(2.0)
    lens = 2 * r**2 * np.arccos(dist / (2 * r)) - 0.5 * dist * np.sqrt(4 * r**2 - dist**2)
    assert int(re.search(r"only (\d+) of", str(exc.value)).group(1)) == pytest.approx(lens, rel=0.02)
    (d,) = load_data(_surface(f, centre_mm=[68.0, 68.0]))
    assert d.sag_um.size == n
    assert np.abs(d.x_mm).max() <= 68.0 and np.abs(d.y_mm).max() <= 68.0
    np.testing.assert_allclose(d.sag_um, quilt_um(d.x_mm, d.y_mm), atol=5e-7)  # printed to 1e-6 µm
    r = read_summary(d)
    assert r["points_used"] == n and r["x_range_mm"] == [-68.0, 68.0] and "(68, 68) subtracted" in r["centre_mm"]
    s = quilt_um(d.x_mm, d.y_mm)
    assert r["pv_um"] == pytest.approx(s.max() - s.min(), rel=1e-3)


def test_the_extent_read_is_the_valid_datas_not_the_grids(tmp_path):
    """A map in a 140 mm grid with NaN outside a 137 mm aperture reads the valid data's extent,
    as a list of valid points does (an outside lab saw -69.93..69.93 for one, ±68.5 for the other)."""
    g = np.arange(-69.93, 69.94, 0.37)
    X, Y = np.meshgrid(g, g)
    z = np.where(X**2 + Y**2 <= 68.5**2, 0.2 * np.cos(2 * np.pi * X / 21.0), np.nan)
    f = tmp_path / "padded.csv"
    f.write_text("x_mm,y_mm,sag_um\n" + "".join(f"{a:.2f},{b:.2f},{c:.6f}\n" for a, b, c in
                                                zip(X.ravel(), Y.ravel(), z.ravel())))
    (d,) = load_data(_surface(f))
    r = read_summary(d)
    inside = g[np.abs(g) <= 68.5]
    assert r["x_range_mm"] == pytest.approx([inside.min(), inside.max()], abs=1e-6)
    assert r["y_range_mm"] == pytest.approx([inside.min(), inside.max()], abs=1e-6)


def test_a_map_off_centre_within_registration_reach_is_read(tmp_path):
    """8 mm off: within the registration effect's ±10 mm, so it is data, not a refusal."""
    f, n = _map_csv(tmp_path / "off.csv", 8.0, -3.0)
    (d,) = load_data(_surface(f, aperture_diameter_mm=160))  # 68 + 8.6 mm < 80
    assert d.sag_um.size == n and "centre_mm" not in read_summary(d)


@pytest.mark.parametrize("value, pattern", [([1000.0, 0.0], r"centre_mm=\[1000.0, 0.0\] must be \[x0, y0\] with "
                                                             r"\|x0\|, \|y0\| <= 300 mm"),
                                            (5.0, r"centre_mm=5.0 must be a list of 2 numbers")])
def test_a_bad_centre_is_refused_by_name(tmp_path, value, pattern):
    f, _ = _map_csv(tmp_path / "m.csv", 0.0, 0.0)
    with pytest.raises(ValueError, match=pattern):
        _surface(f, centre_mm=value)


def test_a_manifest_path_given_to_parse_manifest_is_named():
    with pytest.raises(TypeError, match=r"parse_manifest: data='m.toml' must be a dict.*load_manifest\(path\)"):
        parse_manifest("m.toml")


def _double_line(u):
    """A quilted line's two peaks (26 µm apart) and its satellites, unit peak."""
    g = lambda mu, s: np.exp(-0.5 * ((u - mu) / s) ** 2)  # noqa: E731
    return g(-13, 10.5) + 0.92 * g(13, 10.5) + 0.08 * g(-45, 12) + 0.07 * g(45, 12)


def _profile_forward(tmp_path, step_um, sigma_rel, seed):
    rng = np.random.default_rng(seed)
    u = np.arange(-90.0, 160.0, step_um) + 0.37 * step_um
    counts = 500.0 + 20000.0 * _double_line(u - 35.0) + 20000.0 * sigma_rel * rng.normal(size=u.size)
    f = tmp_path / f"p{step_um:g}.csv"
    np.savetxt(f, np.column_stack([u, counts]), delimiter=",", header="offset_um,intensity", comments="", fmt="%.4f")
    (pd,) = load_data(parse_manifest({"measurement": [{"kind": "line_profile", "file": str(f), "grating": "J",
                                                       "wavelength_um": 1.25, "pixel_scale_mas": 250}]}))
    fw = ProfileForward(pd, quilt_sag_map(0.6, "sum", spacing_mm=1.0), 80.0)
    return pd, fw, fw.residual({}, fw.delta0_um)


def test_a_profile_sampled_once_per_pixel_asks_for_its_noise(tmp_path):
    """At one sample per 18 µm pixel the neighbour-prediction estimate reads the line's
    structure as noise (here ~50x the true 0.002 of the peak): refused, naming noise_rel and
    noise_counts."""
    pd, fw, r = _profile_forward(tmp_path, 18.0, 0.002, 1)
    with pytest.raises(ValueError, match=r"measurement 'p18': noise_rel is required: its 14 samples \(18 µm apart\) "
                                         r"are too coarse.*valid 1e-06..1\) in its \[\[measurement\]\], or "
                                         r"noise_counts = the same in the file's intensity units; the \d+ samples "
                                         r"where the nominal line is below 5 % of its peak scatter"):
        fw.estimate_noise(r)
    assert pd.origin_um == pytest.approx(35.0, abs=3.0)  # the line's centre, moved to the model's origin


def test_a_densely_sampled_profile_gives_its_noise(tmp_path):
    """The same line at 1 µm steps: the estimate is the noise written (250 samples:
    relative sd ~1.7 / sqrt(250) = 0.11 of the estimator, so within 35 %), and the
    nominal's leakage is far below the limit."""
    pd, fw, r = _profile_forward(tmp_path, 1.0, 0.002, 2)
    peak = 20000.0 * _double_line(np.array([-13.0]))[0]
    sigma = fw.estimate_noise(r)
    assert sigma == pytest.approx(0.002 * 20000.0 / peak, rel=0.35)
    rd = read_summary(pd)
    assert rd["samples"] == pd.offset_um.size and rd["step_um"] == pytest.approx(1.0)
    # the half-maximum centre of two nearly equal peaks about 35 µm
    assert rd["line_centre_um"] == pytest.approx(35.0, abs=2.0)
    assert rd["shift_applied_um"] == pytest.approx(pd.origin_um)
    assert NOISE_LEAK_LIMIT < 1.0


def test_the_help_shows_a_manifest_whose_keys_are_the_readers():
    """`cryograting diagnose --help` carries the manifest layout; every key it shows is one
    the manifest parser accepts (the help cannot drift from the parser unnoticed)."""

    from pipeline.diagnosis.cli import HELP_DESCRIPTION
    from pipeline.diagnosis.manifest import MEASUREMENT_KEYS, SIMULATION_KEYS

    keys = set(re.findall(r"^\s*#?\s*([a-z_A-Z0-9]+) = ", HELP_DESCRIPTION, flags=re.M))
    accepted = set(SIMULATION_KEYS).union(*MEASUREMENT_KEYS.values())
    assert {"centre_mm", "noise_rel", "noise_um", "pixel_scale_mas", "temperature_K"} <= keys
    assert keys <= accepted, sorted(keys - accepted)


def test_the_verdict_is_said_in_words_with_the_reason():
    """Each test a finding fails is named with its number and threshold."""
    from types import SimpleNamespace

    from pipeline.diagnosis.criteria import Criteria
    from pipeline.diagnosis.finding import Finding
    from pipeline.diagnosis.report import verdict_text
    from pipeline.diagnosis.wings import WINGS_LABEL

    def diag(verdict, f, unexplained_in=()):
        return SimpleNamespace(verdict=verdict, best=f, criteria=Criteria(), unexplained_in=unexplained_in,
                               parts_alone=())

    weak = Finding("slit_width", ("slit_width",), {}, {}, 0.0, -6.1, 1.0, 0.8, 0.2, 0.36, excess_explained=0.35)
    assert verdict_text(diag("unexplained", weak)) == (
        "No library effect explains the gap. The nearest candidate, slit_width, is not the explanation: it is not "
        "significant (ΔBIC -6.1; a finding needs ≤ −10); it takes up only 35% of the residual beyond noise (needs 50%).")
    pinned = Finding("amplitude_scale", ("amplitude_scale",), {"scale_J": 0.3}, {}, 0.0, -400.0, 1.0, 0.4, 0.6, 0.8,
                     excess_explained=0.7, significant=True, at_bound=("scale_J",), degenerate_with=(WINGS_LABEL,))
    t = verdict_text(diag("unexplained", pinned))
    assert "scale_J ended at the bound of its prior range" in t and "fits as well: the detector side" in t
    beside = Finding("amplitude_scale", ("amplitude_scale",), {"scale_J": 1.08}, {}, 0.0, -220.0, 1.0, 0.4, 0.6, 0.8,
                     excess_explained=0.85, significant=True, needs_outside=(WINGS_LABEL,))
    assert "part of the gap, and the data need something outside the library beside it: the detector side" \
        in verdict_text(diag("unexplained", beside))
    good = Finding("temperature", ("temperature",), {}, {}, 0.0, -250.0, 1.0, 0.3, 0.7, 0.9, excess_explained=0.92,
                   significant=True, heldout_shrink_fraction=0.61)
    assert verdict_text(diag("explained", good)) == ("temperature explains the gap: it lowers the BIC by 250 and takes "
                                                     "up 92% of the residual beyond noise, and fitted on part of the "
                                                     "data it shrinks the rest by 61%.")
    # a finding that takes up most of the gap says where the rest is (an outside lab's profiles
    # broadened by a box were called explained by a collimator error, two of three still beyond noise)
    rest = [{"measurement": "J_100mas", "rms_ratio": 2.737, "z": 10.87, "noise_rel_sd": 0.3}]
    assert verdict_text(diag("explained", good, rest)).endswith(
        "shrinks the rest by 61%. Part of the gap remains beyond noise after it, in J_100mas (2.7 × noise, "
        "χ² excess 10.9 σ).")
    assert "no gap" in verdict_text(diag("no_gap", None))


def test_an_untestable_fold_says_why_in_words():
    from pipeline.diagnosis.heldout import untestable_reason

    assert untestable_reason(0.0, 0.0) == "the training part's fit predicts no change on the withheld part"
    assert untestable_reason(0.01, float("inf")) == "a parameter is left free within its prior by the training part"
    assert untestable_reason(0.01, 0.02) == "the training part predicts the withheld change 0.01 only to ±0.02"


def test_a_centre_from_the_wrong_corner_is_refused_with_the_right_one(tmp_path):
    """A map whose blank centre is at (68, 68) in its own coordinates, given centre_mm from
    another corner: most of it would fall off the blank, so it is refused with the centre
    that puts it back."""
    f, _ = _map_csv(tmp_path / "corner.csv", 68.0, 68.0)
    with pytest.raises(ValueError, match=r"centre_mm=\[0.0, 136.0\] puts the blank off the map: with centre_mm = "
                                         r"\[0, 136\], only \d+ of the \d+ valid points.*give centre_mm = \[68.0, 68.0\]"):
        load_data(_surface(f, centre_mm=[0.0, 136.0]))


def test_a_map_with_heights_along_minus_z_is_read_with_sag_sign(tmp_path):
    f, _ = _map_csv(tmp_path / "m.csv", 0.0, 0.0)
    (d,) = load_data(_surface(f, sag_sign=-1))
    np.testing.assert_allclose(d.sag_um, -quilt_um(d.x_mm, d.y_mm), atol=5e-7)
    with pytest.raises(ValueError, match=r"sag_sign=2 must be 1 or -1"):
        _surface(f, sag_sign=2)


def test_a_map_reversed_or_turned_by_90_degrees_is_named_with_its_remedy():
    """The nominal here is the analytic quilt (21 x 18 mm pitches). Reversed heights and a
    +90° turn are named with the reading that undoes them; the map as it should be, with
    noise, passes; applying the named remedy makes the turned map pass."""
    from pipeline.diagnosis.plausibility import orientation_problems

    rng = np.random.default_rng(3)
    g = np.arange(-68.0, 68.5, 1.0)
    X, Y = np.meshgrid(g, g)
    ok = X**2 + Y**2 <= 68.0**2
    x, y = X[ok], Y[ok]
    noise = 0.002 * rng.normal(size=x.size)
    assert orientation_problems("m", x, y, quilt_um(x, y) + noise, quilt_um) == []
    (p,) = orientation_problems("m", x, y, -quilt_um(x, y) + noise, quilt_um)
    assert p.fatal and "with its heights reversed" in p.message and "sag_sign = -1" in p.message
    turned = quilt_um(y, -x) + noise  # the blank turned by +90°: map point p shows blank point R(-90) p
    (p,) = orientation_problems("m", x, y, turned, quilt_um)
    assert "turned by +90°" in p.message and "x_new = y, y_new = -x" in p.message
    assert orientation_problems("m", y, -x, turned, quilt_um) == []  # read as the message says


def test_a_profile_with_photon_noise_gets_its_mean_noise():
    """An arc line's variance grows with its counts: the noise the gap test compares an
    unweighted residual with is the RMS over the samples, sqrt(mean(var)). Written here
    with Poisson counts (peak 2e4, background 300, read 10) at 2000 random offsets: the
    estimate is within 4 of its relative sd (3.2 / sqrt(n) = 0.072) of the truth, where the
    wings' white scatter reads half of it; white noise still gives its sigma."""
    from pipeline.diagnosis.noise import (SIGNAL_DEPENDENT_NOISE_REL_SD_SQRT_N, estimate_noise,
                                          estimate_noise_signal_dependent)

    rng = np.random.default_rng(11)
    n = 2000
    u = np.sort(rng.uniform(-130.0, 130.0, n))
    shape = _double_line(u) / _double_line(np.array([-13.0]))[0]
    peak, bg, read = 2e4, 300.0, 10.0
    counts = rng.poisson(peak * shape + bg) + rng.normal(0.0, read, n) - bg
    truth = np.sqrt(np.mean(peak * shape + bg + read**2)) / peak
    tol = 4 * SIGNAL_DEPENDENT_NOISE_REL_SD_SQRT_N / np.sqrt(n)
    assert estimate_noise_signal_dependent(u, counts / peak) == pytest.approx(truth, rel=tol)
    assert estimate_noise(u, counts / peak) < 0.7 * truth  # the wings' scatter misses the line's
    white = shape + rng.normal(0.0, 0.003, n)
    assert estimate_noise_signal_dependent(u, white) == pytest.approx(0.003, rel=tol)


def test_the_explained_excess_is_counted_per_measurement():
    """Two profiles with stated noise (so the noise is not discounted): one with a residual
    four times its noise (chi^2_red 4), one whose stated noise is too large (chi^2_red 0.4).
    A fit that brings the first to its noise explains all of its excess (3 units of noise
    variance per sample); the second neither cancels that excess nor adds to it."""
    from types import SimpleNamespace

    from pipeline.diagnosis.fitting import FitOutcome, Problem
    from pipeline.diagnosis.gap import excess_explained

    def fw(name):
        return SimpleNamespace(name=name, kind="line_profile", n=103, noise_known=0.01, nuisance_count=2, n_shift=1,
                               correlated_noise=None)

    prob = Problem([fw("a"), fw("b")], weights={"a": 1.0, "b": 1.0}, noise={"a": 0.01, "b": 0.01})
    n = {"a": 103, "b": 103}  # 100 degrees of freedom each after 3 nuisances

    def outcome(rss):
        return FitOutcome({}, {}, {}, rss, n, n, 0, True, 0, 0.0)

    nominal = outcome({"a": 4 * 100 * 1e-4, "b": 0.4 * 100 * 1e-4})
    assert excess_explained(prob, nominal, outcome({"a": 1 * 100 * 1e-4, "b": 0.4 * 100 * 1e-4})) == 1.0
    assert excess_explained(prob, nominal, outcome({"a": 2.5 * 100 * 1e-4, "b": 0.1 * 100 * 1e-4})) == pytest.approx(0.5)


def _counts_profile(tmp_path, **extra):
    """A Gaussian line of 5000 counts above a 300-count pedestal at 1 µm steps over +-100 µm
    (over half the samples at the pedestal), read through a manifest with ``extra``."""
    u = np.arange(-100.0, 100.5, 1.0)
    f = tmp_path / "counts.csv"
    np.savetxt(f, np.column_stack([u, 300.0 + 5000.0 * np.exp(-0.5 * (u / 12.0) ** 2)]), delimiter=",",
               header="offset_um,counts", comments="", fmt="%.4f")
    return parse_manifest({"measurement": [{"kind": "line_profile", "file": str(f), "grating": "J",
                                            "wavelength_um": 1.25, "pixel_scale_mas": 250, **extra}]})


def test_a_noise_in_counts_is_a_fraction_of_the_lines_peak(tmp_path):
    """25 counts of noise on a line 5000 counts above its pedestal: 0.005 of the peak, what
    the profile's model is weighted by."""
    (pd,) = load_data(_counts_profile(tmp_path, noise_counts=25.0))
    assert pd.measurement.noise_rel == pytest.approx(0.005, rel=1e-9)
    fw = ProfileForward(pd, quilt_sag_map(0.6, "sum", spacing_mm=1.0), 80.0)
    assert fw.noise_known == pytest.approx(0.005, rel=1e-9)


def test_an_images_noise_in_counts_is_a_fraction_of_its_peak_above_the_pedestal(tmp_path):
    """A 2-D Gaussian spot (numpy, no project model) 4000 counts above a 300-count pedestal,
    window reaching the pedestal: 20 counts of noise are 0.005 of the peak."""
    from pipeline.io.measured import write_psf_image_csv

    g = np.arange(-60.0, 60.5, 2.0)
    X, Y = np.meshgrid(g, g)
    write_psf_image_csv(tmp_path / "spot.csv", X.ravel(), Y.ravel(),
                        300.0 + 4000.0 * np.exp(-0.5 * (X.ravel() ** 2 + Y.ravel() ** 2) / 5.0**2))
    (d,) = load_data(parse_manifest({"measurement": [{"kind": "psf_image", "file": str(tmp_path / "spot.csv"),
                                                      "grating": "J", "order": -2, "wavelength_um": 1.25,
                                                      "pixel_um": 18, "noise_counts": 20.0}]}))
    assert d.measurement.noise_rel == pytest.approx(0.005, rel=1e-9)


@pytest.mark.parametrize("extra, pattern", [
    ({"noise_counts": 25.0, "noise_rel": 0.005}, r"noise_counts=25.*and noise_rel = 0.005 are both given"),
    ({"noise_counts": -3.0}, r"noise_counts=-3.*must be a finite number > 0"),
    ({"noise_counts": 6000.0}, r"noise_counts=6000.*is 1.2 of the line's peak above background \(5000 in the "
                               r"file's units\), outside the valid range \[1e-06, 1\]"),
])
def test_a_noise_in_counts_that_cannot_be_used_is_refused_by_name(tmp_path, extra, pattern):
    with pytest.raises(ValueError, match=pattern):
        load_data(_counts_profile(tmp_path, **extra))


def test_a_psf_images_noise_in_counts_matches_its_residual_where_the_files_maximum_does_not(tmp_path):
    """A J PSF image of 18 µm pixels cut at +-30 µm (the image model's nominal; its floor is
    the PSF's own wing, 0.45 of the peak above the true background), noise of 45 counts
    written here on a 9100-count peak: with ``noise_counts = 45`` the nominal fit's residual RMS is the stated noise
    (ratio 1 +- 3 sd of a 961-sample RMS, 0.07); the same noise stated by hand from the
    file's maximum (``noise_rel = 45 / max``) is 1.8x too small."""
    from scipy.interpolate import RectBivariateSpline
    from scipy.optimize import minimize

    from pipeline.diagnosis.psf_image import PsfImageForward, psf_image_model
    from pipeline.io.measured import write_psf_image_csv

    nominal = quilt_sag_map(0.6, "sum", spacing_mm=0.5)
    ux, uy, img = psf_image_model("J", 1.25, -2, nominal, {}, 18.0)
    g = np.arange(-30.0, 30.001, 2.0)
    X, Y = np.meshgrid(g, g)
    v = RectBivariateSpline(uy, ux, img).ev(Y.ravel() - 1.0, X.ravel() + 2.0)
    counts = 50.0 + 9100.0 * v / v.max()
    counts += np.random.default_rng(3).normal(0.0, 45.0, counts.size)
    write_psf_image_csv(tmp_path / "psf.csv", X.ravel(), Y.ravel(), counts)
    ratio = {}
    for key, value in (("noise_counts", 45.0), ("noise_rel", 45.0 / counts.max())):
        (data,) = load_data(parse_manifest({"measurement": [{"kind": "psf_image", "file": str(tmp_path / "psf.csv"),
                                                             "grating": "J", "order": -2, "wavelength_um": 1.25,
                                                             "pixel_um": 18, key: value}]}))
        f = PsfImageForward(data, nominal, 80.0)
        best = minimize(lambda s: float(np.sum(f.residual({}, tuple(s)) ** 2)), np.asarray(f.delta0_um, float),
                        method="Nelder-Mead", options={"xatol": 1e-3, "fatol": 1e-12})
        r = f.residual({}, tuple(best.x))
        ratio[key] = float(np.sqrt(np.sum(r**2) / (r.size - 4))) / f.noise_known
    assert ratio["noise_counts"] == pytest.approx(1.0, abs=0.07), ratio
    assert ratio["noise_rel"] > 1.5, ratio


def test_a_fold_whose_training_fit_ends_at_a_prior_bound_does_not_count(monkeypatch):
    """The prior, not the training part, set a parameter left at its bound: such a fold says so
    and is not scored (a plating gradient fitted on profiles alone went to both bounds and
    'predicted' the withheld map)."""
    from types import SimpleNamespace

    from pipeline.diagnosis import heldout
    from pipeline.diagnosis.finding import Finding
    from pipeline.diagnosis.fitting import FitOutcome, Problem

    def fw(name, kind):
        return SimpleNamespace(name=name, kind=kind, n=50, blank="J")

    prob = Problem([fw("p", "line_profile"), fw("map", "surface")], weights={"p": 1.0, "map": 1.0})
    finding = Finding("plating_gradient", ("plating_gradient",), {}, {}, 0.0, -20.0, 1.0, 0.5, 0.5, 0.75)
    at_bounds = {"plating_grad_x": -0.1, "plating_grad_y": 0.1}
    monkeypatch.setattr(heldout, "fit", lambda *a, **k: FitOutcome(at_bounds, {n: 0.01 for n in at_bounds}, {}, {}, {},
                                                                     {}, 2, True, 1, 0.0))
    h, note = heldout.heldout_check(prob, finding, None)
    assert h is None
    assert note.count("untestable (the training part leaves plating_grad_x, plating_grad_y at a bound") == 2, note


def test_a_fold_that_withholds_what_the_finding_cannot_change_does_not_count(monkeypatch):
    """A pupil shift does not change a surface map: the fold "others -> map" could carry only
    its bow companion's reading, so it is reported untestable and not fitted; the profile
    folds are tested as before."""
    from types import SimpleNamespace

    from pipeline.diagnosis import heldout
    from pipeline.diagnosis.finding import Finding
    from pipeline.diagnosis.fitting import FitOutcome, Problem

    def fw(name, kind):
        return SimpleNamespace(name=name, kind=kind, n=50, blank="J")

    prob = Problem([fw("p1", "line_profile"), fw("p2", "line_profile"), fw("map", "surface")],
                   weights={"p1": 1.0, "p2": 1.0, "map": 1.0})
    finding = Finding("pupil_shift", ("pupil_shift",), {}, {}, 0.0, -20.0, 1.0, 0.5, 0.5, 0.75,
                      companions=("blank_bow",))
    trained = []

    def fake_fit(prob, params, masks=None, **k):
        trained.append(masks)
        return FitOutcome({"pupil_x_mm": 1.0, "pupil_y_mm": 0.5, "bow_defocus_um": 0.01, "bow_spherical_um": 0.0},
                          {}, {}, {}, {}, {}, 4, True, 1, 0.0)

    monkeypatch.setattr(heldout, "fit", fake_fit)
    monkeypatch.setattr(heldout, "_prediction_spread", lambda *a: (1.0, 0.1))
    _, note = heldout.heldout_check(prob, finding, None)
    assert "others -> map: untestable (the finding's own effects do not change the withheld part)" in note, note
    assert "others -> p1: shrink" in note and "others -> p2: shrink" in note, note
    assert not any(set(m) == {"map"} for m in trained if m), "the map fold was fitted"  # train masks: what is left out
    assert any(set(m) == {"p1"} for m in trained if m)


def test_each_parts_own_reading_is_said_with_its_distance_from_the_joint_value():
    """The finding's own parameter always, a companion only where a part pulls it 2 sigma or
    more from the joint value; a part's remaining gap by measurement."""
    from types import SimpleNamespace

    from pipeline.diagnosis.alone import PartFit
    from pipeline.diagnosis.finding import Finding
    from pipeline.diagnosis.report import alone_text

    best = Finding("amplitude_scale", ("amplitude_scale",), {"scale_J": 1.153, "quilt_cross_ratio": 1.01}, {}, 0.0,
                   -263.0, 1.0, 0.1, 0.9, 0.99, companions=("quilt_shape",))
    parts = (PartFit("surface maps", ("map_J",), {"scale_J": 1.1998, "quilt_cross_ratio": 1.0}, {"scale_J": 0.036,
                     "quilt_cross_ratio": 0.08}, {"scale_J": 1.29, "quilt_cross_ratio": -0.13}, ()),
             PartFit("line profiles", ("a", "b"), {"scale_J": 1.1494, "quilt_cross_ratio": 0.9}, {"scale_J": 0.0025,
                     "quilt_cross_ratio": 0.01}, {"scale_J": -1.48, "quilt_cross_ratio": -11.0},
                     ({"measurement": "a", "rms_ratio": 1.31, "z": 3.0},)))
    t = alone_text(SimpleNamespace(best=best, parts_alone=parts))
    assert t == ("Fitted to each part alone, surface maps alone read scale_J = 1.2 ± 0.036, 1.3 σ from the joint "
                 "value; it leaves no gap; line profiles alone read scale_J = 1.149 ± 0.0025, 1.5 σ from the joint "
                 "value, quilt_cross_ratio = 0.9 ± 0.01, 11.0 σ from the joint value; it leaves a at 1.31 × noise."), t
    assert alone_text(SimpleNamespace(best=best, parts_alone=())) == ""
    # a part none of the finding's own parameters acts on (a map beside a pupil shift)
    pupil = Finding("pupil_shift", ("pupil_shift",), {"pupil_x_mm": 3.3}, {}, 0.0, -182.0, 1.0, 0.5, 0.5, 0.75)
    part = PartFit("surface maps", ("map",), {}, {}, {}, ({"measurement": "map", "rms_ratio": 1.86, "z": 40.0},))
    assert alone_text(SimpleNamespace(best=pupil, parts_alone=(part,))) == (
        "Fitted to each part alone, surface maps alone hold none of the finding's own parameters; it leaves map at "
        "1.86 × noise."), alone_text(SimpleNamespace(best=pupil, parts_alone=(part,)))
