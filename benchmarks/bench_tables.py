"""Benchmark: the paper's 15-case table on the default mesh (wall time, peak memory).

Run on demand (not a test):  .venv/bin/python benchmarks/bench_tables.py [OUT.md [SIZE BULK]]
Writes benchmarks/results_tables.md (or OUT.md); SIZE/BULK override the mesh sizes (mm). Target (issue 2): <= 60 s wall, <= 4 GB peak.
"""
from __future__ import annotations

import resource
import time
from pathlib import Path

from fea.api import prepare
from fea.calibration import STRESS_SCALE, paper_cases
from fea.coating import Coating
from fea.mesh import MeshSpec


def main(out: Path | None = None, spec: MeshSpec | None = None) -> None:
    out = Path(__file__).with_name("results_tables.md") if out is None else out
    spec = MeshSpec() if spec is None else spec
    t0 = time.perf_counter()
    model = prepare(mesh=spec)
    t_prep = time.perf_counter() - t0
    lines = [f"# 15-case paper table, mesh {spec.size_mm}/{spec.size_bulk_mm} mm", "",
             f"Prepare (mesh from cache or gmsh, bulk stiffness): {t_prep:.1f} s, {model.ndof} DOFs.", "",
             ("| case | P/V_center (µm) | assembly (s) | solve (s) | CG iterations | initial residual "
              "| preconditioner | reduced basis |"), "|---|---|---|---|---|---|---|---|"]
    for c in paper_cases():
        r = model.solve(Coating.symmetric(c.t0_um, c.polish, c.coverage), stress_scale=STRESS_SCALE)
        lines.append(f"| {c.label} | {r.sag.pv_um('center'):.3f} | {r.info['assembly_s']:.1f} | "
                     f"{r.info['solve_s']:.1f} | {r.info['solver'].get('iterations', '-')} | "
                     f"{r.info['solver'].get('initial_residual', float('nan')):.1e} | "
                     f"{r.info['solver'].get('preconditioner', '-')} | "
                     f"{r.info['solver'].get('reduced_basis_size', '-')} |")
        print(lines[-1], flush=True)
    wall = time.perf_counter() - t0
    peak_gb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024**2
    lines += ["", f"Total wall time {wall:.0f} s (target 60 s); peak RSS {peak_gb:.1f} GB (target 4 GB).",
              f"Machine load at the end: {open('/proc/loadavg').read().split()[:3]}"]
    out.write_text("\n".join(lines) + "\n")
    print("\n".join(lines[-2:]))


if __name__ == "__main__":
    import sys

    main(Path(sys.argv[1]) if len(sys.argv) > 1 else None,
         MeshSpec(float(sys.argv[2]), float(sys.argv[3])) if len(sys.argv) > 3 else None)
