"""Benchmark: the README's main job, ``cryograting run`` (the paper's default study).

Run on demand (not a test):  .venv/bin/python benchmarks/bench_run.py [OUT.md]

Runs the CLI in a fresh output directory as a child process (so nothing is reused from an
earlier study; the mesh and film-operator caches under meshes/cache are, as on any second
run on a machine) and records wall time, peak memory of the child and the stage times it
prints. Target: <= 3 min on 2 cores.
"""
from __future__ import annotations

import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def main(out: Path) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        t = time.perf_counter()
        proc = subprocess.run([sys.executable, "-m", "pipeline.cli", "run", "--out", str(Path(tmp) / "r")], capture_output=True, text=True)
        wall = time.perf_counter() - t
    if proc.returncode != 0:
        sys.exit(f"cryograting run failed ({proc.returncode}):\n{proc.stderr[-3000:]}")
    peak_gb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024**2
    with open("/proc/loadavg") as fh:
        load = fh.read().split()[:3]
    stages = [ln for ln in proc.stdout.splitlines()
              if any(k in ln for k in ("line profiles:", "fits and study.nc", "render", "written in"))]
    lines = ["# `cryograting run` (default study), fresh output directory", "",
             f"Wall time **{wall:.0f} s** (target 180 s); peak RSS of the run {peak_gb:.1f} GB; "
             f"load average at the end {load}.", "", "Stage lines printed by the run:", "",
             *[f"    {ln}" for ln in stages]]
    out.write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).with_name("results_run.md"))
