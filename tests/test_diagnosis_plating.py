"""The plating_gradient effect (alone and as a companion of other effects) and the
model-mismatch inflation of the uncertainties. Nominal: the analytic sum quilt (no FEA)."""

from __future__ import annotations

import numpy as np
import pytest

from optics.zernike import zernike_xy
from pipeline.diagnosis import diagnose
from pipeline.diagnosis.effects import LIBRARY
from pipeline.diagnosis.fitting import Problem, long_run_s2
from pipeline.diagnosis.nominal import thermal_factor
from pipeline.diagnosis.synth import blank_shape_map, synthetic_surface
from pipeline.io.registry import write_sag_map

from diagnosis_cases import nominal_map, surface_manifest


def _gradient_map(tmp_path, gx, gy, extra=None, seed=5, noise_um=0.002):
    nom = nominal_map(tmp_path)
    t = blank_shape_map(nom.scaled(thermal_factor(128, 80)), {"plating_grad_x": gx, "plating_grad_y": gy})
    write_sag_map(synthetic_surface(t, np.random.default_rng(seed), extra_um=extra, noise_um=noise_um), tmp_path / "map.npz")
    return surface_manifest(tmp_path)


def test_library_keeps_names_and_adds_plating_gradient():
    assert {"astigmatism", "amplitude_scale", "temperature", "registration", "pupil_shift", "collimator_wfe",
            "slit_width", "plating_gradient"} <= set(LIBRARY)
    e = LIBRARY["plating_gradient"]
    assert e.companion and set(e.kinds) == {"surface", "line_profile", "psf_image"}
    assert [q.name for q in e.parameters] == ["plating_grad_x", "plating_grad_y"]


def test_plating_gradient_alone_recovered(tmp_path):
    """Injection-recovery of the gradient alone (6 % across x, -4 % across y)."""
    d = diagnose(_gradient_map(tmp_path, 0.06, -0.04))
    assert d.verdict == "explained" and d.best.effect == "plating_gradient"
    assert d.best.parameters["plating_grad_x"] == pytest.approx(0.06, rel=0.2)
    assert d.best.parameters["plating_grad_y"] == pytest.approx(-0.04, rel=0.2)
    assert abs(d.best.parameters["plating_grad_x"] - 0.06) < 3 * d.best.uncertainties["plating_grad_x"] + 0.005


def test_gradient_is_fitted_as_companion_of_the_best_effect(tmp_path):
    """Astigmatism injected on a blank with a 5 % plating gradient: the astigmatism ranks
    first, the gradient is fitted alongside it (listed in ``companions``), and the
    astigmatism's parameters come from the joint fit."""
    c0 = 0.06
    d = diagnose(_gradient_map(tmp_path, 0.0, 0.05, lambda x, y: c0 * zernike_xy(2, 2, x, y, 68.5)))
    assert d.verdict == "explained" and d.best.effect == "astigmatism"
    assert d.best.companions == ("plating_gradient",)
    assert d.best.parameters["astig_0_um"] == pytest.approx(c0, rel=0.1)
    assert d.best.parameters["plating_grad_y"] == pytest.approx(0.05, rel=0.2)
    # the finding's evidence is judged against the gradient alone, not the bare nominal
    assert d.best.significant and d.best.excess_explained >= 0.5


def test_no_companion_without_a_gradient(tmp_path):
    """Without a gradient in the data the joint fit does not lower the BIC enough: the
    finding stays the effect alone."""
    nom = nominal_map(tmp_path)
    t = nom.scaled(thermal_factor(128, 80))
    m = synthetic_surface(t, np.random.default_rng(6), noise_um=0.01,
                          extra_um=lambda x, y: 0.06 * zernike_xy(2, -2, x, y, 68.5))
    write_sag_map(m, tmp_path / "map.npz")
    d = diagnose(surface_manifest(tmp_path))
    assert d.best.effect == "astigmatism" and d.best.companions == ()


class _F:
    kind = "line_profile"

    def __init__(self, name, x):
        self.name, self.x, self.n = name, x, x.size


def test_long_run_variance_inflates_correlated_residuals():
    """Same residual RMS: white -> s^2 ~ RSS/(n-k); a smooth (correlated) mismatch of the
    same RMS -> s^2 larger by about its correlation length in samples."""
    rng = np.random.default_rng(0)
    x = np.linspace(-100, 100, 400)
    white = rng.normal(0, 1.0, x.size)
    smooth = np.sin(x / 12.0) * np.sqrt(2.0)
    f = _F("p", x)
    prob = Problem([f], {"p": 1.0}, {"p": float(x.size)})
    s_white = long_run_s2(prob, [f], {}, {"p": white}, 3)
    s_smooth = long_run_s2(prob, [f], {}, {"p": smooth}, 3)
    assert s_white == pytest.approx(np.sum(white**2) / (x.size - 3), rel=0.3)
    assert s_smooth > 5 * s_white


def test_uncertainties_cover_truth_under_model_mismatch(tmp_path):
    """An astigmatism fitted on a map with an unmodelled smooth bow: the reported 1-sigma
    is at least the long-run (correlated-residual) value, so the truth lies within 3 sigma."""
    c45 = 0.05
    bow = lambda x, y: 0.02 * zernike_xy(4, 0, x, y, 68.5) + 0.015 * zernike_xy(3, 3, x, y, 68.5)
    nom = nominal_map(tmp_path)
    t = nom.scaled(thermal_factor(128, 80))
    m = synthetic_surface(t, np.random.default_rng(8), noise_um=0.01,
                          extra_um=lambda x, y: c45 * zernike_xy(2, -2, x, y, 68.5) + bow(x, y))
    write_sag_map(m, tmp_path / "map.npz")
    f = diagnose(surface_manifest(tmp_path), heldout=False).finding("astigmatism")
    assert abs(f.parameters["astig_45_um"] - c45) <= 3 * f.uncertainties["astig_45_um"]
