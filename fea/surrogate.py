"""Millisecond surrogate of the plated blank over film thickness, polish, coverage and cold temperature.

Units: µm for film thickness and sag, K for temperatures.

Built on :class:`fea.reduced.ReducedBasis`: with the mesh fixed the system is an exact
polynomial in each surface group's film thickness, so the Galerkin projection onto a
few full solutions is exact in form and only the basis is approximate. The basis is
chosen greedily: among random candidate points of the domain, the one with the largest
(sketched) residual gets a full solve, until every candidate's residual estimate is
below ``tol``. The cold temperature and the calibration scale only scale the load, so
they are free at evaluation time.

Accuracy is reported, not assumed: :meth:`FEASurrogate.validate` compares P/V with full
solves at random points of the domain (``benchmarks/bench_surrogate.py``).
"""

from __future__ import annotations

import copy
import time
from dataclasses import dataclass, field, replace

import numpy as np

from .coating import COVERAGES, Coating
from .materials import NIP_HIGH_P, Material, get_material
from .model import PreparedBlank, ThermalLoad
from .reduced import ReducedBasis
from .surface import FrontSag

__all__ = ["FEASurrogate", "SurrogateDomain", "build_surrogate"]


@dataclass(frozen=True)
class SurrogateDomain:
    """Box of coating parameters the surrogate is trained on.

    Parameters
    ----------
    t0_um : (float, float)
        Range of the original film thickness (µm).
    polish : (float, float)
        Range of the polish fraction of the faces (front = back).
    coverages : tuple of str
        Coverage presets included.
    """

    t0_um: tuple[float, float] = (50.0, 300.0)
    polish: tuple[float, float] = (0.25, 1.0)
    coverages: tuple[str, ...] = ("all", "holes", "surfaces")

    def __post_init__(self):
        lo, hi = self.t0_um
        if not (0 < lo <= hi <= 2000):
            raise ValueError(f"t0_um={self.t0_um}: need 0 < low <= high <= 2000 µm")
        lo, hi = self.polish
        if not (0 < lo <= hi <= 1):
            raise ValueError(f"polish={self.polish}: need 0 < low <= high <= 1")
        bad = [c for c in self.coverages if c not in COVERAGES or c == "none"]
        if not self.coverages or bad:
            raise ValueError(f"coverages={self.coverages}: valid values are "
                             f"{[c for c in COVERAGES if c != 'none']}")

    def contains(self, coating: Coating, rel_tol: float = 1e-9) -> bool:
        lo, hi = self.t0_um
        plo, phi = self.polish
        return (coating.coverage in self.coverages
                and lo * (1 - rel_tol) <= coating.t0_um <= hi * (1 + rel_tol)
                and all(plo - rel_tol <= p <= phi + rel_tol
                        for p in (coating.polish_front, coating.polish_back)))

    def sample(self, n: int, rng: np.random.Generator) -> list[Coating]:
        """``n`` random symmetric coatings, uniform in t0, polish and coverage."""
        cov = rng.choice(list(self.coverages), n)
        t0 = rng.uniform(*self.t0_um, n)
        p = rng.uniform(*self.polish, n)
        return [Coating.symmetric(float(a), float(b), str(c)) for a, b, c in zip(t0, p, cov)]

    def corners(self) -> list[Coating]:
        return [Coating.symmetric(t, p, c) for c in self.coverages for t in self.t0_um for p in self.polish]


@dataclass
class SurrogateResult:
    """One surrogate evaluation: the sag and the sketched relative residual."""

    sag: FrontSag
    residual_estimate: float
    coating: Coating
    load: ThermalLoad


@dataclass
class FEASurrogate:
    """Reduced model of one prepared mesh, film material and calibration scale.

    Use :func:`build_surrogate`; evaluate with :meth:`evaluate` or :meth:`pv_center_um`.
    """

    model: PreparedBlank
    film: Material
    stress_scale: float
    domain: SurrogateDomain
    rb: ReducedBasis
    sag_template: FrontSag
    sag_basis_um: np.ndarray  # (n_samples, m): sag of each basis vector
    sag_normal_basis_um: np.ndarray
    build_info: dict = field(default_factory=dict)
    _region_ops: dict = field(default_factory=dict, repr=False)

    @property
    def size(self) -> int:
        return self.rb.size

    def _region_operator(self, region: str):
        """Detrended sag basis over ``region`` and its weighted Gram matrix.

        The piston/tilt removal of :meth:`FrontSag.detrended` is a linear projection, so
        it is applied once to the basis: a case's P/V is then max − min of one
        (n_region × m) product and its RMS an m × m quadratic form.
        """
        if region not in self._region_ops:
            t = self.sag_template
            m = t.in_region(region)
            S, w = self.sag_basis_um[m], t.weight_mm2[m]
            A = np.column_stack([np.ones(m.sum()), t.x_mm[m], t.y_mm[m]])
            sw = np.sqrt(w)[:, None]
            C, *_ = np.linalg.lstsq(A * sw, S * sw, rcond=None)
            D = S - A @ C
            self._region_ops[region] = (D, D.T @ (w[:, None] * D), D.T @ w, w.sum())
        return self._region_ops[region]

    def statistics(self, coating: Coating, load: ThermalLoad | None = None,
                   stress_scale: float | None = None, regions=("center", "full")) -> dict:
        """P/V and RMS (µm, piston/tilt removed per region) of one case, without forming the sag.

        Returns ``{"pv_<region>_um": ..., "rms_<region>_um": ..., "residual_estimate": ...}``;
        equal to ``evaluate(...).sag.pv_um(region)`` / ``rms_um(region)`` to rounding.
        """
        a, res = self.coefficients(coating, load, stress_scale)
        out = {"residual_estimate": res}
        for region in regions:
            D, G, c, W = self._region_operator(region)
            d = D @ a
            out[f"pv_{region}_um"] = float(d.max() - d.min())
            out[f"rms_{region}_um"] = float(np.sqrt(max(a @ G @ a / W - (c @ a / W) ** 2, 0.0)))
        return out

    def statistics_many(self, coatings, loads=None, stress_scales=None, regions=("center", "full"),
                        chunk: int = 64) -> list[dict]:
        """:meth:`statistics` of many cases at once (same numbers, to rounding).

        The detrended sag basis (n_samples × m, ~35 MB per region at the default mesh) is
        read once per ``chunk`` cases (one matrix product) instead of once per case: ~20x
        faster than calling :meth:`statistics` in a loop for a 1000-point sweep.
        """
        n = len(coatings)
        loads = [None] * n if loads is None else list(loads)
        scales = [None] * n if stress_scales is None else list(stress_scales)
        if not (len(loads) == len(scales) == n):
            raise ValueError(f"{n} coatings but {len(loads)} loads and {len(scales)} stress scales")
        coef = [self.coefficients(c, ld, sc) for c, ld, sc in zip(coatings, loads, scales)]
        out = [{"residual_estimate": res} for _, res in coef]
        A = np.array([a for a, _ in coef]).T  # (m, n)
        for region in regions:
            D, G, c, W = self._region_operator(region)
            rms = np.sqrt(np.maximum(np.einsum("in,ij,jn->n", A, G, A) / W - (c @ A / W) ** 2, 0.0))
            for s0 in range(0, n, chunk):
                d = D @ A[:, s0:s0 + chunk]
                pv = d.max(axis=0) - d.min(axis=0)
                for k, i in enumerate(range(s0, min(s0 + chunk, n))):
                    out[i][f"pv_{region}_um"] = float(pv[k])
                    out[i][f"rms_{region}_um"] = float(rms[i])
        return out

    def check(self, coating: Coating, load: ThermalLoad | None = None) -> None:
        """Raise ValueError when the case is outside the training domain or the material data."""
        if not self.domain.contains(coating):
            raise ValueError(f"coating {coating.coverage} t0_um={coating.t0_um} polish="
                             f"{coating.polish_front}/{coating.polish_back} is outside the surrogate's "
                             f"domain (t0_um {self.domain.t0_um}, polish {self.domain.polish}, "
                             f"coverages {self.domain.coverages}); use a full solve")
        load = ThermalLoad() if load is None else load
        self.model.substrate.check_temperature(load.cold_K, "cold_K")
        self.film.check_temperature(load.cold_K, "cold_K")

    def coefficients(self, coating: Coating, load: ThermalLoad | None = None,
                     stress_scale: float | None = None):
        """Reduced coefficients and residual estimate of one case.

        ``stress_scale`` defaults to the one the surrogate was trained with; any other
        value only rescales the load, which the reduced model represents exactly."""
        load = ThermalLoad() if load is None else load
        scale = self.stress_scale if stress_scale is None else stress_scale
        eps = self.model.mismatch_strain(self.film, load, scale)
        t_mm = {g: t * 1e-3 for g, t in self.model.film_thickness_um(coating).items()}
        a = self.rb.solve(t_mm, eps)
        return a, self.rb.residual_estimate(a, t_mm, eps)

    def evaluate(self, coating: Coating, load: ThermalLoad | None = None,
                 check_domain: bool = True, stress_scale: float | None = None) -> SurrogateResult:
        """Front sag of one case (milliseconds).

        Raises
        ------
        ValueError
            When ``coating`` lies outside the training domain (extrapolation is not
            checked by the greedy construction) and ``check_domain`` is true.
        """
        if check_domain:
            self.check(coating, load)
        load = ThermalLoad() if load is None else load
        self.model.substrate.check_temperature(load.cold_K, "cold_K")
        self.film.check_temperature(load.cold_K, "cold_K")
        a, res = self.coefficients(coating, load, stress_scale)
        sag = replace(self.sag_template, sag_um=self.sag_basis_um @ a,
                      sag_normal_um=self.sag_normal_basis_um @ a)
        return SurrogateResult(sag, res, coating, load)

    def pv_center_um(self, coating: Coating, load: ThermalLoad | None = None) -> float:
        return self.evaluate(coating, load).sag.pv_um("center")

    def validate(self, n_points: int = 8, seed: int = 1, progress=None) -> list[dict]:
        """Compare with full solves at ``n_points`` random points of the domain.

        Returns one dict per point: parameters, full and surrogate P/V_center (µm),
        relative error, residual estimate, full-solve time (s).
        """
        rng = np.random.default_rng(seed)
        rows = []
        for c in self.domain.sample(n_points, rng):
            t = time.perf_counter()
            full = self.model.solve(c, self.film, stress_scale=self.stress_scale).sag.pv_um("center")
            t_full = time.perf_counter() - t
            t = time.perf_counter()
            r = self.evaluate(c)
            t_sur = time.perf_counter() - t
            pv = r.sag.pv_um("center")
            rows.append({"coverage": c.coverage, "t0_um": c.t0_um, "polish": c.polish_front,
                         "pv_center_full_um": full, "pv_center_surrogate_um": pv,
                         "rel_error": pv / full - 1 if full else float("nan"),
                         "residual_estimate": r.residual_estimate,
                         "full_solve_s": t_full, "surrogate_s": t_sur})
            if progress is not None:
                progress(rows[-1])
        return rows


def _freeze(rb: ReducedBasis) -> dict:
    return {k: copy.deepcopy(v) for k, v in vars(rb).items() if k not in ("K_bulk", "films", "sketch")}


def _restore(rb: ReducedBasis, state: dict) -> None:
    for k, v in state.items():
        setattr(rb, k, v)


def build_surrogate(model: PreparedBlank, domain: SurrogateDomain = SurrogateDomain(),
                    film: Material | str = NIP_HIGH_P, stress_scale: float = 1.0, tol: float = 2e-3,
                    max_solves: int = 24, n_candidates: int = 300, seed: int = 0,
                    progress=None, snapshot_rtol: float | None = None) -> FEASurrogate:
    """Greedy reduced-basis construction on ``model`` over ``domain``.

    Parameters
    ----------
    model : PreparedBlank
        The meshed blank (its reduced basis grows with the training solves).
    domain : SurrogateDomain
        Training box.
    film : Material or str
    stress_scale : float
        Calibration scale (``fea.calibration.STRESS_SCALE`` for calibrated results).
    tol : float
        Stop when every candidate's sketched relative residual is below this. At
        2e-3 the P/V error is ~1e-3 (measured in ``benchmarks/results_surrogate.md``).
    max_solves : int
        Full solves allowed; if ``tol`` is not reached the surrogate is still returned
        and ``build_info["converged"]`` is False.
    n_candidates : int
        Random candidate points (plus the domain's corners).
    progress : callable, optional
        Called with a dict after each full solve.
    snapshot_rtol : float, optional
        Residual to which the training solves are converged; default ``tol / 10``, not below
        1e-5: a snapshot needs no more accuracy than the basis it joins, and the looser
        solve saves iterations.
    """
    film = get_material(film)
    snap_rtol = max(1e-5, tol / 10) if snapshot_rtol is None else snapshot_rtol
    rng = np.random.default_rng(seed)
    cands = domain.corners() + domain.sample(n_candidates, rng)
    rb = model.reduced_basis(film)
    eps = model.mismatch_strain(film, ThermalLoad(), stress_scale)
    if eps == 0:
        raise ValueError("the mismatch strain is zero (stress_scale=0 or matched CTE): nothing to reduce")
    thick = [{g: t * 1e-3 for g, t in model.film_thickness_um(c).items()} for c in cands]
    t_start = time.perf_counter()
    solves, worst = 0, np.inf
    history = []
    mid = Coating.symmetric(float(np.mean(domain.t0_um)), float(np.mean(domain.polish)), domain.coverages[0])
    next_case = mid if rb.size == 0 else None
    while True:
        if next_case is None:
            est = np.array([rb.residual_estimate(rb.solve(t, eps), t, eps) for t in thick])
            i = int(np.argmax(est))
            worst = float(est[i])
            history.append(worst)
            if worst < tol or solves >= max_solves:
                break
            next_case = cands[i]
        size = rb.size
        model.solve(next_case, film, stress_scale=stress_scale, rtol=snap_rtol)
        solves += 1
        if rb.size == size and worst > tol:
            raise RuntimeError(f"the full solve of {next_case} did not enlarge the reduced basis "
                               f"(size {size}); the surrogate cannot improve")
        if progress is not None:
            progress({"solves": solves, "basis": rb.size, "worst_residual": worst,
                      "case": f"{next_case.coverage} {next_case.t0_um:.0f}/{next_case.polish_front:.2f}"})
        next_case = None
    # sag of each basis vector (the sag is linear in the displacement)
    cols, ncols, template = [], [], None
    for q in rb.Q.T:
        s = model.front_sampler()(q.reshape(-1, 3).T)
        template = s if template is None else template
        cols.append(s.sag_um)
        ncols.append(s.sag_normal_um)
    frozen = copy.copy(rb)
    _restore(frozen, _freeze(rb))
    info = {"full_solves": solves, "basis_size": rb.size, "worst_residual_estimate": worst,
            "converged": worst < tol, "tol": tol, "build_s": time.perf_counter() - t_start,
            "residual_history": history, "n_candidates": len(cands), "snapshot_rtol": snap_rtol}
    return FEASurrogate(model, film, stress_scale, domain, frozen, template,
                        np.column_stack(cols), np.column_stack(ncols), info)
