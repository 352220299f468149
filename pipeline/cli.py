"""The ``cryograting`` command line: a thin layer, one API call per subcommand.

``main(argv=None)`` is what the console script runs and what the tests call.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

__all__ = ["main"]


def _values(text: str) -> list:
    """'100,150,200' or '100:200:50' or '0.5:1:3n' → floats; anything else stays a string."""
    from pipeline.sweeps.sweep import parse_range

    try:
        return parse_range(text)
    except ValueError:
        return [t.strip() for t in text.split(",") if t.strip()]


def _check_mesh_options(a) -> None:
    """Element sizes given on the command line, checked before any case is queued."""
    import math

    for opt, v in (("--mesh-size-mm", a.mesh_size_mm), ("--mesh-bulk-mm", a.mesh_bulk_mm)):
        if v is not None and not (math.isfinite(v) and v > 0):
            raise ValueError(f"{opt} {v} must be a finite number > 0 (mm)")
    if a.mesh_size_mm is not None and a.mesh_bulk_mm is not None and a.mesh_bulk_mm < a.mesh_size_mm:
        raise ValueError(f"--mesh-bulk-mm {a.mesh_bulk_mm} must be >= --mesh-size-mm {a.mesh_size_mm}")


def _cmd_tables(a) -> int:
    from pipeline.sweeps.fea_cases import format_table, run_tables

    _check_mesh_options(a)
    rows = run_tables(a.out, progress=not a.quiet, mesh_size_mm=a.mesh_size_mm, mesh_bulk_mm=a.mesh_bulk_mm)
    print(format_table(rows))
    print(f"\nwritten: {Path(a.out) / 'tables.csv'}, {Path(a.out) / 'sweep.nc'}, {Path(a.out) / 'figure_summary.csv'}")
    return 0


def _cmd_paper(a) -> int:
    from pipeline.paper import format_scorecard, scorecard

    print(format_scorecard(scorecard(a.out, progress=not a.quiet)))
    print(f"\nwritten: {Path(a.out) / 'scorecard.json'}, {Path(a.out) / 'scorecard.md'}")
    return 0


def _cmd_sweep(a) -> int:
    from pipeline.sweeps.fea_cases import run_fea_sweep

    axes: dict = {}
    for flag, name in (("t0_um", "t0_um"), ("polish", "polish"), ("coverage", "coverage"),
                       ("cold_K", "cold_K")):
        v = getattr(a, flag)
        if v is not None:
            axes[name] = v
    for item in a.param or []:
        if "=" not in item:
            raise ValueError(f"--param {item!r}: expected NAME=VALUES, e.g. hole_diameter_mm=14,15,16")
        name, text = item.split("=", 1)
        axes[name.strip()] = _values(text)
    _check_sweep_size(axes, a.surrogate, a.validate)
    from pipeline.bounds import max_workers

    if not 1 <= a.workers <= max_workers():
        raise ValueError(f"--workers {a.workers} is outside the valid range 1..{max_workers()} (twice this "
                         "machine's cores: each worker holds a whole FEA model)")
    if a.surrogate:
        from pipeline.sweeps.surrogate import run_surrogate_sweep

        if a.scheduler is not None or a.workers != 1:
            raise ValueError("--surrogate runs in this process (milliseconds per case); "
                             "drop --scheduler/--workers")
        res, rows, info = run_surrogate_sweep(axes, a.out, validate=a.validate, tol=a.tol,
                                              progress=not a.quiet, with_maps=not a.no_maps)
    else:
        res = run_fea_sweep(axes, a.out, scheduler=a.scheduler, workers=a.workers,
                            progress=not a.quiet, with_maps=not a.no_maps)
    cols = ["coverage", "t0_um", "polish"] + [k for k in axes if k not in ("coverage", "t0_um", "polish")]
    print(" ".join(f"{c:>12}" for c in cols + ["pv_center_um", "rms_center_um", "pv_full_um"]))
    for case, out in res:
        p = case.as_dict()
        print(" ".join(f"{p[c]!s:>12}" for c in cols) + " " +
              " ".join(f"{out[k]:12.4f}" for k in ("pv_center_um", "rms_center_um", "pv_full_um")))
    print(f"\n{res.n_computed} computed, {res.n_reused} reused; written: "
          f"{Path(a.out) / 'sweep.csv'}, {Path(a.out) / 'sweep.nc'}")
    if a.surrogate:
        if info:
            print(f"surrogate: {info['full_solves']} full solves, basis {info['basis_size']}, worst "
                  f"residual estimate {info['worst_residual_estimate']:.1e} (tol {info['tol']:.0e}), "
                  f"built in {info['build_s']:.0f} s")
        if rows:
            err = max(abs(r["rel_error"]) for r in rows)
            print(f"validation against {len(rows)} full solves at random points: max |P/V error| "
                  f"{100 * err:.3f} % ({Path(a.out) / 'surrogate_validation.csv'})")
    return 0


def _check_sweep_size(axes: dict, surrogate: bool, validate: int) -> None:
    """Refuse a sweep past its cap, and say up front when it will take more than an hour."""
    from pipeline.bounds import (GEOMETRY_KEYS, MAX_FEA_CASES, MAX_SURROGATE_CASES, SECONDS, fea_case_seconds,
                                 product_count, warn_if_long)

    if surrogate and not 0 <= validate <= MAX_FEA_CASES:  # each is a full FEA solve
        raise ValueError(f"--validate {validate} is outside the valid range 0..{MAX_FEA_CASES}")
    n = product_count(len(v) if isinstance(v, list) else 1 for v in axes.values())
    cap = MAX_SURROGATE_CASES if surrogate else MAX_FEA_CASES
    if n > cap:
        raise ValueError(f"{n} sweep cases (the product of the value lists given) is outside the valid range "
                         f"1..{cap}; give fewer values" + ("" if surrogate else " or use --surrogate"))
    mesh = axes.get("mesh_size_mm")
    per = fea_case_seconds(min(mesh) if isinstance(mesh, list) and mesh and all(
        isinstance(m, float) for m in mesh) else None)
    if surrogate:
        warn_if_long(n * SECONDS["surrogate_case"] + (max(validate, 0) + 20) * per, "sweep",
                     f"{n} surrogate cases x ~{SECONDS['surrogate_case']:g} s + ~20 training and {validate} "
                     f"validation solves x ~{per:.1f} s")
    else:
        # the solver already uses both cores: more workers do not divide the time
        n_geo = product_count(len(v) for k, v in axes.items() if k in GEOMETRY_KEYS and isinstance(v, list))
        warn_if_long(n * per + n_geo * SECONDS["new_blank"], "sweep",
                     f"{n} FEA cases x ~{per:.1f} s + {n_geo} mesh(es) x ~{SECONDS['new_blank']:.0f} s")


def _cmd_calibrate(a) -> int:
    from pipeline.calibration_run import format_calibration, run_calibration

    cal = run_calibration(a.out, mesh_size_mm=a.mesh_size_mm, mesh_bulk_mm=a.mesh_bulk_mm, progress=not a.quiet)
    print(f"\n{format_calibration(cal)}")
    if a.out:
        print(f"written: {Path(a.out) / 'calibration.csv'}")
    return 0


def _study_config(config: str | None, preset: str | None, overrides=None):
    """The config of ``run``/``config --check``: a file, a shipped preset, or None (default),
    with ``--set KEY=VALUE`` overrides applied."""
    from pipeline.study.config import (apply_overrides, load_study_config, preset_path, read_study_data,
                                 study_config_from_dict)

    if config and preset:
        raise ValueError(f"give either a config file ({config}) or --preset {preset}, not both")
    path = preset_path(preset) if preset else config
    base = load_study_config(path) if path else None  # file errors first, named as such
    if not overrides:
        return base
    source = f"{path or 'default study'} with --set {' '.join(overrides)}"
    return study_config_from_dict(apply_overrides(read_study_data(path), overrides), source)


def _cmd_run(a) -> int:
    from pipeline.study.run import run_study

    _check_mesh_options(a)
    config = _study_config(a.config, a.preset, a.set)  # validated before anything is written
    run_study(a.out, config, progress=not a.quiet, mesh_size_mm=a.mesh_size_mm, mesh_bulk_mm=a.mesh_bulk_mm)
    return 0


def _cmd_config(a) -> int:
    from pipeline.study.config import example_config_text, list_presets, preset_path
    from pipeline.study.run import default_study

    if a.example:
        print(example_config_text(), end="")
    elif a.list:
        for name in list_presets():
            print(f"{name:28} {preset_path(name)}")
    elif a.show:
        print(preset_path(a.show).read_text(encoding="utf-8"), end="")
    else:
        from pipeline.bounds import format_duration
        from pipeline.study.run import estimate_seconds

        config = _study_config(a.check, a.preset, a.set) or default_study()
        print(f"valid: {config.summary()}")
        seconds, detail = estimate_seconds(config)
        print(f"estimated run time: ~{format_duration(seconds)} ({detail}; cached cases and meshes take none)")
        for c in config.cases():
            print(f"  FEA  {c.label}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="cryograting", description=(
        "Cryogenic deformation of lightweighted, NiP-plated grating blanks and its effect on "
        "spectral line profiles (SINFONI/SPIFFI)."))
    p.add_argument("--debug", action="store_true", help="on an error, show the Python traceback instead of "
                   "one line (also accepted after the command)")
    sub = p.add_subparsers(dest="command", required=True)

    q = sub.add_parser("run", help="a study (default: the paper's): FEA cases, sag maps, line profiles, "
                       "plots and report")
    q.add_argument("config", nargs="?", default=None, metavar="CONFIG.toml",
                   help="study config (see 'cryograting config --example'); default: the paper's study")
    q.add_argument("--preset", default=None, metavar="NAME",
                   help="a shipped config instead of a file (list: 'cryograting config --list')")
    q.add_argument("--out", default="results", help="output directory (default: results)")
    q.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help=(
        "override or sweep any config key, repeatable: fea.t0_um=100:200:50, fea.polish=[0.5,1], "
        "fea.cases[0].coverage=holes, profiles.pupil_shift_x_mm=-10:10:5n, profiles.grating=J,K, "
        "profiles[1].pixel_scale_mas=25"))
    q.add_argument("--mesh-size-mm", type=float, default=None, help="element size near walls (mm)")
    q.add_argument("--mesh-bulk-mm", type=float, default=None, help="element size in the bulk (mm)")
    q.add_argument("--quiet", action="store_true", help="no progress bars")
    q.set_defaults(func=_cmd_run)

    q = sub.add_parser("config", help="study configs: print the commented example, list, show or check")
    g = q.add_mutually_exclusive_group(required=True)
    g.add_argument("--example", action="store_true", help="print a commented example config")
    g.add_argument("--list", action="store_true", help="list the shipped configs (presets)")
    g.add_argument("--show", metavar="NAME", help="print a shipped config")
    g.add_argument("--check", metavar="CONFIG.toml", help="validate a config file and list its FEA cases")
    g.add_argument("--preset", metavar="NAME", help="validate a shipped config and list its FEA cases")
    q.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="with --check/--preset: overrides as in 'cryograting run --set'")
    q.set_defaults(func=_cmd_config)

    q = sub.add_parser("tables", help="the paper's 15 P/V cases, model vs paper")
    q.add_argument("--out", default="results/tables", help="output directory")
    q.add_argument("--mesh-size-mm", type=float, default=None, help="element size near walls (mm)")
    q.add_argument("--mesh-bulk-mm", type=float, default=None, help="element size in the bulk (mm)")
    q.add_argument("--quiet", action="store_true")
    q.set_defaults(func=_cmd_tables)

    q = sub.add_parser("paper", help="the paper's claims, one by one, on the model: scorecard.json/.md + figures")
    q.add_argument("--out", default="results/paper", help="output directory (FEA cases cached in OUT/fea)")
    q.add_argument("--quiet", action="store_true", help="no progress bars")
    q.set_defaults(func=_cmd_paper)

    q = sub.add_parser("sweep", help="FEA over every combination of the given values")
    q.add_argument("--t0-um", dest="t0_um", type=float, nargs="+", help="NiP thickness(es), µm")
    q.add_argument("--polish", type=float, nargs="+", help="polish fraction(s), (0, 1]")
    q.add_argument("--coverage", nargs="+", help="all | holes | surfaces | faces | none")
    q.add_argument("--cold-K", dest="cold_K", type=float, nargs="+", help="cold temperature(s), K")
    q.add_argument("--param", action="append", metavar="NAME=VALUES",
                   help="any other model parameter, e.g. hole_diameter_mm=14,15,16 or pitch_x_mm=18:24:3")
    q.add_argument("--out", required=True, help="output directory (reused on re-run)")
    q.add_argument("--workers", type=int, default=1, help="local processes (default 1: the solver "
                   "already uses both cores)")
    q.add_argument("--scheduler", default=None, help="Dask scheduler address tcp://host:port")
    q.add_argument("--no-maps", action="store_true", help="do not store sag maps")
    q.add_argument("--surrogate", action="store_true", help="evaluate a reduced-basis surrogate trained "
                   "on the sweep's t0/polish/coverage box (ms per case; for hundreds of cases)")
    q.add_argument("--validate", type=int, default=3, help="with --surrogate: random points solved in "
                   "full to measure its error (default 3)")
    q.add_argument("--tol", type=float, default=2e-3, help="with --surrogate: greedy residual tolerance")
    q.add_argument("--quiet", action="store_true")
    q.set_defaults(func=_cmd_sweep)

    q = sub.add_parser("calibrate", help="refit the film stress scale to the paper's tables")
    q.add_argument("--out", default=None, help="directory for the fit's CSV (optional)")
    q.add_argument("--mesh-size-mm", type=float, default=None, help="element size near walls and faces (mm)")
    q.add_argument("--mesh-bulk-mm", type=float, default=None, help="element size in the bulk (mm)")
    q.add_argument("--quiet", action="store_true")
    q.set_defaults(func=_cmd_calibrate)

    from pipeline.diagnosis.cli import register as register_diagnosis
    from pipeline.fe_cli import register as register_fe
    from pipeline.map_cli import register as register_convert
    from pipeline.optics_cli import register as register_optics

    register_optics(sub)
    register_diagnosis(sub)
    register_fe(sub)
    register_convert(sub)
    return p


def main(argv: list[str] | None = None) -> int:
    """Run one subcommand; a user error is one line on stderr and exit code 2
    (:mod:`pipeline.errors`), ``--debug`` anywhere shows the traceback instead."""
    from pipeline.errors import command_options, pop_debug, run_command

    argv, debug = pop_debug(argv)
    parser = build_parser()
    a = parser.parse_args(argv)
    return run_command(a.func, a, a.command, debug, command_options(parser, a.command, a))


if __name__ == "__main__":
    sys.exit(main())
