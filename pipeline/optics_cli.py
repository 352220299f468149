"""``cryograting lsf`` and ``cryograting psf``: thin argparse layer over
:func:`optics.lineprofile.line_profile` and :func:`optics.lineprofile.point_psf`.

Wire into the main CLI with ``register(subparsers)``; ``main(argv)`` runs these two
subcommands stand-alone (used by the tests).
"""

from __future__ import annotations

import argparse
import json

import numpy as np

__all__ = ["register", "main", "load_sag_map"]


from pipeline.io.registry import load_sag_map  # noqa: E402  (.npz/.nc/.int/.dat/.csv)
from pipeline.io.common import atomic_path, atomic_write, ensure_writable_dir  # noqa: E402
from pipeline.io.measured import write_line_profile_csv  # noqa: E402


#: Largest analytic quilt P/V (µm) the line-profile and PSF pupils sample without aliasing:
#: along the dispersion the quilt's wavefront changes by 0.22 / 0.40 / 0.76 waves between
#: neighbouring pupil samples at 1 / 2 / 4 µm P/V (J, 1.25 µm, 25 mas; measured on the
#: pupil field), and a phase is aliased past 0.5. The paper's quilts are 0.1-1 µm.
MAX_QUILT_PV_UM = 2.0


def _add_common(p: argparse.ArgumentParser) -> None:
    p.add_argument("--grating", required=True, help="J, H, K or HK")
    p.add_argument("--wavelength-um", type=float, required=True, help="line wavelength (µm)")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--sag", metavar="FILE", help="sag map (.npz or .nc, µm, mm, grating frame)")
    src.add_argument("--quilt-pv-um", type=float, help="analytic quilt P/V (µm); 0 = perfect grating")
    p.add_argument("--quilt-form", choices=["product", "sum"], default="sum",
                   help="analytic quilt form (default: sum, see docs/physics.md)")
    p.add_argument("--pupil-shift-mm", type=float, nargs=2, default=(0.0, 0.0), metavar=("X", "Y"),
                   help="footprint shift on the grating (mm)")
    p.add_argument("--no-collimator-wfe", action="store_true", help="omit the default collimator wavefront error")
    p.add_argument("--order", type=int, default=None, help="diffraction order (default: blaze order)")
    p.add_argument("--out", required=True, help="output directory")


def _sag_from_args(a):
    from optics.sagmap import quilt_sag_map

    if a.sag:
        return load_sag_map(a.sag)
    if not (np.isfinite(a.quilt_pv_um) and 0 <= a.quilt_pv_um <= MAX_QUILT_PV_UM):
        raise ValueError(f"--quilt-pv-um {a.quilt_pv_um} must be a finite number >= 0 and <= {MAX_QUILT_PV_UM:g} (µm; "
                         "a steeper quilt is aliased by the pupil sampling)")
    return None if a.quilt_pv_um == 0 else quilt_sag_map(a.quilt_pv_um, form=a.quilt_form)


def _wfe(a):
    from optics.pupil import DEFAULT_COLLIMATOR_ZERNIKE_UM

    return None if a.no_collimator_wfe else DEFAULT_COLLIMATOR_ZERNIKE_UM


def _run_lsf(a) -> int:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from optics.lineprofile import line_profile
    from optics.metrics import profile_metrics

    out = ensure_writable_dir(a.out, "--out")
    sag = _sag_from_args(a)
    kw = dict(order=a.order, pupil_shift_mm=tuple(a.pupil_shift_mm), torsion_shift_x_mm=a.torsion_shift_x_mm,
              slit_position=a.slit_position, collimator_zernike_um=_wfe(a))
    res = line_profile(a.grating, a.wavelength_um, a.pixel_scale_mas, sag, **kw)
    perfect = line_profile(a.grating, a.wavelength_um, a.pixel_scale_mas, None, **kw)
    d = res.detected
    write_line_profile_csv(out / "lsf.csv", d.offset_um, d.intensity)
    report = {"info": res.info, "metrics": profile_metrics(d), "perfect_metrics": profile_metrics(perfect.detected),
              "partially_coherent_metrics": profile_metrics(res.partially_coherent)}
    with atomic_write(out / "metrics.json") as fh:
        fh.write(json.dumps(report, indent=2, default=float))
    fig, ax = plt.subplots(figsize=(7, 4))
    ax.plot(perfect.detected.offset_um, perfect.detected.intensity, color="0.5", label="perfect grating")
    ax.plot(d.offset_um, d.intensity, color="C0", label=res.info["sag"] or "deformed")
    half = 0.5 * res.info["slit_image_width_um"]
    ax.axvspan(-half, half, fill=False, ls=":", color="k", label="geometric slit image")
    ax.set(xlim=(-100, 100), xlabel="offset along dispersion (µm, +x_g)", ylabel="intensity (unit area)",
           title=f"{res.info['grating']} {a.wavelength_um:g} µm order {res.info['order']}, "
                 f"{res.info['pixel_scale_mas']} mas, shift {res.info['pupil_shift_mm']} mm")
    ax.legend(fontsize=8)
    fig.tight_layout()
    with atomic_path(out / "lsf.png") as tmp:
        fig.savefig(tmp, dpi=120)
    plt.close(fig)
    print(f"wrote {out / 'lsf.csv'}, metrics.json, lsf.png  (FWHM {report['metrics']['fwhm_um']:.1f} µm, "
          f"R {report['metrics'].get('resolving_power', float('nan')):.0f})")
    return 0


def _run_psf(a) -> int:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from optics.lineprofile import point_psf

    out = ensure_writable_dir(a.out, "--out")
    p = point_psf(a.grating, a.wavelength_um, _sag_from_args(a), order=a.order,
                  pupil_shift_mm=tuple(a.pupil_shift_mm), collimator_zernike_um=_wfe(a),
                  detector_step_um=a.detector_step_um, window_um=a.window_um)
    with atomic_write(out / "psf.npz", "wb") as fh:
        np.savez_compressed(fh, offset_x_um=p.offset_x_um, offset_y_um=p.offset_y_um,
                            intensity=p.intensity, meta=json.dumps(p.meta, default=float))
    fig, ax = plt.subplots(figsize=(6, 5))
    ext = [p.offset_x_um[0], p.offset_x_um[-1], p.offset_y_um[0], p.offset_y_um[-1]]
    im = ax.imshow(np.log10(p.intensity / p.intensity.max() + 1e-6), origin="lower", extent=ext, vmin=-5,
                   cmap="magma")
    fig.colorbar(im, label="log10 relative intensity")
    ax.set(xlabel="x: dispersion (µm)", ylabel="y: along slit (µm)",
           title=f"PSF {p.meta['grating']} {a.wavelength_um:g} µm order {p.meta['order']}")
    fig.tight_layout()
    with atomic_path(out / "psf.png") as tmp:
        fig.savefig(tmp, dpi=120)
    plt.close(fig)
    print(f"wrote {out / 'psf.npz'}, psf.png")
    return 0


def register(subparsers) -> None:
    """Add the ``lsf`` and ``psf`` subcommands to an argparse ``subparsers`` object."""
    p = subparsers.add_parser("lsf", help="detected line profile of a fully illuminated slit (partially coherent)")
    _add_common(p)
    p.add_argument("--pixel-scale-mas", required=True, help="25, 100 or 250")
    p.add_argument("--torsion-shift-x-mm", type=float, default=0.0,
                   help="slicer torsion: extra x shift at the slit end (mm)")
    p.add_argument("--slit-position", type=float, default=0.0, help="position along the slitlet, -1..1")
    p.set_defaults(func=_run_lsf)
    q = subparsers.add_parser("psf", help="point-source PSF on the detector")
    _add_common(q)
    q.add_argument("--detector-step-um", type=float, default=0.5, help="PSF sampling (µm)")
    q.add_argument("--window-um", type=float, default=150.0, help="half width of the PSF image (µm)")
    q.set_defaults(func=_run_psf)


def main(argv=None) -> int:
    """Stand-alone entry point for the two subcommands."""
    from pipeline.errors import command_options, pop_debug, run_command

    argv, debug = pop_debug(argv)
    parser = argparse.ArgumentParser(prog="cryograting")
    register(parser.add_subparsers(dest="command", required=True))
    a = parser.parse_args(argv)
    code = run_command(a.func, a, a.command, debug, command_options(parser, a.command, a))
    if code:
        raise SystemExit(code)
    return 0
