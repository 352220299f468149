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


def test_a_cut_out_keeps_its_detector_pixel_numbers(tmp_path):
    # a unitless WCS of step one is pixel numbers, wherever it starts
    x, _ = _profile(_spectrum(tmp_path / "cut.fits", CRVAL1=1024.0, CDELT1=1.0, CRPIX1=1.0))
    np.testing.assert_allclose(x, 18.0 * np.arange(1024, 1033))
