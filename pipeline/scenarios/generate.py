"""Generate the bundled diagnosis scenarios: synthetic stand-ins for the paper's three
diagnoses (the paper publishes no curves or maps).

    .venv/bin/python -m pipeline.scenarios.generate [--seed 2017] [--cache-dir DIR]

Every scenario's truth comes from a DIFFERENT model than the one its manifest
diagnoses: the truth maps are solved on the refined FEA mesh (1.0/2.0 mm, 480 k DOFs,
within 0.4-1.0 % of the extrapolated P/V) while the manifests ask for the default mesh
(1.4/2.8 mm, the converged model a user would run); the truth gets a random plating-thickness
gradient and a low-order bow (:func:`pipeline.diagnosis.synth.shape_discrepancy`);
profiles are computed with the converged LSF sampling (the diagnosis fits with a
coarser one); then piston/tilt or shift/flux/background, noise, dropouts and sparse
sampling are applied.

Scenarios (paper section -> what is injected):

* ``cryo_astigmatism`` (§3.3): J spare blank, 200 µm / 75 %, at 128 K, 137 mm window,
  scaled so P/V_center = 0.60 µm without and 0.80 µm with an oblique astigmatism.
* ``j_repolished`` (§5.3): J grating profiles (1.25 µm at 250/100/25 mas, 1.175 µm at
  25 mas) from a 200 µm / 50 % blank with the pupil 4 mm off in x; the manifest's
  nominal is 200 µm / 75 %.
* ``hk_amplitude`` (§5.4): the 1.25 µm line on the H (order -3) and K (order -4)
  gratings at 250/100/25 mas, truth 1.2 x the 200 µm / 75 % deformation.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from scipy.optimize import brentq

from optics.zernike import zernike_xy
from pipeline.diagnosis.manifest import NOMINAL_SIMULATION, Simulation
from pipeline.diagnosis.nominal import case_sag_map, thermal_factor
from pipeline.diagnosis.synth import shape_discrepancy, synthetic_profile, synthetic_surface
from pipeline.io.measured import write_line_profile_csv
from pipeline.io.registry import write_sag_map

HERE = Path(__file__).parent
SIM = "[simulation]\n" + "".join(f'{k} = "{v}"\n' if isinstance(v, str) else f"{k} = {v:g}\n"
                                  for k, v in {**NOMINAL_SIMULATION, "mesh": "default"}.items())
_COLD_K = NOMINAL_SIMULATION["cold_K"]


def _nominal_case(mesh: str, **changes) -> Simulation:
    return Simulation.from_params({**NOMINAL_SIMULATION, **changes, "mesh": mesh})


def _truth(polish: float, cache_dir, rng, scale: float = 1.0):
    m = case_sag_map(_nominal_case("refined", polish=polish), cache_dir=cache_dir)
    return shape_discrepancy(m.scaled(scale), rng)


def quilt_ratio(truth, cache_dir) -> float:
    """Truth / diagnosed-nominal amplitude of the quilt fundamental (1/Dx, 0) over the
    pupil: the amplitude scale a line-profile fit should find (the component that
    diffracts along dispersion; paper §5.3), which differs from the P/V ratio when the
    deformation's shape differs (200/50 vs 200/75)."""
    from optics.fitting import fit_fourier

    nom = case_sag_map(_nominal_case("default"), cache_dir=cache_dir)
    return float(fit_fourier(truth, aperture="pupil", harmonics=2).component(1, 0)[0]
                 / fit_fourier(nom, aperture="pupil", harmonics=2).component(1, 0)[0])


def cryo_astigmatism(out: Path, rng, cache_dir) -> dict:
    base = _truth(0.75, cache_dir, rng, thermal_factor(128.0, _COLD_K))
    base = base.scaled(0.60 / base.remove_piston_tilt("center").pv_um("center"))
    X, Y = base.grid()

    def pv_with(c):
        return base.with_sag(base.sag_um + c * zernike_xy(2, -2, X, Y, 68.5)).remove_piston_tilt("center").pv_um("center")

    c45 = brentq(lambda c: pv_with(c) - 0.80, 0.0, 0.5)
    meas = synthetic_surface(base, rng, extra_um=lambda x, y: c45 * zernike_xy(2, -2, x, y, 68.5),
                             label="synthetic cryogenic map 128 K")
    write_sag_map(meas, out / "cryo_map.int")
    (out / "manifest.toml").write_text(SIM + '\n[[measurement]]\nkind = "surface"\nfile = "cryo_map.int"\n'
                                       'temperature_K = 128\naperture_diameter_mm = 137\ngrating = "J"\n')
    return {"astig_45_um": c45, "pv_center_um": 0.80, "pv_center_without_astig_um": 0.60}


def _profiles(out, rng, truth, specs, params) -> str:
    text = SIM
    for g, wl, order, ps in specs:
        name = f"{g}_{str(wl).replace('.', 'p')}_{ps}mas"
        u, y, info = synthetic_profile(g, wl, order, ps, truth, rng, params=params)
        write_line_profile_csv(out / f"{name}.csv", u, y)
        text += (f'\n[[measurement]]\nkind = "line_profile"\nfile = "{name}.csv"\ngrating = "{g}"\norder = {order}\n'
                 f"wavelength_um = {wl}\npixel_scale_mas = {ps}\nslit_position = 0.0\n")
    return text


def j_repolished(out: Path, rng, cache_dir) -> dict:
    truth = _truth(0.50, cache_dir, rng)
    specs = [("J", 1.25, -2, 250), ("J", 1.25, -2, 100), ("J", 1.25, -2, 25), ("J", 1.175, -2, 25)]
    (out / "manifest.toml").write_text(_profiles(out, rng, truth, specs, {"pupil_x_mm": 4.0}))
    return {"truth": "FEA 200/50 refined mesh + discrepancy", "pupil_x_mm": 4.0,
            "expected_scale_J_quilt_fundamental": quilt_ratio(truth, cache_dir)}


def hk_amplitude(out: Path, rng, cache_dir) -> dict:
    truth = _truth(0.75, cache_dir, rng, 1.2)
    specs = [(g, 1.25, o, ps) for g, o in (("H", -3), ("K", -4)) for ps in (250, 100, 25)]
    (out / "manifest.toml").write_text(_profiles(out, rng, truth, specs, {}))
    return {"truth": "1.2 x FEA 200/75 refined mesh + discrepancy", "scale": 1.2,
            "expected_scale_quilt_fundamental": quilt_ratio(truth, cache_dir)}


SCENARIOS = {"cryo_astigmatism": cryo_astigmatism, "j_repolished": j_repolished, "hk_amplitude": hk_amplitude}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=2017)
    ap.add_argument("--cache-dir", default=None, help="FEA map cache (default: none)")
    ap.add_argument("--out", default=str(HERE))
    a = ap.parse_args(argv)
    for i, (name, make) in enumerate(SCENARIOS.items()):
        out = Path(a.out) / name
        out.mkdir(parents=True, exist_ok=True)
        truth = make(out, np.random.default_rng([a.seed, i]), a.cache_dir)
        (out / "TRUTH.md").write_text(
            f"# {name}: synthetic stand-in (generated by `python -m pipeline.scenarios.generate --seed {a.seed}`)\n\n"
            "Not measured data: the paper publishes no curves. Truth from the refined FEA mesh (1.0/2.0 mm) + a "
            "random shape discrepancy, converged LSF sampling, noise, shifts, sparse sampling; the manifest "
            "diagnoses the default-mesh (1.4/2.8 mm) 200/75 nominal.\n\n" + "\n".join(f"* {k}: {v}" for k, v in truth.items()) + "\n")
        print(name, truth)


if __name__ == "__main__":
    main()
