"""Refit the film stress scale (``cryograting calibrate``): solve the paper's cases, write the fit.

The fit itself is :func:`fea.calibration.calibrate`; this module meshes the blank, reports
progress, and writes ``calibration.csv`` atomically into a directory checked before the solves.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fea.calibration import Calibration, calibrate

__all__ = ["run_calibration", "format_calibration"]


def run_calibration(out_dir=None, *, mesh_size_mm: float | None = None, mesh_bulk_mm: float | None = None,
                    progress: bool = True) -> Calibration:
    """Solve the paper's 15 cases at stress scale 1 and fit the scale.

    Parameters
    ----------
    out_dir : path, optional
        Directory for ``calibration.csv`` (checked writable before any solve).
    mesh_size_mm, mesh_bulk_mm : float, optional
        Element sizes (mm); the default mesh otherwise. Checked as FEA case parameters
        (ranges and the mesh's memory estimate) before meshing.
    """
    from fea.api import prepare
    from fea.case import FEACase
    from pipeline.io.common import atomic_write, ensure_writable_dir

    if out_dir is not None:
        ensure_writable_dir(out_dir, "--out")
    sizes = {k: v for k, v in (("mesh_size_mm", mesh_size_mm), ("mesh_bulk_mm", mesh_bulk_mm)) if v is not None}
    objects = FEACase.from_params(sizes).to_objects()
    model = prepare(objects.blank, objects.mesh, objects.substrate)

    def report(case, pv_um):
        print(f"{case.label:28s} paper {case.pv_center_um:5.2f}  model(scale 1) {pv_um:.4f}", flush=True)

    cal = calibrate(model, progress=report if progress else None)
    if out_dir is not None:
        with atomic_write(Path(out_dir) / "calibration.csv") as fh:
            fh.write("case,paper_pv_um,model_pv_scale1_um,calibrated_error,used\n")
            for c, m, e in zip(cal.cases, cal.model_pv_scale1_um, cal.residuals):
                fh.write(f"{c.label},{c.pv_center_um},{m:.5f},{e:+.4f},{c.calibrate}\n")
    return cal


def format_calibration(cal: Calibration) -> str:
    """The fitted scale and the residual of every case, as text."""
    used = cal.residuals[cal.used]
    lines = [f"STRESS_SCALE = {cal.scale:.4f}   (mesh {cal.ndof} DOFs, {int(cal.used.sum())} rows)"]
    lines += [f"  {c.label:28s} {100 * e:+6.1f} %{'' if c.calibrate else '   (excluded)'}"
              for c, e in zip(cal.cases, cal.residuals)]
    lines.append(f"calibrated rows: RMS {100 * np.sqrt(np.mean(used**2)):.2f} %, max |.| {100 * np.abs(used).max():.2f} %")
    return "\n".join(lines)
