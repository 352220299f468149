"""The detector-side wing kernels (pipeline.diagnosis.effects.instrument_wings), against
their definitions: a narrow line through the halo is the Lorentzian (its half width read
off the profile), through the tail a one-sided exponential (its decay read off a log-linear
fit); both keep the flux but for what they scatter beyond the model's window; zero fractions leave the profile untouched; a non-uniform grid
is refused naming the parameter."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.diagnosis.effects.instrument_wings import INSTRUMENT_WINGS, wings_profile

U = np.arange(-150.0, 150.001, 1.5)


def _delta():
    y = np.zeros(U.size)
    y[U.size // 2] = 1.0 / 1.5  # unit area
    return y


def test_zero_fractions_leave_the_profile_untouched():
    y = np.exp(-U**2 / 400.0)
    assert wings_profile(U, y, {}) is not None
    assert np.array_equal(wings_profile(U, y, {"halo_hwhm_um": 80.0, "tail_decay_um": 9.0}), y)


@pytest.mark.parametrize("hwhm_um", [15.0, 40.0])
def test_a_narrow_line_gets_a_lorentzian_halo(hwhm_um):
    f = 0.1
    y = wings_profile(U, _delta(), {"halo_fraction": f, "halo_hwhm_um": hwhm_um})
    # the kernel spans twice the window; what it scatters beyond the window is lost, as on a
    # detector: the Lorentzian's share within +-150 of +-300 um, atan(150/w) / atan(300/w)
    kept = np.arctan(150.0 / hwhm_um) / np.arctan(300.0 / hwhm_um)
    assert np.sum(y) * 1.5 == pytest.approx(1.0 - f * (1.0 - kept), rel=2e-3)
    assert y[U.size // 2] > 0.5 / 1.5  # the core keeps 1 - f
    halo = np.delete(y, U.size // 2)
    uu = np.delete(U, U.size // 2)
    # the Lorentzian's shape: halo(u) / halo(u ~ 0) = w^2 / (u^2 + w^2), half at u = w
    ref = halo[np.argmin(np.abs(uu - 1.5))] * (1.5**2 + hwhm_um**2)
    expect = ref / (uu**2 + hwhm_um**2)
    assert np.allclose(halo, expect, rtol=1e-9)


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_a_narrow_line_gets_a_one_sided_exponential_tail(sign):
    y = wings_profile(U, _delta(), {"tail_fraction": 0.08 * sign, "tail_decay_um": 12.0})
    assert np.sum(y) * 1.5 == pytest.approx(1.0 - 0.08 * np.exp(-150.0 / 12.0), rel=1e-6)
    c = U.size // 2
    behind = y[c - 40:c] if sign > 0 else y[c + 1:c + 41]
    assert np.all(np.abs(behind) < 1e-15)  # FFT rounding only
    ahead_u = U[c + 1:c + 41] if sign > 0 else -U[c - 40:c]
    ahead = y[c + 1:c + 41] if sign > 0 else y[c - 40:c]
    slope = np.polyfit(ahead_u, np.log(ahead), 1)[0]
    assert -1.0 / slope == pytest.approx(12.0, rel=1e-6)


def test_a_non_uniform_grid_is_refused():
    u = np.r_[U[:10], U[11:]]
    with pytest.raises(ValueError, match="offset_um must be a uniform increasing grid"):
        wings_profile(u, np.exp(-u**2 / 400.0), {"halo_fraction": 0.05})


def test_the_alternative_is_not_a_library_candidate():
    from pipeline.diagnosis.effects import ALTERNATIVES, LIBRARY

    assert INSTRUMENT_WINGS.name in ALTERNATIVES and INSTRUMENT_WINGS.name not in LIBRARY


def test_non_linearity_loses_gain_in_proportion_to_the_signal():
    """``P (1 - b P / max P)``: the peak loses the fraction b of its gain, a sample at half the
    peak b/2, the wings nothing (written out by hand, not with the module's formula)."""
    u = np.linspace(-100.0, 100.0, 201)
    y = np.exp(-0.5 * (u / 20.0) ** 2)
    out = wings_profile(u, y, {"nonlinearity": 0.06})
    assert out[100] == pytest.approx(0.94)
    half = int(np.argmin(np.abs(y - 0.5)))
    assert out[half] / y[half] == pytest.approx(1.0 - 0.06 * y[half])
    assert out[0] / y[0] == pytest.approx(1.0, abs=1e-6)


@pytest.mark.parametrize("blur_um", [2.0, 5.2])
def test_a_gaussian_line_blurred_adds_the_blurs_variance(blur_um):
    """A Gaussian line of sigma 8 µm through a Gaussian blur of sigma ``blur_um`` is the
    Gaussian of variance 64 + blur^2 (convolution of Gaussians), flux kept."""
    y = np.exp(-0.5 * (U / 8.0) ** 2)
    out = wings_profile(U, y, {"blur_um": blur_um})
    s = np.hypot(8.0, blur_um)
    expected = np.exp(-0.5 * (U / s) ** 2) * 8.0 / s
    assert np.max(np.abs(out - expected)) < 1e-6
    assert np.sum(out) == pytest.approx(np.sum(y), rel=1e-9)
