"""Files as other software writes them, each written here with numpy, astropy or plain text
(never with the project's writers): an IRAF spectrum, FITS axes without units, grids printed
to a few digits or stored in float32, wavelengths in Angstrom, intensities in any unit, tables
with a commented header, a tab table with commas in its names, bad-pixel markers, a Windows
code page. Expected values are the numbers written; a file whose axis could mean several
things is refused by name, never read as one of them."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.io import registry as ic
from pipeline.io.gridding import grid_from_options

OFFSET_UM = np.arange(-4.0, 4.01, 1.0)
COUNTS = np.array([1.0, 3.0, 10.0, 40.0, 90.0, 41.0, 11.0, 2.0, 1.0])
DISPERSION = -1000.0  # detector µm per µm of wavelength


def _profile(path):
    return ic.read_measured("line profile", path, normalise=False, pixel_um=18.0, dispersion_um_per_um=DISPERSION)


# ------------------------------------------------------------------ FITS axes
def _spectrum(path, **cards):
    from astropy.io import fits

    h = fits.PrimaryHDU(COUNTS.copy())
    for k, v in cards.items():
        h.header[k] = v
    h.writeto(path)
    return path


def test_an_iraf_spectrum_reads_its_unit_from_the_wat_cards(tmp_path):
    # IRAF's onedspec: CTYPE1 = 'LINEAR', the unit only in WAT1_001
    f = _spectrum(tmp_path / "iraf.fits", CTYPE1="LINEAR", CRVAL1=12496.0, CDELT1=2.0, CRPIX1=1.0,
                  WAT0_001="system=equispec", WAT1_001="wtype=linear label=Wavelength units=angstroms")
    x, y = _profile(f)
    # 2 Angstrom = 2e-4 µm per pixel, times the dispersion, about the median wavelength
    np.testing.assert_allclose(x, np.sort(OFFSET_UM * 2e-4 * DISPERSION), atol=1e-9)
    np.testing.assert_array_equal(y, COUNTS[::-1])  # negative dispersion: sorted by offset


def test_a_fits_axis_with_a_wcs_but_no_unit_is_refused_by_name(tmp_path):
    # CRVAL/CDELT without CUNIT or WAT: Angstrom? nm? pixels? Not guessed
    f = _spectrum(tmp_path / "nounit.fits", CRVAL1=12500.0, CDELT1=2.0, CRPIX1=1.0)
    with pytest.raises(ValueError, match=r"nounit\.fits: axis 1 has a WCS \(CRVAL1=12500.0, CDELT1=2.0\) but no "
                                         r"unit.*add CUNIT1 \(Angstrom, nm, um, mm, or pixel\)"):
        _profile(f)
    # the pixel numbers themselves are pixels
    x, _ = _profile(_spectrum(tmp_path / "pixels.fits", CRVAL1=1.0, CDELT1=1.0, CRPIX1=1.0))
    np.testing.assert_allclose(x, 18.0 * np.arange(1, 10))


@pytest.mark.parametrize("cunit,to_um", [("Angstroms", 1e-4), ("angstroms", 1e-4), ("micron", 1.0),
                                         ("microns", 1.0), ("nanometer", 1e-3), ("nanometers", 1e-3)])
def test_a_spectrum_whose_cunit_is_spelled_out_is_read_in_that_unit(tmp_path, cunit, to_um):
    # wcslib refuses these spellings on a spectral axis; pipelines and lab tools write them
    f = _spectrum(tmp_path / "s.fits", CTYPE1="WAVE", CUNIT1=cunit, CRVAL1=1.2496 / to_um, CDELT1=2e-4 / to_um,
                  CRPIX1=1.0)
    x, y = _profile(f)
    np.testing.assert_allclose(x, np.sort(OFFSET_UM * 2e-4 * DISPERSION), atol=1e-6)
    np.testing.assert_array_equal(y, COUNTS[::-1])


@pytest.mark.parametrize("ctype", ["WAVELENGTH", "Wavelength"])
def test_a_spectrum_typed_wavelength_in_full_is_a_wavelength(tmp_path, ctype):
    # CTYPE1 = 'WAVELENGTH' is outside the WCS standard, and common; in µm it is no offset
    f = _spectrum(tmp_path / "s.fits", CTYPE1=ctype, CUNIT1="um", CRVAL1=1.2496, CDELT1=2e-4, CRPIX1=1.0)
    x, _ = _profile(f)
    np.testing.assert_allclose(x, np.sort(OFFSET_UM * 2e-4 * DISPERSION), atol=1e-6)


@pytest.mark.parametrize("cards", [{}, {"CTYPE1": "LINEAR"}])
def test_a_spectrum_in_um_not_typed_a_wavelength_is_refused_by_name(tmp_path, cards):
    # 1.2496, 1.2498, ... µm read as detector offsets would be a line 0.002 µm wide: not guessed
    f = _spectrum(tmp_path / "s.fits", CUNIT1="um", CRVAL1=1.2496, CDELT1=2e-4, CRPIX1=1.0, **cards)
    with pytest.raises(ValueError, match=r"s\.fits: axis 1 \(unit 'um', CTYPE (none|LINEAR)\) reads as detector "
                                         r"offsets spanning 0\.0016 µm, below the 1 µm.*declare it \(CTYPE1 = 'WAVE'"):
        _profile(f)
    # a detector-offset axis in µm is one
    x, _ = _profile(_spectrum(tmp_path / "o.fits", CUNIT1="um", CRVAL1=-36.0, CDELT1=9.0, CRPIX1=1.0, **cards))
    np.testing.assert_allclose(x, 9.0 * OFFSET_UM)


@pytest.mark.parametrize("cards", [{"PS1_0": "WCS-TAB", "PS1_1": "COORDS"}, {}])
def test_a_tabulated_wavelength_axis_is_refused_by_name(tmp_path, cards):
    # wcslib reads a -TAB axis from another HDU: from the header alone it raised a MemoryError
    # (no PSi_m cards) or asked for an HDUList
    f = _spectrum(tmp_path / "tab.fits", CTYPE1="WAVE-TAB", CUNIT1="um", CRVAL1=1.25, CDELT1=1.0, CRPIX1=1.0, **cards)
    with pytest.raises(ValueError, match=r"tab\.fits: axis 1: CTYPE1='WAVE-TAB' is a tabulated \(-TAB\) axis, which "
                                         r"is not read; write the profile as a binary table"):
        _profile(f)


@pytest.mark.parametrize("name", ["OFFSET", "X"])
def test_a_fits_table_offset_without_a_unit_is_refused_by_name(tmp_path, name):
    from astropy.io import fits

    cols = [fits.Column(name=name, format="D", array=OFFSET_UM),
            fits.Column(name="INTENSITY", format="D", array=COUNTS)]
    fits.BinTableHDU.from_columns(cols).writeto(tmp_path / "t.fits")
    with pytest.raises(ValueError, match=rf"t\.fits: table column '{name}' has no unit \(TUNIT\).*give its TUNIT"):
        _profile(tmp_path / "t.fits")


# ------------------------------------------------------------------ grids as printed or stored
def test_a_third_of_a_millimetre_grid_printed_to_six_digits_is_a_grid(tmp_path):
    g = np.arange(12) / 3.0
    X, Y = np.meshgrid(g, g)
    S = 0.1 * X - 0.02 * Y**2
    np.savetxt(tmp_path / "m.csv", np.column_stack([X.ravel(), Y.ravel(), S.ravel()]), delimiter=",",
               header="x_mm,y_mm,sag_um", comments="", fmt="%.6g")
    m = ic.read_sag_map(tmp_path / "m.csv")
    assert m.meta["gridding"] == "uniform grid detected"
    np.testing.assert_allclose(m.x_mm, g, atol=1e-6)
    np.testing.assert_allclose(m.sag_um, S, atol=1e-6)


def test_float32_coordinates_in_npz_and_netcdf_are_a_grid(tmp_path):
    import xarray as xr

    g = (np.arange(200) - 99.5) * 0.685
    X, Y = np.meshgrid(g, g)
    S = 0.3 * np.cos(2 * np.pi * X / 21.0)
    np.savez(tmp_path / "m.npz", x_mm=g.astype(np.float32), y_mm=g.astype(np.float32), sag_um=S)
    xr.Dataset({"height": (("y", "x"), S * 1e3, {"units": "nm"})},
               coords={"x": ("x", g.astype(np.float32), {"units": "mm"}),
                       "y": ("y", g.astype(np.float32), {"units": "mm"})}).to_netcdf(tmp_path / "m.nc")
    for f in ("m.npz", "m.nc"):
        m = ic.read_sag_map(tmp_path / f)
        np.testing.assert_allclose(m.x_mm, g, atol=1e-4)  # float32 of 68 mm: 4e-6 mm
        np.testing.assert_allclose(np.diff(m.x_mm), 0.685, rtol=1e-6)
        np.testing.assert_allclose(m.sag_um, S, atol=1e-9)


def test_a_sag_in_waves_may_say_lambda(tmp_path):
    g = np.arange(5.0)
    X, Y = np.meshgrid(g, g)
    np.savetxt(tmp_path / "w.csv", np.column_stack([X.ravel(), Y.ravel(), 0.1 * X.ravel()]), delimiter=",",
               header="x [mm],y [mm],Height [λ]", comments="", fmt="%.12g", encoding="utf-8")
    m = ic.read_sag_map(tmp_path / "w.csv", wavelength_um=0.6328)
    np.testing.assert_allclose(m.sag_um, 0.06328 * X)


@pytest.mark.parametrize("where", ["variable", "file"])
def test_a_netcdf_sag_in_waves_takes_the_wavelength_it_states(tmp_path, where):
    """A NetCDF map in waves that states its wavelength (an attribute of the variable or of
    the file, in µm or nm) is read with it; a manifest's different wavelength is refused
    naming both, and one without any names the manifest key."""
    import xarray as xr

    g = np.arange(-10.0, 10.5, 0.5)
    X, _ = np.meshgrid(g, g)
    attrs = {"units": "waves"} | ({"wavelength_um": 0.6328} if where == "variable" else {})
    ds = xr.Dataset({"height": (("y", "x"), 0.1 * X, attrs)},
                    coords={"x": ("x", g, {"units": "mm"}), "y": ("y", g, {"units": "mm"})},
                    attrs={"wavelength_nm": 632.8} if where == "file" else {})
    ds.to_netcdf(tmp_path / "w.nc")
    m = ic.read_sag_map(tmp_path / "w.nc")
    np.testing.assert_allclose(m.sag_um, 0.06328 * X, rtol=1e-12)
    np.testing.assert_allclose(ic.read_sag_map(tmp_path / "w.nc", wavelength_um=0.6328).sag_um, m.sag_um)
    with pytest.raises(ValueError, match=r"wavelength_um=0.55 contradicts the file's wavelength_(um|nm) \(0.6328 µm\)"):
        ic.read_sag_map(tmp_path / "w.nc", wavelength_um=0.55)
    xr.Dataset({"height": (("y", "x"), 0.1 * X, {"units": "waves"})},
               coords={"x": ("x", g, {"units": "mm"}), "y": ("y", g, {"units": "mm"})}).to_netcdf(tmp_path / "n.nc")
    with pytest.raises(ValueError, match=r"needs wavelength_um.*the measurement's 'wavelength_um' key"):
        ic.read_sag_map(tmp_path / "n.nc")


def test_a_netcdf_coordinate_in_an_unknown_unit_is_named_as_the_coordinate(tmp_path):
    import xarray as xr

    g = np.arange(5.0)
    xr.Dataset({"sag": (("y", "x"), np.zeros((5, 5)), {"units": "um"})},
               coords={"x": ("x", g, {"units": "cm"}), "y": ("y", g, {"units": "mm"})}).to_netcdf(tmp_path / "c.nc")
    with pytest.raises(ValueError, match=r"c\.nc: coordinate 'x': units='cm' is not a known length unit"):
        ic.read_sag_map(tmp_path / "c.nc")


def test_grid_options_of_the_wrong_form_are_named():
    with pytest.raises(ValueError, match=r"extent_mm=\[1, 2, 3\] must be four numbers \(xmin, xmax, ymin, ymax\)"):
        grid_from_options(3, 3, extent_mm=[1, 2, 3])
    with pytest.raises(ValueError, match=r"spacing_mm='abc' must be a number > 0 or a pair"):
        grid_from_options(3, 3, spacing_mm="abc")
    np.testing.assert_allclose(grid_from_options(3, 3, spacing_mm="0.5")[0], [-0.5, 0.0, 0.5])


# ------------------------------------------------------------------ profile tables
def _text(path, header, rows, delimiter=",", encoding="utf-8"):
    body = "\n".join(delimiter.join(r) for r in rows)
    path.write_bytes(((header + "\n" if header is not None else "") + body + "\n").encode(encoding))
    return path


def _rows(x=OFFSET_UM, y=COUNTS):
    return [(repr(float(a)), repr(float(b))) for a, b in zip(x, y)]


@pytest.mark.parametrize("header,scale", [("wavelength [A]", 1e-4), ("Wavelength (Angstrom)", 1e-4),
                                          ("wave_angstrom", 1e-4), ("lambda [nm]", 1e-3)])
def test_a_wavelength_in_angstrom(tmp_path, header, scale):
    wl = 12500.0 * 1e-4 / scale + OFFSET_UM  # one unit per sample
    x, y = _profile(_text(tmp_path / "p.csv", f"{header},flux", _rows(wl)))
    np.testing.assert_allclose(x, np.sort(OFFSET_UM * scale * DISPERSION), atol=1e-9)


def test_a_commented_header_as_numpy_and_astropy_write_it(tmp_path):
    np.savetxt(tmp_path / "a.csv", np.column_stack([OFFSET_UM, COUNTS]), delimiter=",", header="offset_um,intensity")
    np.savetxt(tmp_path / "b.txt", np.column_stack([OFFSET_UM, COUNTS]), header="title line\noffset_um intensity")
    for f in ("a.csv", "b.txt"):
        x, y = _profile(tmp_path / f)
        np.testing.assert_array_equal(x, OFFSET_UM)
        np.testing.assert_array_equal(y, COUNTS)


def test_an_astropy_ecsv_table_gives_its_units_in_its_yaml_header(tmp_path):
    import astropy.units as u
    from astropy.table import Table

    lam_um = 1.2496 + 2e-4 * (OFFSET_UM + 4.0)
    Table({"wavelength": lam_um * u.um, "flux": COUNTS}).write(tmp_path / "p.ecsv")
    x, y = _profile(tmp_path / "p.ecsv")
    np.testing.assert_allclose(x, np.sort((lam_um - np.median(lam_um)) * DISPERSION), atol=1e-9)
    np.testing.assert_array_equal(y, COUNTS[::-1])
    g = np.arange(5.0)
    X, Y = np.meshgrid(g, g)
    Table({"x": X.ravel() * u.mm, "y": Y.ravel() * u.mm, "height": 10.0 * X.ravel() * u.nm}).write(
        tmp_path / "m.txt", format="ascii.ecsv")
    m = ic.read_sag_map(tmp_path / "m.txt")
    np.testing.assert_allclose(m.sag_um, 0.01 * X)
    Table({"x": X.ravel(), "y": Y.ravel(), "height": X.ravel()}).write(tmp_path / "n.txt", format="ascii.ecsv")
    with pytest.raises(ValueError, match=r"n\.txt, line 8: missing column\(s\) \['x_mm', 'y_mm', 'sag_um'\].*'x' has no unit.*"
                                         r"'height' has no unit"):
        ic.read_sag_map(tmp_path / "n.txt")


def test_a_tab_table_with_commas_in_its_names(tmp_path):
    f = _text(tmp_path / "p.tsv", "Offset [um]\tIntensity, counts\tcomment, note",
              [(a, b, "ok") for a, b in _rows()], delimiter="\t")
    x, y = _profile(f)
    np.testing.assert_array_equal(y, COUNTS)


@pytest.mark.parametrize("marker", ["", "NA", "-", "n/a", "null"])
def test_a_bad_pixel_marker_is_a_masked_sample(tmp_path, marker):
    rows = _rows()
    rows[3] = (rows[3][0], marker)
    x, y = _profile(_text(tmp_path / "p.csv", "offset_um,intensity", rows))
    np.testing.assert_array_equal(x, np.delete(OFFSET_UM, 3))
    np.testing.assert_array_equal(y, np.delete(COUNTS, 3))


def test_fortran_exponents_trailing_delimiters_and_comments(tmp_path):
    rows = [(f"{a:.3E}".replace("E", "D"), f"{b:.4E}".replace("E", "D") + ",") for a, b in zip(OFFSET_UM, COUNTS)]
    rows[2] = (rows[2][0], rows[2][1] + "   # hot pixel?")
    x, y = _profile(_text(tmp_path / "p.csv", "Offset / µm,Intensity / ADU", rows))
    np.testing.assert_allclose(x, OFFSET_UM)
    np.testing.assert_allclose(y, COUNTS)


@pytest.mark.parametrize("header", ["Offset [pixels]", "pixels"])
def test_offsets_in_pixels_spelled_out(tmp_path, header):
    x, _ = _profile(_text(tmp_path / "p.csv", f"{header},counts", _rows()))
    np.testing.assert_allclose(x, 18.0 * OFFSET_UM)


def test_a_windows_code_page_header(tmp_path):
    # "µ" is byte 0xB5 in Windows-1252 and Latin-1, not UTF-8
    x, y = _profile(_text(tmp_path / "p.csv", "Offset [µm];Intensity", [(a, b) for a, b in _rows()],
                          delimiter=";", encoding="cp1252"))
    np.testing.assert_array_equal(x, OFFSET_UM)
    np.testing.assert_array_equal(y, COUNTS)


def test_an_image_in_detector_pixels(tmp_path):
    X, Y = np.meshgrid(np.arange(-3.0, 3.01), np.arange(-3.0, 3.01))
    counts = 20.0 + 500.0 * np.exp(-0.5 * (X**2 + Y**2))
    f = _text(tmp_path / "img.csv", "X [px],Y [px],Counts",
              [tuple(repr(float(q)) for q in r) for r in zip(X.ravel(), Y.ravel(), counts.ravel())])
    x, y, v = ic.read_measured("psf image", f, pixel_um=18.0)
    np.testing.assert_array_equal(x, 18.0 * X.ravel())
    np.testing.assert_array_equal(y, 18.0 * Y.ravel())
    np.testing.assert_array_equal(v, counts.ravel())
    with pytest.raises(ValueError, match=r"img\.csv: offsets in detector pixels \(column 'x_px'\) need pixel_um"):
        ic.read_measured("psf image", f)


@pytest.mark.parametrize("names,units", [("Offset,Intensity", "(um),(counts)"), ("offset,intensity", "um,counts"),
                                         ("offset_um,intensity", "[um],[ADU]")])
def test_units_in_a_second_header_line(tmp_path, names, units):
    # a spreadsheet's export: the names on one line, their units under them
    x, y = _profile(_text(tmp_path / "p.csv", f"{names}\n{units}", _rows()))
    np.testing.assert_array_equal(x, OFFSET_UM)
    np.testing.assert_array_equal(y, COUNTS)


def test_a_european_spreadsheet_map_with_its_units_under_the_names(tmp_path):
    """pandas' two-row header (names, then units) in a European locale's export: BOM, ';',
    CRLF, decimal commas; the units row is told from the data by the decimal commas."""
    import pandas as pd

    g = np.arange(-10.0, 10.01, 0.5)
    X, Y = np.meshgrid(g, g)
    S_nm = np.round(300.0 * np.cos(2 * np.pi * X / 21.0) + 10.0 * Y, 3)
    df = pd.DataFrame({"X": X.ravel(), "Y": Y.ravel(), "Z": S_nm.ravel()})
    df.columns = pd.MultiIndex.from_tuples([("X", "mm"), ("Y", "mm"), ("Z", "nm")])
    df.to_csv(tmp_path / "m.csv", sep=";", decimal=",", index=False, encoding="utf-8-sig", lineterminator="\r\n")
    m = ic.read_sag_map(tmp_path / "m.csv")
    np.testing.assert_allclose(m.x_mm, g)
    np.testing.assert_allclose(m.sag_um, S_nm * 1e-3, atol=1e-12)


def test_a_map_saved_as_a_matrix_is_refused_naming_what_it_lacks(tmp_path):
    # np.savetxt of sag[y, x] (MATLAB's writematrix alike): no coordinates, no unit
    np.savetxt(tmp_path / "m.csv", np.zeros((20, 30)), delimiter=",")
    with pytest.raises(ValueError, match=r"m\.csv, line 1: no header line, and 30 numbers on the row: a matrix of "
                                         r"values .* is not read; write the sag CSV as a table with a header line "
                                         r"x_mm,y_mm,sag_um, or as a FITS image"):
        ic.read_sag_map(tmp_path / "m.csv")


@pytest.mark.parametrize("suffix", [".nc", ".xlsx"])
def test_a_binary_file_given_as_a_profile_is_named_binary(tmp_path, suffix):
    import xarray as xr

    f = tmp_path / f"p{suffix}"
    if suffix == ".nc":
        xr.Dataset({"intensity": (("offset_um",), COUNTS)}, coords={"offset_um": OFFSET_UM}).to_netcdf(f)
        kind = r"HDF5 or NetCDF-4"
    else:  # an .xlsx workbook is a zip archive
        import zipfile

        with zipfile.ZipFile(f, "w") as z:
            z.writestr("xl/workbook.xml", "<workbook/>")
        kind = r"a zip archive: an Excel \.xlsx workbook"
    with pytest.raises(ValueError, match=rf"line profile .*p\{suffix}: is a binary file \({kind}.*\), not a text "
                                         r"table; save it as delimited text \(CSV\)"):
        _profile(f)


@pytest.mark.parametrize("comments", ["line centre,dark subtracted", ","])
def test_an_origin_export_with_names_units_and_comments_lines(tmp_path, comments):
    # OriginLab's ASCII export: long names, units, then a comments line (empty or not)
    x, y = _profile(_text(tmp_path / "p.csv", f"Offset,Intensity\num,counts\n{comments}", _rows()))
    np.testing.assert_array_equal(x, OFFSET_UM)
    np.testing.assert_array_equal(y, COUNTS)
    # a second line of words that are not units is no units line: the names stay without one
    with pytest.raises(ValueError, match=r"missing column\(s\) \['offset_um'\]; found header \['offset', 'intensity'\]"):
        _profile(_text(tmp_path / "q.csv", "Offset,Intensity\nfrom centre,dark\nline centre,dark subtracted",
                       _rows()))


def test_a_cut_out_keeps_its_detector_pixel_numbers(tmp_path):
    # a unitless WCS of step one is pixel numbers, wherever it starts
    x, _ = _profile(_spectrum(tmp_path / "cut.fits", CRVAL1=1024.0, CDELT1=1.0, CRPIX1=1.0))
    np.testing.assert_allclose(x, 18.0 * np.arange(1024, 1033))


# ------------------------------------------------------------------ another FE solver's displacements
def _fe_block(tmp_path):
    import meshio

    pts = np.array([[x, y, z] for z in (0.0, 10.0) for y in (0.0, 5.0) for x in (0.0, 5.0)])
    meshio.write(tmp_path / "b.vtu", meshio.Mesh(pts, [("hexahedron", np.array([[0, 1, 3, 2, 4, 5, 7, 6]]))]))
    u = np.column_stack([np.zeros(8), 1e-3 * np.arange(8), 2e-3 * np.arange(8) - 0.005])
    return tmp_path / "b.vtu", u


@pytest.mark.parametrize("header,sep,columns", [
    ("Node Label,U-Magnitude,U-U1,U-U2,U-U3", ",", lambda i, u: [i, np.linalg.norm(u), *u]),  # Abaqus report
    ("node_id,x,y,z,ux,uy,uz", ",", lambda i, u: [i, 1.0, 2.0, 3.0, *u]),
    ("node_id;uz;uy;ux", ";", lambda i, u: [i, *u[::-1]]),
    ("NODE UX UY UZ", " ", lambda i, u: [i, *u])])
def test_fe_displacement_columns_are_read_by_their_names(tmp_path, header, sep, columns):
    from pipeline.io.fe import read_fe_result

    mesh, u = _fe_block(tmp_path)
    rows = [sep.join(repr(float(v)) if k else str(v) for k, v in enumerate(columns(i + 1, u[i]))) for i in range(8)]
    (tmp_path / "u.csv").write_text(header + "\n" + "\n".join(rows[::-1]) + "\n")
    r = read_fe_result(mesh, displacement_csv=tmp_path / "u.csv")
    np.testing.assert_allclose(r.displacement_mm, u, atol=1e-15)


def test_fe_displacements_without_a_header_or_with_a_node_twice_are_refused(tmp_path):
    from pipeline.io.fe import read_fe_result

    mesh, u = _fe_block(tmp_path)
    (tmp_path / "u5.csv").write_text("\n".join(f"{i + 1},1.0,{u[i, 0]},{u[i, 1]},{u[i, 2]}" for i in range(8)))
    with pytest.raises(ValueError, match=r"u5\.csv:1: 5 values and no header line; .*exactly node_id,ux,uy,uz"):
        read_fe_result(mesh, displacement_csv=tmp_path / "u5.csv")
    rows = [f"{i + 1},{u[i, 0]},{u[i, 1]},{u[i, 2]}" for i in range(8)] + ["3,0,0,0"]
    (tmp_path / "dup.csv").write_text("node_id,ux,uy,uz\n" + "\n".join(rows))
    with pytest.raises(ValueError, match=r"dup\.csv: node 3 is listed twice \(lines 4 and 10\)"):
        read_fe_result(mesh, displacement_csv=tmp_path / "dup.csv")


# ------------------------------------------------------------------ manifests
def test_a_grating_named_in_lower_case_is_one_blank_with_its_profiles(tmp_path):
    from pipeline.diagnosis.manifest import parse_manifest

    (tmp_path / "m.csv").write_text("x_mm,y_mm,sag_um\n0,0,0\n1,0,0\n0,1,0\n1,1,0\n")
    (tmp_path / "p.csv").write_text("offset_um,intensity\n" + "\n".join(f"{a},{b}" for a, b in _rows()) + "\n")
    surface = {"kind": "surface", "file": "m.csv", "temperature_K": 128, "grating": "j"}
    profile = {"kind": "line_profile", "file": "p.csv", "grating": "J", "wavelength_um": 1.25, "pixel_scale_mas": 250}
    man = parse_manifest({"measurement": [surface, profile]}, tmp_path)
    assert [(m.grating, m.blank) for m in man.measurements] == [("J", "J"), ("J", "J")]
    assert parse_manifest({"measurement": [{**surface, "grating": None, "blank": "h+k"}]},
                          tmp_path).measurements[0].blank == "HK"
    with pytest.raises(ValueError, match=r"measurement 'm'.*grating.*'X'.*is unknown; valid: \['H', 'HK', 'J', 'K'\]"):
        parse_manifest({"measurement": [{**surface, "grating": "X"}]}, tmp_path)


# ------------------------------------------------------------------ Zemax files with a writer's comments
def test_zemax_files_with_a_comment_line_and_a_float_term_count(tmp_path):
    from pipeline.io.zemax import read_zemax_zernike

    sag_mm = np.arange(30.0).reshape(6, 5) * 1e-4  # rows along y, unitflag 0: mm
    rows = [f"{v:.6e} 0 0 0 0" for v in sag_mm.ravel()]
    (tmp_path / "g.dat").write_text("! Grid sag written by MATLAB\n5 6 0.5 0.5 0 0 0\n" + "\n".join(rows) + "\n")
    m = ic.read_sag_map(tmp_path / "g.dat")
    np.testing.assert_allclose(m.x_mm, [-1.0, -0.5, 0.0, 0.5, 1.0])
    np.testing.assert_allclose(np.sort(m.sag_um.ravel()), np.sort(sag_mm.ravel() * 1e3), atol=1e-9)
    (tmp_path / "z.dat").write_text("! Zernike Fringe Sag extra data\n9.000000E+000\n6.250000E+001\n"
                                    + "\n".join(f"{c:.6E}" for c in np.arange(1, 10) * 1e-5) + "\n")
    coeffs, info = read_zemax_zernike(tmp_path / "z.dat", "fringe", False)
    assert info["n_terms"] == 9 and info["radius_mm"] == 62.5
    np.testing.assert_allclose(sorted(coeffs.values()), np.arange(1, 10) * 1e-2)  # mm -> µm


@pytest.mark.parametrize("data,message", [
    ({"simulation": [{"cold_K": 80}]}, r"\[simulation\] is a list .*not a table.*not \[\[simulation\]\]"),
    ({"simulation": "x"}, r"\[simulation\] is a str .*not a table"),
    ({"measurement": [{"kind": "surface", "file": ["a.csv"]}]}, r"#1: file=\['a\.csv'\] must be one path, a string"),
])
def test_a_manifest_of_the_wrong_shape_is_named(data, message):
    from pipeline.diagnosis.manifest import parse_manifest

    with pytest.raises(ValueError, match=message):
        parse_manifest({"measurement": [{"kind": "surface", "file": "m.csv"}], **data})


def test_a_model_in_inches_keeps_its_face_edge(tmp_path):
    # the face's edge at 20 mm is 0.787401574803... in: back in mm it misses the grid's edge line by round-off
    import meshio

    from pipeline.io.fe import import_fe

    g = np.array([-20.0, 0.0, 20.0])
    pts = np.array([[x, y, z] for z in (0.0, 10.0) for y in g for x in g]) * (1 / 25.4)  # as a converter writes it
    idx = np.arange(18).reshape(2, 3, 3)  # [z, y, x]
    hexes = [[idx[0, j, i], idx[0, j, i + 1], idx[0, j + 1, i + 1], idx[0, j + 1, i]]
             for j in range(2) for i in range(2)]
    hexes = [h + [v + 9 for v in h] for h in hexes]  # the top face's nodes are the bottom's + 9
    u = np.zeros_like(pts)
    u[:, 2] = 1e-4 * (pts[:, 0] * 25.4) ** 2 / 25.4  # 0.1 µm/mm² of x², in inches
    meshio.write(tmp_path / "in.vtu", meshio.Mesh(pts, [("hexahedron", np.array(hexes))], point_data={"U": u}))
    m = import_fe(tmp_path / "in.vtu", f"z={float(pts[:, 2].max())!r}", length_unit="in", spacing_mm=5.0).sag_map
    np.testing.assert_allclose(m.x_mm, np.arange(-20.0, 20.01, 5.0), atol=1e-9)
    assert np.isfinite(m.sag_um).all()


def test_a_grid_coarser_than_the_face_names_the_spacing_and_the_unit(tmp_path):
    from pipeline.io.fe import import_fe

    mesh, _ = _fe_block(tmp_path)  # a 5 x 5 mm face
    with pytest.raises(ValueError, match=r"spacing_mm=100 leaves fewer than two grid lines across the face, which "
                                         r"spans 5 x 5 mm.*length unit"):
        import_fe(_with_displacement(mesh), "z=10", spacing_mm=100.0)


def _with_displacement(path):
    import meshio

    m = meshio.read(path)
    m.point_data["U"] = np.zeros_like(m.points)
    out = path.with_name("u_" + path.name)
    meshio.write(out, m)
    return out


def test_a_wavefront_file_in_a_manifest_takes_its_factor(tmp_path):
    from pipeline.diagnosis.manifest import load_data, parse_manifest

    counts = np.arange(400).reshape(20, 20) - 200  # OPD = counts / SSZ * WVL
    (tmp_path / "w.int").write_text("interferometer export\nGRD 20 20 WFR WVL 0.6328 SSZ 1000 NDA 32767\n"
                                    + "\n".join(" ".join(str(c) for c in row) for row in counts) + "\n")
    entry = {"kind": "surface", "file": "w.int", "temperature_K": 128, "spacing_mm": 5.0}
    with pytest.raises(ValueError, match=r"WFR is a wavefront .*pass wfr_to_sag_factor"):
        load_data(parse_manifest({"measurement": [entry]}, tmp_path))
    (sd,) = load_data(parse_manifest({"measurement": [{**entry, "wfr_to_sag_factor": -0.5}]}, tmp_path))
    np.testing.assert_allclose(np.sort(sd.sagmap.sag_um.ravel()), np.sort(-0.5 * counts.ravel() / 1000 * 0.6328))
    with pytest.raises(ValueError, match=r"wfr_to_sag_factor.*0.*must be a finite non-zero number"):
        parse_manifest({"measurement": [{**entry, "wfr_to_sag_factor": 0}]}, tmp_path)


def test_a_codev_grid_option_that_contradicts_the_files_title_is_refused(tmp_path):
    counts = np.arange(25).reshape(5, 5)
    (tmp_path / "m.int").write_text("map EXTENT_MM -8 8 -8 8\nGRD 5 5 SUR WVL 1.0 SSZ 1000 NDA 32767\n"
                                    + "\n".join(" ".join(str(c) for c in row) for row in counts) + "\n")
    assert ic.read_sag_map(tmp_path / "m.int", spacing_mm=4.0).x_mm[1] == pytest.approx(-4.0)  # agrees
    with pytest.raises(ValueError, match=r"m\.int: the title's 'EXTENT_MM -8 8 -8 8' gives a 4 x 4 mm step but the "
                                         r"spacing_mm argument, centred gives 2 x 2 mm"):
        ic.read_sag_map(tmp_path / "m.int", spacing_mm=2.0)


def test_a_codev_wavelength_in_nanometres_is_refused(tmp_path):
    (tmp_path / "m.int").write_text("GRD 3 3 SUR WVL 632.8 SSZ 1000 NDA 32767\n1 2 3 4 5 6 7 8 9\n")
    with pytest.raises(ValueError, match=r"m\.int, line 1: WVL 632\.8 is outside 0\.1\.\.30: the wavelength is in µm"):
        ic.read_sag_map(tmp_path / "m.int", spacing_mm=1.0)


def test_an_xdmf_time_series_gives_its_last_step(tmp_path, monkeypatch):
    # dolfinx's write_function and meshio's TimeSeriesWriter write one grid per step
    pytest.importorskip("h5py")
    import meshio

    from pipeline.io.fe import read_fe_result

    path, u = _fe_block(tmp_path)
    mesh = meshio.read(path)
    monkeypatch.chdir(tmp_path)  # the writer puts its .h5 beside the working directory
    with meshio.xdmf.TimeSeriesWriter(tmp_path / "ts.xdmf") as w:
        w.write_points_cells(mesh.points, mesh.cells)
        w.write_data(0.0, point_data={"u": 0.0 * u})
        w.write_data(1.0, point_data={"u": u})
    monkeypatch.chdir("/")
    r = read_fe_result(tmp_path / "ts.xdmf")
    np.testing.assert_allclose(r.displacement_mm, u)  # the last step's, not the first's zeros


# ------------------------------------------------------------------ what the project writes for other programs
def test_a_label_from_another_file_keeps_the_headers_ascii(tmp_path):
    from optics.sagmap import SagMap

    m = SagMap(np.arange(4.0), np.arange(3.0), np.ones((3, 4)), "Δsag µm 20 K\nsecond line " + "x" * 80)
    ic.write_sag_map(m, tmp_path / "m.int")
    title = (tmp_path / "m.int").read_bytes().split(b"\n")[0]
    assert len(title) <= 80 and title.isascii() and title.startswith(b"dsag um 20 K second line")
    ic.write_sag_map(m, tmp_path / "m.fits")  # astropy refuses a non-ASCII or multi-line card
    from astropy.io import fits

    assert fits.getheader(tmp_path / "m.fits")["OBJECT"].startswith("dsag um 20 K second line")


def test_a_netcdf_map_says_cf_and_its_coordinates_have_no_fill_value(tmp_path):
    import netCDF4

    from optics.sagmap import SagMap

    sag = np.ones((3, 4))
    sag[1, 1] = np.nan
    ic.write_sag_map(SagMap(np.arange(4.0), np.arange(3.0), sag, "m"), tmp_path / "m.nc")
    with netCDF4.Dataset(tmp_path / "m.nc") as ds:
        assert ds.Conventions == "CF-1.8"
        assert "_FillValue" not in ds["x_mm"].ncattrs() and ds["x_mm"].axis == "X" and ds["x_mm"].units == "mm"
        assert np.isnan(ds["sag_um"]._FillValue) and ds["sag_um"].units == "um"


def test_fe_displacements_under_four_names_of_their_own_are_read_in_order(tmp_path):
    from pipeline.io.fe import read_fe_result

    mesh, u = _fe_block(tmp_path)
    rows = [f"{i + 1},{u[i, 0]:.17g},{u[i, 1]:.17g},{u[i, 2]:.17g}" for i in range(8)]
    (tmp_path / "u.csv").write_text("n,dx_mm,dy_mm,dz_mm\n" + "\n".join(rows) + "\n")
    np.testing.assert_allclose(read_fe_result(mesh, displacement_csv=tmp_path / "u.csv").displacement_mm, u)
    (tmp_path / "u6.csv").write_text("n,a,b,c,d,e\n" + "\n".join(r + ",0,0" for r in rows) + "\n")
    with pytest.raises(ValueError, match=r"u6\.csv:1: header .* has no column for \['node_id', 'ux', 'uy', 'uz'\]"):
        read_fe_result(mesh, displacement_csv=tmp_path / "u6.csv")
