"""Can the detector terms beside a finding be seen at all? Re-run recorded out-of-library
cases whose detector light was named as a library effect, and refit the detector terms beside
that finding started at the truth's own detector values (all six terms, and the truth's
family alone): if even that start lowers the BIC by less than ``Criteria.min_delta_bic``, no
start or check of the detector-side alternative can find the light in those profiles.

    .venv/bin/python benchmarks/wings_from_truth.py benchmarks/frozen_nested_start_raw.json 13 43 \
        [--cache-dir DIR]

Prints, per case, the recorded check, then per start the joint BIC's gain over the finding
and the weighted residual's drop.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from rerun_cases import recorded_config  # noqa: E402

from pipeline.diagnosis import engine  # noqa: E402
from pipeline.diagnosis.campaign import campaign_maps, case_type, one_blas_thread, run_case  # noqa: E402
from pipeline.diagnosis.effects import applicable_effects  # noqa: E402
from pipeline.diagnosis.finding import all_effects  # noqa: E402
from pipeline.diagnosis.fitting import fit  # noqa: E402
from pipeline.diagnosis.ranking import parameters_of  # noqa: E402
from pipeline.diagnosis.wings import WINGS_PARAMETERS  # noqa: E402

#: truth keys of the campaign's detector families -> the detector terms' parameters
_TRUTH_TERMS = ("tail_fraction", "tail_decay_um", "nonlinearity", "halo_fraction", "halo_hwhm_um")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("raw", type=Path)
    ap.add_argument("index", type=int, nargs="+")
    ap.add_argument("--cache-dir", type=Path, default=None)
    a = ap.parse_args(argv)
    raw = json.loads(a.raw.read_text())["campaign"]
    cfg = recorded_config(raw)
    one_blas_thread()
    nominal, base = campaign_maps(cfg, cache_dir=a.cache_dir)
    seen = {}
    check = engine.wings_alternative.wings_check

    def spy(prob, finding, fo, c):  # the check's own inputs: the problem and the finding's fit
        out = check(prob, finding, fo, c)
        seen.update(prob=prob, finding=finding, fo=fo, out=out)
        return out

    engine.wings_alternative.wings_check = spy
    for i in a.index:
        seen.clear()
        row = run_case((i, case_type(cfg, i), cfg, nominal, base))
        print(i, row["effect"], row["truth"], row["top"], row["verdict"], flush=True)
        if "prob" not in seen:
            print("  no detector-side check ran")
            continue
        prob, finding, fo, out = seen["prob"], seen["finding"], seen["fo"], seen["out"]
        print(f"  recorded check: gain {out.wings_gain_bic:.1f}, joint terms {out.wings_joint}")
        background = tuple(e.name for e in applicable_effects({f.kind for f in prob.forwards}) if e.background)
        own = parameters_of(tuple(dict.fromkeys(all_effects(finding) + background)), prob.forwards)
        start = {q.name: fo.parameters.get(q.name, q.null) for q in own}
        truth = {q.name: q.null for q in WINGS_PARAMETERS}
        truth.update({k: row["truth"][k] for k in _TRUTH_TERMS if k in row["truth"]})
        if "tail_side" in row["truth"]:
            truth["tail_fraction"] *= row["truth"]["tail_side"]
        family = tuple(q for q in WINGS_PARAMETERS if q.name in row["truth"])
        b_f, w_f = fo.bic(prob.weights), fo.weighted_rss(prob.weights)
        for label, terms in (("all six terms", WINGS_PARAMETERS), ("the truth's family", family)):
            j = fit(prob, own + tuple(terms), start={**start, **{q.name: truth[q.name] for q in terms}},
                    start_deltas_um=fo.deltas_um, max_nfev=400)
            print(f"  from the truth, {label}: gain {b_f - j.bic(prob.weights):.1f}, weighted residual drop "
                  f"{w_f - j.weighted_rss(prob.weights):.1f} (ln n {math.log(sum(fo.counts.values())):.2f}); "
                  + ", ".join(f"{q.name} {float(j.parameters[q.name]):.4f}" for q in terms), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
