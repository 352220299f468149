"""The check of a collimator finding against pupil aberrations of other orders
(:mod:`pipeline.diagnosis.pupil_orders`): the profiles are made by the independent truth
generator (2-D finite-slit Abbe sum, :mod:`pipeline.diagnosis.truth.abbe`), which shares
no code with the engine's forward model. Nominal: the analytic sum quilt (no FEA)."""

from __future__ import annotations

import math

import pytest

from pipeline.diagnosis import diagnose
from pipeline.diagnosis.criteria import Criteria
from pipeline.diagnosis.finding import Finding
from pipeline.diagnosis.fitting import FitOutcome
from pipeline.diagnosis.effects.pupil_other_orders import PUPIL_OTHER_ORDERS
from pipeline.diagnosis.forward import collimator_terms
from pipeline.diagnosis.pupil_orders import OTHER_ORDERS_LABEL, PupilOrdersCheck, checks, other_orders_check, with_check
from pipeline.diagnosis.truth.generate import COLLIMATOR_UM

from diagnosis_cases import abbe_profiles_manifest


def _profiles(tmp_path, camera_um=None, collimator_extra_um=None, seed=3):
    """J 1.25 µm order -2 profiles at 250 and 25 mas of the nominal blank, made by the
    independent truth with the instrument's collimator plus ``collimator_extra_um`` and a
    camera wavefront ``camera_um`` ({(n, m): µm RMS}); measured with photon and read
    noise, background, sub-pixel phases (:func:`.truth.detector.measure_profile`)."""
    coll = dict(COLLIMATOR_UM)
    for nm, v in (collimator_extra_um or {}).items():
        coll[nm] = coll.get(nm, 0.0) + v
    return abbe_profiles_manifest(tmp_path, (250, 25), seed, collimator_um=coll, camera_um=camera_um)


def test_other_order_terms_reach_the_pupil_and_are_not_the_collimators():
    terms = collimator_terms({"pupil_spherical_um": 0.2, "coll_coma_um": 0.1})
    assert terms[(4, 0)] == 0.2
    assert {nm for _, nm in PUPIL_OTHER_ORDERS.pupil_zernike}.isdisjoint({(3, 1), (2, 0), (2, -2)})
    assert {nm: v for nm, v in collimator_terms({}).items() if v} == COLLIMATOR_UM


def test_check_applies_only_to_collimator_findings():
    f = Finding("slit_width", ("slit_width",), {}, {}, 0.0, -20.0, 1.0, 0.5, 0.5, 0.75)
    assert not checks(f) and not checks(None)
    assert checks(Finding("slit_width", ("slit_width",), {}, {}, 0.0, -20.0, 1.0, 0.5, 0.5, 0.75,
                          companions=("collimator_wfe",)))
    fo = FitOutcome({}, {}, {}, {}, {}, {}, 0, True, 0, 0.0)
    with pytest.raises(ValueError, match="slit_width.*collimator_wfe"):
        other_orders_check(None, f, fo, Criteria())
    ambiguous = PupilOrdersCheck(0.0, 1.0, {}, True, "")
    g = with_check(with_check(f, ambiguous), ambiguous)
    assert g.degenerate_with == (OTHER_ORDERS_LABEL,)
    assert with_check(f, PupilOrdersCheck(0.0, 30.0, {}, False, "")) is f
    assert PupilOrdersCheck(0.0, 30.0, {"pupil_spherical_um": 0.1}, False, "text", 24.3).summary() == {
        "bic_finding": 0.0, "bic_other_orders": 30.0, "parameters": {"pupil_spherical_um": 0.1},
        "ambiguous": False, "score_equal_count": 24.3}


@pytest.mark.slow
def test_camera_spherical_is_not_blamed_on_the_collimator(tmp_path):
    """Truth: only primary spherical Z(4,0), 0.3 µm RMS, in the pupil (beyond the
    instrument's collimator). The three collimator terms take up part of it (without the
    check: collimator_wfe, delta BIC about -31, "explained"); the other-order basis fits
    the spherical itself, so the data cannot say the aberration is the collimator's. Beside
    the detector's inter-pixel coupling (a nuisance of every profile model, which takes up
    part of the spherical's broadening) the collimator terms are not even significant
    (measured: delta BIC +2.4, verdict ``unexplained``); where they are, the check must
    flag them."""
    d = diagnose(_profiles(tmp_path, camera_um={(4, 0): 0.3}), effects=("collimator_wfe", "slit_width"),
                 heldout=False)
    assert d.verdict != "explained"
    f = d.finding("collimator_wfe")
    assert not f.significant or OTHER_ORDERS_LABEL in f.degenerate_with


@pytest.mark.slow
def test_collimator_coma_is_still_the_collimators(tmp_path):
    """Truth: extra collimator coma Z(3,1) -0.2 µm RMS. The 250 mas profile's tall
    illuminated pupil tells coma from trefoil and secondary coma: the finding stands."""
    d = diagnose(_profiles(tmp_path, collimator_extra_um={(3, 1): -0.2}), effects=("collimator_wfe", "slit_width"),
                 heldout=False)
    assert d.verdict == "explained" and "collimator_wfe" in d.best.effects
    assert OTHER_ORDERS_LABEL not in d.best.degenerate_with
    assert d.best.parameters["coll_coma_um"] == pytest.approx(-0.2, abs=0.05)
    # the check's outcome is recorded although it changed nothing; its four terms pay one
    # parameter more than the collimator's three, one log N_eff of BIC the likelihood alone does not
    check = d.to_dict()["checks"]["pupil_orders"]
    assert not check["ambiguous"]
    extra = check["bic_other_orders"] - check["bic_finding"] - check["score_equal_count"]
    assert extra == pytest.approx(math.log(sum(d.baseline["n_count"].values())), rel=1e-6)
