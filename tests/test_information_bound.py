"""``benchmarks/information_bound.py``: the Cramér–Rao covariance of a linear model is the
analytic one (white and correlated noise), and the chance of a reading within the campaign's
20 % rule is the Gaussian integral (a signed parameter, and one compared by magnitude)."""

from __future__ import annotations

import importlib.util
import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from pipeline.diagnosis.noise import CorrelatedNoise

ROOT = Path(__file__).resolve().parents[1]


def _module():
    spec = importlib.util.spec_from_file_location("information_bound", ROOT / "benchmarks" / "information_bound.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


class _Linear:
    """A forward whose residual is ``d - A p - slope * delta``: its information is analytic."""

    kind, n_shift, delta0_um = "line_profile", 1, 0.0

    def __init__(self, name, A, slope, names, correlated_noise=None):
        self.name, self.A, self.slope, self.names = name, A, slope, names
        self.x = np.linspace(-60.0, 60.0, A.shape[0])
        self.correlated_noise = correlated_noise

    def residual(self, p, delta_um=0.0, mask=None):
        return -(self.A @ np.array([p[n] for n in self.names]) + self.slope * delta_um)


@pytest.mark.parametrize("correlated", [False, True])
def test_linear_model_bound_is_the_analytic_covariance(correlated):
    mod = _module()
    rng = np.random.default_rng(3)
    n, names = 80, ["a_um", "b_um"]
    A, slope = rng.normal(size=(n, 2)), rng.normal(size=n)
    cn = CorrelatedNoise(0.02, 8.0) if correlated else None
    fw = _Linear("J_1.25_25mas", A, slope, names, cn)
    sigma_w = 0.01
    prob = SimpleNamespace(forwards=[fw], noise={fw.name: sigma_w})
    params = [SimpleNamespace(name=n_, width=1.0) for n_ in names]
    cov = mod.fisher_sigma(prob, params, {"a_um": 0.1, "b_um": -0.2}, {fw.name: 0.0})
    C = sigma_w**2 * np.eye(n) + (cn.rms_rel**2 * cn.correlation(fw.x) if cn else 0.0)
    X = np.column_stack([A, slope])  # the offset shift marginalised beside the parameters
    expected = np.linalg.inv(X.T @ np.linalg.solve(C, X))[:2, :2]
    np.testing.assert_allclose(cov, expected, rtol=1e-6)
    # ``--white-only``: a stated correlated noise is left out of the covariance
    white = mod.fisher_sigma(prob, params, {"a_um": 0.1, "b_um": -0.2}, {fw.name: 0.0}, correlated=False)
    np.testing.assert_allclose(white, sigma_w**2 * np.linalg.inv(X.T @ X)[:2, :2], rtol=1e-6)


def test_within_rate_is_the_gaussian_integral():
    mod = _module()
    rng = np.random.default_rng(5)
    # a signed parameter: |x - t| <= 0.2 |t| with x ~ N(t, sigma)
    p = mod.within_rate({"pupil_x_mm": 5.0}, ["pupil_x_mm"], np.array([[0.5**2]]), set(), rng, 200_000)
    assert p == pytest.approx(math.erf(1.0 / (0.5 * math.sqrt(2))), abs=0.005)
    # compared by magnitude about 0, window 0.2 x the 3 mm floor: ||x| - t| <= 0.6 <=> |x| <= 0.7
    p = mod.within_rate({"pupil_y_mm": 0.1}, ["pupil_y_mm"], np.array([[1.0]]), {"pupil_y_mm"}, rng, 200_000)
    assert p == pytest.approx(math.erf(0.7 / math.sqrt(2)), abs=0.005)


def test_too_few_draws_are_refused_by_name(capsys):
    mod = _module()
    with pytest.raises(SystemExit):
        mod.main([str(ROOT / "benchmarks" / "frozen_repeat_draw_raw.json"), "--out", "unused.json", "--draws", "0"])
    err = capsys.readouterr().err
    assert "--draws=0" in err and "valid: >= 100" in err
