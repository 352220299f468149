"""Zygo interferometer maps come in: MetroPro ASCII written by prysm (another code), and
MetroPro ASCII and binary files written here byte by byte from the MetroPro Reference
Guide's layout, not with the reader's code. Expected heights come from the format's rule
``counts * S * O * wavelength / R``; orientation from "rows from the top of the frame"."""

from __future__ import annotations

import struct

import numpy as np
import pytest

from pipeline.io import registry as ic
from pipeline.io.zygo import INVALID_COUNTS, is_zygo_dat

PITCH_MM = 0.5


def _truth_um(ny=41, nx=51):
    """A masked interferogram (rows from the top, as stored): a tilt that rises towards the
    top of the frame and the right, and a bump in the top-right quarter; NaN outside a disc."""
    r, c = np.mgrid[0:ny, 0:nx]
    up, right = (ny - 1 - r) * PITCH_MM, c * PITCH_MM
    h = 0.02 * up / 10 + 0.01 * right / 10 + np.where((r < ny // 2 - 2) & (c > nx // 2 + 2), 0.1, 0.0)
    disc = (r - (ny - 1) / 2) ** 2 + (c - (nx - 1) / 2) ** 2 <= (0.45 * min(nx, ny)) ** 2
    return np.where(disc, h, np.nan)


def _check_map(m, truth_rows_from_top, tol_um):
    ny, nx = truth_rows_from_top.shape
    assert m.sag_um.shape == (ny, nx)
    np.testing.assert_allclose(np.diff(m.x_mm), PITCH_MM, rtol=1e-6)
    np.testing.assert_allclose(np.diff(m.y_mm), PITCH_MM, rtol=1e-6)
    expected = truth_rows_from_top[::-1]  # y increasing
    np.testing.assert_array_equal(np.isnan(m.sag_um), np.isnan(expected))
    assert np.nanmax(np.abs(m.sag_um - expected)) <= tol_um
    # orientation: the bump is where x > 0 and y > 0, the tilt rises with y
    X, Y = m.grid()
    with np.errstate(invalid="ignore"):
        bump = (m.sag_um - (0.002 * (Y - Y.min()) + 0.001 * (X - X.min()))) > 0.05
    assert (X[bump] > 0).all() and (Y[bump] > 0).all()
    # centred on the valid pixels (the disc)
    valid = m.mask
    assert abs(0.5 * (X[valid].min() + X[valid].max())) < 1e-9
    assert abs(0.5 * (Y[valid].min() + Y[valid].max())) < 1e-9


def test_a_metropro_ascii_file_written_by_prysm_reads_back(tmp_path):
    """prysm 0.21's ``write_zygo_ascii`` divides the phase by the wavelength twice and writes
    ``dx * 1e3`` as the camera resolution in m: with a 1 µm wavelength the first is exact,
    and ``dx`` is given so that the resolution written is the 0.5 mm pitch."""
    io = pytest.importorskip("prysm.io")
    truth = _truth_um()
    path = tmp_path / "prysm.asc"
    io.write_zygo_ascii(str(path), truth.copy(), dx=PITCH_MM * 1e-6, wavelength=1.0)
    m = ic.read_sag_map(path)
    assert m.meta["format"] == "zygo-ascii" and m.meta["wavelength_um"] == pytest.approx(1.0)
    # counts are truncated to integers at 2 * 32768 counts per µm
    _check_map(m, truth, tol_um=1.0 / 65536 + 1e-12)


def _ascii_file(counts_rows_from_top, *, phase_res=2, scale=0.5, obliquity=1.0, wavelength_m=632.8e-9,
                res_m=PITCH_MM * 1e-3, sign=0, intensity_buckets=2, newline="\r\n"):
    """A MetroPro ASCII file from the Reference Guide's layout, with an intensity block."""
    ph, pw = counts_rows_from_top.shape
    iw, ih = (pw, ph) if intensity_buckets else (0, 0)
    head = [
        "Zygo ASCII Data File - Format 2",
        '0 8 11 2 "Tue Nov 24 10:00:00 2026      "',
        f"0 0 {iw} {ih} {intensity_buckets} 65535",
        f"12 7 {pw} {ph}",
        '"a grating at 80 K"', '"SN 1"', '"part 1"',
        f"0 {scale} {wavelength_m} 0 {obliquity} 1 {res_m} 1795000000",
        f'{pw} {ph} 0 0 0 0 "obj"',
        "0 0 0 0 0 0 0 0 0 0",
        f"{phase_res} 1 20 2 0 0 0 {sign} 0",
        '0 ""', "1 0", '""',
    ]
    out = newline.join(head) + newline
    if intensity_buckets:
        inten = np.arange(intensity_buckets * iw * ih) % 4000
        out += newline.join(" ".join(map(str, inten[i:i + 10])) for i in range(0, inten.size, 10)) + newline
    out += "#" + newline
    flat = counts_rows_from_top.ravel()
    out += newline.join(" ".join(map(str, flat[i:i + 10])) for i in range(0, flat.size, 10)) + newline
    out += "#" + newline
    return out


def _counts(truth_um, wavelength_m, scale, obliquity, R):
    c = np.round(truth_um * 1e-6 * R / (scale * obliquity * wavelength_m))
    return np.where(np.isnan(truth_um), INVALID_COUNTS + 3, c).astype(np.int64)


@pytest.mark.parametrize("phase_res, R, sign", [(2, 131072, 0), (1, 32768, 1), (0, 4096, 0)])
def test_a_metropro_ascii_file_with_intensity_crlf_and_data_sign(tmp_path, phase_res, R, sign):
    truth = _truth_um()
    wl, S, O = 632.8e-9, 0.5, 1.02
    counts = _counts(truth if sign == 0 else -truth, wl, S, O, R)
    path = tmp_path / "m.asc"
    path.write_bytes(_ascii_file(counts, phase_res=phase_res, scale=S, obliquity=O, wavelength_m=wl,
                                 sign=sign).encode())
    m = ic.read_sag_map(path)
    step_um = S * O * wl / R * 1e6
    _check_map(m, truth, tol_um=0.5 * step_um + 1e-12)
    assert m.meta["data_sign"] == sign and m.meta["phase_res"] == phase_res


def test_an_ascii_file_without_lateral_scale_needs_spacing_mm(tmp_path):
    truth = _truth_um()
    path = tmp_path / "m.asc"
    path.write_text(_ascii_file(_counts(truth, 632.8e-9, 0.5, 1.0, 131072), res_m=0.0, intensity_buckets=0,
                                newline="\n"))
    with pytest.raises(ValueError, match="no lateral scale.*pass spacing_mm"):
        ic.read_sag_map(path)
    m = ic.read_sag_map(path, spacing_mm=PITCH_MM)
    _check_map(m, truth, tol_um=0.5 * 0.5 * 632.8e-9 / 131072 * 1e6 + 1e-12)
    with pytest.raises(ValueError, match="spacing_mm=-1.0 must be a finite number of mm > 0"):
        ic.read_sag_map(path, spacing_mm=-1.0)


def test_bad_ascii_files_are_refused_with_the_line(tmp_path):
    truth = _truth_um(11, 13)
    good = _ascii_file(_counts(truth, 632.8e-9, 0.5, 1.0, 131072), intensity_buckets=0, newline="\n")
    lines = good.split("\n")
    cases = {
        "header": ("\n".join(["Zemax Grid Sag"] + lines[1:]), r"line 1: expected 'Zygo ASCII Data File"),
        "short": ("\n".join(lines[:6]), "ends inside its 14-line header"),
        "scale": ("\n".join(lines[:7] + ["0 0.5 x 0 1 1 0.0005 1"] + lines[8:]), r"line 8: WavelengthIn='x'"),
        "count": (good.replace("#\n", "#\n1 2 3\n#\n", 1), r"phase block holds 3 values; .* = 143 expected"),
        "width": ("\n".join(lines[:3] + ["12 7 inf 11"] + lines[4:]), r"line 4: PhaseWidth='inf' must be an integer"),
        "zero S": ("\n".join(lines[:7] + ["0 0 6.328e-07 0 1 1 0.0005 1"] + lines[8:]), "IntfScaleFactor=0.0 must be > 0"),
    }
    for name, (text, match) in cases.items():
        p = tmp_path / f"{name}.asc"
        p.write_text(text)
        with pytest.raises(ValueError, match=match):
            ic.read_sag_map(p)
    allbad = tmp_path / "allbad.asc"
    allbad.write_text(_ascii_file(np.full((5, 6), INVALID_COUNTS), intensity_buckets=0, newline="\n"))
    with pytest.raises(ValueError, match="every pixel of the phase map is marked invalid"):
        ic.read_sag_map(allbad)


def _metropro_dat(counts_rows_from_top, *, scale=0.5, obliquity=1.0, wavelength_m=632.8e-9, res_m=PITCH_MM * 1e-3,
                  phase_res=2, sign=0, header_format=3, header_size=4096):
    """A MetroPro binary file (header format 3) from the Reference Guide's byte offsets:
    big-endian header fields, no intensity frame, the phase counts as big-endian int32."""
    ph, pw = counts_rows_from_top.shape
    h = bytearray(header_size)

    def put(offset, fmt, value):
        struct.pack_into(fmt, h, offset, value)

    put(0, ">I", {1: 0x881B036F, 2: 0x881B0370, 3: 0x881B0371}[header_format])
    put(4, ">H", header_format)
    put(6, ">I", header_size)
    put(42, ">H", 9)  # MetroPro 9.1.0
    put(44, ">H", 1)
    put(64, ">H", 0)
    put(66, ">H", 0)
    put(68, ">H", pw)
    put(70, ">H", ph)
    put(72, ">I", 4 * pw * ph)
    put(164, ">f", scale)
    put(168, ">f", wavelength_m)
    put(176, ">f", obliquity)
    put(180, ">f", 1.0)
    put(184, ">f", res_m)
    put(218, ">H", phase_res)
    put(232, ">H", sign)
    put(234, ">H", pw)
    put(236, ">H", ph)
    return bytes(h) + counts_rows_from_top.astype(">i4").tobytes()


def test_a_metropro_binary_file_is_read_and_told_from_a_zemax_grid_sag(tmp_path):
    pytest.importorskip("prysm.io")
    truth = _truth_um()
    wl, S, O, R = 632.8e-9, 0.5, 1.0, 131072
    path = tmp_path / "zygo.dat"
    path.write_bytes(_metropro_dat(_counts(truth, wl, S, O, R), sign=0))
    assert is_zygo_dat(path)
    m = ic.read_sag_map(path)
    assert m.meta["format"] == "zygo-dat"
    _check_map(m, truth, tol_um=0.5 * S * O * wl / R * 1e6 + 1e-12)
    inverted = tmp_path / "inverted.dat"
    inverted.write_bytes(_metropro_dat(_counts(-truth, wl, S, O, R), sign=1))
    np.testing.assert_allclose(ic.read_sag_map(inverted).sag_um, m.sag_um, atol=S * O * wl / R * 1e6)
    # a Zemax Grid Sag .dat beside it is still read as one
    zemax = ic.write_sag_map(m, tmp_path / "zemax.dat")
    assert not is_zygo_dat(zemax)
    back = ic.read_sag_map(zemax)
    np.testing.assert_allclose(back.sag_um, m.sag_um, atol=1e-9, equal_nan=True)


def test_a_cut_metropro_binary_file_is_refused_with_the_sizes(tmp_path):
    pytest.importorskip("prysm.io")
    raw = _metropro_dat(_counts(_truth_um(), 632.8e-9, 0.5, 1.0, 131072))
    path = tmp_path / "cut.dat"
    path.write_bytes(raw[:-100])
    with pytest.raises(ValueError, match=r"cut.dat: \d+ bytes; a 51 x 41 phase map .* needs \d+ \(truncated\)"):
        ic.read_sag_map(path)


def test_zygo_binary_files_without_prysm_name_the_extra(tmp_path, monkeypatch):
    import sys

    path = tmp_path / "zygo.dat"
    path.write_bytes(_metropro_dat(_counts(_truth_um(), 632.8e-9, 0.5, 1.0, 131072)))
    monkeypatch.setitem(sys.modules, "prysm", None)
    with pytest.raises(ValueError, match=r"needs prysm \(pip install 'cryograting\[zygo\]'\)"):
        ic.read_sag_map(path)


def test_zygo_maps_are_read_only_formats_of_the_registry(tmp_path):
    assert {".asc", ".datx"} <= set(ic.SAG_READERS)
    m = ic.read_sag_map(_write(tmp_path / "m.asc"))
    with pytest.raises(ValueError, match=r"'\.asc' files are read, not written"):
        ic.write_sag_map(m, tmp_path / "out.asc")


def _write(path):
    path.write_text(_ascii_file(_counts(_truth_um(), 632.8e-9, 0.5, 1.0, 131072), intensity_buckets=0,
                                newline="\n"))
    return path


def test_a_diagnosis_manifest_takes_a_zygo_map_with_its_pixel_pitch(tmp_path):
    """A 140 mm aperture measured at 2 mm per pixel, exported without a lateral scale: the
    manifest's ``spacing_mm`` reaches the reader and the points inside the aperture are the data."""
    from pipeline.diagnosis.manifest import load_data, parse_manifest

    n = 71
    r, c = np.mgrid[0:n, 0:n]
    x, y = (c - 35) * 2.0, (35 - r) * 2.0
    truth = 0.05 * np.cos(2 * np.pi * x / 21.0) + 0.01 * y / 70
    truth = np.where(np.hypot(x, y) <= 70.0, truth, np.nan)
    path = tmp_path / "cold.asc"
    path.write_text(_ascii_file(_counts(truth, 632.8e-9, 0.5, 1.0, 131072), res_m=0.0, intensity_buckets=0,
                                newline="\n"))
    entry = {"kind": "surface", "file": str(path), "temperature_K": 80}
    with pytest.raises(ValueError, match=r"measurement 'cold'.*no lateral scale.*spacing_mm"):
        load_data(parse_manifest({"measurement": [entry]}))
    (s,) = load_data(parse_manifest({"measurement": [{**entry, "spacing_mm": 2.0}]}))
    expected = 0.05 * np.cos(2 * np.pi * s.x_mm / 21.0) + 0.01 * s.y_mm / 70
    np.testing.assert_allclose(s.sag_um, expected, atol=0.5 * 0.5 * 632.8e-9 / 131072 * 1e6 + 1e-12)
    assert s.x_mm.size == np.sum(np.hypot(x, y) <= 68.5)


def test_a_zygo_datx_file_is_read(tmp_path):
    """An Mx ``.datx`` written here with h5py in Zygo's layout (``Data/Surface/<frame>`` in
    fringes with its scale factors, ``Attributes/<frame>`` with the lateral resolution)."""
    h5py = pytest.importorskip("h5py")
    truth = _truth_um()
    wl, S, O = 632.8e-9, 0.5, 1.0
    fringes = truth * 1e-6 / (S * O * wl)
    no_data = 1.7976931348623157e308
    path = tmp_path / "cold.datx"
    with h5py.File(path, "w") as f:
        d = f.create_dataset("Data/Surface/{ABCD-0001}", data=np.where(np.isnan(fringes), no_data, fringes))
        d.attrs["No Data"] = np.array([no_data])
        d.attrs["Wavelength"] = np.array([wl])
        d.attrs["Unit"] = np.array([b"Fringes"], dtype=object)
        d.attrs["Interferometric Scale Factor"] = np.array([S])
        d.attrs["Obliquity Factor"] = np.array([O])
        a = f.create_group("Attributes/{ABCD-0001}")
        a.attrs["Data Context.Lateral Resolution:Value"] = np.array([PITCH_MM * 1e-3])
        a.attrs["Data Context.Lateral Resolution:Unit"] = np.array([b"Meters"], dtype=object)
    m = ic.read_sag_map(path)
    assert m.meta["format"] == "zygo-datx"
    _check_map(m, truth, tol_um=1e-9)


def _converter(res_m):
    """An Mx ``X/Y Converter`` attribute: category, base unit, parameters (1: m per pixel)."""
    dt = np.dtype([("Category", "S16"), ("BaseUnit", "S16"), ("Parameters", "<f8", (4,))])
    return np.array([(b"LateralCat", b"Meters", [0.0, res_m, 0.0, 0.0])], dtype=dt)


@pytest.mark.parametrize("layout", ["um_converter_only", "nx2_measurement_nm_nan", "angstrom_float32"])
def test_datx_files_in_other_units_and_layouts_are_read(tmp_path, layout):
    """``.datx`` files as Mx and older exports write them besides fringes: heights in µm with
    the lateral scale only in the surface's ``X Converter`` (no ``Attributes`` group); the
    older ``Measurement/Surface`` layout in nm with NaN holes; float32 Ångström with the
    float32 maximum as ``No Data``. Each must give the truth within float rounding."""
    h5py = pytest.importorskip("h5py")
    truth = _truth_um()
    path = tmp_path / f"{layout}.datx"
    with h5py.File(path, "w") as f:
        if layout == "um_converter_only":
            no_data = 1.7976931348623157e308
            d = f.create_dataset("Data/Surface/{F-1}", data=np.where(np.isnan(truth), no_data, truth))
            d.attrs["Unit"] = np.array([b"MicroMeters"], dtype=object)
            d.attrs["No Data"] = np.array([no_data])
            d.attrs["X Converter"] = d.attrs["Y Converter"] = _converter(PITCH_MM * 1e-3)
        elif layout == "nx2_measurement_nm_nan":
            d = f.create_dataset("Measurement/Surface", data=truth * 1e3)
            d.attrs["Unit"] = np.array([b"NanoMeters"], dtype=object)
            d.attrs["No Data"] = np.array([np.nan])
            d.attrs["X Converter"] = _converter(PITCH_MM * 1e-3)
        else:
            no_data = np.finfo(np.float32).max
            d = f.create_dataset("Data/Surface/{F-2}",
                                 data=np.where(np.isnan(truth), no_data, truth * 1e4).astype(np.float32))
            d.attrs["Unit"] = np.array([b"Angstroms"], dtype=object)
            d.attrs["No Data"] = np.array([no_data], dtype=np.float32)
            a = f.create_group("Attributes/{F-2}")
            a.attrs["Data Context.Lateral Resolution:Value"] = np.array([PITCH_MM * 1e-3])
    m = ic.read_sag_map(path)
    # float32 keeps 24 bits: a relative rounding of 6e-8
    _check_map(m, truth, tol_um=2e-7 * np.nanmax(np.abs(truth)) if layout == "angstrom_float32" else 1e-9)


def test_datx_refusals_name_what_is_wrong(tmp_path):
    """An unknown height unit names the valid ones; no lateral scale asks for ``spacing_mm``
    (and is read with it); a file that is not HDF5 says so — never an h5py traceback."""
    h5py = pytest.importorskip("h5py")
    truth = _truth_um()
    with h5py.File(tmp_path / "inch.datx", "w") as f:
        d = f.create_dataset("Data/Surface/{F}", data=np.nan_to_num(truth))
        d.attrs["Unit"] = np.array([b"Inches"], dtype=object)
    with pytest.raises(ValueError, match=r"Unit='Inches'.*valid are \['Fringes', 'NanoMeters', 'MicroMeters'"):
        ic.read_sag_map(tmp_path / "inch.datx")
    with h5py.File(tmp_path / "noscale.datx", "w") as f:
        d = f.create_dataset("Data/Surface/{F}", data=truth * 1e3)
        d.attrs["Unit"] = np.array([b"NanoMeters"], dtype=object)
    with pytest.raises(ValueError, match="no lateral scale.*spacing_mm"):
        ic.read_sag_map(tmp_path / "noscale.datx")
    assert ic.read_sag_map(tmp_path / "noscale.datx", spacing_mm=PITCH_MM).meta["spacing_mm"] == PITCH_MM
    with h5py.File(tmp_path / "badres.datx", "w") as f:
        d = f.create_dataset("Data/Surface/{F}", data=truth * 1e3)
        d.attrs["Unit"] = np.array([b"NanoMeters"], dtype=object)
        f.create_group("Attributes/{F}").attrs["Data Context.Lateral Resolution:Value"] = np.array([b"n/a"],
                                                                                                  dtype=object)
    with pytest.raises(ValueError, match=r"Lateral Resolution:Value=.*n/a.*not a lateral resolution.*spacing_mm"):
        ic.read_sag_map(tmp_path / "badres.datx")
    assert ic.read_sag_map(tmp_path / "badres.datx", spacing_mm=PITCH_MM).meta["spacing_mm"] == PITCH_MM
    (tmp_path / "text.datx").write_text("x,y,z\n")
    with pytest.raises(ValueError, match="not an HDF5 file"):
        ic.read_sag_map(tmp_path / "text.datx")


def test_prysm_datx_reader_takes_neither_micrometres_nor_a_file_without_attributes(tmp_path):
    """Why the ``.datx`` reader is ours: prysm's refuses heights in µm and needs the
    ``Attributes`` group (an Mx user may pick the unit; MetroPro's export has no such group)."""
    h5py = pytest.importorskip("h5py")
    prysm_io = pytest.importorskip("prysm.io")
    truth = np.nan_to_num(_truth_um())
    for name, unit, with_attrs in (("um", b"MicroMeters", True), ("noattrs", b"NanoMeters", False)):
        with h5py.File(tmp_path / f"{name}.datx", "w") as f:
            d = f.create_dataset("Data/Surface/{F}", data=truth)
            d.attrs.update({"Unit": np.array([unit], dtype=object), "No Data": np.array([1e308]),
                            "Wavelength": np.array([632.8e-9]), "Interferometric Scale Factor": np.array([0.5]),
                            "Obliquity Factor": np.array([1.0])})
            if with_attrs:
                f.create_group("Attributes/{F}").attrs["Data Context.Lateral Resolution:Value"] = np.array([5e-4])
        with pytest.raises((ValueError, KeyError)):
            prysm_io.read_zygo_datx(tmp_path / f"{name}.datx")
        assert ic.read_sag_map(tmp_path / f"{name}.datx", spacing_mm=PITCH_MM).sag_um.shape == truth.shape


def test_cli_convert_turns_an_interferogram_into_a_codev_int_and_refuses_what_it_cannot_read(tmp_path, capsys):
    from pipeline.cli import main

    truth = _truth_um()
    src = tmp_path / "cold.asc"
    src.write_text(_ascii_file(_counts(truth, 632.8e-9, 0.5, 1.0, 131072), res_m=0.0, intensity_buckets=0,
                               newline="\n"))
    assert main(["convert", str(src), str(tmp_path / "cold.int"), "--spacing-mm", str(PITCH_MM)]) == 0
    out = capsys.readouterr().out
    assert "zygo-ascii" in out and "51 x 41 samples at 0.5 x 0.5 mm" in out
    back = ic.read_sag_map(tmp_path / "cold.int")
    step = np.nanmax(np.abs(truth)) / 32766  # the INT file's 16-bit step
    _check_map(back, truth, tol_um=1.01 * step + 0.5 * 0.5 * 632.8e-9 / 131072 * 1e6)
    assert main(["convert", str(src), str(tmp_path / "cold.nc")]) == 2
    assert "no lateral scale" in capsys.readouterr().err


def test_cli_fit_gives_the_zernike_and_quilt_terms_put_into_a_measured_map(tmp_path, capsys):
    """A Zygo export of known Fringe Zernike terms (unnormalised: Z5 = rho^2 cos 2theta,
    Z9 = 6 rho^4 - 6 rho^2 + 1) plus a quilt: the fit returns the values put in."""
    from pipeline.cli import main

    n, pitch = 121, 1.0
    r, c = np.mgrid[0:n, 0:n]
    x, y = (c - 60) * pitch, (60 - r) * pitch
    R = 60.0
    rho2, cos2t = (x**2 + y**2) / R**2, np.where(x**2 + y**2 > 0, (x**2 - y**2) / np.maximum(x**2 + y**2, 1e-300), 1)
    truth = 0.08 * rho2 * cos2t + 0.03 * (6 * rho2**2 - 6 * rho2 + 1)
    truth = np.where(rho2 <= 1.0, truth, np.nan)
    src = tmp_path / "m.asc"
    src.write_text(_ascii_file(_counts(truth, 632.8e-9, 0.5, 1.0, 131072), res_m=pitch * 1e-3, intensity_buckets=0,
                               newline="\n"))
    out = tmp_path / "z.csv"
    assert main(["fit", str(src), "--basis", "zernike-fringe:16", "--out", str(out)]) == 0
    table = {row.split(",")[0]: float(row.split(",")[1]) for row in out.read_text().splitlines()[1:]}
    assert table["Z5 (n=2 m=2)"] == pytest.approx(0.08, abs=2e-4)
    assert table["Z9 (n=4 m=0)"] == pytest.approx(0.03, abs=2e-4)
    assert abs(table["Z4 (n=2 m=0)"]) < 2e-4 and abs(table["Z6 (n=2 m=-2)"]) < 2e-4
    assert "captured" in capsys.readouterr().out
    for bad, msg in (("legendre:5", "unknown basis 'legendre'"), ("zernike-noll:0", "integer in [1, 231]")):
        assert main(["fit", str(src), "--basis", bad]) == 2
        assert msg in capsys.readouterr().err
    quilt = tmp_path / "q.asc"
    q = np.where(rho2 <= 1.0, 0.05 * np.cos(2 * np.pi * x / 21.0) + 0.02 * np.cos(2 * np.pi * y / 18.0), np.nan)
    quilt.write_text(_ascii_file(_counts(q, 632.8e-9, 0.5, 1.0, 131072), res_m=pitch * 1e-3, intensity_buckets=0,
                                 newline="\n"))
    assert main(["fit", str(quilt), "--basis", "fourier:2", "--out", str(out)]) == 0
    table = {row.split(",")[0]: float(row.split(",")[1]) for row in out.read_text().splitlines()[1:]}
    assert table["i=1 j=0"] == pytest.approx(0.05, abs=1e-5) and table["i=0 j=1"] == pytest.approx(0.02, abs=1e-5)
    assert abs(table["i=1 j=1"]) < 1e-5 and abs(table["i=2 j=0"]) < 1e-5
