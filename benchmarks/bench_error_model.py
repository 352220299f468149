"""The two error models of the diagnosis on the reduced campaign of
``tests/test_diagnosis_scenarios.py::test_reduced_campaign`` (19 cases, seed 7, truths from the
default-mesh map plus the out-of-library trefoil/tetrafoil/pentafoil discrepancy), and the
quilt-shape cases of the same seed.

    PYTHONPATH=. .venv/bin/python benchmarks/bench_error_model.py [--cache-dir DIR] [--workers 2] [--quilt-cases 45]

Prints one JSON line per error model (``Criteria.error_model``) and one for the quilt cases
(``EXTRA_CASE_TYPES``, the first ``--quilt-cases`` indices).
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from pipeline.diagnosis.campaign import EXTRA_CASE_TYPES, CampaignConfig, run_campaign
from pipeline.diagnosis.engine import Criteria
from pipeline.diagnosis.error_model import ERROR_MODELS


def _row(res: dict, wall_s: float) -> dict:
    s = res["summary"]
    surf = [r for r in res["cases"] if r["kind"] == "surface" and not r["effect"].startswith("ool")]
    out = {k: s[k] for k in ("n_cases", "correct_top_rate", "recovered_20pct_rate", "ool_unexplained_rate",
                             "within_2sigma_rate")}
    out["surface_correct"] = float(np.mean([r["correct"] for r in surf])) if surf else None
    out["wall_s"] = round(wall_s, 1)
    return out


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cache-dir", default=None)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--quilt-cases", type=int, default=45)
    a = ap.parse_args(argv)
    for em in ERROR_MODELS:
        cfg = CampaignConfig(n_cases=19, seed=7, workers=a.workers, truth_mesh="default",
                             criteria=Criteria(heldout_top=1, pair_from=2, error_model=em))
        t = time.perf_counter()
        res = run_campaign(cfg, cache_dir=a.cache_dir)
        print(json.dumps({"error_model": em, **_row(res, time.perf_counter() - t)}))
    cfg = CampaignConfig(n_cases=a.quilt_cases, seed=7, workers=a.workers, truth_mesh="default",
                         only_types=EXTRA_CASE_TYPES)
    t = time.perf_counter()
    res = run_campaign(cfg, cache_dir=a.cache_dir)
    print(json.dumps({"cases": "quilt_shape", **_row(res, time.perf_counter() - t),
                      "recovery_errors": [round(r["recovery_error"], 3) for r in res["cases"]]}))


if __name__ == "__main__":
    main()
