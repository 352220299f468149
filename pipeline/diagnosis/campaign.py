"""Injection-recovery campaign (``cryograting diagnose --validate``).

Each case draws one effect (library or out-of-library) at a random magnitude, makes
synthetic measurements from a truth, withholds the effect from the model (default-mesh
nominal) and runs :func:`~pipeline.diagnosis.diagnose`. Two truth generators
(``CampaignConfig.truth``, ``--truth``):

* ``"independent"`` (default): :mod:`pipeline.diagnosis.truth` — optics by a 2-D
  finite-slit Abbe sum written apart from the forward model, quilt-shape mixtures at a
  5-30 % harmonic distance from the nominal, detector effects, and out-of-library
  families of ``benchmarks/truth_families.md`` (its case types: ``truth.CASE_TYPES``);
* ``"model"``: the diagnosis's own forward code (:mod:`.synth`): refined-mesh FEA map +
  a random model discrepancy, converged LSF sampling, noise, piston/tilt or
  shift/flux/background, dropouts, sparse sampling (case types :data:`CASE_TYPES`).

Scoring: a library case is *correct* when the verdict is ``explained`` and the top
finding is the injected effect alone or lists it in ``degenerate_with`` (the engine
says the data cannot tell the two apart, as the issue asks it to); its parameters
are *recovered* when every parameter of the injected effect's own fit is within 20 %
(``|fit - true| / max(|true|, floor)``, floors in :mod:`.effects`), comparing
magnitudes for parameters the engine reports as ``sign_degenerate``. Reported beside it
(:func:`recovery_errors`): the *vector* rule for effects whose parameters are one
physical vector (astigmatism and collimator WFE: orthonormal Zernike coefficients,
whose error norm is the RMS of the wavefront/surface error; pupil shift: a
displacement), ``||fit - true|| <= 0.2 ||true||``, and whether the truth lies within
2 sigma of the fit (honest error bars). The line-profile measurement set is
``CampaignConfig.profile_specs`` (:data:`PROFILE_SETS`).
Out-of-library cases should end ``unexplained`` (or ``no_gap``). A companion the top
finding adopts that the truth does not carry (the injected effect, and the truth's
``present`` effects: ``quilt_shape`` for the independent truth, bow and plating
gradient for the model truth's ``"companions"`` discrepancy) is a false attribution:
the case is not correct, and the confusion matrix counts it as ``<top>+<companion>``.
The summary gives the three scores per measurement kind (``by_measurement``: map only,
profiles only, profiles + map). Beside the correct top effect it gives the same count in
the diagnosis's own amplitude convention (``correct_top_fundamental``,
:func:`score_case_fundamental`): an independent truth is normalised to the nominal as a
whole, so its x fundamental, which the rescalings measure, may differ from the nominal's;
where it does by more than the amplitude's floor, a rescaling named beside the injected
effect is part of the truth, not a false attribution. The same convention with the
rescalings judged by their value (``correct_top_measured``, :func:`score_case_measured`):
a rescaling named beside the injected effect is part of the truth when its factor lies
within that floor of the truth's x-fundamental ratio (times the injected rescaling's
factor), whatever the ratio; and ``recovered_20pct_measured`` compares a rescaled truth's
parameters in that convention (:func:`measured_truth`), the other effects' as the named
finding reads them.

The model discrepancy (``CampaignConfig.discrepancy``): ``"unmodelled"`` (default) is a
0.01 µm RMS trefoil/tetrafoil/pentafoil surface error (:func:`~.synth.unmodelled_shape`),
outside the library, so that it stays in every case's residual; ``"companions"`` is the
bow and plating gradient of the paper scenarios (:func:`~.synth.shape_discrepancy`). Those are
library companions: a map or a focal-plane image finds them (delta BIC -165 … -512), so
with them every out-of-library case also carries a library effect, and a companion-only
``explained`` verdict on it is a correct finding counted as a false attribution.

Cases are independent and seeded by ``(seed, index)``; they run in worker processes.
The nominal and truth FEA maps are computed once (disk cache) before the pool starts.
"""

from __future__ import annotations

import json
import math
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from optics.sagmap import SagMap
from optics.zernike import zernike_xy
from pipeline.io.measured import write_line_profile_csv, write_psf_image_csv
from pipeline.io.registry import write_sag_map

from .effect_draws import signed_uniform
from .effects import LIBRARY, Effect, SummaryContext, draw_campaign_truth, parameter_spec
from .effects.rescaling import offset_for_factor
from .engine import Criteria, diagnose
from .forward import blank_coordinates, deformation_factor, map_terms_um, true_temperature
from .manifest import NOMINAL_SIMULATION, Simulation
from .nominal import case_sag_map, thermal_factor
from .synth import (blank_shape_map, shape_discrepancy, synthetic_profile, synthetic_psf_image, synthetic_surface,
                    unmodelled_shape)

__all__ = ["CASE_TYPES", "EXTRA_CASE_TYPES", "DISCREPANCIES", "DISCREPANCY_PRESENT", "TRUTHS", "PROFILE_SETS", "PSF_IMAGE_SPEC",
           "OUT_OF_LIBRARY", "parse_types", "CampaignConfig", "score_case", "recovery_errors", "on_truth_side", "make_case",
           "case_type",
           "run_case", "run_campaign",
           "one_blas_thread", "write_campaign"]

CASE_TYPES = (
    ("surface", "astigmatism"), ("surface", "amplitude_scale"), ("surface", "temperature"),
    ("surface", "registration"), ("surface", "ool_coma"), ("surface", "ool_bump"),
    ("line_profile", "amplitude_scale"), ("line_profile", "temperature"), ("line_profile", "pupil_shift"),
    ("line_profile", "collimator_wfe"), ("line_profile", "slit_width"),
    ("line_profile", "ool_ghost"), ("line_profile", "ool_distortion"),
)
#: Case types run only when asked for (``only_types`` / ``--types``), after CASE_TYPES in the
#: cycle, so that the default campaign's cases keep their indices and draws: every other
#: (kind, effect) of a library effect with a truth draw (a new effect's cases are these
#: until it is appended to CASE_TYPES, which changes the default campaign's draws).
EXTRA_CASE_TYPES = tuple((k, e.name) for e in LIBRARY.values() if e.draw_truth is not None
                         for k in ("surface", "line_profile") if k in e.kinds and (k, e.name) not in CASE_TYPES)
#: (grating, wavelength µm, order, pixel scale mas) of the synthetic line profiles.
#: "minimal": the three profiles of the first campaigns. "extended": what an instrument
#: team measures in a J-band line-profile test (the paper's set: all three pixel scales at
#: 1.25 µm, lines at the band edges 1.10 / 1.40 µm and at 1.175 µm at 25 mas). With
#: white noise alone the extra profiles shrink the collimator errors only 1.2-1.4x
#: (Fisher matrix, benchmarks/results_diagnosis.md); what they buy is robustness against the model
#: discrepancy: the truth's bow and plating gradient can no longer be absorbed by
#: trading the collimator's defocus against its oblique astigmatism on one pixel scale.
PROFILE_SETS = {
    "minimal": (("J", 1.25, -2, 250), ("J", 1.25, -2, 25), ("J", 1.175, -2, 25)),
    "extended": (("J", 1.25, -2, 250), ("J", 1.25, -2, 100), ("J", 1.25, -2, 25),
                 ("J", 1.10, -2, 25), ("J", 1.175, -2, 25), ("J", 1.40, -2, 25)),
}
#: The campaign's optional point-source image (``--psf-image``): J grating, 1.25 µm,
#: order -2, imaged in the focal plane (no pixel: a microscope-relayed image resolves
#: the ~4 µm diffraction core, which the 18 µm detector pixel would smooth away).
PSF_IMAGE_SPEC = ("J", 1.25, -2, 0.0)
#: The blank a line-profile case's truth is drawn for (the profile sets' grating): the map
#: beside the profiles is of it too.
_PROFILE_BLANK = "J"
PROFILE_SPECS_MINIMAL = PROFILE_SETS["minimal"]
PROFILE_SPECS = PROFILE_SETS["extended"]
SURFACE_T_K = 128.0
#: Aperture (mm) of the campaign's synthetic maps.
MAP_APERTURE_MM = 137.0
#: CampaignConfig.discrepancy -> the truth's model discrepancy (see the module docstring).
DISCREPANCIES = {"unmodelled": unmodelled_shape, "companions": shape_discrepancy}
#: Library effects the model truth carries besides the injected one, per discrepancy.
DISCREPANCY_PRESENT = {"unmodelled": (), "companions": ("blank_bow", "plating_gradient")}
#: CampaignConfig.truth: the truth generators (module docstring).
TRUTHS = ("independent", "model")


@dataclass(frozen=True)
class CampaignConfig:
    """Campaign size, seed, parallelism and noise (µm for maps, fraction of peak for profiles)."""

    n_cases: int = 200
    seed: int = 1
    nominal_mesh: str = "default"
    truth_mesh: str = "refined"
    workers: int = 2
    noise_um: float = 0.01
    noise_rel: float = 0.01
    #: Case types cycled over; None: the truth generator's own (:data:`CASE_TYPES` for
    #: "model", :data:`pipeline.diagnosis.truth.CASE_TYPES` for "independent").
    case_types: tuple | None = None
    profile_specs: tuple = PROFILE_SPECS
    #: If set, the line-profile cases also get a cold-minus-warm map of the same blank at
    #: this temperature (K), as in the paper's data (a cryogenic interferogram beside the
    #: line profiles); None: profiles only.
    profile_map_K: float | None = None
    #: If set, (grating, wavelength µm, order, pixel µm) of a point-source image that the
    #: line-profile cases also get (:data:`PSF_IMAGE_SPEC`: a focal-plane image of the J
    #: grating at 1.25 µm, 1 µm steps over ±30 µm); None: no image.
    psf_image: tuple | None = None
    #: Run only the cases of these (kind, effect) types, keeping every case's index (and so
    #: its random draws): the same cases as the full campaign's, for comparisons.
    only_types: tuple | None = None
    #: The truth's model discrepancy, a key of :data:`DISCREPANCIES`.
    discrepancy: str = "unmodelled"
    #: The truth generator, one of :data:`TRUTHS`.
    truth: str = "independent"
    #: The independent truth's grating families (``benchmarks/truth_families.md``), one
    #: drawn per case; the default is ``pipeline.diagnosis.truth.generate.FAMILIES``.
    truth_families: tuple = ("sum_mix", "product_mix")
    #: The independent truth's profile manifests state the correlated noise its detector drew
    #: for each profile (``correlated_noise_counts``, ``correlation_length_um``), as a lab that
    #: characterised its detector on flats would; False: they state no noise.
    state_correlated_noise: bool = False
    criteria: Criteria = Criteria(heldout_top=1, pair_from=2)

    def __post_init__(self) -> None:
        from pipeline.bounds import MAX_CAMPAIGN_CASES

        if (isinstance(self.n_cases, bool) or not isinstance(self.n_cases, int)
                or not 1 <= self.n_cases <= MAX_CAMPAIGN_CASES):
            raise ValueError(f"CampaignConfig: n_cases={self.n_cases!r} must be an integer in the valid range "
                             f"1..{MAX_CAMPAIGN_CASES}")
        if isinstance(self.workers, bool) or not isinstance(self.workers, int) or self.workers < 1:
            raise ValueError(f"CampaignConfig: workers={self.workers!r} must be an integer >= 1")
        if self.truth not in TRUTHS:
            raise ValueError(f"CampaignConfig: truth={self.truth!r} is not one of {list(TRUTHS)}")
        from .truth.generate import check_families

        object.__setattr__(self, "truth_families", check_families(self.truth_families))
        if self.case_types is None:
            from .truth import CASE_TYPES as INDEPENDENT_TYPES

            object.__setattr__(self, "case_types", INDEPENDENT_TYPES if self.truth == "independent" else CASE_TYPES)
        if self.profile_map_K is not None and not 20.0 <= self.profile_map_K <= 290.0:
            raise ValueError(f"CampaignConfig: profile_map_K={self.profile_map_K} K is outside the valid range "
                             "20 ... 290 K (or None: profiles only)")
        if self.psf_image is not None and (len(self.psf_image) != 4 or not 0 <= self.psf_image[3] <= 100):
            raise ValueError(f"CampaignConfig: psf_image={self.psf_image!r} must be (grating, wavelength_um, order, "
                             "pixel_um) with pixel_um in [0, 100] (or None)")
        if self.state_correlated_noise and self.truth != "independent":
            raise ValueError(f"CampaignConfig: state_correlated_noise=True needs truth='independent' (truth="
                             f"{self.truth!r} adds white noise only)")
        if self.discrepancy not in DISCREPANCIES:
            raise ValueError(f"CampaignConfig: discrepancy={self.discrepancy!r} is not one of {sorted(DISCREPANCIES)}")
        extra = EXTRA_CASE_TYPES if self.truth == "model" else _pair_types()  # opt-in cases
        unknown = set(self.only_types or ()) - set(self.case_types) - set(extra)
        if unknown:
            raise ValueError(f"CampaignConfig: only_types {sorted(unknown)} are not case types; valid: "
                             f"{[f'{k}:{e}' for k, e in self.case_types]}")


def parse_types(text: str | None, truth: str = "model") -> tuple | None:
    """``"line_profile:collimator_wfe,surface:astigmatism"`` -> ((kind, effect), ...); None -> None.
    ``truth``: the generator whose case types are valid (:data:`TRUTHS`)."""
    if not text:
        return None
    from .truth import CASE_TYPES as INDEPENDENT_TYPES

    valid = INDEPENDENT_TYPES + _pair_types() if truth == "independent" else CASE_TYPES + EXTRA_CASE_TYPES
    out = []
    for item in text.split(","):
        kind, sep, effect = item.strip().partition(":")
        if not sep or (kind, effect) not in valid:
            raise ValueError(f"--types: {item.strip()!r} is not a case type of the {truth} truth; valid: "
                             f"{[f'{k}:{e}' for k, e in valid]}")
        out.append((kind, effect))
    return tuple(out)


_COLD_K = NOMINAL_SIMULATION["cold_K"]


def _pair_types() -> tuple:
    """The independent truth's opt-in cases with two effects injected together."""
    from .truth import PAIR_CASE_TYPES

    return PAIR_CASE_TYPES


def injected(effect: str) -> tuple[str, ...]:
    """The effects a case type injects: ``"a+b"`` (a pair case) -> ``("a", "b")``."""
    return tuple(effect.split("+"))


def in_library(effect: str) -> bool:
    """Whether every effect a case type injects is a library effect (the diagnosis should
    name it) rather than out of the library (it should be left ``unexplained``)."""
    return all(e in LIBRARY for e in injected(effect))


def _ool_coma(rng):
    a, th = rng.uniform(0.04, 0.15), rng.uniform(0, 2 * np.pi)
    return {"coma_um": a, "angle_rad": th}, \
        lambda x, y: a * (math.cos(th) * zernike_xy(3, 1, x, y, 68.5) + math.sin(th) * zernike_xy(3, -1, x, y, 68.5))


def _ool_bump(rng):
    h, w = signed_uniform(rng, 0.1, 0.3), rng.uniform(12.0, 30.0)
    r, th = rng.uniform(0, 45.0), rng.uniform(0, 2 * np.pi)
    x0, y0 = r * math.cos(th), r * math.sin(th)
    return ({"height_um": h, "sigma_mm": w, "x0_mm": x0, "y0_mm": y0},
            lambda x, y: h * np.exp(-((x - x0) ** 2 + (y - y0) ** 2) / (2 * w * w)))


def _ool_ghost(rng):
    h, u0 = rng.uniform(0.03, 0.08), signed_uniform(rng, 45.0, 90.0)
    return {"ghost_rel": h, "ghost_offset_um": u0}, lambda u, y: y + h * y.max() * np.exp(-0.5 * ((u - u0) / 4.0) ** 2)


def _ool_distortion(rng):
    a = signed_uniform(rng, 0.1, 0.25)
    return {"tilt_rel": a}, lambda u, y: y * (1.0 + a * np.tanh(u / 30.0))


#: Out-of-library case types of the model truth: ``draw(rng) -> (truth, change)`` with the
#: change a surface ``extra_um(x, y)`` added to the map (drawn after the model
#: discrepancy) or a profile ``distortion(u, y) -> y`` (drawn before it).
OUT_OF_LIBRARY = {"surface": {"ool_coma": _ool_coma, "ool_bump": _ool_bump},
                  "line_profile": {"ool_ghost": _ool_ghost, "ool_distortion": _ool_distortion}}


def _applies(e: Effect, kind: str) -> bool:
    """Whether :func:`make_case` applies effect ``e``'s truth to a case of ``kind``: through
    the blank's deformation (``scale``, ``temperature``, ``shape``: at ``truth_stage``
    "blank" on a map), the measured map (``coordinates``, ``map_zernike``: at "map") or,
    for line profiles, the deformation or the spectrograph (``pupil_zernike``, ``optics``)."""
    blank = e.scale is not None or e.temperature is not None or e.shape is not None
    if kind == "surface":
        return blank if e.truth_stage == "blank" else (e.coordinates is not None or bool(e.map_zernike))
    return blank or e.optics is not None or bool(e.pupil_zernike)


def _library_truth(effect: str, kind: str, rng: np.random.Generator, blank: str) -> dict:
    """The effect's drawn truth; ValueError if :func:`make_case` would not apply it (the
    case would silently inject nothing)."""
    truth = draw_campaign_truth(effect, kind, rng, blank)
    e = LIBRARY[effect]
    if not _applies(e, kind):
        raise ValueError(f"make_case: parameters {sorted(truth)} of effect={effect!r} are not applied to a {kind} "
                         f"truth: the effect has no hook for it (Effect.scale, temperature or shape at truth_stage "
                         f"'blank', coordinates or map_zernike at 'map'; for line profiles also pupil_zernike or "
                         f"optics)")
    return truth


def make_case(kind: str, effect: str, rng: np.random.Generator, base: SagMap, out: Path,
              cfg: CampaignConfig) -> tuple[dict, dict]:
    """Write one synthetic case into ``out``; returns (manifest dict, injected truth).

    A library effect's truth is its ``Effect.draw_truth``; it is applied through the
    effect's hooks (:class:`~.effects.Effect`), as the forward model applies them: the
    overall factor and the blank's shape (decomposed from the truth's own map) change the
    blank's deformation before the model discrepancy; the measured points' coordinates
    and the map terms change a map after it (a "map"-stage truth is drawn after the
    discrepancy); the spectrograph's hooks act in the profile and PSF-image synthesis."""
    if kind not in OUT_OF_LIBRARY:
        raise ValueError(f"make_case: kind={kind!r} is not one of {list(OUT_OF_LIBRARY)}")
    if effect not in LIBRARY and effect not in OUT_OF_LIBRARY[kind]:
        raise ValueError(f"make_case: effect={effect!r} is not a {kind} case type; valid: library effects and "
                         f"{sorted(OUT_OF_LIBRARY[kind])}")
    sim = {**NOMINAL_SIMULATION, "mesh": cfg.nominal_mesh}
    lib = LIBRARY.get(effect)
    truth = {}
    if kind == "surface":
        if lib is not None and lib.truth_stage == "blank":
            truth = _library_truth(effect, kind, rng, "spare")
        k = deformation_factor(truth, "spare", SURFACE_T_K, _COLD_K)
        t = DISCREPANCIES[cfg.discrepancy](blank_shape_map(base, truth).scaled(k), rng)
        extra = None
        if lib is None:
            truth, extra = OUT_OF_LIBRARY[kind][effect](rng)
        else:
            if lib.truth_stage == "map":
                truth = _library_truth(effect, kind, rng, "spare")
            if {name for name, _ in lib.map_zernike} & set(truth):
                extra = lambda x, y: map_terms_um(x, y, 0.5 * MAP_APERTURE_MM, truth)  # noqa: E731
            moved = blank_coordinates(*t.grid(), truth)
            if moved is not None:
                t = t.with_sag(t.sample(*moved))
        m = synthetic_surface(t, rng, noise_um=cfg.noise_um, extra_um=extra)
        write_sag_map(m, out / "map.npz")
        meas = [{"kind": "surface", "file": "map.npz", "temperature_K": SURFACE_T_K,
                 "aperture_diameter_mm": MAP_APERTURE_MM}]
        return {"simulation": sim, "measurement": meas}, truth
    distortion = None
    if lib is None:
        truth, distortion = OUT_OF_LIBRARY[kind][effect](rng)
    else:
        truth = _library_truth(effect, kind, rng, _PROFILE_BLANK)
    # The profiles are stated at the simulation's cold temperature.
    k = deformation_factor(truth, _PROFILE_BLANK, _COLD_K, _COLD_K)
    # A library truth's spectrograph hooks act in the optics (its others ignore the optics).
    params = truth if lib is not None else {}
    t = DISCREPANCIES[cfg.discrepancy](blank_shape_map(base, truth).scaled(k), rng)
    meas = []
    for i, (g, wl, order, ps) in enumerate(cfg.profile_specs):
        u, y, _ = synthetic_profile(g, wl, order, ps, t, rng, params=params, noise_rel=cfg.noise_rel, distortion=distortion)
        write_line_profile_csv(out / f"p{i}.csv", u, y)
        meas.append({"kind": "line_profile", "file": f"p{i}.csv", "name": f"{g}_{wl}_{ps}mas", "grating": g,
                     "order": order, "wavelength_um": wl, "pixel_scale_mas": ps})
    if cfg.profile_map_K is not None:
        # The same blank (discrepancy included) cooled to the map's temperature; a
        # temperature offset is one of the cryostat's reading, so it applies here too.
        # Drawn after the profiles: the profiles are those of the profile-only campaign.
        m = synthetic_surface(t.scaled(thermal_factor(true_temperature(cfg.profile_map_K, truth),
                                                      true_temperature(_COLD_K, truth))), rng, noise_um=cfg.noise_um)
        write_sag_map(m, out / "map.npz")
        # The map is of the profiles' blank: said so, else the diagnosis reads it as a
        # spare blank's, with an amplitude scale of its own.
        meas.append({"kind": "surface", "file": "map.npz", "temperature_K": cfg.profile_map_K,
                     "aperture_diameter_mm": MAP_APERTURE_MM, "blank": _PROFILE_BLANK})
    if cfg.psf_image is not None:
        # Drawn last: the profiles (and map) are those of the campaign without the image.
        g, wl, order, pix = cfg.psf_image
        x, y, v, _ = synthetic_psf_image(g, wl, order, t, rng, params=params, noise_rel=cfg.noise_rel, pixel_um=pix,
                                         step_um=1.0, half_range_um=30.0)
        write_psf_image_csv(out / "psf.csv", x, y, v)
        meas.append({"kind": "psf_image", "file": "psf.csv", "name": f"{g}_{wl}_psf", "grating": g, "order": order,
                     "wavelength_um": wl, "pixel_um": pix})
    return {"simulation": sim, "measurement": meas}, truth


def on_truth_side(fit, true: float, origin: float):
    """``fit`` (a value or an array of readings), each reading on the other side of ``origin``
    from ``true`` replaced by its mirror ``2 origin - fit``: how a parameter whose sign the
    engine does not claim (``sign_degenerate``) is compared with the truth, by its magnitude
    about its sign origin (:attr:`.effects.Parameter.origin`)."""
    v = np.asarray(fit, float)
    out = np.where((v - origin) * (true - origin) >= 0, v, 2.0 * origin - v)
    return float(out) if out.ndim == 0 else out


def recovery_errors(d, effect: str, truth: dict, finding=None) -> dict | None:
    """Recovery of the injected parameters by the injected effect's own fit (or by
    ``finding``, a finding that holds the effect: the one the diagnosis names).

    ``per_parameter``: max over parameters of ``|fit - true| / max(|true|, floor)``
    (floors in :mod:`.effects`). ``vector`` (effects with ``Effect.vector``: Zernike
    coefficients of orthonormal terms, a displacement): ``||fit - true|| / max(||true||, floor)``,
    i.e. the RMS of the fitted-minus-injected surface/wavefront error (or the length of the
    displacement error) relative to the injected one; other effects: equal to
    ``per_parameter``. For parameters the engine reports as ``sign_degenerate`` the
    magnitudes about the parameter's sign origin (:attr:`.effects.Parameter.origin`) are
    compared (the engine does not claim a sign). ``within_2sigma``: every
    parameter within twice its reported 1-sigma uncertainty of the truth (are the error
    bars honest?). None if the effect is out of the library or was not fitted."""
    f = d.finding(effect) if finding is None else finding
    if f is None or not in_library(effect):
        return None
    floors = {q.name: q.floor for e in injected(effect) for q in LIBRARY[e].parameters}
    errs, dv, tv, sig_ok = [], [], [], True
    for k, v in truth.items():
        fit = f.parameters.get(k)
        floor = floors.get(k, floors.get(k.rsplit("_", 1)[0], 0.0))
        if fit is None:
            errs.append(math.inf)
            sig_ok = False
            continue
        if k in f.sign_degenerate:  # sign undetermined: magnitudes compared about the sign origin
            fit = on_truth_side(fit, v, parameter_spec(k).origin)
        errs.append(abs(fit - v) / max(abs(v), floor))
        dv.append(fit - v)
        tv.append(v)
        sig_ok &= abs(fit - v) <= 2.0 * f.uncertainties.get(k, math.inf)
    if not errs:
        return None
    per = float(max(errs))
    vec = per
    if len(injected(effect)) == 1 and LIBRARY[effect].vector and len(dv) == len(errs):
        vec = float(np.linalg.norm(dv) / max(np.linalg.norm(tv), max(floors.values())))
    return {"per_parameter": per, "vector": vec, "within_2sigma": bool(sig_ok)}


#: The library's rescaling effects (``Effect.rescales``) and the amplitude's floor: the
#: amplitude conventions' unit of "no distinguishable change" of the deformation factor.
_RESCALINGS = tuple(name for name, e in LIBRARY.items() if e.rescales)
_AMPLITUDE_FLOOR = LIBRARY["amplitude_scale"].parameters[0].floor


def rescalings_present(fundamental_x_ratio: float | None) -> tuple[str, ...]:
    """The rescaling effects an independent truth carries in the diagnosis's own amplitude
    convention: the rescalings measure the quilt's x fundamental (what a line profile
    sees), so a truth whose x fundamental differs from the nominal's by more than the
    amplitude's floor carries an amplitude change, though its whole map is normalised to
    the nominal (``k = 1``, :mod:`.truth.gratings`). Empty without a ratio."""
    if fundamental_x_ratio is None:
        return ()
    if abs(float(fundamental_x_ratio) - 1.0) <= _AMPLITUDE_FLOOR:
        return ()
    return _RESCALINGS


def score_case_fundamental(verdict: str, best, effect: str, present=(), fundamental_x_ratio=None) -> bool:
    """Correct in the diagnosis's amplitude convention: as :func:`score_case`, and also a
    top finding that names the injected effect beside a rescaling the truth carries by
    :func:`rescalings_present` (for a rescaling truth, the same rescaling)."""
    if score_case(verdict, best, effect, present)[0]:
        return True
    rescaled = rescalings_present(fundamental_x_ratio)
    allowed = {*injected(effect), *present, *rescaled}
    if verdict != "explained" or best is None or not in_library(effect) or not rescaled:
        return False
    false = _false_companions(best, allowed)
    names = set(injected(effect)) <= set(best.effects) or effect in best.degenerate_with
    return bool(names and set(best.effects) <= allowed and not false)


def _reference(kind: str) -> tuple[str, float]:
    """The blank and the stated temperature (K) of a case's rescaled measurements: a map-only
    case's spare blank at :data:`SURFACE_T_K`, a profile case's grating at the simulation's
    cold temperature."""
    return ("spare", SURFACE_T_K) if kind == "surface" else (_PROFILE_BLANK, _COLD_K)


def rescaling_factor(parameters: dict, kind: str) -> float:
    """The deformation factor that the rescaling parameters among ``parameters`` (a
    finding's or a truth's) give a case's measurements of ``kind`` against the nominal at
    their stated temperature (1: none): the thermal factor of a temperature offset times the
    blank's amplitude scale (:func:`~.forward.deformation_factor`)."""
    blank, T = _reference(kind)
    return float(deformation_factor(parameters, blank, T, T))


def measured_rescaling(kind: str, effect: str, truth: dict, fundamental_x_ratio: float | None) -> float:
    """The deformation factor a truth carries in the diagnosis's amplitude convention: the
    rescalings measure the quilt's x fundamental, so an independent truth's x-fundamental
    ratio (1 without one) times the injected rescaling's factor, if the injected effect is
    a rescaling."""
    k = 1.0 if fundamental_x_ratio is None else float(fundamental_x_ratio)
    return k * rescaling_factor(truth, kind) if in_library(effect) and LIBRARY[effect].rescales else k


def measured_truth(kind: str, effect: str, truth: dict, fundamental_x_ratio: float | None) -> dict:
    """The injected parameters in the diagnosis's amplitude convention: a rescaling's value
    that gives :func:`measured_rescaling` (the amplitude times the x-fundamental ratio; the
    temperature offset whose thermal factor is that ratio times the injected one's); other
    effects' parameters unchanged."""
    if fundamental_x_ratio is None or not (in_library(effect) and LIBRARY[effect].rescales):
        return dict(truth)
    blank, T = _reference(kind)
    out = {}
    for k, v in truth.items():
        if k == "temperature_offset_K":
            out[k] = offset_for_factor(v, float(fundamental_x_ratio), SummaryContext(cold_K=T))
        elif k == f"scale_{blank}":
            out[k] = v * float(fundamental_x_ratio)
        else:
            out[k] = v
    return out


def score_case_measured(verdict: str, best, effect: str, present, kind: str, true_factor: float) -> bool:
    """Correct with the rescalings judged by their value: as :func:`score_case`, and also a
    top finding that names the injected effect beside rescalings (as effects of the finding
    or companions; nothing else the truth does not carry) whose factor
    (:func:`rescaling_factor`) lies within the amplitude's floor (0.05) of the factor the
    truth carries in the diagnosis's amplitude convention (``true_factor``,
    :func:`measured_rescaling`). Unlike :func:`score_case_fundamental` this also holds for a
    truth whose x fundamental differs by less than the floor, and not for a rescaling the
    diagnosis reads wrong."""
    if score_case(verdict, best, effect, present)[0]:
        return True
    if verdict != "explained" or best is None or not in_library(effect):
        return False
    extra = (set(best.effects) | set(best.companions)) - {*injected(effect), *present}
    names = set(injected(effect)) <= set(best.effects) or effect in best.degenerate_with
    return bool(names and extra and extra <= set(_RESCALINGS)
                and abs(rescaling_factor(best.parameters, kind) - true_factor) <= _AMPLITUDE_FLOOR)


def _false_companions(best, allowed) -> list[str]:
    """The companions of the top finding ``best`` that are not among the ``allowed`` effects."""
    return [c for c in best.companions if c not in allowed]


def score_case(verdict: str, best, effect: str, present=()) -> tuple[bool, list[str]]:
    """(correct, false companions) of one case whose injected effect is ``effect`` and
    whose truth also carries the library effects ``present``.

    Correct: a library effect, verdict ``explained``, the top finding ``best`` is the
    effect alone or lists it in ``degenerate_with``, and it adopted no companion the
    truth does not carry. Such companions of an ``explained`` top finding are returned as
    false attributions, for any case (an ``unexplained`` verdict attributes nothing)."""
    explained = verdict == "explained" and best is not None
    false = _false_companions(best, {*injected(effect), *present}) if explained else []
    correct = bool(in_library(effect) and verdict == "explained" and best is not None
                   and (best.effects == injected(effect) or effect in best.degenerate_with) and not false)
    return correct, false


def run_case(args) -> dict:
    """One campaign case (picklable arguments: index, type, config, maps)."""
    index, (kind, effect), cfg, nominal, base = args
    rng = np.random.default_rng([cfg.seed, index])
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        if cfg.truth == "independent":
            from .truth import make_case as make_independent_case

            man, truth = make_independent_case(kind, effect, rng, nominal, base, Path(tmp), cfg)
        else:
            man, truth = make_case(kind, effect, rng, base, Path(tmp), cfg)
            truth = {**truth, "_present": list(DISCREPANCY_PRESENT[cfg.discrepancy])}
        present = truth.pop("_present", [])
        truth_info = truth.pop("_truth", None)
        from .manifest import parse_manifest

        try:
            d = diagnose(parse_manifest(man, tmp), criteria=cfg.criteria, nominal=nominal, keep_curves=False)
        except ValueError as exc:  # refused before any fit (implausible data): attributes nothing
            return {"index": index, "kind": kind, "effect": effect, "truth": truth, "truth_info": truth_info,
                    "truth_present": list(present), "measurement": _measurement_kind(kind, cfg),
                    "false_companions": [], "verdict": "refused", "refusal": str(exc), "top": None,
                    "correct": False, "correct_fundamental": False, "recovery_error": None,
                    "recovery_error_vector": None, "recovery_error_named": None,
                    "correct_measured": False, "recovery_error_measured": None,
                    "within_2sigma": None, "seconds": time.perf_counter() - t0}
    best = d.best
    own = d.finding(effect) if in_library(effect) else None  # the injected effect's own fit
    rec = recovery_errors(d, effect, truth)
    # what a user reads: the parameters of the named finding, where it holds the injected effect
    named = best if best and effect in best.effects else None
    rec_named = recovery_errors(d, effect, truth, finding=named) if named else None
    correct, false_companions = score_case(d.verdict, best, effect, present)
    fx = (truth_info or {}).get("fundamental_x_ratio")
    correct_fundamental = score_case_fundamental(d.verdict, best, effect, present, fx)
    # the rescalings judged by their value against what the truth carries in the amplitude
    # convention; parameters by the named finding where it holds the effect, else its own fit
    true_factor = measured_rescaling(kind, effect, truth, fx)
    correct_measured = score_case_measured(d.verdict, best, effect, present, kind, true_factor)
    rec_measured = recovery_errors(d, effect, measured_truth(kind, effect, truth, fx), finding=named)
    return {"index": index, "kind": kind, "effect": effect, "truth": truth, "truth_info": truth_info,
            "truth_present": list(present), "measurement": _measurement_kind(kind, cfg),
            "false_companions": false_companions, "verdict": d.verdict,
            "top": best.effect if best else None, "top_degenerate_with": list(best.degenerate_with) if best else [],
            "top_delta_bic": best.delta_bic if best else None, "top_shrink": best.shrink_fraction if best else None,
            "top_heldout_shrink": best.heldout_shrink_fraction if best else None,
            # each fold's outcome or why it was untestable: which rule decided a verdict
            "top_heldout_note": best.heldout_note if best else "",
            "correct": correct, "correct_fundamental": correct_fundamental,
            "rescalings_present": list(rescalings_present(fx)),
            "recovery_error": rec["per_parameter"] if rec else None,
            "recovery_error_vector": rec["vector"] if rec else None,
            "recovery_error_named": rec_named["per_parameter"] if rec_named else None,
            "correct_measured": correct_measured, "rescaling_true": true_factor,
            "rescaling_named": rescaling_factor(best.parameters, kind) if best else None,
            "recovery_error_measured": rec_measured["per_parameter"] if rec_measured else None,
            "top_parameters": best.parameters if best else None,
            "top_uncertainties": best.uncertainties if best else None,
            "within_2sigma": rec["within_2sigma"] if rec else None,
            "uncertainties": own.uncertainties if own else None,
            "fitted": own.parameters if own else None,
            "fitted_summary": own.summary if own else None,
            "sign_degenerate": list(own.sign_degenerate) if own else [],
            "companions": list(own.companions) if own else [],
            "top_companions": list(best.companions) if best else [],
            "top_absorbs": best.absorbs if best else {},
            "top_excess_explained": best.excess_explained if best else None,
            "top_excess_explained_overall": best.excess_explained_overall if best else None,
            "top_unconstrained": list(best.unconstrained) if best else [],
            "unexplained_in": [g["measurement"] for g in d.unexplained_in],
            "ranking_note": d.ranking_note, "n_eff": d.baseline["n_eff"], "n_count": d.baseline["n_count"],
            "map_departure_choice": d.baseline.get("map_departure_choice"), "checks": d.checks,
            "seconds": time.perf_counter() - t0}


def _measurement_kind(kind: str, cfg: CampaignConfig) -> str:
    """"map" (surface cases), "profiles" or "profiles+map" (line-profile cases)."""
    if kind == "surface":
        return "map"
    return "profiles" if cfg.profile_map_K is None else "profiles+map"


def _scores(rows: list[dict]) -> dict:
    """The three headline scores of ``rows`` (correct top, within 20 %, out-of-library unexplained).
    ``recovered_20pct`` reads the injected effect's own fit; ``recovered_20pct_named`` the named
    (top) finding's where it holds the injected effect (a pair named beside a rescaling has its
    own value of the effect's parameters). ``correct_top_measured`` and
    ``recovered_20pct_measured`` score in the diagnosis's amplitude convention with the
    rescalings judged by their value (:func:`score_case_measured`, :func:`measured_truth`;
    parameters of the named finding where it holds the effect, else of its own fit)."""
    lib = [r for r in rows if in_library(r["effect"])]
    ool = [r for r in rows if not in_library(r["effect"])]
    return {"n_library": len(lib), "n_ool": len(ool),
            "correct_top": sum(r["correct"] for r in lib),
            "correct_top_fundamental": sum(bool(r.get("correct_fundamental")) for r in lib),
            "recovered_20pct": sum(r["recovery_error"] is not None and r["recovery_error"] <= 0.2 for r in lib),
            "recovered_20pct_named": sum(r.get("recovery_error_named") is not None
                                         and r["recovery_error_named"] <= 0.2 for r in lib),
            "correct_top_measured": sum(bool(r.get("correct_measured")) for r in lib),
            "recovered_20pct_measured": sum(r.get("recovery_error_measured") is not None
                                            and r["recovery_error_measured"] <= 0.2 for r in lib),
            "ool_unexplained": sum(r["verdict"] != "explained" for r in ool),
            "false_companion_cases": sum(bool(r.get("false_companions")) for r in rows)}


def _summary(rows: list[dict], wall_s: float, cfg: CampaignConfig) -> dict:
    lib = [r for r in rows if in_library(r["effect"])]
    ool = [r for r in rows if not in_library(r["effect"])]
    confusion = {}
    for r in rows:
        row = confusion.setdefault(f"{r['kind']}:{r['effect']}", {})
        col = r["top"] if r["verdict"] == "explained" else r["verdict"]
        if r["verdict"] == "explained" and r.get("false_companions"):
            col = "+".join([col, *r["false_companions"]])
        row[col] = row.get(col, 0) + 1
    rec = [r["recovery_error"] for r in lib if r["recovery_error"] is not None]
    per_type = {}
    for key in confusion:
        rs = [r for r in rows if f"{r['kind']}:{r['effect']}" == key]
        e = [r["recovery_error"] for r in rs if r["recovery_error"] is not None]
        ev = [r["recovery_error_vector"] for r in rs if r.get("recovery_error_vector") is not None]
        per_type[key] = {"n": len(rs), "correct": sum(r["correct"] for r in rs),
                         "unexplained": sum(r["verdict"] != "explained" for r in rs),
                         "recovered_20pct": sum(x <= 0.2 for x in e), "median_recovery_error": float(np.median(e)) if e else None,
                         "recovered_20pct_vector": sum(x <= 0.2 for x in ev),
                         "median_recovery_error_vector": float(np.median(ev)) if ev else None,
                         "within_2sigma": sum(bool(r.get("within_2sigma")) for r in rs),
                         "sign_degenerate_flagged": sum(bool(r.get("sign_degenerate")) for r in rs),
                         "top_absorbs_flagged": sum(bool(r.get("top_absorbs")) for r in rs)}
    recv = [r["recovery_error_vector"] for r in lib if r.get("recovery_error_vector") is not None]
    return {"n_cases": len(rows), "correct_top_rate": sum(r["correct"] for r in lib) / max(len(lib), 1),
            "recovered_20pct_rate": sum(x <= 0.2 for x in rec) / max(len(lib), 1),
            "recovered_20pct_vector_rate": sum(x <= 0.2 for x in recv) / max(len(lib), 1),
            "within_2sigma_rate": sum(bool(r.get("within_2sigma")) for r in lib) / max(len(lib), 1),
            "profile_specs": [list(p) for p in cfg.profile_specs],
            "recovered_20pct_rate_among_correct": (sum(r["recovery_error"] is not None and r["recovery_error"] <= 0.2
                                                       for r in lib if r["correct"]) / max(sum(r["correct"] for r in lib), 1)),
            "median_recovery_error": float(np.median(rec)) if rec else None,
            "ool_unexplained_rate": sum(r["verdict"] != "explained" for r in ool) / max(len(ool), 1),
            "per_type": per_type, "confusion": confusion, "truth": cfg.truth,
            "by_measurement": {k: _scores([r for r in rows if r.get("measurement") == k])
                               for k in sorted({r.get("measurement") for r in rows})},
            "seconds_per_case_mean": float(np.mean([r["seconds"] for r in rows])),
            "wall_s": wall_s, "workers": cfg.workers, "seed": cfg.seed}


def _log(row: dict, progress) -> dict:
    if progress is not None:
        with open(progress, "a") as fh:
            fh.write(json.dumps(row, default=float) + "\n")
    return row


def campaign_maps(cfg: CampaignConfig, cache_dir=None) -> tuple[SagMap, SagMap]:
    """(diagnosed nominal, truth base) FEA maps of 200 µm / 75 % at 80 K."""
    nominal = case_sag_map(Simulation.from_params({**NOMINAL_SIMULATION, "mesh": cfg.nominal_mesh}),
                           cache_dir=cache_dir)
    base = case_sag_map(Simulation.from_params({**NOMINAL_SIMULATION, "mesh": cfg.truth_mesh}), cache_dir=cache_dir)
    return nominal, base


def case_type(cfg: CampaignConfig, index: int) -> tuple[str, str]:
    """``(kind, effect)`` of case ``index``: the configured types cycled, with the
    ``only_types`` not among them appended to the cycle."""
    types = cfg.case_types + tuple(t for t in cfg.only_types or () if t not in cfg.case_types)
    return types[index % len(types)]


def run_campaign(cfg: CampaignConfig = CampaignConfig(), cache_dir=None, progress=None) -> dict:
    """Run ``cfg.n_cases`` cases (types cycled) in ``cfg.workers`` processes.

    ``progress`` (path, optional): each finished case is appended to it as one JSON line
    (in case order), so an interrupted campaign leaves its partial results."""
    t0 = time.perf_counter()
    nominal, base = campaign_maps(cfg, cache_dir)
    tasks = [(i, case_type(cfg, i), cfg, nominal, base) for i in range(cfg.n_cases)
             if cfg.only_types is None or case_type(cfg, i) in cfg.only_types]
    t_maps = time.perf_counter() - t0
    if cfg.workers > 1:
        with ProcessPoolExecutor(cfg.workers, initializer=one_blas_thread) as ex:
            rows = [_log(r, progress) for r in ex.map(run_case, tasks, chunksize=1)]
    else:
        rows = [_log(run_case(t), progress) for t in tasks]
    wall = time.perf_counter() - t0
    s = _summary(rows, wall, cfg)
    s["maps_s"] = t_maps
    return {"summary": s, "cases": rows, "config": {k: v for k, v in asdict(cfg).items() if k != "criteria"},
            "criteria": asdict(cfg.criteria)}


def one_blas_thread() -> None:
    """Limit this process's BLAS and OpenMP pools to one thread (the campaign workers'
    initializer).

    The workers already fill the cores; a second BLAS thread per worker has no core of its own
    and OpenBLAS threads spin while they wait, which makes the diagnosis fits several times
    slower. An environment variable set in the parent cannot do this: the workers are forked
    after numpy has loaded its BLAS, so the pools are limited at run time (threadpoolctl)."""
    from threadpoolctl import threadpool_limits

    threadpool_limits(limits=1)


def write_campaign(result: dict, out_dir) -> Path:
    from pipeline.io.common import atomic_write

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    p = out / "campaign.json"
    with atomic_write(p) as fh:
        fh.write(json.dumps(result, indent=1, default=float))
    return p
