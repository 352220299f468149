"""How far the nominal model sits from nominal data made by the independent truth, and what
the noise estimate makes of it: the floor under every line-profile diagnosis.

The grating is the nominal quilt, nothing else differs: profiles of J 1.25 µm (order -2) at
250, 100 and 25 mas made by the truth's 2-D finite-slit Abbe sum
(:mod:`pipeline.diagnosis.truth.abbe`, the nominal collimator) and measured by the truth's
detector (:func:`pipeline.diagnosis.truth.detector.measure_profile`). Each is fitted by the
nominal line-profile model with its nuisances only (flux, inter-pixel coupling, background,
offset shift) and three numbers are read:

* **model floor**: the residual RMS (fraction of the line's peak) on noiseless data (a
  1e12-count peak, no read or correlated noise): what the strip model and the Abbe sum
  disagree by;
* **white**: the noise estimate (:meth:`ProfileForward.estimate_noise`) over the residual's
  RMS per degree of freedom, photon and read noise only (the truth's correlated noise off):
  the estimator's bias and scatter where the residual *is* white noise;
* **detector**: the same ratio with the truth's full detector (its correlated noise, 0.2-0.6 %
  of the peak over 6-20 µm, on): what the gap test (``Criteria.no_gap_ratio``) meets on a
  profile whose model is right.

And whether the correlated noise could be told from an out-of-library halo by where its power
lies: the residual's band-pass RMS (:func:`band_rms`, Gaussian smoothing at 4 µm minus at 25 µm,
and 25 minus 80 µm) over the noise estimate, for white noise, the truth's detector, and white
noise beside a Lorentzian halo written here (4 % of the flux at 45 µm half width, 8 % at 80 µm;
the library's own halo code is not used).

    PYTHONPATH=. .venv/bin/python benchmarks/nominal_floor.py [--draws 40] [--out FILE.json]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np
from scipy.optimize import minimize_scalar

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from diagnosis_cases import nominal_map, sag_function_of  # noqa: E402
from pipeline.diagnosis.criteria import Criteria  # noqa: E402
from pipeline.diagnosis.forward import ProfileForward  # noqa: E402
from pipeline.diagnosis.manifest import load_data, load_manifest  # noqa: E402
from pipeline.diagnosis.truth.abbe import RELATIVE_NA, abbe_line_profile  # noqa: E402
from pipeline.diagnosis.truth.detector import measure_profile  # noqa: E402
from pipeline.diagnosis.truth.generate import COLLIMATOR_UM  # noqa: E402
from pipeline.io.measured import write_line_profile_csv  # noqa: E402

DETECTORS = {"noiseless": dict(peak_counts=(1e12, 1e12), read_e=(0.0, 0.0), corr_rel=(0.0, 0.0)),
             "white": dict(corr_rel=(0.0, 0.0)), "detector": {}}
#: Halos beside white noise for the band-pass probe: (fraction of the flux, half width µm).
HALOS = {"white + halo 4 % / 45 µm": (0.04, 45.0), "white + halo 8 % / 80 µm": (0.08, 80.0)}
#: Gaussian smoothing scales (µm) of the two bands: fine (where the truth's correlated noise
#: lies) and broad (where a halo lies).
BANDS_UM = {"band_4_25": (4.0, 25.0), "band_25_80": (25.0, 80.0)}


def halo(fraction: float, hwhm_um: float):
    """A detector-side distortion ``(u, y) -> y``: ``fraction`` of the flux into a Lorentzian
    of half width ``hwhm_um`` (``u`` a uniform grid)."""
    def distort(u, y):
        k = (np.arange(u.size) - u.size // 2) * (u[1] - u[0])
        lor = hwhm_um / (k * k + hwhm_um * hwhm_um)
        return (1.0 - fraction) * y + fraction * np.convolve(y, lor / lor.sum(), mode="same")
    return distort


def band_rms(x_um: np.ndarray, r: np.ndarray, fine_um: float, broad_um: float) -> float:
    """RMS of ``r`` smoothed at ``fine_um`` minus ``r`` smoothed at ``broad_um`` (Gaussian
    kernel regression on the irregular samples ``x_um``)."""
    def smooth(s):
        w = np.exp(-0.5 * ((x_um[:, None] - x_um[None, :]) / s) ** 2)
        return w @ r / w.sum(axis=1)
    return float(np.sqrt(np.mean((smooth(fine_um) - smooth(broad_um)) ** 2)))


def profile_manifest(work: Path, x, counts, mas: int, extra: str = "") -> Path:
    """Write the J 1.25 µm profile ``(x, counts)`` at ``mas`` and a manifest of it (nominal
    map ``nominal.npz`` in ``work``, ``extra`` manifest lines for the measurement); returns
    the manifest's path."""
    write_line_profile_csv(work / "p.csv", x, counts)
    path = work / "m.toml"
    path.write_text('[simulation]\nsag_file = "nominal.npz"\ncold_K = 80\n\n[[measurement]]\n'
                    'kind = "line_profile"\nfile = "p.csv"\ngrating = "J"\norder = -2\n'
                    f'wavelength_um = 1.25\npixel_scale_mas = {mas}\n{extra}')
    return path


def nominal_fit(work: Path, nominal, x, counts, mas: int) -> tuple[float, float, dict, float]:
    """(residual RMS per degree of freedom, noise estimate, band-pass RMS by band — fractions
    of the line's peak — and the estimate's relative uncertainty) of the nominal model fitted
    to the profile ``(x, counts)`` with its nuisances only."""
    (data,) = load_data(load_manifest(profile_manifest(work, x, counts, mas)))
    f = ProfileForward(data, nominal, 80.0)
    best = minimize_scalar(lambda d: float(np.sum(f.residual({}, d) ** 2)),
                           bounds=(f.delta0_um - 2.0, f.delta0_um + 2.0), method="bounded")
    r = f.residual({}, best.x)
    dof = f.n - f.nuisance_count - f.n_shift
    rms = float(np.sqrt(np.sum(r**2) / dof))
    try:
        sigma = f.estimate_noise(r)
    except ValueError:  # noiseless: the estimate needs noise_rel
        sigma = float("nan")
    return rms, sigma, {k: band_rms(f.x, r, *v) for k, v in BANDS_UM.items()}, f.noise_rel_sd


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--draws", type=int, default=40, help="noisy draws per pixel scale and detector")
    ap.add_argument("--out", type=Path, help="write the table as JSON")
    a = ap.parse_args(argv)
    limit = Criteria().no_gap_ratio
    out = {"no_gap_ratio": limit, "rows": []}
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        nominal = nominal_map(work)
        sag = sag_function_of(nominal)
        for mas in (250, 100, 25):
            u, det = abbe_line_profile("J", 1.25, -2, RELATIVE_NA[mas], sag, collimator_um=dict(COLLIMATOR_UM))
            floor = [nominal_fit(work, nominal, *measure_profile(u, det, np.random.default_rng(s),
                                                                 **DETECTORS["noiseless"])[:2], mas)[0]
                     for s in range(5)]
            row = {"pixel_scale_mas": mas, "model_floor_rel": float(np.mean(floor))}
            cases = {"white": (DETECTORS["white"], None), "detector": (DETECTORS["detector"], None)}
            cases.update({k: (DETECTORS["white"], halo(*v)) for k, v in HALOS.items()})
            for name, (kw, distortion) in cases.items():
                fits = [nominal_fit(work, nominal, *measure_profile(u, det, np.random.default_rng(1000 + s),
                                                                    distortion=distortion, **kw)[:2], mas)
                        for s in range(a.draws)]
                q = np.array([sigma / rms for rms, sigma, _, _ in fits])
                rel = np.array([r for _, _, _, r in fits])
                row[name] = {"estimate_over_rms_mean": float(q.mean()), "sd": float(q.std()),
                             "p10": float(np.percentile(q, 10)), "p90": float(np.percentile(q, 90)),
                             "residual_rms_rel": float(np.mean([rms for rms, _, _, _ in fits])),
                             "beyond_no_gap_ratio": float(np.mean(1.0 / q > limit)),
                             # the gap test's ratio: against the estimate's one-sigma upper bound
                             "beyond_gap_test_ratio": float(np.mean(1.0 / q > limit * (1.0 + rel)))}
                for band in BANDS_UM:
                    b = np.array([bands[band] / sigma for _, sigma, bands, _ in fits])
                    row[name][f"{band}_over_estimate"] = [float(b.mean()), float(b.std())]
            out["rows"].append(row)
            print(json.dumps(row), flush=True)
    if a.out:
        a.out.write_text(json.dumps(out, indent=1))
    return out


if __name__ == "__main__":
    main()
