"""Bounded work: every size a user can blow up is capped before work starts, and a run
estimated over an hour says so in its first line.

Every bad input is generated here (TOML text, value lists, campaign sizes). The caps are
the stated ones of pipeline/bounds.py; work that must not start is replaced by a stub that
fails the test if it is called, and the estimates use the tabulated per-case seconds.
"""

from __future__ import annotations

import numpy as np
import pytest

import pipeline.study.cases as cases_module
import pipeline.study.config as config_module
import pipeline.study.profile_specs as profile_specs_module
import pipeline.study.study_config as study_config_module
from cli_checks import never, one_error_line
from pipeline.bounds import (LONG_RUN_S, MAX_CAMPAIGN_CASES, MAX_FEA_CASES, MAX_PROFILE_JOBS, SECONDS,
                             campaign_seconds, warn_if_long)
from pipeline.cli import main
from pipeline.study.cases import CaseSelector, FEAGroup
from pipeline.study.config import loads_study_config
from pipeline.study.schema import ConfigError
from pipeline.study.study_config import StudyConfig
from pipeline.diagnosis.campaign import CampaignConfig
from pipeline.diagnosis.manifest import parse_manifest


# ------------------------------------------------------------------ bounded work
def _lower_cap(monkeypatch, name, value, *modules):
    """Lower one cap of pipeline/bounds.py in every study module that enforces it."""
    for module in modules:
        monkeypatch.setattr(module, name, value)


def test_study_case_cap_refused_before_any_case_is_validated(monkeypatch):
    monkeypatch.setattr(cases_module, "_check_case", never)
    text = "[fea]\nt0_um = {start = 0.1, stop = 2000, num = %d}\n" % (MAX_FEA_CASES + 1)
    with pytest.raises(ConfigError, match=rf"fea: {MAX_FEA_CASES + 1} FEA cases is outside the valid range "
                                          rf"1\.\.{MAX_FEA_CASES}"):
        loads_study_config(text)


def test_case_cap_counts_every_table_of_the_study(monkeypatch):
    _lower_cap(monkeypatch, "MAX_FEA_CASES", 5, config_module, cases_module, study_config_module)
    text = ("[fea]\nmesh_size_mm = 5\nmesh_bulk_mm = 5\n[[fea.cases]]\nt0_um = [100, 150, 200]\n"
            "[[fea.cases]]\nname = 'b'\nt0_um = [120, 170, 220]\n")
    with pytest.raises(ConfigError, match=r"fea\.cases\[1\]: 6 FEA cases up to this table .* 1\.\.5"):
        loads_study_config(text)
    groups = [FEAGroup(f"g{i}", {"t0_um": [100 + i, 200 + i], "mesh_size_mm": 5, "mesh_bulk_mm": 5})
              for i in range(3)]
    with pytest.raises(ConfigError, match=r"fea: 6 FEA cases in the study is outside the valid range 1\.\.5"):
        StudyConfig(fea=groups)


def test_profile_cap_refused_before_the_grating_equation_runs():
    n = MAX_PROFILE_JOBS + 1
    text = f"[[profiles]]\ngrating = 'J'\npixel_scale_mas = 25\nwavelength_um = '1.1:1.4:{n}n'\n"
    with pytest.raises(ConfigError, match=rf"profiles\[0\]: {n} line profiles in one \[\[profiles\]\] table "
                                          rf"is outside the valid range 1\.\.{MAX_PROFILE_JOBS}"):
        loads_study_config(text)


def test_profile_cap_counts_the_whole_study(monkeypatch):
    _lower_cap(monkeypatch, "MAX_PROFILE_JOBS", 10, profile_specs_module, study_config_module)
    # 2 tables x 3 pixel scales x (perfect + 1 case) = 12 profiles
    table = "[[profiles]]\ngrating = 'J'\ndeformation = ['perfect', {t0_um = 200}]\n"
    text = "[fea]\nmesh_size_mm = 5\nmesh_bulk_mm = 5\n" + table + table.replace("'J'", "'K'")
    with pytest.raises(ConfigError, match=r"profiles: 12 line profiles in the study .* 1\.\.10"):
        loads_study_config(text)


def _selector_study(n):
    vals = [round(100 + 0.5 * i, 1) for i in range(n)]
    sels = ", ".join(f"{{t0_um = {v}}}" for v in vals)
    return (f"[fea]\nt0_um = {vals}\nmesh_size_mm = 5\nmesh_bulk_mm = 5\n"
            f"[[profiles]]\ngrating = 'J'\npixel_scale_mas = 25\ndeformation = ['perfect', {sels}]\n")


def test_config_check_is_linear_in_the_number_of_cases(monkeypatch):
    """A selector per case: value lookups grow as the cases (a scan per selector grew as n^2)."""
    calls = {"n": 0}
    token = study_config_module.canonical_token

    def counting(v):
        calls["n"] += 1
        return token(v)

    monkeypatch.setattr(study_config_module, "canonical_token", counting)
    counts = []
    for n in (150, 300):
        calls["n"] = 0
        cfg = loads_study_config(_selector_study(n))
        assert cfg.n_profile_jobs() == len(cfg.profile_jobs()) == n + 1
        counts.append(calls["n"])
    assert counts[1] / counts[0] < 2.5, counts  # quadratic would be ~4
    # the index finds exactly what CaseSelector.matches finds
    cfg = loads_study_config(_selector_study(20) + "[[fea.cases]]\nname = 'a'\n[[fea.cases]]\nname = 'hot'\n"
                             "cold_K = 120\n")
    for sel in [{"t0_um": 100.5}, {"group": "hot"}, {"group": "hot", "t0_um": 101.0}, {"cold_K": 80}]:
        s = CaseSelector(sel)
        assert cfg.select(s) == [c for c in cfg.cases() if s.matches(c)]


def test_sweep_past_its_cap_is_refused_before_anything_is_written(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr("pipeline.sweeps.fea_cases.run_fea_sweep", never)
    out = tmp_path / "sweep"
    assert main(["sweep", "--param", "t0_um=1:2000:0.1", "--out", str(out), "--quiet"]) == 2
    one_error_line(capsys, f"19991 sweep cases (the product of the value lists given) is outside the valid "
                            f"range 1..{MAX_FEA_CASES}")
    assert not out.exists()


def test_fea_sweep_api_cap():
    from pipeline.sweeps.fea_cases import run_fea_sweep

    with pytest.raises(ValueError, match=rf"cases=20000 is outside the valid range 1\.\.{MAX_FEA_CASES}"):
        run_fea_sweep({"t0_um": list(np.linspace(1, 2000, 200)), "polish": list(np.linspace(0.01, 1, 100))},
                      "unused")


@pytest.mark.parametrize("n", [0, -1, MAX_CAMPAIGN_CASES + 1])
def test_campaign_size_outside_its_range_is_refused(n, tmp_path, capsys, monkeypatch):
    monkeypatch.setattr("pipeline.diagnosis.campaign.run_campaign", never)
    with pytest.raises(ValueError, match=rf"n_cases={n} must be an integer in the valid range "
                                         rf"1\.\.{MAX_CAMPAIGN_CASES}"):
        CampaignConfig(n_cases=n)
    assert main(["diagnose", "--validate", "--cases", str(n), "--out", str(tmp_path / "o")]) == 2
    one_error_line(capsys, f"--cases {n} is outside the valid range 1..{MAX_CAMPAIGN_CASES}")
    with pytest.raises(ValueError, match="workers=0 must be an integer >= 1"):
        CampaignConfig(workers=0)


def test_long_run_warning_is_one_line_and_only_past_an_hour(capsys):
    assert not warn_if_long(LONG_RUN_S, "x", "d")
    assert capsys.readouterr().err == ""
    assert warn_if_long(2 * 86400 + 1, "sweep", "50000 FEA cases x ~3.5 s")
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and "cryograting sweep: warning: estimated run time 2.0 days (50000 FEA cases" in err[0]
    # a campaign case is one core's work; two workers halve the wall time, more do not (2 cores)
    assert campaign_seconds(100, 2, False, False) == pytest.approx(100 * SECONDS["campaign_profiles"] / 2)
    assert campaign_seconds(100, 8, True, True) == campaign_seconds(100, 2, True, True)


def _stop(*a, **k):
    raise ValueError("stub: stopped after the estimate")


def test_sweep_run_and_campaign_warn_up_front(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr("pipeline.sweeps.fea_cases.run_fea_sweep", _stop)
    n = int(LONG_RUN_S / SECONDS["fea_case"]) + 50  # just past an hour of default-mesh cases
    assert main(["sweep", "--param", f"t0_um=1:2000:{n}n", "--out", str(tmp_path / "s"), "--quiet"]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 2 and "warning: estimated run time" in err[0] and f"{n} FEA cases" in err[0]
    assert "stub" in err[1]
    assert main(["sweep", "--t0-um", "100", "200", "--out", str(tmp_path / "s"), "--quiet"]) == 2
    assert "warning" not in capsys.readouterr().err  # two cases: seconds

    monkeypatch.setattr("pipeline.study.run._run_fea", _stop)
    cfg = tmp_path / "big.toml"
    cfg.write_text(f"[fea]\nt0_um = {{start = 1, stop = 2000, num = {n}}}\n")
    assert main(["run", str(cfg), "--out", str(tmp_path / "r"), "--quiet"]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 2 and "cryograting run: warning: estimated run time" in err[0] and "stub" in err[1]

    monkeypatch.setattr("pipeline.diagnosis.campaign.run_campaign", _stop)
    cases = int(2 * LONG_RUN_S / SECONDS["campaign_profiles"]) + 10
    assert main(["diagnose", "--validate", "--cases", str(cases), "--workers", "2", "--out", str(tmp_path / "c")]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 2 and "cryograting diagnose: warning" in err[0] and f"{cases} campaign cases" in err[0]


def test_manifest_measurement_count_is_capped_before_any_file_is_read(tmp_path):
    from pipeline.bounds import MAX_MEASUREMENTS

    entries = [{"kind": "line_profile", "file": f"p{i}.csv"} for i in range(MAX_MEASUREMENTS + 1)]
    with pytest.raises(ValueError, match=rf"{MAX_MEASUREMENTS + 1} \[\[measurement\]\] entries, outside the valid "
                                         rf"range 1\.\.{MAX_MEASUREMENTS}"):
        parse_manifest({"measurement": entries}, tmp_path)


@pytest.mark.parametrize("command", [["sweep", "--t0-um", "200"], ["diagnose", "--validate", "--cases", "2"]])
@pytest.mark.parametrize("workers", [0, 10_000])
def test_worker_count_outside_its_range_is_refused_before_work(command, workers, tmp_path, capsys, monkeypatch):
    from pipeline.bounds import max_workers

    monkeypatch.setattr("pipeline.sweeps.fea_cases.run_fea_sweep", never)
    monkeypatch.setattr("pipeline.diagnosis.campaign.run_campaign", never)
    assert main([*command, "--workers", str(workers), "--out", str(tmp_path / "o")]) == 2
    one_error_line(capsys, f"--workers {workers} is outside the valid range 1..{max_workers()}")


def test_config_check_states_the_estimate(capsys):
    """The paper's study: 15 FEA cases at the default mesh and its line profiles."""
    assert main(["config", "--preset", "paper_default"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[1].startswith("estimated run time: ~") and "15 FEA cases x ~3.5 s" in out[1]


def test_surrogate_validation_solves_are_capped(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr("pipeline.sweeps.surrogate.run_surrogate_sweep", never)
    assert main(["sweep", "--surrogate", "--t0-um", "100", "200", "--validate", str(MAX_FEA_CASES + 1),
                 "--out", str(tmp_path / "o")]) == 2
    one_error_line(capsys, f"--validate {MAX_FEA_CASES + 1} is outside the valid range 0..{MAX_FEA_CASES}")


def test_surrogate_sweep_api_caps():
    from pipeline.bounds import MAX_SURROGATE_CASES
    from pipeline.sweeps.surrogate import run_surrogate_sweep

    with pytest.raises(ValueError, match=rf"validate={MAX_FEA_CASES + 1} is outside the valid range 0\.\."):
        run_surrogate_sweep({"t0_um": [100.0, 200.0]}, "unused", validate=MAX_FEA_CASES + 1)
    n_t0, n_polish = 1000, MAX_SURROGATE_CASES // 1000 + 1
    with pytest.raises(ValueError, match=rf"cases={n_t0 * n_polish} is outside the valid range "
                                         rf"1\.\.{MAX_SURROGATE_CASES}"):
        run_surrogate_sweep({"t0_um": list(np.linspace(1, 2000, n_t0)),
                             "polish": list(np.linspace(0.001, 1, n_polish))}, "unused")
