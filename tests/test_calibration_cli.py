"""`cryograting calibrate`: the fit on a model with a known answer, and output checked first."""

from types import SimpleNamespace

import numpy as np
import pytest

from fea.calibration import calibrate, paper_cases


class _KnownModel:
    """Gives every paper case the P/V paper / 0.8 at scale 1, so the fitted scale is 0.8
    and every residual of the used rows is zero."""

    ndof = 123

    def __init__(self):
        self.pv = {(c.coverage, c.t0_um, c.polish): c.pv_center_um / 0.8 for c in paper_cases()}

    def solve(self, coating, stress_scale):
        assert stress_scale == 1.0
        pv = self.pv[(coating.coverage, coating.t0_um, coating.polish_front)]
        return SimpleNamespace(sag=SimpleNamespace(pv_um=lambda region: pv))


def test_calibrate_fits_the_scale_of_a_model_with_a_known_answer():
    seen = []
    cal = calibrate(_KnownModel(), progress=lambda c, pv: seen.append(c.label))
    assert cal.scale == pytest.approx(0.8, rel=1e-12)
    assert np.allclose(cal.residuals, 0.0, atol=1e-12) and cal.ndof == 123
    assert len(seen) == 15 and int(cal.used.sum()) == 12       # Table 1 (9) + holes-only (3)


def test_calibrate_command_writes_the_fit(tmp_path, monkeypatch, capsys):
    import fea.api
    from pipeline.cli import main

    monkeypatch.setattr(fea.api, "prepare", lambda blank, mesh, substrate: _KnownModel())
    assert main(["calibrate", "--out", str(tmp_path), "--quiet", "--mesh-size-mm", "5", "--mesh-bulk-mm", "10"]) == 0
    assert "STRESS_SCALE = 0.8000" in capsys.readouterr().out
    rows = (tmp_path / "calibration.csv").read_text().splitlines()
    assert rows[0] == "case,paper_pv_um,model_pv_scale1_um,calibrated_error,used" and len(rows) == 16


def test_calibrate_checks_its_output_and_mesh_before_solving(tmp_path, monkeypatch, capsys):
    import fea.api
    from pipeline.cli import main

    def no_mesh(*args, **kwargs):
        raise AssertionError("meshed before the checks")

    monkeypatch.setattr(fea.api, "prepare", no_mesh)
    blocker = tmp_path / "file"
    blocker.write_text("x")
    assert main(["calibrate", "--out", str(blocker)]) == 2
    assert str(blocker) in capsys.readouterr().err
    assert main(["calibrate", "--mesh-size-mm", "0.01", "--mesh-bulk-mm", "0.02"]) == 2
    assert "--mesh-size-mm 0.01" in capsys.readouterr().err  # the option as the command spells it
