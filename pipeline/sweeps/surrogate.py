"""Large FEA sweeps through the reduced-basis surrogate (:mod:`fea.surrogate`).

Units: µm for film thickness and sag, K for temperatures.

The surrogate covers the coating parameters (``coverage``, ``t0_um``, ``polish``) and
the load (``cold_K``, ``warm_K``, ``stress_scale``) on one mesh, blank and pair of
materials; any other parameter must have a single value in the sweep. It is trained
on the box spanned by the sweep's values (greedy full solves), then each case costs
milliseconds. Its accuracy is measured, not assumed: ``validate`` random points of the
box are solved in full and the P/V errors written to ``surrogate_validation.csv``.

Results go through the same sweep engine as full solves (cache, resume, atomic
files, progress), under a cache namespace that names the surrogate's training box
and tolerance, so they never mix with full-solve results.
"""

from __future__ import annotations

import csv
import hashlib
import json
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

from fea.case import PARAMETERS, FEACase, model_namespace
from fea.surrogate import FEASurrogate, SurrogateDomain, build_surrogate
from pipeline.bounds import MAX_FEA_CASES, MAX_SURROGATE_CASES, check_count, product_count
from pipeline.io.common import atomic_write
from pipeline.sweeps.fea_cases import (
    SAG_GRID_X_MM,
    SAG_GRID_Y_MM,
    SAG_SPACING_MM,
    FEACaseRunner,
    fea_grid,
    quilt_direction_um,
)
from pipeline.sweeps.sweep import run_sweep

__all__ = ["SURROGATE_PARAMETERS", "SurrogateCaseRunner", "run_surrogate_sweep"]

#: parameters the surrogate may vary within one sweep
SURROGATE_PARAMETERS = ("coverage", "t0_um", "polish", "cold_K", "warm_K", "stress_scale")


class SurrogateCaseRunner:
    """Case function evaluating the surrogate; trains it on first use.

    Parameters
    ----------
    params0 : dict
        One case of the sweep (fixes blank, mesh and materials).
    domain : SurrogateDomain
        Training box.
    tol : float
        Greedy stopping tolerance on the sketched relative residual.
    with_maps : bool
        Also return the sag map on the fixed output grid.
    """

    def __init__(self, params0: dict, domain: SurrogateDomain, tol: float = 2e-3,
                 with_maps: bool = True, seed: int = 0, log=None):
        self.params0, self.domain, self.tol, self.with_maps, self.seed = params0, domain, tol, with_maps, seed
        self.log = log
        self.surrogate: FEASurrogate | None = None
        self._maps = None
        self._quilt_rows = None

    def build(self) -> FEASurrogate:
        if self.surrogate is None:
            case = FEACase.from_params(self.params0)
            o = case.to_objects()
            model = FEACaseRunner(with_maps=False).model(o.blank, o.mesh, case.substrate)
            self.blank = o.blank
            self.surrogate = build_surrogate(model, self.domain, case.film, stress_scale=o.stress_scale, tol=self.tol,
                                             seed=self.seed, progress=self.log)
            model.release_preconditioner()
            if self.with_maps:
                s = self.surrogate
                self._maps = np.array([
                    replace(s.sag_template, sag_um=col).sag_map(SAG_SPACING_MM)
                    .resampled(SAG_GRID_X_MM, SAG_GRID_Y_MM).sag_um for col in s.sag_basis_um.T])
        return self.surrogate

    def plan(self, cases) -> None:
        """Announce the cases about to run (the ``planner`` of :func:`pipeline.sweeps.sweep.run_sweep`:
        the uncached ones): the first call that needs the surrogate then evaluates them all
        in one batch (a fully cached re-run builds nothing)."""
        self._planned = list(cases)

    def precompute(self, cases) -> None:
        """Evaluate the statistics of many cases in one batch (:meth:`FEASurrogate.statistics_many`);
        the per-case calls then only look them up (invalid cases are left to them)."""
        s = self.build()
        ok = []
        for case in cases:
            params = case.as_dict() if hasattr(case, "as_dict") else dict(case)
            case = FEACase.from_params(params)
            o = case.to_objects()
            try:
                s.check(o.coating, o.load)
            except ValueError:
                continue
            ok.append((case.cache_key(), o.coating, o.load, o.stress_scale))
        stats = s.statistics_many([o[1] for o in ok], [o[2] for o in ok], [o[3] for o in ok])
        self._batch = {o[0]: st for o, st in zip(ok, stats)}

    def __call__(self, params: dict) -> dict:
        s = self.build()
        if getattr(self, "_planned", None):
            planned, self._planned = self._planned, None
            self.precompute(planned)
        case = FEACase.from_params(params)
        o = case.to_objects()
        coating, load, scale = o.coating, o.load, o.stress_scale
        s.check(coating, load)
        batch = getattr(self, "_batch", {}).get(case.cache_key())
        out = dict(batch) if batch is not None else s.statistics(coating, load, stress_scale=scale)
        a, _ = s.coefficients(coating, load, stress_scale=scale)
        if self._quilt_rows is None:  # the quilt direction is linear in the sag: one row per basis vector
            self._quilt_rows = np.array([quilt_direction_um(replace(s.sag_template, sag_um=col), self.blank)
                                         for col in s.sag_basis_um.T])
        out.update(quilt_direction_um=float(self._quilt_rows @ a), surrogate_basis=s.size,
                   stress_scale_used=float(scale))
        if self.with_maps:
            out["sag_um"] = (("y_mm", "x_mm"), np.tensordot(a, self._maps, axes=1).astype(np.float32))
            out["coord:y_mm"] = SAG_GRID_Y_MM
            out["coord:x_mm"] = SAG_GRID_X_MM
        return out


def _domain_for(cases) -> tuple[SurrogateDomain, dict]:
    params = [c.as_dict() for c in cases]
    fixed = {}
    for name in sorted({k for p in params for k in p}):
        vals = {repr(p.get(name)) for p in params}
        if name not in SURROGATE_PARAMETERS and len(vals) > 1:
            raise ValueError(f"{name} takes {len(vals)} values in this sweep, but the surrogate is built for "
                             f"one mesh, blank and material pair; only {list(SURROGATE_PARAMETERS)} may vary "
                             "(run a full sweep instead, or one surrogate sweep per value)")
        fixed[name] = params[0].get(name)
    coatings = [FEACase.from_params(p).to_objects().coating for p in params]
    bad = [c for c in coatings if c.polish_front != c.polish_back]
    if bad:
        raise ValueError(f"polish_back={bad[0].polish_back} differs from polish={bad[0].polish_front}: "
                         "the surrogate covers symmetric polish only; use a full sweep")
    covs = tuple(sorted({c.coverage for c in coatings}))
    if "none" in covs:
        raise ValueError("coverage='none' gives zero deformation; leave it out of a surrogate sweep")
    t0 = [c.t0_um for c in coatings]
    pol = [c.polish_front for c in coatings]
    return SurrogateDomain((min(t0), max(t0)), (min(pol), max(pol)), covs), fixed


def run_surrogate_sweep(axes: dict, out_dir, *, validate: int = 3, tol: float = 2e-3, seed: int = 0,
                        progress: bool = True, with_maps: bool = True):
    """Sweep the surrogate over every combination of ``axes`` and write the results.

    Parameters
    ----------
    axes : dict
        name → list of values; only :data:`SURROGATE_PARAMETERS` may take several values.
    out_dir : path
        Writes ``sweep.csv``, ``sweep.nc`` (as a full sweep, plus ``residual_estimate``)
        and ``surrogate_validation.csv``; cases are cached under ``out_dir/cases``.
    validate : int
        Random points of the training box solved in full to measure the error (0: none).
    tol : float
        Greedy tolerance on the sketched relative residual (P/V error ≈ tol / 2, measured).

    Returns
    -------
    (SweepResult, list of dict, dict)
        The results, the validation rows and the build information.
    """
    if not (isinstance(validate, int) and validate >= 0):
        raise ValueError(f"validate={validate!r} must be an int >= 0")
    if not (0 < tol < 1):
        raise ValueError(f"tol={tol!r} must be in (0, 1)")
    if validate > MAX_FEA_CASES:
        raise ValueError(f"validate={validate} is outside the valid range 0..{MAX_FEA_CASES} (full FEA solves)")
    core = {k: [PARAMETERS[k].default] for k in ("coverage", "t0_um", "polish")}
    axes = {**core, **axes}
    check_count(product_count(len(v) if isinstance(v, (list, tuple)) else 1 for v in axes.values()),
                "cases", MAX_SURROGATE_CASES, "the product of the axes' value counts; give fewer values")
    cases = fea_grid(**axes)
    domain, _ = _domain_for(cases)
    ident = json.dumps({"domain": [domain.t0_um, domain.polish, domain.coverages], "tol": tol,
                        "seed": seed}, sort_keys=True)
    namespace = f"surrogate-{model_namespace()}-{hashlib.sha256(ident.encode()).hexdigest()[:12]}"

    def log(d):
        if progress:
            print(f"surrogate: full solve {d['solves']} ({d['case']}), basis {d['basis']}, "
                  f"worst residual estimate {d['worst_residual']:.1e}", file=sys.stderr, flush=True)

    runner = SurrogateCaseRunner(cases[0].as_dict(), domain, tol, with_maps, seed, log)
    res = run_sweep(runner, cases, out_dir, namespace=namespace, workers=1, progress=progress,
                    description="surrogate sweep", planner=runner.plan)
    out = Path(out_dir)
    res.write_csv(out / "sweep.csv")
    res.write_netcdf(out / "sweep.nc")
    rows: list[dict] = []
    info: dict = {}
    if runner.surrogate is not None:
        info = dict(runner.surrogate.build_info)
        if validate:
            rows = runner.surrogate.validate(validate, seed=seed + 1)
            runner.surrogate.model.release_preconditioner()
            _write_validation(rows, out / "surrogate_validation.csv")
    return res, rows, info


def _write_validation(rows: list[dict], path: Path) -> None:
    keys = list(rows[0])
    with atomic_write(path) as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(keys)
        for r in rows:
            w.writerow([f"{r[k]:.6g}" if isinstance(r[k], float) else r[k] for k in keys])
