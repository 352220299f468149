"""The two-part error model (white noise plus a smooth mismatch; ``Criteria.error_model =
"two_part"``): the split of a residual, the sign rule, and a diagnosis with it."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter1d

from pipeline.diagnosis import diagnose
from pipeline.diagnosis.engine import Criteria
from pipeline.diagnosis.error_model import ERROR_MODELS, SIGN_Z, error_source, model_for_kinds, sign_is_claimed
from pipeline.diagnosis.noise import two_part_errors
from optics.zernike import zernike_xy

from diagnosis_cases import surface_case


def test_two_part_split_of_a_residual():
    """White noise plus Gaussian-filtered noise of filter width s samples: the mismatch's
    integral correlation length is 2 sqrt(pi) s (the integral of its Gaussian
    autocorrelation of width sqrt(2) s); its RMS is what the residual has beyond the noise."""
    x = np.arange(4000.0)
    s = 8.0
    lengths = []
    for seed in range(20):  # the integral-scale estimate scatters by ~15 % at 4000 samples
        rng = np.random.default_rng(seed)
        m = gaussian_filter1d(rng.normal(size=x.size), s)
        m *= 0.03 / m.std()
        e = two_part_errors(m + rng.normal(0.0, 0.01, x.size), x, None, 0.01)
        assert e.sigma_m == pytest.approx(0.03, rel=0.05)
        assert e.long_run_var == pytest.approx(0.01**2 + e.sigma_m**2 * e.corr_samples)
        lengths.append(e.corr_samples)
    assert np.mean(lengths) == pytest.approx(2 * np.sqrt(np.pi) * s, rel=0.1)
    assert min(lengths) > 0.5 * 2 * np.sqrt(np.pi) * s and max(lengths) < 1.5 * 2 * np.sqrt(np.pi) * s
    white = two_part_errors(rng.normal(0.0, 0.01, x.size), x, None, 0.01)
    assert white.sigma_m < 0.003 and white.long_run_var == pytest.approx(1e-4, rel=0.3)
    with pytest.raises(ValueError, match="sigma_w"):
        two_part_errors(m, x, None, float("nan"))


class _Fit:
    def __init__(self, cost):
        self.cost = cost

    def weighted_rss(self, w):
        return self.cost


class _Prob:
    weights = {"a": 1.0}


def test_errors_measured_on_the_best_single():
    """A pair ranked first would take part of the mismatch into its second member and so
    shrink the errors that rank it: the errors come from the best single, whatever pairs
    were tried; a pair only where no single was ranked."""
    from types import SimpleNamespace as F
    pair, single, other = (F(effect="a+b", effects=("a", "b")), F(effect="b", effects=("b",)),
                           F(effect="a", effects=("a",)))
    assert error_source([pair, single, other]) is single
    assert error_source([other, pair]) is other
    assert error_source([pair]) is pair
    assert error_source([]) is None


def test_sign_claimed_only_beyond_what_the_errors_could_do():
    """Flip separation D (chi^2 units): the errors move the flip's cost by 2 sqrt(D) per
    standard deviation; a sign is claimed iff the observed extra cost exceeds SIGN_Z of them."""
    d = np.full(100, 0.5)  # D = 25: the errors move the cost by 10 (1 sigma)
    pred, flip = {"a": np.zeros(100)}, {"a": d}
    assert sign_is_claimed(_Prob(), _Fit(100.0), _Fit(100.0 + 2 * SIGN_Z * 5.0 + 1.0), pred, flip)
    assert not sign_is_claimed(_Prob(), _Fit(100.0), _Fit(100.0 + 2 * SIGN_Z * 5.0 - 1.0), pred, flip)


def test_criteria_error_model_checked():
    with pytest.raises(ValueError, match="error_model"):
        Criteria(error_model="gls")


@pytest.mark.slow
def test_two_part_diagnosis_of_an_astigmatic_map(tmp_path):
    """The same map as test_diagnosis's astigmatism case: the astigmatism is still found and
    recovered; the errors are recorded (the truth's quilt mismatch is smooth: sigma_m > 0)."""
    p = surface_case(tmp_path, lambda x, y: 0.08 * zernike_xy(2, -2, x, y, 68.5))
    d = diagnose(p, criteria=Criteria(error_model="two_part"))
    assert d.verdict == "explained" and "astigmatism" in d.best.effects
    assert d.best.parameters["astig_45_um"] == pytest.approx(0.08, rel=0.1)
    e = d.baseline["errors"]["map"]
    assert e["sigma_w"] == pytest.approx(0.01, rel=0.2) and e["sigma_m"] > 0 and e["corr_samples"] > 1


def test_error_model_by_kind():
    """``by_kind`` is the two-part model where a line profile is measured, the effective
    sample counts elsewhere; the other models are themselves; an unknown name is refused."""
    assert model_for_kinds("by_kind", {"line_profile"}) == "two_part"
    assert model_for_kinds("by_kind", {"line_profile", "surface"}) == "two_part"
    assert model_for_kinds("by_kind", {"surface"}) == "n_eff"
    assert model_for_kinds("by_kind", {"psf_image"}) == "n_eff"
    for m in ("n_eff", "two_part"):
        assert model_for_kinds(m, {"surface"}) == m == model_for_kinds(m, {"line_profile"})
    with pytest.raises(ValueError, match="error_model='gls'"):
        model_for_kinds("gls", {"surface"})


def test_cli_offers_every_error_model(capsys):
    """The CLI's choices (a literal, to keep ``cryograting --help`` free of the diagnosis's
    imports) are the engine's models: each is accepted, another name is refused."""
    import argparse

    from pipeline.diagnosis.cli import register

    sub = argparse.ArgumentParser().add_subparsers()
    p = register(sub)
    for m in ERROR_MODELS:
        assert p.parse_args(["m.toml", "--out", "o", "--error-model", m]).error_model == m
    with pytest.raises(SystemExit):
        p.parse_args(["m.toml", "--out", "o", "--error-model", "gls"])
    assert "invalid choice: 'gls'" in capsys.readouterr().err


@pytest.mark.slow
def test_by_kind_diagnosis_of_a_map_is_the_n_eff_one(tmp_path):
    """A map alone under ``by_kind``: the same findings as ``n_eff``, and the record says
    which model scored it."""
    p = surface_case(tmp_path, lambda x, y: 0.08 * zernike_xy(2, -2, x, y, 68.5))
    a = diagnose(p, criteria=Criteria(error_model="by_kind"), heldout=False)
    b = diagnose(p, criteria=Criteria(), heldout=False)
    assert a.baseline["error_model"] == "by_kind" and a.baseline["error_model_used"] == "n_eff"
    assert [(f.effect, f.delta_bic) for f in a.findings] == [(f.effect, f.delta_bic) for f in b.findings]
    assert a.baseline["errors"] == {}


def test_other_basin_moves_span_minima_inside_one_s2():
    """A second minimum within s^2 of the best widens the uncertainty by its distance; one
    beyond it, or the best itself, adds nothing (Wilks: delta chi^2 = 1 bounds the 68 %
    region of one parameter)."""
    from pipeline.diagnosis.fitting import other_basin_moves

    minima = [(30.62, np.array([0.40, 0.0])), (30.619, np.array([0.66, 0.1])), (31.5, np.array([-0.7, 3.0]))]
    np.testing.assert_allclose(other_basin_moves(minima, s2=0.44), [0.26, 0.1])
    np.testing.assert_allclose(other_basin_moves(minima, s2=2.0), [1.36, 2.9])
    np.testing.assert_allclose(other_basin_moves(minima[:1], s2=0.44), [0.0, 0.0])


@pytest.mark.slow
def test_each_two_part_pass_starts_from_the_pass_before(tmp_path, monkeypatch):
    """Under the two-part error model a re-weighted pass refits every model. A fit's residual
    per measurement does not depend on the weights, so every fit of the pass before is a point
    of the new objective: no fit of the new pass may end above one it holds (J profiles of a
    6 mm pupil shift, whose weights move after the first pass)."""
    import pipeline.diagnosis.engine as engine

    from diagnosis_cases import profile_image_case

    calls, real = [], engine.rank

    def recording(prob, nom, cands, criteria, memo, warm=()):
        out = real(prob, nom, cands, criteria, memo, warm)
        calls.append((prob, out[1], out[2], warm))
        return out

    monkeypatch.setattr(engine, "rank", recording)
    p = profile_image_case(tmp_path, {"pupil_x_mm": 6.0, "pupil_y_mm": 1.0}, psf=False)
    diagnose(p, criteria=Criteria(error_model="two_part"), heldout=False)
    assert len(calls) >= 2  # the weights moved: a second pass ran

    def every_fit(fits, joint_fits):
        return list(fits.values()) + [fo for tried in joint_fits.values() for _, fo in tried]

    for (_, fits0, joint0, _), (prob, fits1, joint1, warm) in zip(calls, calls[1:]):
        before = every_fit(fits0, joint0)
        assert all(any(b is w for w in warm) for b in before)
        w = prob.weights
        for fo in every_fit(fits1, joint1):
            held = [b.weighted_rss(w) for b in before if b.parameters and set(b.parameters) <= set(fo.parameters)]
            if held:
                assert fo.weighted_rss(w) <= min(held) * (1 + 1e-6)
