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
