"""False gaps on nominal line profiles whose noise is estimated from the data: the gap
test's ratio against the estimate itself and against its one-sigma upper bound
(``benchmarks/results_gap_noise_bound.md``, ``pipeline/diagnosis/gap.py``).

    PYTHONPATH=. .venv/bin/python benchmarks/gap_noise_bound.py [--draws 300] [--seed 7]

Each draw is a three-profile case as an outside lab delivered it: the J line at 1.25 µm and
250/100/25 mas (the analytic sum quilt, P/V 0.82 µm; the model is exact, so every residual is
noise), resampled on the lab's grids (1.5/2.0/2.25 µm steps over ±120/±110/±100 µm, random
origin), peaks of 40 000/40 000/25 000 counts on a 1500-count pedestal, Poisson plus 15
counts of read noise. The noise is estimated as the diagnosis does
(:func:`pipeline.diagnosis.noise.estimate_noise_signal_dependent` of the residual, the model
as the signal level); a case holds a false gap if any profile's residual RMS exceeds
``no_gap_ratio`` times the estimate (before) or times the estimate's one-sigma upper bound
(now). The chi^2 test, unchanged, is not counted here.
"""

from __future__ import annotations

import argparse
import json

import numpy as np
from scipy.interpolate import CubicSpline

from optics.sagmap import quilt_sag_map
from pipeline.diagnosis.criteria import Criteria
from pipeline.diagnosis.forward import profile_curve
from pipeline.diagnosis.noise import SIGNAL_DEPENDENT_NOISE_REL_SD_SQRT_N, estimate_noise_signal_dependent

#: (pixel scale mas, step µm, half range µm, peak counts): the outside lab's profiles
LAB = ((250, 1.5, 120.0, 40000.0), (100, 2.0, 110.0, 40000.0), (25, 2.25, 100.0, 25000.0))
PEDESTAL, READ = 1500.0, 15.0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--draws", type=int, default=300)
    ap.add_argument("--seed", type=int, default=7)
    a = ap.parse_args()
    rng = np.random.default_rng(a.seed)
    sag = quilt_sag_map(0.82, "sum", spacing_mm=0.5)
    lines = {ps: CubicSpline(*profile_curve("J", 1.25, -2, ps, sag, {})) for ps, *_ in LAB}
    ratio = Criteria().no_gap_ratio
    before = now = 0
    low = {ps: [] for ps, *_ in LAB}
    for _ in range(a.draws):
        hit_before = hit_now = False
        for ps, step, half, peak in LAB:
            u = np.arange(-half, half + 1e-9, step) + rng.uniform(-0.2, 0.2)
            p = np.clip(lines[ps](u), 0.0, None)
            p = p / p.max() * peak
            counts = rng.poisson(p + PEDESTAL).astype(float) + rng.normal(0.0, READ, u.size)
            model = p / peak
            resid = (counts - PEDESTAL) / peak - model
            est = estimate_noise_signal_dependent(u, resid, level=model)
            true = float(np.sqrt(np.mean(p + PEDESTAL + READ**2))) / peak
            low[ps].append(est / true)
            rms = float(np.sqrt(np.mean(resid**2)))
            r = SIGNAL_DEPENDENT_NOISE_REL_SD_SQRT_N / np.sqrt(u.size)
            hit_before |= rms > ratio * est
            hit_now |= rms > ratio * est * (1.0 + r)
        before += int(hit_before)
        now += int(hit_now)
    print(json.dumps({"draws": a.draws, "seed": a.seed, "false_gap_cases_before": before, "false_gap_cases_now": now,
                      "estimate_over_true": {ps: {"mean": round(float(np.mean(v)), 3), "sd": round(float(np.std(v)), 3)}
                                             for ps, v in low.items()}}))


if __name__ == "__main__":
    main()
