"""CODE V grid INT and ZFR decks, OpticStudio Zernike Sag lists: hand-written fixtures
(tests/data/, see README_interchange_fixtures.md) read against hand-worked values, 16-bit
write limits, quantisation bound, and refusals (files that would otherwise be misread)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from optics.sagmap import SagMap
from optics.zernike import wavefront_from_coefficients
from pipeline.io.codev import CODEV_NDA, MAX_COUNT, grating_wfr_to_sag_factor, read_codev_int, write_codev_int
from pipeline.io.codev_zfr import read_codev_zernike, write_codev_zernike
from pipeline.io.zemax import read_zemax_grid_sag, read_zemax_zernike, write_zemax_zernike
from pipeline.io.zernike import write_zernike_list

DATA = Path(__file__).parent / "data"


# ------------------------------------------------------------------ grid INT fixtures
def test_fixture_crlf_comments_nnb_xsc():
    m = read_codev_int(DATA / "codev_grid_crlf_nnb.int")
    q = 0.6328 / 2  # um per count: WVL / SSZ
    np.testing.assert_allclose(m.x_mm, [-3, -1, 1, 3])
    np.testing.assert_allclose(m.y_mm, [-1, 0, 1])
    np.testing.assert_allclose(m.sag_um[2], q * np.array([2, 4, 6, 8]))          # first file row = +y
    np.testing.assert_allclose(m.sag_um[1, [0, 2, 3]], q * np.array([-2, 0, 1]))
    assert np.isnan(m.sag_um[1, 1])                                               # the NDA 32767
    np.testing.assert_allclose(m.sag_um[0], q * np.array([-32767, -4, 10, 20]))   # -32767 is data
    assert m.meta["nnb"] is True and m.meta["xsc"] == 1.0 and m.meta["ysc"] == 1.0
    assert m.meta["codev_type"] == "SUR" and m.meta["nda_declared"] and m.meta["counts_16bit"]
    assert m.label.startswith("fixture 4x3 SUR")
    with pytest.raises(ValueError, match=r"wfr_to_sag_factor=-0.5 given but the data type is SUR"):
        read_codev_int(DATA / "codev_grid_crlf_nnb.int", wfr_to_sag_factor=-0.5)


def test_fixture_other_writer_nda_minus_32768():
    m = read_codev_int(DATA / "codev_grid_other_writer.int", spacing_mm=2.0)
    np.testing.assert_allclose(m.sag_um[2], [1, 2, 3])   # WVL 1, SSZ 1: one count = 1 um
    np.testing.assert_allclose(m.sag_um[1, 1:], [5, 6])
    assert np.isnan(m.sag_um[1, 0])
    np.testing.assert_allclose(m.sag_um[0], [7, 8, -9])
    np.testing.assert_allclose(m.x_mm, [-2, 0, 2])
    assert m.meta["nda"] == -32768


def test_fixture_wfr_without_nda():
    """No NDA: 32767 is no-data; WFR is a wavefront, read as sag only with a factor."""
    f = DATA / "codev_grid_wfr_no_nda.int"
    w = read_codev_int(f, extent_mm=(0, 2, 0, 1), quantity="wavefront")
    q = 0.55 / 2000
    np.testing.assert_allclose(w.sag_um[1, :2], q * np.array([1000, 2000]))
    assert np.isnan(w.sag_um[1, 2])
    np.testing.assert_allclose(w.sag_um[0], q * np.array([-1000, 0, 4000]))
    assert w.meta["nda"] == CODEV_NDA and not w.meta["nda_declared"]
    with pytest.raises(ValueError, match=r"codev_grid_wfr_no_nda\.int: data type WFR.*wfr_to_sag_factor"):
        read_codev_int(f, extent_mm=(0, 2, 0, 1))
    # a grating at alpha = 60 deg, beta = 0 deg: OPD = -(0.5 + 1) sag -> sag = -OPD / 1.5
    k = grating_wfr_to_sag_factor(60.0, 0.0)
    assert k == pytest.approx(-1 / 1.5)
    s = read_codev_int(f, extent_mm=(0, 2, 0, 1), wfr_to_sag_factor=k)
    np.testing.assert_allclose(s.sag_um[0], -q * np.array([-1000, 0, 4000]) / 1.5)


GRID_REFUSALS = [
    # no NDA: -32768 is outside the 16-bit data range and may be another writer's marker
    ("t EXTENT_MM 0 1 0 1\nGRD 2 2 SUR WVL 1 SSZ 1\n1 2\n-32768 4\n", r"line 4: count -32768 .*add 'NDA -32768'"),
    # no NDA and 32-bit counts: not a CODE V 16-bit file
    ("t EXTENT_MM 0 1 0 1\nGRD 2 2 SUR WVL 1 SSZ 1\n1 70000\n3 4\n", r"line 3: count 70000 is outside"),
    # NDA -32768 declared but a 32767 marker in a 16-bit file: ambiguous no-data
    ("t EXTENT_MM 0 1 0 1\nGRD 2 2 SUR WVL 1 SSZ 1 NDA -32768\n1 2\n32767 -32768\n", r"line 4: count 32767 is a 16-bit no-data marker"),
    ("t EXTENT_MM 0 1 0 1\nGRD 2 2 FIL WVL 1 SSZ 1\n1 2 3 4\n", r"line 2: unknown header keyword 'FIL'"),
    ("t EXTENT_MM 0 1 0 1\nGRD 2 2 SUR WVL nan SSZ 1\n1 2 3 4\n", r"line 2: WVL=nan must be a finite number"),
    ("t\nZFR 4 SUR WVL 1 SSZ 1\n1 2 3 4\n", r"line 2: INT type 'ZFR' is not a grid.*read_codev_zernike"),
    # no title line and so no EXTENT_MM: the grid keys are asked for
    ("GRD 2 2 SUR WVL 1 SSZ 1\n1 2\n3 4\n", r"spacing_mm.*extent_mm|extent_mm.*spacing_mm"),
]


def test_a_grid_without_its_title_line_is_read_with_the_grid_keys(tmp_path):
    """Some writers leave out CODE V's title line: the header is then the first line, and
    the grid's size comes from ``extent_mm`` (there is no title to carry it)."""
    f = tmp_path / "notitle.int"
    f.write_bytes(b"GRD 3 2 SUR WVL 0.5 SSZ 2 NDA -32767\r\n10 20 -32767\r\n-4 0 6\r\n")
    m = read_codev_int(f, extent_mm=(-1.0, 1.0, 0.0, 2.0))
    np.testing.assert_allclose(m.x_mm, [-1.0, 0.0, 1.0])
    np.testing.assert_allclose(m.y_mm, [0.0, 2.0])
    # the same values and holes as the same file with a title line
    ref = read_codev_int(_titled(f, tmp_path), extent_mm=(-1.0, 1.0, 0.0, 2.0))
    np.testing.assert_array_equal(np.isnan(m.sag_um), np.isnan(ref.sag_um))
    np.testing.assert_allclose(m.sag_um[np.isfinite(m.sag_um)], ref.sag_um[np.isfinite(ref.sag_um)])


def _titled(f, tmp_path):
    g = tmp_path / "titled.int"
    g.write_bytes(b"a title\r\n" + f.read_bytes())
    return g


def test_wide_legacy_file_with_nda_is_read(tmp_path):
    """An explicit NDA makes 32-bit counts unambiguous: read, and flagged."""
    f = tmp_path / "wide.int"
    f.write_text("t EXTENT_MM 0 1 0 1\nGRD 2 2 SUR WVL 0.5 SSZ 10 NDA -2147483647\n100000 32767\n-2147483647 -5\n")
    m = read_codev_int(f)
    np.testing.assert_allclose(m.sag_um[1], [5000.0, 32767 * 0.05])
    assert np.isnan(m.sag_um[0, 0]) and not m.meta["counts_16bit"]


# ------------------------------------------------------------------ grid INT writer
@pytest.fixture
def negative_map() -> SagMap:
    """Non-square, one-signed (all < 0), NaN holes, a corner feature."""
    rng = np.random.default_rng(11)
    x = np.linspace(-40.0, 40.0, 33)
    y = np.linspace(-10.0, 15.0, 11)
    X, Y = np.meshgrid(x, y)
    sag = -0.2 - 0.05 * rng.random(X.shape) - np.where((X < -20) & (Y > 5), 0.6, 0.0)
    sag[0, :4] = np.nan
    sag[5, 17] = np.nan
    return SagMap(x, y, sag, "negative! map")


@pytest.mark.parametrize("wavelength_um", [0.6328, 1.0, 2.2])
def test_writer_counts_16bit_and_quantisation_bound(tmp_path, negative_map, wavelength_um):
    path = write_codev_int(negative_map, tmp_path / "n.int", wavelength_um=wavelength_um)
    lines = path.read_text().splitlines()
    assert "!" not in lines[0] and all(len(s) <= 80 for s in lines)
    head = lines[1].split()
    ssz = float(head[head.index("SSZ") + 1])
    counts = np.array(" ".join(lines[2:]).split(), dtype=np.int64)
    data = counts[counts != CODEV_NDA]
    assert data.size == np.isfinite(negative_map.sag_um).sum()
    assert np.abs(data).max() <= MAX_COUNT < CODEV_NDA           # never the no-data value
    assert (data < 0).all()                                      # one-signed stays one-signed
    max_abs = np.nanmax(np.abs(negative_map.sag_um))
    step_um = wavelength_um / ssz
    assert step_um <= max_abs / 32766 * (1 + 1e-5)               # the 16-bit range is used
    back = read_codev_int(path)
    np.testing.assert_array_equal(np.isnan(back.sag_um), np.isnan(negative_map.sag_um))
    assert np.nanmax(np.abs(back.sag_um - negative_map.sag_um)) <= 0.5 * step_um * (1 + 1e-9)
    np.testing.assert_allclose(back.x_mm, negative_map.x_mm)
    np.testing.assert_allclose(back.y_mm, negative_map.y_mm)


def test_writer_explicit_ssz_checked(tmp_path, negative_map):
    path = write_codev_int(negative_map, tmp_path / "i.int", ssz=20000)  # integer SSZ on request
    assert path.read_text().splitlines()[1].split()[7] == "20000"
    with pytest.raises(ValueError, match=r"ssz=1e\+06 gives counts up to .* use ssz <="):
        write_codev_int(negative_map, tmp_path / "j.int", ssz=1e6)
    with pytest.raises(ValueError, match=r"kind='FIL'"):
        write_codev_int(negative_map, tmp_path / "k.int", kind="FIL")


# ------------------------------------------------------------------ ZFR decks
def test_zfr_fixture_against_hand_values():
    coeffs, info = read_codev_zernike(DATA / "codev_zfr9.int", normalised=False, radius_mm=25.0)
    assert info["codev_type"] == "SUR" and info["n_terms"] == 9 and info["ssz"] == 1.0
    w = 0.6328
    assert coeffs[(0, 0)] == pytest.approx(0.1 * w) and coeffs[(1, -1)] == pytest.approx(-0.3 * w)
    assert coeffs[(2, 0)] == pytest.approx(0.5 * w) and coeffs[(4, 0)] == pytest.approx(-0.05 * w)
    # the surface at hand-evaluated points (Fringe terms: Z2 = r cos t, Z3 = r sin t,
    # Z4 = 2r^2 - 1, Z9 = 6r^4 - 6r^2 + 1): rim on +x 0.75 waves, centre -0.45, rim on +y 0.25
    x, y = np.array([25.0, 0.0, 0.0]), np.array([0.0, 0.0, 25.0])
    np.testing.assert_allclose(wavefront_from_coefficients(coeffs, x, y, 25.0, norm=False),
                               w * np.array([0.75, -0.45, 0.25]), atol=1e-12)
    with pytest.raises(ValueError, match=r"wfr_to_sag_factor=2.0 given but the data type is SUR"):
        read_codev_zernike(DATA / "codev_zfr9.int", normalised=False, radius_mm=25.0, wfr_to_sag_factor=2.0)
    with pytest.raises(ValueError, match="no normalisation radius.*radius_mm"):
        read_codev_zernike(DATA / "codev_zfr9.int", normalised=False)


def test_zfr_round_trip_and_layout(tmp_path):
    c_norm = {(0, 0): 0.01, (1, 1): -0.2, (2, 0): 0.35, (2, -2): 0.05, (3, 1): -0.07, (4, 0): 0.02, (12, 0): 0.001}
    f = write_codev_zernike(c_norm, tmp_path / "z.int", radius_mm=62.5, coeffs_normalised=True, wavelength_um=1.0)
    lines = f.read_text().splitlines()
    assert lines[0].endswith("NRADIUS_MM 62.5") and lines[1] == "ZFR 37 SUR WVL 1 SSZ 1" and len(lines) == 39
    assert float(lines[2 + 3]) == pytest.approx(0.35 * np.sqrt(3))  # Z4, unnormalised, waves of 1 um
    back, info = read_codev_zernike(f, normalised=True)
    assert info["radius_mm"] == 62.5
    for k, v in c_norm.items():
        assert back[k] == pytest.approx(v, rel=1e-11)
    assert sum(abs(v) for k, v in back.items() if k not in c_norm) == 0.0


def test_zfr_refusals(tmp_path):
    with pytest.raises(ValueError, match=r"fringe term 4 \(n, m\)=\(2, 0\) is nan"):
        write_codev_zernike({(2, 0): float("nan")}, tmp_path / "a.int", 10.0, coeffs_normalised=False)
    with pytest.raises(ValueError, match=r"\(8, 8\).*not one of the 37 Fringe terms"):
        write_codev_zernike({(8, 8): 1.0}, tmp_path / "a.int", 10.0, coeffs_normalised=False)
    f = tmp_path / "b.int"
    f.write_text("deck\nZFR 3 SUR WVL 1 SSZ 1\n0.1\nnan\n0.3\n")
    with pytest.raises(ValueError, match=r"b\.int, line 4: Fringe Z2 \(1, 1\): coefficient 'nan'"):
        read_codev_zernike(f, normalised=False, radius_mm=1.0)
    f.write_text("deck\nZFR 3 WFR WVL 1 SSZ 1\n0.1\n0.2\n")
    with pytest.raises(ValueError, match=r"b\.int, line 4: ZFR 3 needs 3 coefficients, found 2"):
        read_codev_zernike(f, normalised=False, radius_mm=1.0)
    f.write_text("ZFR 2 SUR WVL 1 SSZ 1\n0.1\n0.2\n")  # no title line: the header is the first line
    c, _ = read_codev_zernike(f, normalised=False, radius_mm=1.0)
    assert c[(0, 0)] == pytest.approx(0.1 * 1.0) and c[(1, 1)] == pytest.approx(0.2 * 1.0)
    f.write_text("deck\nZFR 2 WFR WVL 1 SSZ 1\n0.1\n0.2\n")
    with pytest.raises(ValueError, match="WFR is a wavefront"):
        read_codev_zernike(f, normalised=False, radius_mm=1.0)
    c, _ = read_codev_zernike(f, normalised=False, radius_mm=1.0, wfr_to_sag_factor=-0.5)
    assert c[(1, 1)] == pytest.approx(-0.1)


ZFR_HEADER_REFUSALS = [
    ("deck\nZFR 2 SUR WVL 1 SSZ 1 ZOOM 2\n0.1\n0.2\n", r"line 2: unknown header keyword 'ZOOM'; valid are SUR, WFR"),
    ("deck\nZFR 2 SUR WVL 1 SSZ 0\n0.1\n0.2\n", r"line 2: SSZ=0\.0 must be a finite number > 0"),
    ("deck\nZFR 2 SUR WVL abc\n0.1\n0.2\n", r"line 2: WVL value 'abc' is not a number"),
    ("deck\nZFR 2 SUR WVL\n0.1\n0.2\n", r"line 2: keyword WVL has no value"),
    ("deck\nZFR 2 SUR SSZ 1\n0.1\n0.2\n", r"line 2: header has no WVL"),
    ("deck\nZFR 2 WVL 1\n0.1\n0.2\n", r"line 2: header has no data type"),
    ("deck\nZFR 2 SUR WFR WVL 1\n0.1\n0.2\n", r"line 2: two data types"),
    ("deck\nGRD 2 2 SUR WVL 1 SSZ 1\n1 2 3 4\n", r"line 2: header must start with 'ZFR <n>'.*read_codev_int"),
    ("deck ! only a title\n", r"line 1: file ends before the ZFR header line"),
]

#: reader name -> how a refusal test reads the file
INT_READERS = {"grid": read_codev_int, "zfr": lambda f: read_codev_zernike(f, normalised=False, radius_mm=1.0)}


@pytest.mark.parametrize("reader,text,pattern", [("grid", *r) for r in GRID_REFUSALS]
                         + [("zfr", *r) for r in ZFR_HEADER_REFUSALS])
def test_int_refusals_name_file_and_line(tmp_path, reader, text, pattern):
    f = tmp_path / "bad.int"
    f.write_text(text)
    with pytest.raises(ValueError, match=r"bad\.int, " + pattern):
        INT_READERS[reader](f)


def test_zernike_list_refuses_nan(tmp_path):
    with pytest.raises(ValueError, match=r"noll term 4 \(n, m\)=\(2, 0\) is inf"):
        write_zernike_list({(2, 0): float("inf")}, tmp_path / "l.txt", "noll", 10.0, coeffs_normalised=True)
    f = write_zernike_list({(2, 0): 1.0}, tmp_path / "l.txt", "noll", 10.0, coeffs_normalised=True)
    f.write_text(f.read_text().replace("4,2,0,1", "4,2,0,nan"))
    with pytest.raises(ValueError, match=r"l\.txt, line 7: noll term 4: coefficient 'nan'"):
        from pipeline.io.zernike import read_zernike_list
        read_zernike_list(f, normalised=True)


# ------------------------------------------------------------------ OpticStudio Zernike Sag lists
def test_zemax_standard_fixture():
    c, info = read_zemax_zernike(DATA / "zemax_zernike_standard.dat", "standard", normalised=True)
    assert info["surface_type"] == "Zernike Standard Sag" and info["n_terms"] == 5 and info["radius_mm"] == 25.0
    assert c[(1, 1)] == pytest.approx(1.0) and c[(2, 0)] == pytest.approx(0.5)   # Noll Z2, Z4; mm -> um
    # normalised terms: Z2 = 2 r cos t, Z4 = sqrt(3)(2r^2 - 1)
    x, y = np.array([25.0, 0.0]), np.array([0.0, 0.0])
    np.testing.assert_allclose(wavefront_from_coefficients(c, x, y, 25.0, norm=True),
                               [2.0 + 0.5 * np.sqrt(3), -0.5 * np.sqrt(3)], atol=1e-12)


def test_zemax_fringe_fixture_crlf():
    c, info = read_zemax_zernike(DATA / "zemax_zernike_fringe.dat", "fringe", normalised=False)
    assert info["surface_type"] == "Zernike Fringe Sag" and info["n_terms"] == 9
    x, y = np.array([25.0, 0.0]), np.array([0.0, 0.0])
    np.testing.assert_allclose(wavefront_from_coefficients(c, x, y, 25.0, norm=False), [0.7, -0.3], atol=1e-12)


@pytest.mark.parametrize("convention,first_terms", [("standard", [(0, 0), (1, 1), (1, -1), (2, 0)]),
                                                    ("fringe", [(0, 0), (1, 1), (1, -1), (2, 0)])])
def test_zemax_zernike_round_trip(tmp_path, convention, first_terms):
    c_norm = {(0, 0): 0.01, (1, 1): -0.2, (2, 0): 0.35, (2, 2): 0.05, (3, -1): -0.07, (4, 0): 0.02}
    f = write_zemax_zernike(c_norm, tmp_path / "z.dat", convention, radius_mm=41.0, coeffs_normalised=True)
    vals = [float(v) for v in f.read_text().split()]
    n_terms = 11 if convention == "standard" else 9      # Noll (4, 0) = Z11; Fringe (4, 0) = Z9
    assert vals[:2] == [n_terms, 41.0] and len(vals) == n_terms + 2
    # mm in the file; Standard keeps RMS-normalised values, Fringe is peak-normalised (x sqrt(3) for defocus)
    assert vals[2 + 3] == pytest.approx(0.35e-3 * (1 if convention == "standard" else np.sqrt(3)))
    back, info = read_zemax_zernike(f, convention, normalised=True)
    for k, v in c_norm.items():
        assert back[k] == pytest.approx(v, rel=1e-11)
    with pytest.raises(ValueError, match=r"one value per line.*read_zemax_zernike"):
        read_zemax_grid_sag(f)


def test_zemax_zernike_refusals(tmp_path):
    with pytest.raises(ValueError, match=r"term 6 \(n, m\)=\(2, 2\) is nan"):
        write_zemax_zernike({(2, 2): np.nan}, tmp_path / "a.dat", "standard", 10.0, coeffs_normalised=True)
    with pytest.raises(ValueError, match=r"\(6, 6\).*not one of the 37 Fringe terms"):
        write_zemax_zernike({(6, 6): 1.0}, tmp_path / "a.dat", "fringe", 10.0, coeffs_normalised=True)
    f = tmp_path / "b.dat"
    f.write_text("3\n10\n0\n1e-3\n")
    with pytest.raises(ValueError, match=r"b\.dat, line 4: 3 terms declared, found 2"):
        read_zemax_zernike(f, "standard", normalised=True)
    f.write_text("2\n10\n0\ninf\n")
    with pytest.raises(ValueError, match=r"b\.dat, line 4: standard Z2 \(1, 1\): coefficient 'inf'"):
        read_zemax_zernike(f, "standard", normalised=True)
    with pytest.raises(ValueError, match=r"convention='noll'.*\['fringe', 'standard'\]"):
        read_zemax_zernike(f, "noll", normalised=True)


def test_cli_sag_option_refuses_wavefront_file():
    """``--sag`` (and manifests, which use the same loader) never take a WFR file as sag."""
    from pipeline.io.registry import load_sag_map

    with pytest.raises(ValueError, match=r"^--sag .*codev_grid_wfr_no_nda\.int.*data type WFR is a wavefront"):
        load_sag_map(DATA / "codev_grid_wfr_no_nda.int")
