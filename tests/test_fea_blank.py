"""The meshed blank on coarse meshes: symmetry, limits, signs, input checks, CLI.

Coarse meshes (5 mm walls / 10 mm bulk) keep this tier fast; the paper's numbers are
checked on the default mesh in tests/test_paper_tables.py (slow tier).
"""
import csv
from dataclasses import replace

import numpy as np
import pytest

from fea.api import solve
from fea.coating import Coating
from fea.geometry import Blank
from fea.mesh import MeshSpec
from optics.fitting import fit_fourier

COARSE = MeshSpec(size_mm=5.0, size_bulk_mm=10.0)


@pytest.fixture(scope="module")
def eighth(coarse_eighth):
    return coarse_eighth.model


@pytest.fixture(scope="module")
def eighth_200_50(coarse_eighth):
    """The eighth model's 200 µm / 50 % case, the reference of the symmetry checks."""
    return coarse_eighth.solve(200, 0.5)


def test_no_film_gives_zero_sag(eighth):
    r = solve(coverage="none", prepared=eighth)
    assert np.abs(r.sag.sag_um).max() == 0.0


def test_table2_cases_deform_in_opposite_directions(eighth):
    from pipeline.sweeps.fea_cases import quilt_direction_um as _quilt_direction_um

    holes = solve(200, 1.0, "holes", prepared=eighth)
    surf = solve(200, 1.0, "surfaces", prepared=eighth)
    assert _quilt_direction_um(holes.sag, Blank()) > 0.1   # over hole crossings: higher
    assert _quilt_direction_um(surf.sag, Blank()) < -0.1   # ... lower with outer surfaces coated


@pytest.mark.slow
def test_film_response_is_linear_in_mismatch(eighth):
    a = solve(150, 0.75, prepared=eighth, stress_scale=1.0).sag.pv_um("center")
    b = solve(150, 0.75, prepared=eighth, stress_scale=0.5).sag.pv_um("center")
    assert b == pytest.approx(0.5 * a, rel=1e-9)


def test_solid_block_with_uniform_film_has_no_quilting(coarse_eighth):
    solid = Blank(n_holes_x=0, n_holes_y=0)
    light = coarse_eighth.solve(200, 0.75).sag.sag_map(1.0)
    flat = solve(200, 0.75, blank=solid, mesh=COARSE).sag.sag_map(1.0)
    def quilt(m):
        f = fit_fourier(m, harmonics=2, aperture="center")
        return max(f.component(i, j)[0] for i, j in ((1, 0), (0, 1), (1, 1), (1, -1)))
    assert quilt(light) > 0.05
    assert quilt(flat) < 0.01 * quilt(light)


@pytest.mark.slow
@pytest.mark.parametrize("symmetry", ["quarter", "full"])
def test_symmetric_parts_agree_with_the_full_model(eighth_200_50, symmetry):
    """The eighth model (default) equals the quarter and full models up to discretisation.

    Different unstructured meshes of 5 mm: the P/V agrees within 3 % and the RMS of the
    map difference over the centre is below 2 % of the P/V. Piston and tilt are removed
    first: the full model's 3-2-1 point constraints leave an arbitrary rigid tilt.
    """
    ref = eighth_200_50
    other = solve(200, 0.5, mesh=replace(COARSE, symmetry=symmetry))
    assert other.sag.pv_um("center") == pytest.approx(ref.sag.pv_um("center"), rel=0.03)
    m_ref = ref.sag.sag_map(1.0).remove_piston_tilt("center")
    m_o = other.sag.sag_map(1.0).remove_piston_tilt("center")
    d = m_o.sag_um - m_ref.sag_um
    dc = d[m_ref.region_mask("center")]
    assert np.sqrt(np.nanmean(dc**2)) < 0.02 * ref.sag.pv_um("center")


@pytest.mark.slow  # several FEA solves compared, among the slowest tests of the fast tier: the full tier
def test_asymmetric_polish_uses_a_quarter_model_and_tilts_nothing(eighth_200_50):
    r = solve(200, 0.5, polish_back=1.0, mesh=COARSE)
    assert "sym_z" not in r.info["symmetry_planes"]
    sym = eighth_200_50
    assert r.sag.pv_um("center") != pytest.approx(sym.sag.pv_um("center"), rel=1e-3)


@pytest.mark.slow  # several FEA solves compared, among the slowest tests of the fast tier: the full tier
def test_off_midplane_holes_use_a_quarter_model():
    r = solve(200, 0.75, blank=Blank(hole_axis_z_mm=1.0), mesh=COARSE)
    assert r.info["symmetry_planes"] == ["sym_x", "sym_y"]
    assert r.sag.pv_um("center") > 0


def test_eighth_model_refuses_asymmetric_coating(eighth):
    with pytest.raises(ValueError, match="polish_front=0.5 != polish_back=1.0"):
        eighth.solve(Coating(200, 0.5, 1.0))


@pytest.mark.parametrize("axes, match", [
    (dict(t0_um=[-10]), r"t0_um=-10.0 is outside the valid range"),
    (dict(polish=[1.5]), r"polish=1.5 is outside the valid range"),
    (dict(coverage=["inside"]), r"coverage='inside' is unknown"),
    (dict(hole_diameter_mm=[21]), r"hole_diameter_mm"),
    (dict(cold_K=[500]), None),
    (dict(bogus=[1]), r"unknown FEA parameter\(s\) \['bogus'\]"),
    (dict(substrate=["steel"]), r"substrate='steel' is unknown"),
])
def test_bad_sweep_input_is_refused_before_meshing(axes, match):
    from pipeline.sweeps.fea_cases import fea_grid

    if match is None:  # temperature range is checked against the material data at solve time
        with pytest.raises(ValueError, match=r"cold_K=500"):
            solve(cold_K=500, mesh=COARSE)
        return
    with pytest.raises(ValueError, match=match):
        fea_grid(**axes)


@pytest.mark.slow
def test_cli_sweep_writes_table_and_reuses_cases(tmp_path, capsys):
    from pipeline.cli import main

    args = ["sweep", "--t0-um", "100", "200", "--polish", "1.0", "--param", "mesh_size_mm=5",
            "--param", "mesh_bulk_mm=10", "--out", str(tmp_path), "--quiet"]
    assert main(args) == 0
    rows = list(csv.DictReader((tmp_path / "sweep.csv").open()))
    assert len(rows) == 2
    for col in ("coverage", "t0_um", "polish", "pv_center_um", "rms_center_um", "pv_full_um"):
        assert col in rows[0]
    assert rows[0]["coverage"] == "all"
    assert float(rows[1]["pv_center_um"]) > float(rows[0]["pv_center_um"]) > 0
    assert main(args) == 0
    assert "0 computed, 2 reused" in capsys.readouterr().out
    import xarray as xr

    ds = xr.open_dataset(tmp_path / "sweep.nc")
    assert ds["sag_um"].dims[-2:] == ("y_mm", "x_mm")


def test_cli_reports_bad_input_without_traceback(tmp_path, capsys):
    from pipeline.cli import main

    assert main(["sweep", "--polish", "0", "--out", str(tmp_path)]) == 2
    assert "--polish 0.0 is outside the valid range (0, 1]" in capsys.readouterr().err
