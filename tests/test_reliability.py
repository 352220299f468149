"""Bad input and faults on the optics commands: one clear line, nothing half-written.

Expected values come from the grating equation written out here, not from the code
under test.
"""
import math

import numpy as np
import pytest

from optics.grating import MAX_GRATING_TURN_DEG, get_grating
from optics.lineprofile import line_profile, point_psf
from pipeline.io.common import ensure_writable_dir
from pipeline.optics_cli import main as optics_main


@pytest.mark.parametrize("name,wavelength_um,order", [("J", 1.10, -2), ("H", 1.25, -3), ("K", 1.25, -4),
                                                        ("HK", 2.45, -1)])
def test_turned_grating_sends_the_line_along_the_camera_axis(name, wavelength_um, order):
    """After turning by turn_deg, beta - alpha equals the design deviation (grating equation)."""
    g = get_grating(name)
    alpha = g.incidence_deg
    m0, lam0, d = g.order, g.centre_um, g.groove_spacing_um
    deviation = math.degrees(math.asin(m0 * lam0 / d - math.sin(math.radians(alpha)))) - alpha
    t = g.turn_deg(wavelength_um, order)
    beta = math.degrees(math.asin(order * wavelength_um / d - math.sin(math.radians(alpha + t))))
    assert beta - (alpha + t) == pytest.approx(deviation, abs=1e-9)
    assert abs(t) <= MAX_GRATING_TURN_DEG


def test_a_line_far_outside_the_band_is_refused_with_the_valid_range():
    with pytest.raises(ValueError, match=r"wavelength_um=4\.5 in order -2 .* valid for turns up to 5 deg: "
                                         r"0\.79\d+\.\.1\.69\d+ um"):
        line_profile("J", 4.5, 250, None)
    lo, hi = get_grating("J").domain_um()
    for w in (lo * 1.001, hi * 0.999):
        get_grating("J").check_in_domain(w)
    for w in (lo * 0.99, hi * 1.01):
        with pytest.raises(ValueError, match="turned by"):
            get_grating("J").check_in_domain(w)


@pytest.mark.parametrize("kw,match", [
    (dict(detector_step_um=0.0), r"detector_step_um=0\.0 must be a finite number > 0"),
    (dict(detector_step_um=float("nan")), r"detector_step_um=nan must be a finite number > 0"),
    (dict(window_um=0.0), r"window_um=0\.0 must be a finite number > 0"),
    (dict(window_um=float("nan")), r"window_um=nan must be"),
    (dict(window_um=1e6), r"window_um=1e\+06 is outside .*\.\.256 um"),
    (dict(detector_step_um=1e-4), r"detector_step_um=0\.0001 is so fine .* valid: "),
    (dict(detector_step_um=5.0), r"detector_step_um=5 is coarser than the PSF's Nyquist step"),
])
def test_psf_sampling_outside_what_the_fft_delivers_is_refused(kw, match):
    with pytest.raises(ValueError, match=match):
        point_psf("J", 1.25, None, **kw)


def test_psf_nyquist_limit_is_lambda_f_over_d():
    """The coarsest step the pupil allows is lambda f_cam / D on the finer axis."""
    g = get_grating("J")
    anam = float(g.anamorphic_factor(1.25))
    limit_um = 1.25 * 342.0 * min(anam, 1.0) / 110.0
    point_psf("J", 1.25, None, detector_step_um=0.99 * limit_um, window_um=50.0, collimator_zernike_um=None)
    with pytest.raises(ValueError, match="coarser"):
        point_psf("J", 1.25, None, detector_step_um=1.01 * limit_um, window_um=50.0)


@pytest.mark.parametrize("args,needle", [
    (["psf", "--detector-step-um", "0"], "--detector-step-um 0.0 must be"),
    (["psf", "--window-um", "nan"], "--window-um nan must be"),
    (["psf", "--wavelength-um", "4.5"], "--wavelength-um 4.5 in order"),
    (["lsf", "--pixel-scale-mas", "100", "--wavelength-um", "4.5"], "--wavelength-um 4.5 in order"),
])
def test_optics_commands_fail_in_one_line(args, needle, tmp_path, capsys):
    base = ["--grating", "J", "--quilt-pv-um", "0", "--out", str(tmp_path / "o")]
    if "--wavelength-um" not in args:
        base += ["--wavelength-um", "1.25"]
    with pytest.raises(SystemExit) as e:
        optics_main(args + base)
    assert e.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and needle in err[0] and "Traceback" not in err[0]


def test_output_dir_that_is_a_file_is_refused_before_any_work(tmp_path):
    f = tmp_path / "taken"
    f.write_text("x")
    with pytest.raises(NotADirectoryError, match=r"--out .*taken' exists and is not a directory"):
        ensure_writable_dir(f, "--out")
    assert ensure_writable_dir(tmp_path / "a" / "b", "--out").is_dir()


def test_psf_npz_is_not_left_half_written(tmp_path, monkeypatch, capsys):
    """A failure while writing (a full disk) leaves no psf.npz under the final name."""
    def full_disk(*a, **k):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(np, "savez_compressed", full_disk)
    out = tmp_path / "o"
    with pytest.raises(SystemExit) as e:
        optics_main(["psf", "--grating", "J", "--wavelength-um", "1.25", "--quilt-pv-um", "0",
                     "--window-um", "20", "--out", str(out)])
    assert e.value.code == 2
    assert "No space left on device" in capsys.readouterr().err
    assert not (out / "psf.npz").exists()
    assert not list(out.glob(".psf.npz*"))


def test_cold_above_warm_is_refused_unless_heating_is_asked_for():
    from fea.model import ThermalLoad
    from pipeline.study.config import loads_study_config
    from pipeline.study.schema import ConfigError

    with pytest.raises(ValueError, match=r"cold_K=300 K must be below warm_K=293 K"):
        ThermalLoad(warm_K=293.0, cold_K=300.0)
    assert ThermalLoad(warm_K=293.0, cold_K=300.0, heating=True).cold_K == 300.0
    with pytest.raises(ConfigError, match=r"cold_K.*must be below warm_K"):
        loads_study_config("[fea]\ncold_K = 295\n")

