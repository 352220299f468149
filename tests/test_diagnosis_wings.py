"""The check of a line-profile finding against light the detector side adds
(:mod:`pipeline.diagnosis.wings`). The profiles are made by the independent truth generator
(2-D finite-slit Abbe sum, :mod:`pipeline.diagnosis.truth.abbe`), and the stray-light halo
is written here with numpy (a Lorentzian convolved on the truth's own grid), not with the
check's kernels. Nominal: the analytic sum quilt (no FEA)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from pipeline.diagnosis import diagnose
from pipeline.diagnosis.criteria import Criteria
from pipeline.diagnosis.engine import build_problem, explains
from pipeline.diagnosis.manifest import load_data, load_manifest
from pipeline.diagnosis.ranking import fit_effects
from pipeline.diagnosis.finding import Finding
from pipeline.diagnosis.fitting import FitOutcome
from pipeline.diagnosis.verdict import failed_tests
from pipeline.diagnosis.wings import WINGS_LABEL, WingsCheck, checks, wings_check, with_check
from pipeline.diagnosis.truth.generate import COLLIMATOR_UM
from pipeline.io.registry import read_sag_map

from diagnosis_cases import abbe_profiles_manifest


class _Fw:
    def __init__(self, kind):
        self.kind = kind


class _Prob:
    def __init__(self, *kinds):
        self.forwards = [_Fw(k) for k in kinds]


def test_check_applies_to_findings_on_line_profiles_only():
    f = Finding("pupil_shift", ("pupil_shift",), {}, {}, 0.0, -20.0, 1.0, 0.5, 0.5, 0.75)
    assert checks(_Prob("line_profile", "surface"), f)
    assert not checks(_Prob("surface"), f) and not checks(_Prob("line_profile"), None)
    fo = FitOutcome({}, {}, {}, {}, {}, {}, 0, True, 0, 0.0)
    with pytest.raises(ValueError, match="pupil_shift.*line profile"):
        wings_check(_Prob("surface"), f, fo, Criteria())
    ambiguous = WingsCheck(0.0, 1.0, {}, {}, True, "")
    assert with_check(with_check(f, ambiguous), ambiguous).degenerate_with == (WINGS_LABEL,)
    assert with_check(f, WingsCheck(30.0, 0.0, {}, {}, False, "")) is f
    beside = WingsCheck(30.0, 0.0, {}, {}, False, "", 12.0, True)
    g = with_check(with_check(f, beside), beside)
    assert g.needs_outside == (WINGS_LABEL,) and g.degenerate_with == ()
    sig = replace(f, significant=True, excess_explained=0.9)
    assert explains(sig, Criteria()) and not explains(with_check(sig, beside), Criteria())
    assert failed_tests(with_check(sig, ambiguous), Criteria()) == ("alternative",)
    assert failed_tests(with_check(sig, beside), Criteria()) == ("outside",)


def _halo(fraction, hwhm_um):
    """A Lorentzian halo of ``fraction`` of the flux, on the profile's own grid (numpy)."""
    def distort(u, y):
        lor = hwhm_um / np.pi / (u**2 + hwhm_um**2)
        return (1 - fraction) * y + fraction * np.convolve(y, lor / lor.sum(), mode="same")
    return distort


def _profiles(tmp_path, distortion=None, pupil_shift_mm=(0.0, 0.0), seed=5):
    """J 1.25 µm order -2 profiles at 250, 100 and 25 mas of the nominal blank by the Abbe
    sum with the instrument's collimator, measured with noise, coupling and sub-pixel
    phases, ``distortion`` on the detector."""
    return abbe_profiles_manifest(tmp_path, (250, 100, 25), seed, distortion=distortion,
                                  pupil_shift_mm=pupil_shift_mm, collimator_um=dict(COLLIMATOR_UM))


@pytest.mark.slow
def test_a_stray_light_halo_is_not_blamed_on_the_grating(tmp_path):
    """Truth: the nominal grating and a Lorentzian halo of 5 % of the flux, half width 30 µm.
    A pupil shift fitted to it (the effect the campaign's halos were blamed on) is checked:
    the wings beside the background alone fit as well, so the check is ambiguous. The
    wings' values are not a measurement of the halo: the rule first written here (fraction
    within a factor 2 of the truth's) failed, 0.101 at a half width of 16 µm for 0.05 at
    30 µm, since over a ±126 µm profile a halo's fraction and width trade off; only a halo
    is asserted."""
    path = _profiles(tmp_path, distortion=_halo(0.05, 30.0))
    man = load_manifest(path)
    prob, nom = build_problem(man, load_data(man), read_sag_map(tmp_path / "nominal.npz"))
    f, fo = fit_effects(prob, nom, ("pupil_shift",), Criteria())
    chk = wings_check(prob, f, fo, Criteria())
    assert chk.ambiguous and chk.bic_alternative - chk.bic_joint < Criteria().min_delta_bic
    assert chk.wings_alternative["halo_fraction"] > 0.02
    assert "pupil_shift is not the explanation" in chk.note
    d = diagnose(path, effects=("pupil_shift", "temperature", "slit_width", "quilt_shape"), heldout=False)
    assert d.verdict != "explained"


@pytest.mark.slow
def test_a_pupil_shift_is_still_the_pupils(tmp_path):
    """Truth: a 6 mm beam footprint offset along the dispersion, no wings. The pupil shift
    moves light between the peaks of the quilted line, which no detector kernel does: the
    finding stands, and the note says it is still needed beside the wings. The pupil's x
    position is not pinned to better than a few mm by these profiles: their cost has two
    minima, near 4.0 and 6.6 mm, 0.002 apart against a residual variance of 0.44, and which
    one the fit ends in has differed between machines (the rule first written here, 6 ± 1.5
    mm, passed on one and failed on another). The detector's inter-pixel coupling, a nuisance
    of every profile model, broadens the line as the pupil's x position partly does: with it
    the fit reads 6.9 ± 3.3 mm (2-3 mm sigma without it). Asserted: the truth within the
    reported 1 sigma of the fit, a sigma that spans both minima (> 2 mm) and stays below half
    the prior's ±10 mm (the profiles still say where the pupil is)."""
    d = diagnose(_profiles(tmp_path, pupil_shift_mm=(6.0, 0.0)), effects=("pupil_shift", "temperature",
                                                                          "slit_width", "quilt_shape"),
                 heldout=False)
    assert d.verdict == "explained" and "pupil_shift" in d.best.effects
    assert WINGS_LABEL not in d.best.degenerate_with and d.best.needs_outside == ()
    assert "still needed beside the detector side" in d.ranking_note
    x, sx = d.best.parameters["pupil_x_mm"], d.best.uncertainties["pupil_x_mm"]
    assert abs(x - 6.0) <= sx and 2.0 < sx < 5.0


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="where the check's power ends: a 5 % halo beside an 8 % stronger quilt on "
                                       "three profiles is not seen beside the rescaling")
def test_a_halo_beside_a_stronger_quilt_is_not_all_explained(tmp_path):
    """Truth: the nominal quilt 8 % stronger *and* a Lorentzian halo of 5 % of the flux, half
    width 30 µm (the independent campaign's stray-light cases on quilts with a stronger
    fundamental, where the rescaling took up most of the excess and the halo was left out).
    Expected when written: the amplitude scale is needed, and so are the detector terms beside
    it, so the verdict is not ``explained``. Measured: the amplitude scale (1.079) takes up 95 %
    of the excess and the detector terms beside it change the BIC by +4.6 (seed 5) and -3.1
    (seed 6), short of the 10 they need; a 10 % halo is seen (-11.9). Three profiles at the
    n_eff score do not resolve a 5 % halo beside a rescaling; the campaign's profile sets (six
    profiles) did in one of two such cases."""
    path = abbe_profiles_manifest(tmp_path, (250, 100, 25), 5, distortion=_halo(0.05, 30.0), sag_scale=1.08,
                                  collimator_um=dict(COLLIMATOR_UM))
    d = diagnose(path, effects=("amplitude_scale", "pupil_shift", "temperature", "slit_width", "quilt_shape"),
                 heldout=False)
    assert d.verdict == "unexplained"
    assert WINGS_LABEL in d.best.needs_outside + d.best.degenerate_with


@pytest.mark.slow
def test_a_stronger_quilt_alone_needs_no_wings(tmp_path):
    """The control of the test above: the same 8 % stronger quilt, no halo. The amplitude
    scale explains, within 3 % of the truth, and nothing outside the library is asked for."""
    path = abbe_profiles_manifest(tmp_path, (250, 100, 25), 5, sag_scale=1.08, collimator_um=dict(COLLIMATOR_UM))
    d = diagnose(path, effects=("amplitude_scale", "pupil_shift", "temperature", "slit_width", "quilt_shape"),
                 heldout=False)
    assert d.verdict == "explained" and d.best.effect == "amplitude_scale"
    assert d.best.needs_outside == () and WINGS_LABEL not in d.best.degenerate_with
    scale = next(v for q, v in d.best.parameters.items() if q.startswith("scale_"))
    assert scale == pytest.approx(1.08, rel=0.03)


def _fit_outcome(parameters, rss, deltas_um=None):
    return FitOutcome(dict(parameters), {}, dict(deltas_um or {}), {"m": rss}, {"m": 100}, {"m": 100.0},
                      len(parameters), True, 1, rss)


@pytest.mark.parametrize("alternative_fits_better", [False, True])
def test_the_joint_fit_starts_at_the_optimum_it_nests(monkeypatch, alternative_fits_better):
    """The joint fit (detector terms beside the finding and the background) nests the
    reference (the finding beside the background) and the finding: it starts at the
    lower-objective of their optima, parameters and position nuisances, with the detector
    terms at their nulls, or at the alternative's values where those fit better there (a
    descending fit then never ends above the fit it nests). The reference starts from the
    finding's position nuisances."""
    import pipeline.diagnosis.wings as wings
    from types import SimpleNamespace

    prob = SimpleNamespace(forwards=[SimpleNamespace(kind="line_profile", blank="J", name="m")], weights={"m": 1.0})
    finding = Finding("slit_width", ("slit_width",), {"slit_image_width_um": 30.0}, {}, -100.0, -100.0,
                      1.0, 0.5, 0.5, 0.75)
    fo = _fit_outcome({"slit_image_width_um": 30.0}, 5.0, {"m": 2.0})
    wing_null = {q.name: q.null for q in wings.WINGS_PARAMETERS}
    alt_wings = {"halo_fraction": 0.15, "halo_hwhm_um": 30.0, "tail_fraction": 0.15, "tail_decay_um": 5.0,
                 "blur_um": 3.0, "nonlinearity": 0.0}
    calls = []

    def fake_fit(problem, params, start=None, start_deltas_um=None, regrid=(), max_nfev=None, **kw):
        names = {q.name for q in params}
        calls.append((names, dict(start or {}), start_deltas_um))
        if "halo_fraction" in names and "slit_image_width_um" not in names:  # the alternative
            return _fit_outcome({**{n: 1.0 for n in names}, **alt_wings}, 9.0, {"m": 1.0})
        if "halo_fraction" not in names:  # the reference: the finding and the quilt's shape
            return _fit_outcome({n: start.get(n, 1.0) for n in names} | {"slit_image_width_um": 31.0}, 4.0, {"m": 2.5})
        return _fit_outcome(start, 4.0, start_deltas_um)  # the joint: stays at its start

    def fake_objective(problem, values, deltas_um=None):
        at_null = all(values[n] == v for n, v in wing_null.items())
        return 3.0 if at_null != alternative_fits_better else 4.0

    monkeypatch.setattr(wings, "fit", fake_fit)
    monkeypatch.setattr(wings, "objective", fake_objective)
    wings_check(prob, finding, fo, Criteria())
    (_, _, _), (ref_names, _, ref_deltas), (joint_names, joint_start, joint_deltas) = calls
    assert ref_deltas == {"m": 2.0}  # from the finding's optimum
    assert joint_deltas == {"m": 2.5}  # the reference's: its objective (4.0) is below the finding's (5.0)
    assert joint_start["slit_image_width_um"] == 31.0
    assert {n: joint_start[n] for n in wing_null} == (alt_wings if alternative_fits_better else wing_null)
    assert joint_names == ref_names | set(wing_null)
