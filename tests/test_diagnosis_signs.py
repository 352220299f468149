"""Identifiability of signs, and the pair search's slots.

Signs: line profiles integrate along the slit and the pupil is mirror-symmetric in eta,
so for a y-symmetric grating the mirror eta -> -eta changes only the sign of the total
oblique astigmatism Z(2,-2) (the default collimator's term plus the fitted extra one):
the profiles depend on that total through its square, and the sign the data cannot tell
is that of the total, not of the extra term."""

from __future__ import annotations

import numpy as np
import pytest

from optics.pupil import DEFAULT_COLLIMATOR_ZERNIKE_UM
from optics.sagmap import quilt_sag_map
from pipeline.diagnosis import diagnose
from pipeline.diagnosis.campaign import recovery_errors
from pipeline.diagnosis.criteria import Criteria
from pipeline.diagnosis.effects import parameter_spec
from pipeline.diagnosis.forward import profile_curve
from pipeline.diagnosis.ranking import pair_singles, pairs_to_fit

from diagnosis_cases import FakeDiagnosis, FakeFinding, profile_image_case, single_finding

#: The extra Z(2,-2) at which the total vanishes: the default collimator's term, negated.
ASTIG_ORIGIN_UM = -DEFAULT_COLLIMATOR_ZERNIKE_UM[(2, -2)]


def test_profiles_see_the_total_oblique_astigmatism_through_its_square():
    """On a y-symmetric quilt, extra astigmatism ``a`` and ``2 o - a`` (total Z(2,-2) +t and
    -t) give the same profile to rounding; ``a`` and ``-a`` (totals of different size) differ
    by several percent of the peak, far above a 1 % noise."""
    sag = quilt_sag_map(0.6, "sum", spacing_mm=0.5)
    X, Y = sag.grid()
    assert np.array_equal(sag.sag_um, sag.sample(X, -Y))  # the premise: y-symmetric grating
    assert parameter_spec("coll_astig45_um").origin == pytest.approx(ASTIG_ORIGIN_UM)
    base = {"coll_coma_um": 0.1, "coll_defocus_um": 0.05}
    for a in (-0.3, 0.4):
        _, p = profile_curve("J", 1.25, -2, 250, sag, {**base, "coll_astig45_um": a})
        _, mirror = profile_curve("J", 1.25, -2, 250, sag, {**base, "coll_astig45_um": 2 * ASTIG_ORIGIN_UM - a})
        _, minus = profile_curve("J", 1.25, -2, 250, sag, {**base, "coll_astig45_um": -a})
        assert np.max(np.abs(p - mirror)) < 1e-9 * p.max()
        assert np.max(np.abs(p - minus)) > 0.02 * p.max()


@pytest.mark.slow
@pytest.mark.parametrize("astig45_um", [-0.3, 0.4])
def test_sign_of_oblique_astigmatism_on_profiles_is_flagged(tmp_path, astig45_um):
    """Profiles of a truth with extra astigmatism ``astig45_um`` (noisy, shifted, scaled,
    with a background): the data are the same for the mirrored total, so the engine must
    report that sign undetermined — also at the prior bound (0.4 µm, whose mirror lies
    beyond the prior). The coma's sign is seen (the profile's left-right asymmetry)."""
    truth = {"coll_coma_um": 0.1, "coll_defocus_um": 0.05, "coll_astig45_um": astig45_um}
    d = diagnose(profile_image_case(tmp_path, truth, psf=False), effects=("collimator_wfe",), heldout=False)
    f = d.finding("collimator_wfe")
    assert "coll_astig45_um" in f.sign_degenerate
    assert "coll_coma_um" not in f.sign_degenerate
    fitted_total = f.parameters["coll_astig45_um"] - ASTIG_ORIGIN_UM
    assert abs(fitted_total) == pytest.approx(abs(astig45_um - ASTIG_ORIGIN_UM), abs=0.1)


def test_campaign_scores_an_undetermined_sign_by_the_total_magnitude():
    """A sign-degenerate astigmatism fitted at the mirror of the truth (same |total|) is
    recovered; the same fit without the flag is scored as the wrong value it is."""
    truth = {"coll_coma_um": 0.10, "coll_defocus_um": 0.05, "coll_astig45_um": -0.30}
    fit = {**truth, "coll_astig45_um": 2 * ASTIG_ORIGIN_UM + 0.30 + 0.01}  # mirror, 0.01 µm off in size
    sig = dict.fromkeys(fit, 0.02)
    flagged = recovery_errors(FakeDiagnosis("collimator_wfe", FakeFinding(fit, sig, ["coll_astig45_um"])),
                              "collimator_wfe", truth)
    silent = recovery_errors(FakeDiagnosis("collimator_wfe", FakeFinding(fit, sig)), "collimator_wfe", truth)
    assert flagged["per_parameter"] == pytest.approx(0.01 / 0.30) and flagged["within_2sigma"]
    assert silent["per_parameter"] == pytest.approx(abs(fit["coll_astig45_um"] + 0.30) / 0.30)
    assert not silent["within_2sigma"]


def test_pair_slots_keep_one_rescaling_effect():
    """temperature and amplitude_scale rescale the same deformation (their pair is never
    fitted): with both among the three best singles, only the better one takes a slot and
    the next effect gets the third, so a real pair can be formed. Background-only and
    not-significant singles take none."""
    findings = [single_finding("temperature", -120.0), single_finding("amplitude_scale", -119.0), single_finding("pupil_shift", -90.0),
                single_finding("collimator_wfe", -80.0), single_finding("slit_width", -200.0, significant=False),
                single_finding("quilt_shape", -300.0)]
    chosen = [f.effect for f in pair_singles(findings, 3)]
    assert chosen == ["temperature", "pupil_shift", "collimator_wfe"]
    assert [f.effect for f in pair_singles(findings, 1)] == ["temperature"]
    findings[1] = single_finding("amplitude_scale", -130.0)  # the better rescaling one is kept, whichever it is
    assert [f.effect for f in pair_singles(findings, 3)] == ["amplitude_scale", "pupil_shift", "collimator_wfe"]


def test_pairs_are_formed_among_the_best_and_from_the_best_with_every_other():
    """Pairs among the ``n`` best eligible singles, and the best one with each further
    eligible single (one forward-selection step), better single first; none for n < 2;
    the second rescaling effect, background-only and not-significant singles never pair."""
    findings = [single_finding("temperature", -120.0), single_finding("amplitude_scale", -130.0), single_finding("pupil_shift", -40.0),
                single_finding("collimator_wfe", -80.0), single_finding("slit_width", -90.0), single_finding("quilt_shape", -500.0),
                single_finding("blank_bow", -10.0, significant=False)]
    pairs = [(a.effect, b.effect) for a, b in pairs_to_fit(findings, 2, forward=True)]
    assert pairs == [("amplitude_scale", "slit_width"), ("amplitude_scale", "collimator_wfe"),
                     ("amplitude_scale", "pupil_shift")]
    pairs3 = [(a.effect, b.effect) for a, b in pairs_to_fit(findings, 3, forward=True)]
    assert pairs3[:3] == [("amplitude_scale", "slit_width"), ("amplitude_scale", "collimator_wfe"),
                          ("slit_width", "collimator_wfe")]
    assert pairs3[3:] == [("amplitude_scale", "pupil_shift")]
    assert pairs_to_fit(findings, 1, forward=True) == [] and pairs_to_fit(findings[:1], 3, forward=True) == []
    assert [(a.effect, b.effect) for a, b in pairs_to_fit(findings, 3)] == pairs3[:3]  # default: no forward step
    # The forward step adds no rescaling: it pairs the best single with a rescaling only
    # from among the n best.
    findings[2] = single_finding("pupil_shift", -140.0)
    assert [(a.effect, b.effect) for a, b in pairs_to_fit(findings, 2, forward=True)] == [
        ("pupil_shift", "amplitude_scale"), ("pupil_shift", "slit_width"), ("pupil_shift", "collimator_wfe")]
    findings[0], findings[1] = single_finding("temperature", -20.0), single_finding("amplitude_scale", -60.0)
    assert [(a.effect, b.effect) for a, b in pairs_to_fit(findings, 2, forward=True)] == [
        ("pupil_shift", "slit_width"), ("pupil_shift", "collimator_wfe")]


def test_the_forward_step_can_pair_the_best_with_every_single_that_lowers_the_bic():
    """``pair_second = "improving"``: the best single is also paired with each further single
    that lowers the BIC at all, significant or not (best first, each pair once); a single
    that raises it, a rescaling and a background-only single still never pair."""
    findings = [single_finding("amplitude_scale", -130.0), single_finding("slit_width", -90.0),
                single_finding("pupil_shift", -4.6, significant=False), single_finding("collimator_wfe", -80.0),
                single_finding("temperature", -129.0), single_finding("plating_gradient", 3.0, significant=False),
                single_finding("quilt_shape", -7.0, significant=False), single_finding("registration", -2.0, significant=False)]
    significant = [(a.effect, b.effect) for a, b in pairs_to_fit(findings, 2, forward=True)]
    assert significant == [("amplitude_scale", "slit_width"), ("amplitude_scale", "collimator_wfe")]
    improving = [(a.effect, b.effect) for a, b in pairs_to_fit(findings, 2, forward=True, second="improving")]
    assert improving == significant + [("amplitude_scale", "pupil_shift"), ("amplitude_scale", "registration")]
    assert [(a.effect, b.effect) for a, b in pairs_to_fit(findings, 2, second="improving")] == significant[:1]
    assert pairs_to_fit(findings[2:3], 2, forward=True, second="improving") == []  # no significant best


def test_pair_second_is_checked():
    with pytest.raises(ValueError, match="pair_second='all'.*significant"):
        Criteria(pair_second="all")


def test_a_temperature_whose_mirror_has_no_physical_state_keeps_its_sign(tmp_path):
    """Profiles of a blank deformed to 0.67x (a warmer grating: the temperature fit lands
    near +70 K above the stated 80 K). Its sign test mirrors the offset about 0, to a few K
    above absolute zero, below the materials' strain data: no state of the other sign
    exists, so the sign stands and the diagnosis is made (it used to be refused with the
    materials' range error)."""
    d = diagnose(profile_image_case(tmp_path, {}, psf=False, scale=0.67), effects=("temperature",), heldout=False)
    f = d.finding("temperature")
    assert f.parameters["temperature_offset_K"] > 40.0
    assert "temperature_offset_K" not in f.sign_degenerate


class _Bump:
    """A map-kind forward: a line of amplitude ``a`` at position ``b_mm`` (width 0.5 mm)
    on a 20 mm axis. Far from the data's bump the cost is flat in ``b_mm``: a warm start
    there is a wrong basin a local fit cannot leave."""

    kind, n_shift, nuisance_count, delta0_um = "surface", 0, 0, 0.0

    def __init__(self, a, b_mm):
        self.name = "m"
        self.x = np.linspace(-10.0, 10.0, 401)
        self.n = self.x.size
        self.y = self._model(a, b_mm)

    def _model(self, a, b_mm):
        return a * np.exp(-0.5 * ((self.x - b_mm) / 0.5) ** 2)

    def residual(self, p, delta_um=0.0, mask=None):
        r = self.y - self._model(p["a"], p["b_mm"])
        return r if mask is None else r[mask]


def test_regrid_leaves_a_warm_starts_wrong_basin():
    """``fit(start=..., regrid=...)``: a warm start in a flat wrong basin stays there; with the
    parameter re-gridded beside it the grid point nearest the truth wins."""
    from pipeline.diagnosis.effects.base import Parameter
    from pipeline.diagnosis.fitting import Problem, fit

    f = _Bump(1.5, 4.0)
    prob = Problem([f], {"m": 1.0}, {"m": float(f.n)})
    params = (Parameter("a", 1.0, 0.0, 3.0, starts=(1.0,)),
              Parameter("b_mm", 0.0, -10.0, 10.0, starts=(-8.0, -4.0, 0.0, 4.2, 8.0)))
    warm = {"a": 1.0, "b_mm": -9.0}
    stuck = fit(prob, params, start=warm)
    assert abs(stuck.parameters["b_mm"] + 9.0) < 1.0
    freed = fit(prob, params, start=warm, regrid=("b_mm",))
    assert freed.parameters["b_mm"] == pytest.approx(4.0, abs=1e-3)
    assert freed.parameters["a"] == pytest.approx(1.5, abs=1e-3)
