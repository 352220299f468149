"""`cryograting sweep --surrogate`: the surrogate through the sweep engine (coarse mesh)."""
import csv

import pytest

from fea.api import solve
from pipeline.cli import main
from pipeline.sweeps.surrogate import run_surrogate_sweep

COARSE = ["--param", "mesh_size_mm=5", "--param", "mesh_bulk_mm=10"]


@pytest.mark.slow  # eight FEA solves through the CLI, the slowest test of the fast tier: the full tier
def test_surrogate_sweep_cli_matches_full_solves(tmp_path, capsys):
    out = tmp_path / "sur"
    # tol 1e-2 (looser than the default 2e-3) keeps the greedy build to a few solves here;
    # the P/V check below still asks for 0.5 %
    rc = main(["sweep", "--t0-um", "100", "150", "200", "--polish", "0.5", "1.0", *COARSE,
               "--surrogate", "--validate", "1", "--tol", "1e-2", "--out", str(out), "--quiet"])
    assert rc == 0
    text = capsys.readouterr().out
    assert "validation against 1 full solves" in text
    with open(out / "sweep.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 6 and all(float(r["residual_estimate"]) < 1e-2 for r in rows)
    for r in rows[:: 5]:
        full = solve(float(r["t0_um"]), float(r["polish"]), "all", mesh=_coarse()).sag.pv_um("center")
        assert float(r["pv_center_um"]) == pytest.approx(full, rel=5e-3)
    with open(out / "surrogate_validation.csv") as fh:
        val = list(csv.DictReader(fh))
    assert abs(float(val[0]["rel_error"])) < 5e-3
    assert (out / "sweep.nc").exists()
    # a re-run reuses every case and does not rebuild the surrogate
    res, _, info = run_surrogate_sweep({"t0_um": [100, 150, 200], "polish": [0.5, 1.0], "mesh_size_mm": [5],
                                        "mesh_bulk_mm": [10]}, out, validate=0, tol=1e-2, progress=False)
    assert res.n_reused == 6 and info == {}


def _coarse():
    from fea.mesh import MeshSpec

    return MeshSpec(5.0, 10.0)


def test_surrogate_sweep_rejects_a_varying_mesh_parameter(tmp_path):
    with pytest.raises(ValueError, match="hole_diameter_mm takes 2 values"):
        run_surrogate_sweep({"t0_um": [100, 200], "hole_diameter_mm": [14, 15]}, tmp_path, progress=False)
    with pytest.raises(ValueError, match="symmetric polish"):
        run_surrogate_sweep({"t0_um": [100, 200], "polish_back": [0.5]}, tmp_path, progress=False)
