"""Benchmark of the sim-to-real diagnosis: the three paper scenarios and the
injection-recovery campaign. Writes the per-case rows and the summary as JSON (``--out``);
``benchmarks/results_diagnosis.md`` gives the tables and the command behind each.

    .venv/bin/python benchmarks/bench_diagnosis.py [--cases 208] [--workers 2] [--seed 1] [--cache-dir DIR]
        [--profiles extended|minimal] [--no-scenarios] [--out FILE] [--progress FILE.jsonl] [--profile-map-K K]
        [--psf-image] [--types KIND:EFFECT,...] [--discrepancy unmodelled|companions]
        [--n-eff-from nominal|best_fit] [--truth independent|model] [--truth-families FAM,...]
        [--error-model by_kind|n_eff|two_part] [--pair-forward] [--pair-from N] [--diagnosis-criteria]
        [--weight-scale measurement|kind] [--pair-second significant|improving] [--no-map-in-optics]

``--progress``: every finished case is appended there as a JSON line (partial results
survive an interrupted run). ``--profiles``: the campaign's line-profile measurement set
(:data:`pipeline.diagnosis.campaign.PROFILE_SETS`). ``--profile-map-K 128``: the line-profile
cases also get a 128 K map of the same blank (``CampaignConfig.profile_map_K``).
``--truth-families pocket_jitter,sharp_ribs``: the independent truth's grating families
(``CampaignConfig.truth_families``; default ``sum_mix,product_mix``). ``--pair-from``: how
many of the best singles are paired (``Criteria.pair_from``; the campaign's default is 2, the
diagnosis's own 3). ``--diagnosis-criteria``: the campaign diagnoses with the diagnosis's own
``Criteria()`` (pairs among 3 singles, held-out checks of the 3 best findings) instead of the
campaign's narrower, faster ``CampaignConfig.criteria`` (2 and 1): the score of the product
as a user runs it. ``--weight-scale``: what each measurement's weight is normalised by
(``Criteria.weight_scale``). ``--pair-second``: with the forward pair step, which further
singles are paired with the best one (``Criteria.pair_second``).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from pathlib import Path

from pipeline.diagnosis import diagnose
from pipeline.diagnosis.criteria import PAIR_SECONDS, WEIGHT_SCALES
from pipeline.diagnosis.engine import N_EFF_SOURCES, Criteria
from pipeline.diagnosis.error_model import ERROR_MODELS
from pipeline.diagnosis.campaign import (DISCREPANCIES, PROFILE_SETS, PSF_IMAGE_SPEC, TRUTHS, CampaignConfig, parse_types,
                                         run_campaign)

HERE = Path(__file__).parent
SCEN = HERE.parent / "pipeline" / "scenarios"


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--cases", type=int, default=208)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--cache-dir", default=None)
    ap.add_argument("--profiles", default="extended", choices=sorted(PROFILE_SETS))
    ap.add_argument("--no-scenarios", action="store_true")
    ap.add_argument("--out", default=str(HERE / "results_diagnosis_raw.json"))
    ap.add_argument("--progress", default=None)
    ap.add_argument("--profile-map-K", type=float, default=None,
                    help="also a cold map at this temperature beside the line profiles (the paper's data set)")
    ap.add_argument("--psf-image", action="store_true", help="also a focal-plane point-source image beside the profiles")
    ap.add_argument("--types", default=None, help="only these case types (kind:effect,...), same case indices")
    ap.add_argument("--discrepancy", default="unmodelled", choices=sorted(DISCREPANCIES),
                    help="the truth's model discrepancy (CampaignConfig.discrepancy)")
    ap.add_argument("--n-eff-from", default="nominal", choices=N_EFF_SOURCES,
                    help="residual the effective sample counts come from (Criteria.n_eff_from)")
    ap.add_argument("--truth", default="independent", choices=TRUTHS,
                    help="campaign truth generator (CampaignConfig.truth; benchmarks/truth_families.md)")
    ap.add_argument("--truth-families", default="sum_mix,product_mix",
                    help="independent truth's grating families, comma-separated (benchmarks/truth_families.md)")
    ap.add_argument("--state-correlated-noise", action="store_true",
                    help="the profiles' manifests state the correlated noise the truth's detector drew "
                         "(CampaignConfig.state_correlated_noise)")
    ap.add_argument("--error-model", default=Criteria().error_model, choices=ERROR_MODELS,
                    help="the score's error model (Criteria.error_model)")
    ap.add_argument("--pair-forward", action="store_true",
                    help="also pair the best single with every other (Criteria.pair_forward)")
    ap.add_argument("--pair-from", type=int, default=None,
                    help=f"pairs among this many best singles (Criteria.pair_from; campaign default "
                         f"{CampaignConfig.criteria.pair_from}, the diagnosis's own {Criteria().pair_from})")
    ap.add_argument("--diagnosis-criteria", action="store_true",
                    help="diagnose with the diagnosis's own Criteria() (as a user runs it), not the campaign's")
    ap.add_argument("--pair-second", default=None, choices=PAIR_SECONDS,
                    help="with --pair-forward: which further singles pair with the best (Criteria.pair_second)")
    ap.add_argument("--weight-scale", default=None, choices=WEIGHT_SCALES,
                    help="what a measurement's weight is normalised by (Criteria.weight_scale; default: the criteria's)")
    ap.add_argument("--no-map-in-optics", action="store_true",
                    help="form the profiles on the nominal alone, not on the nominal plus the map's departure "
                         "(Criteria.map_in_optics)")
    a = ap.parse_args(argv)
    base = Criteria() if a.diagnosis_criteria else CampaignConfig.criteria
    try:
        criteria = dataclasses.replace(base, n_eff_from=a.n_eff_from, error_model=a.error_model,
                                       pair_forward=a.pair_forward or base.pair_forward,
                                       pair_second=base.pair_second if a.pair_second is None else a.pair_second,
                                       pair_from=base.pair_from if a.pair_from is None else a.pair_from,
                                       weight_scale=base.weight_scale if a.weight_scale is None else a.weight_scale,
                                       map_in_optics=base.map_in_optics and not a.no_map_in_optics)
    except ValueError as exc:
        ap.error(str(exc))
    out = {"scenarios": {}}
    for name in () if a.no_scenarios else ("cryo_astigmatism", "j_repolished", "hk_amplitude"):
        t = time.perf_counter()
        d = diagnose(SCEN / name / "manifest.toml", cache_dir=a.cache_dir,
                     criteria=dataclasses.replace(Criteria(), n_eff_from=a.n_eff_from))
        b = d.best
        out["scenarios"][name] = {"verdict": d.verdict, "best": b.effect, "parameters": b.parameters,
                                  "uncertainties": b.uncertainties, "shrink": b.shrink_fraction,
                                  "heldout_shrink": b.heldout_shrink_fraction, "delta_bic": b.delta_bic,
                                  "ranking": [(f.effect, round(f.delta_bic, 1)) for f in d.findings],
                                  "seconds": time.perf_counter() - t, "timings_s": d.timings_s}
        print(name, json.dumps(out["scenarios"][name], default=float))
    cfg = CampaignConfig(n_cases=a.cases, seed=a.seed, workers=a.workers, profile_specs=PROFILE_SETS[a.profiles],
                         profile_map_K=a.profile_map_K, psf_image=PSF_IMAGE_SPEC if a.psf_image else None,
                         only_types=parse_types(a.types, a.truth), discrepancy=a.discrepancy, criteria=criteria,
                         truth=a.truth, truth_families=a.truth_families,
                         state_correlated_noise=a.state_correlated_noise)
    res = run_campaign(cfg, cache_dir=a.cache_dir, progress=a.progress)
    res["profile_set"] = a.profiles
    out["campaign"] = res
    s = res["summary"]
    print(json.dumps({k: v for k, v in s.items() if k not in ("per_type", "confusion")}, indent=1, default=float))
    for k, v in s["per_type"].items():
        print(k, v, s["confusion"][k])
    Path(a.out).write_text(json.dumps(out, indent=1, default=float))


if __name__ == "__main__":
    main()
