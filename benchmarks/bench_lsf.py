"""Benchmark and convergence study of :func:`optics.lineprofile.line_profile`.

Run: ``.venv/bin/python benchmarks/bench_lsf.py`` (about a minute on 2 cores). Writes
``benchmarks/results_lsf.md`` with what it measured: timings (one LSF; all 4 gratings x
3 wavelengths x 3 pixel scales), the L1 distance of the default settings from a
converged reference for every case, a one-parameter-at-a-time sensitivity table, and
the paper-behaviour numbers on the analytic quilt.
"""

from __future__ import annotations

import math
import os
import platform
import time
from pathlib import Path

import numpy as np

from optics.grating import GRATINGS, SPIFFI
from optics.imaging import basic_lsf
from optics.lineprofile import LsfSettings, line_profile, point_psf
from optics.metrics import find_profile_peaks, l1_distance, profile_metrics
from optics.sagmap import quilt_sag_map

REF = LsfSettings(detector_step_um=0.25, n_fft=4096, source_step_mm=0.5, min_source_rows=20)
SCALES = (25, 100, 250)


def _time(fn, repeat=7):
    ts = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t)
    return float(np.median(ts)), float(np.min(ts))


def main() -> None:
    q = quilt_sag_map(0.82, form="product")  # the harder form for convergence (broader order spectrum)
    qs = quilt_sag_map(0.82, form="sum")
    out = ["# LSF benchmark and convergence (`benchmarks/bench_lsf.py`)", "",
           "Regenerate: `.venv/bin/python benchmarks/bench_lsf.py` (about 20 s on 2 cores).", "",
           f"Machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
           f"numpy {np.__version__}. Defaults: `{LsfSettings()}`.", "",
           f"Converged reference: `{REF}` (itself within 0.07 % L1 of a 2x finer one, J 1.10 µm).", ""]

    # ---- timings
    line_profile("J", 1.25, 100, q)  # warm-up
    med, best = _time(lambda: line_profile("J", 1.25, 100, q))
    out += ["## Timing", "", f"* One detected LSF (J 1.25 µm, 100 mas, quilt): median {med * 1e3:.1f} ms, best {best * 1e3:.1f} ms."]
    for mas in SCALES:
        m2, _ = _time(lambda: line_profile("J", 1.10, mas, q))
        out.append(f"* J 1.10 µm, {mas} mas: median {m2 * 1e3:.1f} ms")
    cases = [(g, lam, mas) for g in ("J", "H", "K", "HK") for lam in GRATINGS[g].band_um for mas in SCALES]

    def run_all():
        return [line_profile(g, lam, mas, q).detected for g, lam, mas in cases]

    run_all()
    tot, tbest = _time(run_all, repeat=3)
    out += [f"* All {len(cases)} (4 gratings x 3 wavelengths x 3 pixel scales): median {tot:.2f} s, best {tbest:.2f} s "
            "(target <= 5 s).", ""]

    # ---- convergence, every case
    out += ["## Default vs converged reference (L1 of unit-area detected profiles, product quilt 0.82 µm)", "",
            "| grating | λ (µm) | 25 mas | 100 mas | 250 mas |", "|---|---|---|---|---|"]
    worst = 0.0
    for g in ("J", "H", "K", "HK"):
        for lam in GRATINGS[g].band_um:
            row = []
            for mas in SCALES:
                d = l1_distance(line_profile(g, lam, mas, q, settings=REF).detected, line_profile(g, lam, mas, q).detected)
                worst = max(worst, d)
                row.append(f"{100 * d:.2f} %")
            out.append(f"| {g} | {lam:.2f} | " + " | ".join(row) + " |")
    out += ["", f"Worst case: {100 * worst:.2f} % (target <= 0.5 %).", ""]

    # ---- sensitivity, one parameter at a time
    trials = {"default": LsfSettings(), "detector_step 0.5 µm, n_fft 1024": LsfSettings(detector_step_um=0.5, n_fft=1024),
              "detector_step 2 µm, n_fft 256": LsfSettings(detector_step_um=2.0, n_fft=256),
              "n_fft 1024 (period 1024 µm)": LsfSettings(n_fft=1024),
              "source_step 2.5 mm": LsfSettings(source_step_mm=2.5), "source_step 0.6 mm": LsfSettings(source_step_mm=0.6),
              "min_source_rows 3": LsfSettings(min_source_rows=3)}
    out += ["## Sensitivity (L1 % from reference / time), product quilt", "",
            "Times are of a second call: the first with a new sampling also computes its slit modes "
            "(`optics/slit_modes.py`), once.", "",
            "| setting | J 1.10 25 | J 1.10 100 | J 1.10 250 | K 2.45 25 | K 2.45 100 | K 2.45 250 |",
            "|---|---|---|---|---|---|---|"]
    refs = {(g, lam, mas): line_profile(g, lam, mas, q, settings=REF).detected
            for g, lam in (("J", 1.10), ("K", 2.45)) for mas in SCALES}
    for name, s in trials.items():
        cells = []
        for (g, lam, mas), ref in refs.items():
            line_profile(g, lam, mas, q, settings=s)  # the illumination's slit modes, computed once per setting
            t = time.perf_counter()
            p = line_profile(g, lam, mas, q, settings=s).detected
            cells.append(f"{100 * l1_distance(ref, p):.2f} / {1e3 * (time.perf_counter() - t):.0f} ms")
        out.append(f"| {name} | " + " | ".join(cells) + " |")
    out.append("")

    # ---- paper behaviour numbers
    out += ["## Paper-behaviour numbers (analytic quilt P/V 0.82 µm)", ""]
    for g, lam in (("J", 1.25), ("K", 2.2)):
        beta = math.radians(GRATINGS[g].beta_deg(lam))
        theory = SPIFFI.camera_focal_mm * lam / (21.0 * math.cos(beta))
        line = basic_lsf(point_psf(g, lam, qs, collimator_zernike_um=None, detector_step_um=0.25, n_fft=2048, window_um=80), 0.0)
        pos = np.array(find_profile_peaks(line.offset_um, line.intensity, prominence=0.01)["offset_um"])
        meas = [pos[np.argmin(np.abs(pos - s * theory))] for s in (1, -1)]
        out.append(f"* Satellites {g} {lam} µm (sum quilt, PSF collapsed): theory ±{theory:.2f} µm, measured "
                   f"{meas[0]:+.2f} / {meas[1]:+.2f} µm")
    out += ["", "| form | grating λ | mas | WFE | FWHM µm | R_FWHM | peaks (µm, rel. height) | spacing µm | outside slit | shoulder asym |",
            "|---|---|---|---|---|---|---|---|---|---|"]
    for form, sag in (("perfect", None), ("sum", qs), ("product", q)):
        for g, lam in (("J", 1.25), ("H", 1.65), ("K", 2.2)):
            for mas in SCALES:
                for wfe in (True, False):
                    kw = {} if wfe else {"collimator_zernike_um": None}
                    m = profile_metrics(line_profile(g, lam, mas, sag, **kw).detected)
                    pk = m["peaks"]
                    peaks = ", ".join(f"{o:+.1f} ({h:.2f})" for o, h in zip(pk["offset_um"][:4], pk["height"][:4]))
                    out.append(f"| {form} | {g} {lam} | {mas} | {'yes' if wfe else 'no'} | {m['fwhm_um']:.1f} | "
                               f"{m['resolving_power']:.0f} | {peaks} | {pk['peak_spacing_um']:.1f} | "
                               f"{m['outside_slit_fraction']:.3f} | {m['shoulder_asymmetry']:+.3f} |")
    out += ["", "R_2px (λ / (2 px / dispersion)) at band centre: " + ", ".join(
        f"{g} {profile_metrics(line_profile(g, GRATINGS[g].centre_um, 250, None).detected)['resolving_power_2px']:.0f}"
        for g in ("J", "H", "K", "HK")), ""]
    out += ["Pupil-shift sensitivity: mean L1 between the centred profile and shifts -11..+11 mm (9 steps, x):", ""]
    shifts = np.linspace(-11, 11, 9)
    for form, sag in (("sum", qs), ("product", q)):
        for g, lam in (("J", 1.25), ("K", 2.2)):
            ch = {}
            for mas in SCALES:
                ref = line_profile(g, lam, mas, sag).detected
                ch[mas] = np.mean([l1_distance(ref, line_profile(g, lam, mas, sag, pupil_shift_mm=(s, 0)).detected)
                                   for s in shifts])
            out.append(f"* {form} {g} {lam} µm: 25 mas {100 * ch[25]:.2f} %, 100 mas {100 * ch[100]:.2f} %, "
                       f"250 mas {100 * ch[250]:.2f} %; ratio 25/250 = {ch[25] / ch[250]:.1f}")
    Path(__file__).with_name("results_lsf.md").write_text("\n".join(out) + "\n")
    print("\n".join(out))


if __name__ == "__main__":
    main()
