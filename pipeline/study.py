"""The default end-to-end study: the paper's FEA tables and the line profiles they cause.

``run_study(out_dir)`` (CLI: ``cryograting run``) writes into ``out_dir``:

* ``fea/tables.csv``, ``fea/sweep.nc`` — the 15 paper cases, model vs paper, sag maps;
* ``profiles.csv`` and ``profiles.nc`` — detected line profiles and their metrics for
  J, H, K at band centre and edges in 250/100/25 mas, for a perfect grating and for the
  200 µm / 75 % deformation (J also 200 µm / 50 %), and the 1.25 µm line on the J, H
  and K gratings in orders −2/−3/−4 (J with 200/50, H and K with 200/75, as the paper);
* PNG figures and ``report.html`` that puts them together.
"""

from __future__ import annotations

import csv
import html
import time
from pathlib import Path

import numpy as np

__all__ = ["run_study", "STUDY_PROFILES"]

#: (grating, wavelengths µm) of the default study: band edges and centre
STUDY_BANDS = {"J": (1.10, 1.25, 1.40), "H": (1.45, 1.65, 1.85), "K": (1.95, 2.20, 2.45)}
PIXEL_SCALES = (250, 100, 25)
NOMINAL = ("all", 200.0, 0.75)
J_STRONG = ("all", 200.0, 0.50)
#: the 1.25 µm line on three gratings (paper §5.4): grating, order, deformation
STUDY_PROFILES = [("J", -2, J_STRONG), ("H", -3, NOMINAL), ("K", -4, NOMINAL)]


def _profiles(maps, progress: bool):
    from optics.lineprofile import line_profile
    from optics.metrics import profile_metrics

    jobs = []
    for g, wls in STUDY_BANDS.items():
        defs = [("perfect", None), ("200/75", NOMINAL)] + ([("200/50", J_STRONG)] if g == "J" else [])
        for wl in wls:
            for mas in PIXEL_SCALES:
                for label, case in defs:
                    jobs.append(dict(grating=g, order=None, wavelength_um=wl, pixel_scale_mas=mas,
                                     deformation=label, case=case))
    for g, order, case in STUDY_PROFILES:
        for mas in PIXEL_SCALES:
            jobs.append(dict(grating=g, order=order, wavelength_um=1.25, pixel_scale_mas=mas,
                             deformation=f"{case[1]:g}/{100 * case[2]:g}", case=case, multigrating=True))
    out = []
    t0 = time.perf_counter()
    for j in jobs:
        sag = None if j["case"] is None else maps[j["case"]]
        r = line_profile(j["grating"], j["wavelength_um"], j["pixel_scale_mas"], sag, order=j["order"])
        m = profile_metrics(r.detected)
        out.append((j, r.detected, m))
    if progress:
        print(f"line profiles: {len(out)} in {time.perf_counter() - t0:.1f} s")
    return out


def _write_profiles(results, out: Path) -> None:
    import xarray as xr

    from pipeline.io_common import atomic_path, atomic_write

    keys = ["grating", "order", "wavelength_um", "pixel_scale_mas", "deformation"]
    mkeys = ["fwhm_um", "fwhm_nm", "resolving_power", "resolving_power_2px", "centroid_um",
             "asymmetry", "outside_slit_fraction", "shoulder_asymmetry"]
    with atomic_write(out / "profiles.csv") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(keys + mkeys + ["n_peaks", "peak_positions_um"])
        for j, prof, m in results:
            peaks = m["peaks"].get("offset_um", [])
            w.writerow([j["grating"], j["order"] if j["order"] is not None else "", j["wavelength_um"],
                        j["pixel_scale_mas"], j["deformation"]] +
                       [f"{m.get(k, np.nan):.5g}" for k in mkeys] +
                       [len(peaks), " ".join(f"{p:.1f}" for p in peaks)])
    grid = np.arange(-150.0, 150.0 + 1e-9, 0.5)
    I = np.stack([np.interp(grid, p.offset_um, p.intensity, left=0.0, right=0.0) for _, p, _ in results])
    ds = xr.Dataset(
        {"intensity": (("profile", "offset_um"), I, {"units": "1/µm", "long_name": "detected line profile"})},
        coords={"offset_um": ("offset_um", grid, {"units": "µm"}),
                **{k: ("profile", [str(j[k]) if k in ("order", "deformation", "grating") else j[k]
                                   for j, _, _ in results]) for k in keys},
                **{k: ("profile", [float(m.get(k, np.nan)) for _, _, m in results]) for k in mkeys}},
        attrs={"title": "cryograting default study: detected line profiles (unit area)"})
    with atomic_path(out / "profiles.nc") as tmp:
        ds.to_netcdf(tmp)


def run_study(out_dir, *, progress: bool = True, mesh_size_mm: float | None = None,
              mesh_bulk_mm: float | None = None) -> dict:
    """Run the default study and write tables, profiles, figures and ``report.html``.

    Returns a dict with the table rows, the profile results and the figure paths.
    """
    from optics.lineprofile import point_psf
    from pipeline.fea_cases import format_table, run_tables
    from pipeline.plots import plot_line_profiles, plot_multigrating, plot_psfs, plot_sag_maps

    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise NotADirectoryError(f"--out {out} exists and is not a directory")
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    rows, maps = run_tables(out / "fea", progress=progress, return_maps=True,
                            mesh_size_mm=mesh_size_mm, mesh_bulk_mm=mesh_bulk_mm)
    table = format_table(rows)
    print(table, flush=True)
    t_fea = time.perf_counter() - t0
    results = _profiles(maps, progress)
    _write_profiles(results, out)
    figs = {}
    figs["sag_table1"] = plot_sag_maps([maps[("all", 200.0, p)] for p in (1.0, 0.75, 0.5)],
                                       ["200 µm, 100 %", "200 µm, 75 %", "200 µm, 50 %"], out / "sag_table1.png")
    figs["sag_table2"] = plot_sag_maps([maps[("holes", 200.0, 1.0)], maps[("surfaces", 200.0, 1.0)]],
                                       ["NiP only in holes, 200 µm", "NiP only on surfaces, 200 µm"],
                                       out / "sag_table2.png")
    psfs = [point_psf(g, wl, maps[NOMINAL]) for g, wl in (("J", 1.25), ("K", 2.20))]
    figs["psf"] = plot_psfs(psfs, ["J 1.25 µm, 200/75", "K 2.20 µm, 200/75"], out / "psf_J_K.png")
    for g in STUDY_BANDS:
        panels = {}
        for j, prof, _ in results:
            if j["grating"] == g and not j.get("multigrating"):
                panels.setdefault((f"{j['wavelength_um']:.2f} µm", f"{j['pixel_scale_mas']} mas"), []).append(
                    (j["deformation"], prof))
        figs[f"profiles_{g}"] = plot_line_profiles(panels, out / f"profiles_{g}.png")
    multi = [(f"{j['grating']} order {j['order']} ({j['deformation']})", prof)
             for j, prof, _ in results if j.get("multigrating") and j["pixel_scale_mas"] == 250]
    figs["multigrating"] = plot_multigrating(multi, out / "multigrating_1p25um.png")
    _report(out, table, results, figs, t_fea, time.perf_counter() - t0)
    print(f"\nwritten: {out}/report.html (+ fea/tables.csv, profiles.csv, profiles.nc, PNG figures)")
    return {"rows": rows, "profiles": results, "figures": figs}


def _report(out: Path, table: str, results, figs: dict, t_fea: float, t_all: float) -> None:
    import base64

    from pipeline.io_common import atomic_write

    def img(p):
        return f'<img src="data:image/png;base64,{base64.b64encode(Path(p).read_bytes()).decode()}" style="max-width:100%">'

    rrows = "".join(
        f"<tr><td>{j['grating']}</td><td>{j['wavelength_um']:.2f}</td><td>{j['pixel_scale_mas']}</td>"
        f"<td>{html.escape(j['deformation'])}</td><td>{m['fwhm_um']:.1f}</td>"
        f"<td>{m.get('resolving_power', float('nan')):.0f}</td><td>{m['asymmetry']:+.3f}</td>"
        f"<td>{m['outside_slit_fraction']:.3f}</td></tr>"
        for j, _, m in results if j["wavelength_um"] in (1.25, 1.65, 2.20) and not j.get("multigrating"))
    body = f"""<!doctype html><html><head><meta charset="utf-8"><title>cryograting study</title>
<style>body{{font-family:sans-serif;max-width:1100px;margin:auto}} td,th{{padding:2px 8px;text-align:right}}
pre{{background:#f4f4f4;padding:8px}}</style></head><body>
<h1>Cryogenic deformation of the SPIFFI gratings — default study</h1>
<p>FEA of the NiP-plated Al 6061 blank cooled 293 K → 80 K (scikit-fem, curved quadratic tets, bonded
thin-film NiP with offset), one global film-stress calibration (see README); Fourier-optics line
profiles (partially coherent slit illumination, collimator WFE, 18 µm pixel). FEA {t_fea:.0f} s,
total {t_all:.0f} s.</p>
<h2>P/V<sub>center</sub>: model vs paper (Tables 1 and 2)</h2><pre>{html.escape(table)}</pre>
<h2>Sag maps</h2>{img(figs['sag_table1'])}{img(figs['sag_table2'])}
<h2>Point-spread functions (200 µm / 75 %)</h2>{img(figs['psf'])}
<h2>Detected line profiles</h2>{img(figs['profiles_J'])}{img(figs['profiles_H'])}{img(figs['profiles_K'])}
<h2>1.25 µm on the J, H and K gratings</h2>{img(figs['multigrating'])}
<h2>Line-profile metrics (band centres)</h2><table><tr><th>grating</th><th>λ µm</th><th>mas</th>
<th>deformation</th><th>FWHM µm</th><th>R (FWHM)</th><th>asymmetry</th><th>outside slit</th></tr>{rrows}</table>
</body></html>"""
    with atomic_write(out / "report.html") as fh:
        fh.write(body)
