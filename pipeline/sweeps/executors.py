"""Where sweep cases run: inline, in local processes, or on a Dask cluster.

Each executor is a generator ``iter_*(func, jobs, ...)`` over ``jobs = [(key, params),
...]`` that yields ``(key, outcome)`` in completion order, where ``outcome`` is what
:func:`run_case` returns. The caller (the parent process) writes results as they
arrive, so a killed run keeps every case that completed. Exceptions raised by the case
function never escape an executor; they come back as ``("error", ...)`` outcomes.
"""

from __future__ import annotations

import multiprocessing
import os
import threading
import time
import traceback
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool

from pipeline.sweeps.cache import normalise_result

__all__ = ["run_case", "iter_inline", "iter_processes", "iter_dask", "check_scheduler"]


def run_case(func, params: dict) -> tuple:
    """Run ``func(params)`` and validate its output; never raises an ``Exception``.

    Returns
    -------
    tuple
        ``("ok", result, elapsed_s)`` or ``("error", "Type: message", traceback_text)``.
        Errors travel as text because arbitrary exception objects may not unpickle in
        the parent.
    """
    t0 = time.perf_counter()
    try:
        result = normalise_result(func(dict(params)), tuple(params))
    except Exception as exc:
        return ("error", f"{type(exc).__name__}: {exc}", traceback.format_exc())
    return ("ok", result, time.perf_counter() - t0)


def iter_inline(func, jobs) -> Iterator[tuple[str, tuple]]:
    """Run the jobs one after the other in this process (``workers=1``; debuggable)."""
    for key, params in jobs:
        yield key, run_case(func, params)


def _exit_with_parent(parent_pid: int) -> None:
    """Worker initializer: exit when the parent dies.

    A ``ProcessPoolExecutor`` worker outlives a SIGKILLed parent and would go on
    taking queued cases whose results nobody writes; this thread ends it instead.
    """

    def watch():
        while True:
            time.sleep(0.5)
            if os.getppid() != parent_pid:
                os._exit(1)

    threading.Thread(target=watch, daemon=True, name="exit-with-parent").start()


def iter_processes(func, jobs, workers: int) -> Iterator[tuple[str, tuple]]:
    """Run the jobs on ``workers`` local processes (``concurrent.futures``).

    Processes are started with ``spawn``: forking a parent that holds threads (tqdm's
    monitor, BLAS pools, a Dask client) can deadlock the child, and spawn also keeps a
    gmsh/OpenMP state of the parent out of the workers. The price is one interpreter
    start and the imports of ``func``'s module per worker, once per sweep.
    """
    pool = ProcessPoolExecutor(
        max_workers=min(workers, len(jobs)),
        mp_context=multiprocessing.get_context("spawn"),
        initializer=_exit_with_parent,
        initargs=(os.getpid(),),
    )
    finished = False
    try:
        futures = {pool.submit(run_case, func, params): key for key, params in jobs}
        for fut in as_completed(futures):
            try:
                outcome = fut.result()
            except BrokenProcessPool as exc:
                # A worker died (segfault, OOM kill, os._exit): its case and all pending ones fail.
                outcome = ("error", f"worker process died: {exc}", "")
            except Exception as exc:  # e.g. the result could not be pickled back
                outcome = ("error", f"{type(exc).__name__}: {exc}", traceback.format_exc())
            yield futures[fut], outcome
        finished = True
    finally:
        # On an interrupt, drop the queued cases and don't wait for running ones.
        pool.shutdown(wait=finished, cancel_futures=True)


def check_scheduler(scheduler: str) -> str:
    """Validate a ``scheduler`` argument: ``"local"`` or a Dask address like ``tcp://host:port``."""
    valid = "'local' or a Dask scheduler address such as 'tcp://10.0.0.5:8786' (also tls://, ws://, inproc://)"
    if not isinstance(scheduler, str):
        raise TypeError(f"scheduler={scheduler!r} must be a str: {valid}")
    if scheduler == "local":
        return scheduler
    proto, sep, rest = scheduler.partition("://")
    if not sep or proto not in {"tcp", "tls", "ws", "wss", "inproc", "ucx"} or not rest:
        raise ValueError(f"scheduler={scheduler!r} is not valid; use {valid}")
    return scheduler


def iter_dask(func, jobs, scheduler: str, workers: int, connect_timeout_s: float) -> Iterator[tuple[str, tuple]]:
    """Run the jobs on a Dask cluster.

    ``scheduler`` is an address of a running scheduler (``workers`` is then ignored:
    the cluster decides), or ``"local"`` to start a ``LocalCluster`` of ``workers``
    single-threaded processes for the duration of the sweep. ``func`` and its module
    must be importable on the workers.

    Raises
    ------
    ConnectionError
        the scheduler did not answer within ``connect_timeout_s`` seconds.
    ImportError
        ``distributed`` is not installed.
    """
    try:
        from distributed import Client, LocalCluster, as_completed
    except ImportError as exc:
        raise ImportError(f"scheduler={scheduler!r} needs Dask: pip install 'dask[distributed]'") from exc

    cluster = None
    if scheduler == "local":
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None)
        address = cluster.scheduler_address
    else:
        address = scheduler
    try:
        try:
            client = Client(address, timeout=connect_timeout_s)
        except (OSError, TimeoutError) as exc:
            raise ConnectionError(
                f"cannot reach Dask scheduler at {address!r} within {connect_timeout_s} s ({exc}); "
                "start one (`dask scheduler` + `dask worker <address>`) or give no scheduler to run in local processes"
            ) from exc
        finished = False
        futures = {}
        try:
            for key, params in jobs:
                futures[client.submit(run_case, func, params, pure=False)] = key
            for fut in as_completed(list(futures)):
                try:
                    outcome = fut.result()
                except Exception as exc:  # KilledWorker, CancelledError, lost connection
                    outcome = ("error", f"{type(exc).__name__}: {exc}", traceback.format_exc())
                yield futures[fut], outcome
            finished = True
        finally:
            if not finished:
                client.cancel(list(futures))
            client.close()
    finally:
        if cluster is not None:
            cluster.close()
