"""Cross-check of the independent truth's 2-D finite-slit Abbe sum
(:mod:`pipeline.diagnosis.truth.abbe`) against the project's line profiles
(:func:`optics.lineprofile.line_profile`, converged settings): L1 difference of the
unit-area detected J 1.25 µm profiles (order -2, default collimator) and the budget of
both codes' discretisation errors (``tests/test_truth.py::abbe_cross_check``). Prints a
Markdown table.

    .venv/bin/python benchmarks/bench_truth_crosscheck.py [--cache-dir DIR]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from pipeline.diagnosis.nominal import fea_sag_map  # noqa: E402
from test_truth import abbe_cross_check  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--cache-dir", default=None)
    a = ap.parse_args(argv)
    fea = fea_sag_map(200.0, 0.75, "all", 80.0, "default", cache_dir=a.cache_dir)
    print("| grating map | pixel scale | pupil shift mm | L1 difference | budget | seconds |")
    print("|---|---|---|---|---|---|")
    for label, m in (("perfect", None), ("FEA 200 µm / 75 %, default mesh", fea)):
        for mas, shift in ((250, (0.0, 0.0)), (100, (0.0, 0.0)), (25, (0.0, 0.0)), (25, (3.0, 2.0))):
            if m is None and shift != (0.0, 0.0):
                continue
            t = time.perf_counter()
            diff, tol, _ = abbe_cross_check(mas, m, shift)
            print(f"| {label} | {mas} mas | {shift} | {100 * diff:.3f} % | {100 * tol:.3f} % | "
                  f"{time.perf_counter() - t:.0f} |", flush=True)


if __name__ == "__main__":
    main()
