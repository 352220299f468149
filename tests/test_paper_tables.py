"""Validation against the paper's Tables 1 and 2 on the default mesh (slow tier).

Reference values: ``tests/data/paper_pv_center.csv`` (with their source). One global
calibration constant (fea.calibration.STRESS_SCALE) is used unchanged for every row.
Targets: Table 1 within ±5 %, holes-only within ±15 %, Table 2 cases deform in
opposite directions, no film gives zero. The surfaces-only rows are a documented known
discrepancy (README): tested for their sign and for the measured model/paper ratio.
"""
import csv
from pathlib import Path

import numpy as np
import pytest

from fea.calibration import STRESS_SCALE, TABLE_SIGMA, fit_stress_scale, paper_cases

pytestmark = pytest.mark.slow
DATA = Path(__file__).parent / "data" / "paper_pv_center.csv"


def test_reference_data_is_the_packaged_copy():
    pkg = Path(__file__).parents[1] / "fea" / "data" / "paper_pv_center.csv"
    assert DATA.read_text() == pkg.read_text()
    rows = list(csv.DictReader(line for line in DATA.open() if not line.startswith("#")))
    assert len(rows) == 15


@pytest.fixture(scope="module")
def rows(paper_fea_dir):
    """Solve through the CLI, then reload through the API (every case reused from the cache).
    The directory is the one the paper scorecard solves its tables in (``fea/tables``)."""
    import contextlib
    import io

    from pipeline.cli import main
    from pipeline.sweeps.fea_cases import run_tables

    out = paper_fea_dir / "fea" / "tables"
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main(["tables", "--out", str(out), "--quiet"]) == 0
    printed = buf.getvalue()
    assert "surfaces" in printed and "paper" in printed and "(not calibrated: see README)" in printed
    csv_rows = list(csv.DictReader((out / "tables.csv").open()))
    assert len(csv_rows) == 15
    result = run_tables(out, progress=False)
    assert [f"{r.model_pv_um:.4f}" for r in result] == [c["model_pv_center_um"] for c in csv_rows]
    return result


def test_table1_within_5_percent(rows):
    t1 = [r for r in rows if r.table == "1"]
    assert len(t1) == 9
    for r in t1:
        assert abs(r.error) <= 0.05, f"{r.coverage} {r.t0_um} {r.polish}: {100 * r.error:+.1f} %"


def test_holes_only_within_15_percent(rows):
    for r in (r for r in rows if r.coverage == "holes"):
        assert abs(r.error) <= 0.15, f"holes {r.t0_um}: {100 * r.error:+.1f} %"


def test_every_row_deforms_in_the_paper_direction(rows):
    for r in rows:
        assert r.direction_ok, f"{r.coverage} {r.t0_um} {r.polish}: {r.model_direction_um:+.3f} µm"


def test_surfaces_only_known_discrepancy(rows):
    """Model/paper ratio for outer-surfaces-only: measured 0.645-0.661 (README, docs/physics.md)."""
    ratios = np.array([r.model_pv_um / r.paper_pv_um for r in rows if r.coverage == "surfaces"])
    assert len(ratios) == 3
    assert np.all((ratios > 0.60) & (ratios < 0.72)), ratios


def test_stored_calibration_reproduces(rows):
    """Refit from these results (P/V is linear in the scale) gives the stored constant."""
    cal = [r for r in rows if r.calibrated]
    model_at_1 = np.array([r.model_pv_um for r in cal]) / STRESS_SCALE
    s, res = fit_stress_scale(model_at_1, np.array([r.paper_pv_um for r in cal]),
                              np.array([TABLE_SIGMA[r.table] for r in cal]))
    assert s == pytest.approx(STRESS_SCALE, rel=2e-3)
    assert len(cal) == 12 and sum(c.calibrate for c in paper_cases()) == 12
