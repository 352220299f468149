"""Gridding an FEA front face onto its sag-map grid: scipy's LinearNDInterpolator against
:func:`optics.triangulation.linear_on_grid` (the same interpolant).

Run: ``.venv/bin/python benchmarks/bench_gridding.py`` (about a minute on 2 cores). Solves the
default blank on the default mesh once, then grids its front-face samples onto the 0.5 mm
map grid of ``fea.surface.FrontSag.sag_map`` with each method; reports the median CPU time
(``time.process_time``, so a busy machine disturbs it less than wall time) of 3 runs and
the largest difference. Writes ``benchmarks/results_gridding.md``.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from scipy.interpolate import LinearNDInterpolator
from scipy.spatial import Delaunay

from fea.case import FEACase
from fea.api import prepare
from optics.triangulation import linear_on_grid

OUT = Path(__file__).with_name("results_gridding.md")


def _cpu(fn, repeat=3):
    times, out = [], None
    for _ in range(repeat):
        t = time.process_time()
        out = fn()
        times.append(time.process_time() - t)
    return float(np.median(times)), out


def main() -> None:
    o = FEACase().to_objects()
    sag = prepare(o.blank, o.mesh, o.substrate).solve(o.coating, o.film, o.load, stress_scale=o.stress_scale).sag
    x, y, s = sag.x_mm, sag.y_mm, sag.sag_um
    grid = sag.sag_map(0.5)
    gx, gy = grid.x_mm, grid.y_mm
    X, Y = np.meshgrid(gx, gy)
    pts = np.column_stack([x, y])
    t_del, tri = _cpu(lambda: Delaunay(pts))
    t_scipy, ref = _cpu(lambda: LinearNDInterpolator(pts, s)(X, Y))
    t_own, got = _cpu(lambda: linear_on_grid(x, y, s, gx, gy))
    diff = float(np.nanmax(np.abs(got - ref)))
    same_nan = bool(np.array_equal(np.isnan(got), np.isnan(ref)))
    text = "\n".join([
        "# Gridding an FEA front face onto its sag-map grid", "",
        "Regenerate: `.venv/bin/python benchmarks/bench_gridding.py` (median CPU time of 3 runs).", "",
        f"Default blank, default mesh: {x.size} front-face samples, {tri.simplices.shape[0]} Delaunay "
        f"triangles, grid {gx.size} x {gy.size} at 0.5 mm.", "",
        "| step | CPU s |", "|---|---|",
        f"| Delaunay triangulation (both methods) | {t_del:.2f} |",
        f"| `scipy.interpolate.LinearNDInterpolator` (triangulation + `transform` + evaluation) | {t_scipy:.2f} |",
        f"| `optics.triangulation.linear_on_grid` (triangulation + rasterised closed-form weights) | {t_own:.2f} |",
        "", f"Largest difference {diff:.1e} µm (sag up to {np.nanmax(np.abs(ref)):.2f} µm); "
        f"the same NaN nodes: {same_nan}.", ""])
    OUT.write_text(text)
    print(text)


if __name__ == "__main__":
    main()
