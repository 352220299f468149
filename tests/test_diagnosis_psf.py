"""The PSF-image measurement kind: model limits, where-decomposition, bad input, and
what it adds to line profiles (the collimator's oblique astigmatism, which profiles
integrated along the slit see only through its square). Nominal: the analytic sum quilt."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.diagnosis import diagnose
from pipeline.diagnosis.psf_image import psf_image_model
from pipeline.diagnosis.where import psf_image_parts
from optics.sagmap import quilt_sag_map

from diagnosis_cases import nominal_map, profile_image_case


def test_pixel_integration_is_a_box_filter():
    """Integrating over a w x w pixel convolves with a box: unit volume kept, and along each
    axis the marginal's Fourier transform is multiplied by sinc(w f) (the pixel's transfer
    function). Measured: within 3.4e-4 for f <= 1/40 µm^-1 (what the box pushes out of the
    finite window is the rest)."""
    p = {"coll_defocus_um": 0.3}  # a broad core, so the window holds the convolved image
    ux, uy, a = psf_image_model("J", 1.25, -2, None, p, pixel_um=0.0)
    _, _, b = psf_image_model("J", 1.25, -2, None, p, pixel_um=18.0)
    cell = (ux[1] - ux[0]) * (uy[1] - uy[0])
    assert a.sum() * cell == pytest.approx(1.0, abs=2e-3) and b.sum() == pytest.approx(a.sum(), rel=2e-3)
    for axis, u in ((0, ux), (1, uy)):
        ma, mb = a.sum(axis), b.sum(axis)
        for f in (1 / 100, 1 / 60, 1 / 40):
            ratio = abs(np.sum(mb * np.exp(-2j * np.pi * f * u)) / np.sum(ma * np.exp(-2j * np.pi * f * u)))
            assert ratio == pytest.approx(np.sinc(18.0 * f), rel=1e-3), (axis, f)


def test_fitting_grid_image_is_within_a_tenth_of_a_percent_of_converged():
    """The pixel-integrated J image on the fitting grid (1.5 µm steps) against a converged one
    (0.25 µm, 2048-point FFT), both peak-normalised over ±30 µm: within 0.1 % of the peak
    RMS and 0.4 % at worst (measured 0.077 % and 0.31 %; the trapezoid rule's pixel
    integral was 0.53 % and 1.7 %)."""
    from scipy.interpolate import RectBivariateSpline

    from pipeline.diagnosis.psf_image import FIT_PSF_SETTINGS, PsfImageSettings

    g = np.arange(-30.0, 30.001, 1.0)
    X, Y = np.meshgrid(g, g)
    images = []
    for s in (PsfImageSettings(0.25, 2048, 100.0), FIT_PSF_SETTINGS):
        ux, uy, img = psf_image_model("J", 1.25, -2, quilt_sag_map(0.6, "sum", spacing_mm=0.5), {}, 18.0, s)
        v = RectBivariateSpline(uy, ux, img).ev(Y, X)
        images.append(v / v.max())
    d = images[1] - images[0]
    assert np.sqrt(np.mean(d**2)) < 1e-3 and np.abs(d).max() < 4e-3


def test_where_parity_parts():
    """A residual odd in x and in y (astigmatism at 45°) is all 'odd_xy_oblique'; one odd
    in x only is all 'odd_x_left_right' — about a centre off the lattice."""
    g = np.arange(-20.0, 20.01, 1.0)
    X, Y = np.meshgrid(g, g)
    x, y = X.ravel(), Y.ravel()
    c = (0.5, -1.0)
    for r, part in (((x - c[0]) * (y - c[1]), "odd_xy_oblique"), ((x - c[0]) * np.exp(-(y - c[1]) ** 2 / 50), "odd_x_left_right")):
        shares = {w["component"]: w["share"] for w in psf_image_parts("psf", x, y, r, c) if w["decomposition"] == "image_symmetry"}
        assert shares[part] == pytest.approx(1.0, abs=1e-9)
        assert sum(shares.values()) == pytest.approx(1.0, abs=1e-9)


@pytest.mark.slow
def test_psf_image_pins_oblique_astigmatism(tmp_path):
    """Profiles alone know the collimator's oblique astigmatism to ~±0.06 µm (it enters
    through its square); a focal-plane image of a point source beside them pins it, sign
    included, and the profile-only error bar is honest about the difference."""
    truth = {"coll_coma_um": 0.05, "coll_defocus_um": 0.05, "coll_astig45_um": -0.15}
    eff = ("collimator_wfe", "pupil_shift")
    d0 = diagnose(profile_image_case(tmp_path, truth, psf=False), effects=eff, heldout=False)
    d1 = diagnose(profile_image_case(tmp_path, truth, psf=True), effects=eff, heldout=False)
    f0, f1 = d0.finding("collimator_wfe"), d1.finding("collimator_wfe")
    assert d1.verdict == "explained" and d1.best is f1 and not f1.sign_degenerate
    for k, v in truth.items():
        assert f1.parameters[k] == pytest.approx(v, abs=0.01), k
    assert f0.uncertainties["coll_astig45_um"] > 5 * f1.uncertainties["coll_astig45_um"]
    shares = {w["component"]: w["share"] for w in d1.where if w["measurement"] == "psf"}
    assert shares["odd_xy_oblique"] > 0.02  # the nominal misses an oblique term the image shows


@pytest.mark.parametrize("edit, fragment", [
    (lambda t: t.replace("pixel_um = 0.0", "pixel_um = 300"), "pixel_um=300"),
    (lambda t: t.replace('grating = "J"\norder = -2\nwavelength_um = 1.25\npixel_um', 'grating = "Q"\norder = -2\nwavelength_um = 1.25\npixel_um'), "grating='Q'"),
])
def test_bad_psf_manifest(tmp_path, edit, fragment):
    p = profile_image_case(tmp_path, {}, psf=True)
    p.write_text(edit(p.read_text()))
    with pytest.raises(ValueError) as e:
        diagnose(p)
    assert "measurement 'psf'" in str(e.value) and fragment in str(e.value)


@pytest.mark.parametrize("content, fragment", [
    ("x_um,y_um\n" + "".join(f"{i},0\n" for i in range(30)), "missing column"),
    ("x_um,y_um,intensity\n" + "".join(f"{i},{i % 3},{-1 if i != 7 else 1}\n" for i in range(30)), "no flux"),
    ("x_um,y_um,intensity\n" + "".join(f"{i},{i % 3},0\n" for i in range(30)), "no flux"),
    ("x_um,y_um,intensity\n" + "".join(f"{i},{i * 0.37},1\n" for i in range(30)), "noise_rel"),
])
def test_bad_psf_file(tmp_path, content, fragment):
    p = profile_image_case(tmp_path, {}, psf=True)
    (tmp_path / "psf.csv").write_text(content)
    with pytest.raises(ValueError) as e:
        diagnose(p)
    assert "measurement 'psf'" in str(e.value) and fragment in str(e.value)


def test_campaign_psf_image_beside_profiles(tmp_path):
    """``psf_image``: a line-profile case also gets a point-source image, drawn last, so
    the profiles are those of the case without it; ``only_types`` keeps case indices."""
    from pipeline.diagnosis.campaign import PROFILE_SETS, PSF_IMAGE_SPEC, CampaignConfig, make_case, parse_types
    from pipeline.diagnosis.manifest import parse_manifest

    base = nominal_map(tmp_path)
    out = []
    for spec in (None, PSF_IMAGE_SPEC):
        cfg = CampaignConfig(profile_specs=PROFILE_SETS["minimal"][:1], psf_image=spec)
        d = tmp_path / str(spec is not None)
        d.mkdir()
        man, truth = make_case("line_profile", "collimator_wfe", np.random.default_rng([1, 9]), base, d, cfg)
        out.append((man, truth, (d / "p0.csv").read_text()))
    (m0, t0, p0), (m1, t1, p1) = out
    assert t0 == t1 and p0 == p1
    assert [m["kind"] for m in m1["measurement"]] == ["line_profile", "psf_image"]
    parse_manifest(m1, tmp_path / "True")  # a valid manifest
    assert parse_types("line_profile:collimator_wfe") == (("line_profile", "collimator_wfe"),)
    with pytest.raises(ValueError, match="'surface:pupil_shift' is not a case type"):
        parse_types("surface:pupil_shift")
    with pytest.raises(ValueError, match="psf_image="):
        CampaignConfig(psf_image=("J", 1.25, -2, 500.0))


def test_otf_cutoff_bounds_the_image_spectrum():
    """No power beyond the incoherent cut-off (aberrated, shifted pupil), some just inside it."""
    from optics.lineprofile import otf_cutoff_per_um, point_psf

    ps = point_psf("J", 1.25, None, order=-2, pupil_shift_mm=(3.0, -2.0),
                   collimator_zernike_um={(2, -2): 0.15, (3, 1): 0.1}, detector_step_um=0.5, n_fft=512,
                   window_um=None, workers=1)
    fx_c, fy_c = otf_cutoff_per_um("J", 1.25, -2)
    power = np.abs(np.fft.fft2(ps.intensity)) ** 2
    fy, fx = np.meshgrid(np.fft.fftfreq(ps.offset_y_um.size, 0.5), np.fft.fftfreq(ps.offset_x_um.size, 0.5),
                         indexing="ij")
    rho = np.hypot(fx / fx_c, fy / fy_c)
    # measured: 1e-33 beyond 1.02 (round-off), 5e-12 in 1.01-1.02 (the sampled pupil rim),
    # 1e-5 in 0.98-1.0
    assert power[rho > 1.02].max() < 1e-20 * power.max()
    assert power[(rho > 0.98) & (rho < 1.0)].max() > 1e-6 * power.max()


def test_band_limited_noise_estimate():
    """Sigma of white noise under a strong band-limited residual (an aberrated minus a
    perfect PSF, 1 µm grid, 3 % of the nodes missing) to a few per cent (measured 0.9 %;
    zeros in the missing nodes instead of the band-limited fill gave 1.7x); a grid coarser than the Nyquist
    step of the cut-off gives nan (no band left for the noise)."""
    from optics.lineprofile import otf_cutoff_per_um, point_psf
    from pipeline.diagnosis.noise import estimate_noise_band_limited

    kw = dict(order=-2, detector_step_um=1.0, n_fft=256, window_um=30.0, workers=1)
    a = point_psf("J", 1.25, None, collimator_zernike_um={(2, 0): 0.1, (2, -2): 0.1}, **kw)
    b = point_psf("J", 1.25, None, **kw)
    peak = b.intensity.max()
    X, Y = np.meshgrid(b.offset_x_um, b.offset_y_um)
    rng = np.random.default_rng(7)
    sigma = 0.01
    signal = (a.intensity - b.intensity) / peak
    keep = rng.random(X.size) >= 0.03
    x, y = X.ravel()[keep], Y.ravel()[keep]
    resid = signal.ravel()[keep] + rng.normal(0.0, sigma, x.size)
    assert np.std(signal) > 2 * sigma  # the residual is signal-dominated
    cut = otf_cutoff_per_um("J", 1.25, -2)
    est = estimate_noise_band_limited(x, y, resid, cut)
    assert abs(est / sigma - 1) < 0.05
    coarse = (np.round(x) % 3 == 0) & (np.round(y) % 3 == 0)
    assert np.isnan(estimate_noise_band_limited(x[coarse], y[coarse], resid[coarse], cut))
    assert np.isnan(estimate_noise_band_limited(x + rng.normal(0, 0.1, x.size), y, resid, cut))
