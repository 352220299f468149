"""Run a function over a grid of parameter cases, with a resumable on-disk cache.

>>> cases = grid(temperature_K=[80, 300], pitch_mm=parse_range("1:2:3n"))
>>> res = run_sweep(solve_case, cases, "runs/thermal", namespace="fea-v1")  # doctest: +SKIP
>>> res.to_dataset()["pv_um"].sel(temperature_K=80)                         # doctest: +SKIP

``solve_case(params: dict) -> dict`` must be a pure, picklable (top-level) function
of the case. Each case's outputs are cached under ``out_dir/cases/<key>.npz`` (+ a
``.json``), keyed by ``namespace`` and the canonical params (see
:meth:`Case.key`). Change ``namespace`` when the case function changes meaning: the
cache never compares code or library versions, only namespace and params; each
case file is verified against its key and checksum on load (:mod:`fea.store`),
and one that is not what it claims to be is recomputed with a :class:`CacheWarning`.
"""

from __future__ import annotations

import csv
import importlib.util
import io
import itertools
import math
import os
import pickle
import sys
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from tqdm.auto import tqdm

from pipeline.io.common import atomic_path, atomic_write, ensure_writable_dir
from fea.store import CacheWarning
from pipeline.sweeps.cache import (
    COORD_PREFIX,
    CacheMiss,
    canonical_token,
    case_key,
    library_version,
    load_case,
    save_case,
)
from pipeline.sweeps.executors import check_scheduler, iter_dask, iter_inline, iter_processes

__all__ = ["Case", "grid", "parse_range", "run_sweep", "SweepResult", "SweepError", "CacheWarning"]

_PARAM_TYPES = "float, int, str or bool"
#: Cached cases that fail verification are each named in a warning up to this many.
_MAX_CASE_WARNINGS = 10


class SweepError(RuntimeError):
    """Some cases raised; the others completed and are cached.

    Attributes
    ----------
    failures : list of (Case, str, str)
        failed case, ``"ExceptionType: message"`` and the worker's traceback text.
    result : SweepResult
        the cases that succeeded (reused or computed), in input order.
    """

    def __init__(self, failures, result, n_total):
        self.failures = failures
        self.result = result
        lines = [f"{len(failures)} of {n_total} cases failed (the other cases are cached; "
                 "tracebacks in SweepError.failures, rerun with workers=1 to debug):"]
        lines += [f"  {case}: {message}" for case, message, _ in failures[:20]]
        if len(failures) > 20:
            lines.append(f"  ... and {len(failures) - 20} more")
        super().__init__("\n".join(lines))


def _check_param(name: object, value: object):
    """Return ``value`` as a plain Python scalar, or raise naming the parameter."""
    if not isinstance(name, str) or not name:
        raise TypeError(f"parameter name {name!r} must be a non-empty str")
    if isinstance(value, np.generic):
        value = value.item()
    if not isinstance(value, (bool, int, float, str)):
        raise TypeError(f"parameter {name!r} = {value!r} has type {type(value).__name__}; use {_PARAM_TYPES}")
    if isinstance(value, float) and not math.isfinite(value):
        raise ValueError(f"parameter {name!r} = {value!r} must be finite")
    return value


@dataclass(frozen=True)
class Case:
    """One point of a sweep: an ordered mapping of parameter name -> scalar.

    Parameters
    ----------
    params : tuple of (str, scalar) pairs, or a mapping
        values are float, int, str or bool (NumPy scalars are converted). Order is
        kept for display and for dataset dimensions; it does not enter :meth:`key`.
    """

    params: tuple[tuple[str, object], ...]

    def __post_init__(self):
        raw = self.params.items() if isinstance(self.params, Mapping) else self.params
        pairs = []
        for item in raw:
            if not (isinstance(item, tuple) and len(item) == 2):
                raise TypeError(f"Case params must be (name, value) pairs, got {item!r}")
            pairs.append((item[0], _check_param(*item)))
        names = [n for n, _ in pairs]
        if len(set(names)) != len(names):
            raise ValueError(f"Case params repeat a name: {names}")
        object.__setattr__(self, "params", tuple(pairs))

    def as_dict(self) -> dict:
        """The params as a new ``dict`` (what the case function receives)."""
        return dict(self.params)

    def key(self, namespace: str) -> str:
        """Cache key: sha256 hex of ``namespace`` + canonical JSON of the params.

        Keys are sorted, and numbers canonicalised: integral values are written as
        integers (``200 == 200.0``), others with 12 significant digits, so values
        equal up to float noise share a key; ``True``, ``1`` and ``"1"`` differ.
        """
        return case_key(namespace, dict(self.params))

    def __str__(self) -> str:
        return ", ".join(f"{n}={v!r}" for n, v in self.params)


def grid(**axes) -> list[Case]:
    """Cartesian product of parameter axes, first axis outermost (as ``itertools.product``).

    Parameters
    ----------
    **axes : sequence of scalars, or a scalar
        values of each parameter; a bare scalar is a one-value axis.

    Raises
    ------
    ValueError
        no axes, an empty axis or a repeated value (naming the axis).
    TypeError
        an unsupported value type (naming the axis).
    """
    if not axes:
        raise ValueError("grid() needs at least one axis, e.g. grid(temperature_K=[80, 300])")
    values = []
    for name, axis in axes.items():
        if isinstance(axis, (str, bool, int, float, np.generic)):
            axis = [axis]
        elif not isinstance(axis, (Sequence, np.ndarray, range)) or getattr(axis, "ndim", 1) != 1:
            raise TypeError(f"grid axis {name!r} = {axis!r:.80} must be a 1-D sequence of {_PARAM_TYPES}")
        axis = [_check_param(name, v) for v in axis]
        if not axis:
            raise ValueError(f"grid axis {name!r} is empty; give at least one value")
        tokens = [canonical_token(v) for v in axis]
        if len(set(tokens)) != len(tokens):
            dup = next(v for v, t in zip(axis, tokens) if tokens.count(t) > 1)
            raise ValueError(f"grid axis {name!r} repeats the value {dup!r}: {axis}")
        values.append(axis)
    names = list(axes)
    return [Case(tuple(zip(names, combo))) for combo in itertools.product(*values)]


_RANGE_FORMS = ("'100,150,200' (list), '100:200:50' (start:stop:step, stop included) "
                "or '0.5:1:3n' (3 evenly spaced points from 0.5 to 1)")


def parse_range(text: str) -> list[float]:
    """Parse a CLI value list: ``"100,150,200"``, ``"100:200:50"`` or ``"0.5:1:3n"``.

    ``start:stop:step`` includes ``stop``, which must be a whole number of steps from
    ``start``; ``start:stop:Nn`` is ``numpy.linspace(start, stop, N)``. Generated
    values are rounded to 15 significant digits so ``0.1:0.3:0.1`` gives ``0.3``,
    not ``0.30000000000000004``.

    Raises
    ------
    ValueError
        naming ``text``, what is wrong and the valid forms.
    """
    def fail(why):
        return ValueError(f"range {text!r}: {why}; valid forms: {_RANGE_FORMS}")

    def number(part):
        try:
            x = float(part)
        except ValueError:
            raise fail(f"{part.strip()!r} is not a number") from None
        if not math.isfinite(x):
            raise fail(f"{part.strip()!r} is not finite")
        return x

    if not isinstance(text, str):
        raise TypeError(f"parse_range expects a str, got {type(text).__name__}")
    if not text.strip():
        raise fail("empty")
    if ":" not in text:
        return [number(p) for p in text.split(",")]
    parts = [p.strip() for p in text.split(":")]
    if len(parts) != 3:
        raise fail(f"{len(parts)} ':'-separated fields, expected 3")
    start, stop = number(parts[0]), number(parts[1])
    if parts[2].lower().endswith("n"):
        try:
            n = int(parts[2][:-1])
        except ValueError:
            raise fail(f"point count {parts[2]!r} is not an integer followed by 'n'") from None
        if n < 2:
            raise fail(f"point count {n} must be >= 2 (for one value write just the value)")
        values = np.linspace(start, stop, n)
    else:
        step = number(parts[2])
        if step == 0:
            raise fail("step is 0")
        span = (stop - start) / step
        n = round(span)
        if span < 0:
            raise fail(f"step {step:g} goes away from stop {stop:g}")
        if abs(span - n) > 1e-9 * max(1.0, span):
            raise fail(f"stop {stop:g} is not start {start:g} + a whole number of steps {step:g}")
        values = start + step * np.arange(n + 1)
    if len(values) > 1_000_000:
        raise fail(f"{len(values)} points (more than 1e6)")
    return [float(format(v, ".15g")) for v in values]


def _prepare_out_dir(out_dir) -> Path:
    """Create ``out_dir/cases`` and prove it writable, before any case runs."""
    path = Path(out_dir)
    if path.exists() and not path.is_dir():
        raise ValueError(f"out_dir {str(path)!r} exists and is not a directory")
    try:
        return ensure_writable_dir(path / "cases", "out_dir")
    except OSError as exc:  # the sweep API reports bad input as ValueError
        raise ValueError(f"out_dir {str(path)!r} is not a writable directory: {exc}") from exc


def run_sweep(func, cases, out_dir, *, namespace: str, workers: int | None = None,
              scheduler: str | None = None, progress: bool = True, description: str = "sweep",
              connect_timeout_s: float = 5.0, planner=None) -> "SweepResult":
    """Run ``func`` over ``cases``, reusing cached results and caching new ones.

    Parameters
    ----------
    func : callable
        ``func(params: dict) -> dict`` of outputs: scalars, ``np.ndarray``, or
        ``(dims_tuple, array)`` labelled arrays, plus optional 1-D ``"coord:<dim>"``
        arrays. Must be top-level (picklable) unless ``workers=1``.
    cases : sequence of Case (or of mappings)
        e.g. from :func:`grid`. Repeated cases are computed once.
    out_dir : path
        results go to ``out_dir/cases/<key>.npz`` and ``.json``, written atomically by
        this process as cases complete, so a killed sweep resumes where it stopped.
    namespace : str
        identifies the meaning of ``func`` in the cache key; change it to invalidate.
    workers : int, optional
        local processes (default ``os.cpu_count()``); ``1`` runs inline, for debugging.
        With ``scheduler="local"`` the number of Dask workers; ignored for an address.
    scheduler : str, optional
        ``"tcp://host:port"`` of a running Dask scheduler, or ``"local"`` to start a
        Dask ``LocalCluster`` for this sweep. ``None`` uses local processes.
    progress : bool
        tqdm bar on stderr with ETA and reused/computed/failed counts.
    description : str
        label of the progress bar.
    connect_timeout_s : float
        how long to wait for the Dask scheduler before raising ``ConnectionError``.
    planner : callable, optional
        ``planner(list_of_params)`` is told the uncached cases before an inline run
        (``workers=1``), so that ``func`` can compute them in batches (e.g.
        ``FEACaseRunner.plan``: cases sharing a mesh solved in lockstep blocks). Not
        called when cases run in worker processes, where each case is computed alone.

    Returns
    -------
    SweepResult

    Raises
    ------
    SweepError
        after all other cases finished, if any case raised (failed cases write nothing).
    ValueError, TypeError
        bad arguments or ``out_dir``, before any case runs.
    ConnectionError
        the Dask scheduler is unreachable (only contacted if a case needs computing).
    """
    if not callable(func):
        raise TypeError(f"func must be callable, got {type(func).__name__}")
    if planner is not None and not callable(planner):
        raise TypeError(f"planner must be callable or None, got {type(planner).__name__}")
    if not isinstance(namespace, str) or not namespace:
        raise ValueError(f"namespace={namespace!r} must be a non-empty str, e.g. 'fea-v1'")
    cases = [c if isinstance(c, Case) else Case(c) for c in cases]
    if not cases:
        raise ValueError("cases is empty; nothing to sweep")
    workers = (os.cpu_count() or 1) if workers is None else workers
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ValueError(f"workers={workers!r} must be an int >= 1")
    if scheduler is not None:
        check_scheduler(scheduler)
    elif workers > 1:
        try:
            pickle.dumps(func)
        except Exception as exc:
            raise TypeError(f"func {func!r} cannot be sent to worker processes ({exc}); "
                            "define it at module top level, or pass workers=1 to run inline") from None
    cases_dir = _prepare_out_dir(out_dir)

    keys = [c.key(namespace) for c in cases]
    unique = dict(zip(keys, cases))
    results, todo, misses = {}, [], []
    for key, case in unique.items():
        try:
            results[key], _ = load_case(cases_dir, key, namespace, case.as_dict())
        except FileNotFoundError:
            todo.append(key)
        except CacheMiss as exc:
            misses.append((case, exc))
            todo.append(key)
    # one line per case, but bounded: a cache of an older format can hold thousands of cases
    for case, exc in misses[:_MAX_CASE_WARNINGS]:
        warnings.warn(f"recomputing case {case}: {exc}", CacheWarning, stacklevel=2)
    if len(misses) > _MAX_CASE_WARNINGS:
        warnings.warn(f"recomputing {len(misses) - _MAX_CASE_WARNINGS} more cases whose files in {cases_dir} "
                      "do not verify", CacheWarning, stacklevel=2)
    n_reused, failures = len(results), []

    bar = tqdm(total=len(unique), initial=n_reused, desc=description, unit="case",
               file=sys.stderr, disable=not progress, dynamic_ncols=True)
    bar.set_postfix_str(f"reused {n_reused}, computed 0", refresh=True)
    try:
        if todo:
            jobs = [(k, unique[k].as_dict()) for k in todo]
            if scheduler is not None:
                outcomes = iter_dask(func, jobs, scheduler, workers, connect_timeout_s)
            elif workers == 1:
                if planner is not None:
                    planner([params for _, params in jobs])
                outcomes = iter_inline(func, jobs)
            else:
                outcomes = iter_processes(func, jobs, workers)
            for key, (status, payload, extra) in outcomes:
                if status == "ok":
                    save_case(cases_dir, key, namespace, unique[key].as_dict(), payload, extra)
                    results[key] = payload
                else:
                    failures.append((unique[key], payload, extra))
                bar.update(1)
                bar.set_postfix_str(f"reused {n_reused}, computed {len(results) - n_reused}"
                                    + (f", failed {len(failures)}" if failures else ""), refresh=False)
    finally:
        bar.close()

    result = SweepResult([(c, results[k]) for c, k in zip(cases, keys) if k in results],
                         n_reused=n_reused, n_computed=len(results) - n_reused, namespace=namespace)
    if failures:
        raise SweepError(failures, result, len(unique))
    return result


@dataclass(eq=False)  # outputs hold arrays, so == would be ambiguous
class SweepResult(Sequence):
    """The cases of a sweep and their outputs, in input order.

    Behaves as a list of ``(Case, result_dict)``; ``n_reused`` cases came from the
    cache, ``n_computed`` were computed by this call.
    """

    items: list = field(default_factory=list)
    n_reused: int = 0
    n_computed: int = 0
    namespace: str = ""

    def __len__(self):
        return len(self.items)

    def __getitem__(self, i):
        return self.items[i]

    def to_table(self) -> list[dict]:
        """One flat dict per case: params, then scalar outputs (arrays are left out)."""
        return [{**case.as_dict(), **{k: v for k, v in res.items() if not isinstance(v, (np.ndarray, tuple))}}
                for case, res in self.items]

    def write_csv(self, path) -> None:
        """Write :meth:`to_table` as CSV (atomically); columns in first-seen order."""
        rows = self.to_table()
        columns = list(dict.fromkeys(k for row in rows for k in row))
        buf = io.StringIO()
        writer = csv.DictWriter(buf, fieldnames=columns, lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)
        with atomic_write(Path(path)) as fh:
            fh.write(buf.getvalue())

    def write_netcdf(self, path) -> None:
        """Write :meth:`to_dataset` as netCDF-4, atomically.

        Uses the h5netcdf engine when its h5py backend is installed (h5netcdf >= 1.4
        no longer pulls h5py in), else netCDF4; both write the same netCDF-4 file.
        """
        find = importlib.util.find_spec
        engine = "h5netcdf" if find("h5py") and find("h5netcdf") else "netcdf4"  # h5py alone (XDMF) is not enough
        if engine == "netcdf4" and not importlib.util.find_spec("netCDF4"):
            raise ImportError("write_netcdf needs h5netcdf + h5py or netCDF4: pip install 'h5netcdf[h5py]'")
        ds = self.to_dataset()
        with atomic_path(Path(path)) as tmp:
            ds.to_netcdf(tmp, engine=engine)

    def to_dataset(self):
        """The outputs as an ``xarray.Dataset``.

        If the cases form a full cartesian grid of their params, each param is a
        dimension (coordinates = its values in first-seen order); otherwise there is
        one ``case`` dimension with each param as a coordinate along it. Scalar outputs
        span those dimensions; an array output adds ``<name>_dim0, ...``, a labelled
        ``(dims, array)`` output adds its own dims, with coordinates taken from
        ``"coord:<dim>"`` outputs (which must be equal in every case).
        """
        import xarray as xr

        if not self.items:
            raise ValueError("SweepResult is empty; nothing to convert")
        cases = [c for c, _ in self.items]
        lead_dims, lead_shape, positions, coords = _layout(cases)
        data_vars = {}
        outputs = list(dict.fromkeys(k for _, res in self.items for k in res))
        for name in outputs:
            values = []
            for case, res in self.items:
                if name not in res:
                    raise ValueError(f"output {name!r} is missing in case {case}; to_dataset needs the same outputs in every case")
                values.append(res[name])
            if name.startswith(COORD_PREFIX):
                dim = name[len(COORD_PREFIX):]
                for case, v in zip(cases, values):
                    if not np.array_equal(v, values[0]):
                        raise ValueError(f"coordinate {name!r} differs between cases {cases[0]} and {case}")
                if dim in lead_dims:
                    raise ValueError(f"coordinate {name!r} has the name of a parameter")
                coords[dim] = values[0]
                continue
            dims, stacked = _stack(name, cases, values, lead_dims)
            data = np.empty(lead_shape + stacked.shape[1:], dtype=stacked.dtype)
            data[positions] = stacked
            data_vars[name] = (lead_dims + dims, data)
        return xr.Dataset(data_vars, coords=coords,
                          attrs={"namespace": self.namespace, "cryograting_version": library_version()})


def _layout(cases):
    """Leading dims, their shape, index arrays placing each case, and coordinates."""
    names = [n for n, _ in cases[0].params]
    for case in cases:
        if [n for n, _ in case.params] != names:
            raise ValueError(f"case {case} has params {[n for n, _ in case.params]}, the first case {names}; "
                             "to_dataset needs the same params, in the same order, in every case")
    tokens = [tuple(canonical_token(v) for _, v in c.params) for c in cases]
    axes = [dict() for _ in names]  # per param: token -> (index, first value)
    for case, toks in zip(cases, tokens):
        for ax, tok, (_, v) in zip(axes, toks, case.params):
            ax.setdefault(tok, (len(ax), v))
    if len(set(tokens)) == len(cases) and math.prod(len(ax) for ax in axes) == len(cases):
        # Distinct cases, as many as the product of the axis lengths: a full grid.
        index = np.array([[ax[t][0] for ax, t in zip(axes, toks)] for toks in tokens])
        coords = {n: np.asarray([v for _, v in ax.values()]) for n, ax in zip(names, axes)}
        return tuple(names), tuple(len(ax) for ax in axes), tuple(index.T), coords
    coords = {n: ("case", np.asarray([c.params[i][1] for c in cases])) for i, n in enumerate(names)}
    return ("case",), (len(cases),), (np.arange(len(cases)),), coords


def _stack(name, cases, values, lead_dims):
    """Stack one output over cases; return its own dims and the stacked array."""
    first = values[0]
    kind = "labelled" if isinstance(first, tuple) else "array" if isinstance(first, np.ndarray) else "scalar"
    for case, v in zip(cases, values):
        k = "labelled" if isinstance(v, tuple) else "array" if isinstance(v, np.ndarray) else "scalar"
        if k != kind:
            raise ValueError(f"output {name!r} is a {kind} in case {cases[0]} but a {k} in case {case}")
    if kind == "scalar":
        return (), np.asarray(values)
    if kind == "labelled":
        dims = first[0]
        for case, v in zip(cases, values):
            if v[0] != dims:
                raise ValueError(f"output {name!r} has dims {dims} in case {cases[0]} but {v[0]} in case {case}")
        clash = set(dims) & set(lead_dims)
        if clash:
            raise ValueError(f"output {name!r} uses dims {sorted(clash)} that are parameter names")
        arrays = [v[1] for v in values]
    else:
        arrays = values
        dims = tuple(f"{name}_dim{i}" for i in range(first.ndim))
    for case, a in zip(cases, arrays):
        if a.shape != arrays[0].shape:
            raise ValueError(f"output {name!r} has shape {arrays[0].shape} in case {cases[0]} "
                             f"but {a.shape} in case {case}")
    return dims, np.stack(arrays)
