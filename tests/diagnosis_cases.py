"""Shared diagnosis test cases, built without the FEA: an analytic sum-quilt nominal, a
surface truth of another quilt form, manifests for surface maps and for J-band line profiles
with a PSF image, and stand-ins for a diagnosis and its finding (the campaign's scoring
rules read only these attributes)."""

from __future__ import annotations

import numpy as np

from optics.sagmap import quilt_sag_map
from pipeline.diagnosis.finding import Finding
from pipeline.diagnosis.nominal import thermal_factor
from pipeline.diagnosis.synth import synthetic_profile, synthetic_psf_image, synthetic_surface
from pipeline.io.measured import write_line_profile_csv, write_psf_image_csv
from pipeline.io.registry import write_sag_map

__all__ = ["nominal_map", "sag_function_of", "abbe_profiles_manifest", "gaussian_profile_data", "other_quilt_truth",
           "surface_manifest", "surface_case", "profile_image_case", "single_finding", "FakeFinding", "FakeDiagnosis"]


def nominal_map(tmp_path):
    m = quilt_sag_map(0.6, "sum", spacing_mm=0.5)
    write_sag_map(m, tmp_path / "nominal.npz")
    return m


def sag_function_of(nominal):
    """``sag(x_mm, y_mm) -> µm`` of a map for the independent truth's Abbe sum: bilinear,
    holes at 0, NaN off the map."""
    from scipy.interpolate import RegularGridInterpolator

    s = np.where(np.isfinite(nominal.sag_um), nominal.sag_um, 0.0)
    itp = RegularGridInterpolator((nominal.y_mm, nominal.x_mm), s, bounds_error=False, fill_value=np.nan)

    def sag(x, y):
        x, y = np.broadcast_arrays(np.asarray(x, float), np.asarray(y, float))
        return itp(np.column_stack([y.ravel(), x.ravel()])).reshape(x.shape)
    return sag


def abbe_profiles_manifest(tmp_path, pixel_scales, seed, distortion=None, line=("J", 1.25, -2), sag_scale=1.0,
                           sag_factor=None, **abbe_kwargs):
    """Manifest of profiles of ``line`` (grating, wavelength µm, order; default J 1.25 µm
    order -2) of the nominal blank (:func:`nominal_map`) at
    ``pixel_scales`` (mas), made by the independent truth's 2-D Abbe sum with
    ``abbe_kwargs`` (collimator, camera, pupil shift, slit width) and measured with photon and read
    noise, background, coupling and sub-pixel phases, ``distortion`` on the detector
    (:func:`pipeline.diagnosis.truth.detector.measure_profile`); the grating's sag is the
    nominal's times ``sag_scale`` (and times ``sag_factor(x_mm, y_mm)``, a field of factors,
    if given)."""
    from pipeline.diagnosis.truth.abbe import RELATIVE_NA, abbe_line_profile
    from pipeline.diagnosis.truth.detector import measure_profile

    nominal_sag = sag_function_of(nominal_map(tmp_path))

    def sag(x, y):
        f = 1.0 if sag_factor is None else sag_factor(np.asarray(x, float), np.asarray(y, float))
        return sag_scale * f * nominal_sag(x, y)
    rng = np.random.default_rng(seed)
    lines = ['[simulation]\nsag_file = "nominal.npz"\ncold_K = 80\n']
    grating, wl, order = line
    for ps in pixel_scales:
        u, det = abbe_line_profile(grating, wl, order, RELATIVE_NA[ps], sag, **abbe_kwargs)
        x, counts, _ = measure_profile(u, det, rng, distortion=distortion)
        write_line_profile_csv(tmp_path / f"p{ps}.csv", x, counts)
        lines.append(f'[[measurement]]\nkind = "line_profile"\nfile = "p{ps}.csv"\ngrating = "{grating}"\n'
                     f'order = {order}\nwavelength_um = {wl}\npixel_scale_mas = {ps}\n')
    p = tmp_path / "m.toml"
    p.write_text("\n".join(lines))
    return p


def gaussian_profile_data(tmp_path, nominal, offset_um, sigma_um, noise_rel=None, extra=""):
    """The data of one J 1.25 µm order -2 profile at 250 mas, read through a manifest whose
    nominal is ``nominal`` (written beside it): a Gaussian of ``sigma_um`` sampled at
    ``offset_um``, its noise ``noise_rel`` where given, ``extra`` added to its
    [[measurement]] table. For tests of the profile model's machinery (memos, carried shapes,
    nuisances), not of a line's physics."""
    from pipeline.diagnosis.manifest import load_data, load_manifest

    write_sag_map(nominal, tmp_path / "nominal.npz")
    u = np.asarray(offset_um, float)
    write_line_profile_csv(tmp_path / "p.csv", u, np.exp(-0.5 * (u / sigma_um) ** 2))
    noise = "" if noise_rel is None else f"noise_rel = {noise_rel}\n"
    (tmp_path / "m.toml").write_text('[simulation]\nsag_file = "nominal.npz"\ncold_K = 80\n\n[[measurement]]\n'
                                     'kind = "line_profile"\nfile = "p.csv"\ngrating = "J"\norder = -2\n'
                                     'wavelength_um = 1.25\npixel_scale_mas = 250\n' + noise + extra)
    (data,) = load_data(load_manifest(tmp_path / "m.toml"))
    return data


def other_quilt_truth(nominal):
    # a different model: 10 % product-form admixture and a slight period error
    other = quilt_sag_map(0.6, "product", spacing_mm=0.5, period_x_mm=21.1)
    return nominal.with_sag(0.9 * nominal.sag_um + 0.1 * other.sag_um)


def surface_manifest(tmp_path, file="map.npz", extra=""):
    text = ('[simulation]\nsag_file = "nominal.npz"\ncold_K = 80\n\n[[measurement]]\nkind = "surface"\n'
            f'file = "{file}"\ntemperature_K = 128\naperture_diameter_mm = 137\n{extra}')
    p = tmp_path / "m.toml"
    p.write_text(text)
    return p


def surface_case(tmp_path, extra=None, seed=0, scale=1.0):
    nom = nominal_map(tmp_path)
    t = other_quilt_truth(nom).scaled(thermal_factor(128, 80) * scale)
    m = synthetic_surface(t, np.random.default_rng(seed), extra_um=extra, noise_um=0.01)
    write_sag_map(m, tmp_path / "map.npz")
    return surface_manifest(tmp_path)


def profile_image_case(tmp_path, params, psf=True, pixel_um=0.0, seed=3, scale=1.0):
    """Manifest of J profiles at 250 and 25 mas (and a PSF image) of the nominal quilt times
    ``scale`` with the effect parameters ``params``; the nominal is written unscaled."""
    nom = nominal_map(tmp_path)
    truth = nom if scale == 1.0 else nom.with_sag(scale * nom.sag_um)
    rng = np.random.default_rng(seed)
    lines = ['[simulation]\nsag_file = "nominal.npz"\ncold_K = 80\n']
    for ps in (250, 25):
        u, y, _ = synthetic_profile("J", 1.25, -2, ps, truth, rng, params=params, noise_rel=0.01)
        write_line_profile_csv(tmp_path / f"p{ps}.csv", u, y)
        lines.append(f'[[measurement]]\nkind = "line_profile"\nfile = "p{ps}.csv"\ngrating = "J"\norder = -2\n'
                     f'wavelength_um = 1.25\npixel_scale_mas = {ps}\n')
    if psf:
        x, y, v, _ = synthetic_psf_image("J", 1.25, -2, truth, rng, params=params, noise_rel=0.01, pixel_um=pixel_um,
                                         step_um=1.0, half_range_um=30.0)
        write_psf_image_csv(tmp_path / "psf.csv", x, y, v)
        lines.append(f'[[measurement]]\nkind = "psf_image"\nfile = "psf.csv"\ngrating = "J"\norder = -2\n'
                     f'wavelength_um = 1.25\npixel_um = {pixel_um}\n')
    p = tmp_path / "m.toml"
    p.write_text("\n".join(lines))
    return p


def single_finding(effect, score, significant=True, companions=()):
    """A single-effect :class:`~pipeline.diagnosis.finding.Finding` whose BIC and delta BIC
    are both ``score`` (for the ranking rules, which read only these and the effects)."""
    return Finding(effect, (effect,), {}, {}, score, score, 1.0, 1.0, 0.0, 0.0, significant=significant,
                   companions=companions)


class FakeFinding:
    def __init__(self, parameters, uncertainties, sign_degenerate=()):
        self.parameters, self.uncertainties, self.sign_degenerate = parameters, uncertainties, tuple(sign_degenerate)


class FakeDiagnosis:
    def __init__(self, effect, finding):
        self._f = {effect: finding}

    def finding(self, effect):
        return self._f.get(effect)
