"""Write a diagnosis: ``diagnosis.json`` and a self-contained HTML report with figures
(residuals before/after, the ranking, held-out results, where the residual lies)."""

from __future__ import annotations

import base64
import html
import io
import json
import math
from pathlib import Path

import numpy as np

from pipeline.io.common import atomic_write

from .effects import library_rows
from .verdict import OUTSIDE_ALTERNATIVES, failed_tests, own_parameters

__all__ = ["alone_text", "coupling_text", "read_text", "verdict_text", "write_report"]


def _png(fig) -> str:
    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90, bbox_inches="tight")
    plt.close(fig)
    return f'<img src="data:image/png;base64,{base64.b64encode(buf.getvalue()).decode()}"/>'


def _measurement_figure(name, data, nominal, best, best_label, kind="surface"):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    x, y, d = data
    if y is not None:  # surface map or PSF image: residual maps before/after
        image = kind == "psf_image"
        unit, axis = ("peak = 1", "µm") if image else ("µm", "mm")
        fig, axs = plt.subplots(1, 2 if best is not None else 1, figsize=(9, 4), squeeze=False)
        panels = [("data - nominal", d - nominal)] + ([(f"data - ({best_label})", d - best)] if best is not None else [])
        lim = float(np.nanpercentile(np.abs(d - nominal), 99))
        for ax, (t, r) in zip(axs[0], panels):
            sc = ax.scatter(x, y, c=r - np.mean(r), s=3, cmap="RdBu_r", vmin=-lim, vmax=lim, marker="s")
            ax.set_title(f"{name}: {t}\nRMS {np.std(r):.4f} ({unit})", fontsize=9)
            ax.set_aspect("equal")
            ax.set_xlabel(f"x ({axis}, dispersion)")
            ax.set_ylabel(f"y ({axis}{', along the slit' if image else ''})")
        fig.colorbar(sc, ax=axs[0].tolist(), label=unit)
        return fig
    fig, (a0, a1) = plt.subplots(2, 1, figsize=(7, 5), sharex=True, gridspec_kw={"height_ratios": [2, 1]})
    a0.plot(x, d, ".", ms=3, color="k", label="data")
    a0.plot(x, nominal, "-", color="tab:blue", label="nominal")
    a1.plot(x, d - nominal, "-", color="tab:blue", label="nominal")
    if best is not None:
        a0.plot(x, best, "-", color="tab:red", label=best_label)
        a1.plot(x, d - best, "-", color="tab:red", label=best_label)
    a0.set_title(name, fontsize=9)
    a0.legend(fontsize=7)
    a1.axhline(0, color="0.5", lw=0.5)
    a1.set_xlabel("offset (µm)")
    a1.set_ylabel("residual (peak = 1)")
    return fig


def _ranking_figure(findings):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 0.35 * len(findings) + 1))
    names = [f.effect for f in findings][::-1]
    ax.barh(names, [f.delta_bic for f in findings][::-1], color=["tab:green" if f.significant else "0.6" for f in findings][::-1])
    ax.axvline(-10, color="k", ls=":", lw=0.8)
    ax.set_xlabel("ΔBIC vs nominal (lower is better; dotted: -10)")
    return fig


def _table(rows, cols) -> str:
    head = "".join(f"<th>{html.escape(c)}</th>" for c in cols)
    body = "".join("<tr>" + "".join(f"<td>{html.escape(str(r.get(c, '')))}</td>" for c in cols) + "</tr>" for r in rows)
    return f"<table><tr>{head}</tr>{body}</table>"


def _fmt(v):
    return f"{v:.4g}" if isinstance(v, float) else v


def _unit_text(f, k: str) -> str:
    """' K' for a parameter in kelvin, '' for a dimensionless one (from the finding's parameter_units)."""
    unit = f.parameter_units.get(k, "")
    return "" if unit in ("", "1") else f" {unit}"


def _param_text(f, k: str) -> str:
    """'temperature_offset_K = 12.3 ± 1.1 K' (unit from the finding's parameter_units)."""
    return f"{k} = {f.parameters[k]:.4g} ± {f.uncertainties.get(k, float('nan')):.2g}{_unit_text(f, k)}"


def _absorbs_text(absorbed: str, k: dict) -> str:
    """'coll_defocus_um contains -1.7 x bow_defocus_um' (terms above 5 % of the largest)."""
    big = max((abs(m) for m in k.values()), default=0.0)
    terms = [f"{n} contains {m:+.3g} × {absorbed}" for n, m in k.items() if big > 0 and abs(m) >= 0.05 * big]
    return ", ".join(terms) or f"{absorbed}: no parameter moves"


def verdict_text(d) -> str:
    """The verdict in one or two plain sentences: what explains the gap, or why the
    nearest candidate does not (the tests of ``docs/diagnosis.md``, step 9)."""
    b, c = d.best, d.criteria
    if d.verdict == "no_gap":
        return "The data agree with the simulation within their noise: there is no gap to explain."
    if b is None:
        return "No library effect applies to these data, so the gap is left unexplained."
    if d.verdict == "explained":
        held = ("" if b.heldout_shrink_fraction is None
                else f", and fitted on part of the data it shrinks the rest by {b.heldout_shrink_fraction:.0%}")
        left = ""
        if d.unexplained_in:  # the finding takes up most of the gap, not all of it: say where the rest is
            left = (" Part of the gap remains beyond noise after it, in "
                    + "; ".join(f"{g['measurement']} ({g['rms_ratio']:.1f} × noise, χ² excess {g['z']:.1f} σ)"
                                for g in d.unexplained_in) + ".")
        alone = alone_text(d)
        return (f"{b.effect} explains the gap: it lowers the BIC by {-b.delta_bic:.0f} and takes up "
                f"{b.excess_explained:.0%} of the residual beyond noise{held}.{left}" + (f" {alone}" if alone else ""))
    failed = failed_tests(b, c)
    why = []
    if "significant" in failed:
        why.append(f"it is not significant (ΔBIC {b.delta_bic:+.1f}; a finding needs ≤ −{c.min_delta_bic:g})")
    if "excess" in failed:
        why.append(f"it takes up only {b.excess_explained:.0%} of the residual beyond noise (needs "
                   f"{c.min_variance_explained:.0%})")
    if "heldout" in failed:
        why.append("fitted on part of the data it does not predict the rest (held-out check)")
    if "prior" in failed:
        why.append(f"{', '.join(b.at_bound)} ended at the bound of its prior range, so the prior stopped the fit")
    if "alternative" in failed:
        why.append("something outside the library fits as well: "
                   + "; ".join(e for e in b.degenerate_with if e in OUTSIDE_ALTERNATIVES))
    if "outside" in failed:
        why.append("it takes up part of the gap, and the data need something outside the library beside it: "
                   + "; ".join(b.needs_outside))
    return ("No library effect explains the gap. The nearest candidate, " + b.effect + ", is not the explanation"
            + (": " + "; ".join(why) if why else "") + ".")


def alone_text(d) -> str:
    """What each part of the data reads fitted alone (:attr:`Diagnosis.parts_alone`), in one
    sentence: the finding's own parameters (a companion's only where it lies 2 sigma or more
    from the joint value), how far each lies from the joint value in the part's own errors,
    and where a gap is left after the part's own fit ("" when the parts were not refitted)."""
    if not d.parts_alone or d.best is None:
        return ""
    b = d.best
    own = own_parameters(b)
    texts = []
    for p in d.parts_alone:
        vals = []
        for k, v in p.parameters.items():
            if k not in own and not abs(p.tension.get(k, 0.0)) >= 2.0:
                continue  # a companion is named only where this part pulls it away from the joint value
            e, t = p.uncertainties.get(k, math.inf), p.tension.get(k, math.nan)
            err = f" ± {e:.2g}" if math.isfinite(e) else " (not constrained)"
            far = f", {abs(t):.1f} σ from the joint value" if math.isfinite(t) and abs(t) >= 1.0 else ""
            vals.append(f"{k} = {v:.4g}{err}{_unit_text(b, k)}{far}")
        left = ("; it leaves " + ", ".join(f"{g['measurement']} at {g['rms_ratio']:.2f} × noise" for g in p.gap)
                if p.gap else "; it leaves no gap")
        if vals:
            texts.append(f"{p.label} alone read {', '.join(vals)}{left}")
        else:  # none of the finding's own parameters acts on this part, and no companion is pulled away
            texts.append(f"{p.label} alone hold none of the finding's own parameters{left}")
    return "Fitted to each part alone, " + "; ".join(texts) + "."


def _rms_unit(f) -> str:
    units = {p["unit"] for p in f.per_measurement}
    if units == {"um"}:
        return "µm"
    if units == {"fraction_of_peak"}:
        return "of the line peak"
    return "(weighted over the measurements, the nominal's = 1)"


def read_text(read: dict) -> str:
    """One line of what was read from a file (:func:`.manifest.read_summary`; a list is a range)."""
    return "; ".join(f"{k} {' .. '.join(map(str, v)) if isinstance(v, list) else v}" for k, v in read.items())


def _measurement_rows(d) -> list[dict]:
    """One row per measurement: its file, what was read from it, how its samples were
    gridded (scattered points are interpolated onto a grid for display; the fit uses the
    points) and its noise."""
    noise = d.baseline.get("noise", {})
    rows = []
    for m in d.measurements:
        sigma = noise.get(m["name"])
        unit = "µm" if m["kind"] == "surface" else "of the peak"
        rows.append({"measurement": m["name"], "kind": m["kind"], "file": m["file"],
                     "read": read_text(m["read"]) if m.get("read") else "—", "gridding": m.get("gridding") or "—",
                     "noise": f"{sigma:.3g} {unit}" if isinstance(sigma, float) else "—",
                     "noise from": m.get("noise_from", "—"), "inter-pixel coupling": coupling_text(d.baseline, m["name"])})
    return rows


def coupling_text(baseline: dict, name: str) -> str:
    """A profile's or detector image's inter-pixel coupling as the report states it: stated
    by the manifest, or fitted with the verdict's fit and with the nominal ("—" for maps and
    focal-plane images)."""
    c = baseline.get("interpixel_coupling") or {}
    if name in c.get("stated", {}):
        return f"{c['stated'][name]:.4f} (stated)"
    if name not in c.get("after", {}):
        return "—"
    text = f"{c['after'][name]:.4f} fitted"
    return text + (f" (nominal: {c['nominal'][name]:.4f})" if name in c.get("nominal", {}) else "")


def write_report(diagnosis, out_dir: str | Path) -> tuple[Path, Path]:
    """Write ``diagnosis.json`` and ``report.html`` into ``out_dir``; returns both paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    jpath = out / "diagnosis.json"
    with atomic_write(jpath) as fh:
        fh.write(json.dumps(diagnosis.to_dict(), indent=1, default=float))
    d = diagnosis
    parts = [f"<h1>Sim-to-real diagnosis</h1><p>manifest: {html.escape(d.manifest)}</p>",
             f"<h2>Verdict: {html.escape(d.verdict)}</h2>", f"<p>{html.escape(verdict_text(d))}</p>",
             "<h3>What was read</h3>" + _table(_measurement_rows(d), ["measurement", "kind", "file", "read", "gridding",
                                                                     "noise", "noise from",
                                                                     "inter-pixel coupling"])]

    if d.best:
        b = d.best
        parts.append(f"<p>Best: <b>{html.escape(b.effect)}</b> — parameters "
                     + ", ".join(html.escape(_param_text(b, k)) for k in b.parameters)
                     + f"; residual RMS {b.residual_rms_before:.4g} → {b.residual_rms_after:.4g} {_rms_unit(b)} "
                     f"(shrink {b.shrink_fraction:.2f}, "
                     f"held-out shrink {b.heldout_shrink_fraction if b.heldout_shrink_fraction is None else round(b.heldout_shrink_fraction, 2)})"
                     + (f"; degenerate with {', '.join(b.degenerate_with)}" if b.degenerate_with else "")
                     + (f"; fitted together with {', '.join(b.companions)}" if b.companions else "")
                     + (f"; sign undetermined: {', '.join(b.sign_degenerate)}" if b.sign_degenerate else "")
                     + (f"; not constrained by these data (1σ beyond half the prior range): {', '.join(b.unconstrained)}"
                        if b.unconstrained else "") + "</p>")
        if b.summary:
            parts.append("<p>In physical terms: " + "; ".join(
                f"{html.escape(e)}: " + html.escape(", ".join(f"{k} = {_fmt(v)}" for k, v in s.items()))
                for e, s in b.summary.items()) + "</p>")
        if b.absorbs:
            parts.append("<p>These data cannot identify some effects on their own; the parameters above contain them: "
                         + "; ".join(html.escape(_absorbs_text(k, v)) for k, v in b.absorbs.items())
                         + ". A measurement that can (e.g. a surface map for a blank bow) separates them.</p>")
    if d.ranking_note:
        parts.append(f"<p>{html.escape(d.ranking_note)}.</p>")
    choice = d.baseline.get("map_departure_choice")
    if choice:  # a map beside the images of its blank: was its departure part of their optics?
        parts.append(f"<p>{html.escape(choice['note'][0].upper() + choice['note'][1:])}.</p>")
    if d.unexplained_in:
        parts.append("<p>Residual still beyond noise (unexplained) in: " + "; ".join(
            html.escape(f"{g['measurement']} (RMS {g['rms_ratio']:.2f} × noise, χ² excess {g['z']:.1f} σ)")
            for g in d.unexplained_in) + "</p>")
    if d.verdict != "explained" and alone_text(d):  # an explained verdict's sentence holds it already
        parts.append(f"<p>{html.escape(alone_text(d))}</p>")
    rows = [{"effect": f.effect, "ΔBIC": _fmt(f.delta_bic), "shrink": _fmt(f.shrink_fraction),
             "variance explained": _fmt(f.variance_explained),
             "excess over noise explained (where it acts)": _fmt(f.excess_explained),
             "excess explained (all data)": _fmt(f.excess_explained_overall),
             "held-out shrink": _fmt(f.heldout_shrink_fraction) if f.heldout_shrink_fraction is not None else "—",
             "overfit": f.overfit, "degenerate with": ", ".join(f.degenerate_with),
             "fitted with": ", ".join(f.companions), "sign undetermined": ", ".join(f.sign_degenerate),
             "unconstrained": ", ".join(f.unconstrained), "absorbs": ", ".join(f.absorbs),
             "parameters": ", ".join(_param_text(f, k) for k in f.parameters)}
            for f in d.findings]
    parts += ["<h2>Ranking</h2>", _png(_ranking_figure(d.findings)) if d.findings else "",
              _table(rows, list(rows[0]) if rows else [])]
    parts.append("<h2>Held-out validation</h2>" + _table(
        [{"effect": f.effect, "folds": f.heldout_note} for f in d.findings if f.heldout_note], ["effect", "folds"]))
    parts.append("<h2>Where the residual lies (nominal)</h2>" + _table(
        [{**w, "share": f"{w['share']:.3f}"} for w in d.where], ["measurement", "decomposition", "component", "share"]))
    if d.where_after:
        parts.append(f"<h2>Remaining residual after {html.escape(d.best.effect)}</h2>" + _table(
            [{**w, "share": f"{w['share']:.3f}"} for w in d.where_after], ["measurement", "decomposition", "component", "share"]))
    if d.curves:
        parts.append("<h2>Residuals before / after</h2>")
        for name, data in d.curves["data"].items():
            best = d.curves.get("best", {}).get(name)
            parts.append(_png(_measurement_figure(name, data, d.curves["nominal"][name], best, d.best.effect if d.best else "",
                                                  d.curves.get("kinds", {}).get(name, "surface"))))
    if d.best:
        parts.append("<h2>Per measurement (best finding)</h2>" + _table(
            [{k: _fmt(v) for k, v in p.items()} for p in d.best.per_measurement],
            ["measurement", "unit", "rms_before", "rms_after", "noise", "chi2_red_before", "chi2_red_after"]))
    tried = {e for f in d.findings for e in tuple(f.effects) + tuple(f.companions)}
    parts.append("<h2>Effect parameters</h2>" + _table(
        [{k: _fmt(v) for k, v in r.items()} for r in library_rows() if r["effect"] in tried],
        ["effect", "parameter", "unit", "null", "prior", "kinds", "meaning"]))
    parts.append(f"<p>timings (s): {html.escape(json.dumps(d.timings_s))}</p>")
    style = "<style>body{font-family:sans-serif;max-width:1100px} table{border-collapse:collapse;font-size:12px} td,th{border:1px solid #ccc;padding:2px 6px}</style>"
    hpath = out / "report.html"
    with atomic_write(hpath) as fh:
        fh.write(f"<html><head><meta charset='utf-8'>{style}</head><body>{''.join(parts)}</body></html>")
    return jpath, hpath
