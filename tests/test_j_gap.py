"""The mechanism behind the J 1.25 µm amplitude gap (``benchmarks/results_j_gap.md``):
a quilt whose x amplitude varies from pupil row to pupil row (the egg-crate (1, ±1)
terms of the FEA quilt) suppresses the central diffraction order less than a uniform
one with the same x fundamental, as Bessel theory says row by row."""

import math

import numpy as np
import pytest
from scipy.special import j0

from optics.grating import SPIFFI, get_grating
from optics.imaging import basic_lsf
from optics.lineprofile import point_psf
from optics.pupil import circular_aperture, centred_axis
from optics.sagmap import SagMap

DX_MM, DY_MM, LAM_UM, ORDER = 21.0, 18.0, 1.25, -2


def _quilt(a_um, c_um):
    """``a (cos 2πx/Dx + cos 2πy/Dy) + c cos 2πx/Dx cos 2πy/Dy``: x amplitude a + c cos 2πy/Dy per row."""
    x, y = np.arange(-90, 90.01, 0.25), np.arange(-70, 70.01, 0.25)
    X, Y = np.meshgrid(x, y)
    cx, cy = np.cos(2 * np.pi * X / DX_MM), np.cos(2 * np.pi * Y / DY_MM)
    return SagMap(x, y, a_um * (cx + cy) + c_um * cx * cy, "quilt")


def _central_fraction(sag, half_um):
    """Flux of the y-collapsed point-source PSF within ±half_um of the undiffracted image."""
    line = basic_lsf(point_psf("J", LAM_UM, sag, order=ORDER, collimator_zernike_um=None, detector_step_um=0.5,
                               n_fft=2048, window_um=400.0), 0.0)
    k = np.abs(line.offset_um) <= half_um
    return float(line.intensity[k].sum() / line.intensity.sum())


def test_row_modulated_quilt_suppresses_the_central_order_less():
    g = get_grating("J")
    beta = float(g.beta_deg(LAM_UM, ORDER))
    k_opd = math.cos(math.radians(g.incidence_deg)) + math.cos(math.radians(beta))
    spacing_um = SPIFFI.camera_focal_mm * LAM_UM / (DX_MM * math.cos(math.radians(beta)))
    half = 0.5 * spacing_um
    # The aperture's own diffraction spreads each order; what a perfect grating leaves
    # outside ±half the order spacing bounds the error of reading orders this way.
    leak = 1.0 - _central_fraction(None, half)
    # Bessel, row by row: the collapsed profile is the sum over pupil rows eta of the 1-D
    # images, so order 0 holds J0(phi(eta))^2 weighted by the row's chord of the circle.
    eta = centred_axis(0.05, 55.0)
    chord = circular_aperture(np.array([0.0]), eta, 110.0)[:, 0] * 2 * np.sqrt(np.clip(55.0**2 - eta**2, 0, None))
    a, c = 0.185, 0.078  # FEA 200/50: A(1,0) ~ 0.18 µm, 2 A(1,±1) ~ 0.08 µm
    got, expected = {}, {}
    for name, cc in (("uniform", 0.0), ("modulated", c)):
        phi = 2 * np.pi * k_opd * (a + cc * np.cos(2 * np.pi * eta / DY_MM)) / LAM_UM
        expected[name] = float(np.sum(chord * j0(phi) ** 2) / np.sum(chord))
        got[name] = _central_fraction(_quilt(a, cc), half)
        assert got[name] == pytest.approx(expected[name], abs=1.5 * leak), (name, got, expected, leak)
    # J0^2 is convex around its first zero, so spreading phi over the rows raises the
    # mean central order: theory and the optics agree on the sign and on the size.
    assert expected["modulated"] > expected["uniform"]
    assert got["modulated"] - got["uniform"] == pytest.approx(expected["modulated"] - expected["uniform"], abs=leak)


def _dft_amplitude(sag, i, j, half_x_mm=42.0, half_y_mm=36.0):
    """Amplitude (µm) of the (i/Dx, j/Dy) quilt component by a plain DFT over the
    half-open box [-42, 42) × [-36, 36) mm: exactly 4 × 4 periods, so no leakage and
    no least squares (independent of :mod:`optics.fitting`)."""
    kx = (sag.x_mm >= -half_x_mm - 1e-9) & (sag.x_mm < half_x_mm - 1e-9)
    ky = (sag.y_mm >= -half_y_mm - 1e-9) & (sag.y_mm < half_y_mm - 1e-9)
    h = sag.sag_um[np.ix_(ky, kx)]
    X, Y = np.meshgrid(sag.x_mm[kx], sag.y_mm[ky])
    return float(2 * abs(np.mean(h * np.exp(-2j * np.pi * (i * X / DX_MM + j * Y / DY_MM)))))


@pytest.mark.slow
def test_fea_quilt_has_less_x_fundamental_per_pv_than_a_sinusoid(coarse_eighth):
    """The 200 µm / 50 % FEA quilt (coarse mesh): P/V_center / A(1,0) > 4 (a sum sinusoid's
    ratio), egg-crate terms A(1,±1) >= 10 % of A(1,0) and equal by the blank's y mirror
    symmetry; the least-squares quilt fit agrees with the DFT over whole periods."""
    from optics.fitting import fit_fourier
    from optics.sagmap import Region

    sag = coarse_eighth.solve(200, 0.5).sag.sag_map(spacing_mm=0.5)
    a10, a11, a1m1 = (_dft_amplitude(sag, *k) for k in ((1, 0), (1, 1), (1, -1)))
    assert sag.pv_um("center") / a10 > 4.0
    assert min(a11, a1m1) >= 0.10 * a10
    assert a11 == pytest.approx(a1m1, rel=0.01)
    # one sample row/column of the closed box and out-of-basis content: <= 2 %
    fit = fit_fourier(sag, DX_MM, DY_MM, harmonics=3, aperture=Region("p4", "rectangle", width_mm=84.0, height_mm=72.0))
    assert fit.component(1, 0)[0] == pytest.approx(a10, rel=0.02)
    assert fit.component(1, 1)[0] == pytest.approx(a11, rel=0.02)
