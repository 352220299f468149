"""How close to the truth could any unbiased reading of the campaign's data come?

For each library line-profile case of a recorded campaign (the same configuration, seed and
case index as the raw file records, so the same truth and noise draw), the Cramér–Rao bound
of the injected effect's parameters: the Fisher information ``J^T J`` of the diagnosis's own
forward models at the truth's parameter values, each measurement weighted by one over the
noise the diagnosis estimates from its data (its white part) and the correlated noise the
manifest states (a profile's covariance whitened by its Cholesky factor), the profiles' offset shifts and
the linear nuisances (flux, background: projected out inside each forward) free beside them.
Three sets of free parameters (:func:`free_sets`): the injected effect alone (a perfect model: the
most the data can tell); the effect beside ``quilt_shape`` (the companion every independent
truth carries, since its quilt's shape differs from the simulation's); and beside
``quilt_shape`` and ``amplitude_scale`` (the truth's quilt departs in its x fundamental too).

From the bound's covariance, the chance that an unbiased reading lands within the campaign's
20 % rule (every parameter ``|fit - true| <= 0.2 max(|true|, floor)``; a parameter the
recorded finding reports ``sign_degenerate`` compared by magnitude about its sign origin, as
``pipeline.diagnosis.campaign.recovery_errors`` scores it) is drawn by Monte Carlo; the sum
over cases is the within-20 % count such a reading would reach on average. Beside it, the
bound's 1σ against the 1σ the diagnosis reported.

The bound takes the forward model's derivatives at the truth, and the linear nuisances as each
forward projects them out (least squares, not weighted by the correlated noise: a close
approximation where the nuisances' columns are smooth). The truth's departures from the model
only lower the information, so the count is a ceiling for an unbiased reading. An amplitude's truth is the
truth's own x-fundamental ratio (``rescaling_true``), the amplitude the rescalings measure.

Usage::

    .venv/bin/python benchmarks/information_bound.py RAW.json [RAW.json ...] --out ROWS.json \\
        [--cache-dir DIR] [--indices I ...] [--draws 20000]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np
from scipy.linalg import solve_triangular

sys.path.insert(0, str(Path(__file__).parent))
from rerun_cases import recorded_config  # noqa: E402  (a sibling script)

from pipeline.diagnosis.campaign import campaign_maps, case_type, on_truth_side, one_blas_thread  # noqa: E402
from pipeline.diagnosis.effects import parameter_spec  # noqa: E402
from pipeline.diagnosis.engine import build_problem  # noqa: E402
from pipeline.diagnosis.fitting import fit  # noqa: E402
from pipeline.diagnosis.manifest import load_data, parse_manifest  # noqa: E402
from pipeline.diagnosis.ranking import parameters_of  # noqa: E402
from pipeline.diagnosis.truth.generate import make_case  # noqa: E402

#: central-difference steps: a fraction of each parameter's prior width, and of a micrometre
#: for an offset shift (the profiles are smooth on both scales)
PARAM_STEP = 0.005
SHIFT_STEP_UM = 0.05


def _whitener(forward, sigma_w: float, correlated: bool = True):
    """Residual -> residual in units of its noise: white noise ``sigma_w``, plus a line
    profile's stated correlated noise (squared-exponential, :class:`.noise.CorrelatedNoise`)
    through the Cholesky factor of the covariance (``correlated=False``: white noise only)."""
    cn = getattr(forward, "correlated_noise", None) if correlated else None
    if cn is None:
        return lambda r: r / sigma_w
    cov = sigma_w**2 * np.eye(len(forward.x)) + cn.rms_rel**2 * cn.correlation(forward.x)
    chol = np.linalg.cholesky(cov)
    return lambda r: solve_triangular(chol, r, lower=True)


def fisher_sigma(prob, params, p0: dict, deltas_um: dict, correlated: bool = True) -> np.ndarray:
    """Covariance of ``params`` (physical units) from ``J^T J`` of the noise-weighted residuals
    at ``p0``, every forward's position nuisances free beside them (marginalised)."""
    fws = prob.forwards
    whiten = {f.name: _whitener(f, prob.noise[f.name], correlated) for f in fws}

    def resid(p, d):
        return np.concatenate([whiten[f.name](f.residual(p, d.get(f.name, 0.0))) for f in fws])

    cols = []
    for q in params:
        h = PARAM_STEP * q.width
        up, dn = dict(p0), dict(p0)
        up[q.name] += h
        dn[q.name] -= h
        cols.append((resid(up, deltas_um) - resid(dn, deltas_um)) / (2 * h))
    for f in fws:
        for k in range(f.n_shift):
            d0 = np.atleast_1d(np.asarray(deltas_um.get(f.name, f.delta0_um), dtype=float))
            du, dd = d0.copy(), d0.copy()
            du[k] += SHIFT_STEP_UM
            dd[k] -= SHIFT_STEP_UM
            up = {**deltas_um, f.name: du[0] if d0.size == 1 else tuple(du)}
            dn = {**deltas_um, f.name: dd[0] if d0.size == 1 else tuple(dd)}
            cols.append((resid(p0, up) - resid(p0, dn)) / (2 * SHIFT_STEP_UM))
    J = np.column_stack(cols)
    cov = np.linalg.pinv(J.T @ J)
    return cov[:len(params), :len(params)]


def within_rate(truth: dict, names: list, cov: np.ndarray, sign_free: set, rng, draws: int) -> float:
    """Share of unbiased readings ``N(truth, cov)`` within the campaign's 20 % rule."""
    t = np.array([truth[n] for n in names])
    x = rng.multivariate_normal(t, cov, size=draws, method="eigh")
    ok = np.ones(draws, bool)
    for j, n in enumerate(names):
        q = parameter_spec(n)
        v = x[:, j]
        if n in sign_free:  # compared by magnitude, as the campaign compares it
            v = on_truth_side(v, t[j], q.origin)
        ok &= np.abs(v - t[j]) <= 0.2 * max(abs(t[j]), q.floor)
    return float(ok.mean())


def free_sets(effect: str) -> tuple:
    """The sets of free effects the bound is taken with: the injected effect alone; beside
    ``quilt_shape``; beside ``quilt_shape`` and the quilt's amplitude (``amplitude_scale``, the
    x fundamental an independent truth's quilt also departs in), unless it is the effect."""
    amp = () if effect == "amplitude_scale" else ("amplitude_scale",)
    return (("alone", (effect,)), ("with_quilt_shape", (effect, "quilt_shape")),
            ("with_quilt_shape_and_amplitude", (effect, "quilt_shape") + amp))


def case_bound(cfg, row: dict, nominal, base, rng_mc, draws: int, correlated: bool = True) -> dict:
    """The bound for one recorded case row (both sets of free parameters)."""
    index, (kind, effect) = row["index"], case_type(cfg, row["index"])
    rng = np.random.default_rng([cfg.seed, index])
    with tempfile.TemporaryDirectory() as tmp:
        man, truth = make_case(kind, effect, rng, nominal, base, Path(tmp), cfg)
        truth.pop("_present", None)
        truth.pop("_truth", None)
        manifest = parse_manifest(man, tmp)
        prob, _ = build_problem(manifest, load_data(manifest), nominal,
                                map_in_optics=cfg.criteria.map_in_optics)
    names = [n for n in truth if isinstance(truth[n], (int, float))]
    if "scale_J" in truth and row.get("rescaling_true"):
        truth = {**truth, "scale_J": row["rescaling_true"]}
    out = {"index": index, "effect": effect, "measurement": row["measurement"], "truth": truth,
           "sign_degenerate": row.get("sign_degenerate") or [], "reported_sigma": row.get("uncertainties") or {},
           "recovery_error_measured": row.get("recovery_error_measured")}
    for label, effects in free_sets(effect):
        params = parameters_of(effects, prob.forwards)
        p0 = {q.name: q.null for q in params}
        p0.update({n: truth[n] for n in names if n in p0})
        # the offset shifts where the truth's line lies for this model (public fit: nuisances only)
        deltas = fit(prob, (), fixed=p0).deltas_um
        cov_all = fisher_sigma(prob, params, p0, deltas, correlated)
        idx = [i for i, q in enumerate(params) if q.name in names]
        cov = cov_all[np.ix_(idx, idx)]
        own = [params[i].name for i in idx]
        out[label] = {"sigma": {n: float(np.sqrt(max(cov[j, j], 0.0))) for j, n in enumerate(own)},
                      "p_within_20pct": within_rate(truth, own, cov, set(out["sign_degenerate"]), rng_mc, draws)}
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("raw", type=Path, nargs="+", help="campaign raw JSON files (bench_diagnosis.py --out)")
    ap.add_argument("--out", type=Path, required=True, help="JSON file of the per-case bounds")
    ap.add_argument("--cache-dir", type=Path, default=None, help="disk cache of the nominal FEA maps")
    ap.add_argument("--indices", type=int, nargs="*", default=None, help="only these case indices")
    ap.add_argument("--draws", type=int, default=20000, help="Monte Carlo readings per case")
    ap.add_argument("--white-only", action="store_true", help="leave the stated correlated noise out")
    a = ap.parse_args(argv)
    if a.draws < 100:
        ap.error(f"--draws={a.draws}: the Monte Carlo needs at least 100 readings a case (valid: >= 100; "
                 "the pages use 20000)")
    one_blas_thread()
    rng_mc = np.random.default_rng(7)
    rows = []
    for path in a.raw:
        raw = json.loads(path.read_text()).get("campaign")
        if not isinstance(raw, dict) or not {"config", "criteria", "cases"} <= set(raw):
            ap.error(f"raw={str(path)!r}: not a campaign's raw JSON (needs 'campaign' with 'config', 'criteria', "
                     "'cases', as bench_diagnosis.py --out writes it)")
        cfg = recorded_config(raw)
        if cfg.truth != "independent":
            ap.error(f"raw={str(path)!r}: the bound is taken on independent truths (truth={cfg.truth!r})")
        nominal, base = campaign_maps(cfg, cache_dir=a.cache_dir)
        for row in raw["cases"]:
            if row.get("kind") != "line_profile" or row["effect"].startswith("ool"):
                continue
            if a.indices is not None and row["index"] not in a.indices:
                continue
            b = case_bound(cfg, row, nominal, base, rng_mc, a.draws, correlated=not a.white_only)
            b["raw"] = path.name
            rows.append(b)
            print(path.name, b["index"], b["effect"], b["measurement"],
                  *(f"{k} {b[k]['p_within_20pct']:.2f} {({n: round(v, 4) for n, v in b[k]['sigma'].items()})}"
                    for k, _ in free_sets(b["effect"])), flush=True)
            a.out.write_text(json.dumps(rows, indent=1, default=float))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
