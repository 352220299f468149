"""FITS inputs as other software writes them: files built here with astropy alone and
headers the way detector pipelines, IRAF-style tools and ESO data products spell them;
expected values come from the FITS WCS definitions (world = CRVAL + (p - CRPIX) CDELT,
1-based p), not from the project's writer."""

from __future__ import annotations

import numpy as np
import pytest

fits = pytest.importorskip("astropy.io.fits")

from pipeline.io.fits import read_line_profile_fits, read_psf_image_fits, read_sag_fits, write_sag_fits  # noqa: E402
from pipeline.io.gridding import GridUnknownError  # noqa: E402
from pipeline.io.registry import read_measured, read_sag_map, write_sag_map  # noqa: E402

DISPERSION = -2.0e3  # detector µm per µm of wavelength (signed, as the SPIFFI orders)


def _line(n=81, rng=None):
    rng = rng or np.random.default_rng(3)
    i = np.arange(n)
    return 500.0 + 4000.0 * np.exp(-0.5 * ((i - 43.3) / 3.0) ** 2) + rng.normal(0, 5.0, n)


def _write(path, *hdus):
    fits.HDUList(list(hdus)).writeto(path)
    return path


def test_wavelength_spectrum_in_counts_with_bscale(tmp_path):
    counts = _line()
    h = fits.Header()
    h["CTYPE1"], h["CUNIT1"], h["CRVAL1"], h["CRPIX1"], h["CDELT1"] = "WAVE", "Angstrom", 12500.0, 40.5, 0.25
    hdu = fits.PrimaryHDU(np.round(counts).astype(np.int16), header=h)
    hdu.scale("int16", bscale=1.0, bzero=1000.0)  # stored as int16 - 1000, read back by astropy
    p = _write(tmp_path / "arc.fits", hdu)
    x, y = read_line_profile_fits(p, normalise=False, dispersion_um_per_um=DISPERSION)
    wl_um = (12500.0 + (np.arange(1, 82) - 40.5) * 0.25) * 1e-4
    expect = np.sort((wl_um - np.median(wl_um)) * DISPERSION)
    np.testing.assert_allclose(x, expect, atol=1e-9)
    # negative dispersion reverses the order of the samples on the detector
    np.testing.assert_allclose(y, np.round(counts)[::-1])


def test_linear_ctype_in_nm_is_a_wavelength_and_cd_matrix_is_read(tmp_path):
    h = fits.Header()
    h["CTYPE1"], h["CUNIT1"], h["CRVAL1"], h["CRPIX1"], h["CD1_1"] = "LINEAR", "nm", 1250.0, 1.0, 0.02
    p = _write(tmp_path / "s.fits", fits.PrimaryHDU(_line(), header=h))
    x, _ = read_line_profile_fits(p, normalise=False, dispersion_um_per_um=DISPERSION)
    assert np.ptp(x) == pytest.approx(80 * 0.02e-3 * abs(DISPERSION))


def test_wave_axis_without_cunit_is_in_metres(tmp_path):
    """FITS WCS paper III: the default unit of a WAVE axis is the metre."""
    h = fits.Header([("CTYPE1", "WAVE"), ("CRVAL1", 1.25e-6), ("CRPIX1", 41.0), ("CDELT1", 2e-11)])
    p = _write(tmp_path / "w.fits", fits.PrimaryHDU(_line(), header=h))
    x, _ = read_line_profile_fits(p, normalise=False, dispersion_um_per_um=DISPERSION)
    assert np.ptp(x) == pytest.approx(80 * 2e-5 * abs(DISPERSION))


def test_pixel_axis_without_wcs_needs_the_pixel_pitch(tmp_path):
    p = _write(tmp_path / "px.fits", fits.PrimaryHDU(_line()))
    with pytest.raises(ValueError, match="pixel_um"):
        read_line_profile_fits(p)
    x, _ = read_line_profile_fits(p, pixel_um=18.0)
    np.testing.assert_allclose(x, 18.0 * np.arange(1, 82))


def test_one_row_extraction_with_an_offset_axis_in_um_and_masked_samples(tmp_path):
    y = _line()
    y[10] = np.nan  # a bad pixel: masked, not an error
    h = fits.Header()
    h["CTYPE1"], h["CUNIT1"], h["CRVAL1"], h["CRPIX1"], h["CDELT1"] = "OFFSET", "um", -360.0, 1.0, 9.0
    p = _write(tmp_path / "row.fits", fits.PrimaryHDU(y[None, :], header=h))
    x, v = read_line_profile_fits(p, normalise=False)
    assert x.size == 80 and -360.0 + 9.0 * 10 not in x
    np.testing.assert_allclose(x[:10], -360.0 + 9.0 * np.arange(10))


def test_eso_style_table_of_one_row_of_arrays(tmp_path):
    wl_nm = 1245.0 + 0.1 * np.arange(81)
    col_w = fits.Column(name="WAVE", format="81D", unit="nm", array=wl_nm[None, :])
    col_f = fits.Column(name="FLUX", format="81D", unit="adu", array=_line()[None, :])
    table = fits.BinTableHDU.from_columns([col_w, col_f])
    p = _write(tmp_path / "sdp.fits", fits.PrimaryHDU(), table)
    x, y = read_line_profile_fits(p, normalise=False, dispersion_um_per_um=DISPERSION)
    np.testing.assert_allclose(np.sort(x), np.sort((wl_nm - np.median(wl_nm)) * 1e-3 * DISPERSION), atol=1e-9)
    assert y.sum() == pytest.approx(_line().sum())


def test_table_of_rows_with_unit_in_the_column_name(tmp_path):
    off_mm = np.linspace(-0.4, 0.4, 81)
    table = fits.BinTableHDU.from_columns([fits.Column(name="offset_mm", format="D", array=off_mm),
                                           fits.Column(name="counts", format="D", array=_line())])
    p = _write(tmp_path / "t.fits", fits.PrimaryHDU(), table)
    x, _ = read_line_profile_fits(p, normalise=False)
    np.testing.assert_allclose(x, off_mm * 1e3)


def test_detector_cut_out_is_summed_along_the_slit(tmp_path):
    rng = np.random.default_rng(5)
    rows = np.exp(-0.5 * ((np.arange(20) - 9.5) / 4.0) ** 2)  # the slit's illumination
    frame = rows[:, None] * _line()[None, :] + rng.normal(0, 2.0, (20, 81))
    frame[4, 30] = np.nan  # a bad pixel: its column is scaled up from the 19 valid ones
    h = fits.Header([("CTYPE1", "WAVE"), ("CUNIT1", "nm"), ("CRVAL1", 1250.0), ("CRPIX1", 41.0), ("CDELT1", 0.02)])
    p = _write(tmp_path / "frame.fits", fits.PrimaryHDU(frame, header=h))
    x, y = read_line_profile_fits(p, normalise=False, dispersion_um_per_um=DISPERSION)
    expect = np.nansum(frame, axis=0)
    expect[30] *= 20 / 19
    np.testing.assert_allclose(y, expect[::-1])  # negative dispersion: reversed on the detector
    assert x.size == 81


def test_background_subtracted_profile_is_data(tmp_path):
    y = _line() - 560.0  # negative noise on both sides of the line
    assert (y < 0).sum() > 20
    p = _write(tmp_path / "bs.fits", fits.PrimaryHDU(y))
    x, v = read_line_profile_fits(p, pixel_um=18.0)
    assert np.trapezoid(v, x) == pytest.approx(1.0)


@pytest.mark.parametrize("make,match", [
    (lambda: fits.PrimaryHDU(_line(), header=fits.Header([("CTYPE1", "FREQ"), ("CUNIT1", "Hz"),
                                                          ("CRVAL1", 2.4e14), ("CDELT1", 1e9)])), "FREQ"),
    (lambda: fits.PrimaryHDU(np.ones((5, 6, 7))), "no 1-D or 2-D image"),
    (lambda: fits.PrimaryHDU(_line(), header=fits.Header([("CTYPE1", "LINEAR"), ("CRVAL1", 4.097),
                                                          ("CDELT1", 1e-5), ("DC-FLAG", 1)])), "log-linear"),
])
def test_profiles_refused_by_name(tmp_path, make, match):
    p = _write(tmp_path / "bad.fits", make())
    with pytest.raises(ValueError, match=match):
        read_line_profile_fits(p, pixel_um=18.0, dispersion_um_per_um=DISPERSION)


def test_table_wavelength_without_unit_is_refused(tmp_path):
    table = fits.BinTableHDU.from_columns([fits.Column(name="WAVE", format="D", array=np.linspace(1.2, 1.3, 81)),
                                           fits.Column(name="FLUX", format="D", array=_line())])
    p = _write(tmp_path / "t.fits", fits.PrimaryHDU(), table)
    with pytest.raises(ValueError, match="no unit"):
        read_line_profile_fits(p, dispersion_um_per_um=DISPERSION)


def test_not_a_fits_file_is_named(tmp_path):
    p = tmp_path / "x.fits"
    p.write_text("offset_um,intensity\n")
    with pytest.raises(ValueError, match="not a readable FITS file"):
        read_line_profile_fits(p)


def _map_header(cdelt1_m=5e-4, cdelt2_m=-5e-4, crpix=(1.0, 1.0), crval_m=(-0.01, 0.0075)):
    h = fits.Header()
    h["BUNIT"] = "nm"
    for i, (d, p, v) in enumerate(zip((cdelt1_m, cdelt2_m), crpix, crval_m), start=1):
        h[f"CTYPE{i}"], h[f"CUNIT{i}"], h[f"CDELT{i}"], h[f"CRPIX{i}"], h[f"CRVAL{i}"] = "LINEAR", "m", d, p, v
    return h


def test_interferometer_map_in_nm_with_blank_and_descending_y(tmp_path):
    ny, nx = 31, 41
    yy, xx = np.mgrid[0:ny, 0:nx]
    sag_nm = 100.0 * np.sin(xx / 5.0) + 3.0 * yy
    raw = np.round(sag_nm / 0.5).astype(np.int32)  # stored in half-nm counts
    raw[0, 0] = -999999
    hdu = fits.PrimaryHDU(raw, header=_map_header())
    hdu.header["BSCALE"], hdu.header["BLANK"] = 0.5, -999999
    p = _write(tmp_path / "cold.fits", hdu)
    m = read_sag_map(p)
    # x: -10 mm + 0.5 mm steps; y given descending from +7.5 mm, flipped to ascending
    np.testing.assert_allclose(m.x_mm, -10.0 + 0.5 * np.arange(nx))
    np.testing.assert_allclose(m.y_mm, 7.5 - 0.5 * np.arange(ny)[::-1])
    expect_um = (raw * 0.5 * 1e-3)[::-1].astype(float)
    expect_um[-1, 0] = np.nan
    np.testing.assert_allclose(m.sag_um, expect_um, atol=1e-12)
    assert m.meta["source_units"] == "nm"


def test_map_in_pixels_needs_a_grid_option(tmp_path):
    h = fits.Header([("BUNIT", "um")])
    p = _write(tmp_path / "px.fits", fits.PrimaryHDU(np.zeros((11, 21)), header=h))
    with pytest.raises(GridUnknownError, match="pixels"):
        read_sag_fits(p)
    m = read_sag_map(p, spacing_mm=0.5)
    np.testing.assert_allclose(m.x_mm, 0.5 * np.arange(21) - 5.0)


@pytest.mark.parametrize("edit,match", [
    (lambda h: h.remove("BUNIT"), "BUNIT"),
    (lambda h: h.update(BUNIT="kelvin"), "BUNIT"),
    (lambda h: h.update(PC1_2=0.1, PC2_1=-0.1), "rotated"),
    (lambda h: h.update(CUNIT1="deg"), "not a length"),
])
def test_maps_refused_by_name(tmp_path, edit, match):
    h = _map_header()
    edit(h)
    p = _write(tmp_path / "bad.fits", fits.PrimaryHDU(np.zeros((11, 21)), header=h))
    with pytest.raises(ValueError, match=match):
        read_sag_fits(p)


def test_grid_options_beside_a_wcs_are_refused(tmp_path):
    p = _write(tmp_path / "m.fits", fits.PrimaryHDU(np.zeros((11, 21)), header=_map_header()))
    with pytest.raises(ValueError, match="already gives the grid"):
        read_sag_fits(p, spacing_mm=0.5)


def test_written_map_reads_back_exactly(tmp_path):
    from optics.sagmap import SagMap

    x, y = np.linspace(-20, 20, 41), np.linspace(-15, 15, 31)
    z = np.cos(x[None, :] / 3.0) * np.sin(y[:, None] / 4.0)
    z[3, 4] = np.nan
    sm = SagMap(x, y, z, "t", {})
    p = write_sag_map(sm, tmp_path / "m.fits")
    back = read_sag_map(p)
    np.testing.assert_allclose(back.x_mm, x, rtol=0, atol=1e-12)
    np.testing.assert_allclose(back.y_mm, y, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(np.isnan(back.sag_um), np.isnan(z))
    np.testing.assert_array_equal(back.sag_um[~np.isnan(z)], z[~np.isnan(z)])
    assert fits.getheader(p)["BUNIT"] == "um"  # readable by other FITS software as a labelled image
    assert write_sag_fits  # the registry's writer for .fits


def test_psf_image_frame_in_pixels_and_in_um(tmp_path):
    yy, xx = np.mgrid[0:15, 0:17]
    img = 100.0 + 1e4 * np.exp(-((xx - 8.2) ** 2 + (yy - 7.1) ** 2) / 4.0)
    img[2, 3] = np.nan
    p = _write(tmp_path / "psf.fits", fits.PrimaryHDU(img))
    with pytest.raises(ValueError, match="pixel_um"):
        read_psf_image_fits(p)
    x, y, v = read_psf_image_fits(p, pixel_um=18.0)
    assert x.size == img.size - 1
    assert set(np.unique(x)) == set(18.0 * np.arange(1, 18))
    h = fits.Header()
    for i in (1, 2):
        h[f"CUNIT{i}"], h[f"CDELT{i}"], h[f"CRPIX{i}"], h[f"CRVAL{i}"] = "um", 2.0, 1.0, -16.0
    p2 = _write(tmp_path / "psf_um.fits", fits.PrimaryHDU(img, header=h))
    x2, y2, v2 = read_psf_image_fits(p2)
    np.testing.assert_allclose(np.unique(y2), -16.0 + 2.0 * np.arange(15))
    assert v2.sum() == pytest.approx(np.nansum(img))


def test_registry_reads_measured_files_by_suffix(tmp_path):
    p = tmp_path / "prof.txt"  # whitespace table under a suffix no format claims
    u = np.linspace(-100, 100, 41)
    p.write_text("offset_um intensity\n" + "\n".join(f"{a} {np.exp(-a * a / 800):.6f}" for a in u) + "\n")
    x, _ = read_measured("line profile", p, normalise=False, pixel_um=18.0, dispersion_um_per_um=DISPERSION)
    np.testing.assert_allclose(x, u)
    f = _write(tmp_path / "prof.fits", fits.PrimaryHDU(_line()))
    x, _ = read_measured("line profile", f, pixel_um=18.0, dispersion_um_per_um=DISPERSION)
    assert x.size == 81
    with pytest.raises(ValueError, match="kind"):
        read_measured("sag map", f)


def test_manifest_reads_fits_profile_like_its_csv(tmp_path):
    """A FITS spectrum and the CSV of the same samples give the diagnosis the same data."""
    from pipeline.diagnosis.manifest import load_data, load_manifest
    from pipeline.io.measured import write_line_profile_csv

    y = _line()
    h = fits.Header()
    h["CTYPE1"], h["CUNIT1"], h["CRVAL1"], h["CRPIX1"], h["CDELT1"] = "OFFSET", "um", -360.0, 1.0, 9.0
    _write(tmp_path / "p.fits", fits.PrimaryHDU(y, header=h))
    write_line_profile_csv(tmp_path / "p.csv", -360.0 + 9.0 * np.arange(81), y)
    text = ('[simulation]\nt0_um = 200\npolish = 0.75\n'
            + "".join(f'[[measurement]]\nkind = "line_profile"\nfile = "p.{s}"\nname = "{s}"\ngrating = "J"\n'
                      'order = -2\nwavelength_um = 1.25\npixel_scale_mas = 250\n' for s in ("fits", "csv")))
    (tmp_path / "m.toml").write_text(text)
    a, b = load_data(load_manifest(tmp_path / "m.toml"))
    np.testing.assert_allclose(a.offset_um, b.offset_um)
    np.testing.assert_allclose(a.intensity, b.intensity)
    assert a.origin_um == b.origin_um != 0.0


def test_manifest_reads_a_fits_psf_frame_at_its_pixel_pitch(tmp_path):
    """A detector frame in pixels is sampled at the manifest's ``pixel_um``; a focal-plane
    image (``pixel_um = 0``) has no pitch and must carry a WCS in µm."""
    from pipeline.diagnosis.manifest import load_data, load_manifest

    yy, xx = np.mgrid[0:21, 0:21]
    img = 10.0 + 1e4 * np.exp(-((xx - 10.0) ** 2 + (yy - 10.0) ** 2) / 3.0)
    _write(tmp_path / "psf.fits", fits.PrimaryHDU(img))
    for pix in (18, 0):
        (tmp_path / "m.toml").write_text(
            '[simulation]\nt0_um = 200\n[[measurement]]\nkind = "psf_image"\nfile = "psf.fits"\ngrating = "J"\n'
            f'order = -2\nwavelength_um = 1.25\npixel_um = {pix}\nnoise_rel = 0.01\n')
        if pix:
            (d,) = load_data(load_manifest(tmp_path / "m.toml"))
            assert np.ptp(d.x_um) == pytest.approx(20 * 18.0) and d.origin_um != (0.0, 0.0)
        else:
            with pytest.raises(ValueError, match=r"psf.fits.*in pixels.*WCS in µm"):
                load_data(load_manifest(tmp_path / "m.toml"))


def test_infinite_samples_are_refused_while_nan_ones_are_masked(tmp_path):
    """NaN is a masked pixel; an infinite one is a broken file, refused as in CSV tables."""
    y = _line()
    y[5] = np.inf
    p = _write(tmp_path / "inf.fits", fits.PrimaryHDU(y))
    with pytest.raises(ValueError, match="intensity finite or nan"):
        read_line_profile_fits(p, pixel_um=18.0)
    img = np.ones((11, 11))
    img[5, 5] = 100.0
    img[2, 2] = np.inf
    p = _write(tmp_path / "inf_img.fits", fits.PrimaryHDU(img))
    with pytest.raises(ValueError, match="intensity finite or nan"):
        read_psf_image_fits(p, pixel_um=18.0)


# A detector cut-out of a double-peaked line: 121 samples along a wavelength axis (1250 nm
# at the 61st pixel, 0.025 nm per pixel), 30 along the slit; the dispersion is chosen so a
# pixel is 3 µm on the detector and the two peaks lie 20 µm apart.
CUT_DISPERSION = -1.2e5  # detector µm per µm of wavelength
CUT_NOISE = 3.0  # counts RMS per pixel


def _cut_out():
    """(frame[slit, wavelength], offset_um of each wavelength column, noise-free summed line)."""
    rng = np.random.default_rng(11)
    wl_um = (1250.0 + (np.arange(121) - 60) * 0.025) * 1e-3
    offset_um = (wl_um - 1.25) * CUT_DISPERSION
    line = (1000.0 * np.exp(-0.5 * ((offset_um + 10.0) / 6.0) ** 2)
            + 800.0 * np.exp(-0.5 * ((offset_um - 10.0) / 6.0) ** 2))
    slit = np.exp(-0.5 * ((np.arange(30) - 14.5) / 6.0) ** 2)
    pedestal = 200.0
    frame = slit[:, None] * line[None, :] + pedestal + rng.normal(0.0, CUT_NOISE, (30, 121))
    return frame, offset_um, slit.sum() * line + 30 * pedestal


def _wave_keys(axis):
    return [(f"CTYPE{axis}", "WAVE"), (f"CUNIT{axis}", "nm"), (f"CRVAL{axis}", 1250.0), (f"CRPIX{axis}", 61.0),
            (f"CDELT{axis}", 0.025)]


def test_cut_out_dispersion_axis_is_taken_from_the_wcs_in_either_orientation(tmp_path):
    """The same cut-out written with the wavelength along NAXIS1 and, transposed, along
    NAXIS2 (a long slit dispersed along y) reads as one profile: the written frame summed
    along the slit, on the wavelength axis's offsets."""
    frame, offset_um, model = _cut_out()
    along_1 = _write(tmp_path / "cut.fits", fits.PrimaryHDU(frame, header=fits.Header(
        _wave_keys(1) + [("CTYPE2", "PIXEL"), ("CRVAL2", 1.0), ("CRPIX2", 1.0), ("CDELT2", 1.0)])))
    along_2 = _write(tmp_path / "cut_T.fits", fits.PrimaryHDU(frame.T.copy(), header=fits.Header(_wave_keys(2))))
    order = np.argsort(offset_um)  # the negative dispersion reverses the columns on the detector
    read = []
    for p in (along_1, along_2):
        x, y = read_measured("line profile", p, normalise=False, pixel_um=18.0, dispersion_um_per_um=CUT_DISPERSION)
        np.testing.assert_allclose(x, offset_um[order], rtol=0, atol=1e-9)
        np.testing.assert_allclose(y, frame.sum(axis=0)[order], rtol=1e-12)
        # the written line, within 5 sigma of the noise summed over the 30 slit pixels
        assert np.max(np.abs(y - model[order])) < 5 * CUT_NOISE * np.sqrt(30)
        read.append((x, y))
    np.testing.assert_array_equal(read[0][0], read[1][0])
    np.testing.assert_allclose(read[0][1], read[1][1], rtol=1e-12)
    # the two peaks where they were written: -10 µm, the taller, and +10 µm
    x, y = read[0]
    assert x[np.argmax(np.where(x < 0, y, 0))] == pytest.approx(-10.0, abs=3.0)
    assert x[np.argmax(np.where(x > 0, y, 0))] == pytest.approx(10.0, abs=3.0)


def test_cut_out_without_a_wcs_is_dispersed_along_naxis1(tmp_path):
    frame, _, _ = _cut_out()
    p = _write(tmp_path / "raw.fits", fits.PrimaryHDU(frame))
    x, y = read_measured("line profile", p, normalise=False, pixel_um=18.0)
    np.testing.assert_allclose(x, 18.0 * np.arange(1, 122))
    np.testing.assert_allclose(y, frame.sum(axis=0), rtol=1e-12)


@pytest.mark.parametrize("data,keys,match", [
    (np.ones((30, 121)), _wave_keys(1) + [("CTYPE2", "AWAV"), ("CUNIT2", "nm"), ("CRVAL2", 1250.0), ("CDELT2", 0.1)],
     r"amb\.fits: ambiguous dispersion axis: axes \[1, 2\] are all spectral \(CTYPE1='WAVE', CUNIT1='nm', "
     r"CTYPE2='AWAV', CUNIT2='nm'\); .*exactly one spectral axis"),
    (np.ones((30, 121)), [("CTYPE1", "LINEAR"), ("CUNIT1", "Angstrom"), ("CTYPE2", "WAVE"), ("CUNIT2", "um")],
     r"amb\.fits: ambiguous dispersion axis: .*CUNIT1='Angstrom'.*CTYPE2='WAVE'"),
    (np.ones((1, 121)), [("CTYPE1", "PIXEL"), ("CTYPE2", "WAVE"), ("CUNIT2", "nm"), ("CRVAL2", 1250.0)],
     r"amb\.fits: the spectral axis \(CTYPE2='WAVE', CUNIT2='nm'\) has a single pixel"),
], ids=["two_wave_ctypes", "nm_unit_and_wave_ctype", "spectral_axis_of_one_pixel"])
def test_cut_out_with_an_ambiguous_dispersion_axis_is_refused(tmp_path, data, keys, match):
    p = _write(tmp_path / "amb.fits", fits.PrimaryHDU(data, header=fits.Header(keys)))
    with pytest.raises(ValueError, match=match):
        read_measured("line profile", p, pixel_um=18.0, dispersion_um_per_um=CUT_DISPERSION)
