"""``cryograting diagnose``: thin argparse layer over :func:`pipeline.diagnosis.diagnose`
and :func:`pipeline.diagnosis.campaign.run_campaign` (``--validate``).

Wire into the main CLI with ``register(subparsers)``; ``main(argv)`` runs it stand-alone.
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import replace
from pathlib import Path

__all__ = ["HELP_DESCRIPTION", "register", "main"]


def _criteria(args, base=None):
    from .engine import Criteria

    base = Criteria() if base is None else base
    scale = base.weight_scale if args.weight_scale is None else args.weight_scale
    return replace(base, n_eff_from=args.n_eff_from, error_model=args.error_model, weight_scale=scale)


def _run(args) -> int:
    from pipeline.io.common import ensure_writable_dir

    if args.validate:
        from pipeline.bounds import MAX_CAMPAIGN_CASES, campaign_seconds, max_workers, warn_if_long

        if not 1 <= args.cases <= MAX_CAMPAIGN_CASES:
            raise ValueError(f"--cases {args.cases} is outside the valid range 1..{MAX_CAMPAIGN_CASES} "
                             "(campaign cases)")
        if not 1 <= args.workers <= max_workers():
            raise ValueError(f"--workers {args.workers} is outside the valid range 1..{max_workers()} (campaign "
                             "worker processes: twice this machine's cores)")
        from .campaign import PROFILE_SETS, PSF_IMAGE_SPEC, CampaignConfig, parse_types, run_campaign, write_campaign

        cfg = CampaignConfig(n_cases=args.cases, seed=args.seed, workers=args.workers,
                             profile_specs=PROFILE_SETS[args.profiles], profile_map_K=args.profile_map_K,
                             psf_image=PSF_IMAGE_SPEC if args.psf_image else None,
                             only_types=parse_types(args.types, args.truth), discrepancy=args.discrepancy,
                             truth=args.truth, truth_families=args.truth_families)
        cfg = replace(cfg, criteria=_criteria(args, cfg.criteria))
        ensure_writable_dir(args.out, "--out")  # before the campaign, not after it
        warn_if_long(campaign_seconds(args.cases, args.workers, args.profile_map_K is not None, args.psf_image),
                     "diagnose", f"{args.cases} campaign cases on {args.workers} worker(s)")
        res = run_campaign(cfg, cache_dir=args.cache_dir)
        path = write_campaign(res, args.out)
        print(json.dumps(res["summary"], indent=1))
        print(f"wrote {path}")
        return 0
    if args.manifest is None:
        print("cryograting diagnose: MANIFEST is required unless --validate is given", file=sys.stderr)
        return 2
    from .engine import diagnose
    from .manifest import load_manifest
    from .report import read_text, verdict_text, write_report

    effects = tuple(args.effects.split(",")) if args.effects else None
    manifest = load_manifest(args.manifest, allow_outside=args.allow_outside_paths)
    ensure_writable_dir(args.out, "--out")  # before the FEA and the fits, not after them
    d = diagnose(manifest, effects=effects, cache_dir=args.cache_dir, heldout=not args.no_heldout,
                 criteria=_criteria(args))
    j, h = write_report(d, args.out)
    for m in d.measurements:
        print(f"read {m['name']} ({m['kind']}): {read_text(m['read'])}"
              + (f"; gridding: {m['gridding']}" if m.get("gridding") else "") + f"; noise from {m['noise_from']}")
    best = d.best
    print(f"verdict: {d.verdict}" + (f"; best: {best.effect} {best.parameters} shrink {best.shrink_fraction:.2f}" if best else ""))
    print(verdict_text(d))
    print(f"wrote {j} and {h}")
    return 0


def _add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("manifest", nargs="?", help="measurement manifest (TOML; layout above)")
    p.add_argument("--out", required=True, help="output directory (diagnosis.json, report.html)")
    p.add_argument("--cache-dir", default=str(Path.home() / ".cache" / "cryograting" / "diagnosis"),
                   help="cache of nominal FEA maps (default: ~/.cache/cryograting/diagnosis)")
    p.add_argument("--effects", default=None, help="comma-separated library effects to try (default: all)")
    p.add_argument("--no-heldout", action="store_true", help="skip the held-out validation")
    p.add_argument("--allow-outside-paths", action="store_true",
                   help="let the manifest name files outside its own directory (absolute paths elsewhere, ../)")
    p.add_argument("--n-eff-from", default="nominal", choices=("nominal", "best_fit"),
                   help="residual whose correlation sets the effective samples the score counts: nominal "
                        "(conservative, default) or best_fit (the best finding's residual: an optimistic bound on "
                        "the evidence; fits and error bars unchanged)")
    p.add_argument("--error-model", default="n_eff", choices=("n_eff", "two_part", "by_kind"),
                   help="n_eff (default): effective-sample counts; two_part: white noise plus a smooth mismatch "
                        "measured from the post-fit residual (chi^2 score; pipeline/diagnosis/error_model.py); "
                        "by_kind: two_part when a line profile is among the measurements, n_eff otherwise")
    p.add_argument("--weight-scale", default=None, choices=("measurement", "kind"),
                   help="with n_eff: normalise each measurement's weight by its own nominal residual "
                        "(measurement) or share one normalisation among the measurements of a kind (kind: "
                        "within a kind, weights go as one over the noise); default: the criteria's")
    p.add_argument("--validate", action="store_true", help="run the injection-recovery campaign instead")
    p.add_argument("--cases", type=int, default=200, help="campaign cases (with --validate)")
    p.add_argument("--seed", type=int, default=1, help="campaign seed (with --validate)")
    p.add_argument("--workers", type=int, default=2, help="campaign worker processes (with --validate)")
    p.add_argument("--profiles", default="extended", choices=("extended", "minimal"),
                   help="campaign line-profile measurement set (with --validate): extended = J 1.25 um at "
                        "250/100/25 mas + 1.10/1.175/1.40 um at 25 mas; minimal = J 1.25 um at 250/25 mas + 1.175 um at 25 mas")
    p.add_argument("--profile-map-K", type=float, default=None, metavar="K",
                   help="campaign (with --validate): also a cold map of the same blank at this temperature beside "
                        "the line profiles, as in the paper's data (default: profiles only)")
    p.add_argument("--psf-image", action="store_true",
                   help="campaign (with --validate): also a focal-plane point-source image (J, 1.25 um) beside the "
                        "line profiles")
    p.add_argument("--types", default=None, metavar="KIND:EFFECT,...",
                   help="campaign (with --validate): run only these case types, e.g. line_profile:collimator_wfe "
                        "(cases keep their index and random draws)")
    p.add_argument("--truth", default="independent", choices=("independent", "model"),
                   help="campaign (with --validate): truth generator: independent = 2-D finite-slit Abbe optics, "
                        "quilt-shape mixtures, detector effects and out-of-library families written apart from the "
                        "forward model (default; benchmarks/truth_families.md); model = the diagnosis's own forward "
                        "code with a small discrepancy")
    p.add_argument("--truth-families", default="sum_mix,product_mix", metavar="FAMILY,...",
                   help="campaign (with --validate, --truth independent): the truth's grating families, comma-separated: "
                        "sum_mix, product_mix (default), pocket_jitter, sharp_ribs (benchmarks/truth_families.md)")
    p.add_argument("--discrepancy", default="unmodelled", choices=("unmodelled", "companions"),
                   help="campaign (with --validate, --truth model): the truth's model discrepancy: unmodelled = 0.01 um RMS "
                        "trefoil/tetrafoil/pentafoil (outside the library, default); companions = bow + plating "
                        "gradient (library companions, the first campaigns')")


HELP_DESCRIPTION = """\
Compare measured data (cold surface maps, line profiles, point-source images) with the
simulation, find where they disagree, and name the effect that explains the gap, or say
that none does. MANIFEST is a TOML file listing the simulation and the measurements:

  [simulation]                # the nominal FEA case (any FEA parameter; default 200 um / 75 %)
  cold_K = 80
  # sag_file = "nominal.npz"  # or a cold map of the simulation itself

  [[measurement]]
  kind = "surface"            # cold-minus-warm map: .csv x_mm,y_mm,sag_um (valid points
  file = "cryo_128K.csv"      #   only is fine), .nc, .npz, CODE V .int, Zemax/Zygo .dat, .asc, .datx
  temperature_K = 128
  aperture_diameter_mm = 137
  # noise_um = 0.005          # optional: else estimated from the map
  # blank = "J"               # the map is of the J grating's blank (default: a spare blank,
                              #   with a deformation scale of its own)
  # spacing_mm = 0.5 | extent_mm = [x0, x1, y0, y1]   # a CODE V .int without its grid
  # centre_mm = [68.5, 60]    # map coordinates of the blank's centre (corner-origin exports)
  # sag_sign = -1             # heights along -z (the diagnosis takes the sag along +z)

  [[measurement]]
  kind = "line_profile"       # .csv offset_um|offset_px|wavelength_nm,intensity or FITS
  file = "J_1p25_250mas.csv"  #   (counts, pedestal, negative noise, any grid are fine)
  grating = "J"
  order = -2
  wavelength_um = 1.25
  pixel_scale_mas = 250       # 25, 100 or 250
  # noise_rel = 0.003         # white noise / line peak; required for one sample per pixel
  # noise_counts = 12.0       #   or the same in the file's intensity units
  # correlated_noise_rel = 0.004  # a characterised correlated noise / line peak (or
  # correlation_length_um = 12    #   correlated_noise_counts), its correlation length at the detector

Paths are relative to the manifest. Each error names the measurement and the field; the
run prints what it read from each file. Details: README (Sim-to-real diagnosis) and
docs/diagnosis.md."""


def register(subparsers) -> argparse.ArgumentParser:
    """Add the ``diagnose`` subcommand to an argparse ``subparsers`` object."""
    p = subparsers.add_parser("diagnose", help="diagnose the sim-to-real gap of a measurement manifest",
                              description=HELP_DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter)
    _add_arguments(p)
    p.set_defaults(func=_run)
    return p


def main(argv=None) -> int:
    from pipeline.errors import command_options, pop_debug, run_command

    argv, debug = pop_debug(argv)
    ap = argparse.ArgumentParser(prog="cryograting")
    sub = ap.add_subparsers(dest="command", required=True)
    register(sub)
    args = ap.parse_args(argv)
    return run_command(args.func, args, args.command, debug, command_options(ap, args.command, args))


if __name__ == "__main__":
    raise SystemExit(main())
