"""``benchmarks/rerun_cases.py`` re-runs recorded campaign cases: the configuration it rebuilds
from a raw file is the recorded one (its seed, case list and profile map; the criteria, with
the map in the optics switched only when asked), and an index outside the campaign is refused
naming the valid range."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
RAW = ROOT / "benchmarks" / "frozen_fifteenth_raw_map.json"


def _module():
    spec = importlib.util.spec_from_file_location("rerun_cases", ROOT / "benchmarks" / "rerun_cases.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_the_recorded_configuration_is_rebuilt():
    mod = _module()
    raw = json.loads(RAW.read_text())["campaign"]
    cfg = mod.recorded_config(raw)
    assert (cfg.seed, cfg.n_cases, cfg.profile_map_K, cfg.workers) == (20261139, 45, 128.0, 1)
    assert cfg.case_types == tuple(tuple(t) for t in raw["config"]["case_types"])
    assert cfg.criteria.map_in_optics is True and cfg.criteria.heldout_top == raw["criteria"]["heldout_top"]
    assert mod.recorded_config(raw, "off").criteria.map_in_optics is False


def test_an_index_outside_the_campaign_is_refused(tmp_path, capsys):
    with pytest.raises(SystemExit):
        _module().main([str(RAW), "45", "--out", str(tmp_path / "rows.jsonl")])
    assert "index [45]: the recorded campaign has cases 0..44" in capsys.readouterr().err


def test_case_indices_map_to_the_recorded_types():
    """Each recorded row's (kind, effect) is the type the rebuilt configuration gives its index."""
    from pipeline.diagnosis.campaign import case_type

    raw = json.loads(RAW.read_text())["campaign"]
    cfg = _module().recorded_config(raw)
    assert all(case_type(cfg, r["index"]) == (r["kind"], r["effect"]) for r in raw["cases"])


def test_a_file_that_is_not_a_campaign_is_refused(tmp_path, capsys):
    bad = tmp_path / "other.json"
    bad.write_text('{"summary": {}}')
    with pytest.raises(SystemExit):
        _module().main([str(bad), "0", "--out", str(tmp_path / "rows.jsonl")])
    assert "not a campaign's raw JSON" in capsys.readouterr().err
