"""Imaging: analytic limits (Bessel orders, Airy), signs, the infinite-slit limit,
convergence of the defaults, a prysm cross-check and the paper's qualitative results."""

import math

import numpy as np
import pytest
from scipy.special import j1, jv

from optics.grating import GRATINGS, SPIFFI
from optics.imaging import PSF, basic_lsf, box_convolve, box_convolve_bandlimited, partially_coherent_lsf, psf, source_points
from optics.lineprofile import LsfSettings, line_profile, line_profile_footprint_mm, point_psf, pupil_rows
from optics.metrics import find_profile_peaks, l1_distance, profile_metrics
from optics.pupil import centred_axis, circular_aperture, collimator_opd_um, grating_opd_um
from optics.sagmap import SagMap, quilt_sag_map

F_CAM = SPIFFI.camera_focal_mm
NO_WFE = {"collimator_zernike_um": None}


def _peak_x(p: PSF) -> float:
    """Parabolic-refined x position of the PSF maximum (µm)."""
    iy, ix = np.unravel_index(np.argmax(p.intensity), p.intensity.shape)
    a, b, c = p.intensity[iy, ix - 1: ix + 2]
    return float(p.offset_x_um[ix] + 0.5 * (a - c) / (a - 2 * b + c) * (p.offset_x_um[1] - p.offset_x_um[0]))


# ------------------------------------------------------------------ analytic limits
@pytest.mark.parametrize("phi", [0.5, 1.5, 2.405, 3.8])
def test_sinusoidal_phase_grating_orders_are_bessel_squared(phi):
    """Born & Wolf §8.6: exp(i phi sin(2 pi x / p)) puts J_n(phi)^2 into order n.
    Square uniform aperture with 8 whole periods; orders land on FFT bins."""
    step, period, n = 1.0, 16.0, 128
    xi = np.arange(n) * step
    eta = np.arange(16) * step
    amp = np.ones((eta.size, n))
    field = amp * np.exp(1j * phi * np.sin(2 * np.pi * xi / period))[None, :]
    kw = dict(wavelength_um=1.0, camera_focal_mm=1000.0, n_fft=(16, 512))
    ref, img = psf(amp.astype(complex), xi, eta, **kw), psf(field, xi, eta, **kw)
    iy0, ix0 = np.unravel_index(np.argmax(ref.intensity), ref.intensity.shape)
    k = 512 * step / period  # bins per order
    for order in range(-3, 4):
        ratio = img.intensity[iy0, ix0 + int(order * k)] / ref.intensity[iy0, ix0]
        assert abs(ratio - jv(order, phi) ** 2) <= 1e-3, (order, ratio, jv(order, phi) ** 2)


def test_circular_pupil_gives_airy_pattern():
    lam, D, step = 1.25, 110.0, 0.25
    xi = centred_axis(step, D / 2)
    amp = circular_aperture(xi, xi, D, step)
    p = psf(amp.astype(complex), xi, xi, lam, F_CAM, n_fft=(4096, 4096), window_um=20.0)
    cut = p.intensity[np.argmin(np.abs(p.offset_y_um))]
    u = p.offset_x_um
    x = np.pi * D * u / (lam * F_CAM)
    with np.errstate(invalid="ignore", divide="ignore"):
        airy = np.where(x == 0, 1.0, (2 * j1(x) / x) ** 2)
    assert np.max(np.abs(cut / cut.max() - airy)) < 2e-3
    # First zero at 1.22 lambda f / D (4.74 µm): root of the signed amplitude (sqrt of the
    # intensity, sign flipped beyond the minimum), cubic through the 4 nearest samples.
    k = np.argmin(np.where((u > 3) & (u < 6), cut, np.inf))
    last_pos = k - 1 if cut[k - 1] < cut[k + 1] else k  # the zero lies after this sample
    idx = np.arange(last_pos - 1, last_pos + 3)
    amp_signed = np.sqrt(cut[idx]) * np.where(idx <= last_pos, 1.0, -1.0)
    roots = np.roots(np.polyfit(u[idx] - u[last_pos], amp_signed, 3)) + u[last_pos]
    roots = roots[np.isreal(roots)].real
    u0 = roots[(roots >= u[last_pos]) & (roots <= u[last_pos + 1])][0]
    assert u0 == pytest.approx(1.2197 * lam * F_CAM / D, rel=2e-3)


@pytest.mark.parametrize("grating,lam,expected", [("J", 1.25, 20.6), ("K", 2.2, 36.2)])
def test_satellite_positions_on_quilted_grating(grating, lam, expected):
    g = GRATINGS[grating]
    q = quilt_sag_map(0.82, form="sum")
    beta = math.radians(g.beta_deg(lam))
    theory = F_CAM * lam / (q.meta["period_x_mm"] * math.cos(beta))
    assert theory == pytest.approx(expected, abs=0.05)
    p = point_psf(grating, lam, q, **NO_WFE, detector_step_um=0.25, n_fft=2048, window_um=80)
    line = basic_lsf(p, 0.0)
    pk = find_profile_peaks(line.offset_um, line.intensity, prominence=0.01)
    pos = np.array(pk["offset_um"])
    for sign in (+1, -1):
        found = pos[np.argmin(np.abs(pos - sign * theory))]
        assert abs(found - sign * theory) < 0.2, (sign, found, theory)


# ------------------------------------------------------------------ signs and orientation
def test_tilt_moves_light_to_plus_offset():
    """OPD = +t xi (Zernike (1, 1) = 2 rho cos theta) lands at +f_cam t cos(a)/cos(b)."""
    c = 0.05  # µm RMS -> t = 2 c / R µm per mm
    p = point_psf("J", 1.25, None, collimator_zernike_um={(1, 1): c}, detector_step_um=0.25, n_fft=1024, window_um=30)
    t = 2 * c / 55.0
    assert _peak_x(p) == pytest.approx(F_CAM * t * GRATINGS["J"].anamorphic_factor(1.25), abs=0.05)
    assert _peak_x(p) > 0


def test_grating_sag_ramp_sign_and_pupil_shift_direction():
    g = GRATINGS["J"]
    a = 0.01  # µm per mm: surface rising towards +x_g (normal tilted to -x_g)
    x, y = np.arange(-120, 121, 1.0), np.arange(-90, 91, 1.0)
    ramp = SagMap(x, y, a * np.broadcast_to(x, (y.size, x.size)), "ramp")
    p = point_psf("J", 1.25, ramp, **NO_WFE, detector_step_um=0.25, n_fft=1024, window_um=30)
    ca, cb = math.cos(math.radians(g.incidence_deg)), math.cos(math.radians(g.beta_deg(1.25)))
    assert _peak_x(p) == pytest.approx(-F_CAM * (ca + cb) * a / cb, abs=0.05)  # light goes to -offset
    # A +x shift moves the footprint to +x_g: a bump at x_g = +10 mm sits at the pupil centre.
    bump = SagMap(x, y, np.exp(-((x[None, :] - 10) ** 2 + y[:, None] ** 2) / 8.0), "bump")
    xi = eta = np.array([-1.0, 0.0, 1.0])
    opd = grating_opd_um(bump, xi, eta, g.incidence_deg, g.beta_deg(1.25), shift_mm=(10.0, 0.0))
    assert opd[1, 1] == pytest.approx(-(ca + cb), rel=1e-9)  # -(cos a + cos b) * h, h = 1


def test_coma_sign_and_default_puts_shoulder_power_left():
    """Positive (3, 1) coma sends the flare right at full NA (250 mas); the default
    collimator WFE (negative coma) therefore puts the shoulder power LEFT."""
    pos = profile_metrics(line_profile("J", 1.25, 250, None, collimator_zernike_um={(3, 1): 0.2}).detected)
    default = profile_metrics(line_profile("J", 1.25, 250, None).detected)
    assert pos["shoulder_asymmetry"] < -0.1
    assert default["shoulder_asymmetry"] > 0.2
    # At low NA only the central pupil is lit, where coma is a local tilt: the line moves.
    low = profile_metrics(line_profile("J", 1.25, 25, None).detected)
    assert low["centroid_um"] > 3.0


# ------------------------------------------------------------------ infinite-slit limit
def _finite_slit_centre_profile(rows_fn, xi, sx, sy, w, lam, w_coll, l_coll, anam, n_fft, d_eta):
    """Literal 2-D Abbe sum for a slit of length l_coll (µm, collimator plane): pupil field
    P(xi, eta) T(xi - s_x) L(eta - s_y) on a fine eta grid, 2-D Fourier integral evaluated at
    the slit centre (v = 0 row of the 2-D FFT = sum over eta of the 1-D FFTs along xi)."""
    f_coll = SPIFFI.collimator_focal_mm
    eta = centred_axis(d_eta, 55.0)
    P = rows_fn(eta)
    sc = lambda width: width * 1e-3 / (lam * 1e-3 * f_coll)
    acc = np.zeros(n_fft)
    for j, s_y in enumerate(sy):
        L = np.sinc(sc(l_coll) * (eta - s_y))
        col = (L[:, None] * P).sum(axis=0)  # integral over eta at v = 0
        for k, s_x in enumerate(sx):
            if w[j, k] > 0:
                e = np.fft.fft(col * np.sinc(sc(w_coll) * (xi - s_x)), n_fft)
                acc += w[j, k] * np.abs(e) ** 2
    return np.fft.fftshift(acc)


def test_infinite_slit_limit_matches_finite_slit_2d_abbe_sum():
    g, lam = GRATINGS["K"], 2.2
    q = quilt_sag_map(0.82, form="product")
    beta, anam = g.beta_deg(lam), g.anamorphic_factor(lam)
    n_fft, du = 256, 2.0
    d_xi = lam * F_CAM * anam / (n_fft * du)
    xi = centred_axis(d_xi, 55.0)
    sx, sy, w = source_points(5.5, 1.0)  # 25 mas
    rows_fn = lambda eta: pupil_rows(g, lam, xi, eta, beta, q, (0.0, 0.0), None, SPIFFI, d_xi)
    w_coll = g.slit_width_collimator_um()
    fast = partially_coherent_lsf(rows_fn(sy), xi, sx, w, lam, w_coll, SPIFFI.collimator_focal_mm, F_CAM, anam, n_fft)
    mag = SPIFFI.collimator_focal_mm / F_CAM  # along the slit (no anamorphism)
    errs = []
    for length_um in (100.0, 400.0):
        brute = _finite_slit_centre_profile(rows_fn, xi, sx, sy, w, lam, w_coll, length_um * mag, anam, n_fft, 0.1)
        brute = brute / (brute.sum() * du)
        errs.append(np.sum(np.abs(brute - fast.intensity)) * du)
    assert errs[1] < 0.005, errs  # 400 µm slit (paper): < 0.5 % L1 from the infinite-slit limit
    assert errs[1] < errs[0], errs


# ------------------------------------------------------------------ convergence of the defaults
@pytest.mark.parametrize("grating,lam,mas", [("J", 1.10, 100), ("K", 2.45, 25), ("J", 1.25, 250)])
def test_default_settings_within_half_percent_of_converged(grating, lam, mas):
    q = quilt_sag_map(0.82, form="product")
    ref = LsfSettings(detector_step_um=0.25, n_fft=4096, source_step_mm=0.5, min_source_rows=20)
    a = line_profile(grating, lam, mas, q).detected
    b = line_profile(grating, lam, mas, q, settings=ref).detected
    assert l1_distance(b, a) < 0.005
    assert a.area() == pytest.approx(1.0)


# ------------------------------------------------------------------ prysm cross-check
def test_psf_matches_prysm():
    """Same pupil built with prysm's own grid/geometry/Zernike: identical PSF.
    prysm: arrays [y, x], phase in nm, exp(+i k OPD), fftshift(fft2(ifftshift)) -> same
    orientation as ours (+x tilt -> +x); its grid puts 0 at index n/2 like ours."""
    pytest.importorskip("prysm")
    from prysm.coordinates import cart_to_polar, make_xy_grid
    from prysm.geometry import circle
    from prysm.polynomials import zernike_nm
    from prysm.propagation import Wavefront

    n, D, lam = 256, 110.0, 1.6
    x, y = make_xy_grid(n, diameter=D * n / (n - 1) * 1.0)
    dx = float(x[0, 1] - x[0, 0])
    r, t = cart_to_polar(x, y)
    amp = circle(D / 2, r).astype(float)
    coeffs = {(3, 1): 0.2, (2, -2): -0.15, (4, 0): 0.05}
    opd = sum(c * zernike_nm(nn, m, r / (D / 2), t, norm=True) for (nn, m), c in coeffs.items())
    wf = Wavefront.from_amp_and_phase(amp, opd * 1e3 * amp, lam, dx).focus(F_CAM, Q=2)
    ref = np.abs(wf.data) ** 2
    ref /= ref.sum() * wf.dx**2  # prysm PSF sample spacing is in µm
    ours_opd = collimator_opd_um(x[0], y[:, 0], coeffs, D / 2)
    ours = psf(amp * np.exp(2j * np.pi * ours_opd * amp / lam), x[0], y[:, 0], lam, F_CAM, n_fft=(2 * n, 2 * n))
    assert ours.offset_x_um[1] - ours.offset_x_um[0] == pytest.approx(wf.dx)
    assert np.max(np.abs(ours.intensity - ref)) < 1e-6 * ref.max()


# ------------------------------------------------------------------ the paper's behaviour (analytic quilt)
# The stand-in for an FEA map is quilt_sag_map(0.82, form="sum") (P/V of the paper's
# 200/100 case; the separable form puts a clean +-1st order along x, see docs/physics.md).
SUM_QUILT = quilt_sag_map(0.82, form="sum")


@pytest.mark.parametrize("mas", [100, 250])
def test_paper_j_band_double_peak(mas):
    m = profile_metrics(line_profile("J", 1.25, mas, SUM_QUILT).detected)
    assert m["peaks"]["double_peak"]
    assert 36.0 <= m["peaks"]["peak_spacing_um"] <= 45.0


def test_paper_k_band_shoulders_near_36um():
    m = profile_metrics(line_profile("K", 2.2, 250, SUM_QUILT, **NO_WFE).detected)
    pos = np.array(m["peaks"]["offset_um"])
    assert abs(pos[0]) < 2.0  # main peak central
    for sign in (+1, -1):
        assert np.min(np.abs(pos - sign * 36.2)) < 3.0


@pytest.mark.parametrize("grating", ["J", "K"])
def test_paper_shorter_wavelength_more_satellite_flux(grating):
    """Satellite fraction = flux of the thin-slit basic LSF beyond half the order spacing."""
    g = GRATINGS[grating]
    frac = []
    for lam in (g.band_um[0], g.band_um[2]):
        line = basic_lsf(point_psf(grating, lam, SUM_QUILT, **NO_WFE, detector_step_um=1.0, n_fft=512, window_um=200), 0.0)
        half = 0.5 * F_CAM * lam / (21.0 * math.cos(math.radians(g.beta_deg(lam))))
        frac.append(np.sum(line.intensity[np.abs(line.offset_um) > half]) / np.sum(line.intensity))
    assert frac[0] > frac[1] + 0.05, frac


def _shift_change(grating, lam, mas, sag, shifts=np.linspace(-11, 11, 9)):
    """Mean L1 distance (unit-area profiles) between shifted-pupil and centred profiles."""
    ref = line_profile(grating, lam, mas, sag).detected
    return float(np.mean([l1_distance(ref, line_profile(grating, lam, mas, sag, pupil_shift_mm=(s, 0.0)).detected)
                          for s in shifts]))


@pytest.mark.parametrize("form", ["sum", "product"])
def test_paper_pupil_shift_matters_at_25mas_not_250mas(form):
    q = quilt_sag_map(0.82, form=form)
    assert _shift_change("J", 1.25, 25, q) >= 5 * _shift_change("J", 1.25, 250, q)


@pytest.mark.parametrize("grating", ["J", "H", "K"])
def test_perfect_grating_resolving_power(grating):
    """R ~ 4000 (paper §6) holds for the 2-pixel resolution element; the FWHM of the
    detected profile (27 µm slit * 18 µm pixel, FWHM ~ 26-29 µm) gives R ~ 5200-6200."""
    g = GRATINGS[grating]
    m = profile_metrics(line_profile(grating, g.centre_um, 250, None).detected)
    assert m["resolving_power_2px"] == pytest.approx(4000, rel=0.1)
    assert 4000 < m["resolving_power"] < 6500


# ------------------------------------------------------------------ bad input
def test_bad_inputs_raise_value_errors_naming_the_value():
    x, y = np.arange(-100, 101, 1.0), np.arange(-80, 81, 1.0)
    with pytest.raises(ValueError, match=r"wavelength_um=5\.0.*valid range"):
        line_profile("J", 5.0, 100)
    with pytest.raises(ValueError, match=r"grating='Q'.*\['H', 'HK', 'J', 'K'\]"):
        line_profile("Q", 1.25, 100)
    with pytest.raises(ValueError, match=r"50.*\[25, 100, 250\]"):
        line_profile("J", 1.25, 50)
    far = SagMap(x + 500, y, np.zeros((y.size, x.size)), "far")
    with pytest.raises(ValueError, match="no valid samples in the pupil footprint"):
        line_profile("J", 1.25, 100, far)
    holed = np.zeros((y.size, x.size))
    holed[80, 100] = np.nan
    with pytest.raises(ValueError, match="NaN/out-of-map points inside the pupil footprint"):
        line_profile("J", 1.25, 100, SagMap(x, y, holed, "holed"))
    xc, yc = np.arange(-100, 101, 3.0), np.arange(-81, 82, 3.0)
    with pytest.raises(ValueError, match=r"too coarse.*6\.0 samples per 18 mm.*spacing <= 2\.25 mm"):
        line_profile("J", 1.25, 100, SagMap(xc, yc, np.zeros((yc.size, xc.size)), "coarse"))
    with pytest.raises(ValueError, match="slit_position"):
        line_profile("J", 1.25, 100, None, slit_position=2.0)


# ------------------------------------------------------------------ CLI
def test_cli_lsf_and_psf(tmp_path):
    import json

    from pipeline.optics_cli import main

    q = quilt_sag_map(0.82, form="sum")
    np.savez(tmp_path / "q.npz", x_mm=q.x_mm, y_mm=q.y_mm, sag_um=q.sag_um)
    assert main(["lsf", "--grating", "J", "--wavelength-um", "1.25", "--pixel-scale-mas", "100",
                 "--sag", str(tmp_path / "q.npz"), "--out", str(tmp_path / "a")]) == 0
    data = np.loadtxt(tmp_path / "a" / "lsf.csv", delimiter=",", skiprows=1)
    assert data.shape[1] == 2 and (tmp_path / "a" / "lsf.png").exists()
    m = json.loads((tmp_path / "a" / "metrics.json").read_text())
    assert m["metrics"]["peaks"]["double_peak"] and m["info"]["pixel_scale_mas"] == 100
    assert main(["psf", "--grating", "K", "--wavelength-um", "2.2", "--quilt-pv-um", "0.82",
                 "--no-collimator-wfe", "--out", str(tmp_path / "b")]) == 0
    with np.load(tmp_path / "b" / "psf.npz") as d:
        assert d["intensity"].shape == (d["offset_y_um"].size, d["offset_x_um"].size)
    with pytest.raises(SystemExit):
        main(["lsf", "--grating", "J", "--wavelength-um", "9", "--pixel-scale-mas", "100",
              "--quilt-pv-um", "0", "--out", str(tmp_path / "c")])


def test_bandlimited_box_integrates_a_coarsely_sampled_line_exactly():
    """An 18 µm box over a Gaussian of sigma 2 µm sampled every 1.5 µm (its spectrum at the
    sampling's Nyquist frequency is 1.5e-4 of its peak): the spectral box matches the erf
    integral to 1e-5 of the peak, on either axis of a 2-D array; the trapezoid rule, exact
    only for straight lines between samples, is off by more than 1e-3 (why the band-limited
    form exists)."""
    from scipy.special import erf

    u = np.arange(-60.0, 60.001, 1.5)
    sigma, w = 2.0, 18.0
    y = np.exp(-0.5 * (u / sigma) ** 2)
    exact = sigma * math.sqrt(math.pi / 2) * (erf((u + w / 2) / (sigma * math.sqrt(2)))
                                              - erf((u - w / 2) / (sigma * math.sqrt(2)))) / w
    peak = exact.max()
    assert np.max(np.abs(box_convolve_bandlimited(u, y, w) - exact)) < 1e-5 * peak
    assert np.max(np.abs(box_convolve(u, y, w) - exact)) > 1e-3 * peak
    img = np.outer(np.linspace(0.5, 1.5, 7), y)
    assert np.allclose(box_convolve_bandlimited(u, img.T, w, axis=0).T, np.outer(np.linspace(0.5, 1.5, 7), exact),
                       atol=1e-5 * peak)
    with pytest.raises(ValueError, match="width_um=-1"):
        box_convolve_bandlimited(u, y, -1.0)


@pytest.mark.parametrize("mas, shift_mm", [(25, (0.0, 0.0)), (250, (3.3, -1.7))])
def test_line_profile_reads_only_its_footprint(mas, shift_mm):
    """The map cut to :func:`line_profile_footprint_mm` plus the bilinear stencil gives the
    same profile to the last bit, and a sample changed outside it changes nothing: what a
    caller deforming only that part of a map relies on."""
    settings = LsfSettings(detector_step_um=1.5, n_fft=256, source_step_mm=2.5, min_source_rows=5, window_um=150.0,
                           workers=1)
    sag = quilt_sag_map(0.4, spacing_mm=0.5)
    kw = dict(order=-2, pupil_shift_mm=shift_mm, settings=settings)
    x0, x1, y0, y1 = line_profile_footprint_mm("J", 1.25, mas, **kw)
    xs = slice(np.searchsorted(sag.x_mm, x0) - 2, np.searchsorted(sag.x_mm, x1) + 2)
    ys = slice(np.searchsorted(sag.y_mm, y0) - 2, np.searchsorted(sag.y_mm, y1) + 2)
    assert xs.start > 0 and ys.start > 0 and xs.stop < sag.x_mm.size and ys.stop < sag.y_mm.size
    part = SagMap(sag.x_mm[xs], sag.y_mm[ys], sag.sag_um[ys, xs], sag.label)
    whole = line_profile("J", 1.25, mas, sag, **kw).detected.intensity
    assert np.array_equal(line_profile("J", 1.25, mas, part, **kw).detected.intensity, whole)
    outside = sag.sag_um.copy()
    outside[:ys.start, :] = np.nan
    outside[:, xs.stop:] = 1.0
    assert np.array_equal(line_profile("J", 1.25, mas, sag.with_sag(outside), **kw).detected.intensity, whole)
