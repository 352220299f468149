"""Assemble the paper scorecard, write ``scorecard.json``, ``scorecard.md`` and its figures.

``scorecard(out_dir)`` is the one API call behind ``cryograting paper --out DIR``.
FEA cases are cached under ``out_dir/fea`` (a re-run reuses every solved case).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from pipeline.paper.claim import Claim
from pipeline.paper.design_claims import design_claims
from pipeline.paper.fea_claims import fea_claims, solve_paper_cases
from pipeline.paper.optics_claims import ProfileBook, optics_claims

__all__ = ["scorecard", "format_scorecard", "write_scorecard"]


def format_scorecard(claims: list[Claim]) -> str:
    """Plain-text table: id, status, source, paper, model."""
    lines = [f"{'claim':32} {'status':13} {'source':8} paper | model", "-" * 110]
    for c in claims:
        lines.append(f"{c.id:32} {c.status:13} {c.source:8} {c.paper} | {c.model}")
    counts = {s: sum(c.status == s for c in claims) for s in ("reproduced", "partial", "contradicted", "not testable")}
    lines.append("-" * 110)
    lines.append(", ".join(f"{k} {v}" for k, v in counts.items()))
    return "\n".join(lines)


def _markdown(claims: list[Claim], figures: list[str]) -> str:
    out = ["# The paper, claim by claim, on the model", "",
           "Regenerate: `cryograting paper --out DIR`. Status rules: `pipeline/paper/*_claims.py` "
           "(module docstrings).", "",
           "| id | claim | section | paper | model | status | source | reason |", "|---|---|---|---|---|---|---|---|"]
    for c in claims:
        cells = [c.id, c.claim, c.section, c.paper, c.model, f"**{c.status}**", c.source, c.reason]
        out.append("| " + " | ".join(s.replace("|", "/") for s in cells) + " |")
    out += ["", "## Figures", ""] + [f"![{f}]({f})" for f in figures]
    return "\n".join(out) + "\n"


def _figures(fea, book: ProfileBook, factor: float, out: Path) -> list[str]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from pipeline.study.plots import save

    names = []
    fig, ax = plt.subplots(figsize=(8, 4))
    rows = list(fea.rows)
    lab = [f"{r.coverage[:4]} {r.t0_um:g}/{100 * r.polish:g}" for r in rows]
    x = np.arange(len(rows))
    ax.bar(x - 0.2, [r.paper_pv_um for r in rows], 0.4, label="paper")
    ax.bar(x + 0.2, [r.model_pv_um * fea.scale_factor for r in rows], 0.4, label="model (Table 1 calibration)")
    ax.set_xticks(x, lab, rotation=60, fontsize=7)
    ax.set_ylabel("P/V_center (µm)")
    ax.legend()
    fig.tight_layout()
    names.append(save(fig, out / "tables.png").name)

    fig, axes = plt.subplots(1, 2, figsize=(10, 4), sharey=True)
    for ax, mas in zip(axes, (100, 250)):
        sags = ["perfect", "200/50", "sinusoid"] + ([f"200/50 x{factor:.2f}"] if factor == factor else [])
        for s in sags:
            p = book.get(s, "J", 1.25, mas)
            ax.plot(p.offset_um, p.intensity, label="sinusoid 0.58 µm P/V (analytic)" if s == "sinusoid" else s)
        ax.set_xlim(-80, 80)
        ax.set_title(f"J 1.25 µm, {mas} mas")
        ax.set_xlabel("offset (µm)")
    axes[0].legend(fontsize=8)
    axes[0].set_ylabel("detected profile (unit area, 1/µm)")
    fig.tight_layout()
    names.append(save(fig, out / "j_double_peak.png").name)

    fig, axes = plt.subplots(1, 3, figsize=(12, 3.6), sharey=True)
    for ax, mas in zip(axes, (25, 100, 250)):
        for s in ("perfect", "200/75"):
            p = book.get(s, "K", 2.20, mas)
            ax.plot(p.offset_um, p.intensity, label=s)
        ax.set_xlim(-80, 80)
        ax.set_title(f"K 2.2 µm, {mas} mas")
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    names.append(save(fig, out / "k_shoulders.png").name)
    return names


def write_scorecard(claims: list[Claim], figures: list[str], out_dir) -> None:
    """Write ``scorecard.json`` and ``scorecard.md`` atomically."""
    from pipeline.io.common import atomic_write

    out = Path(out_dir)
    with atomic_write(out / "scorecard.json") as fh:
        json.dump({"claims": [c.as_dict() for c in claims]}, fh, indent=1, ensure_ascii=False)
    with atomic_write(out / "scorecard.md") as fh:
        fh.write(_markdown(claims, figures))


def scorecard(out_dir, *, progress: bool = True, figures: bool = True) -> list[Claim]:
    """Evaluate the paper's claims on the model and write the scorecard into ``out_dir``.

    Returns the claims in report order (FEA tables, optics, design).
    """
    from pipeline.io.common import ensure_writable_dir

    out = ensure_writable_dir(out_dir)
    fea = solve_paper_cases(out, progress=progress)
    claims = fea_claims(fea)
    oc, extra = optics_claims(fea)
    book = extra["book"]
    claims += oc + design_claims(fea, book)
    figs = _figures(fea, book, extra["factor"], out) if figures else []
    write_scorecard(claims, figs, out)
    return claims
