"""One error path for every command, output checks before work, and paths that mean what
the caller meant.

Every bad input is generated here (garbage and undecodable files, a CODE V INT without its
grid, options out of range, a manifest that points out of its directory, an unreachable
Dask scheduler); faults are raised by stubs. A user's mistake must end the command with one
stderr line naming the file or the option as the command spells it, and exit code 2.
"""

from __future__ import annotations

import re
import subprocess
import zipfile
from pathlib import Path

import numpy as np
import pytest

from cli_checks import never, one_error_line
from pipeline.cli import main
from pipeline.diagnosis.manifest import load_manifest, parse_manifest
from pipeline.errors import cli_spelling, describe, run_command

REPO = Path(__file__).resolve().parents[1]


# ------------------------------------------------------------------ one error path
@pytest.mark.parametrize("exc, needle", [
    (OSError(28, "No space left on device", "/full/disk/psf.npz"), "/full/disk/psf.npz: No space left on device"),
    (PermissionError(13, "Permission denied", "out/x"), "out/x: Permission denied"),
    (OSError(28, "No space left on device"), "(files given: --out o, --sag in.npz)"),
    (UnicodeDecodeError("utf-8", b"\xff", 0, 1, "invalid start byte"),
     "not UTF-8 text (undecodable byte at offset 0); save it as UTF-8 (files given: --sag in.npz)"),
    (OverflowError("(34, 'Numerical result out of range')"), "numeric OverflowError"),
    (ZeroDivisionError("float division by zero"), "numeric ZeroDivisionError"),
    (FloatingPointError("overflow encountered in square"), "numeric FloatingPointError"),
    (EOFError("No data left in file"), "empty, truncated or not what its name says (EOFError"),
    (zipfile.BadZipFile("File is not a zip file"), "(BadZipFile: File is not a zip file) (files given: --sag in.npz)"),
    (ValueError("line one\n  line two"), "error: line one line two"),
    (ImportError("scheduler='local' needs Dask"), "needs Dask"),
])
def test_every_user_error_is_one_line_and_exit_2(exc, needle, capsys):
    from types import SimpleNamespace

    def fail(a):
        raise exc

    args = SimpleNamespace(sag="in.npz", out="o", quiet=False)
    assert run_command(fail, args, "psf") == 2
    one_error_line(capsys, needle)
    with pytest.raises(type(exc)):  # --debug: the exception and its traceback
        run_command(fail, args, "psf", debug=True)


def test_interrupt_is_one_line_and_exit_130(capsys):
    def interrupted(a):
        raise KeyboardInterrupt

    assert run_command(interrupted, None, "run") == 130
    one_error_line(capsys, "cryograting run: interrupted")


def test_a_bug_keeps_its_traceback():
    def bug(a):
        raise KeyError("a programming error, not bad input")

    with pytest.raises(KeyError):
        run_command(bug, None, "run")


def test_debug_flag_before_or_after_the_command_shows_the_traceback(tmp_path):
    args = ["psf", "--grating", "J", "--wavelength-um", "1.25", "--quilt-pv-um", "0", "--detector-step-um", "0",
            "--out", str(tmp_path / "o")]
    for argv in (["--debug", *args], [*args, "--debug"]):
        with pytest.raises(ValueError, match="detector_step_um=0.0 must be"):
            main(argv)


def test_option_names_in_messages_are_the_commands_spelling():
    opts = {"window_um": "--window-um", "detector_step_um": "--detector-step-um", "out": "--out",
            "profiles": "--profiles"}
    assert cli_spelling("window_um=0.0 must be > 0; change detector_step_um or window_um", opts) == \
        "--window-um 0.0 must be > 0; change --detector-step-um or --window-um"
    for kept in ("LsfSettings.window_um=1 too small", "timeout=3", "fea.window_um = 3", "valid: ['window_um']",
                 "line profiles differ"):
        assert cli_spelling(kept, opts) == kept


def _foreign_int(path):
    """A CODE V INT with no grid size (no EXTENT_MM in its title), as a metrology tool writes it."""
    path.write_text("interferogram\nGRD 4 4 SUR WVL 0.6328 SSZ 1000 NDA -32768\n"
                    "0 1 2 3\n1 2 3 4\n2 3 4 5\n3 4 5 6\n")
    return path


@pytest.mark.parametrize("command", ["lsf", "psf"])
def test_int_without_grid_names_what_the_command_can_do(command, tmp_path, capsys):
    f = _foreign_int(tmp_path / "tool.int")
    argv = [command, "--grating", "J", "--wavelength-um", "1.25", "--sag", str(f), "--out", str(tmp_path / "o")]
    argv += ["--pixel-scale-mas", "25"] if command == "lsf" else []
    assert main(argv) == 2
    line = one_error_line(capsys, "add EXTENT_MM x0 x1 y0 y1")
    assert "spacing_mm" not in line and "extent_mm" not in line  # options that lsf/psf do not have


@pytest.mark.parametrize("name, content", [("empty.npz", b""), ("zip.npz", b"PK\x03\x04garbage"),
                                           ("noise.nc", bytes(range(256)) * 2),
                                           ("u16.csv", "x,y\n1,2\n".encode("utf-16"))])
def test_garbage_sag_files_fail_in_one_line_naming_the_file(name, content, tmp_path, capsys):
    f = tmp_path / name
    f.write_bytes(content)
    assert main(["psf", "--grating", "J", "--wavelength-um", "1.25", "--sag", str(f),
                 "--out", str(tmp_path / "o")]) == 2
    one_error_line(capsys, name)


def test_garbage_fe_result_fails_in_one_line(tmp_path, capsys):
    f = tmp_path / "result.vtu"
    f.write_bytes(bytes(range(256)))
    assert main(["import-fe", str(f), "--surface", "+z", "--out", str(tmp_path / "o.npz")]) == 2
    out = capsys.readouterr()
    err = out.err.strip().splitlines()
    assert len(err) == 1 and "result.vtu" in err[0] and out.out == ""  # meshio's own complaint folded in


@pytest.mark.parametrize("text", [b"\xff\xfe[\x00f\x00e\x00a\x00]\x00", bytes(range(128, 256))])
def test_undecodable_config_fails_in_one_line(text, tmp_path, capsys):
    f = tmp_path / "study.toml"
    f.write_bytes(text)
    assert main(["config", "--check", str(f)]) == 2
    one_error_line(capsys, "study.toml")


def test_calibrate_checks_its_output_before_solving(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr("fea.api.prepare", never)
    taken = tmp_path / "taken"
    taken.write_text("a file where the output directory should go")
    for out in (taken, taken / "sub"):
        assert main(["calibrate", "--out", str(out)]) == 2
        one_error_line(capsys, f"--out '{out}'")


def _profile_manifest(dirpath, file_field="p.csv", extra=""):
    dirpath.mkdir(parents=True, exist_ok=True)
    x = np.arange(-60.0, 60.01, 1.0)
    np.savetxt(dirpath / "p.csv", np.column_stack([x, np.exp(-0.5 * (x / 10) ** 2)]), delimiter=",",
               header="offset_um,intensity", comments="")
    m = dirpath / "m.toml"
    m.write_text(f"[[measurement]]\nkind = 'line_profile'\nfile = '{file_field}'\ngrating = 'J'\n"
                 f"wavelength_um = 1.25\npixel_scale_mas = 250\n{extra}")
    return m


def test_diagnose_checks_its_output_before_any_work(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr("pipeline.diagnosis.engine.diagnose", never)
    monkeypatch.setattr("pipeline.diagnosis.campaign.run_campaign", never)
    m = _profile_manifest(tmp_path / "data")
    taken = tmp_path / "taken"
    taken.write_text("x")
    assert main(["diagnose", str(m), "--out", str(taken)]) == 2
    one_error_line(capsys, "--out")
    assert main(["diagnose", "--validate", "--cases", "2", "--out", str(taken)]) == 2
    one_error_line(capsys, "--out")


def test_unknown_truth_family_is_refused_before_the_campaign(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr("pipeline.diagnosis.campaign.run_campaign", never)
    assert main(["diagnose", "--validate", "--cases", "2", "--truth-families", "sum_mix,hexagons",
                 "--out", str(tmp_path / "o")]) == 2
    line = one_error_line(capsys, "--truth-families")
    assert "hexagons" in line and "pocket_jitter" in line  # the value and the valid names


@pytest.mark.parametrize("field, value, valid", [("noise_rel", "1e-300", "[1e-06, 1]"),
                                                 ("noise_rel", "2.0", "[1e-06, 1]"),
                                                 ("noise_rel", "-0.01", "[1e-06, 1]")])
def test_noise_outside_its_range_is_refused_with_the_range(field, value, valid, tmp_path, capsys):
    m = _profile_manifest(tmp_path / "data", extra=f"{field} = {value}\n")
    with pytest.raises(ValueError, match=rf"{field}={float(value)!r} is outside the valid range {re.escape(valid)}"):
        load_manifest(m)
    assert main(["diagnose", str(m), "--out", str(tmp_path / "o")]) == 2
    one_error_line(capsys, f"{field}={float(value)!r} is outside the valid range")


def test_noise_um_range(tmp_path):
    f = tmp_path / "map.npz"
    f.write_bytes(b"")
    entry = {"kind": "surface", "file": "map.npz", "temperature_K": 128}
    with pytest.raises(ValueError, match=r"noise_um=1e-300 is outside the valid range \[1e-06, 10\] µm"):
        parse_manifest({"measurement": [{**entry, "noise_um": 1e-300}]}, tmp_path)


def test_unreachable_dask_scheduler_is_one_line(tmp_path):
    pytest.importorskip("distributed")
    from pipeline.sweeps.sweep import run_sweep

    with pytest.raises(ConnectionError) as e:
        run_sweep(abs, [{"x": 1.0}], tmp_path / "s", namespace="t", scheduler="tcp://127.0.0.1:9",
                  connect_timeout_s=0.5, progress=False)
    line = describe(e.value)
    assert "\n" not in line and "cannot reach Dask scheduler at 'tcp://127.0.0.1:9'" in line
    assert "scheduler=None" not in line  # an API argument the sweep command does not have


# ------------------------------------------------------------------ paths
@pytest.mark.parametrize("where", ["../outside.csv", "ABSOLUTE", "link.csv"])
def test_manifest_paths_leaving_its_directory_need_the_flag(where, tmp_path, capsys):
    outside = tmp_path / "outside.csv"
    m = _profile_manifest(tmp_path / "data")
    outside.write_text((tmp_path / "data" / "p.csv").read_text())
    if where == "link.csv":
        (tmp_path / "data" / "link.csv").symlink_to(outside)
    field = str(outside) if where == "ABSOLUTE" else where
    m.write_text(m.read_text().replace("file = 'p.csv'", f"file = '{field}'"))
    with pytest.raises(ValueError, match=r"leaves the manifest's directory .*--allow-outside-paths "
                                         r"\(API: allow_outside=True\)"):
        load_manifest(m)
    assert load_manifest(m, allow_outside=True).measurements[0].file.resolve() == outside.resolve()
    assert main(["diagnose", str(m), "--out", str(tmp_path / "o")]) == 2
    one_error_line(capsys, "--allow-outside-paths")


def test_manifest_paths_inside_its_directory_resolve_against_it(tmp_path, monkeypatch):
    m = _profile_manifest(tmp_path / "data")
    sub = tmp_path / "data" / "profiles"
    sub.mkdir()
    (tmp_path / "data" / "p.csv").rename(sub / "p.csv")
    m.write_text(m.read_text().replace("file = 'p.csv'", "file = 'profiles/../profiles/p.csv'"))
    monkeypatch.chdir(tmp_path)  # the working directory plays no part
    assert load_manifest(Path("data/m.toml")).measurements[0].file.resolve() == (sub / "p.csv").resolve()
    nominal = tmp_path / "nominal.npz"
    nominal.write_bytes(b"")
    m.write_text(f"[simulation]\nsag_file = '{nominal}'\n" + m.read_text())
    with pytest.raises(ValueError, match=r"\[simulation\] sag_file=.* leaves the manifest's directory"):
        load_manifest(m)


def test_render_child_works_in_the_callers_directory(tmp_path, monkeypatch):
    """The child starts in the caller's directory with the output as an absolute path; a
    'pipeline' package there does not shadow the toolkit's."""
    from pipeline.study.render3d import StudyRender

    decoy = tmp_path / "pipeline"
    decoy.mkdir()
    (decoy / "__init__.py").write_text("raise ImportError('decoy package imported')\n")
    monkeypatch.chdir(tmp_path)
    seen = {}
    real_popen = subprocess.Popen

    def spy(cmd, **kw):
        seen.update(cmd=cmd, cwd=kw.get("cwd"))
        return real_popen(cmd, **kw)

    monkeypatch.setattr(subprocess, "Popen", spy)
    render = StudyRender(Path("rel_out"), {}, timeout_s=120, progress=False)
    res = render.result()
    assert res["error"] is None, res["error"]
    assert Path(seen["cwd"]) == tmp_path
    study = Path(seen["cmd"][seen["cmd"].index("--study") + 1])
    assert study.is_absolute() and study == tmp_path / "rel_out"
    assert not (REPO / "rel_out").exists()


def test_element_sizes_are_checked_before_any_case(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr("pipeline.sweeps.fea_cases.run_tables", never)
    monkeypatch.setattr("pipeline.study.run.run_study", never)
    for argv, needle in ((["tables", "--mesh-size-mm", "0"], "--mesh-size-mm 0.0 must be a finite number > 0"),
                         (["run", "--mesh-size-mm", "nan"], "--mesh-size-mm nan must be"),
                         (["tables", "--mesh-size-mm", "3", "--mesh-bulk-mm", "2"], "--mesh-bulk-mm 2.0 must be >=")):
        assert main([*argv, "--out", str(tmp_path / "o")]) == 2
        one_error_line(capsys, needle)


def test_a_config_key_is_not_renamed_to_an_option_the_user_did_not_give(tmp_path, capsys):
    cfg = tmp_path / "s.toml"
    cfg.write_text("[fea]\nmesh_size_mm = -1\n")
    assert main(["config", "--check", str(cfg)]) == 2
    line = one_error_line(capsys, "fea.mesh_size_mm")
    assert "--mesh-size-mm" not in line  # it came from the file, not from an option
    assert main(["run", str(cfg), "--out", str(tmp_path / "o")]) == 2
    assert "--mesh-size-mm" not in one_error_line(capsys, "mesh_size_mm")


@pytest.mark.parametrize("value", ["-1", "nan", "inf", "1e12", "2.5"])
def test_quilt_amplitude_named_as_the_option(value, tmp_path, capsys):
    assert main(["lsf", "--grating", "J", "--wavelength-um", "1.25", "--pixel-scale-mas", "25", "--quilt-pv-um",
                 value, "--out", str(tmp_path / "o")]) == 2
    one_error_line(capsys, f"--quilt-pv-um {float(value)} must be a finite number >= 0")


def test_dense_scattered_points_name_no_option_psf_lacks(tmp_path, capsys):
    """Scattered points along a 280 mm diagonal within 0.1 µm of it: one node per point
    over their hull (area ~0.04 mm²) would need (200 mm / 9 µm)^2 nodes; the message
    names no spacing option, which psf does not have."""
    rng = np.random.default_rng(3)
    t = rng.uniform(-100, 100, 500)
    xy = np.column_stack([t, t + rng.uniform(-1e-4, 1e-4, t.size)])
    f = tmp_path / "points.csv"
    np.savetxt(f, np.column_stack([xy, np.zeros(len(xy))]), delimiter=",", header="x_mm,y_mm,sag_um", comments="",
               fmt="%.9f")
    assert main(["psf", "--grating", "J", "--wavelength-um", "1.25", "--sag", str(f),
                 "--out", str(tmp_path / "o")]) == 2
    line = one_error_line(capsys, "sqrt(hull area / points)")
    assert "spacing_mm" not in line and "--spacing" not in line


@pytest.mark.parametrize("argv, needle", [
    (["--param", "hole_diameter_mm"], "--param 'hole_diameter_mm': expected NAME=VALUES"),
    (["--surrogate", "--workers", "2"], "--surrogate runs in this process (milliseconds per case); drop"),
])
def test_sweep_option_mistakes_take_the_error_path(argv, needle, tmp_path, capsys):
    assert main(["sweep", "--t0-um", "200", *argv, "--out", str(tmp_path / "o")]) == 2
    one_error_line(capsys, f"cryograting sweep: error: {needle}")
