"""``cryograting convert`` and ``cryograting fit`` on files that do not say everything
about themselves: every reader option a format may need is a command-line option of both
commands, and an error names it as the command line spells it."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.cli import main
from pipeline.io.registry import read_sag_map

N = 65
EXTENT_MM = 64.0  # first to last sample, each axis: 1 mm pitch


def _foreign_int(path, kind: str, values_um: np.ndarray, wavelength_um: float = 0.6328) -> None:
    """A CODE V INT grid as another tool writes it: no EXTENT_MM in the title, CRLF, values in
    waves of ``wavelength_um`` at SSZ counts per wave, NDA for no data."""
    ssz = 1000
    counts = np.where(np.isfinite(values_um), np.rint(values_um / wavelength_um * ssz), -32768).astype(int)
    lines = ["! written by another tool", "foreign grid", f"GRD {N} {N} {kind} WVL {wavelength_um} SSZ {ssz} NDA -32768"]
    lines += [" ".join(str(v) for v in row) for row in counts]  # first row is the top (+y)
    path.write_bytes(("\r\n".join(lines) + "\r\n").encode())


def _astig_um() -> np.ndarray:
    x = np.linspace(-EXTENT_MM / 2, EXTENT_MM / 2, N)
    X, Y = np.meshgrid(x, x[::-1])  # rows from the top
    r = np.hypot(X, Y)
    return np.where(r <= EXTENT_MM / 2, 0.2 * (X * Y) / (EXTENT_MM / 2) ** 2, np.nan)


def test_a_wavefront_int_without_extent_is_converted_with_the_cli_options(tmp_path, capsys):
    """A WFR grid: refused without a factor (the message names --wfr-to-sag-factor and
    --quantity, not API keywords), read as sag = -0.5 x OPD with it; without EXTENT_MM the
    message names --extent-mm and --spacing-mm, and --extent-mm gives the 1 mm pitch."""
    opd = _astig_um()
    src = tmp_path / "wfe.int"
    _foreign_int(src, "WFR", opd)
    assert main(["convert", str(src), str(tmp_path / "a.nc"), "--spacing-mm", "1"]) == 2
    err = capsys.readouterr().err
    assert "pass --wfr-to-sag-factor" in err and "--quantity" in err and " wfr_to_sag_factor" not in err
    assert main(["convert", str(src), str(tmp_path / "a.nc"), "--wfr-to-sag-factor", "-0.5"]) == 2
    err = capsys.readouterr().err
    assert "--extent-mm" in err and "--spacing-mm" in err and "extent_mm" not in err
    h = EXTENT_MM / 2
    assert main(["convert", str(src), str(tmp_path / "a.nc"), "--wfr-to-sag-factor", "-0.5",
                 "--extent-mm", str(-h), str(h), str(-h), str(h)]) == 0
    m = read_sag_map(tmp_path / "a.nc")
    np.testing.assert_allclose(np.diff(m.x_mm), 1.0)
    step_um = 0.6328 / 1000 * 0.5
    np.testing.assert_allclose(m.sag_um[::-1], -0.5 * opd, atol=step_um, equal_nan=True)
    assert main(["convert", str(src), str(tmp_path / "w.nc"), "--quantity", "wavefront", "--spacing-mm", "1"]) == 0
    np.testing.assert_allclose(read_sag_map(tmp_path / "w.nc").sag_um[::-1], opd, atol=2 * step_um, equal_nan=True)


def test_fit_reads_a_map_in_waves_with_wavelength_um(tmp_path, capsys):
    """A CSV of valid points in waves: ``fit`` asks for --wavelength-um (the manifest key
    quoted as such), and with it recovers the oblique astigmatism."""
    sag = _astig_um()
    x = np.linspace(-EXTENT_MM / 2, EXTENT_MM / 2, N)
    X, Y = np.meshgrid(x, x[::-1])
    ok = np.isfinite(sag)
    path = tmp_path / "cold.csv"
    np.savetxt(path, np.column_stack([X[ok], Y[ok], sag[ok] / 0.6328]), delimiter=",",
               header="x_mm,y_mm,sag_waves", comments="")
    assert main(["fit", str(path), "--basis", "zernike-noll:6"]) == 2
    err = capsys.readouterr().err
    assert "--wavelength-um" in err and "'wavelength_um' key" in err
    out_csv = tmp_path / "z.csv"
    assert main(["fit", str(path), "--basis", "zernike-noll:6", "--wavelength-um", "0.6328",
                 "--out", str(out_csv)]) == 0
    rows = {r.split(",")[0]: float(r.split(",")[1]) for r in out_csv.read_text().splitlines()[1:]}
    # 0.2 x y / R^2 over the unit disc is Z5 (Noll, RMS-normalised) of 0.2 / (2 sqrt 6) about the
    # disc the fit takes: the one of the valid points, radius 32 mm
    z5 = next(v for k, v in rows.items() if k.startswith("Z5 "))
    assert z5 == pytest.approx(0.2 / (2 * np.sqrt(6)), rel=0.02)
