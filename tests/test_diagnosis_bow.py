"""The blank_bow effect (alone, as a companion, only with a map in the data), the
model-choice term of the uncertainties, the campaign's map beside the profiles and its
model discrepancy, and the verdict beside an unexplained measurement. Nominal: the
analytic sum quilt (no FEA)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pipeline.diagnosis import diagnose
from pipeline.diagnosis.effects import LIBRARY, applicable_effects
from pipeline.diagnosis.engine import Finding
from pipeline.diagnosis.ranking import mismatch_errors
from pipeline.diagnosis.effects.blank_bow import bow_um
from pipeline.diagnosis.nominal import thermal_factor
from pipeline.diagnosis.synth import blank_shape_map, synthetic_surface
from pipeline.io.measured import write_line_profile_csv
from pipeline.io.registry import write_sag_map

from diagnosis_cases import nominal_map, surface_manifest


def _bow_map(tmp_path, b2, b4, temperature_K=128.0, seed=7):
    """A 128 K map of a blank whose cold deformation at 80 K carries a bow (b2, b4) µm,
    really at ``temperature_K`` (the manifest says 128 K)."""
    nom = nominal_map(tmp_path)
    t = blank_shape_map(nom, {"bow_defocus_um": b2, "bow_spherical_um": b4}).scaled(thermal_factor(temperature_K, 80))
    write_sag_map(synthetic_surface(t, np.random.default_rng(seed), noise_um=0.005), tmp_path / "map.npz")
    return surface_manifest(tmp_path)


def test_bow_is_rms_normalised_zernike_on_70mm():
    r = (np.arange(4000) + 0.5) * 70 / 4000
    th = np.linspace(0, 2 * np.pi, 180, endpoint=False)
    R, T = np.meshgrid(r, th)
    w = R  # area element
    for args in ((0.1, 0.0), (0.0, 0.1)):
        z = bow_um(R * np.cos(T), R * np.sin(T), *args)
        z = z - np.sum(z * w) / np.sum(w)
        assert math.sqrt(np.sum(z**2 * w) / np.sum(w)) == pytest.approx(0.1, rel=1e-2)


def test_bow_needs_a_map():
    """On line profiles alone the bow is degenerate with collimator defocus: not tried."""
    e = LIBRARY["blank_bow"]
    assert e.companion and e.requires == ("surface",)
    assert "blank_bow" not in {x.name for x in applicable_effects({"line_profile"})}
    assert "blank_bow" in {x.name for x in applicable_effects({"line_profile", "surface"})}


def test_bow_alone_recovered(tmp_path):
    d = diagnose(_bow_map(tmp_path, 0.05, -0.02))
    assert d.verdict == "explained" and d.best.effect == "blank_bow"
    assert d.best.parameters["bow_defocus_um"] == pytest.approx(0.05, rel=0.1)
    assert d.best.parameters["bow_spherical_um"] == pytest.approx(-0.02, rel=0.2)
    assert all(not f.absorbs for f in d.findings)  # with a map the bow is fitted, not absorbed


def test_bow_companion_unbiases_temperature(tmp_path):
    """A map really at 150 K (stated 128 K) of a bowed blank: the temperature fitted with
    the bow as companion is right; the bow is listed in ``companions``."""
    d = diagnose(_bow_map(tmp_path, 0.04, 0.0, temperature_K=150.0))
    f = d.finding("temperature") or d.finding("amplitude_scale")
    assert "blank_bow" in f.companions
    t = d.finding("temperature")
    assert t is not None and t.parameters["temperature_offset_K"] == pytest.approx(22.0, abs=4.0)
    assert t.parameters["bow_defocus_um"] == pytest.approx(0.04, rel=0.2)


def _finding(value, sigma, **extra):
    return Finding("x", ("x",), {"a": value, **extra}, {"a": sigma}, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0)


def test_mismatch_errors():
    """The largest move to an alternative is added in quadrature to the finding's own
    parameters; parameters that are not its own (a companion's) keep their error."""
    a = _finding(1.0, 0.1, c=5.0)
    a = Finding(a.effect, a.effects, a.parameters, {"a": 0.1, "c": 0.2}, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0)
    e = mismatch_errors(a, [_finding(1.3, 0.1), _finding(0.6, 0.1)], {"a"})
    assert e["a"] == pytest.approx(math.hypot(0.1, 0.4))
    assert e["c"] == 0.2
    assert mismatch_errors(a, [], {"a"})["a"] == 0.1


def test_campaign_map_beside_profiles(tmp_path):
    """``profile_map_K``: a line-profile case also gets a map of the same blank; the
    profiles are those of the profile-only case (the map is drawn after them)."""
    from pipeline.diagnosis.campaign import PROFILE_SETS, CampaignConfig, make_case
    from pipeline.diagnosis.manifest import parse_manifest

    base = nominal_map(tmp_path)
    cfgs = [CampaignConfig(profile_specs=PROFILE_SETS["minimal"][:1], profile_map_K=k) for k in (None, 128.0)]
    out = []
    for cfg in cfgs:
        d = tmp_path / str(cfg.profile_map_K)
        d.mkdir()
        man, truth = make_case("line_profile", "temperature", np.random.default_rng([1, 7]), base, d, cfg)
        out.append((man, truth, (d / "p0.csv").read_text()))
    (m0, t0, p0), (m1, t1, p1) = out
    assert t0 == t1 and p0 == p1
    assert [m["kind"] for m in m1["measurement"]] == ["line_profile", "surface"]
    assert m1["measurement"][1]["temperature_K"] == 128.0
    # the map is said to be of the profiles' blank, so one amplitude scale covers both
    blanks = {m.kind: m.blank for m in parse_manifest(m1, tmp_path / "128.0").measurements}
    assert blanks == {"line_profile": "J", "surface": "J"}


def test_campaign_map_temperature_checked():
    from pipeline.diagnosis.campaign import CampaignConfig
    from pipeline.diagnosis.cli import main

    with pytest.raises(ValueError, match=r"profile_map_K=5.0 K is outside the valid range 20 ... 290 K"):
        CampaignConfig(profile_map_K=5.0)
    assert main(["diagnose", "--validate", "--profile-map-K", "500", "--out", "unused"]) == 2


def _bowed_profiles(tmp_path, b2):
    """J 1.25 µm profiles at 250 and 25 mas of the analytic blank carrying a bow ``b2`` µm
    (no collimator error): manifest path."""
    from pipeline.diagnosis.synth import synthetic_profile

    nom = nominal_map(tmp_path)
    truth = blank_shape_map(nom, {"bow_defocus_um": b2, "bow_spherical_um": 0.0})
    rng = np.random.default_rng(11)
    lines = ['[simulation]\nsag_file = "nominal.npz"\ncold_K = 80\n']
    for ps in (250, 25):
        u, y, _ = synthetic_profile("J", 1.25, -2, ps, truth, rng, noise_rel=0.005)
        write_line_profile_csv(tmp_path / f"p{ps}.csv", u, y)
        lines.append(f'[[measurement]]\nkind = "line_profile"\nfile = "p{ps}.csv"\ngrating = "J"\norder = -2\n'
                     f'wavelength_um = 1.25\npixel_scale_mas = {ps}\n')
    p = tmp_path / "m.toml"
    p.write_text("\n".join(lines))
    return p


def test_bow_absorbed_by_collimator_defocus_on_profiles(tmp_path):
    """On line profiles alone a blank bow is not fitted; the collimator finding that takes
    it up says so (``degenerate_with`` blank_bow, ``absorbs`` bow_defocus_um), and the
    coefficient it reports predicts the defocus actually fitted to a bowed blank's
    profiles (measured: -1.70 per µm of bow; fitted -0.070 µm for a 0.04 µm bow)."""
    b2 = 0.04
    d = diagnose(_bowed_profiles(tmp_path, b2), effects=("collimator_wfe", "slit_width"), heldout=False)
    f = d.finding("collimator_wfe")
    assert f is d.best and f.significant
    assert "blank_bow" in f.degenerate_with
    k = f.absorbs["bow_defocus_um"]["coll_defocus_um"]
    assert abs(k) > 0.5
    assert f.parameters["coll_defocus_um"] == pytest.approx(k * b2, rel=0.15)
    assert abs(f.parameters["coll_coma_um"]) < 0.2 * abs(f.parameters["coll_defocus_um"])


@pytest.mark.slow
def test_seen_bow_refitted_beside_every_significant_single(tmp_path):
    """Profiles + 128 K map + focal-plane PSF image of a blank with a bow and plating
    gradient (the campaign's ``discrepancy="companions"``), and a slit 21 µm wide. The data
    see the bow on its own (delta BIC about -360), and pupil_shift and collimator_wfe each
    mimic part of it, so on the first ranking they sit above slit_width; refitting only the
    two best singles with the companions left blank_bow on top for this draw and for a
    35 µm slit (measured before the rule). Every significant single is now refitted:
    slit_width with the bow is the finding. The effects tried are the ones that compete
    here (the map-only effects and the rescalings, which take up none of the bow, are left
    out: with them the same finding, measured 126 s against 92 s)."""
    from pipeline.diagnosis.campaign import PROFILE_SETS, PSF_IMAGE_SPEC, CampaignConfig, make_case
    from pipeline.diagnosis.manifest import parse_manifest

    base = nominal_map(tmp_path)
    cfg = CampaignConfig(profile_specs=PROFILE_SETS["minimal"], psf_image=PSF_IMAGE_SPEC, profile_map_K=128.0,
                         discrepancy="companions")
    man, truth = make_case("line_profile", "slit_width", np.random.default_rng([1, 0]), base, tmp_path, cfg)
    d = diagnose(parse_manifest(man, tmp_path), criteria=cfg.criteria, nominal=base, keep_curves=False,
                 heldout=False, effects=("slit_width", "pupil_shift", "collimator_wfe", "plating_gradient",
                                         "blank_bow"))
    assert d.verdict == "explained" and d.best.effect == "slit_width" and "blank_bow" in d.best.companions
    # measured: 20.92 for 21.05 µm
    assert d.best.parameters["slit_image_width_um"] == pytest.approx(truth["slit_image_width_um"], rel=0.02)


def test_unmodelled_discrepancy_is_outside_the_surface_library():
    """The campaign's default model discrepancy (trefoil/tetrafoil/pentafoil) has mean
    square ``rms_um**2`` over the 137 mm aperture and no component along the library's
    surface terms there (piston, tilt, bow, astigmatism, and the coma an out-of-library case
    injects): least-squares coefficients below 1 % of its RMS on the 1 mm map grid."""
    from optics.sagmap import SagMap
    from optics.zernike import zernike_basis_xy
    from pipeline.diagnosis.synth import unmodelled_shape

    ax = np.arange(-68.0, 68.5, 1.0)
    flat = SagMap(ax, ax, np.zeros((ax.size, ax.size)), "flat")
    X, Y = flat.grid()
    inside = X**2 + Y**2 <= 68.5**2
    library = zernike_basis_xy([(0, 0), (1, 1), (1, -1), (2, 0), (2, 2), (2, -2), (3, 1), (3, -1), (4, 0)],
                               X[inside], Y[inside], 68.5).T
    ms = []
    for seed in range(40):
        d = unmodelled_shape(flat, np.random.default_rng(seed), rms_um=0.02).sag_um[inside]
        rms = np.sqrt(np.mean(d**2))
        coef = np.linalg.lstsq(library, d, rcond=None)[0]
        assert np.max(np.abs(coef)) < 0.01 * rms
        ms.append(rms**2)
    assert np.mean(ms) == pytest.approx(0.02**2, rel=0.25)  # 40 draws of a 6-term chi-square
    with pytest.raises(ValueError, match=r"rms_um=-0.01 must be a finite number >= 0 µm"):
        unmodelled_shape(flat, np.random.default_rng(0), rms_um=-0.01)
    with pytest.raises(ValueError, match=r"radius_mm=0.0 must be a finite number > 0 mm"):
        unmodelled_shape(flat, np.random.default_rng(0), radius_mm=0.0)


def test_unmodelled_discrepancy_stays_unexplained(tmp_path):
    """A map whose only difference from the nominal is a 0.03 µm RMS unmodelled shape
    (3x the noise) has a gap, and no library effect takes it up: ``unexplained``."""
    from pipeline.diagnosis.synth import unmodelled_shape

    nom = nominal_map(tmp_path)
    t = unmodelled_shape(nom, np.random.default_rng(5), rms_um=0.03).scaled(thermal_factor(128, 80))
    write_sag_map(synthetic_surface(t, np.random.default_rng(6), noise_um=0.01), tmp_path / "map.npz")
    d = diagnose(surface_manifest(tmp_path), heldout=False)
    assert d.verdict == "unexplained"
    assert d.best is None or d.best.excess_explained < 0.5


def test_campaign_discrepancy_checked():
    from pipeline.diagnosis.campaign import DISCREPANCIES, CampaignConfig

    assert set(DISCREPANCIES) == {"unmodelled", "companions"}
    assert CampaignConfig().discrepancy == "unmodelled"
    with pytest.raises(ValueError, match=r"discrepancy='bow' is not one of \['companions', 'unmodelled'\]"):
        CampaignConfig(discrepancy="bow")
    # the CLI spells the choices out (it imports the campaign only when it runs): same set
    import argparse

    from pipeline.diagnosis.cli import register

    p = register(argparse.ArgumentParser().add_subparsers())
    choices = next(a.choices for a in p._actions if a.dest == "discrepancy")
    assert set(choices) == set(DISCREPANCIES)


@pytest.mark.slow
def test_slit_explained_beside_an_unexplained_map(tmp_path):
    """A map carrying only an unmodelled 0.03 µm RMS shape and two J profiles of a 35 µm
    slit: slit_width explains the profiles (excess where it acts: measured 0.83; 0.95 without
    the profiles' inter-pixel coupling nuisance, which takes part of a wider slit's
    broadening from the nominal's gap while the unmodelled shape's stays), the
    verdict is ``explained``, and the map, which a slit width does not change, is named in
    ``unexplained_in`` (chi^2 excess ~130 sd) instead of lowering the explained fraction
    (over all data: measured 0.61; in a slit-width campaign case the map and a PSF image took it to
    0.31 and the verdict to ``unexplained``)."""
    from pipeline.diagnosis.synth import synthetic_profile, unmodelled_shape

    nom = nominal_map(tmp_path)
    truth = unmodelled_shape(nom, np.random.default_rng(5), rms_um=0.03)
    write_sag_map(synthetic_surface(truth.scaled(thermal_factor(128, 80)), np.random.default_rng(6), noise_um=0.01),
                  tmp_path / "map.npz")
    rng = np.random.default_rng(11)
    lines = [surface_manifest(tmp_path).read_text()]
    for ps in (250, 25):
        u, y, _ = synthetic_profile("J", 1.25, -2, ps, truth, rng, params={"slit_image_width_um": 35.0})
        write_line_profile_csv(tmp_path / f"p{ps}.csv", u, y)
        lines.append(f'[[measurement]]\nkind = "line_profile"\nfile = "p{ps}.csv"\ngrating = "J"\norder = -2\n'
                     f'wavelength_um = 1.25\npixel_scale_mas = {ps}\n')
    (tmp_path / "m.toml").write_text("\n".join(lines))
    d = diagnose(tmp_path / "m.toml", heldout=False)
    b = d.best
    assert d.verdict == "explained" and b.effect == "slit_width"
    assert b.parameters["slit_image_width_um"] == pytest.approx(35.0, rel=0.02)
    assert b.excess_explained > 0.8 and b.excess_explained_overall < b.excess_explained - 0.2
    assert [g["measurement"] for g in d.unexplained_in] == ["map"] and d.unexplained_in[0]["z"] > 50
    assert d.to_dict()["unexplained_in"][0]["measurement"] == "map"
