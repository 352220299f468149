"""How often the diagnosis's 1-sigma errors cover the truth, over the recorded frozen runs.

For every library line-profile case of the frozen, pre-registered campaign runs recorded in
``benchmarks/frozen_*raw*.json`` whose top finding is the injected effect (rescalings judged
by their value, ``correct_measured``), each injected parameter's pull
``z = (fitted - true) / reported 1-sigma`` is collected; an amplitude is compared with the
truth's own x-fundamental ratio (``rescaling_true``), the amplitude the rescalings measure. A
parameter the finding reports as ``sign_degenerate`` (the engine claims no sign) is compared
as the campaign scores it: the fit's mirror about the parameter's sign origin on the truth's
side.
Well-calibrated Gaussian errors put 68 % of pulls within 1 and 95 % within 2, with a median
``|z|`` of 0.67.

Usage: ``python benchmarks/error_bar_coverage.py`` (prints the table in markdown).
"""
from __future__ import annotations

import argparse
import collections
import glob
import json
from pathlib import Path

import numpy as np

from pipeline.diagnosis.campaign import on_truth_side
from pipeline.diagnosis.effects import parameter_spec

HERE = Path(__file__).parent


def pulls(paths) -> dict:
    """``{parameter: [z, ...]}`` over the library cases named right in the raw campaign files."""
    seen, out = set(), collections.defaultdict(list)
    for path in paths:
        try:
            data = json.loads(Path(path).read_text())
        except (OSError, ValueError):
            continue
        for campaign in (v for v in data.values() if isinstance(v, dict) and "cases" in v):
            for r in campaign["cases"]:
                if r.get("kind") != "line_profile" or r["effect"].startswith("ool") or not r.get("correct_measured"):
                    continue
                fitted, sigma = r.get("top_parameters") or {}, r.get("top_uncertainties") or {}
                truth = dict(r.get("truth") or {})
                if "scale_J" in truth and r.get("rescaling_true"):
                    truth["scale_J"] = r["rescaling_true"]
                for name, true in truth.items():
                    s = sigma.get(name)
                    if name not in fitted or not isinstance(true, (int, float)) or not s or not np.isfinite(s):
                        continue
                    key = (str(path), r["index"], r["measurement"], name)
                    if key in seen:
                        continue
                    seen.add(key)
                    fit = fitted[name]
                    if name in (r.get("sign_degenerate") or ()):
                        fit = on_truth_side(fit, true, parameter_spec(name).origin)
                    out[name].append((fit - true) / s)
    return dict(out)


def table(by: dict) -> str:
    lines = ["| parameter | n | within 1σ | within 2σ | median \\|z\\| |", "|---|---|---|---|---|"]
    every = np.concatenate([np.asarray(v) for v in by.values()]) if by else np.zeros(0)
    for name, z in sorted(by.items()) + [("all", every)]:
        z = np.abs(np.asarray(z))
        lines.append(f"| {name} | {z.size} | {np.mean(z <= 1):.0%} | {np.mean(z <= 2):.0%} | {np.median(z):.2f} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    argparse.ArgumentParser(description=__doc__.splitlines()[0]).parse_args(argv)
    print(table(pulls(sorted(glob.glob(str(HERE / "frozen_*raw*.json"))))))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
