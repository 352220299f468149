"""FEA cases as sweep cases: any model parameter, the paper's tables, one call each.

Units: µm for film thickness and sag, mm for geometry, K for temperatures.

A case is a flat dict of scalars (see :data:`fea.case.PARAMETERS` for names, units,
defaults and valid ranges; :class:`fea.case.FEACase` checks it); :class:`FEACaseRunner` turns it into outputs (P/V and RMS over the
centre and the whole face, the quilt direction, and the sag map on a fixed grid) and
keeps one prepared model (mesh + bulk stiffness) per geometry/mesh/substrate so that a
sweep over coatings and temperatures assembles the bulk once.
"""

from __future__ import annotations

import csv
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fea import store
from fea.calibration import STRESS_SCALE, paper_cases
from fea.case import PARAMETERS, FEACase, model_namespace
from fea.front_figure import front_figure_outputs
from fea.geometry import Blank
from fea.mesh import MeshSpec, blank_mesh
from fea.model import FEAResult, PreparedBlank
from optics.sagmap import SagMap
from pipeline.bounds import MAX_FEA_CASES, check_count, product_count
from pipeline.io.common import atomic_write
from pipeline.sweeps.sweep import Case, grid, run_sweep

__all__ = ["FEACaseRunner", "fea_grid", "run_fea_sweep", "run_tables",
           "TableRow", "format_table", "SAG_GRID_X_MM", "SAG_GRID_Y_MM", "FIGURE_KEYS", "case_namespace",
           "write_figure_summary", "write_table_rows", "quilt_direction_um", "field_path", "save_field", "load_field"]

#: Fixed output grid of the sag maps (covers the default 160 x 140 mm face).
SAG_SPACING_MM = 0.5
SAG_GRID_X_MM = np.round(np.arange(-80.0, 80.0 + 1e-9, SAG_SPACING_MM), 6)
SAG_GRID_Y_MM = np.round(np.arange(-70.0, 70.0 + 1e-9, SAG_SPACING_MM), 6)


def _case(params: dict):
    """Case dict -> (FEACase, its solver objects); ValueError naming the parameter."""
    case = FEACase.from_params(params)
    return case, case.to_objects()


def quilt_direction_um(sag, blank: Blank) -> float:
    """Sag over the central hole crossing minus over the adjacent rib crossing (µm)."""
    xs, ys = blank.hole_x_positions_mm, blank.hole_y_positions_mm
    if len(xs) == 0 or len(ys) == 0:
        return 0.0
    x0 = xs[np.argmin(np.abs(xs))]
    y0 = ys[np.argmin(np.abs(ys))]
    return sag.value_at(x0, y0) - sag.value_at(x0 + blank.pitch_x_mm / 2, y0 + blank.pitch_y_mm / 2)


def field_path(fields_dir, params: dict):
    """The :mod:`fea.store` entry of the displacement field of the case ``params``
    (key: params + model version; ``.payload`` is the ``.npz``)."""
    norm = {k: (v if isinstance(v, (str, int, float, bool)) or v is None else str(v)) for k, v in params.items()}
    return store.entry(fields_dir, f"field-{model_namespace()}", norm)


def save_field(entry, result) -> None:
    """Displacement field (mm, float32) + node positions + case info, written atomically
    with its checksummed sidecar (``entry`` from :func:`field_path`)."""
    store.save_arrays(entry, {"coords_mm": result.coords_mm,
                              "displacement_mm": result.displacement_mm.astype(np.float32),
                              "uniform_strain": result.uniform_strain,
                              "info": json.dumps(result.info, default=str)})


def load_field(entry):
    """The :class:`fea.model.FEAResult` (without sag) saved by :func:`save_field`, or None
    (absent; a damaged or mismatched file also warns)."""
    try:
        z, _ = store.load_arrays(entry)
        return FEAResult(z["coords_mm"], z["displacement_mm"].astype(float), float(z["uniform_strain"]),
                         None, json.loads(str(z["info"])))
    except FileNotFoundError:
        return None
    except (store.CacheMiss, KeyError, ValueError) as exc:
        store.warn_rebuild(entry, exc, "displacement field")
        return None


class FEACaseRunner:
    """Callable case function for :func:`pipeline.sweeps.sweep.run_sweep`.

    Keeps prepared models (mesh + bulk stiffness) per (blank, mesh, substrate) in the
    instance; pickling sends an empty cache, so each worker process builds its own.

    Parameters
    ----------
    with_maps : bool
        Return the sag map on the fixed grid.
    fields_dir : path, optional
        Keep the displacement fields of the cases in ``fields_for`` there
        (:func:`field_path`), e.g. for the study's 3-D renders.
    fields_for : list of dict
        Case parameter dicts whose fields are kept.
    """

    def __init__(self, with_maps: bool = True, fields_dir=None, fields_for=()):
        self.with_maps = with_maps
        self.fields_dir = fields_dir
        self.fields_for = [dict(p) for p in fields_for]
        self._models: dict = {}

    def __getstate__(self):
        return {"with_maps": self.with_maps, "fields_dir": self.fields_dir, "fields_for": self.fields_for,
                "_models": {}}

    def model(self, blank: Blank, spec: MeshSpec, substrate: str) -> PreparedBlank:
        key = (blank, spec, substrate)
        if key not in self._models:
            self._models = {key: PreparedBlank(blank_mesh(blank, spec), substrate)}  # keep one: memory
        return self._models[key]

    #: cases solved together in one lockstep block (PreparedBlank.solve_many); a block is
    #: also a unit of progress, so it stays small enough for the progress bar to move
    block_size = 16

    def plan(self, params_list) -> None:
        """Announce the cases about to be run (the ``planner`` of an inline sweep): those
        that share a mesh, materials and load are then solved in blocks
        (:meth:`PreparedBlank.solve_many`), one block when its first case is asked for."""
        self._planned = [dict(p) for p in params_list]
        self._solved: dict = {}

    def _solve_block(self, params: dict):
        """Solve the planned block that holds ``params``; returns its FEAResult or None."""
        try:
            case, obj = _case(params)
        except ValueError:
            return None
        key = case.cache_key()
        if key in getattr(self, "_solved", {}):
            return self._solved.pop(key)
        planned = getattr(self, "_planned", None)
        if not planned:
            return None

        def shared(c: FEACase, o) -> tuple:  # what the cases of one block have in common
            return o.blank, o.mesh, c.substrate, c.film, o.load, o.stress_scale

        same, rest = [], []
        for p in planned:  # this case first, then the planned ones that share its model
            try:
                c, o = _case(p)
            except ValueError:
                rest.append(p)
                continue
            if shared(c, o) != shared(case, obj):
                rest.append(p)
            elif c.cache_key() == key:
                same.insert(0, (p, c.cache_key(), o.coating))
            else:
                same.append((p, c.cache_key(), o.coating))
        if not same or same[0][1] != key or len(same) < 2:
            return None
        same, later = same[:self.block_size], same[self.block_size:]
        self._planned = rest + [p for p, _, _ in later]
        model = self.model(obj.blank, obj.mesh, case.substrate)
        try:
            results = model.solve_many([c for _, _, c in same], case.film, obj.load, stress_scale=obj.stress_scale)
        except ValueError:  # e.g. one case the model refuses: let each case say it on its own
            return None
        for (_, k, _), r in zip(same, results):
            self._solved[k] = r
        return self._solved.pop(key)

    def __call__(self, params: dict) -> dict:
        case, o = _case(params)
        blank, scale = o.blank, o.stress_scale
        model = self.model(blank, o.mesh, case.substrate)
        r = self._solve_block(params) or model.solve(o.coating, case.film, o.load, stress_scale=scale)
        if self.fields_dir is not None and dict(params) in self.fields_for:
            save_field(field_path(self.fields_dir, params), r)
        s = r.sag
        out = {
            "pv_center_um": s.pv_um("center"), "rms_center_um": s.rms_um("center"),
            "pv_full_um": s.pv_um("full"), "rms_full_um": s.rms_um("full"),
            "quilt_direction_um": quilt_direction_um(s, blank),
            "ndof": int(r.info["ndof"]), "solve_s": float(r.info["solve_s"]),
            "stress_scale_used": float(scale),
        }
        out.update(front_figure_outputs(model.mesh, r, model.symmetry_planes))
        if self.with_maps:
            m = s.sag_map(SAG_SPACING_MM).resampled(SAG_GRID_X_MM, SAG_GRID_Y_MM)
            out["sag_um"] = (("y_mm", "x_mm"), m.sag_um.astype(np.float32))
            out["coord:y_mm"] = SAG_GRID_Y_MM
            out["coord:x_mm"] = SAG_GRID_X_MM
        return out


def fea_grid(**axes) -> list:
    """Cartesian product of FEA parameter values, validated before any meshing."""
    cases = grid(**axes)
    for c in cases:
        FEACase.from_params(c.as_dict())  # raises with the parameter's name, value and range
    return cases


def case_namespace() -> str:
    """Cache namespace of :class:`FEACaseRunner` outputs: the model's, plus the version of the
    output set (cases cached before the rigid-body/power outputs are recomputed, not reused)."""
    return f"{model_namespace()}-outputs2"


#: Per-case outputs of the front face's rigid-body motion and low-order figure
#: (:mod:`fea.front_figure`) -> (SigFit-style column header, UDUNITS unit, long name).
FIGURE_KEYS = {
    "rb_dx_um": ("T1 dx", "um", "front-face rigid-body translation x (dispersion), relative to the blank"),
    "rb_dy_um": ("T2 dy", "um", "front-face rigid-body translation y (rulings), relative to the blank"),
    "rb_dz_um": ("T3 dz", "um", "front-face rigid-body translation z (piston), relative to the blank"),
    "rb_rx_urad": ("R1 rx", "urad", "front-face rigid-body rotation about x, relative to the blank"),
    "rb_ry_urad": ("R2 ry", "urad", "front-face rigid-body rotation about y, relative to the blank"),
    "rb_rz_urad": ("R3 rz", "urad", "front-face rigid-body rotation about z (groove clocking), relative to the blank"),
    "pv_center_um": ("PV center PT", "um", "P/V over the central 82 x 72 mm, piston and tilt removed"),
    "rms_center_um": ("RMS center PT", "um", "RMS over the central 82 x 72 mm, piston and tilt removed"),
    "pv_center_pttp_um": ("PV center PTP", "um", "P/V over the central 82 x 72 mm, piston, tilt, power removed"),
    "rms_center_pttp_um": ("RMS center PTP", "um", "RMS over the central 82 x 72 mm, piston, tilt, power removed"),
    "power_center_um_per_mm2": ("power center", "um mm-2", "removed power c of c (x^2 + y^2), central 82 x 72 mm"),
    "pv_full_um": ("PV full PT", "um", "P/V over the whole face, piston and tilt removed"),
    "rms_full_um": ("RMS full PT", "um", "RMS over the whole face, piston and tilt removed"),
    "pv_full_pttp_um": ("PV full PTP", "um", "P/V over the whole face, piston, tilt, power removed"),
    "rms_full_pttp_um": ("RMS full PTP", "um", "RMS over the whole face, piston, tilt, power removed"),
    "power_full_um_per_mm2": ("power full", "um mm-2", "removed power c of c (x^2 + y^2), whole face"),
}


def write_figure_summary(path, labels, outputs: dict) -> Path:
    """SigFit-style summary CSV: one row per case, rigid-body motion then P/V and RMS with
    piston/tilt (PT) and piston/tilt/power (PTP) removed; a units row under the header."""
    keys = [k for k in FIGURE_KEYS if all(k in outputs[lb] for lb in labels)]
    with atomic_write(Path(path)) as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(["case", *(FIGURE_KEYS[k][0] for k in keys)])
        w.writerow(["units", *(FIGURE_KEYS[k][1] for k in keys)])
        for lb in labels:
            w.writerow([lb, *(f"{float(outputs[lb][k]):.6g}" for k in keys)])
    return Path(path)


def run_fea_sweep(axes: dict, out_dir, *, scheduler: str | None = None, workers: int | None = 1,
                  progress: bool = True, with_maps: bool = True):
    """Run every combination of ``axes`` (name → list of values) and write the results.

    Writes ``out_dir/sweep.csv`` (one row per case: parameters, P/V and RMS) and
    ``out_dir/sweep.nc`` (the same plus sag maps on a fixed grid); finished cases are
    cached under ``out_dir/cases`` and reused on re-run, so a killed sweep resumes.
    ``workers=1`` (default) solves in this process: PARDISO already uses both cores.
    """
    # the table always names the case: unswept core parameters appear as one-value axes
    core = {k: [PARAMETERS[k].default] for k in ("coverage", "t0_um", "polish")}
    axes = {**core, **axes}
    check_count(product_count(len(v) if isinstance(v, (list, tuple)) else 1 for v in axes.values()),
                "cases", MAX_FEA_CASES, "the product of the axes' value counts; give fewer values")
    cases = fea_grid(**axes)
    runner = FEACaseRunner(with_maps)
    res = run_sweep(runner, cases, out_dir, namespace=case_namespace(), workers=workers, scheduler=scheduler,
                    progress=progress, description="FEA sweep", planner=runner.plan)
    out = Path(out_dir)
    res.write_csv(out / "sweep.csv")
    res.write_netcdf(out / "sweep.nc")
    if len(res):
        labels = [" ".join(f"{k}={v}" for k, v in case.as_dict().items()) for case, _ in res]
        write_figure_summary(out / "figure_summary.csv", labels, {lb: o for lb, (_, o) in zip(labels, res)})
    return res


@dataclass(frozen=True)
class TableRow:
    table: str
    coverage: str
    t0_um: float
    polish: float
    paper_pv_um: float
    model_pv_um: float
    paper_direction: str
    model_direction_um: float
    calibrated: bool
    #: the case's rigid-body and low-order figure outputs (:data:`FIGURE_KEYS`), written as extra columns
    figure: dict = field(default_factory=dict, compare=False)

    @property
    def error(self) -> float:
        return self.model_pv_um / self.paper_pv_um - 1.0

    @property
    def direction_ok(self) -> bool:
        return (self.model_direction_um > 0) == (self.paper_direction == "up")


def run_tables(out_dir, *, progress: bool = True, mesh_size_mm: float | None = None,
               mesh_bulk_mm: float | None = None, stress_scale: float | None = None,
               return_maps: bool = False):
    """Solve the paper's 15 cases (Tables 1 and 2) and compare with the paper.

    Writes ``out_dir/tables.csv`` (model vs paper, % error, quilt direction) and
    ``out_dir/sweep.nc`` with the sag maps. Returns the rows, or ``(rows, maps)``
    with ``maps[(coverage, t0_um, polish)]`` a :class:`optics.sagmap.SagMap` when
    ``return_maps``.
    """
    extra = {k: v for k, v in (("mesh_size_mm", mesh_size_mm), ("mesh_bulk_mm", mesh_bulk_mm),
                               ("stress_scale", stress_scale)) if v is not None}
    paper = paper_cases()
    cases = [Case({"coverage": c.coverage, "t0_um": c.t0_um, "polish": c.polish, **extra}) for c in paper]
    runner = FEACaseRunner()
    res = run_sweep(runner, cases, out_dir, namespace=case_namespace(), workers=1,
                    progress=progress, description="paper tables", planner=runner.plan)
    rows = [TableRow(c.table, c.coverage, c.t0_um, c.polish, c.pv_center_um, float(out["pv_center_um"]),
                     c.direction, float(out["quilt_direction_um"]), c.calibrate, figure_of(out))
            for c, (_, out) in zip(paper, res)]
    out = Path(out_dir)
    res.write_netcdf(out / "sweep.nc")
    write_table_rows(rows, out / "tables.csv")
    labels = [f"{r.table} {r.coverage} {r.t0_um:g}/{100 * r.polish:g}" for r in rows]
    write_figure_summary(out / "figure_summary.csv", labels, {lb: r.figure for lb, r in zip(labels, rows)})
    if not return_maps:
        return rows
    maps = {(c.coverage, c.t0_um, c.polish): SagMap(SAG_GRID_X_MM, SAG_GRID_Y_MM,
                                                    np.asarray(o["sag_um"][1] if isinstance(o["sag_um"], tuple)
                                                               else o["sag_um"], float),
                                                    f"{c.coverage} {c.t0_um:g} µm / {100 * c.polish:g} %")
            for c, (_, o) in zip(paper, res)}
    return rows, maps


def figure_of(outputs: dict) -> dict:
    """The :data:`FIGURE_KEYS` outputs of one case (those present)."""
    return {k: float(outputs[k]) for k in FIGURE_KEYS if k in outputs}


_TABLE_FIGURE_KEYS = [k for k in FIGURE_KEYS if k not in ("pv_center_um", "rms_center_um", "pv_full_um",
                                                          "rms_full_um")]


def write_table_rows(rows, path: Path) -> None:
    """Write the paper-table rows (:class:`TableRow`) as ``tables.csv``, atomically."""
    extra = [k for k in _TABLE_FIGURE_KEYS if rows and all(k in r.figure for r in rows)]
    buf = [["table", "coverage", "t0_um", "polish", "paper_pv_center_um", "model_pv_center_um",
             "error_percent", "paper_direction", "model_quilt_direction_um", "direction_ok",
             "used_in_calibration", *extra]]
    for r in rows:
        buf.append([r.table, r.coverage, f"{r.t0_um:g}", f"{r.polish:g}", f"{r.paper_pv_um:.2f}",
                    f"{r.model_pv_um:.4f}", f"{100 * r.error:+.1f}", r.paper_direction,
                    f"{r.model_direction_um:+.4f}", str(r.direction_ok).lower(),
                    "yes" if r.calibrated else "no", *(f"{r.figure[k]:.6g}" for k in extra)])
    with atomic_write(path) as fh:
        csv.writer(fh, lineterminator="\n").writerows(buf)


def format_table(rows: list[TableRow]) -> str:
    """The side-by-side model-vs-paper table as text."""
    lines = [f"{'table':5} {'coverage':9} {'t0 µm':>6} {'polish':>6} {'paper':>7} {'model':>7} "
             f"{'error':>7}  direction",
             "-" * 66]
    for r in rows:
        d = "up" if r.model_direction_um > 0 else "down"
        flag = "" if r.calibrated else "  (not calibrated: see README)"
        lines.append(f"{r.table:5} {r.coverage:9} {r.t0_um:6g} {r.polish:6.2f} {r.paper_pv_um:7.2f} "
                     f"{r.model_pv_um:7.3f} {100 * r.error:+6.1f}%  {d:4} "
                     f"({'ok' if r.direction_ok else 'WRONG'}){flag}")
    cal = [r for r in rows if r.calibrated]
    if cal:
        e = np.array([r.error for r in cal])
        lines.append("-" * 66)
        lines.append(f"calibrated rows: RMS error {100 * np.sqrt(np.mean(e**2)):.1f}%, "
                     f"max |error| {100 * np.abs(e).max():.1f}% (stress scale {STRESS_SCALE:.4f})")
    return "\n".join(lines)
