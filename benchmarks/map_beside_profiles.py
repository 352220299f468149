"""Does a surface map beside the line profiles change what the diagnosis says about them?
A paired reading of the recorded frozen runs: every run that diagnosed the same truths
(same seed, same case indices) as profiles alone and as profiles + map, at one engine, gives
for each line-profile case the two outcomes side by side. No diagnosis is re-run.

    .venv/bin/python benchmarks/map_beside_profiles.py [benchmarks/*_raw_map.json ...]

For out-of-library cases an outcome is right when the verdict is not ``explained``; for
library cases when ``correct`` (the headline rule of the run). A pair is counted only where
the two rows hold the same truth. Prints per run and in total the 2x2 table (alone right /
with map right), the discordant pairs by case type and the exact two-sided sign-test p-value of
the discordant pairs (McNemar's exact test).
"""

from __future__ import annotations

import argparse
import collections
import json
import math
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent


def _profile_rows(path: Path) -> dict:
    cases = json.loads(path.read_text())["campaign"]["cases"]
    return {r["index"]: r for r in cases if r["kind"] == "line_profile"}


def right(row: dict) -> bool:
    """Out of library: not attributed (``explained``) to a library effect; library: correct."""
    if row["effect"].startswith("ool"):
        return row["verdict"] != "explained"
    return bool(row["correct"])


def right_by_value(row: dict) -> bool | None:
    """Library cases: correct with rescalings judged by their value (``correct_measured``,
    recorded by the later runs; None where the run did not record it)."""
    v = row.get("correct_measured")
    return None if v is None else bool(v)


def paired(alone_path: Path, map_path: Path) -> list[tuple[dict, dict]]:
    """(row alone, row with the map) per line-profile case both files diagnosed from the same truth."""
    a, b = _profile_rows(alone_path), _profile_rows(map_path)
    return [(a[i], b[i]) for i in sorted(set(a) & set(b)) if a[i]["truth"] == b[i]["truth"]]


def sign_test_p(n_for: int, n_against: int) -> float:
    """Exact two-sided binomial p-value of ``n_for`` against ``n_against`` at p = 1/2."""
    n = n_for + n_against
    if n == 0:
        return 1.0
    k = min(n_for, n_against)
    tail = sum(math.comb(n, j) for j in range(k + 1)) / 2.0**n
    return min(1.0, 2.0 * tail)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("raw_map", nargs="*", type=Path, help="profiles + map raw files (default: every benchmarks/*_raw_map.json)")
    a = ap.parse_args(argv)
    files = a.raw_map or sorted(HERE.glob("*_raw_map.json"))
    total = collections.Counter()
    by_type = collections.defaultdict(collections.Counter)
    moves = collections.Counter()
    by_value = collections.Counter()
    print("| run | pairs | out of library: alone right / with map right | rescued / lost | library: alone / with map | rescued / lost |")
    print("|---|---|---|---|---|---|")
    for m in files:
        alone = m.with_name(m.name.replace("_raw_map.json", "_raw.json"))
        if not alone.exists():
            continue
        rows = paired(alone, m)
        c = collections.Counter()
        for row_a, row_b in rows:
            t, ra, rb = row_a["effect"], right(row_a), right(row_b)
            group = "ool" if t.startswith("ool") else "lib"
            c[(group, ra, rb)] += 1
            by_type[t][(ra, rb)] += 1
            if ra != rb:  # named by the wrong outcome's top finding
                moves[(t, (row_b if ra else row_a)["top"], "rescued" if rb else "lost")] += 1
            va, vb = right_by_value(row_a), right_by_value(row_b)
            if group == "lib" and va is not None and vb is not None:
                by_value[(va, vb)] += 1
        total.update(c)
        n_ool = sum(v for k, v in c.items() if k[0] == "ool")
        n_lib = sum(v for k, v in c.items() if k[0] == "lib")
        print(f"| {m.name.replace('_raw_map.json', '')} | {len(rows)} "
              f"| {sum(v for k, v in c.items() if k[0] == 'ool' and k[1])}/{n_ool} / "
              f"{sum(v for k, v in c.items() if k[0] == 'ool' and k[2])}/{n_ool} "
              f"| {c[('ool', False, True)]} / {c[('ool', True, False)]} "
              f"| {sum(v for k, v in c.items() if k[0] == 'lib' and k[1])}/{n_lib} / "
              f"{sum(v for k, v in c.items() if k[0] == 'lib' and k[2])}/{n_lib} "
              f"| {c[('lib', False, True)]} / {c[('lib', True, False)]} |")
    print()
    for g, name in (("ool", "out of library"), ("lib", "library")):
        both = total[(g, True, True)]
        r, lost = total[(g, False, True)], total[(g, True, False)]
        neither = total[(g, False, False)]
        print(f"{name}: both right {both}, map rescues {r}, map loses {lost}, neither {neither}; "
              f"exact sign test on the discordant pairs p = {sign_test_p(r, lost):.3g}")
    if by_value:
        r, lost = by_value[(False, True)], by_value[(True, False)]
        print(f"library, rescalings by value (runs that record it): both right {by_value[(True, True)]}, "
              f"map rescues {r}, map loses {lost}, neither {by_value[(False, False)]}; p = {sign_test_p(r, lost):.3g}")
    print()
    print("| case type | both right | rescued by the map | lost with the map | neither |")
    print("|---|---|---|---|---|")
    for t in sorted(by_type):
        c = by_type[t]
        print(f"| {t} | {c[(True, True)]} | {c[(False, True)]} | {c[(True, False)]} | {c[(False, False)]} |")
    print()
    print("| case type | wrong outcome's top finding | rescued / lost | pairs |")
    print("|---|---|---|---|")
    for (t, top, how), n in sorted(moves.items()):
        print(f"| {t} | {top} | {how} | {n} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
