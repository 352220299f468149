"""Interchange formats: write -> read round trips, file layout/orientation pins,
malformed-file errors, Zernike list conventions, measured line profiles."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from optics.sagmap import SagMap
from optics.zernike import norm_factor, wavefront_from_coefficients
from pipeline.io import registry as ic
from pipeline.io.codev import CODEV_NDA, MAX_COUNT, read_codev_int, write_codev_int
from pipeline.io.measured import read_line_profile
from pipeline.io.zernike import read_zernike_list, write_zernike_list

# Quantisation of each format for the test map (|sag| <= 3.5 um):
#   .int  16-bit counts, SSZ puts max|sag| at 32766 counts: error <= 0.5 * 3.5 / 32766 um
#         (1e-5 for SSZ rounded down to 6 digits)
#   .dat  12 significant digits of the sag in mm  -> < 1e-11 um
#   .csv  12 significant digits of the sag in um  -> < 1e-11 um
#   .nc / .npz  float64, exact
TOL_UM = {".int": 0.5 * 3.5 / 32766 * (1 + 1e-5), ".dat": 1e-11, ".csv": 1e-11, ".nc": 0.0, ".npz": 0.0,
          ".fits": 0.0, ".fit": 0.0, ".fts": 0.0}


@pytest.fixture
def quadrant_map() -> SagMap:
    """Non-square, off-centre, one-signed (1.5..3.5 um) map with NaN holes and a bump
    only in the +x, +y quadrant."""
    rng = np.random.default_rng(7)
    x = np.linspace(-33.0, 22.0, 23)   # dx = 2.5 mm, not centred on 0 (tests decentres)
    y = np.linspace(-13.0, 13.0, 14)   # dy = 2 mm
    X, Y = np.meshgrid(x, y)
    sag = 1.5 + 0.5 * rng.random(X.shape)
    sag += np.where((X > 5) & (Y > 5), 1.5, 0.0)  # the feature: +x, +y only
    sag[0, 0] = np.nan      # (-x, -y) corner
    sag[-1, 3] = np.nan     # top row
    sag[6, 11] = np.nan     # interior hole
    return SagMap(x, y, sag, "quadrant test")


@pytest.mark.parametrize("suffix", sorted(ic.SAG_FORMATS))
def test_round_trip(tmp_path, quadrant_map, suffix):
    path = ic.write_sag_map(quadrant_map, tmp_path / f"m{suffix}")
    back = ic.read_sag_map(path)
    assert back.sag_um.shape == quadrant_map.sag_um.shape
    np.testing.assert_allclose(back.x_mm, quadrant_map.x_mm, atol=1e-9)
    np.testing.assert_allclose(back.y_mm, quadrant_map.y_mm, atol=1e-9)
    np.testing.assert_array_equal(np.isnan(back.sag_um), np.isnan(quadrant_map.sag_um))
    err = np.nanmax(np.abs(back.sag_um - quadrant_map.sag_um))
    assert err <= TOL_UM[suffix], f"{suffix}: {err:.3g} um > {TOL_UM[suffix]:.3g} um"
    # orientation: the bump comes back in the +x, +y quadrant only
    X, Y = back.grid()
    with np.errstate(invalid="ignore"):
        bump = back.sag_um > 2.5
    np.testing.assert_array_equal(bump, (X > 5) & (Y > 5) & back.mask)


def test_codev_int_layout(tmp_path, quadrant_map):
    """Header, 16-bit SSZ, 80-column lines, top-left first value, NDA 32767 for NaN."""
    path = ic.write_sag_map(quadrant_map, tmp_path / "m.int")
    lines = path.read_text().splitlines()
    assert all(len(s) <= 80 for s in lines)
    assert "EXTENT_MM -33 22 -13 13" in lines[0]
    head = lines[1].split()
    assert head[:6] == ["GRD", "23", "14", "SUR", "WVL", "0.6328"] and head[6] == "SSZ"
    assert head[8:] == ["NDA", "32767"] and CODEV_NDA == 32767 and MAX_COUNT == 32766
    s = quadrant_map.sag_um
    ssz = float(head[7])
    # largest |sag| lands within one 6-digit rounding of 32766 counts, never above
    ideal = 32766 * 0.6328 / np.nanmax(np.abs(s))
    assert ideal * (1 - 1e-5) <= ssz <= ideal
    values = np.array(" ".join(lines[2:]).split(), dtype=np.int64)
    # first value = (-x, +y) corner; the NaN at the top row, column 3 is value 3
    assert values[0] == round(s[-1, 0] / 0.6328 * ssz)
    assert values[3] == CODEV_NDA
    assert values[13 * 23] == CODEV_NDA  # (-x, -y) corner: first value of the last row
    data = values[values != CODEV_NDA]
    assert np.abs(data).max() <= 32766 and np.abs(data).max() >= 32766 * (1 - 1e-5) - 0.5


def test_codev_int_reader_fixture(tmp_path):
    """Hand-written file, independent of the writer: value / SSZ * WVL, top row first."""
    f = tmp_path / "hand.int"
    f.write_text("! a comment\nhand made\nGRD 3 2 WFR WVL 0.5 SSZ 1000 NDA -99 XSC 1.0 YSC 1.0\n"
                 "1000 2000 3000\n-99 -500 0\n")
    m = ic.read_sag_map(f, extent_mm=(-1.0, 1.0, -2.0, 2.0), quantity="wavefront")
    np.testing.assert_allclose(m.sag_um[1], [0.5, 1.0, 1.5])   # top row (+y) is the first row in the file
    assert np.isnan(m.sag_um[0, 0])
    np.testing.assert_allclose(m.sag_um[0, 1:], [-0.25, 0.0])
    assert m.meta["codev_type"] == "WFR" and m.meta["xsc"] == 1.0
    np.testing.assert_allclose(m.y_mm, [-2.0, 2.0])
    # spacing_mm instead of an extent: grid centred on the origin
    m2 = read_codev_int(f, spacing_mm=(0.5, 3.0), quantity="wavefront")
    np.testing.assert_allclose(m2.x_mm, [-0.5, 0.0, 0.5])
    np.testing.assert_allclose(m2.y_mm, [-1.5, 1.5])
    # a wavefront is never surface sag without an explicit factor
    with pytest.raises(ValueError, match=r"hand\.int: data type WFR is a wavefront.*wfr_to_sag_factor"):
        ic.read_sag_map(f, extent_mm=(-1.0, 1.0, -2.0, 2.0))
    m3 = ic.read_sag_map(f, extent_mm=(-1.0, 1.0, -2.0, 2.0), wfr_to_sag_factor=-0.5)
    np.testing.assert_allclose(m3.sag_um[1], [-0.25, -0.5, -0.75])
    assert m3.meta["converted_from"] == "WFR" and m3.meta["wfr_to_sag_factor"] == -0.5


def test_codev_int_large_sag_stays_16bit(tmp_path, quadrant_map):
    """A 7 mm map still fits 16-bit counts; the step grows with the map (max|sag| / 32766)."""
    big = quadrant_map.scaled(2000.0)  # up to 7 mm of sag
    path = write_codev_int(big, tmp_path / "big.int", wavelength_um=0.6328)
    ssz = float(path.read_text().splitlines()[1].split()[7])
    values = np.array(" ".join(path.read_text().splitlines()[2:]).split(), dtype=np.int64)
    assert np.abs(values[values != CODEV_NDA]).max() <= 32766
    step_um = 0.6328 / ssz
    assert step_um <= np.nanmax(np.abs(big.sag_um)) / 32766 * (1 + 1e-5)
    back = ic.read_sag_map(path)
    assert np.nanmax(np.abs(back.sag_um - big.sag_um)) <= 0.5 * step_um * (1 + 1e-9)


def test_codev_int_wfr_round_trip(tmp_path, quadrant_map):
    path = ic.write_sag_map(quadrant_map, tmp_path / "w.int", kind="WFR", wavelength_um=1.25)
    back = ic.read_sag_map(path, quantity="wavefront")
    assert back.meta["codev_type"] == "WFR" and back.meta["wavelength_um"] == 1.25
    assert np.nanmax(np.abs(back.sag_um - quadrant_map.sag_um)) <= 0.5 * 1.25 / back.meta["ssz"] * (1 + 1e-9)
    with pytest.raises(ValueError, match="not surface sag"):
        ic.read_sag_map(path)


def test_codev_int_needs_extent(tmp_path):
    f = tmp_path / "noext.int"
    f.write_text("no extent here\nGRD 2 2 SUR WVL 1 SSZ 1 NDA -5\n1 2 3 4\n")
    with pytest.raises(ValueError, match=r"noext\.int.*extent_mm.*spacing_mm"):
        ic.read_sag_map(f)
    assert ic.read_sag_map(f, extent_mm=(0, 1, 0, 1)).sag_um[1, 0] == 1.0


def test_zemax_layout_and_derivatives(tmp_path, quadrant_map):
    path = ic.write_sag_map(quadrant_map, tmp_path / "m.dat")
    lines = path.read_text().splitlines()
    head = lines[0].split()
    assert head[:2] == ["23", "14"] and float(head[2]) == 2.5 and float(head[3]) == 2.0 and head[4] == "0"
    assert float(head[5]) == pytest.approx(-5.5) and float(head[6]) == pytest.approx(0.0)  # grid centre
    first = lines[1].split()
    assert float(first[0]) == pytest.approx(quadrant_map.sag_um[-1, 0] * 1e-3)  # (-x, +y) corner, mm
    assert lines[1 + 3].split()[4] == "1"  # NaN in the top row, column 3
    # derivatives of a plane are exact: dz/dx = a, dz/dy = b (dimensionless), cross term 0
    x, y = quadrant_map.x_mm, quadrant_map.y_mm
    X, Y = np.meshgrid(x, y)
    plane = quadrant_map.with_sag(np.where(np.isnan(quadrant_map.sag_um), np.nan, 2.0 + 0.03 * X - 0.02 * Y))
    rows = np.loadtxt(ic.write_sag_map(plane, tmp_path / "p.dat"), skiprows=1)
    ok = rows[:, 4] == 0
    np.testing.assert_allclose(rows[ok, 1], 0.03e-3, rtol=1e-9)
    np.testing.assert_allclose(rows[ok, 2], -0.02e-3, rtol=1e-9)
    np.testing.assert_allclose(rows[ok, 3], 0.0, atol=1e-15)


def test_zemax_reader_units_and_decentre(tmp_path):
    f = tmp_path / "inch.dat"
    body = "\n".join(f"{0.001 * k} 0 0 0 {1 if k == 7 else 0}" for k in range(25))
    f.write_text(f"5 5 0.1 0.2 2 1.0 -1.0\n{body}\n")
    m = ic.read_sag_map(f)
    np.testing.assert_allclose(m.x_mm, 25.4 * (1.0 + 0.1 * np.arange(-2, 3)))
    np.testing.assert_allclose(m.y_mm, 25.4 * (-1.0 + 0.2 * np.arange(-2, 3)))
    assert m.sag_um[-1, 0] == pytest.approx(0.0) and m.sag_um[-1, 1] == pytest.approx(25.4)  # um per 0.001 in
    assert np.isnan(m.sag_um[-2, 2])  # point 7 = second row from the top, third column


def test_csv_scattered_gridded(tmp_path):
    rng = np.random.default_rng(3)
    x, y = rng.uniform(-10, 10, 400), rng.uniform(-5, 5, 400)
    f = tmp_path / "scat.csv"
    np.savetxt(f, np.column_stack([x, y, 2.0 + 0.1 * x - 0.05 * y]), delimiter=",",
               header="x_mm,y_mm,sag_um", comments="")
    auto = ic.read_sag_map(f)  # spacing: one node per point over their hull; a plane is exact
    assert auto.meta["gridding"].startswith("scattered: linear")
    np.testing.assert_allclose(auto.sag_um[auto.mask], (2.0 + 0.1 * auto.grid()[0] - 0.05 * auto.grid()[1])[auto.mask],
                               atol=1e-9)
    m = ic.read_sag_map(f, spacing_mm=1.0)
    X, Y = m.grid()
    ok = m.mask  # outside the convex hull of the points: NaN
    assert ok.mean() > 0.6
    np.testing.assert_allclose(m.sag_um[ok], (2.0 + 0.1 * X - 0.05 * Y)[ok], atol=1e-9)


# ------------------------------------------------------------------ malformed files
def _int_text():
    return "t EXTENT_MM 0 1 0 2\nGRD 3 2 SUR WVL 1 SSZ 10 NDA -9\n1 2 3\n4 5 6\n"


def _dat_text():
    return "5 5 1 1 0 0 0\n" + "".join("0.1 0 0 0 0\n" for _ in range(25))


MALFORMED = [
    ("trunc.int", lambda: _int_text().rsplit("\n", 2)[0] + "\n", r"trunc\.int, line 3: truncated"),
    ("count.int", lambda: _int_text() + "7\n", r"count\.int, line 5: wrong count"),
    ("float.int", lambda: _int_text().replace("5", "5.5"), r"float\.int, line 4: .*'5\.5' is not an integer"),
    ("hdr.int", lambda: _int_text().replace("GRD", "GRID"), r"hdr\.int, line 2: header must start"),
    ("zoom.int", lambda: _int_text().replace("NDA -9", "NDA -9 ZOOM 2"), r"zoom\.int, line 2: unknown header keyword 'ZOOM'.*valid"),
    ("zfr.int", lambda: "t\nZFR 4 SUR WVL 1 SSZ 1\n1 2 3 4\n", r"zfr\.int, line 2: INT type 'ZFR'"),
    ("nossz.int", lambda: _int_text().replace("SSZ 10 ", ""), r"nossz\.int, line 2: header has no SSZ"),
    ("trunc.dat", lambda: _dat_text().rsplit("\n", 3)[0] + "\n", r"trunc\.dat, line 24: truncated"),
    ("count.dat", lambda: _dat_text() + "0 0 0 0 0\n", r"count\.dat, line 27: wrong count"),
    ("cols.dat", lambda: _dat_text().replace("0.1 0 0 0 0\n", "0.1 0 0\n", 1), r"cols\.dat, line 2: expected 4 or 5"),
    ("text.dat", lambda: _dat_text().replace("0.1 0 0 0 0\n", "abc 0 0 0 0\n", 1), r"text\.dat, line 2: non-numeric"),
    ("hdr.dat", lambda: "5 5 1 1 0\n" + _dat_text().split("\n", 1)[1], r"hdr\.dat, line 1: header needs 7 values"),
    ("unit.dat", lambda: _dat_text().replace("0 0 0\n", "7 0 0\n", 1), r"unit\.dat, line 1: unitflag=7"),
    ("flag.dat", lambda: _dat_text().replace("0.1 0 0 0 0\n", "0.1 0 0 0 2\n", 1), r"flag\.dat, line 2: nodata flag"),
    ("text.csv", lambda: "x_mm,y_mm,sag_um\n0,0,1\n1,0,x\n", r"text\.csv, line 3: non-numeric"),
    ("cols.csv", lambda: "x_mm,sag_um\n0,1\n", r"cols\.csv, line 1: missing column\(s\) \['y_mm'\]"),
]


@pytest.mark.parametrize("name,make,pattern", MALFORMED, ids=[m[0] for m in MALFORMED])
def test_malformed_file_names_file_and_line(tmp_path, name, make, pattern):
    f = tmp_path / name
    f.write_text(make())
    with pytest.raises(ValueError, match=pattern):
        ic.read_sag_map(f)


# ------------------------------------------------------------------ bad input
def test_unknown_suffix_lists_valid(tmp_path, quadrant_map):
    with pytest.raises(ValueError, match=r"\.xyz.*\['\.csv', '\.dat', '\.fit', '\.fits', '\.fts', '\.int', '\.nc', '\.npz'\]"):
        ic.write_sag_map(quadrant_map, tmp_path / "m.xyz")
    with pytest.raises(ValueError, match=r"unknown sag-map format '\.xyz'"):
        ic.read_sag_map(tmp_path / "m.xyz")


@pytest.mark.parametrize("suffix", sorted(ic.SAG_FORMATS))
def test_unwritable_path(tmp_path, quadrant_map, suffix):
    with pytest.raises(ValueError, match=r"cannot write .*no_such_dir"):
        ic.write_sag_map(quadrant_map, tmp_path / "no_such_dir" / f"m{suffix}")


def test_failed_write_leaves_old_file_and_no_tmp(tmp_path, quadrant_map):
    target = tmp_path / "m.dat"
    target.write_text("old")
    tiny = SagMap([0.0, 1.0], [0.0, 1.0], np.ones((2, 2)))
    with pytest.raises(ValueError, match="nx, ny >= 5"):
        ic.write_sag_map(tiny, target)
    ic.write_sag_map(quadrant_map, tmp_path / "ok.int")
    assert target.read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.dat", "ok.int"]


def test_missing_file_and_cli_loader(tmp_path, quadrant_map):
    with pytest.raises(ValueError, match=r"nothere\.nc: file does not exist"):
        ic.read_sag_map(tmp_path / "nothere.nc")
    from pipeline import optics_cli

    assert optics_cli.load_sag_map is ic.load_sag_map
    with pytest.raises(ValueError, match=r"^--sag .*nothere\.npz: file does not exist"):
        optics_cli.load_sag_map(tmp_path / "nothere.npz")
    back = optics_cli.load_sag_map(ic.write_sag_map(quadrant_map, tmp_path / "m.int"))
    assert back.label == "quadrant test"


# ------------------------------------------------------------------ Zernike lists
COEFFS_NORMALISED = {(0, 0): 0.1, (1, 1): -0.2, (2, 0): 0.35, (2, -2): 0.05, (3, 1): -0.07,
                     (4, 0): 0.02, (4, 4): 0.011, (5, -3): -0.004, (12, 0): 0.001}


def test_zernike_fringe_noll_round_trip(tmp_path):
    f = write_zernike_list(COEFFS_NORMALISED, tmp_path / "z_fringe.txt", "fringe",
                              radius_mm=62.5, coeffs_normalised=True)
    text = f.read_text()
    assert "# convention: fringe" in text and "# normalisation_radius_mm: 62.5" in text and "# units: um" in text
    # file holds unnormalised Fringe coefficients: c_u = c_n * N, in Fringe order (Z4 = defocus)
    rows = {int(r.split(",")[0]): float(r.split(",")[3]) for r in text.splitlines()[6:]}
    assert rows[4] == pytest.approx(0.35 * np.sqrt(3)) and rows[37] == pytest.approx(0.001 * np.sqrt(13))
    unnorm, info = read_zernike_list(f, normalised=False)
    assert info == {"convention": "fringe", "radius_mm": 62.5, "normalised": False}
    # same surface: sum c_n Z_normalised == sum c_u Z_unnormalised
    x, y = np.meshgrid(np.linspace(-60, 60, 31), np.linspace(-60, 60, 31))
    np.testing.assert_allclose(wavefront_from_coefficients(unnorm, x, y, 62.5, norm=False),
                               wavefront_from_coefficients(COEFFS_NORMALISED, x, y, 62.5, norm=True), atol=1e-12)
    # Fringe file -> normalised dict -> Noll file -> back: identity
    norm, _ = read_zernike_list(f, normalised=True)
    g = write_zernike_list(norm, tmp_path / "z_noll.txt", "noll", 62.5, coeffs_normalised=True)
    assert "1,0,0," in g.read_text() and "4,2,0," in g.read_text()  # Noll j = 4 is defocus
    back, info = read_zernike_list(g, normalised=True)
    assert info["convention"] == "noll"
    assert back.keys() == COEFFS_NORMALISED.keys()
    for k, v in COEFFS_NORMALISED.items():
        assert back[k] == pytest.approx(v, rel=1e-14)
    # unnormalised in -> Noll (normalised) file: divided by N
    h = write_zernike_list({(2, 2): 1.0}, tmp_path / "z3.txt", "noll", 10.0, coeffs_normalised=False)
    assert read_zernike_list(h, normalised=True)[0][(2, 2)] == pytest.approx(1 / norm_factor(2, 2))


def test_zernike_list_errors(tmp_path):
    with pytest.raises(ValueError, match=r"\(8, 8\).*not one of the 37 Fringe terms"):
        write_zernike_list({(8, 8): 1.0}, tmp_path / "a.txt", "fringe", 10.0, coeffs_normalised=True)
    with pytest.raises(ValueError, match=r"convention='ansi'.*\['fringe', 'noll'\]"):
        write_zernike_list({(0, 0): 1.0}, tmp_path / "a.txt", "ansi", 10.0, coeffs_normalised=True)
    f = write_zernike_list({(2, 0): 1.0}, tmp_path / "b.txt", "noll", 10.0, coeffs_normalised=True)
    f.write_text(f.read_text().replace("4,2,0,", "5,2,0,"))
    with pytest.raises(ValueError, match=r"b\.txt, line 7: noll index 5 is \(n, m\)=\(2, -2\)"):
        read_zernike_list(f, normalised=True)
    f.write_text(f.read_text().replace("# normalisation_radius_mm: 10\n", ""))
    with pytest.raises(ValueError, match=r"b\.txt, line 5: missing '# normalisation_radius_mm"):
        read_zernike_list(f, normalised=True)


# ------------------------------------------------------------------ line profiles
def _profile(tmp_path: Path, text: str) -> Path:
    f = tmp_path / "lsf.csv"
    f.write_text(text)
    return f


def test_read_line_profile(tmp_path):
    x = np.linspace(-20, 20, 41)
    rows = "\n".join(f"{v},{100 * np.exp(-v * v / 50)},junk" for v in x[::-1])  # reversed, extra column
    off, inten = read_line_profile(_profile(tmp_path, "offset_um,intensity,note\n" + rows + "\n"))
    np.testing.assert_allclose(off, x)
    assert np.trapezoid(inten, off) == pytest.approx(1.0)
    assert off[np.argmax(inten)] == 0.0


@pytest.mark.parametrize("text,pattern", [
    ("offset,intensity\n" + "1,1\n" * 6, r"line 1: missing column\(s\) \['offset_um'\]"),
    ("offset_um,intensity\n0,1\n1,2\n2,two\n3,1\n4,1\n", r"line 4: non-numeric"),
    ("offset_um,intensity\n0,1\n1,2\n2,1\n3,1\n", r"needs >= 5 samples, found 4"),
    ("offset_um,intensity\n0,1\n1,-2\n2,-1\n3,-1\n4,1\n", r"no flux.* is -3, must be > 0"),
    ("offset_um,intensity\n0,0\n1,0\n2,0\n3,0\n4,0\n", r"no flux"),
    ("offset_um,intensity\n0,1\n1,2\n1,1\n3,1\n4,1\n", r"needs >= 5 distinct offsets, found 4"),
])
def test_read_line_profile_errors(tmp_path, text, pattern):
    with pytest.raises(ValueError, match=r"lsf\.csv.*" + pattern):
        read_line_profile(_profile(tmp_path, text))


def test_unknown_option_is_named(tmp_path, quadrant_map):
    with pytest.raises(ValueError,
                       match=r"option\(s\) \['spacing_mm'\] are not valid.*\.npz.*valid are \['wavelength_um'\]"):
        ic.read_sag_map(ic.write_sag_map(quadrant_map, tmp_path / "m.npz"), spacing_mm=1.0)
    with pytest.raises(ValueError, match=r"option\(s\) \['kind'\].*valid are \[\]"):
        ic.write_sag_map(quadrant_map, tmp_path / "m.dat", kind="WFR")


def test_csv_ragged_row_named(tmp_path):
    f = tmp_path / "rag.csv"
    f.write_text("x_mm,y_mm,sag_um\n0,0,1\n1,0,2,9\n0,1,3\n1,1,4\n")
    with pytest.raises(ValueError, match=r"rag\.csv, line 3: expected 3 values"):
        ic.read_sag_map(f)


def test_registry_lists_every_reader_and_writer_of_the_io_package():
    """One registry: every public read_*/write_* of a pipeline.io module is a row of FORMATS
    (a reader, a writer, or a reader that also returns a file's scattered points)."""
    import importlib
    import pkgutil

    import pipeline.io

    registered = {f for fmt in ic.FORMATS for f in (fmt.reader, fmt.writer, fmt.points_reader) if f is not None}
    missing = []
    for m in pkgutil.iter_modules(pipeline.io.__path__):
        if m.name in ("common", "registry"):  # shared helpers; the dispatchers themselves
            continue
        mod = importlib.import_module(f"pipeline.io.{m.name}")
        missing += [f"{m.name}.{n}" for n in mod.__all__
                    if n.startswith(("read_", "write_")) and getattr(mod, n) not in registered]
    assert missing == []
    assert all(f.module.startswith("pipeline.io.") for f in ic.FORMATS)


def test_registry_sag_dispatch_is_the_sag_map_rows():
    rows = ic.formats("sag map")
    plain = [s for f in rows if f.sniff is None for s in f.suffixes]
    assert len(plain) == len(set(plain))  # one format per suffix without a content test
    assert all(s in plain for f in rows if f.sniff for s in f.suffixes)  # a sniffed row falls back on one
    assert ic.SAG_FORMATS == {s: (f.reader, f.writer) for f in rows if f.writer and not f.sniff for s in f.suffixes}
    assert ic.SAG_READERS == {s: f.reader for f in rows if not f.writer and not f.sniff for s in f.suffixes}
    assert {f.kind for f in ic.FORMATS} == set(ic.KINDS)
    with pytest.raises(ValueError, match="kind='profile'"):
        ic.formats("profile")
    table = ic.format_table()
    assert all(f.reader.__name__ in table and f.module in table for f in ic.FORMATS)
