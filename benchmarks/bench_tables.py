"""Benchmark: the paper's 15-case table on the default mesh (wall time, peak memory).

Run on demand (not a test):  .venv/bin/python benchmarks/bench_tables.py [OUT.md [SIZE BULK]] [--sequential]

Writes benchmarks/results_tables.md (or OUT.md); SIZE/BULK override the mesh sizes (mm).
Times ``prepare`` + ``PreparedBlank.solve_many`` over the 15 cases — what
``cryograting tables`` and the study's FEA stage run (the sweep engine plans its cases and the
FEA runner solves them as one lockstep block) — or, with ``--sequential``, ``solve`` per case.
The mesh comes from the mesh cache and the film operators from the operator cache when they
are there (as on any second run on a machine; the first run builds both).
Target: <= 60 s wall, <= 4 GB peak.
"""
from __future__ import annotations

import resource
import sys
import time
from pathlib import Path

from fea.api import prepare
from fea.calibration import STRESS_SCALE, paper_cases
from fea.coating import Coating
from fea.mesh import MeshSpec


def main(out: Path | None = None, spec: MeshSpec | None = None, sequential: bool = False) -> None:
    out = Path(__file__).with_name("results_tables.md") if out is None else out
    spec = MeshSpec() if spec is None else spec
    t0 = time.perf_counter()
    model = prepare(mesh=spec)
    t_prep = time.perf_counter() - t0
    cases = list(paper_cases())
    coatings = [Coating.symmetric(c.t0_um, c.polish, c.coverage) for c in cases]
    t = time.perf_counter()
    if sequential:
        results = [model.solve(c, stress_scale=STRESS_SCALE) for c in coatings]
    else:
        results = model.solve_many(coatings, stress_scale=STRESS_SCALE)
    t_solve = time.perf_counter() - t
    mode = "solve() per case" if sequential else "solve_many (lockstep block CG)"
    lines = [f"# 15-case paper table, mesh {spec.size_mm}/{spec.size_bulk_mm} mm, {mode}", "",
             f"Prepare (mesh from cache or gmsh, bulk stiffness): {t_prep:.1f} s, {model.ndof} DOFs; "
             f"solves (film operators from cache or assembled, layouts, factorisation, CG): {t_solve:.1f} s.", "",
             "| case | P/V_center (µm) | CG iterations | initial residual | residual |", "|---|---|---|---|---|"]
    for c, r in zip(cases, results):
        sv = r.info["solver"]
        lines.append(f"| {c.label} | {r.sag.pv_um('center'):.3f} | {sv.get('iterations', '-')} | "
                     f"{sv.get('initial_residual') or float('nan'):.1e} | {sv.get('residual', float('nan')):.1e} |")
    wall = time.perf_counter() - t0
    peak_gb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024**2
    with open("/proc/loadavg") as fh:
        load = fh.read().split()[:3]
    lines += ["", f"Total wall time {wall:.0f} s (target 60 s); peak RSS {peak_gb:.1f} GB (target 4 GB).",
              f"Machine load at the end: {load}"]
    out.write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    args = [a for a in sys.argv[1:] if a != "--sequential"]
    main(Path(args[0]) if args else None,
         MeshSpec(float(args[1]), float(args[2])) if len(args) > 2 else None,
         sequential="--sequential" in sys.argv)
