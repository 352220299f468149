"""Column, variable and array names as other code writes them (:mod:`pipeline.io.columns`):
each accepted spelling of a sag, a map coordinate and an intensity read back to the values
written, each refused one named with the accepted names. Files are written here with
numpy, plain text and netCDF4, never with the project's writers; expected values are the
written ones through the stated unit."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.diagnosis.manifest import load_data, parse_manifest
from pipeline.io import registry as ic

WAVE_UM = 0.6328  # a HeNe interferometer's wave
G = np.arange(-4.0, 4.01, 1.0)  # mm


def _grid():
    """(x_mm, y_mm, sag_um) of every node of a 9 x 9 grid, x fastest."""
    X, Y = np.meshgrid(G, G)
    return X.ravel(), Y.ravel(), (0.05 * X - 0.02 * Y**2 + 0.003 * X * Y).ravel()


def _table(path, header, columns, delimiter=","):
    """A text table: ``header`` names, one row per point, values in Python's round-trip form."""
    rows = (delimiter.join(repr(float(v)) for v in r) for r in zip(*columns))
    path.write_text(delimiter.join(header) + "\n" + "\n".join(rows) + "\n")
    return path


# ------------------------------------------------------------------ surface tables
@pytest.mark.parametrize("name,header,delimiter,scale", [
    ("nm.csv", ("X [mm]", "Y [mm]", "Height [nm]"), ",", 1e3),
    ("height_um.csv", ("x_mm", "y_mm", "height_um"), ",", 1.0),
    ("z_um.csv", ("x_mm", "y_mm", "Z [um]"), ";", 1.0),
    ("z_mm.csv", ("x_mm", "y_mm", "z_mm"), ",", 1e-3),
    ("tab.txt", ("X (mm)", "Y (mm)", "Z (um)"), "\t", 1.0),
    ("space.txt", ("x_mm", "y_mm", "height_nm"), "  ", 1e3),
    ("sag_m.tsv", ("x_mm", "y_mm", "sag_m"), "\t", 1e-6),
], ids=lambda v: v if isinstance(v, str) and "." in v else None)
def test_sag_column_aliases_read_to_um(tmp_path, name, header, delimiter, scale):
    x, y, sag = _grid()
    m = ic.read_sag_map(_table(tmp_path / name, header, (x, y, sag * scale), delimiter))
    np.testing.assert_allclose(m.x_mm, G)
    np.testing.assert_allclose(m.sag_um.ravel(), sag, rtol=1e-12, atol=1e-15)


def test_sag_in_waves_needs_the_wavelength(tmp_path):
    x, y, sag = _grid()
    f = _table(tmp_path / "w.csv", ("X [mm]", "Y [mm]", "sag [waves]"), (x, y, sag / WAVE_UM))
    m = ic.read_sag_map(f, wavelength_um=WAVE_UM)
    np.testing.assert_allclose(m.sag_um.ravel(), sag, rtol=1e-12, atol=1e-15)
    with pytest.raises(ValueError, match=r"w\.csv: column 'sag_waves': units='waves' needs wavelength_um"):
        ic.read_sag_map(f)


def test_manifest_wavelength_reaches_a_table_in_waves(tmp_path):
    X, Y = np.meshgrid(np.arange(-30.0, 30.01, 2.0), np.arange(-30.0, 30.01, 2.0))
    sag = 0.1 * np.cos(2 * np.pi * X / 21.0)
    f = _table(tmp_path / "cold.csv", ("x_mm", "y_mm", "Height [waves]"),
               (X.ravel(), Y.ravel(), sag.ravel() / WAVE_UM))
    entry = {"kind": "surface", "file": str(f), "temperature_K": 128, "wavelength_um": WAVE_UM}
    (s,) = load_data(parse_manifest({"measurement": [entry]}))
    np.testing.assert_allclose(s.sag_um, 0.1 * np.cos(2 * np.pi * s.x_mm / 21.0), rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("header,pattern", [
    (("x_mm", "y_mm", "z"), r"missing column\(s\) \['sag_um'\].*'z' has no unit; accepted sag \(surface height\): "
                            r"'sag', 'height', 'z' with its unit in the name \(sag_um, Height \[nm\]"),
    (("x_mm", "y_mm", "height"), r"missing column.*; 'height' has no unit; accepted sag .*'sag', 'height', 'z'"),
    (("x", "y", "sag_um"), r"missing column\(s\) \['x_mm', 'y_mm'\].*'x' has no unit; accepted x coordinate: 'x' "
                           r"with its unit in the name \(x_mm, X \[m\]\)"),
    (("x_mm", "y_mm", "elevation_um"), r"missing column\(s\) \['sag_um'\].*accepted sag \(surface height\): 'sag', "
                                       r"'height', 'z'"),
    (("x_mm", "y_mm", "z [furlongs]"), r"missing column.*found header \['x_mm', 'y_mm', 'z_furlongs'\].*"
                                       r"accepted sag \(surface height\): 'sag', 'height', 'z' with its unit"),
], ids=["bare_z", "bare_height", "bare_coordinates", "unknown_name", "unknown_unit"])
def test_sag_table_without_an_accepted_column_lists_the_accepted_names(tmp_path, header, pattern):
    x, y, sag = _grid()
    with pytest.raises(ValueError, match=r"t\.csv, line 1: " + pattern):
        ic.read_sag_map(_table(tmp_path / "t.csv", header, (x, y, sag)))


def test_txt_is_read_not_written(tmp_path):
    x, y, sag = _grid()
    m = ic.read_sag_map(_table(tmp_path / "m.txt", ("x_mm", "y_mm", "sag_um"), (x, y, sag), "\t"))
    with pytest.raises(ValueError, match=r"'\.txt' files are read, not written"):
        ic.write_sag_map(m, tmp_path / "out.txt")


# ------------------------------------------------------------------ NetCDF variables and .npz arrays
def _netcdf(path, name, values, units):
    import netCDF4

    with netCDF4.Dataset(path, "w") as ds:
        ds.createDimension("y", G.size)
        ds.createDimension("x", G.size)
        for d in ("y", "x"):
            v = ds.createVariable(d, "f8", (d,))
            v[:] = G
            v.units = "mm"
        v = ds.createVariable(name, "f8", ("y", "x"))
        v[:] = values
        if units is not None:
            v.units = units
    return path


@pytest.mark.parametrize("name,units,scale", [
    ("height", "nm", 1e3), ("z", "um", 1.0), ("height_nm", None, 1e3), ("z_um", None, 1.0), ("Height", "mm", 1e-3),
])
def test_netcdf_sag_variable_aliases(tmp_path, name, units, scale):
    _, _, sag = _grid()
    m = ic.read_sag_map(_netcdf(tmp_path / "m.nc", name, sag.reshape(G.size, G.size) * scale, units))
    np.testing.assert_allclose(m.sag_um.ravel(), sag, rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("name,pattern", [
    ("height", r"variable 'height' has no 'units' attribute; give units .*or put the unit in its name \(height_um\)"),
    ("elevation", r"no sag variable; found \['elevation'\]; accepted sag \(surface height\): 'sag', "
                  r"'height', 'z'"),
])
def test_netcdf_sag_variable_refused_by_name(tmp_path, name, pattern):
    _, _, sag = _grid()
    with pytest.raises(ValueError, match=r"m\.nc: " + pattern):
        ic.read_sag_map(_netcdf(tmp_path / "m.nc", name, sag.reshape(G.size, G.size), None))


@pytest.mark.parametrize("arrays,options", [
    ({"x_mm": 1.0, "y_mm": 1.0, "z_um": 1.0}, {}),
    ({"x_m": 1e-3, "y_um": 1e3, "height_nm": 1e3}, {}),
    ({"x_mm": 1.0, "y_mm": 1.0, "sag_waves": 1 / WAVE_UM}, {"wavelength_um": WAVE_UM}),
], ids=["z_um", "other_units", "waves"])
def test_npz_array_aliases(tmp_path, arrays, options):
    _, _, sag = _grid()
    values = dict(zip(arrays, (G, G, sag.reshape(G.size, G.size))))
    f = tmp_path / "m.npz"
    np.savez(f, **{k: v * arrays[k] for k, v in values.items()})
    m = ic.read_sag_map(f, **options)
    np.testing.assert_allclose(m.x_mm, G, rtol=1e-12)
    np.testing.assert_allclose(m.y_mm, G, rtol=1e-12)
    np.testing.assert_allclose(m.sag_um.ravel(), sag, rtol=1e-12, atol=1e-15)


def test_npz_arrays_without_units_are_refused_naming_the_accepted_ones(tmp_path):
    _, _, sag = _grid()
    f = tmp_path / "g.npz"
    np.savez(f, x=G, y=G, z=sag.reshape(G.size, G.size))
    with pytest.raises(ValueError, match=r"g\.npz: no array for the x coordinate, y coordinate, sag \(surface "
                                         r"height\); found \['x', 'y', 'z'\]; 'x' has no unit; accepted x coordinate: "
                                         r"'x' with its unit in the name \(x_mm.*'z' has no unit; accepted sag"):
        ic.read_sag_map(f)


# ------------------------------------------------------------------ intensities
OFFSET_UM = np.arange(-60.0, 60.01, 3.0)
#: a double-peaked line on a pedestal, in counts
COUNTS = 150.0 + 900.0 * np.exp(-0.5 * ((OFFSET_UM + 10) / 6) ** 2) + 700.0 * np.exp(-0.5 * ((OFFSET_UM - 10) / 6) ** 2)


@pytest.mark.parametrize("header,delimiter", [
    (("offset_um", "counts"), ","), (("Offset [um]", "Flux [ADU]"), ","), (("offset_um", "flux"), ";"),
    (("offset_um", "intensity [counts]"), "\t"), (("offset_um", "Signal (e-)"), ","), (("offset_um", "FLUX"), ","),
], ids=["counts", "Flux_ADU", "flux", "intensity_counts", "signal_e-", "FLUX"])
def test_profile_intensity_aliases(tmp_path, header, delimiter):
    f = _table(tmp_path / "p.csv", header, (OFFSET_UM, COUNTS), delimiter)
    x, y = ic.read_measured("line profile", f, normalise=False, pixel_um=18.0, dispersion_um_per_um=-1.2e5)
    np.testing.assert_array_equal(x, OFFSET_UM)
    np.testing.assert_array_equal(y, COUNTS)


def test_profile_on_pixels_or_wavelengths_with_an_intensity_alias(tmp_path):
    px = 1024.0 + OFFSET_UM / 18.0
    x, y = ic.read_measured("line profile", _table(tmp_path / "px.csv", ("pixel", "counts"), (px, COUNTS)),
                            normalise=False, pixel_um=18.0)
    np.testing.assert_allclose(x, px * 18.0, rtol=1e-15)
    np.testing.assert_array_equal(y, COUNTS)
    dispersion = -1.2e5  # detector µm per µm of wavelength
    wl_nm = (1.25 + OFFSET_UM / dispersion) * 1e3
    f = _table(tmp_path / "wl.csv", ("Wavelength [nm]", "Flux [ADU]"), (wl_nm, COUNTS))
    x, y = ic.read_measured("line profile", f, normalise=False, dispersion_um_per_um=dispersion)
    np.testing.assert_allclose(x, OFFSET_UM, atol=1e-9)
    np.testing.assert_array_equal(y, COUNTS)


@pytest.mark.parametrize("header", [("offset_um", "brightness"), ("offset_um", "flux_err"),
                                    ("offset_um", "Flux (sigma)"), ("offset_um", "counts_bkg")])
def test_profile_without_an_intensity_column_lists_the_accepted_names(tmp_path, header):
    # an error, a background or a quantity the table does not name is not the intensity
    f = _table(tmp_path / "p.csv", header, (OFFSET_UM, COUNTS))
    with pytest.raises(ValueError, match=r"p\.csv, line 1: missing column\(s\) \['intensity'\].*accepted intensity: "
                                         r"'intensity', 'flux', 'counts', 'signal', 'data', 'value', with or without a "
                                         r"unit \(.*any unit"):
        ic.read_measured("line profile", f, pixel_um=18.0)


@pytest.mark.parametrize("name", ["flux [erg/s]", "Flux [e-/s]", "Intensity [ADU/s]", "flux [erg/s/cm2/A]",
                                  "intensity (W)"])
def test_an_intensity_in_any_unit_is_read_beside_its_error(tmp_path, name):
    # the intensity's unit is irrelevant (flux is fitted); its error column comes first
    f = _table(tmp_path / "p.csv", ("offset_um", f"{name.split()[0]}_err", name),
               (OFFSET_UM, np.sqrt(COUNTS), COUNTS))
    x, y = ic.read_measured("line profile", f, normalise=False, pixel_um=18.0)
    np.testing.assert_array_equal(x, OFFSET_UM)
    np.testing.assert_array_equal(y, COUNTS)


def test_psf_image_intensity_alias(tmp_path):
    X, Y = np.meshgrid(np.arange(-10.0, 10.01, 2.0), np.arange(-10.0, 10.01, 2.0))
    counts = 50.0 + 1000.0 * np.exp(-0.5 * (X**2 + Y**2) / 9.0)
    f = _table(tmp_path / "psf.csv", ("x_um", "y_um", "Counts [ADU]"), (X.ravel(), Y.ravel(), counts.ravel()))
    x, y, v = ic.read_measured("psf image", f)
    np.testing.assert_array_equal(v, counts.ravel())  # rows were written sorted by (y, x)
    np.testing.assert_array_equal(x, X.ravel())


# ------------------------------------------------------------------ decimal commas
def test_decimal_commas_are_read_where_the_delimiter_leaves_no_doubt(tmp_path):
    """A European locale's export (semicolon or tab delimited, decimal commas) reads as the
    same numbers as the decimal-point table; a map too. What is refused names why: a comma
    that could be a thousands separator in every number (1,250 is 1.25 or 1250), a table mixing
    both separators, a comma-delimited table whose decimal commas split its numbers."""
    f = tmp_path / "eu.csv"
    f.write_text("offset_um;intensity\n" + "".join(f"{o:.1f};{c:.3f}\n".replace(".", ",")
                                                   for o, c in zip(OFFSET_UM, COUNTS)))
    ref = tmp_path / "ref.csv"
    ref.write_text("offset_um,intensity\n" + "".join(f"{o:.1f},{c:.3f}\n" for o, c in zip(OFFSET_UM, COUNTS)))
    u, v = ic.read_measured("line profile", f)
    u0, v0 = ic.read_measured("line profile", ref)
    np.testing.assert_array_equal(u, u0)
    np.testing.assert_array_equal(v, v0)
    x = np.repeat(np.arange(-4.0, 4.01, 2.0), 5)
    y = np.tile(np.arange(-4.0, 4.01, 2.0), 5)
    sag = 0.0125 * x - 0.003 * y**2
    m = tmp_path / "map.csv"
    m.write_text("x [mm]\ty [mm]\tsag [um]\n" + "".join(f"{a:.2f}\t{b:.2f}\t{c:.5f}\n".replace(".", ",")
                                                      for a, b, c in zip(x, y, sag)))
    sm = ic.read_sag_map(m)
    X, Y = sm.grid()
    np.testing.assert_allclose(sm.sag_um, 0.0125 * X - 0.003 * Y**2, atol=1e-12)
    amb = tmp_path / "thousands.csv"
    amb.write_text("offset_um;intensity\n" + "".join(f"{o};{c}\n" for o, c in (("-1,250", "2,125"), ("1,250", "3,500"))))
    with pytest.raises(ValueError, match=r"thousands\.csv, line 2: decimal comma in '-1,250' .*every comma-number could "
                                         r"hold a thousands separator; export the table with '\.' as the decimal "
                                         r"separator"):
        ic.read_measured("line profile", amb)
    mixed = tmp_path / "mixed.csv"
    mixed.write_text("offset_um;intensity\n-60,5;150.0\n-57,5;151.0\n")
    with pytest.raises(ValueError, match=r"mixed\.csv, line 2: decimal comma in '-60,5' .*the table also has decimal "
                                         r"points"):
        ic.read_measured("line profile", mixed)
    g = tmp_path / "eu_comma.csv"
    g.write_text("offset_um,intensity\n" + "".join(f"{o:.1f},{c:.3f}\n".replace(".", ",")
                                                   for o, c in zip(OFFSET_UM, COUNTS)))
    with pytest.raises(ValueError, match=r"eu_comma\.csv, line 2: expected 2 values like the header, found 4; if the "
                                         r"table uses decimal commas, they split its numbers"):
        ic.read_measured("line profile", g)
