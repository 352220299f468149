"""Benchmark: a 1000-point (t0, polish, coverage) sweep through the surrogate on the default mesh.

Run on demand (not a test):
    .venv/bin/python benchmarks/bench_surrogate.py [OUT.md] [--points 1000] [--validate 10]

Measures the greedy build (full solves), the 1000 evaluations (P/V and RMS over the
centre and the whole face, as the sweep writes them) and the P/V error against full
solves at random points. Target: 1000 points <= 60 s on 2 cores, <= 1 % error.
"""
from __future__ import annotations

import argparse
import resource
import time
from pathlib import Path

import numpy as np

from fea.api import prepare
from fea.calibration import STRESS_SCALE
from fea.surrogate import SurrogateDomain, build_surrogate


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("out", nargs="?", default=str(Path(__file__).with_name("results_surrogate.md")))
    ap.add_argument("--points", type=int, default=1000)
    ap.add_argument("--validate", type=int, default=10)
    ap.add_argument("--tol", type=float, default=2e-3)
    a = ap.parse_args()
    t0 = time.perf_counter()
    model = prepare()
    t_prep = time.perf_counter() - t0
    dom = SurrogateDomain()
    t = time.perf_counter()
    s = build_surrogate(model, dom, stress_scale=STRESS_SCALE, tol=a.tol,
                        progress=lambda d: print(d, flush=True))
    model.release_preconditioner()
    t_build = time.perf_counter() - t
    rng = np.random.default_rng(2026)
    cases = dom.sample(a.points, rng)
    t = time.perf_counter()
    s.statistics_many(cases)  # what a surrogate sweep does (pipeline.sweeps.surrogate)
    t_eval = time.perf_counter() - t
    wall_sweep = time.perf_counter() - t0
    t = time.perf_counter()
    for c in cases[:100]:
        s.statistics(c)
    t_loop = (time.perf_counter() - t) / 100
    rows = s.validate(a.validate, seed=7, progress=lambda r: print(r, flush=True))
    err = np.array([r["rel_error"] for r in rows])
    peak_gb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024**2
    with open("/proc/loadavg") as fh:
        load = fh.read().split()[:3]
    lines = [
        "# Surrogate: 1000-point sweep on the default mesh", "",
        f"Domain: t0 {dom.t0_um} µm, polish {dom.polish}, coverages {dom.coverages}; "
        f"greedy tol {a.tol:g} on the sketched relative residual; calibrated stress scale.", "",
        "| step | time (s) |", "|---|---|",
        f"| prepare (mesh from cache, bulk stiffness; {model.ndof} DOFs) | {t_prep:.1f} |",
        f"| greedy build: {s.build_info['full_solves']} full solves, basis {s.size}, worst residual "
        f"estimate {s.build_info['worst_residual_estimate']:.1e} | {t_build:.1f} |",
        f"| {a.points} evaluations (P/V + RMS, centre and full face) | {t_eval:.1f} "
        f"({1e3 * t_eval / a.points:.2f} ms each, batched; one by one {1e3 * t_loop:.1f} ms each) |",
        f"| **whole {a.points}-point sweep** (prepare + build + evaluations) | **{wall_sweep:.1f}** |", "",
        f"Validation against full solves at {len(rows)} random points of the domain: max |P/V_center "
        f"error| {100 * np.abs(err).max():.3f} %, RMS {100 * np.sqrt(np.mean(err**2)):.3f} %.", "",
        "| coverage | t0 (µm) | polish | P/V full (µm) | P/V surrogate (µm) | error | residual estimate |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(f"| {r['coverage']} | {r['t0_um']:.1f} | {r['polish']:.3f} | {r['pv_center_full_um']:.4f} | "
                     f"{r['pv_center_surrogate_um']:.4f} | {100 * r['rel_error']:+.3f} % | "
                     f"{r['residual_estimate']:.1e} |")
    lines += ["", f"Peak RSS {peak_gb:.1f} GB. Machine load at the end: {load} (2 cores; other jobs "
              "running make times upper bounds)."]
    Path(a.out).write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
