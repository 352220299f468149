"""Re-run chosen cases of a recorded campaign with the engine as it is now: the same
configuration, criteria, seed and case indices as the raw file records, each case's row
(the campaign's own ``run_case``) appended as one JSON line to ``--out``.

    .venv/bin/python benchmarks/rerun_cases.py RAW.json INDEX [INDEX ...] --out ROWS.jsonl
        [--cache-dir DIR] [--map-in-optics on|off|as-recorded] [--state-correlated-noise on|off|as-recorded]

Used where an engine change acts on a few recorded cases only (the rows of
``results_departure_choice.md``): the other cases' rows stay those of the recorded run.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path

from pipeline.diagnosis.campaign import CampaignConfig, campaign_maps, case_type, one_blas_thread, run_case
from pipeline.diagnosis.criteria import Criteria

#: configuration fields that a raw file stores as lists and the config holds as tuples
_TUPLE_FIELDS = ("case_types", "profile_specs", "truth_families", "only_types", "psf_image")


def _as_tuples(v):
    return tuple(_as_tuples(x) for x in v) if isinstance(v, list) else v


def recorded_config(raw: dict, map_in_optics: str = "as-recorded",
                    state_correlated_noise: str = "as-recorded") -> CampaignConfig:
    """The campaign configuration (one worker) and criteria a raw file records; ``on`` /
    ``off`` override the map in the optics and the stated correlated noise."""
    known = {f.name for f in dataclasses.fields(Criteria)}
    crit = Criteria(**{k: _as_tuples(v) for k, v in raw["criteria"].items() if k in known})
    if map_in_optics != "as-recorded":
        crit = dataclasses.replace(crit, map_in_optics=map_in_optics == "on")
    fields = {f.name for f in dataclasses.fields(CampaignConfig)}
    cfg = {k: (_as_tuples(v) if k in _TUPLE_FIELDS else v) for k, v in raw["config"].items() if k in fields}
    if state_correlated_noise != "as-recorded":
        cfg["state_correlated_noise"] = state_correlated_noise == "on"
    return CampaignConfig(**{**cfg, "workers": 1}, criteria=crit)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("raw", type=Path, help="a campaign's raw JSON (bench_diagnosis.py --out)")
    ap.add_argument("index", type=int, nargs="+", help="case indices to re-run")
    ap.add_argument("--out", type=Path, required=True, help="JSON lines file the rows are appended to")
    ap.add_argument("--cache-dir", type=Path, default=None, help="disk cache of the nominal FEA maps")
    ap.add_argument("--map-in-optics", choices=("on", "off", "as-recorded"), default="as-recorded")
    ap.add_argument("--state-correlated-noise", choices=("on", "off", "as-recorded"), default="as-recorded",
                    help="the profiles' manifests state the truth detector's correlated noise")
    a = ap.parse_args(argv)
    raw = json.loads(a.raw.read_text()).get("campaign")
    if not isinstance(raw, dict) or not {"config", "criteria", "cases"} <= set(raw):
        ap.error(f"raw={str(a.raw)!r}: not a campaign's raw JSON (needs 'campaign' with 'config', 'criteria', 'cases', "
                 "as bench_diagnosis.py --out writes it)")
    cfg = recorded_config(raw, a.map_in_optics, a.state_correlated_noise)
    bad = [i for i in a.index if not 0 <= i < cfg.n_cases]
    if bad:
        ap.error(f"index {bad}: the recorded campaign has cases 0..{cfg.n_cases - 1}")
    one_blas_thread()
    nominal, base = campaign_maps(cfg, cache_dir=a.cache_dir)
    for i in a.index:
        row = run_case((i, case_type(cfg, i), cfg, nominal, base))
        with a.out.open("a") as fh:
            fh.write(json.dumps(row, default=float) + "\n")
        print(i, row["effect"], row["top"], row["verdict"], flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
