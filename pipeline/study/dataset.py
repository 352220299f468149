"""The study's fits, its one labelled dataset (``study.nc``) and the exports for design codes.

Used by :func:`pipeline.study.run.run_study` after the FEA cases and line profiles:

* :func:`fit_cases` — every FEA sag map over the central 82 × 72 mm region
  (``optics.sagmap`` region ``center``) with

  - **Zernike**: the 37 Fringe terms (Fringe 1–37, i.e. every term up to n + |m| = 10
    plus Z37 = (12, 0)), least squares on the valid samples of the rectangle, on the
    disc that circumscribes it (centre (0, 0), radius = half-diagonal = 54.56 mm).
    Stored RMS-normalised (Noll / Zemax Standard normalisation) and also unnormalised
    (Fringe / CODE V ZFR: peak 1 at the rim);
  - **Fourier quilt**: DC + plane + the harmonics ``(i/Dx, j/Dy)``, ``|i|, |j| <= 3``
    with cross terms (:func:`optics.fitting.fit_fourier`), ``Dx, Dy`` = the case's hole
    pitches ``pitch_x_mm``, ``pitch_y_mm`` (21 × 18 mm for the paper's blank; the
    what-if blanks use their own; a blank without holes is fitted at its nominal
    pitches and gives ~0 amplitudes), phases referenced to (0, 0).

  Coefficients, residual RMS and P/V are kept. All cases share one design matrix
  (:func:`optics.fitting.fit_zernike_maps`), so 15 cases cost about one fit.
* :func:`study_dataset` / :func:`write_study_netcdf` — ``study.nc``.
* :func:`write_exports` — ``exports/`` (see its docstring for the file names).
"""

from __future__ import annotations

import csv
import math
import re
from pathlib import Path

import numpy as np

from optics.fitting import fit_fourier, fit_fourier_maps, fit_zernike_map, fit_zernike_maps, resolve_terms
from optics.grating import get_grating
from optics.sagmap import SagMap
from optics.zernike import nm_to_fringe, nm_to_noll, norm_factor, zernike_name
from pipeline.io.codev_zfr import write_codev_zernike
from pipeline.io.common import atomic_path, atomic_write
from pipeline.io.registry import write_sag_map
from pipeline.io.zemax import write_zemax_zernike
from pipeline.io.zernike import write_zernike_list
from pipeline.study.schema import FEA_KEYS
from pipeline.sweeps.fea_cases import FIGURE_KEYS

__all__ = [
    "FOURIER_HARMONICS",
    "REPORT_QUILT",
    "REPORT_ZERNIKES",
    "ZERNIKE_APERTURE",
    "file_slug",
    "fit_cases",
    "study_dataset",
    "wavefront_jobs",
    "write_exports",
    "write_study_netcdf",
]

#: Fit region (optics.sagmap REGIONS key): the paper's 82 x 72 mm P/V_center box.
ZERNIKE_APERTURE = "center"
#: Number of Fringe Zernike terms fitted.
N_FRINGE = 37
#: Highest quilt harmonic of the Fourier fit.
FOURIER_HARMONICS = 3
#: Zernike terms shown in the report: (n, m) -> name.
REPORT_ZERNIKES = {(2, 0): "defocus", (2, 2): "astig 0°", (2, -2): "astig 45°", (3, 1): "coma x",
                   (3, -1): "coma y", (3, 3): "trefoil x", (4, 0): "spherical"}
#: Quilt components shown in the report: (i, j) -> name.
REPORT_QUILT = {(1, 0): "1/Dx", (0, 1): "1/Dy", (1, 1): "(1,1)", (1, -1): "(1,−1)", (2, 0): "2/Dx", (0, 2): "2/Dy"}


def fit_cases(cases, maps: dict) -> tuple[list, list]:
    """Zernike and Fourier fits of every case's sag map (see the module docstring).

    Returns ``(zernike_fits, fourier_fits)``, one per case in order; an entry is None
    where the map has too few valid samples in the region (its values become NaN).
    """
    terms = resolve_terms(N_FRINGE, "fringe")
    sags = [maps[c.label] for c in cases]
    periods = [(float(c.full["pitch_x_mm"]), float(c.full["pitch_y_mm"])) for c in cases]
    try:
        zf = fit_zernike_maps(sags, terms, ZERNIKE_APERTURE, index="fringe")
    except ValueError:  # one map is unusable: fit one by one and keep the others
        zf = [_or_none(fit_zernike_map, s, terms, ZERNIKE_APERTURE, index="fringe") for s in sags]
    try:
        ff = fit_fourier_maps(sags, periods, FOURIER_HARMONICS, ZERNIKE_APERTURE)
    except ValueError:
        ff = [_or_none(fit_fourier, s, px, py, FOURIER_HARMONICS, ZERNIKE_APERTURE)
              for s, (px, py) in zip(sags, periods)]
    return zf, ff


def _or_none(f, *args, **kw):
    try:
        return f(*args, **kw)
    except ValueError:
        return None


def wavefront_jobs(jobs) -> list[dict]:
    """The distinct (case, grating, order, wavelength) of the deformed line profiles, with
    ``opd_per_sag = -(cos alpha + cos beta)`` (:func:`optics.pupil.grating_opd_um`)."""
    out, seen = [], set()
    for j in jobs:
        if j.case is None:
            continue
        g = get_grating(j.grating)
        order = g.order if j.order is None else int(j.order)
        key = (j.case.label, g.name, order, float(j.wavelength_um))
        if key in seen:
            continue
        seen.add(key)
        beta = float(g.beta_deg(j.wavelength_um, order))
        factor = -(math.cos(math.radians(g.incidence_deg)) + math.cos(math.radians(beta)))
        out.append({"case": j.case.label, "grating": g.name, "order": order, "wavelength_um": float(j.wavelength_um),
                    "incidence_deg": float(g.incidence_deg), "beta_deg": beta, "opd_per_sag": factor})
    return out


def _column(values):
    """A case/profile coordinate: strings stay strings, numbers become float or int arrays."""
    if all(isinstance(v, str) for v in values):
        return np.array(values, dtype=str)
    if all(isinstance(v, (bool, np.bool_)) for v in values):
        return np.array(values, dtype=np.int8)
    if all(isinstance(v, (int, np.integer)) and not isinstance(v, bool) for v in values):
        return np.array(values, dtype=np.int64)
    try:
        return np.array(values, dtype=float)
    except (TypeError, ValueError):
        return np.array([str(v) for v in values], dtype=str)


_OUTPUT_UNITS = {"pv_center_um": ("µm", "P/V of the sag over the central 82 x 72 mm (piston, tilt removed)"),
                 "rms_center_um": ("µm", "RMS of the sag over the central 82 x 72 mm"),
                 "pv_full_um": ("µm", "P/V of the sag over the whole face"),
                 "rms_full_um": ("µm", "RMS of the sag over the whole face"),
                 "quilt_direction_um": ("µm", "sag over the central hole crossing minus over the rib crossing"),
                 "solve_s": ("s", "FEA solve time"), "ndof": ("1", "FEA degrees of freedom"),
                 "stress_scale_used": ("1", "film-stress calibration factor used")}


def study_dataset(cases, outputs: dict, maps: dict, zfits: list, ffits: list, profiles_ds=None,
                  wavefronts: list | None = None, attrs: dict | None = None):
    """Everything of a study in one labelled :class:`xarray.Dataset` (see ``study.nc`` in the README).

    Dims: ``case``; ``y_mm``, ``x_mm`` (sag maps); ``zernike`` (Fringe index 1-37);
    ``fourier`` (quilt components); ``profile``, ``offset_um`` (line profiles, as
    ``profiles.nc``); ``wavefront`` (grating wavefronts = ``opd_per_sag`` x sag map).
    """
    import xarray as xr

    labels = [c.label for c in cases]
    K = len(cases)
    first = maps[labels[0]]
    zt = next((z.terms for z in zfits if z is not None), None)
    comps = next((f.components for f in ffits if f is not None), ())
    nz = len(zt) if zt else 0
    coords = {
        "case": ("case", np.arange(K), {"long_name": "FEA case index"}),
        "label": ("case", np.array(labels, dtype=str), {"long_name": "case label (as cases.csv, profiles)"}),
        "group": ("case", np.array([c.group for c in cases], dtype=str), {"long_name": "[[fea.cases]] group"}),
        "x_mm": ("x_mm", first.x_mm, {"units": "mm", "long_name": "x on the grating face, dispersion direction"}),
        "y_mm": ("y_mm", first.y_mm, {"units": "mm", "long_name": "y on the grating face, ruling direction"}),
    }
    for k in cases[0].full:
        p = FEA_KEYS.get(k)
        a = {"long_name": f"FEA parameter {k}" + (f": {p.meaning}" if p is not None and p.meaning else "")}
        unit = p.unit if p is not None else ""
        if unit:
            a["units"] = unit
        coords[k] = ("case", _column([c.full[k] for c in cases]), a)
    data = {}
    numeric = [k for k, v in outputs[labels[0]].items()
               if not k.startswith("coord:") and isinstance(v, (int, float, np.integer, np.floating))]
    for k in numeric:
        units, long = _OUTPUT_UNITS.get(k) or FIGURE_KEYS.get(k, ("", "", k))[1:]
        a = {"units": units, "long_name": long}
        if k.startswith("rb_"):
            a["comment"] = ("least-squares 6-DOF motion of the front face about its centre (0, 0, z_front) minus "
                            "that of the whole blank (fea.front_figure); x dispersion, y rulings, z outward normal")
        data[k] = ("case", np.array([float(outputs[lb].get(k, np.nan)) for lb in labels]), a)
    data["sag_um"] = (("case", "y_mm", "x_mm"), np.stack([maps[lb].sag_um for lb in labels]).astype(np.float32),
                      {"units": "µm", "long_name": "front-face sag along +z (outward normal), NaN = no data"})
    if zt:
        zr = next(z for z in zfits if z is not None)
        coords["zernike"] = ("zernike", np.array([nm_to_fringe(*t) for t in zt]),
                             {"long_name": "Fringe (CODE V ZFR) index"})
        coords["zernike_noll"] = ("zernike", np.array([nm_to_noll(*t) for t in zt]), {"long_name": "Noll index"})
        coords["zernike_n"] = ("zernike", np.array([t[0] for t in zt]), {"long_name": "radial degree n"})
        coords["zernike_m"] = ("zernike", np.array([t[1] for t in zt]),
                               {"long_name": "azimuthal frequency m (>0 cos, <0 sin)"})
        coords["zernike_name"] = ("zernike", np.array([zernike_name(*t) for t in zt], dtype=str))
        C = np.array([z.coefficient_array if z is not None else np.full(nz, np.nan) for z in zfits])
        N = np.array([norm_factor(*t) for t in zt])
        zattrs = {"units": "µm", "aperture": f"{ZERNIKE_APERTURE} (82 x 72 mm rectangle)",
                  "normalisation_radius_mm": zr.radius_mm, "centre_x_mm": zr.center_mm[0],
                  "centre_y_mm": zr.center_mm[1], "theta": "from +x towards +y"}
        data["zernike_um"] = (("case", "zernike"), C, {**zattrs, "long_name": "Zernike coefficient, RMS-normalised "
                                                                   "terms (Noll / Zemax Standard normalisation)"})
        data["zernike_fringe_um"] = (("case", "zernike"), C * N, {**zattrs, "long_name": "Zernike coefficient, "
                                                                   "unnormalised terms (Fringe / CODE V ZFR)"})
        for k, lng in (("residual_rms_um", "RMS"), ("residual_pv_um", "P/V"), ("condition_number", "condition")):
            data[f"zernike_{k}"] = ("case", np.array([getattr(z, k) if z is not None else np.nan for z in zfits]),
                                    {"units": "1" if k == "condition_number" else "µm",
                                     "long_name": f"{lng} of the sag minus the 37-term Zernike fit over the region"
                                     if k != "condition_number" else "condition number of the design matrix"})
    if comps:
        coords["fourier"] = ("fourier", np.arange(len(comps)), {"long_name": "quilt component index"})
        coords["fourier_i"] = ("fourier", np.array([c[0] for c in comps]), {"long_name": "harmonic i of 1/Dx"})
        coords["fourier_j"] = ("fourier", np.array([c[1] for c in comps]), {"long_name": "harmonic j of 1/Dy"})
        nan = np.full(len(comps), np.nan)
        data["fourier_amplitude_um"] = (("case", "fourier"), np.array(
            [[f.amplitude_um[c] for c in comps] if f is not None else nan for f in ffits]),
            {"units": "µm", "long_name": "quilt amplitude A_ij: A cos(2 pi (i x/Dx + j y/Dy) - phi)",
             "aperture": f"{ZERNIKE_APERTURE} (82 x 72 mm rectangle)", "phase_origin_mm": "0 0"})
        data["fourier_phase_rad"] = (("case", "fourier"), np.array(
            [[f.phase_rad[c] for c in comps] if f is not None else nan for f in ffits]),
            {"units": "rad", "long_name": "quilt phase phi_ij (origin x = y = 0)"})
        per = {"period_x_mm": ("mm", "Dx: quilt period (hole pitch) along x"),
               "period_y_mm": ("mm", "Dy: quilt period (hole pitch) along y"),
               "piston_um": ("µm", "DC term of the Fourier fit"),
               "residual_rms_um": ("µm", "RMS of the sag minus the Fourier fit over the region"),
               "residual_pv_um": ("µm", "P/V of the sag minus the Fourier fit over the region")}
        for k, (u, lng) in per.items():
            data[f"fourier_{k}"] = ("case", np.array([getattr(f, k) if f is not None else np.nan for f in ffits]),
                                    {"units": u, "long_name": lng})
        for i, ax in enumerate("xy"):
            data[f"fourier_slope_{ax}_um_per_mm"] = (
                "case", np.array([f.slope_um_per_mm[i] if f is not None else np.nan for f in ffits]),
                {"units": "µm/mm", "long_name": f"plane term of the Fourier fit along {ax}"})
    if wavefronts:
        coords["wavefront"] = ("wavefront", np.arange(len(wavefronts)))
        for k, u in (("case", ""), ("grating", ""), ("order", ""), ("wavelength_um", "µm"), ("incidence_deg", "deg"),
                     ("beta_deg", "deg"), ("opd_per_sag", "1")):
            name = "wavefront_case_label" if k == "case" else f"wavefront_{k}"
            coords[name] = ("wavefront", _column([w[k] for w in wavefronts]), {"units": u} if u else {})
        coords["wavefront_opd_per_sag"][2]["long_name"] = ("grating wavefront (OPD) = opd_per_sag x sag_um of the "
                                                          "case = -(cos alpha + cos beta) h")
    ds = xr.Dataset(data, coords=coords,
                    attrs={"title": "cryograting study: FEA cases, sag maps, fits, line profiles",
                           "Conventions": "CF-1.8",
                           "comment": "sag along the outward normal +z; x dispersion, y ruling (optics.sagmap)",
                           **(attrs or {})})
    if profiles_ds is not None:
        ds = ds.merge(profiles_ds, combine_attrs="drop_conflicts")
    return ds


def write_study_netcdf(ds, path: Path) -> Path:
    """Write ``ds`` atomically (temporary file + rename)."""
    with atomic_path(path) as tmp:
        ds.to_netcdf(tmp)
    return Path(path)


def file_slug(text: str) -> str:
    """``text`` (a case label) as a file-name part: ``/`` becomes ``-``, other runs of
    characters outside ``[A-Za-z0-9.+-]`` become ``_`` ("case" when nothing is left)."""
    return re.sub(r"[^A-Za-z0-9.+-]+", "_", str(text).replace("/", "-")).strip("_") or "case"


def write_exports(out: Path, cases, maps: dict, zfits: list, wavefronts: list) -> list[Path]:
    """Files for optical design codes in ``out`` (created), listed in ``out/index.csv``.

    Per FEA case ``i`` (label slug ``L``, e.g. ``200/75`` -> ``200-75``):

    * ``case{i:02d}_{L}_sag.int`` — sag map, CODE V GRD ``SUR`` (WVL 0.6328 µm);
    * ``case{i:02d}_{L}_sag.dat`` — sag map, Zemax Grid Sag (mm);
    * ``case{i:02d}_{L}_zernike_zfr.int`` — the 37-term fit as a CODE V ``ZFR 37 SUR``
      deck (Fringe, unnormalised, waves of 0.6328 µm; radius in the title);
    * ``case{i:02d}_{L}_zernike_standard_zemax.dat`` / ``..._zernike_fringe_zemax.dat`` —
      the fit as OpticStudio Zernike Standard Sag / Zernike Fringe Sag extra data (mm);
    * ``case{i:02d}_{L}_zernike_fringe.txt`` / ``..._zernike_noll.txt`` — the same fit
      as self-describing project lists (Fringe unnormalised, Noll RMS-normalised);

    and per deformed line profile's (case, grating, order, wavelength):
    ``case{i:02d}_{L}_{grating}_m{order}_{wl}um_wfr.int`` — the grating's wavefront
    ``-(cos alpha + cos beta) h`` on the face grid, CODE V ``WFR`` at that wavelength.
    Files written by an earlier run and not rewritten (listed in the old index) are removed.
    """
    out.mkdir(parents=True, exist_ok=True)
    index = []
    stem = {c.label: f"case{i:02d}_{file_slug(c.label)}" for i, c in enumerate(cases)}
    for c, z in zip(cases, zfits):
        s, m = stem[c.label], maps[c.label]
        write_sag_map(m, out / f"{s}_sag.int", kind="SUR")
        write_sag_map(m, out / f"{s}_sag.dat")
        index += [(f"{s}_sag.int", c.label, "sag CODE V INT SUR", "", "", ""),
                  (f"{s}_sag.dat", c.label, "sag Zemax Grid Sag", "", "", "")]
        if z is not None:
            write_codev_zernike(z.coefficients, out / f"{s}_zernike_zfr.int", z.radius_mm, coeffs_normalised=z.norm,
                                title=f"{c.label} sag fit")
            index.append((f"{s}_zernike_zfr.int", c.label, "Zernike fit CODE V ZFR SUR", "", "", ""))
            for conv in ("standard", "fringe"):
                write_zemax_zernike(z.coefficients, out / f"{s}_zernike_{conv}_zemax.dat", conv, z.radius_mm,
                                    coeffs_normalised=z.norm)
                index.append((f"{s}_zernike_{conv}_zemax.dat", c.label, f"Zernike fit Zemax {conv} sag", "", "", ""))
            for conv in ("fringe", "noll"):
                write_zernike_list(z.coefficients, out / f"{s}_zernike_{conv}.txt", conv, z.radius_mm,
                                   coeffs_normalised=z.norm)
                index.append((f"{s}_zernike_{conv}.txt", c.label, f"Zernike list ({conv})", "", "", ""))
    for w in wavefronts:
        m = maps[w["case"]]
        name = f"{stem[w['case']]}_{w['grating']}_m{w['order']}_{w['wavelength_um']:g}um_wfr.int"
        opd = SagMap(m.x_mm, m.y_mm, w["opd_per_sag"] * m.sag_um,
                     f"{w['grating']} order {w['order']} {w['wavelength_um']:g} um OPD, {w['case']}")
        write_sag_map(opd, out / name, kind="WFR", wavelength_um=w["wavelength_um"])
        index.append((name, w["case"], "grating wavefront CODE V INT WFR", w["grating"], w["order"], w["wavelength_um"]))
    old = out / "index.csv"
    if old.exists():
        keep = {r[0] for r in index} | {"index.csv"}
        try:
            with old.open() as fh:
                stale = [r["file"] for r in csv.DictReader(fh) if r.get("file") and r["file"] not in keep]
        except (OSError, csv.Error, KeyError):
            stale = []
        for f in stale:
            if "/" not in f and (out / f).is_file():
                (out / f).unlink()
    with atomic_write(old) as fh:
        wr = csv.writer(fh, lineterminator="\n")
        wr.writerow(["file", "case", "content", "grating", "order", "wavelength_um"])
        wr.writerows(index)
    return [out / r[0] for r in index]
