"""Overhead of the sweep engine per case: inline, local processes, Dask, cache reuse.

Run: ``.venv/bin/python benchmarks/bench_sweep.py [--cases 200] [--pixels 256]``.
The case function does no work beyond building its outputs, so the times measure
scheduling, transport and the atomic npz+json writes (or the cache reads on reuse).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from pipeline.sweeps.sweep import grid, run_sweep


def trivial(params: dict) -> dict:
    """A scalar and an ``n x n`` map: roughly the outputs of one FEA/optics case."""
    n = params["n"]
    return {"pv_um": float(params["i"]), "sag_um": (("y_mm", "x_mm"), np.full((n, n), params["i"], float))}


def _time(label, cases, out, **kw):
    t0 = time.perf_counter()
    res = run_sweep(trivial, cases, out, namespace="bench", progress=False, **kw)
    dt = time.perf_counter() - t0
    print(f"{label:<34} {dt:7.2f} s total  {1e3 * dt / len(cases):8.2f} ms/case  "
          f"(computed {res.n_computed}, reused {res.n_reused})")
    return dt


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--cases", type=int, default=200)
    p.add_argument("--pixels", type=int, default=256, help="side of the array output per case")
    p.add_argument("--no-dask", action="store_true")
    args = p.parse_args(argv)
    cases = grid(i=list(range(args.cases)), n=args.pixels)
    print(f"{args.cases} cases, output {args.pixels}x{args.pixels} float64 "
          f"({args.pixels ** 2 * 8 / 1e6:.2f} MB) + 1 scalar per case")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        _time("inline (workers=1)", cases, tmp / "inline", workers=1)
        _time("reuse from cache", cases, tmp / "inline", workers=1)
        _time("processes (workers=2, spawn)", cases, tmp / "proc", workers=2)
        if not args.no_dask:
            from distributed import LocalCluster

            t0 = time.perf_counter()
            with LocalCluster(n_workers=2, processes=True, threads_per_worker=1, dashboard_address=None) as c:
                print(f"{'LocalCluster start':<34} {time.perf_counter() - t0:7.2f} s")
                _time("dask LocalCluster (2 workers)", cases, tmp / "dask", scheduler=c.scheduler_address)


if __name__ == "__main__":
    main()
