"""End-to-end studies: FEA cases → sag maps → line profiles → tables, figures, report.

``run_study(out_dir, config=None)`` (CLI: ``cryograting run [CONFIG.toml]``) runs a
:class:`pipeline.study.study_config.StudyConfig`; without one it runs :func:`default_study`, the
paper's study: the 15 FEA cases of Tables 1 and 2; detected line profiles of J, H, K at
band centre and edges in 250/100/25 mas for a perfect grating and the 200 µm / 75 %
deformation (J also 200 µm / 50 %); the 1.25 µm line on the J, H and K gratings in
orders −2/−3/−4 (J with 200/50, H and K with 200/75, as the paper). It writes into
``out_dir``:

* ``fea/cases.csv`` — every FEA case: label, P/V, RMS and the value of every parameter;
* ``fea/sweep.nc`` — the same with the sag maps (cases cached under ``fea/cases``: a
  re-run reuses every finished case);
* ``fea/tables.csv`` — model vs paper, for the cases that are the paper's;
* ``profiles.csv`` and ``profiles.nc`` — detected line profiles and their metrics;
* ``study.nc`` — the one labelled dataset: every case's parameters, P/V and RMS, sag
  map, Zernike (Fringe 1–37 over the 82 × 72 mm box) and Fourier quilt fits with their
  residuals, the grating wavefronts of the profiles, and the line profiles
  (:mod:`pipeline.study.dataset`);
* ``exports/`` (``[output] exports``) — sag maps as 16-bit CODE V INT and Zemax Grid Sag
  DAT, the Zernike fit as a CODE V ZFR deck, OpticStudio Zernike Standard/Fringe Sag
  extra data and project lists (Fringe and Noll), grating wavefronts as CODE V INT WFR;
* the PNG figures of the config and ``report.html`` that puts them together.
"""

from __future__ import annotations

import base64
import csv
import html
import time
from pathlib import Path

import numpy as np

from fea.calibration import paper_cases
from optics.grating import get_grating
from optics.lineprofile import line_profile, point_psf
from optics.metrics import profile_metrics
from optics.sagmap import SagMap
from pipeline.bounds import GEOMETRY_KEYS, SECONDS, fea_case_seconds, warn_if_long
from pipeline.io.common import atomic_path, atomic_write, ensure_writable_dir
from pipeline.study.cases import CaseSelector, FEAGroup
from pipeline.study.config import load_study_config
from pipeline.study.dataset import (
    REPORT_QUILT,
    REPORT_ZERNIKES,
    fit_cases,
    study_dataset,
    wavefront_jobs,
    write_exports,
    write_study_netcdf,
)
from pipeline.study.figure_specs import CompareFigure, OutputOptions, ProfileFigure, PsfFigure, SagMapFigure
from pipeline.study.plots import plot_line_profiles, plot_multigrating, plot_psfs, plot_sag_maps
from pipeline.study.profile_specs import ProfileSpec
from pipeline.study.render3d import start_study_render, study_renders
from pipeline.study.study_config import StudyConfig
from pipeline.sweeps.fea_cases import (
    SAG_GRID_X_MM,
    SAG_GRID_Y_MM,
    FEACaseRunner,
    TableRow,
    case_namespace,
    figure_of,
    format_table,
    write_figure_summary,
    write_table_rows,
)
from pipeline.sweeps.sweep import Case, run_sweep

__all__ = ["default_study", "run_study"]

_SCALES_MAS = (250, 100, 25)


def default_study() -> StudyConfig:
    """The paper's study (``cryograting run`` without a config; ``paper_default.toml``)."""
    def case(coverage, t0_um, polish):
        return CaseSelector({"coverage": coverage, "t0_um": t0_um, "polish": polish})

    nominal, strong = case("all", 200, 0.75), case("all", 200, 0.5)
    thicknesses = [200, 150, 100]
    fea = (FEAGroup("table1", {"coverage": "all", "t0_um": thicknesses, "polish": [1.0, 0.75, 0.5]}),
           FEAGroup("table2_holes", {"coverage": "holes", "t0_um": thicknesses, "polish": 1.0}),
           FEAGroup("table2_surfaces", {"coverage": "surfaces", "t0_um": thicknesses, "polish": 1.0}))
    bands = tuple(ProfileSpec("bands", g, "blaze", "band", _SCALES_MAS, deformation=d)
                  for g, d in (("J", ("perfect", nominal, strong)), ("H", ("perfect", nominal)),
                               ("K", ("perfect", nominal))))
    multi = tuple(ProfileSpec("multigrating", g, order, 1.25, _SCALES_MAS, deformation=(d,))
                  for g, order, d in (("J", -2, strong), ("H", -3, nominal), ("K", -4, nominal)))
    figures = (
        SagMapFigure("sag_table1.png", (case("all", 200, 1.0), nominal, strong),
                     ("200 µm, 100 %", "200 µm, 75 %", "200 µm, 50 %"), "Sag maps"),
        SagMapFigure("sag_table2.png", (case("holes", 200, 1.0), case("surfaces", 200, 1.0)),
                     ("NiP only in holes, 200 µm", "NiP only on surfaces, 200 µm"), "Sag maps"),
        PsfFigure("psf_J_K.png", nominal, (("J", 1.25), ("K", 2.20)), ("J 1.25 µm, 200/75", "K 2.20 µm, 200/75"),
                  "Point-spread functions (200 µm / 75 %)"),
        *(ProfileFigure(f"profiles_{g}.png", "bands", g, "Detected line profiles") for g in "JHK"),
        CompareFigure("multigrating_1p25um.png", "multigrating", 250,
                      "1.25 µm line on the J, H and K gratings (250 mas)", "1.25 µm on the J, H and K gratings"),
    )
    return StudyConfig(
        "Cryogenic deformation of the SPIFFI gratings — default study",
        "FEA of the NiP-plated Al 6061 blank cooled 293 K → 80 K (scikit-fem, curved quadratic tets, "
        "bonded thin-film NiP with offset), one global film-stress calibration (see README); "
        "Fourier-optics line profiles (partially coherent slit illumination, collimator WFE, 18 µm pixel).",
        fea, bands + multi, figures, OutputOptions())


def _prepare_out(out: Path) -> None:
    """Create ``out`` and prove it writable before anything is computed or written."""
    ensure_writable_dir(out)


def _run_fea(config: StudyConfig, out: Path, progress: bool):
    """Solve (or reuse) every FEA case; write the case and paper tables; return maps by label."""
    cases = config.cases()
    # the 3-D renders reuse these solutions instead of solving their cases again
    keep = [p for _, ps, _ in study_renders(cases).values() for p in ps] if config.output.figures else []
    runner = FEACaseRunner(fields_dir=out / "fields", fields_for=keep)
    res = run_sweep(runner, [Case(c.params) for c in cases], out, namespace=case_namespace(), workers=1,
                    progress=progress, description="FEA cases", planner=runner.plan)
    res.write_netcdf(out / "sweep.nc")
    outputs = {c.label: o for c, (_, o) in zip(cases, res)}
    _write_cases(cases, outputs, out / "cases.csv")
    write_figure_summary(out / "figure_summary.csv", [c.label for c in cases], outputs)
    maps = {c.label: SagMap(SAG_GRID_X_MM, SAG_GRID_Y_MM,
                            np.asarray(o["sag_um"][1] if isinstance(o["sag_um"], tuple) else o["sag_um"], float),
                            c.label)
            for c, o in ((c, outputs[c.label]) for c in cases)}
    plain = [c for c in cases if c.is_paper_setup]
    rows, in_paper = [], set()
    for pc in paper_cases():
        match = next((c for c in plain if (c.full["coverage"], c.full["t0_um"], c.full["polish"]) ==
                      (pc.coverage, pc.t0_um, pc.polish)), None)
        if match is not None:
            o = outputs[match.label]
            in_paper.add(match.label)
            rows.append(TableRow(pc.table, pc.coverage, pc.t0_um, pc.polish, pc.pv_center_um,
                                 float(o["pv_center_um"]), pc.direction, float(o["quilt_direction_um"]),
                                 pc.calibrate, figure_of(o)))
    if rows:
        write_table_rows(rows, out / "tables.csv")
    return cases, outputs, maps, rows, in_paper


def _write_cases(cases, outputs, path: Path) -> None:
    """One row per FEA case: label, group, P/V and RMS (µm), then every parameter's value."""
    keys = ["pv_center_um", "rms_center_um", "pv_full_um", "rms_full_um", "quilt_direction_um"]
    with atomic_write(path) as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(["label", "group", *keys, *cases[0].full])
        for c in cases:
            w.writerow([c.label, c.group, *(f"{outputs[c.label][k]:.6g}" for k in keys), *c.full.values()])


def format_cases(cases, outputs) -> str:
    """The FEA cases of a study as a text table (P/V and RMS in µm)."""
    w = max(12, *(len(c.label) for c in cases))
    lines = [f"{'case':{w}} {'P/V ctr':>8} {'RMS ctr':>8} {'P/V full':>8} {'quilt':>8}", "-" * (w + 36)]
    for c in cases:
        o = outputs[c.label]
        lines.append(f"{c.label:{w}} {o['pv_center_um']:8.3f} {o['rms_center_um']:8.3f} {o['pv_full_um']:8.3f} "
                     f"{o['quilt_direction_um']:+8.3f}")
    return "\n".join(lines) + "\n(µm; quilt = sag over the central hole crossing − over the rib crossing)"


def _profiles(config: StudyConfig, maps: dict, progress: bool) -> list:
    out = []
    t0 = time.perf_counter()
    for job in config.profile_jobs():
        sag = None if job.case is None else maps[job.case.label]
        r = line_profile(job.grating, job.wavelength_um, job.pixel_scale_mas, sag, order=job.order,
                         pupil_shift_mm=job.pupil_shift_mm)
        out.append((job, r.detected, profile_metrics(r.detected)))
    if progress:
        print(f"line profiles: {len(out)} in {time.perf_counter() - t0:.1f} s")
    return out


_KEYS = ["grating", "order", "wavelength_um", "pixel_scale_mas", "deformation"]
_MKEYS = ["fwhm_um", "fwhm_nm", "resolving_power", "resolving_power_2px", "centroid_um",
          "asymmetry", "outside_slit_fraction", "shoulder_asymmetry"]


def _write_profiles(results, out: Path):
    """Write ``profiles.csv`` and ``profiles.nc``; return the profiles' Dataset (None without profiles)."""
    import xarray as xr


    if not results:
        return None
    with atomic_write(out / "profiles.csv") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(_KEYS + _MKEYS + ["n_peaks", "peak_positions_um", "set", "pupil_shift_x_mm", "pupil_shift_y_mm"])
        for j, prof, m in results:
            peaks = m["peaks"].get("offset_um", [])
            w.writerow([j.grating, j.order if j.order is not None else "", j.wavelength_um,
                        j.pixel_scale_mas, j.deformation] +
                       [f"{m.get(k, np.nan):.5g}" for k in _MKEYS] +
                       [len(peaks), " ".join(f"{p:.1f}" for p in peaks), j.set, *j.pupil_shift_mm])
    grid = np.arange(-150.0, 150.0 + 1e-9, 0.5)
    I = np.stack([np.interp(grid, p.offset_um, p.intensity, left=0.0, right=0.0) for _, p, _ in results])
    col = {"grating": lambda j: j.grating, "order": lambda j: str(j.order),
           "wavelength_um": lambda j: j.wavelength_um, "pixel_scale_mas": lambda j: j.pixel_scale_mas,
           "deformation": lambda j: j.deformation, "set": lambda j: j.set,
           "pupil_shift_x_mm": lambda j: j.pupil_shift_mm[0], "pupil_shift_y_mm": lambda j: j.pupil_shift_mm[1]}
    ds = xr.Dataset(
        {"intensity": (("profile", "offset_um"), I, {"units": "1/µm", "long_name": "detected line profile"})},
        coords={"offset_um": ("offset_um", grid, {"units": "µm"}),
                **{k: ("profile", [f(j) for j, _, _ in results]) for k, f in col.items()},
                **{k: ("profile", [float(m.get(k, np.nan)) for _, _, m in results]) for k in _MKEYS}},
        attrs={"title": "cryograting study: detected line profiles (unit area)"})
    with atomic_path(out / "profiles.nc") as tmp:
        ds.to_netcdf(tmp)
    return ds


def _curve_label(job) -> str:
    label = job.deformation
    if job.order is not None:
        label += f", order {job.order}"
    if any(job.pupil_shift_mm):
        label += f", shift ({job.pupil_shift_mm[0]:g}, {job.pupil_shift_mm[1]:g}) mm"
    return label


def _figures(config: StudyConfig, maps: dict, results: list, out: Path) -> dict:
    """Draw the config's figures; returns {file: (heading, path)} in config order."""
    figs = {}
    for fig in config.figures:
        path = out / fig.file
        if isinstance(fig, SagMapFigure):
            cases = [c for sel in fig.cases for c in config.select(sel)]
            plot_sag_maps([maps[c.label] for c in cases], list(fig.titles) or [c.label for c in cases], path)
        elif isinstance(fig, PsfFigure):
            (c,) = config.select(fig.case)
            psfs = [point_psf(g, wl, maps[c.label]) for g, wl in fig.lines]
            plot_psfs(psfs, list(fig.titles) or [f"{g} {wl:.2f} µm, {c.label}" for g, wl in fig.lines], path)
        elif isinstance(fig, ProfileFigure):
            panels = {}
            for j, prof, _ in results:
                if j.set == fig.set and (not fig.grating or j.grating == fig.grating):
                    row = f"{j.wavelength_um:.2f} µm" + ("" if fig.grating else f" ({j.grating})")
                    panels.setdefault((row, f"{j.pixel_scale_mas} mas"), []).append((_curve_label(j), prof))
            plot_line_profiles(panels, path)
        elif isinstance(fig, CompareFigure):
            sel = [(j, prof) for j, prof, _ in results if j.set == fig.set and j.pixel_scale_mas == fig.pixel_scale_mas]
            several_wl = len({j.wavelength_um for j, _ in sel}) > 1
            curves = [(f"{j.grating}{f' {j.wavelength_um:.2f} µm' if several_wl else ''} order "
                       f"{j.order if j.order is not None else get_grating(j.grating).order} ({j.deformation})"
                       + (f", shift ({j.pupil_shift_mm[0]:g}, {j.pupil_shift_mm[1]:g}) mm"
                          if any(j.pupil_shift_mm) else ""), prof) for j, prof in sel]
            plot_multigrating(curves, path, title=fig.title or f"set {fig.set} ({fig.pixel_scale_mas} mas)")
        figs[fig.file] = (fig.heading, path)
    return figs


def estimate_seconds(config: StudyConfig) -> tuple[float, str]:
    """A study's run time (s) from the benchmarks' per-case seconds (:mod:`pipeline.bounds`),
    and what it is made of, e.g. ``"15 FEA cases x ~3.5 s + 72 line profiles x ~0.05 s"``."""
    cases, n_prof = config.cases(), config.n_profile_jobs()
    fea_s = [fea_case_seconds(c.full["mesh_size_mm"]) for c in cases]
    n_geo = len({tuple(c.full[k] for k in GEOMETRY_KEYS) for c in cases})  # each meshed once (if not cached)
    return (SECONDS["study_overhead"] + sum(fea_s) + n_prof * SECONDS["line_profile"] + n_geo * SECONDS["new_blank"],
            f"{len(cases)} FEA cases x ~{max(fea_s):.1f} s + {n_geo} mesh(es) x ~{SECONDS['new_blank']:.0f} s + "
            f"{n_prof} line profiles x ~{SECONDS['line_profile']:g} s + ~{SECONDS['study_overhead']:.0f} s of "
            "figures, renders and report")


def _warn_if_long(config: StudyConfig) -> None:
    """One stderr line before any work when the study is estimated to take over an hour."""
    seconds, detail = estimate_seconds(config)
    warn_if_long(seconds, "run", detail)


def run_study(out_dir, config: StudyConfig | str | Path | None = None, *, progress: bool = True,
              mesh_size_mm: float | None = None, mesh_bulk_mm: float | None = None) -> dict:
    """Run a study and write tables, profiles, figures and ``report.html`` into ``out_dir``.

    Parameters
    ----------
    out_dir : str or Path
        Output directory (created; finished FEA cases under ``fea/cases`` are reused).
    config : StudyConfig, str or Path, optional
        The study, or a TOML file to load; :func:`default_study` when omitted.
    mesh_size_mm, mesh_bulk_mm : float, optional
        Element sizes (mm) that replace the config's for every FEA case.

    Returns
    -------
    dict
        ``config``, ``cases``, ``outputs`` (per case label: P/V, RMS, ...), ``rows``
        (model vs paper), ``profiles`` (job, profile, metrics) and ``figures``.

    Raises
    ------
    ConfigError, FileNotFoundError
        An invalid or missing config (checked before anything is written).
    NotADirectoryError, PermissionError
        ``out_dir`` is a file or cannot be written.
    """
    if config is None:
        config = default_study()
    elif not isinstance(config, StudyConfig):
        config = load_study_config(config)
    config = config.with_mesh(mesh_size_mm, mesh_bulk_mm)
    out = Path(out_dir)
    _prepare_out(out)
    _warn_if_long(config)
    t0 = time.perf_counter()
    cases, outputs, maps, rows, in_paper = _run_fea(config, out / "fea", progress)
    table = format_table(rows) if rows else ""
    others = [c for c in cases if c.label not in in_paper]
    text = "\n\n".join(t for t in (table, format_cases(others, outputs) if others else "") if t)
    print(text, flush=True)
    t_fea = time.perf_counter() - t0

    # 3-D render: a guarded child process, running while the profiles are computed
    render = start_study_render(cases, out, progress=progress) if config.output.figures else None
    results = _profiles(config, maps, progress)
    profiles_ds = _write_profiles(results, out)
    fits, exports = _fits_dataset_exports(config, cases, outputs, maps, results, profiles_ds, out, progress)
    figs = _figures(config, maps, results, out) if config.output.figures else {}
    if render is not None:
        figs.update(render.figures())
    if config.output.report:
        _report(out, config, table, format_cases(cases, outputs), results, figs, t_fea, time.perf_counter() - t0,
                fits_table=format_fits_html(cases, *fits))
    written = [p for p in ("report.html", "study.nc", "fea/tables.csv", "fea/cases.csv", "profiles.csv")
               if (out / p).exists()]
    print(f"\nwritten in {out}/: {', '.join(written)}, fea/sweep.nc"
          f"{', profiles.nc' if results else ''}{f', {len(figs)} PNG figures' if figs else ''}"
          f"{f', {len(exports)} files in exports/' if exports else ''}")
    return {"config": config, "cases": cases, "outputs": outputs, "rows": rows, "profiles": results,
            "figures": {k: p for k, (_, p) in figs.items()}, "fits": {"zernike": fits[0], "fourier": fits[1]},
            "dataset": out / "study.nc", "exports": exports}


def _fits_dataset_exports(config, cases, outputs, maps, results, profiles_ds, out: Path, progress: bool):
    """Zernike + Fourier fits of every case, ``study.nc``, and (if configured) ``exports/``."""
    t = time.perf_counter()
    zfits, ffits = fit_cases(cases, maps)
    waves = wavefront_jobs([j for j, _, _ in results])
    ds = study_dataset(cases, outputs, maps, zfits, ffits, profiles_ds, waves,
                       attrs={"study_title": config.title, "study_description": config.description})
    write_study_netcdf(ds, out / "study.nc")
    t_ds = time.perf_counter() - t
    exports = write_exports(out / "exports", cases, maps, zfits, waves) if config.output.exports else []
    if progress:
        print(f"fits and study.nc: {t_ds:.1f} s" + (f"; exports ({len(exports)} files): "
                                                    f"{time.perf_counter() - t - t_ds:.1f} s" if exports else ""))
    return (zfits, ffits), exports


def format_fits_html(cases, zfits, ffits) -> str:
    """HTML table: the main Zernike terms (nm, RMS-normalised) and quilt amplitudes (nm) per case."""
    def cell(v):
        return f"<td>{v * 1e3:.1f}</td>" if v is not None and np.isfinite(v) else "<td>–</td>"

    head = ("<tr><th>case</th>" + "".join(f"<th>{html.escape(n)}</th>" for n in REPORT_ZERNIKES.values())
            + "<th>Z resid. RMS</th>" + "".join(f"<th>{html.escape(n)}</th>" for n in REPORT_QUILT.values())
            + "<th>F resid. RMS</th></tr>")
    rows = []
    for c, z, f in zip(cases, zfits, ffits):
        zc = [z.coefficients.get(t) if z is not None else None for t in REPORT_ZERNIKES]
        fa = [f.amplitude_um.get(k) if f is not None else None for k in REPORT_QUILT]
        rows.append(f"<tr><td>{html.escape(c.label)}</td>" + "".join(cell(v) for v in zc)
                    + cell(z.residual_rms_um if z is not None else None) + "".join(cell(v) for v in fa)
                    + cell(f.residual_rms_um if f is not None else None) + "</tr>")
    return f"<table>{head}{''.join(rows)}</table>"


def _report(out: Path, config: StudyConfig, table: str, cases_table: str, results, figs: dict,
            t_fea: float, t_all: float, fits_table: str = "") -> None:
    def img(p):
        return f'<img src="data:image/png;base64,{base64.b64encode(Path(p).read_bytes()).decode()}" style="max-width:100%">'

    # metrics at each grating's band centre in its blaze order (all profiles if there are none)
    shown = [r for r in results if r[0].order is None and r[0].wavelength_um == get_grating(r[0].grating).centre_um]
    rrows = "".join(
        f"<tr><td>{j.grating}</td><td>{j.wavelength_um:.2f}</td><td>{j.pixel_scale_mas}</td>"
        f"<td>{html.escape(j.deformation)}</td><td>{m['fwhm_um']:.1f}</td>"
        f"<td>{m.get('resolving_power', float('nan')):.0f}</td><td>{m['asymmetry']:+.3f}</td>"
        f"<td>{m['outside_slit_fraction']:.3f}</td></tr>"
        for j, _, m in (shown or results))
    sections, last = [], None
    for heading, path in figs.values():
        if heading != last:
            sections.append(f"<h2>{html.escape(heading)}</h2>")
            last = heading
        sections.append(img(path))
    paper = (f"<h2>P/V<sub>center</sub>: model vs paper (Tables 1 and 2)</h2><pre>{html.escape(table)}</pre>"
             if table else "")
    metrics = ("<h2>Line-profile metrics" + (" (band centres)" if shown else "") + "</h2><table><tr><th>grating</th>"
               "<th>λ µm</th><th>mas</th><th>deformation</th><th>FWHM µm</th><th>R (FWHM)</th><th>asymmetry</th>"
               f"<th>outside slit</th></tr>{rrows}</table>" if results else "")
    fits = (f"<h2>Zernike and quilt fits over the central 82 × 72 mm (nm)</h2><p>Zernike: 37 Fringe terms, "
            "RMS-normalised coefficients on the disc circumscribing the box (radius 54.6 mm); quilt: Fourier "
            "amplitudes at the hole pitches D<sub>x</sub> × D<sub>y</sub> (21 × 18 mm on the paper's blank); "
            "residual RMS after each fit. All coefficients are in <code>study.nc</code>.</p>"
            f"{fits_table}" if fits_table else "")
    body = f"""<!doctype html><html><head><meta charset="utf-8"><title>{html.escape(config.title)}</title>
<style>body{{font-family:sans-serif;max-width:1100px;margin:auto}} td,th{{padding:2px 8px;text-align:right}}
pre{{background:#f4f4f4;padding:8px}}</style></head><body>
<h1>{html.escape(config.title)}</h1>
<p>{html.escape(config.description)} FEA {t_fea:.0f} s, total {t_all:.0f} s.</p>
{paper}<h2>FEA cases: P/V and RMS over the central 82 × 72 mm and the whole face</h2>
<pre>{html.escape(cases_table)}</pre>
{fits}{''.join(sections)}
{metrics}
</body></html>"""
    with atomic_write(out / "report.html") as fh:
        fh.write(body)
