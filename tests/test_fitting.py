"""Least-squares Zernike and Fourier fits: exact recovery, noise, errors, quilt capture."""
import numpy as np
import pytest

from optics.fitting import (
    compare_bases,
    fit_fourier,
    fit_fourier_points,
    fit_zernike,
    fit_zernike_map,
    remove_terms,
    resolve_terms,
)
from optics.sagmap import Region, SagMap, quilt_sag_map
from optics.zernike import fringe_to_nm, nm_to_ansi, nm_to_fringe, noll_to_nm, wavefront_from_coefficients

RNG_SEED = 20240611


def _random_coeffs(rng, nm, scale_um=0.1):
    return {t: float(rng.normal(0, scale_um)) for t in nm}


def _disc_points(rng, n, radius_mm, center=(0.0, 0.0)):
    r = radius_mm * np.sqrt(rng.uniform(0, 1, n))
    t = rng.uniform(0, 2 * np.pi, n)
    return center[0] + r * np.cos(t), center[1] + r * np.sin(t)


def _holed_grid_map(fun, spacing_mm=1.0):
    """120 x 100 mm grid with NaN pockets (lightweighting holes seen through) and a NaN corner."""
    x = np.arange(-60, 60 + spacing_mm / 2, spacing_mm)
    y = np.arange(-50, 50 + spacing_mm / 2, spacing_mm)
    X, Y = np.meshgrid(x, y)
    s = fun(X, Y)
    holes = ((np.mod(X, 21.0) - 10.5) ** 2 + (np.mod(Y, 18.0) - 9.0) ** 2) < 3.0**2
    s[holes] = np.nan
    s[(X > 40) & (Y > 30)] = np.nan
    return SagMap(x, y, s, "holed test map")


def test_scattered_fit_recovers_coefficients_exactly():
    rng = np.random.default_rng(RNG_SEED)
    nm = resolve_terms(22)
    truth = _random_coeffs(rng, nm)
    x, y = _disc_points(rng, 3000, 40.0, center=(3.0, -2.0))
    sag = wavefront_from_coefficients(truth, x - 3.0, y + 2.0, 40.0)
    sag[::50] = np.nan  # dropped nodes must be ignored, not zero-filled
    fit = fit_zernike(x, y, sag, 40.0, terms=22, center_mm=(3.0, -2.0))
    np.testing.assert_allclose(fit.coefficient_array, [truth[t] for t in nm], atol=1e-12)
    assert fit.residual_rms_um < 1e-12 and fit.captured_fraction == pytest.approx(1.0, abs=1e-12)
    assert fit.n_points == 3000 - 60 and np.isnan(fit.residual[::50]).all()
    assert fit.condition_number < 5  # near-orthonormal on a well-sampled disc


def test_gridded_fit_rectangle_with_holes_recovers_37_terms():
    rng = np.random.default_rng(RNG_SEED + 1)
    region = Region("offset rect", "rectangle", width_mm=82.0, height_mm=72.0, x0_mm=5.0, y0_mm=-3.0)
    radius = 0.5 * np.hypot(82.0, 72.0)
    nm = resolve_terms(37)
    truth = _random_coeffs(rng, nm)
    m = _holed_grid_map(lambda X, Y: wavefront_from_coefficients(truth, X - 5.0, Y + 3.0, radius))
    fit = fit_zernike_map(m, 37, aperture=region)
    assert fit.radius_mm == pytest.approx(radius) and fit.center_mm == (5.0, -3.0)
    np.testing.assert_allclose(fit.coefficient_array, [truth[t] for t in nm], atol=1e-10)
    assert fit.residual_rms_um < 1e-10
    # fitted/residual are SagMaps on the input grid, NaN outside aperture and in holes
    assert isinstance(fit.residual, SagMap)
    assert np.isfinite(fit.fitted.sag_um).sum() == fit.n_points == m.region_mask(region).sum()
    # evaluate() resamples the fitted surface anywhere, e.g. inside a hole
    assert fit.evaluate(10.5, 9.0) == pytest.approx(
        wavefront_from_coefficients(truth, 5.5, 12.0, radius), abs=1e-10)


def test_fringe_unnormalised_and_index_conventions_agree():
    rng = np.random.default_rng(RNG_SEED + 2)
    nm = [fringe_to_nm(j) for j in range(1, 17)]
    truth = _random_coeffs(rng, nm)
    x, y = _disc_points(rng, 2000, 25.0)
    sag = wavefront_from_coefficients(truth, x, y, 25.0, norm=False)
    by_fringe = fit_zernike(x, y, sag, 25.0, terms=16, index="fringe", norm=False)
    by_nm = fit_zernike(x, y, sag, 25.0, terms=nm, norm=False)
    by_ansi = fit_zernike(x, y, sag, 25.0, terms=[nm_to_ansi(*t) for t in nm], index="ansi", norm=False)
    for f in (by_fringe, by_nm, by_ansi):
        for t in nm:
            assert f.coefficients[t] == pytest.approx(truth[t], abs=1e-12)
    assert by_fringe.index == "fringe" and nm_to_fringe(*by_fringe.terms[8]) == 9
    assert by_nm.index == "nm" and by_nm.by_index("fringe")[9] == pytest.approx(truth[(4, 0)])


def test_ill_conditioned_but_full_rank_fit_still_exact():
    # points on a disc 1/20 of the Zernike radius: cond ~ 3e6, beyond the normal-
    # equation path, so this exercises the QR fallback
    rng = np.random.default_rng(RNG_SEED + 5)
    nm = resolve_terms(15)
    truth = _random_coeffs(rng, nm)
    x, y = _disc_points(rng, 5000, 0.05)
    fit = fit_zernike(x, y, wavefront_from_coefficients(truth, x, y, 1.0), 1.0, terms=15)
    assert 1e6 < fit.condition_number < 1e10
    np.testing.assert_allclose(fit.coefficient_array, [truth[t] for t in nm], atol=1e-9)


def test_noisy_fit_recovered_within_noise():
    rng = np.random.default_rng(RNG_SEED + 3)
    nm = resolve_terms(15)
    truth = _random_coeffs(rng, nm)
    n, sigma = 20000, 0.01
    x, y = _disc_points(rng, n, 50.0)
    sag = wavefront_from_coefficients(truth, x, y, 50.0) + rng.normal(0, sigma, n)
    fit = fit_zernike(x, y, sag, 50.0, terms=15)
    # RMS-normalised basis: A^T A ~ n I, so each coefficient has std ~ sigma / sqrt(n)
    err = fit.coefficient_array - np.array([truth[t] for t in nm])
    assert np.abs(err).max() < 5 * sigma / np.sqrt(n)
    assert fit.residual_rms_um == pytest.approx(sigma, rel=0.03)


def test_plus_x_tilt_gives_positive_x_tilt_coefficient():
    m = _holed_grid_map(lambda X, Y: 0.01 * X)
    fit = fit_zernike_map(m, 3, aperture="center")
    assert fit.coefficients[(1, 1)] > 0 and abs(fit.coefficients[(1, -1)]) < 1e-12


def test_errors_are_raised_never_silent_zeros():
    m = _holed_grid_map(lambda X, Y: 0.001 * X * Y)
    outside = Region("far away", "circle", diameter_mm=10.0, x0_mm=500.0)
    with pytest.raises(ValueError, match="'far away'.*no valid sample"):
        fit_zernike_map(m, 11, aperture=outside)
    with pytest.raises(ValueError, match="'far away'.*no valid sample"):
        fit_fourier(m, aperture=outside)
    # partly outside the grid (centred on the valid corner): only a handful of samples
    corner = Region("corner", "circle", diameter_mm=4.0, x0_mm=-60.0, y0_mm=-50.0)
    with pytest.raises(ValueError, match=r"'corner'.*\d+ valid points for 37 terms"):
        fit_zernike_map(m, 37, aperture=corner)
    # inside the NaN corner: nodes exist but none is valid
    with pytest.raises(ValueError, match="'nan corner'.*no valid sample"):
        fit_zernike_map(m, 3, aperture=Region("nan corner", "circle", diameter_mm=8.0, x0_mm=50, y0_mm=40))
    # samples on a line cannot see the sine terms: rank-deficient, not zeros
    x = np.linspace(-10, 10, 200)
    with pytest.raises(ValueError, match="rank-deficient"):
        fit_zernike(x, np.zeros_like(x), x**2, 10.0, terms=6)
    with pytest.raises(ValueError, match="terms=0"):
        fit_zernike(x, x, x, 10.0, terms=0)
    with pytest.raises(ValueError, match="radius_mm"):
        fit_zernike(x, x, x, -1.0, terms=3)


def _shifted_quilt(X, Y, a, b, shift, px=21.0, py=18.0):
    xs, ys = X - shift[0], Y - shift[1]
    return (a * np.cos(2 * np.pi * xs / px) * np.cos(2 * np.pi * ys / py)
            + b * np.cos(4 * np.pi * xs / px) + 0.002 * X - 0.001 * Y + 0.05)


def _wrap(p):
    return (p + np.pi) % (2 * np.pi) - np.pi


@pytest.mark.parametrize("aperture", ["center", "pupil"])  # pupil: not period-matched
def test_fourier_fit_of_shifted_quilt_recovers_amplitude_and_phase(aperture):
    a, b, shift = 0.41, 0.07, (4.0, -2.5)
    x = np.arange(-80, 80.01, 0.5)
    y = np.arange(-70, 70.01, 0.5)
    X, Y = np.meshgrid(x, y)
    m = SagMap(x, y, _shifted_quilt(X, Y, a, b, shift))
    f = fit_fourier(m, aperture=aperture)
    # a cos(u) cos(v) = a/2 [cos(u + v) + cos(u - v)] with u = 2 pi (x - xs)/Dx, v likewise
    A11, p11 = f.component(1, 1)
    A1m1, p1m1 = f.component(1, -1)
    A20, p20 = f.component(2, 0)
    assert (A11, A1m1, A20) == pytest.approx((a / 2, a / 2, b), abs=1e-12)
    assert p11 == pytest.approx(_wrap(2 * np.pi * (shift[0] / 21 + shift[1] / 18)), abs=1e-10)
    assert p1m1 == pytest.approx(_wrap(2 * np.pi * (shift[0] / 21 - shift[1] / 18)), abs=1e-10)
    assert p20 == pytest.approx(_wrap(4 * np.pi * shift[0] / 21), abs=1e-10)
    assert f.component(-1, 1)[1] == pytest.approx(-p1m1)
    assert f.slope_um_per_mm == pytest.approx((0.002, -0.001), abs=1e-12)
    assert f.piston_um == pytest.approx(0.05, abs=1e-12)
    assert f.captured_fraction == pytest.approx(1.0, abs=1e-12)
    others = [A for k, A in f.amplitude_um.items() if k not in ((1, 1), (1, -1), (2, 0))]
    assert max(others) < 1e-12
    np.testing.assert_allclose(f.evaluate(X, Y), m.sag_um, atol=1e-12)


def test_fourier_fit_on_scattered_points_and_phase_sign():
    rng = np.random.default_rng(RNG_SEED + 4)
    x, y = rng.uniform(-40, 40, 4000), rng.uniform(-35, 35, 4000)
    # a crest moved to +x by 3 mm: positive phase in the A cos(2 pi x / Dx - phi) convention
    sag = 0.2 * np.cos(2 * np.pi * (x - 3.0) / 21.0)
    f = fit_fourier_points(x, y, sag, harmonics=2, include_cross=False)
    A, phi = f.component(1, 0)
    assert A == pytest.approx(0.2, abs=1e-12) and phi == pytest.approx(2 * np.pi * 3 / 21, abs=1e-10)
    assert len(f.components) == 4 and f.residual.shape == x.shape


def test_compare_bases_fourier_beats_zernike_on_quilt():
    q = quilt_sag_map(0.82)
    r = compare_bases(q, "center", n_zernike=37, harmonics=3)
    # measured: Zernike-37 captures 0.32 % (residual 0.203 µm RMS); Fourier and the
    # combined basis capture the analytic quilt to round-off
    assert r["fourier"].captured_fraction > 0.999
    assert r["combined"].captured_fraction > 0.999
    assert r["zernike"].captured_fraction < 0.05
    assert r["zernike"].residual_rms_um > 100 * r["fourier"].residual_rms_um
    assert r["zernike"].residual_rms_um == pytest.approx(q.rms_um("center"), rel=0.01)


def test_remove_terms_takes_out_astigmatism_only():
    radius = 0.5 * np.hypot(82.0, 72.0)
    keep = {(2, 0): 0.2, (3, 1): -0.05}
    astig = {(2, 2): 0.3, (2, -2): 0.1}
    m = _holed_grid_map(lambda X, Y: wavefront_from_coefficients({**keep, **astig}, X, Y, radius))
    out = remove_terms(m, [(2, 2), (2, -2)], aperture="center")
    X, Y = m.grid()
    expected = wavefront_from_coefficients(keep, X, Y, radius)
    assert np.array_equal(np.isnan(out.sag_um), np.isnan(m.sag_um))  # holes stay holes
    np.testing.assert_allclose(out.sag_um[m.mask], expected[m.mask], atol=1e-10)
    assert noll_to_nm(6) == (2, 2)


def test_quilt_plus_low_order_needs_the_combined_basis():
    # the realistic case: print-through quilt on top of cryogenic defocus/astigmatism
    q = quilt_sag_map(0.82, spacing_mm=0.5)
    X, Y = q.grid()
    low = wavefront_from_coefficients({(2, 0): 0.3, (2, 2): 0.1}, X, Y, 0.5 * np.hypot(82.0, 72.0))
    r = compare_bases(q.with_sag(q.sag_um + low), "center")
    # measured: Zernike-37 0.585, Fourier 0.419, combined 1.000 (to round-off)
    assert r["combined"].captured_fraction > 0.999
    assert r["zernike"].captured_fraction < 0.7 and r["fourier"].captured_fraction < 0.7
