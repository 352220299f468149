"""The quilt's amplitude as a companion of every finding: a real quilt's amplitude is never
exactly the simulation's, so beside an effect that does not rescale the deformation the best
rescaling is tried as a companion, as the quilt's shape is (:mod:`pipeline.diagnosis.ranking`)."""

from __future__ import annotations

from types import SimpleNamespace

import pytest

from pipeline.diagnosis import diagnose, ranking
from pipeline.diagnosis.criteria import Criteria
from pipeline.diagnosis.effects import LIBRARY
from pipeline.diagnosis.finding import Finding
from pipeline.diagnosis.fitting import FitOutcome
from pipeline.diagnosis.forward import deformation_factor
from pipeline.diagnosis.ranking import NESTED_RTOL, best_rescaling, rank_key, restart_from_nested
from pipeline.diagnosis.truth.generate import COLLIMATOR_UM

from diagnosis_cases import abbe_profiles_manifest, single_finding


def test_best_rescaling_is_the_rescaling_single_with_the_lowest_bic_that_lowers_it():
    findings = [single_finding("pupil_shift", -300.0), single_finding("temperature", -40.0), single_finding("amplitude_scale", -45.0),
                Finding("amplitude_scale+pupil_shift", ("amplitude_scale", "pupil_shift"), {}, {}, -400.0, -400.0,
                        1.0, 1.0, 0.0, 0.0)]
    assert best_rescaling(findings) == "amplitude_scale"
    findings[1] = single_finding("temperature", -50.0)
    assert best_rescaling(findings) == "temperature"
    assert best_rescaling([single_finding("pupil_shift", -300.0), single_finding("temperature", 3.0)]) is None  # raises the BIC
    assert best_rescaling([single_finding("pupil_shift", -300.0)]) is None


def test_a_rescaling_companion_ranks_as_a_second_claimed_change():
    c = Criteria()
    plain = single_finding("collimator_wfe", -100.0, companions=("quilt_shape",))
    rescaled = single_finding("collimator_wfe", -100.0, companions=("quilt_shape", "amplitude_scale"))
    pair = Finding("amplitude_scale+collimator_wfe", ("amplitude_scale", "collimator_wfe"), {}, {}, -100.0, -100.0,
                   1.0, 1.0, 0.0, 0.0)
    assert rank_key(plain, c) == -100.0
    assert rank_key(rescaled, c) == rank_key(pair, c) == -100.0 + c.pair_extra_bic
    assert all(LIBRARY[e].rescales for e in ("amplitude_scale", "temperature"))


def test_a_single_beside_a_rescaling_and_the_pair_with_it_are_one_model_listed_once():
    # slit width on a 1.127x quilt (rescaling companion's frozen run, case 26): the pair and the
    # single beside the amplitude companion fit the same four parameters
    pair = Finding("amplitude_scale+slit_width", ("amplitude_scale", "slit_width"), {}, {}, -90.0, -90.0,
                   1.0, 1.0, 0.0, 0.0, companions=("quilt_shape",))
    same = single_finding("slit_width", -89.5, companions=("quilt_shape", "amplitude_scale"))
    other = single_finding("slit_width", -60.0, companions=("quilt_shape", "temperature"))
    plain = single_finding("pupil_shift", -70.0, companions=("quilt_shape",))
    assert ranking.model_of(pair) == ranking.model_of(same) == {"amplitude_scale", "slit_width", "quilt_shape"}
    kept = ranking.one_model_each([pair, plain, same, other])
    assert kept == [plain, same, other]  # the single with its companion kept, wherever it ranks; order unchanged
    assert ranking.one_model_each([same, pair]) == [same]
    twin = single_finding("slit_width", -89.0, companions=("amplitude_scale", "quilt_shape"))
    assert ranking.one_model_each([same, twin]) == [same]  # among equals, the better-ranked


def test_rescaling_companion_is_checked():
    with pytest.raises(ValueError, match="rescaling_companion=1"):
        Criteria(rescaling_companion=1)


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="where the rescaling companion does not reach: it is tried beside the findings "
                   "step 5 refits (the two best, and every single where a companion alone is significant); this "
                   "collimator error alone lowers the BIC by 3.5 (not significant) beside a quilt amplitude it cannot "
                   "take up, so it is neither paired nor refitted and the amplitude alone is named (1.112). The pair "
                   "the wider pair search forms reads 1.121, coma -0.256 and defocus -0.138 µm at delta BIC -141 "
                   "against -68")
def test_a_collimator_error_on_a_stronger_quilt_carries_the_quilts_amplitude(tmp_path):
    """Profiles at 250, 100 and 25 mas made by the independent truth's 2-D Abbe sum of a quilt
    1.12 x the simulation's with a collimator error of the campaign's size (-0.25 µm coma,
    -0.15 µm defocus beyond the instrument's own). Rule fixed before the first run: the best
    finding is ``collimator_wfe`` with a rescaling companion whose deformation factor is within
    the amplitude's floor (0.05) of the truth's 1.12, and the coma within 20 % of the truth's."""
    coll = dict(COLLIMATOR_UM)
    coll[(2, 0)] = coll.get((2, 0), 0.0) - 0.15
    coll[(3, 1)] = coll.get((3, 1), 0.0) - 0.25
    path = abbe_profiles_manifest(tmp_path, (250, 100, 25), 21, collimator_um=coll, sag_scale=1.12)
    d = diagnose(path, heldout=False)
    b = d.best
    assert b.effects == ("collimator_wfe",), b.effect
    assert any(LIBRARY[c].rescales for c in b.companions), b.companions
    assert deformation_factor(b.parameters, "J", 80.0, 80.0) == pytest.approx(1.12, abs=0.05)
    assert b.parameters["coll_coma_um"] == pytest.approx(-0.25, rel=0.2)


def _outcome(parameters, rss, deltas_um=None):
    return FitOutcome(dict(parameters), {}, dict(deltas_um or {}), {"m": rss}, {"m": 100}, {"m": 100.0},
                      len(parameters), True, 1, rss)


def test_a_joint_fit_that_ends_above_the_fit_it_nests_is_restarted_from_it(monkeypatch):
    """A joint fit nests each fit of a subset of its effects (the others at their nulls), so
    its optimum is never worse; a local fit from a combined start can be. Then it is fitted
    again from the nested fit with the other parameters at their nulls, and the better of
    the two kept; otherwise, or with nothing nested, the fit is left alone (no extra fit)."""
    params = LIBRARY["collimator_wfe"].parameters + LIBRARY["temperature"].parameters
    prob = SimpleNamespace(weights={"m": 1.0})
    member = _outcome({"coll_coma_um": 0.2, "coll_defocus_um": 0.1, "coll_astig45_um": 0.0}, 4.0, {"m": 2.5})
    combined = _outcome({q.name: 0.0 for q in params}, 9.0)
    starts = []

    def fake_fit(problem, ps, start=None, start_deltas_um=None, **kw):
        starts.append((dict(start), start_deltas_um))
        return _outcome(start, 3.0)
    monkeypatch.setattr(ranking, "fit", fake_fit)
    kept = restart_from_nested(prob, params, combined, (member, _outcome({}, 50.0)))
    assert kept.weighted_rss(prob.weights) == 3.0
    offset = next(q for q in params if q.name == "temperature_offset_K")
    assert starts == [({**member.parameters, offset.name: offset.null}, {"m": 2.5})]  # at the member's optimum
    below = _outcome({q.name: 0.0 for q in params}, 4.0 * (1 + NESTED_RTOL / 2))
    assert restart_from_nested(prob, params, below, (member,)) is below
    assert restart_from_nested(prob, params, combined, ()) is combined
    assert len(starts) == 1

    def worse_fit(problem, ps, start=None, **kw):
        return _outcome(start, 12.0)
    monkeypatch.setattr(ranking, "fit", worse_fit)
    assert restart_from_nested(prob, params, combined, (member,)) is combined  # the restart did no better
