"""How far each truth grating family lies outside the span of the library's ``quilt_shape``.

For ``--draws`` truths per family (:data:`pipeline.diagnosis.truth.generate.GRATING_FAMILIES`,
the truth generator only, no diagnosis), the truth map ``t`` is fitted by least squares over
the central 82 x 72 mm with the parts ``quilt_shape`` rescales (:mod:`pipeline.diagnosis.quilt`:
``F_x``, ``F_y``, the (1, ±1) cross terms ``C``, the harmonics along x ``H_x``, the other
harmonics ``H`` and the smooth figure ``R = nominal - F_x - F_y - C - H_x - H``; their sum is
the nominal) plus piston and tilt
(the map's nuisances). Reported per family (median and range over the draws):

* ``outside``: ``||t - fit|| / ||t - k n||``, the share of the truth's departure from the
  rescaled nominal (``k`` its least-squares scale) that no ``quilt_shape`` reaches;
* ``resid``: ``||t - fit|| / ||t||`` (piston and tilt removed), the same as a fraction of
  the map;
* ``distance``: the harmonic distance to the nominal the family drew or produced.

The first row is the truth's FEA map alone (refined against the default mesh): the floor
every family sits on.

With ``--ratios`` it prints instead the truths' own ``quilt_shape`` ratios: the same
least-squares coefficients of ``F_y``, ``C``, ``H``, ``H_x`` and ``R`` over that of ``F_x`` (the
nominal's are 1), i.e. what a ``quilt_shape`` fit of a noiseless map of the truth returns;
they say which ranges of the ratios real-looking quilts need.

    .venv/bin/python benchmarks/truth_span.py [--draws 20] [--seed 1] [--cache-dir DIR] [--ratios]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from pipeline.diagnosis.campaign import CampaignConfig, campaign_maps
from pipeline.diagnosis.quilt import quilt_components
from pipeline.diagnosis.truth.generate import GRATING_FAMILIES, truth_grating
from pipeline.diagnosis.truth.gratings import central, harmonic_distance


def span_columns(nominal) -> tuple[np.ndarray, np.ndarray]:
    """(columns over the central region, mask): piston, tilt x, tilt y, F_x, F_y, C, H, H_x, R."""
    X, Y = np.meshgrid(nominal.x_mm, nominal.y_mm)
    q = quilt_components(nominal)
    parts = q.parts_um(X, Y)
    r = nominal.sag_um - sum(parts.values())
    mask = central(nominal.x_mm, nominal.y_mm) & np.isfinite(nominal.sag_um)
    cols = [np.ones_like(X), X, Y, *(parts[k] for k in ("fundamental_x", "fundamental_y", "cross", "harmonics",
                                                        "x_harmonics")), r]
    return np.column_stack([c[mask] for c in cols]), mask


def outside_span(t_um: np.ndarray, nominal_um: np.ndarray, A: np.ndarray, mask: np.ndarray) -> dict:
    """``outside`` and ``resid`` (module docstring) of the truth map ``t_um``."""
    t = t_um[mask]
    c, *_ = np.linalg.lstsq(A, t, rcond=None)
    res = np.linalg.norm(t - A @ c)
    P = A[:, :3]  # piston and tilt
    t0 = t - P @ np.linalg.lstsq(P, t, rcond=None)[0]
    d, k = harmonic_distance(t_um, nominal_um, mask)
    dep = np.column_stack([P, nominal_um[mask]])
    departure = np.linalg.norm(t - dep @ np.linalg.lstsq(dep, t, rcond=None)[0])
    return {"outside": res / departure, "resid": res / np.linalg.norm(t0), "distance": d}


def quilt_ratios(t_um: np.ndarray, A: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """``(F_y, C, H, H_x, R)`` coefficients of the truth map over its ``F_x`` coefficient."""
    c, *_ = np.linalg.lstsq(A, t_um[mask], rcond=None)
    return c[4:] / c[3]


def print_ratios(nominal, fea, A, mask, draws: int, seed: int) -> None:
    names = ("quilt_fund_xy_ratio", "quilt_cross_ratio", "quilt_harmonics_ratio", "quilt_x_harmonics_ratio",
             "quilt_figure_ratio")
    print("| family | draws | " + " | ".join(f"`{n}`" for n in names) + " |")
    print("|---|---|" + "---|" * len(names))
    rows = {"FEA map alone (refined mesh)": [quilt_ratios(np.where(np.isfinite(fea.sag_um), fea.sag_um, 0.0), A, mask)]}
    for fam in GRATING_FAMILIES:
        rows[fam] = [quilt_ratios(np.where(np.isfinite(g.sag_um), g.sag_um, 0.0), A, mask)
                     for g in (truth_grating(nominal, fea, np.random.default_rng([seed, s]), (fam,))
                               for s in range(draws))]
    for fam, rs in rows.items():
        r = np.array(rs)
        cells = [f"{np.median(r[:, j]):.2f}" if len(rs) == 1 else
                 f"{np.median(r[:, j]):.2f} ({r[:, j].min():.2f} … {r[:, j].max():.2f})" for j in range(len(names))]
        print(f"| `{fam}` | {len(rs)} | " + " | ".join(cells) + " |")


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--draws", type=int, default=20)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--cache-dir", default=str(Path.home() / ".cache" / "cryograting" / "diagnosis"))
    ap.add_argument("--ratios", action="store_true", help="the truths' own quilt_shape ratios instead")
    a = ap.parse_args(argv)
    nominal, fea = campaign_maps(CampaignConfig(), cache_dir=a.cache_dir)
    n = np.where(np.isfinite(nominal.sag_um), nominal.sag_um, 0.0)
    A, mask = span_columns(nominal)
    if a.ratios:
        print_ratios(nominal, fea, A, mask, a.draws, a.seed)
        return
    rows = {"fea_only (refined mesh)": [outside_span(np.where(np.isfinite(fea.sag_um), fea.sag_um, 0.0), n, A, mask)]}
    for fam in GRATING_FAMILIES:
        rows[fam] = [outside_span(np.where(np.isfinite(g.sag_um), g.sag_um, 0.0), n, A, mask)
                     for g in (truth_grating(nominal, fea, np.random.default_rng([a.seed, s]), (fam,))
                               for s in range(a.draws))]
    print(f"| family | draws | harmonic distance | outside the quilt_shape span, of the departure | "
          f"residual, of the map |")
    print("|---|---|---|---|---|")

    def fmt(v):
        v = np.asarray(v)
        return f"{np.median(v):.1%}" if v.size == 1 else f"{np.median(v):.1%} ({v.min():.1%}–{v.max():.1%})"

    for fam, rs in rows.items():
        print(f"| `{fam}` | {len(rs)} | {fmt([r['distance'] for r in rs])} | {fmt([r['outside'] for r in rs])} | "
              f"{fmt([r['resid'] for r in rs])} |")


if __name__ == "__main__":
    main()
