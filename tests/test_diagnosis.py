"""Fast tests of pipeline.diagnosis: manifest errors, exact degeneracy, astigmatism and
registration recovery, out-of-library coma -> unexplained, JSON/CLI. Nominal map: the
analytic sum quilt (no FEA), truth: a different quilt form mixture + noise."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from optics.zernike import zernike_xy
from pipeline.diagnosis import diagnose
from pipeline.diagnosis.cli import main
from pipeline.diagnosis.noise import effective_samples, estimate_noise
from pipeline.diagnosis.nominal import thermal_factor
from pipeline.diagnosis.synth import synthetic_surface
from pipeline.io.measured import write_line_profile_csv
from pipeline.io.registry import write_sag_map

from diagnosis_cases import FakeDiagnosis, FakeFinding, nominal_map, other_quilt_truth, surface_case, surface_manifest


def test_noise_estimate_white_noise():
    rng = np.random.default_rng(3)
    x = np.sort(rng.uniform(0, 100, 400))
    y = np.sin(x / 7.0) + rng.normal(0, 0.02, x.size)
    assert estimate_noise(x, y) == pytest.approx(0.02, rel=0.15)
    assert effective_samples(rng.normal(size=400), x) > 200
    assert effective_samples(np.sin(x / 15.0), x) < 40


def test_astigmatism_recovered_and_explained(tmp_path):
    c45 = 0.08
    p = surface_case(tmp_path, lambda x, y: c45 * zernike_xy(2, -2, x, y, 68.5))
    d = diagnose(p)
    assert d.verdict == "explained"
    assert d.best.effect == "astigmatism"
    assert d.best.parameters["astig_45_um"] == pytest.approx(c45, rel=0.1)
    assert abs(d.best.parameters["astig_0_um"]) < 3 * d.best.uncertainties["astig_0_um"] + 0.01
    assert d.best.heldout_shrink_fraction > 0.5 and not d.best.overfit
    # the verdict's measure: share of the gap beyond noise, never below the plain variance share
    assert d.best.variance_explained <= d.best.excess_explained <= 1.0
    assert "astig_45_um" not in d.best.sign_degenerate  # a map fixes the sign of an astigmatism
    basis = {w["component"]: w["share"] for w in d.where if w["decomposition"] == "basis"}
    assert basis["astigmatism"] > 0.8


def test_amplitude_and_temperature_are_degenerate_on_one_map(tmp_path):
    # 0.7 x is reachable by a warmer map (~175 K); 1.4 x would not be (eps_m saturates when cold)
    d = diagnose(surface_case(tmp_path, scale=0.7))
    assert d.verdict == "explained"
    assert {d.findings[0].effect, d.findings[1].effect} == {"amplitude_scale", "temperature"}
    assert d.best.degenerate_with == ("temperature",) or d.best.degenerate_with == ("amplitude_scale",)
    assert d.finding("amplitude_scale").parameters["scale_spare"] == pytest.approx(0.7 * 0.9, rel=0.1)
    assert d.finding("amplitude_scale+temperature") is None  # the redundant pair is not fitted


def test_registration_recovered(tmp_path):
    nom = nominal_map(tmp_path)
    t = other_quilt_truth(nom).scaled(thermal_factor(128, 80))
    X, Y = t.grid()
    t = t.with_sag(t.sample(X - 3.0, Y + 2.0))  # model feature at p appears at p + (3, -2)
    write_sag_map(synthetic_surface(t, np.random.default_rng(1)), tmp_path / "map.npz")
    d = diagnose(surface_manifest(tmp_path))
    assert d.verdict == "explained" and d.best.effect == "registration"
    assert d.best.parameters["reg_dx_mm"] == pytest.approx(3.0, abs=0.3)
    assert d.best.parameters["reg_dy_mm"] == pytest.approx(-2.0, abs=0.3)


def test_out_of_library_coma_is_unexplained(tmp_path):
    p = surface_case(tmp_path, lambda x, y: 0.1 * zernike_xy(3, 1, x, y, 68.5), seed=2)
    d = diagnose(p)
    assert d.verdict == "unexplained"
    after = {w["component"]: w["share"] for w in d.where_after if w["decomposition"] == "basis"}
    assert after["coma"] > 0.5  # the structure left over is shown


def test_no_gap_when_model_matches(tmp_path):
    nom = nominal_map(tmp_path)
    m = synthetic_surface(nom.scaled(thermal_factor(128, 80)), np.random.default_rng(4), noise_um=0.01)
    write_sag_map(m, tmp_path / "map.npz")
    assert diagnose(surface_manifest(tmp_path)).verdict == "no_gap"


def test_weak_gap_over_many_samples_is_a_gap(tmp_path):
    """A 0.006 µm RMS astigmatism under 0.01 µm noise: the residual RMS is only 1.18x the
    noise (below ``no_gap_ratio``), but over the 14 333 samples of the map its chi^2 excess
    is 13 standard deviations — a gap, diagnosed as the astigmatism it is (0.0062 µm)."""
    from optics.zernike import zernike_xy
    from pipeline.diagnosis.engine import Criteria, build_problem, has_gap
    from pipeline.diagnosis.manifest import load_data, load_manifest

    nom = nominal_map(tmp_path)
    rng = np.random.default_rng(4)
    m = synthetic_surface(nom.scaled(thermal_factor(128, 80)), rng, noise_um=0.01,
                          extra_um=lambda x, y: 0.006 * zernike_xy(2, 2, x, y, 68.5))
    write_sag_map(m, tmp_path / "map.npz")
    man = load_manifest(surface_manifest(tmp_path))
    prob, nom_fit = build_problem(man, load_data(man), nom)
    (name,) = prob.noise
    assert 1.1 < np.sqrt(nom_fit.rss[name] / nom_fit.n[name]) / prob.noise[name] < Criteria().no_gap_ratio
    assert has_gap(prob, nom_fit, Criteria()) and not has_gap(prob, nom_fit, Criteria(no_gap_z=np.inf))
    d = diagnose(man, nominal=nom)
    assert d.verdict == "explained" and d.best.effect == "astigmatism"
    assert d.best.parameters["astig_0_um"] == pytest.approx(0.006, rel=0.2)


@pytest.mark.parametrize("edit, fragment", [
    (lambda t: t.replace('file = "map.npz"', 'file = "missing.npz"'), "file='missing.npz' does not exist"),
    (lambda t: t.replace("temperature_K = 128", "temperature_K = 400"), "temperature_K=400"),
    (lambda t: t.replace("aperture_diameter_mm = 137", "aperture_diameter_mm = 0.5"), "aperture_diameter_mm"),
    (lambda t: t.replace('kind = "surface"', 'kind = "interferogram"'), "kind='interferogram'"),
])
def test_bad_surface_manifest(tmp_path, edit, fragment):
    p = surface_case(tmp_path)
    p.write_text(edit(p.read_text()))
    with pytest.raises(ValueError) as e:
        diagnose(p)
    assert "measurement '" in str(e.value) and fragment in str(e.value)


def _profile_manifest(tmp_path, grating="J", wl=1.25, order=-2, intensity=None):
    nominal_map(tmp_path)
    u = np.linspace(-100, 100, 101)
    y = np.exp(-0.5 * (u / 10) ** 2) if intensity is None else intensity(u)
    write_line_profile_csv(tmp_path / "p.csv", u, y)
    p = tmp_path / "m.toml"
    p.write_text('[simulation]\nsag_file = "nominal.npz"\n[[measurement]]\nkind = "line_profile"\nfile = "p.csv"\n'
                 f'grating = "{grating}"\norder = {order}\nwavelength_um = {wl}\npixel_scale_mas = 250\n')
    return p


@pytest.mark.parametrize("kw, fragment", [
    ({"grating": "Z"}, "grating='Z'"),
    ({"wl": 3.0, "order": -4}, "wavelength_um=3.0"),
    ({"intensity": lambda u: np.zeros_like(u)}, "flux"),
    ({"intensity": lambda u: np.exp(-0.5 * (u / 10) ** 2) - 0.5}, "no flux"),  # area 25 - 100 < 0
])
def test_bad_profile_manifest(tmp_path, kw, fragment):
    with pytest.raises(ValueError) as e:
        diagnose(_profile_manifest(tmp_path, **kw))
    assert "measurement 'p'" in str(e.value) and fragment in str(e.value)


def test_no_valid_pixels_in_aperture(tmp_path):
    nom = nominal_map(tmp_path)
    m = synthetic_surface(nom, np.random.default_rng(0))
    X, Y = m.grid()
    write_sag_map(m.with_sag(np.where(X**2 + Y**2 < 60**2, np.nan, m.sag_um)), tmp_path / "map.npz")
    p = surface_manifest(tmp_path)
    p.write_text(p.read_text().replace("aperture_diameter_mm = 137", "aperture_diameter_mm = 100"))
    with pytest.raises(ValueError, match="measurement 'map': aperture_diameter_mm=100.0 leaves 0 valid pixels"):
        diagnose(p)


def test_cli_writes_json_and_html(tmp_path):
    p = surface_case(tmp_path, lambda x, y: 0.08 * zernike_xy(2, 2, x, y, 68.5))
    assert main(["diagnose", str(p), "--out", str(tmp_path / "out")]) == 0
    j = json.loads((tmp_path / "out" / "diagnosis.json").read_text())
    assert j["verdict"] == "explained"
    f = j["findings"][0]
    for key in ("effect", "parameters", "uncertainties", "score", "residual_rms_before", "residual_rms_after",
                "shrink_fraction", "heldout_shrink_fraction", "degenerate_with"):
        assert key in f
    assert f["residual_rms_after"] < f["residual_rms_before"]
    scores = [x["score"] + 10 * (len(x["effects"]) - 1) for x in j["findings"]]
    assert scores == sorted(scores)
    assert any(w["component"] == "astigmatism" for w in j["where"])
    assert "<img" in (tmp_path / "out" / "report.html").read_text()
    assert main(["diagnose", str(tmp_path / "nope.toml"), "--out", str(tmp_path / "o2")]) == 2
    assert math.isfinite(f["uncertainties"]["astig_0_um"])


def test_campaign_recovery_rules():
    """Per-parameter rule (floors), vector rule (norm of the coefficient error over the
    injected norm = RMS of the WFE error over the injected WFE RMS), sign-degenerate
    parameters compared by magnitude, error-bar honesty (2 sigma)."""
    from pipeline.diagnosis.campaign import recovery_errors

    truth = {"coll_coma_um": 0.10, "coll_defocus_um": 0.01, "coll_astig45_um": 0.20}
    fit = {"coll_coma_um": 0.11, "coll_defocus_um": 0.035, "coll_astig45_um": 0.19}
    r = recovery_errors(FakeDiagnosis("collimator_wfe", FakeFinding(fit, dict.fromkeys(fit, 0.01))),
                        "collimator_wfe", truth)
    assert r["per_parameter"] == pytest.approx(0.025 / 0.04)  # defocus: 0.025 off, floor 0.04
    assert r["vector"] == pytest.approx(math.sqrt(0.01**2 + 0.025**2 + 0.01**2) / math.sqrt(0.1**2 + 0.01**2 + 0.2**2))
    assert r["vector"] < 0.2 < r["per_parameter"]
    assert r["within_2sigma"] is False  # defocus 2.5 sigma off
    # a pupil_y sign flip: counts only if the engine said the sign is undetermined
    truth = {"pupil_x_mm": 5.0, "pupil_y_mm": 2.0}
    fit = {"pupil_x_mm": 5.2, "pupil_y_mm": -2.1}
    flagged = recovery_errors(FakeDiagnosis("pupil_shift", FakeFinding(fit, dict.fromkeys(fit, 0.2), ["pupil_y_mm"])),
                              "pupil_shift", truth)
    silent = recovery_errors(FakeDiagnosis("pupil_shift", FakeFinding(fit, dict.fromkeys(fit, 0.2))), "pupil_shift", truth)
    assert flagged["vector"] == pytest.approx(math.hypot(0.2, 0.1) / math.hypot(5.0, 2.0)) and flagged["within_2sigma"]
    assert silent["vector"] > 0.5 and not silent["within_2sigma"]
    # registration mixes mm and degrees: no vector rule
    truth = {"reg_dx_mm": 3.0, "reg_dy_mm": 0.0, "reg_rot_deg": 1.0}
    fit = {"reg_dx_mm": 3.1, "reg_dy_mm": 0.2, "reg_rot_deg": 1.0}
    r = recovery_errors(FakeDiagnosis("registration", FakeFinding(fit, dict.fromkeys(fit, 0.1))), "registration", truth)
    assert r["vector"] == r["per_parameter"] == pytest.approx(0.2 / 0.5)


def test_campaign_scores_the_named_finding_beside_the_effects_own_fit():
    """A slit named in a pair beside a rescaling: scored by the named pair's own slit width
    (36.99 µm for 36.98: 0.03 % off) where the slit's single fit reads 40.9 µm (10.6 % off)."""
    from pipeline.diagnosis.campaign import recovery_errors

    truth = {"slit_image_width_um": 36.98}
    single = FakeFinding({"slit_image_width_um": 40.9}, {"slit_image_width_um": 1.2})
    pair = FakeFinding({"slit_image_width_um": 36.99, "scale_J": 1.17}, {"slit_image_width_um": 0.5, "scale_J": 0.02})
    d = FakeDiagnosis("slit_width", single)
    assert recovery_errors(d, "slit_width", truth)["per_parameter"] == pytest.approx(3.92 / 36.98)
    named = recovery_errors(d, "slit_width", truth, finding=pair)
    assert named["per_parameter"] == pytest.approx(0.01 / 36.98) and named["within_2sigma"]


@pytest.mark.parametrize("kw, fragment", [
    ({"min_variance_explained": 1.5}, "min_variance_explained=1.5 must be a number in [0.0, 1.0]"),
    ({"no_gap_ratio": 0.9}, "no_gap_ratio=0.9 must be a number in [1.0, inf]"),
    ({"pair_from": 2.5}, "pair_from=2.5 must be an integer in [0, 20]"),
    ({"min_delta_bic": float("nan")}, "min_delta_bic=nan must be a number"),
    ({"heldout_top": "3"}, "heldout_top='3' must be an integer"),
])
def test_criteria_checked(kw, fragment):
    from pipeline.diagnosis.engine import Criteria

    with pytest.raises(ValueError) as e:
        Criteria(**kw)
    assert fragment in str(e.value)
    Criteria(pair_from=2, heldout_top=1, no_gap_z=5)  # the campaign's


def test_unconstrained_parameters_flagged():
    """A parameter whose 1-sigma exceeds half its prior range is listed (inf and nan too);
    one the data pin down is not; parameters without a prior (none) are left alone."""
    from pipeline.diagnosis.engine import Finding, unconstrained
    from pipeline.diagnosis.effects import LIBRARY

    half = {q.name: 0.5 * q.width for q in LIBRARY["collimator_wfe"].parameters}
    assert half["coll_astig45_um"] == pytest.approx(0.4)
    f = Finding("collimator_wfe", ("collimator_wfe",), {"coll_coma_um": -0.15, "coll_astig45_um": -0.22, "x": 1.0},
                {"coll_coma_um": 0.002, "coll_astig45_um": 85.4, "coll_defocus_um": float("nan"), "x": 1e9},
                0.0, -200.0, 1.0, 0.8, 0.2, 0.36)
    assert unconstrained(f, half) == ("coll_astig45_um", "coll_defocus_um")


def test_pair_gives_way_to_a_member_that_explains():
    """A pair on top that explains too little where it acts gives way to a member that
    explains alone (significant, half the excess where it acts, not overfit); otherwise the
    ranking stands."""
    from pipeline.diagnosis.engine import Criteria, Finding, explains, member_explains

    def f(name, dbic, ex, sig=True, overfit=False):
        return Finding(name, tuple(name.split("+")), {}, {}, dbic, dbic, 1.0, 0.5, 0.5, 0.75, ex,
                       significant=sig, overfit=overfit, heldout_note="checked")

    c = Criteria()
    pair, slit, coll = f("collimator_wfe+slit_width", -229.0, 0.49), f("slit_width", -198.7, 0.92), f("collimator_wfe", -28.4, 0.1)
    assert not explains(pair, c) and explains(slit, c)
    out, note = member_explains(None, [pair, coll, slit], c, heldout=False)
    assert [x.effect for x in out] == ["slit_width", "collimator_wfe+slit_width", "collimator_wfe"]
    assert "slit_width alone explains 0.92" in note and "only 0.49" in note
    for member in (f("slit_width", -198.7, 0.92, sig=False), f("slit_width", -198.7, 0.42),
                   f("slit_width", -198.7, 0.92, overfit=True), f("temperature", -198.7, 0.92)):
        out, note = member_explains(None, [pair, member], c, heldout=False)
        assert out[0] is pair and note == ""


def test_evidence_counts_the_residual_after_the_best_fit(tmp_path):
    # A smooth astigmatism dominates the nominal residual, so its correlation length is the
    # effect's: counted from the nominal residual the map is worth few samples. Counted
    # from the residual the best fit leaves (noise + model mismatch), the evidence grows;
    # the fits and error bars stay the same (only the score's sample count changes).
    from pipeline.diagnosis.engine import Criteria

    # Companions are held out of both runs: whether one is adopted depends on the score,
    # so with them the re-count could change which joint fit a finding reports.
    p = surface_case(tmp_path, lambda x, y: 0.05 * zernike_xy(2, -2, x, y, 68.5))
    nominal = diagnose(p, criteria=Criteria(companion_top=0), heldout=False)
    post = diagnose(p, criteria=Criteria(n_eff_from="best_fit", companion_top=0), heldout=False)
    assert post.baseline["n_eff_from"] == "best_fit" and nominal.baseline["n_eff_from"] == "nominal"
    assert post.baseline["n_count"]["map"] > 2 * nominal.baseline["n_count"]["map"]
    assert post.baseline["n_eff"] == nominal.baseline["n_eff"]
    a, b = nominal.finding("astigmatism"), post.finding("astigmatism")
    assert b.parameters == pytest.approx(a.parameters, rel=1e-6)
    # The fit's own error bars are the same (no companion refit, so no model-choice term).
    assert b.uncertainties == pytest.approx(a.uncertainties, rel=0.01)
    ratio = post.baseline["n_count"]["map"] / nominal.baseline["n_count"]["map"]
    assert b.delta_bic < 0.9 * ratio * a.delta_bic < 0


def test_n_eff_source_checked(tmp_path, capsys):
    import argparse

    from pipeline.diagnosis.cli import register
    from pipeline.diagnosis.engine import N_EFF_SOURCES, Criteria

    with pytest.raises(ValueError, match=r"n_eff_from='residual' must be one of \('nominal', 'best_fit'\)"):
        Criteria(n_eff_from="residual")
    # the CLI spells the choices out (start-up without the engine import): same set, same default
    p = register(argparse.ArgumentParser().add_subparsers())
    action = next(a for a in p._actions if a.dest == "n_eff_from")
    assert tuple(action.choices) == N_EFF_SOURCES and action.default == Criteria().n_eff_from
    assert main(["diagnose", str(surface_case(tmp_path)), "--out", str(tmp_path / "o"), "--no-heldout", "--n-eff-from", "best_fit"]) == 0
    assert json.loads((tmp_path / "o" / "diagnosis.json").read_text())["baseline"]["n_eff_from"] == "best_fit"
    with pytest.raises(SystemExit):
        main(["diagnose", str(surface_case(tmp_path)), "--out", str(tmp_path / "o"), "--n-eff-from", "post"])
    assert "--n-eff-from: invalid choice: 'post'" in capsys.readouterr().err


def test_a_finding_pinned_at_its_prior_bounds_is_no_explanation(tmp_path):
    """A blank deformed 4x the simulation's (amplitude_scale's prior ends at 3): the fit of
    the scale stops at the bound, so the finding is reported ``at_bound`` and the verdict is
    not ``explained`` by it; a companion's parameter at its bound does not pin the finding."""
    from pipeline.diagnosis.engine import Criteria, Finding, explains

    d = diagnose(surface_case(tmp_path, scale=4.0), heldout=False)
    a = d.finding("amplitude_scale")
    assert a.at_bound == tuple(q for q in a.parameters if q.startswith("scale_")) and a.at_bound
    assert a.parameters[a.at_bound[0]] == pytest.approx(3.0, abs=0.01)
    assert not (d.verdict == "explained" and d.best.effect == "amplitude_scale")
    c = Criteria()
    f = Finding("amplitude_scale", ("amplitude_scale",), {"scale_A": 1.2, "bow_defocus_um": 0.2}, {}, -50.0, -50.0,
                1.0, 0.3, 0.7, 0.9, 0.9, significant=True, companions=("blank_bow",), at_bound=())
    assert explains(f, c)
    from dataclasses import replace

    assert not explains(replace(f, at_bound=("scale_A",)), c)
