"""`run_study` writes study.nc (parameters, P/V, sag maps, Zernike + Fourier fits, line
profiles) and exports/ that re-import through pipeline.io.registry (coarse mesh)."""
import numpy as np
import pytest

from pipeline.study.config import loads_study_config

CONFIG = """
[study]
title = "study.nc test"

[fea]
t0_um = 200
mesh_size_mm = 5
mesh_bulk_mm = 10

[[fea.cases]]
name = "polish"
polish = 0.75

[[fea.cases]]
name = "wide pitch"
pitch_x_mm = 24
polish = 1.0

[[profiles]]
set = "lines"
grating = "J"
wavelength_um = 1.25
pixel_scale_mas = 250
deformation = ["perfect", {polish = 0.75}]

[output]
figures = false
"""


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    from pipeline.study.run import run_study

    out = tmp_path_factory.mktemp("study")
    res = run_study(out, loads_study_config(CONFIG), progress=False)
    return out, res


def test_study_nc_holds_cases_fits_maps_and_profiles(study):
    import xarray as xr

    out, res = study
    labels = [c.label for c in res["cases"]]
    with xr.open_dataset(out / "study.nc") as ds:
        assert ds.sizes["case"] == 2 and ds.sizes["zernike"] == 37 and ds.sizes["fourier"] == 24
        assert ds["sag_um"].dims == ("case", "y_mm", "x_mm") and ds["sag_um"].attrs["units"] == "µm"
        assert list(ds["label"].values) == labels
        assert list(ds["polish"].values) == [0.75, 1.0] and ds["pitch_x_mm"].attrs["units"] == "mm"
        assert list(ds["fourier_period_x_mm"].values) == [21.0, 24.0]   # the blank's own pitch
        np.testing.assert_allclose(ds["pv_center_um"].values, [res["outputs"][lb]["pv_center_um"] for lb in labels])
        for v in ("zernike_um", "zernike_fringe_um", "fourier_amplitude_um", "fourier_phase_rad"):
            assert np.isfinite(ds[v].values).all(), v
        assert list(ds["zernike"].values[:4]) == [1, 2, 3, 4] and int(ds["zernike_noll"].values[3]) == 4
        assert ds["zernike_um"].attrs["normalisation_radius_mm"] == pytest.approx(0.5 * np.hypot(82, 72))
        assert (ds["zernike_residual_rms_um"] < ds["rms_center_um"]).all()
        # line profiles merged with their coordinates; one deformed wavefront (J -2 1.25 µm, 200/75)
        assert ds["intensity"].dims == ("profile", "offset_um")
        assert list(ds["deformation"].values) == ["perfect", labels[0]]
        assert list(ds["wavefront_case_label"].values) == [labels[0]]
        beta = np.radians(ds["wavefront_beta_deg"].values[0])
        alpha = np.radians(ds["wavefront_incidence_deg"].values[0])
        assert ds["wavefront_opd_per_sag"].values[0] == pytest.approx(-(np.cos(alpha) + np.cos(beta)))

        # the Zernike coefficients reproduce the sag map to the stated residual
        from optics.sagmap import resolve_region
        from optics.zernike import wavefront_from_coefficients

        X, Y = np.meshgrid(ds["x_mm"].values, ds["y_mm"].values)
        inside = resolve_region("center").contains(X, Y)
        r = float(ds["zernike_um"].attrs["normalisation_radius_mm"])
        for k in range(2):
            coeffs = {(int(n), int(m)): float(c) for n, m, c in
                      zip(ds["zernike_n"].values, ds["zernike_m"].values, ds["zernike_um"].values[k])}
            sag = ds["sag_um"].values[k].astype(float)
            res_map = (sag - wavefront_from_coefficients(coeffs, X, Y, r, norm=True))[inside]
            rms = float(np.sqrt(np.nanmean(res_map**2)))
            assert rms == pytest.approx(float(ds["zernike_residual_rms_um"].values[k]), rel=1e-3, abs=2e-6)
            assert rms < float(np.nanstd(sag[inside]))   # the quilt is left: the Fourier fit holds it


def test_exports_round_trip_through_interchange(study):
    import xarray as xr

    from pipeline.io.registry import read_sag_map
    from pipeline.io.zernike import read_zernike_list
    from pipeline.study.dataset import file_slug

    out, res = study
    ex = out / "exports"
    names = sorted(p.name for p in ex.iterdir())
    assert len([n for n in names if n.endswith("_sag.int")]) == 2
    assert len([n for n in names if n.endswith("_sag.dat")]) == 2
    assert len([n for n in names if n.endswith("_zernike_fringe.txt")]) == 2
    assert len([n for n in names if n.endswith("_zernike_noll.txt")]) == 2
    (wfr,) = [n for n in names if n.endswith("_wfr.int")]
    stem = f"case00_{file_slug(res['cases'][0].label)}"
    assert wfr == f"{stem}_J_m-2_1.25um_wfr.int" and "index.csv" in names
    with xr.open_dataset(out / "study.nc") as ds:
        sag = ds["sag_um"].values[0].astype(float)
        coeffs = {(int(n), int(m)): float(c) for n, m, c in
                  zip(ds["zernike_n"].values, ds["zernike_m"].values, ds["zernike_um"].values[0])}
        factor = float(ds["wavefront_opd_per_sag"].values[0])
        x, y = ds["x_mm"].values, ds["y_mm"].values
    for suffix in ("_sag.int", "_sag.dat"):
        m = read_sag_map(ex / f"{stem}{suffix}")
        # 16-bit INT: half a count, WVL / SSZ = max|sag| / 32766 um per count; DAT: 12 digits
        tol = 0.5 * m.meta["wavelength_um"] / m.meta["ssz"] * (1 + 1e-9) if suffix == "_sag.int" else 1e-9
        if suffix == "_sag.int":
            assert tol <= 0.5 * np.nanmax(np.abs(sag)) / 32766 * (1 + 1e-5)
        np.testing.assert_allclose(m.x_mm, x, atol=1e-9)
        np.testing.assert_allclose(m.y_mm, y, atol=1e-9)
        assert np.array_equal(np.isnan(m.sag_um), np.isnan(sag))
        np.testing.assert_allclose(m.sag_um, sag, atol=tol, equal_nan=True)
    w = read_sag_map(ex / wfr, quantity="wavefront")
    assert w.meta["codev_type"] == "WFR" and w.meta["wavelength_um"] == 1.25
    np.testing.assert_allclose(w.sag_um, factor * sag, atol=0.5 * 1.25 / w.meta["ssz"] * (1 + 1e-9), equal_nan=True)
    # the CODE V ZFR deck and the OpticStudio Zernike Sag lists hold the same fit
    from pipeline.io.codev_zfr import read_codev_zernike
    from pipeline.io.zemax import read_zemax_zernike

    decks = [read_codev_zernike(ex / f"{stem}_zernike_zfr.int", normalised=True)]
    decks += [read_zemax_zernike(ex / f"{stem}_zernike_{c}_zemax.dat", c, normalised=True) for c in ("standard", "fringe")]
    for back, info in decks:
        assert info["radius_mm"] == pytest.approx(0.5 * np.hypot(82, 72))
        np.testing.assert_allclose([back.get(k, 0.0) for k in coeffs], list(coeffs.values()), rtol=1e-10, atol=1e-15)
    for conv, normalised in (("noll", True), ("fringe", False)):
        back, info = read_zernike_list(ex / f"{stem}_zernike_{conv}.txt", normalised=True)
        assert info["radius_mm"] == pytest.approx(0.5 * np.hypot(82, 72))
        assert back.keys() == coeffs.keys()
        np.testing.assert_allclose([back[k] for k in coeffs], list(coeffs.values()), rtol=1e-12, atol=1e-15)
    report = (out / "report.html").read_text()
    assert "Zernike and quilt fits" in report and "astig 0°" in report


def test_exports_switched_off(tmp_path, study):
    from dataclasses import replace

    from pipeline.study.figure_specs import OutputOptions
    from pipeline.study.run import run_study

    out, _ = study
    cfg = loads_study_config(CONFIG)
    cfg = replace(cfg, fea=cfg.fea[:1], profiles=(), figures=(),
                  output=OutputOptions(figures=False, report=False, exports=False))
    import shutil

    shutil.copytree(out / "fea", tmp_path / "fea")       # reuse the solved cases
    res = run_study(tmp_path, cfg, progress=False)
    assert res["exports"] == [] and not (tmp_path / "exports").exists()
    assert (tmp_path / "study.nc").exists()
