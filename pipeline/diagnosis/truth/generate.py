"""One independent campaign case: truth deformation, optics, detector, files, manifest.

:func:`make_case` is the independent counterpart of
:func:`pipeline.diagnosis.campaign.make_case` (same signature and return: manifest dict,
injected truth); :data:`CASE_TYPES` lists its case types (library effects as the model
campaign's, out-of-library families of :mod:`.families`).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from scipy.ndimage import gaussian_filter

from optics.pupil import DEFAULT_COLLIMATOR_ZERNIKE_UM
from pipeline.io.measured import write_line_profile_csv, write_psf_image_csv

from ..effect_draws import DRAWS
from ..manifest import NOMINAL_SIMULATION
from ..nominal import thermal_factor
from .abbe import GRATINGS, RELATIVE_NA, AbbeSettings, abbe_line_profile, point_image, zernike_noll
from .detector import image_reach_um, measure_image, measure_profile
from .families import PROFILE_OOL, SURFACE_OOL, draw_profile_ool, draw_surface_ool
from .gratings import GratingTruth, fundamental_x_ratio, mixed_grating, sag_function
from .lattice import pocket_jitter, sharp_ribs

#: cold temperature of the nominal map (K): the FEA case's default
_COLD_K = NOMINAL_SIMULATION["cold_K"]

__all__ = ["CASE_TYPES", "PAIR_CASE_TYPES", "FAMILIES", "GRATING_FAMILIES", "SURFACE_T_K", "check_families", "truth_grating",
           "measured_map", "make_case"]

CASE_TYPES = (
    ("surface", "astigmatism"), ("surface", "amplitude_scale"), ("surface", "temperature"),
    ("surface", "registration"), *(("surface", e) for e in SURFACE_OOL),
    ("line_profile", "amplitude_scale"), ("line_profile", "temperature"), ("line_profile", "pupil_shift"),
    ("line_profile", "collimator_wfe"), ("line_profile", "slit_width"), *(("line_profile", e) for e in PROFILE_OOL),
)
#: Opt-in cases with two library effects injected together (names in library order, as
#: the diagnosis names a pair): the paper's J grating needed a larger amplitude *and* a
#: pupil shift (its section 5.3); the others pair the amplitude, or the pupil shift, with
#: a change of the spectrograph that also widens or skews the line.
PAIR_CASE_TYPES = (
    ("line_profile", "amplitude_scale+pupil_shift"), ("line_profile", "amplitude_scale+collimator_wfe"),
    ("line_profile", "amplitude_scale+slit_width"), ("line_profile", "pupil_shift+slit_width"),
)
#: The default grating families (the campaign's truths unless ``CampaignConfig.truth_families``
#: says otherwise).
FAMILIES = ("sum_mix", "product_mix")
#: Every grating family (``benchmarks/truth_families.md``): the mixtures, and the lattice
#: families of :mod:`.lattice`, which lie outside the span of the library's quilt shape.
GRATING_FAMILIES = FAMILIES + ("pocket_jitter", "sharp_ribs")
SURFACE_T_K = 128.0
APERTURE_MM = 137.0
#: The blank a line-profile case's truth is drawn for (the profiles' grating): the map beside
#: the profiles is of it too.
_PROFILE_BLANK = "J"
#: The instrument's collimator wavefront (shared data: the model's default collimator).
COLLIMATOR_UM = dict(DEFAULT_COLLIMATOR_ZERNIKE_UM)


def check_families(families) -> tuple:
    """``families`` (names, or one comma-separated string as typed on a command line) as a
    tuple of :data:`GRATING_FAMILIES` names; ValueError otherwise."""
    fams = tuple(f.strip() for f in families.split(",")) if isinstance(families, str) else tuple(families)
    bad = [f for f in fams if f not in GRATING_FAMILIES]
    if not fams or bad or len(set(fams)) != len(fams):
        raise ValueError(f"truth_families={fams!r} must be distinct names from {list(GRATING_FAMILIES)} (at least one)")
    return fams


def truth_grating(nominal, fea, rng: np.random.Generator, families: tuple = FAMILIES) -> GratingTruth:
    """A truth deformation (µm at the nominal's cold temperature) of a family drawn from
    ``families`` with equal probability: ``fea`` (another mesh) mixed with a quilt at a
    harmonic distance drawn in 5-30 % (``sum_mix``, ``product_mix``, ``sharp_ribs``), or
    its quilt jittered per lattice cell (``pocket_jitter``)."""
    families = check_families(families)
    fam = families[int(rng.integers(0, len(families)))]
    n = np.where(np.isfinite(nominal.sag_um), nominal.sag_um, 0.0)
    if fam == "pocket_jitter":
        return pocket_jitter(fea.x_mm, fea.y_mm, fea.sag_um, n, rng)
    if fam == "sharp_ribs":
        return sharp_ribs(fea.x_mm, fea.y_mm, fea.sag_um, n, float(rng.uniform(0.05, 0.30)), rng)
    return mixed_grating(fea.x_mm, fea.y_mm, fea.sag_um, n, fam, float(rng.uniform(0.05, 0.30)), rng)


def measured_map(g: GratingTruth, factor: float, rng: np.random.Generator, extra=None, registration=None,
                 noise_um: float = 0.01) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Interferometer map on a 1 mm grid over the 137 mm window (NaN outside / dropouts):
    ``factor`` times the truth (moved by ``registration`` = (dx, dy, rot_deg): the feature at
    q appears at R q + d), plus ``extra(x, y)``, piston ±0.5 µm, tilt ±2 µrad, white noise,
    correlated noise (Gaussian-filtered, 3-10 mm, 0.003-0.008 µm) and 3 % dropouts."""
    ax = np.arange(-68.0, 68.0 + 0.5, 1.0)
    X, Y = np.meshgrid(ax, ax)
    qx, qy = X, Y
    if registration is not None:
        dx, dy, rot = registration
        c, s = math.cos(math.radians(rot)), math.sin(math.radians(rot))
        xr, yr = X - dx, Y - dy
        qx, qy = c * xr + s * yr, -s * xr + c * yr
    z = factor * sag_function(g)(qx, qy)
    if extra is not None:
        z = z + extra(X, Y)
    z = z + rng.uniform(-0.5, 0.5) + rng.uniform(-2e-3, 2e-3) * X + rng.uniform(-2e-3, 2e-3) * Y
    z = z + rng.normal(0.0, noise_um, z.shape)
    cn = gaussian_filter(rng.normal(size=z.shape), rng.uniform(3.0, 10.0), mode="wrap")
    z = z + cn / cn.std() * rng.uniform(0.003, 0.008)
    z[(X**2 + Y**2 > (0.5 * APERTURE_MM) ** 2) | (rng.random(z.shape) < 0.03) | ~np.isfinite(z)] = np.nan
    return ax, ax, z


def make_case(kind: str, effect: str, rng: np.random.Generator, nominal, fea, out: Path, cfg,
              settings: AbbeSettings = AbbeSettings()) -> tuple[dict, dict]:
    """Write one independent case into ``out``; returns (manifest dict, injected truth).

    ``nominal``, ``fea``: the diagnosed nominal and the truth's FEA map (SagMap-like:
    ``x_mm``, ``y_mm``, ``sag_um``) at 80 K. ``cfg``: a CampaignConfig (nominal_mesh,
    profile_specs, profile_map_K, noise_um). The truth dict holds the injected
    parameters, and under ``"_present"`` the library effects the truth carries besides
    the injected one (``quilt_shape``: its quilt shape differs from the nominal's), under
    ``"_truth"`` how it was made."""
    g = truth_grating(nominal, fea, rng, getattr(cfg, "truth_families", FAMILIES))
    sim = {**NOMINAL_SIMULATION, "mesh": cfg.nominal_mesh}
    meta = {"family": g.family, "mix": g.mix, "harmonic_distance": g.distance,
            "fundamental_x_ratio": fundamental_x_ratio(g.x_mm, g.y_mm, g.sag_um, nominal.sag_um), **g.params}
    truth: dict = {}
    if kind == "surface":
        scale, T, extra, reg = 1.0, SURFACE_T_K, None, None
        if (kind, effect) not in CASE_TYPES:
            raise ValueError(f"make_case: surface effect={effect!r} is not a case type of the independent truth")
        if effect in SURFACE_OOL:
            truth, extra = draw_surface_ool(effect, rng)
        else:
            truth = DRAWS[effect](rng, kind, "spare")
            scale = truth.get("scale_spare", 1.0)
            if "temperature_offset_K" in truth:
                T = SURFACE_T_K + truth["temperature_offset_K"]
            if "astig_0_um" in truth:
                R = 0.5 * APERTURE_MM

                def extra(x, y):
                    rho, t = np.hypot(x, y) / R, np.arctan2(y, x)
                    return truth["astig_0_um"] * zernike_noll(2, 2, rho, t) + truth["astig_45_um"] * zernike_noll(2, -2, rho, t)
            if "reg_dx_mm" in truth:
                reg = (truth["reg_dx_mm"], truth["reg_dy_mm"], truth["reg_rot_deg"])
        x, y, z = measured_map(g, scale * thermal_factor(T, _COLD_K), rng, extra, reg, cfg.noise_um)
        np.savez(out / "map.npz", x_mm=x, y_mm=y, sag_um=z)
        meas = [{"kind": "surface", "file": "map.npz", "temperature_K": SURFACE_T_K, "aperture_diameter_mm": APERTURE_MM}]
        return {"simulation": sim, "measurement": meas}, {**truth, "_present": ["quilt_shape"], "_truth": meta}
    scale, shift, coll, slit, distortion, camera, artefact = 1.0, (0.0, 0.0), dict(COLLIMATOR_UM), None, None, None, None
    if (kind, effect) not in CASE_TYPES + PAIR_CASE_TYPES:
        raise ValueError(f"make_case: line_profile effect={effect!r} is not a case type of the independent truth")
    if effect in PROFILE_OOL:
        truth, distortion, camera, artefact = draw_profile_ool(effect, rng)
    else:
        truth = {k: v for e in effect.split("+") for k, v in DRAWS[e](rng, kind, _PROFILE_BLANK).items()}
        scale = truth.get(f"scale_{_PROFILE_BLANK}", 1.0)
        if "temperature_offset_K" in truth:
            scale = thermal_factor(_COLD_K + truth["temperature_offset_K"], _COLD_K)
        if "pupil_x_mm" in truth:
            shift = (truth["pupil_x_mm"], truth["pupil_y_mm"])
        for key, nm in (("coll_coma_um", (3, 1)), ("coll_defocus_um", (2, 0)), ("coll_astig45_um", (2, -2))):
            if key in truth:
                coll[nm] = coll.get(nm, 0.0) + truth[key]
        slit = truth.get("slit_image_width_um")
    sag = sag_function(g.scaled(scale))
    meas = []
    for i, (gr, wl, order, ps) in enumerate(cfg.profile_specs):
        # the library's slit width is the 27 µm gratings'; the 29 µm HK slit scales alike
        slit_i = None if slit is None else slit * GRATINGS[gr][4] / 27.0
        u, det = abbe_line_profile(gr, wl, order, RELATIVE_NA[ps], sag, pupil_shift_mm=shift, collimator_um=coll,
                                   camera_um=camera, slit_image_width_um=slit_i, settings=settings)
        x, counts, info = measure_profile(u, det, rng, distortion=distortion)
        if artefact is not None:
            counts = artefact(x, counts, rng)
        write_line_profile_csv(out / f"p{i}.csv", x, counts)
        meas.append({"kind": "line_profile", "file": f"p{i}.csv", "name": f"{gr}_{wl}_{ps}mas", "grating": gr,
                     "order": order, "wavelength_um": wl, "pixel_scale_mas": ps})
        if getattr(cfg, "state_correlated_noise", False):
            meas[-1].update(correlated_noise_counts=float(info["correlated_noise_counts"]),
                            correlation_length_um=float(info["correlation_length_um"]))
    if cfg.profile_map_K is not None:
        dT = truth.get("temperature_offset_K", 0.0)
        x, y, z = measured_map(g, scale * thermal_factor(cfg.profile_map_K + dT, _COLD_K + dT), rng, None, None, cfg.noise_um)
        np.savez(out / "map.npz", x_mm=x, y_mm=y, sag_um=z)
        # The map is of the profiles' blank: said so, else the diagnosis reads it as a spare
        # blank's, with an amplitude scale of its own.
        meas.append({"kind": "surface", "file": "map.npz", "temperature_K": cfg.profile_map_K,
                     "aperture_diameter_mm": APERTURE_MM, "blank": _PROFILE_BLANK})
    if getattr(cfg, "psf_image", None) is not None:
        # Drawn last: the profiles (and map) are those of the campaign without the image.
        gr, wl, order, pix = cfg.psf_image
        # as far as the measured lattice reads, plus 2 µm for the cubic interpolation's stencil
        ux, uy, img = point_image(gr, wl, order, sag, pupil_shift_mm=shift, collimator_um=coll, camera_um=camera,
                                  settings=settings, half_range_um=image_reach_um(pix) + 2.0)
        x, y, counts, _ = measure_image(ux, uy, img, rng, pixel_um=pix)
        write_psf_image_csv(out / "psf.csv", x, y, counts)
        meas.append({"kind": "psf_image", "file": "psf.csv", "name": f"{gr}_{wl}_psf", "grating": gr, "order": order,
                     "wavelength_um": wl, "pixel_um": pix})
    return {"simulation": sim, "measurement": meas}, {**truth, "_present": ["quilt_shape"], "_truth": meta}
