"""The line-profile CSV writer (pipeline.io.measured.write_line_profile_csv) against the
reader: exact round trip, hand-written files as laboratories send them, bad input refused.

Expected values are the inputs themselves (the round trip must be the identity to the
last bit) or the numbers typed into a hand-written file.
"""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.io.measured import read_line_profile, write_line_profile_csv
from pipeline.io.registry import formats


def _awkward_profile():
    """Offsets a few ulps apart, sub-pixel phases 1e-9 µm apart, values with no short
    decimal form, negative (background-subtracted) intensities, unsorted rows."""
    rng = np.random.default_rng(7)
    x = np.concatenate([rng.uniform(-126.0, 126.0, 40),
                        [36.000005, 36.000005 + 1e-9, np.nextafter(36.000005, 40.0), 1.0 / 3.0, -0.0]])
    y = np.concatenate([rng.normal(1000.0, 300.0, 40), [0.1 + 0.2, -2.5e-7, 1e-300, 2.0 / 3.0, 12345.678901234567]])
    return x, y


def test_written_profile_reads_back_bit_for_bit(tmp_path):
    x, y = _awkward_profile()
    f = tmp_path / "p.csv"
    write_line_profile_csv(f, x, y)
    xr, yr = read_line_profile(f, normalise=False)
    order = np.argsort(x, kind="stable")  # the reader sorts by offset
    assert np.array_equal(xr, x[order]) and np.array_equal(yr, y[order])
    assert not [p for p in tmp_path.iterdir() if p.name != "p.csv"]  # no temporary left behind


def test_hand_written_crlf_file_with_comments_reads(tmp_path):
    """A lab file: CRLF line ends, comment and blank lines, columns in another order, an
    extra column, upper-case header, rows unsorted, counts on a pedestal."""
    text = ("# detector column 512, J 1.25 um, 250 mas\r\n"
            "Intensity,row,Offset_um\r\n"
            "\r\n"
            "130,1,-36\r\n"
            "# a cosmic ray removed here\r\n"
            "100,2,-72\r\n"
            "1100,3,0\r\n"
            "600,4,36.5\r\n"
            "110,5,72.25\r\n")
    f = tmp_path / "lab.csv"
    f.write_bytes(text.encode("utf-8"))
    x, y = read_line_profile(f, normalise=False)
    assert x.tolist() == [-72.0, -36.0, 0.0, 36.5, 72.25]
    assert y.tolist() == [100.0, 130.0, 1100.0, 600.0, 110.0]


def test_hand_written_crlf_file_without_comments_reads(tmp_path):
    f = tmp_path / "crlf.csv"
    f.write_bytes(b"offset_um,intensity\r\n-2,1\r\n-1,3\r\n0,7\r\n1,3\r\n2,1\r\n")
    x, y = read_line_profile(f, normalise=False)
    assert x.tolist() == [-2.0, -1.0, 0.0, 1.0, 2.0] and y.tolist() == [1.0, 3.0, 7.0, 3.0, 1.0]


@pytest.mark.parametrize("x", [[1.0, 2.0, 1.0, 3.0], [0.0, -0.0, 1.0, 2.0]])
def test_duplicate_offsets_refused_and_nothing_written(tmp_path, x):
    f = tmp_path / "p.csv"
    f.write_text("offset_um,intensity\n0,1\n")
    with pytest.raises(ValueError, match=r"offset_um has duplicate samples \((1\.0|0\.0|-0\.0)"):
        write_line_profile_csv(f, x, [1.0, 2.0, 3.0, 4.0])
    assert f.read_text() == "offset_um,intensity\n0,1\n"  # the old file untouched
    assert [p.name for p in tmp_path.iterdir()] == ["p.csv"]


@pytest.mark.parametrize("x,y,pattern", [
    ([0.0, 1.0, 2.0], [1.0, 2.0], r"1-D arrays of one length; got shapes \(3,\) and \(2,\)"),
    ([[0.0, 1.0]], [[1.0, 2.0]], r"1-D arrays"),
    ([], [], r"offset_um is empty"),
    ([0.0, np.nan, 2.0], [1.0, 2.0, 3.0], r"offset_um\[1\] = nan; every value must be a finite number"),
    ([0.0, 1.0, 2.0], [1.0, 2.0, np.inf], r"intensity\[2\] = inf"),
])
def test_bad_profiles_refused_naming_the_parameter(tmp_path, x, y, pattern):
    with pytest.raises(ValueError, match=pattern):
        write_line_profile_csv(tmp_path / "p.csv", x, y)
    assert not (tmp_path / "p.csv").exists()


def test_registry_lists_the_writer_beside_the_reader():
    (fmt,) = [f for f in formats("line profile") if ".csv" in f.suffixes]
    assert fmt.reader is read_line_profile and fmt.writer is write_line_profile_csv
