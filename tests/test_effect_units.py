"""What each library effect carries besides its parameters: the campaign's truth draw
(``Effect.draw_truth``) and its physical summary for reports (``Effect.summary``)."""

import math

import numpy as np
import pytest

from optics.sagmap import SagMap
from pipeline.diagnosis.campaign import CampaignConfig, make_case
from pipeline.diagnosis.effect_draws import DRAWS
from pipeline.diagnosis.effects import LIBRARY, SummaryContext, effect_parameters, physical_summary
from pipeline.diagnosis.synth import unmodelled_shape

CASE_KINDS = ("surface", "line_profile")


def _drawable():
    """(effect, kind) pairs whose draw accepts the kind: the kinds it changes that a campaign case has."""
    return [(e.name, k) for e in LIBRARY.values() if e.draw_truth is not None for k in CASE_KINDS if k in e.kinds]


def _base_map():
    ax = np.arange(-75.0, 75.01, 1.0)
    X, Y = np.meshgrid(ax, ax)
    return SagMap(ax, ax, 0.05 * np.cos(2 * np.pi * X / 21) + 0.04 * np.cos(2 * np.pi * Y / 18), "test base")


@pytest.mark.parametrize("effect,kind", _drawable())
def test_draws_are_the_effects_own_parameters_inside_their_priors(effect, kind):
    e = LIBRARY[effect]
    specs = {p.name: p for p in effect_parameters(e, ("J",))}
    rng = np.random.default_rng(3)
    for _ in range(200):
        drawn = e.draw_truth(rng, kind, "J")
        assert drawn and set(drawn) <= set(specs)
        for name, v in drawn.items():
            assert specs[name].lo <= v <= specs[name].hi, (name, v)


def test_vector_draws_have_the_stated_magnitudes():
    """RMS (Zernike vectors) and shift length as the draws' docstrings state them."""
    rng = np.random.default_rng(5)
    for _ in range(200):
        a = LIBRARY["astigmatism"].draw_truth(rng, "surface", "spare")
        assert 0.04 <= np.hypot(a["astig_0_um"], a["astig_45_um"]) <= 0.15
        c = LIBRARY["collimator_wfe"].draw_truth(rng, "line_profile", "J")
        assert 0.15 <= np.linalg.norm([c["coll_coma_um"], c["coll_defocus_um"], c["coll_astig45_um"]]) <= 0.35 + 1e-12
        r = LIBRARY["registration"].draw_truth(rng, "surface", "spare")
        assert 1.5 <= np.hypot(r["reg_dx_mm"], r["reg_dy_mm"]) <= 5.0 and abs(r["reg_rot_deg"]) <= 1.5
        t = LIBRARY["temperature"].draw_truth(rng, "line_profile", "J")["temperature_offset_K"]
        assert 35.0 <= t <= 75.0  # profiles: warmer than stated only


def test_the_independent_truths_registry_is_the_librarys_draws():
    """The independent truth (which does not import the library) draws through DRAWS."""
    assert DRAWS == {n: e.draw_truth for n, e in LIBRARY.items() if e.draw_truth is not None}


def test_a_draw_refuses_a_kind_it_does_not_change():
    with pytest.raises(ValueError, match="kind='line_profile'"):
        LIBRARY["astigmatism"].draw_truth(np.random.default_rng(0), "line_profile", "J")


def test_make_case_injects_the_effects_draw_at_its_stage(tmp_path):
    """A "blank"-stage truth is drawn first, a "map"-stage truth after the model
    discrepancy; a per-blank parameter is named for the map's blank ("spare")."""
    base = _base_map()
    cfg = CampaignConfig(truth="model", n_cases=1)
    _, truth = make_case("surface", "amplitude_scale", np.random.default_rng([1, 1]), base, tmp_path, cfg)
    assert truth == LIBRARY["amplitude_scale"].draw_truth(np.random.default_rng([1, 1]), "surface", "spare")
    assert set(truth) == {"scale_spare"}

    _, truth = make_case("surface", "astigmatism", np.random.default_rng([1, 0]), base, tmp_path, cfg)
    rng = np.random.default_rng([1, 0])
    unmodelled_shape(base, rng)  # the default discrepancy's draws come first
    assert truth == LIBRARY["astigmatism"].draw_truth(rng, "surface", "spare")


def test_make_case_refuses_an_effect_without_a_truth_draw(tmp_path):
    assert LIBRARY["plating_gradient"].draw_truth is None
    with pytest.raises(ValueError, match="plating_gradient"):
        make_case("surface", "plating_gradient", np.random.default_rng(0), _base_map(), tmp_path,
                  CampaignConfig(truth="model", n_cases=1))
    with pytest.raises(ValueError, match="ool_nothing"):
        make_case("surface", "ool_nothing", np.random.default_rng(0), _base_map(), tmp_path,
                  CampaignConfig(truth="model", n_cases=1))


@pytest.mark.parametrize("name", sorted(LIBRARY))
def test_every_effect_carries_a_physical_summary(name):
    """A non-empty summary; for the Zernike-type effects the RMS of orthonormal terms is
    the root sum of squares of their coefficients."""
    ctx = SummaryContext(cold_K=80.0, blanks=("J",), surface_radii_mm=(68.5,))
    p = {q.name: q.hi for q in effect_parameters(LIBRARY[name], ctx.blanks)}
    s = physical_summary((name,), p, ctx)[name]
    assert s
    if "rms_um" in s:
        assert s["rms_um"] == pytest.approx(math.sqrt(sum(v * v for v in p.values())))


@pytest.mark.parametrize("name", [n for n, e in LIBRARY.items() if e.rescales])
def test_a_rescaling_effect_only_rescales_the_nominal_map(name):
    """``Effect.rescales`` (never paired; not in the image models' memo key): away from its
    null the map model is the nominal's times one factor."""
    from pathlib import Path

    from pipeline.diagnosis.forward import PROFILE_KEYS, SurfaceForward
    from pipeline.diagnosis.manifest import Measurement, SurfaceData

    base = _base_map()
    X, Y = base.grid()
    inside = X**2 + Y**2 <= 60.0**2
    m = Measurement("map", "surface", Path("map.npz"), "spare", temperature_K=128.0, aperture_diameter_mm=120.0)
    fwd = SurfaceForward(SurfaceData(m, X[inside], Y[inside], base.sag_um[inside]), base, 80.0)
    p = {q.name: 0.5 * (q.null + q.hi) for q in effect_parameters(LIBRARY[name], ("spare",))}
    nominal, changed = fwd.predict({}), fwd.predict(p)
    k = float(changed @ nominal / (nominal @ nominal))
    assert abs(k - 1.0) > 0.05
    np.testing.assert_allclose(changed, k * nominal, rtol=1e-12, atol=1e-12)
    assert not {q.name for q in LIBRARY[name].parameters} & set(PROFILE_KEYS)


def test_only_and_every_rescaling_effect_gives_the_projection_convention():
    """The projection convention converts an overall factor of the deformation: every
    ``rescales`` effect carries an ``Effect.projection`` and one on any other is refused."""
    from pipeline.diagnosis.effects import Effect, Parameter

    assert {n for n, e in LIBRARY.items() if e.projection is not None} == {n for n, e in LIBRARY.items() if e.rescales}
    with pytest.raises(ValueError, match="rescales=True"):
        Effect("fake_shift", ("surface",), (Parameter("fake_shift_mm", 0.0, -1.0, 1.0, unit="mm"),),
               projection=lambda p, k, ctx: {})


def test_a_new_rescaling_effects_projection_is_added_beside_quilt_shape(monkeypatch):
    """The summaries beside ``quilt_shape`` come from ``Effect.projection``, not from a list
    of names: a new rescaling effect's entry appears, at the projection factor of the
    nominal's part shares (x and y fundamentals held, the rest at 0.4 of the nominal's)."""
    from pipeline.diagnosis.effects import Effect, Parameter

    fake = Effect("fake_gain", ("surface",), (Parameter("fake_gain", 1.0, 0.5, 2.0),), rescales=True,
                  summary=lambda p, ctx: {"gain": p["fake_gain"]},
                  projection=lambda p, k, ctx: {"fake_gain_projection": p["fake_gain"] * k})
    monkeypatch.setitem(LIBRARY, "fake_gain", fake)
    w = {"fundamental_x": 0.45, "fundamental_y": 0.38, "cross": 0.07, "harmonics": 0.02, "figure": 0.08}
    ctx = SummaryContext(cold_K=80.0, blanks=("J",), quilt_weights=w)
    ratios = {"quilt_harmonics_ratio": 0.4, "quilt_cross_ratio": 0.4, "quilt_figure_ratio": 0.4}
    s = physical_summary(("fake_gain", "quilt_shape"), {"fake_gain": 1.5, **ratios}, ctx)
    k = 0.45 + 0.38 + 0.4 * (0.07 + 0.02 + 0.08)
    assert s["fake_gain"] == {"gain": 1.5, "fake_gain_projection": pytest.approx(1.5 * k)}
    assert physical_summary(("fake_gain",), {"fake_gain": 1.5}, ctx) == {"fake_gain": {"gain": 1.5}}


def test_make_case_refuses_a_drawn_parameter_it_does_not_apply(tmp_path, monkeypatch):
    """A new effect whose truth the model campaign does not know how to apply is refused,
    not injected as nothing."""
    from pipeline.diagnosis.effects import Effect, Parameter

    fake = Effect("fake_tilt", ("surface",), (Parameter("fake_tilt_urad", 0.0, -5.0, 5.0, unit="µrad"),),
                  draw_truth=lambda rng, kind, blank: {"fake_tilt_urad": rng.uniform(1.0, 2.0)})
    monkeypatch.setitem(LIBRARY, "fake_tilt", fake)
    with pytest.raises(ValueError, match="fake_tilt_urad"):
        make_case("surface", "fake_tilt", np.random.default_rng(0), _base_map(), tmp_path,
                  CampaignConfig(truth="model", n_cases=1))


# --- each effect's action on the forward models, against the formula written by hand ---

def _points():
    x = np.array([-60.0, -21.0, 0.0, 13.5, 40.0, 65.0])
    y = np.array([30.0, -45.0, 0.0, 7.0, -12.5, 10.0])
    return x, y


def test_the_rescalings_give_the_scale_and_the_true_temperature():
    assert LIBRARY["amplitude_scale"].scale({"scale_J": 1.3, "scale_spare": 0.7}, "spare") == 0.7
    assert LIBRARY["amplitude_scale"].scale({}, "J") == 1.0
    assert LIBRARY["temperature"].temperature(128.0, {"temperature_offset_K": -20.0}) == 108.0
    assert LIBRARY["temperature"].temperature(80.0, {}) == 80.0


def test_the_deformation_factor_is_the_thermal_factor_at_the_true_temperature_times_the_scale():
    from pipeline.diagnosis.forward import deformation_factor
    from pipeline.diagnosis.nominal import thermal_factor

    p = {"temperature_offset_K": 15.0, "scale_spare": 1.4}
    assert deformation_factor(p, "spare", 128.0, 80.0) == pytest.approx(1.4 * thermal_factor(143.0, 80.0), rel=1e-15)
    assert deformation_factor(p, "J", 80.0, 80.0) == pytest.approx(thermal_factor(95.0, 80.0), rel=1e-15)


def test_registration_moves_a_feature_at_q_to_R_q_plus_d():
    """A feature at blank point q appears at R q + d: the hook maps the measured point back."""
    p = {"reg_dx_mm": 1.0, "reg_dy_mm": 2.0, "reg_rot_deg": 90.0}
    qx, qy = LIBRARY["registration"].coordinates(np.array([1.0]), np.array([5.0]), p)
    # R(90°) (3, 0) + (1, 2) = (0, 3) + (1, 2) = (1, 5)
    np.testing.assert_allclose([qx[0], qy[0]], [3.0, 0.0], atol=1e-12)
    assert LIBRARY["registration"].coordinates(np.array([1.0]), np.array([5.0]), {}) is None


def test_the_plating_gradient_scales_the_local_deformation():
    x, y = _points()
    s = np.linspace(0.1, 0.6, x.size)
    out = LIBRARY["plating_gradient"].shape(s, x, y, {"plating_grad_x": 0.05, "plating_grad_y": -0.03}, None)
    np.testing.assert_allclose(out, s * (1.0 + 0.05 * x / 70.0 - 0.03 * y / 70.0), rtol=1e-14)


def test_the_bow_adds_rms_normalised_defocus_and_spherical_over_70_mm():
    x, y = _points()
    s = np.linspace(0.1, 0.6, x.size)
    r2 = (x**2 + y**2) / 70.0**2
    out = LIBRARY["blank_bow"].shape(s, x, y, {"bow_defocus_um": 0.1, "bow_spherical_um": -0.05}, None)
    want = s + 0.1 * math.sqrt(3) * (2 * r2 - 1) - 0.05 * math.sqrt(5) * (6 * r2**2 - 6 * r2 + 1)
    np.testing.assert_allclose(out, want, rtol=1e-12, atol=1e-14)


def test_the_quilt_shape_rescales_the_parts_of_the_quilt_and_the_figure():
    """``S + (rho-1) F_y + (h-1) H + (c-1) C + (k-1) H_x + (g-1) (S - F)`` with hand-made parts."""
    x, y = _points()
    s = np.linspace(0.1, 0.6, x.size)
    fy, hh, cc, hx = 0.1 * np.cos(y), 0.02 * np.sin(x), 0.01 * np.cos(x + y), 0.015 * np.cos(2 * x)
    whole = 0.2 * np.cos(x) + fy + hh + cc + hx
    p = {"quilt_fund_xy_ratio": 1.5, "quilt_harmonics_ratio": 0.0, "quilt_cross_ratio": 2.0, "quilt_figure_ratio": 0.5,
         "quilt_x_harmonics_ratio": -0.5}
    parts = {"fundamental_y": fy, "harmonics": hh, "cross": cc, "x_harmonics": hx, "whole": whole}
    out = LIBRARY["quilt_shape"].shape(s, x, y, p, parts)
    np.testing.assert_allclose(out, s + 0.5 * fy - hh + cc - 1.5 * hx - 0.5 * (s - whole), rtol=1e-14)
    assert LIBRARY["quilt_shape"].shape(s, x, y, p, None) is s  # no quilt fit: nothing to reshape


def test_the_shape_stages_reshape_then_multiply_then_add():
    """The quilt is reshaped on the nominal, the gradient scales the reshaped quilt, the
    bow is added unscaled (:data:`pipeline.diagnosis.effects.SHAPE_STAGES`)."""
    from pipeline.diagnosis.forward import blank_shape_um

    x, y = _points()
    s = np.linspace(0.1, 0.6, x.size)
    fy, hh, cc, hx = 0.1 * np.cos(y), 0.02 * np.sin(x), 0.01 * np.cos(x + y), 0.015 * np.cos(2 * x)
    whole = fy + hh + cc + hx
    p = {"quilt_harmonics_ratio": 3.0, "plating_grad_x": 0.07, "bow_defocus_um": 0.02}
    r2 = (x**2 + y**2) / 70.0**2
    want = (s + 2.0 * hh) * (1.0 + 0.07 * x / 70.0) + 0.02 * math.sqrt(3) * (2 * r2 - 1)
    parts = {"fundamental_y": fy, "harmonics": hh, "cross": cc, "x_harmonics": hx, "whole": whole}
    np.testing.assert_allclose(blank_shape_um(s, x, y, p, parts), want, rtol=1e-13)


def test_astigmatism_adds_rms_normalised_zernike_2_2_over_the_map_aperture():
    from pipeline.diagnosis.forward import map_terms_um

    x, y = _points()
    R = 68.5
    rho2, th = (x**2 + y**2) / R**2, np.arctan2(y, x)
    want = math.sqrt(6) * rho2 * (0.03 * np.cos(2 * th) - 0.08 * np.sin(2 * th))
    got = map_terms_um(x, y, R, {"astig_0_um": 0.03, "astig_45_um": -0.08})
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-15)
    assert map_terms_um(x, y, R, {"scale_J": 2.0}) is None


def test_the_pupil_terms_add_to_the_default_collimator():
    from optics.pupil import DEFAULT_COLLIMATOR_ZERNIKE_UM as D
    from pipeline.diagnosis.forward import collimator_terms

    p = {"coll_coma_um": 0.1, "coll_defocus_um": -0.2, "coll_astig45_um": 0.05, "pupil_spherical_um": 0.3,
         "pupil_trefoil_0_um": 0.01, "pupil_trefoil_30_um": -0.02, "pupil_coma2_um": 0.04}
    want = {(3, 1): D[(3, 1)] + 0.1, (2, -2): D[(2, -2)] + 0.05, (2, 0): -0.2, (4, 0): 0.3, (3, 3): 0.01,
            (3, -3): -0.02, (5, 1): 0.04}
    got = collimator_terms(p)
    assert set(got) == set(want) and all(got[k] == pytest.approx(v, abs=1e-15) for k, v in want.items())


def test_the_pupil_shift_and_the_slit_width_change_the_optics():
    """The slit width is the 27 µm gratings'; HK's 29 µm slit scales alike."""
    from pipeline.diagnosis.forward import spectrograph_optics

    o = spectrograph_optics("HK", {"pupil_x_mm": 3.0, "pupil_y_mm": -1.5, "slit_image_width_um": 30.0})
    assert o.pupil_shift_mm == (3.0, -1.5)
    assert o.grating.slit_image_width_um == pytest.approx(29.0 * 30.0 / 27.0)
    nominal = spectrograph_optics("J", {})
    assert nominal.pupil_shift_mm == (0.0, 0.0) and nominal.grating.slit_image_width_um == 27.0


@pytest.mark.parametrize("name", sorted(LIBRARY))
def test_every_effect_acts_on_a_forward_model_through_a_hook(name):
    e = LIBRARY[name]
    assert (e.scale, e.temperature, e.coordinates, e.shape, e.optics) != (None,) * 5 or e.map_zernike or e.pupil_zernike


def test_an_effect_refuses_a_bad_shape_stage_and_a_term_that_is_not_its_parameter():
    from pipeline.diagnosis.effects import Effect, Parameter

    q = (Parameter("fake_um", 0.0, -1.0, 1.0, unit="µm"),)
    with pytest.raises(ValueError, match="shape_stage='later'"):
        Effect("fake", ("surface",), q, shape=lambda s, x, y, p, quilt: s, shape_stage="later")
    with pytest.raises(ValueError, match="other_um"):
        Effect("fake", ("line_profile",), q, pupil_zernike=(("other_um", (4, 0)),))


# --- adding an effect is one new module: a new unit reaches the models and the campaign ---

def _ripple_effect(amplitude_um):
    from pipeline.diagnosis.effects import Effect, Parameter

    def shape(s, x, y, p, quilt):
        a = p.get("fake_ripple_um", 0.0)
        return s + a * np.cos(2 * np.pi * x / 10.0) if a else s

    return Effect("fake_ripple", ("surface", "line_profile"),
                  (Parameter("fake_ripple_um", 0.0, -0.2, 0.2, unit="µm", meaning="a 10 mm ripple along x"),),
                  shape=shape, draw_truth=lambda rng, kind, blank: {"fake_ripple_um": amplitude_um})


def test_a_new_surface_shape_effect_reaches_the_map_model_and_the_campaign_truth(tmp_path, monkeypatch):
    """An effect declared with a ``shape`` hook alone: the map model adds ``k a cos(2 pi x /
    10 mm)`` and the model campaign injects it (same random draws: the written maps differ
    by exactly that, scaled to the map's 128 K)."""
    from pathlib import Path

    from pipeline.diagnosis.forward import SurfaceForward
    from pipeline.diagnosis.manifest import Measurement, SurfaceData
    from pipeline.diagnosis.nominal import thermal_factor
    from pipeline.io.registry import read_sag_map

    monkeypatch.setitem(LIBRARY, "fake_ripple", _ripple_effect(0.05))
    base = _base_map()
    X, Y = base.grid()
    inside = X**2 + Y**2 <= 60.0**2
    m = Measurement("map", "surface", Path("map.npz"), "spare", temperature_K=128.0, aperture_diameter_mm=120.0)
    fwd = SurfaceForward(SurfaceData(m, X[inside], Y[inside], base.sag_um[inside]), base, 80.0)
    k = thermal_factor(128.0, 80.0)
    np.testing.assert_allclose(fwd.predict({"fake_ripple_um": 0.05}) - fwd.predict({}),
                               k * 0.05 * np.cos(2 * np.pi * X[inside] / 10.0), atol=1e-12)

    cfg = CampaignConfig(truth="model", n_cases=1)
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    _, truth = make_case("surface", "fake_ripple", np.random.default_rng(4), base, tmp_path / "a", cfg)
    assert truth == {"fake_ripple_um": 0.05}
    monkeypatch.setitem(LIBRARY, "fake_ripple", _ripple_effect(0.0))
    make_case("surface", "fake_ripple", np.random.default_rng(4), base, tmp_path / "b", cfg)
    a, b = read_sag_map(tmp_path / "a" / "map.npz"), read_sag_map(tmp_path / "b" / "map.npz")
    Xm, _ = a.grid()
    ok = np.isfinite(a.sag_um)
    np.testing.assert_allclose((a.sag_um - b.sag_um)[ok], (k * 0.05 * np.cos(2 * np.pi * Xm / 10.0))[ok], atol=1e-9)


def test_a_new_pupil_term_effect_reaches_the_spectrograph(monkeypatch):
    """An effect declared with ``pupil_zernike`` alone adds its term to the collimator's
    wavefront that the profile and image models use."""
    from pipeline.diagnosis.effects import Effect, Parameter
    from pipeline.diagnosis.forward import collimator_terms, spectrograph_optics

    fake = Effect("fake_camera", ("line_profile", "psf_image"),
                  (Parameter("camera_spherical_um", 0.0, -0.4, 0.4, unit="µm"),),
                  pupil_zernike=(("camera_spherical_um", (4, 0)),))
    monkeypatch.setitem(LIBRARY, "fake_camera", fake)
    assert collimator_terms({"camera_spherical_um": 0.1})[(4, 0)] == pytest.approx(0.1)
    assert collimator_terms({"camera_spherical_um": 0.1, "pupil_spherical_um": 0.2})[(4, 0)] == pytest.approx(0.3)
    assert spectrograph_optics("J", {"camera_spherical_um": 0.1}).collimator_zernike_um[(4, 0)] == pytest.approx(0.1)


def test_the_image_models_memo_key_holds_every_spectrograph_parameter():
    """Every non-rescaling parameter that changes a profile or an image, and the
    alternatives' pupil terms, are in the memo key (else a changed value would reuse a
    stale curve)."""
    from pipeline.diagnosis.effects import ALTERNATIVES
    from pipeline.diagnosis.forward import SpectrographImageModel

    want = {q.name for e in LIBRARY.values() if set(e.kinds) & {"line_profile", "psf_image"} and not e.rescales
            for q in e.parameters} | {q.name for e in ALTERNATIVES.values() for q in e.parameters}
    optics, detected = set(SpectrographImageModel._KEYS), set(SpectrographImageModel._DETECTED_NULLS)
    # the detector side's parameters are keyed apart: they act on the memoised optics' profile
    assert optics | detected == want and not optics & detected
    assert {"pupil_x_mm", "coll_astig45_um", "slit_image_width_um", "pupil_coma2_um"} <= optics
    assert {"halo_fraction", "tail_decay_um"} <= detected


def test_a_wing_parameter_changes_the_profile_and_its_null_gives_the_memoised_nominal(tmp_path):
    """A halo changes the line-profile model's prediction; back at zero fraction the
    prediction is the nominal's bit for bit (no stale curve either way)."""
    from optics.sagmap import quilt_sag_map
    from pipeline.diagnosis.forward import ProfileForward
    from diagnosis_cases import gaussian_profile_data

    nominal = quilt_sag_map(0.6, "sum", spacing_mm=0.5)
    data = gaussian_profile_data(tmp_path, nominal, np.arange(-100.0, 100.1, 2.0), 20.0)
    fw = ProfileForward(data, nominal, 80.0)
    nom = fw.predict({})
    halo = fw.predict({"halo_fraction": 0.1, "halo_hwhm_um": 30.0})
    wider = fw.predict({"halo_fraction": 0.1, "halo_hwhm_um": 60.0})
    assert not np.allclose(halo, nom) and not np.allclose(wider, halo)
    assert np.array_equal(fw.predict({"halo_fraction": 0.0, "halo_hwhm_um": 30.0}), nom)
    assert np.array_equal(fw.predict({"halo_fraction": 0.1, "halo_hwhm_um": 30.0}), halo)


def test_a_rescaling_effect_refuses_a_hook_that_does_more_than_rescale():
    from pipeline.diagnosis.effects import Effect, Parameter

    with pytest.raises(ValueError, match="rescales=True allows only"):
        Effect("fake_gain", ("surface",), (Parameter("fake_gain", 1.0, 0.5, 2.0),), rescales=True,
               scale=lambda p, blank: p.get("fake_gain", 1.0), shape=lambda s, x, y, p, quilt: s)
