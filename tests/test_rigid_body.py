"""Rigid-body motion and low-order figure of point clouds (optics.rigid_body)."""

from __future__ import annotations

import numpy as np
import pytest

from optics.rigid_body import (
    URAD_PER_ARCSEC,
    RigidBodyMotion,
    fit_rigid_body,
    pv_rms_um,
    remove_low_order,
    rigid_displacement_um,
)


def test_arcsec_conversion():
    # 1 arcsec = pi / 648000 rad = 4.8481 µrad
    assert URAD_PER_ARCSEC == pytest.approx(4.84813681, rel=1e-8)
    assert RigidBodyMotion(0, 0, 0, 0, 0, 4.84813681).rz_arcsec == pytest.approx(1.0, rel=1e-8)


def test_sign_conventions():
    """rz > 0 turns +x towards +y (groove clocking); rx > 0 lifts +y; ry > 0 lowers +x."""
    p = np.array([[1.0, 0, 0], [0, 1.0, 0]])
    u = rigid_displacement_um(RigidBodyMotion(0, 0, 0, 0, 0, 1000.0), p)  # 1 mrad = 1 µm/mm
    np.testing.assert_allclose(u, [[0, 1, 0], [-1, 0, 0]], atol=1e-12)
    u = rigid_displacement_um(RigidBodyMotion(0, 0, 0, 1000.0, 1000.0, 0), p)
    np.testing.assert_allclose(u[:, 2], [-1, 1], atol=1e-12)


def test_fit_recovers_motion_from_noisy_cloud_about_an_origin():
    rng = np.random.default_rng(3)
    p = rng.uniform(-50, 50, (400, 3)) * [1, 1, 0.1]
    true = RigidBodyMotion(1.5, -0.7, 2.0, 12.0, -8.0, 30.0, origin_mm=(5.0, -3.0, 1.0))
    u = rigid_displacement_um(true, p) + rng.normal(0, 1e-3, p.shape)
    got = fit_rigid_body(p, u, rng.uniform(0.5, 2, len(p)), origin_mm=true.origin_mm)
    np.testing.assert_allclose(list(got.as_dict().values()), list(true.as_dict().values()), atol=0.05)
    assert got.minus(true).rz_urad == pytest.approx(got.rz_urad - 30.0)


def test_collinear_points_do_not_determine_the_motion():
    p = np.column_stack([np.linspace(0, 10, 5), np.zeros(5), np.zeros(5)])
    with pytest.raises(ValueError, match="rank"):
        fit_rigid_body(p, np.zeros_like(p))
    with pytest.raises(ValueError, match=r"shape \(n, 3\)"):
        fit_rigid_body(p[:, :2], np.zeros((5, 2)))


def test_power_removal():
    x, y = np.meshgrid(np.linspace(-41, 41, 83), np.linspace(-36, 36, 73))
    s = 0.3 + 0.01 * x - 0.02 * y + 2e-4 * (x**2 + y**2)
    r2, c2 = remove_low_order(x, y, s, remove=("piston", "tilt"))
    r3, c3 = remove_low_order(x, y, s, remove=("piston", "tilt", "power"))
    assert np.abs(r3).max() < 1e-12 and c3["power_um_per_mm2"] == pytest.approx(2e-4)
    # piston/tilt only leaves the bowl: P/V = 2e-4 (41² + 36²) on this symmetric grid
    assert pv_rms_um(r2)[0] == pytest.approx(2e-4 * (41**2 + 36**2))
    with pytest.raises(ValueError, match=r"remove=.*'coma'.*\['piston', 'tilt', 'power'\]"):
        remove_low_order(x, y, s, remove=("coma",))


# ---------------------------------------------------------------------- our own FEA's front face
def _bowl_front_sag(c=2e-4):
    from fea.surface import FrontSag

    x, y = (v.ravel() for v in np.meshgrid(np.linspace(-80, 80, 81), np.linspace(-70, 70, 71)))
    s = 0.1 + 0.003 * x + c * (x**2 + y**2)
    return FrontSag(x, y, s, s, np.ones_like(x), np.ones(x.size, bool))


def test_pttp_stats_remove_power_that_pt_leaves():
    from fea.front_figure import pttp_stats

    sag = _bowl_front_sag()
    st = pttp_stats(sag, "center")
    assert st["pv_um"] < 1e-12 and st["power_um_per_mm2"] == pytest.approx(2e-4)
    assert sag.pv_um("center") == pytest.approx(2e-4 * (41**2 + 36**2 - 0), rel=0.05)  # bowl left by P/T


def test_figure_summary_and_table_columns(tmp_path):
    from pipeline.sweeps.fea_cases import FIGURE_KEYS, TableRow, write_table_rows, write_figure_summary

    fig = {k: float(i) for i, k in enumerate(FIGURE_KEYS)}
    write_figure_summary(tmp_path / "s.csv", ["a", "b"], {"a": fig, "b": fig})
    lines = (tmp_path / "s.csv").read_text().splitlines()
    assert lines[0].startswith("case,T1 dx,T2 dy,T3 dz,R1 rx,R2 ry,R3 rz,PV center PT")
    assert lines[1].startswith("units,um,um,um,urad,urad,urad,um")
    assert len(lines) == 4
    write_table_rows([TableRow("1", "all", 200.0, 0.75, 0.6, 0.61, "up", 0.1, True, fig)], tmp_path / "t.csv")
    head, row = (tmp_path / "t.csv").read_text().splitlines()
    assert head.split(",")[:11][-1] == "used_in_calibration" and "rb_rz_urad" in head and "pv_center_pttp_um" in head
    assert row.split(",")[5] == "0.6100"  # the paper's metric, unchanged


def test_front_rigid_body_is_independent_of_how_the_body_is_pinned():
    """Any rigid motion added to the whole field cancels (no symmetry planes: a whole body)."""
    from fea.front_figure import front_rigid_body
    from fea.mesh import MeshSpec, blank_mesh
    from fea.geometry import Blank
    from optics.rigid_body import RigidBodyMotion, rigid_displacement_um

    mesh = blank_mesh(Blank(), MeshSpec(size_mm=5.0, size_bulk_mm=10.0))
    p = mesh.p.T
    rng = np.random.default_rng(0)
    u = 1e-4 * rng.normal(size=p.shape) + 1e-6 * p**2  # some deformation (mm)
    base = front_rigid_body(mesh, u.T)
    extra = RigidBodyMotion(5.0, -3.0, 2.0, 40.0, -25.0, 60.0, origin_mm=(10.0, -4.0, 3.0))
    moved = front_rigid_body(mesh, (u + 1e-3 * rigid_displacement_um(extra, p)).T)
    np.testing.assert_allclose(list(moved.as_dict().values()), list(base.as_dict().values()), atol=1e-8)


@pytest.mark.slow
def test_own_fea_case_outputs_rigid_body_and_power(tmp_path):
    """Eighth model: symmetry forces dx, dy, rx, ry, rz to zero; dz is the face's mean sag
    (the blank's mean z motion is zero by the mid-plane mirror); P/V_center is unchanged."""
    from pipeline.sweeps.fea_cases import FEACaseRunner, field_path, load_field

    params = {"t0_um": 200.0, "polish": 0.5, "mesh_size_mm": 5.0, "mesh_bulk_mm": 10.0}
    runner = FEACaseRunner(with_maps=False, fields_dir=tmp_path, fields_for=[params])
    out = runner(params)
    model = next(iter(runner._models.values()))
    s = model.front_sampler()(load_field(field_path(tmp_path, params)).displacement_mm)  # float32-stored field
    assert out["pv_center_um"] == pytest.approx(s.pv_um("center"), rel=1e-5)
    for k in ("rb_dx_um", "rb_dy_um"):
        assert abs(out[k]) < 1e-9
    for k in ("rb_rx_urad", "rb_ry_urad", "rb_rz_urad"):
        assert abs(out[k]) < 1e-9
    mean = np.sum(s.weight_mm2 * s.sag_um) / np.sum(s.weight_mm2)
    # two quadratures of the same face integral (corner-lumped vs the 15-point lattice)
    assert out["rb_dz_um"] == pytest.approx(mean, abs=0.05 * s.pv_um("full", remove_tilt=False))
    assert 0 < out["pv_center_pttp_um"] and 0 < out["rms_center_pttp_um"] <= out["rms_center_um"] + 1e-12


def test_study_nc_carries_rigid_body_with_units(tmp_path):
    from types import SimpleNamespace

    import xarray as xr

    from optics.sagmap import quilt_sag_map
    from pipeline.sweeps.fea_cases import FIGURE_KEYS
    from pipeline.study.dataset import study_dataset, write_study_netcdf

    case = SimpleNamespace(label="a", group="g", full={"t0_um": 200.0, "pitch_x_mm": 21.0, "pitch_y_mm": 18.0})
    out = {k: 1.0 for k in FIGURE_KEYS}
    ds = study_dataset([case], {"a": out}, {"a": quilt_sag_map(0.5, spacing_mm=4.0)}, [None], [None])
    write_study_netcdf(ds, tmp_path / "s.nc")
    with xr.open_dataset(tmp_path / "s.nc") as back:
        assert back["rb_rz_urad"].attrs["units"] == "urad" and "clocking" in back["rb_rz_urad"].attrs["long_name"]
        assert back["rb_dz_um"].attrs["units"] == "um"
        assert back["rms_full_pttp_um"].attrs["units"] == "um"
        assert back["power_center_um_per_mm2"].attrs["units"] == "um mm-2"
