"""Sweep engine: grids, cache keys, reuse/resume, failures, datasets, Dask."""

from __future__ import annotations

import csv
import json
import os
import signal
import socket
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from pipeline.sweeps.sweep import Case, CacheWarning, SweepError, grid, parse_range, run_sweep

REPO = Path(__file__).resolve().parents[1]


# Case functions live at module top level so worker processes can import them.
def _log_call(params):
    """Append one line per call to ``params["log"]``: the way tests count calls across processes."""
    if "log" in params:
        with open(params["log"], "a") as f:
            f.write(f"{params.get('x')}\n")


def square(params):
    _log_call(params)
    x = params["x"]
    return {"y": x * x, "arr": np.arange(3) * x, "label": f"x{x}"}


def labelled(params):
    x, w = params["x"], params["w"]
    y_mm, x_mm = np.array([-1.0, 1.0]), np.array([0.0, 0.5, 1.0])
    return {"pv_um": x * w, "sag_um": (("y_mm", "x_mm"), x * w + y_mm[:, None] + x_mm[None, :]),
            "coord:y_mm": y_mm, "coord:x_mm": x_mm}


def failing(params):
    _log_call(params)
    if params["x"] == 2:
        raise ValueError(f"bad x={params['x']}")
    return {"y": params["x"]}


def dies(params):
    if params["x"] == 2:
        os._exit(3)  # a segfault or OOM kill, as the pool sees it
    return {"y": params["x"]}


def returns_list(params):
    return {"y": [1, 2]}


def shadows_param(params):
    return {"x": 1.0}


def n_calls(log: Path) -> int:
    return len(log.read_text().splitlines()) if log.exists() else 0


def assert_same_results(a, b):
    assert [c for c, _ in a] == [c for c, _ in b]
    for (_, ra), (_, rb) in zip(a, b):
        assert ra.keys() == rb.keys()
        for k in ra:
            va, vb = ra[k], rb[k]
            if isinstance(va, tuple):
                assert va[0] == vb[0]
                va, vb = va[1], vb[1]
            np.testing.assert_array_equal(va, vb)


# ------------------------------------------------------------------ cases and keys
def test_grid_is_cartesian_with_axis_order_kept():
    cases = grid(T=[80, 300], coating=["gold", "none"], w=[0.5, 1.0, 1.5])
    assert len(cases) == 12
    assert cases[0].params == (("T", 80), ("coating", "gold"), ("w", 0.5))
    assert cases[1].as_dict() == {"T": 80, "coating": "gold", "w": 1.0}
    assert cases[-1].as_dict() == {"T": 300, "coating": "none", "w": 1.5}
    assert grid(T=np.array([1.0, 2.0]), mode="fast")[1].as_dict() == {"T": 2.0, "mode": "fast"}


@pytest.mark.parametrize("axes, match", [
    ({"T": []}, "axis 'T' is empty"),
    ({"T": [1, 1.0]}, "axis 'T' repeats"),
    ({"T": [1, None]}, "parameter 'T' = None"),
    ({"T": [float("nan")]}, "parameter 'T' = nan must be finite"),
    ({"T": {1: 2}}, "axis 'T'"),
    ({}, "at least one axis"),
])
def test_grid_errors_name_the_axis(axes, match):
    with pytest.raises((ValueError, TypeError), match=match):
        grid(**axes)


def test_case_rejects_unsupported_values_naming_the_parameter():
    with pytest.raises(TypeError, match="parameter 'shape' = \\[1, 2\\] has type list"):
        Case((("shape", [1, 2]),))
    with pytest.raises(ValueError, match="repeat"):
        Case((("a", 1), ("a", 2)))


def test_keys_are_canonical():
    k = Case((("w", 0.75), ("T", 200))).key("ns")
    assert Case((("w", float("0.750")), ("T", 200))).key("ns") == k
    assert Case((("T", 200.0), ("w", 0.75))).key("ns") == k  # int == float, order irrelevant
    assert Case({"T": np.int64(200), "w": np.float32(0.75)}).key("ns") == k
    assert Case((("w", 0.1 + 0.2), ("T", 1))).key("ns") == Case((("w", 0.3), ("T", 1))).key("ns")
    assert Case((("w", 0.75), ("T", 200))).key("other") != k
    assert Case((("w", 0.75), ("T", 201))).key("ns") != k
    distinct = {Case((("a", v),)).key("ns") for v in (1, True, "1", 1.5)}
    assert len(distinct) == 4
    assert len(k) == 64 and int(k, 16) >= 0


# ------------------------------------------------------------------ parse_range
@pytest.mark.parametrize("text, expected", [
    ("100,150,200", [100.0, 150.0, 200.0]),
    (" 42 ", [42.0]),
    ("100:200:50", [100.0, 150.0, 200.0]),
    ("200:100:-50", [200.0, 150.0, 100.0]),
    ("0.1:0.3:0.1", [0.1, 0.2, 0.3]),
    ("0.5:1:3n", [0.5, 0.75, 1.0]),
    ("5:5:1", [5.0]),
])
def test_parse_range_forms(text, expected):
    assert parse_range(text) == expected


@pytest.mark.parametrize("text, why", [
    ("", "empty"), ("1,,2", "'' is not a number"), ("a:2:1", "'a' is not a number"),
    ("1:2", "2 ':'-separated fields"), ("1:2:0", "step is 0"), ("100:200:-50", "goes away"),
    ("100:200:30", "whole number of steps"), ("0:1:1n", "point count 1"), ("0:1:xn", "not an integer"),
    ("1,inf", "not finite"),
])
def test_parse_range_errors_name_text_and_forms(text, why):
    with pytest.raises(ValueError) as err:
        parse_range(text)
    msg = str(err.value)
    assert repr(text) in msg and why in msg and "valid forms" in msg and "0.5:1:3n" in msg


# ------------------------------------------------------------------ cache reuse
@pytest.mark.parametrize("workers", [1, 2])
def test_rerun_reuses_without_calling(tmp_path, workers):
    log = tmp_path / "calls.log"
    cases = grid(x=[1, 2, 3, 4], log=str(log))
    first = run_sweep(square, cases, tmp_path / "out", namespace="t", workers=workers, progress=False)
    assert (first.n_computed, first.n_reused, n_calls(log)) == (4, 0, 4)
    assert [r["y"] for _, r in first] == [1, 4, 9, 16] and first[2][1]["label"] == "x3"
    second = run_sweep(square, cases, tmp_path / "out", namespace="t", workers=workers, progress=False)
    assert (second.n_computed, second.n_reused, n_calls(log)) == (0, 4, 4)
    assert_same_results(first, second)
    meta = json.loads((tmp_path / "out" / "cases" / f"{cases[0].key('t')}.json").read_text())
    assert meta["params"] == cases[0].as_dict() and meta["namespace"] == "t" and meta["elapsed_s"] >= 0
    assert "version" in meta
    # A new namespace is a new cache.
    run_sweep(square, cases, tmp_path / "out", namespace="t2", workers=1, progress=False)
    assert n_calls(log) == 8


def test_repeated_cases_computed_once(tmp_path):
    log = tmp_path / "calls.log"
    c = grid(x=[1, 2], log=str(log))
    res = run_sweep(square, [c[0], c[1], c[0]], tmp_path, namespace="t", workers=1, progress=False)
    assert len(res) == 3 and n_calls(log) == 2 and res[2][1]["y"] == 1


def test_corrupt_cache_files_are_recomputed_with_a_warning(tmp_path):
    log = tmp_path / "calls.log"
    cases = grid(x=[1, 2, 3, 4], log=str(log))
    first = run_sweep(square, cases, tmp_path / "out", namespace="t", workers=1, progress=False)
    d = tmp_path / "out" / "cases"
    npz = d / f"{cases[0].key('t')}.npz"
    npz.write_bytes(npz.read_bytes()[: npz.stat().st_size // 2])  # truncated
    (d / f"{cases[1].key('t')}.json").write_text("{")  # unparsable
    (d / f"{cases[2].key('t')}.json").unlink()  # killed between the two writes
    with pytest.warns(CacheWarning) as record:
        again = run_sweep(square, cases, tmp_path / "out", namespace="t", workers=1, progress=False)
    assert len(record) == 3 and "x=1" in str(record[0].message)
    assert (again.n_reused, again.n_computed, n_calls(log)) == (1, 3, 7)
    assert_same_results(first, again)


def test_kill_and_resume_loses_nothing(tmp_path):
    script = tmp_path / "run.py"
    script.write_text(textwrap.dedent(f"""
        import json, sys, time
        sys.path.insert(0, {str(REPO)!r})
        from pipeline.sweeps.sweep import grid, run_sweep

        def slow(params):
            with open(params["log"], "a") as f:
                f.write(f"{{params['x']}}\\n")
            time.sleep(0.3)
            return {{"sq": params["x"] ** 2}}

        if __name__ == "__main__":
            r = run_sweep(slow, grid(x=list(range(12)), log=sys.argv[2]), sys.argv[1],
                          namespace="kill", workers=2, progress=False)
            print(json.dumps({{"reused": r.n_reused, "computed": r.n_computed, "sq": [v["sq"] for _, v in r]}}))
    """))
    out, log = tmp_path / "out", tmp_path / "calls.log"
    cmd = [sys.executable, str(script), str(out), str(log)]
    # Own session, so the kill takes the worker processes too (like a batch-system kill).
    proc = subprocess.Popen(cmd, start_new_session=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    deadline = time.monotonic() + 30
    while len(list(out.glob("cases/*.json"))) < 4:
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline, "sweep made no progress"
        time.sleep(0.02)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.communicate()
    done, calls_before = len(list(out.glob("cases/*.json"))), n_calls(log)
    assert 4 <= done < 12
    rerun = subprocess.run(cmd, capture_output=True, text=True, timeout=60)
    assert rerun.returncode == 0, rerun.stderr
    summary = json.loads(rerun.stdout.splitlines()[-1])
    assert (summary["reused"], summary["computed"]) == (done, 12 - done)
    assert n_calls(log) - calls_before == 12 - done  # finished cases not recomputed
    assert summary["sq"] == [x * x for x in range(12)]


# ------------------------------------------------------------------ failures
@pytest.mark.parametrize("workers", [1, 2])
def test_failing_case_reported_after_the_others_finish(tmp_path, workers):
    log = tmp_path / "calls.log"
    cases = grid(x=[1, 2, 3], log=str(log))
    with pytest.raises(SweepError) as err:
        run_sweep(failing, cases, tmp_path / "out", namespace="t", workers=workers, progress=False)
    assert "1 of 3 cases failed" in str(err.value) and "x=2" in str(err.value)
    assert "ValueError: bad x=2" in str(err.value)
    (case, message, tb), = err.value.failures
    assert case == cases[1] and "raise ValueError" in tb
    assert [c for c, _ in err.value.result] == [cases[0], cases[2]]
    d = tmp_path / "out" / "cases"
    assert not list(d.glob(f"{cases[1].key('t')}*"))
    assert all((d / f"{c.key('t')}.{ext}").exists() for c in (cases[0], cases[2]) for ext in ("npz", "json"))
    with pytest.raises(SweepError) as err:
        run_sweep(failing, cases, tmp_path / "out", namespace="t", workers=1, progress=False)
    assert err.value.result.n_reused == 2 and n_calls(log) == 4


def test_dead_worker_fails_its_cases_not_the_finished_ones(tmp_path):
    cases = grid(x=[1, 2])
    with pytest.raises(SweepError, match="worker process died") as err:
        run_sweep(dies, cases, tmp_path, namespace="t", workers=2, progress=False)
    assert cases[1] in [c for c, _, _ in err.value.failures]
    done = [c for c, _ in err.value.result]
    assert all((tmp_path / "cases" / f"{c.key('t')}.json").exists() for c in done)


@pytest.mark.parametrize("func, match", [(returns_list, "output 'y' has unsupported type list"),
                                         (shadows_param, "output 'x' has the same name as a parameter")])
def test_bad_outputs_are_case_failures(tmp_path, func, match):
    with pytest.raises(SweepError, match=match):
        run_sweep(func, grid(x=[1.0]), tmp_path, namespace="t", workers=1, progress=False)
    assert not list((tmp_path / "cases").iterdir())


# ------------------------------------------------------------------ validation
def test_bad_out_dir_fails_before_any_work(tmp_path):
    log = tmp_path / "calls.log"
    a_file = tmp_path / "file.txt"
    a_file.write_text("x")
    for out in (a_file, a_file / "sub"):
        with pytest.raises(ValueError, match="file.txt"):
            run_sweep(square, grid(x=[1], log=str(log)), out, namespace="t", workers=1)
    assert not log.exists() and a_file.read_text() == "x"


@pytest.mark.skipif(os.name != "posix" or os.geteuid() == 0, reason="root can write anywhere")
def test_read_only_out_dir(tmp_path):
    tmp_path.chmod(0o500)
    try:
        with pytest.raises(ValueError, match="not a writable directory"):
            run_sweep(square, grid(x=[1]), tmp_path / "out", namespace="t", workers=1)
    finally:
        tmp_path.chmod(0o700)


def test_argument_errors(tmp_path):
    cases = grid(x=[1])
    with pytest.raises(ValueError, match="workers=0"):
        run_sweep(square, cases, tmp_path, namespace="t", workers=0)
    with pytest.raises(ValueError, match="namespace"):
        run_sweep(square, cases, tmp_path, namespace="")
    with pytest.raises(ValueError, match="scheduler='localhost:8786'.*tcp://"):
        run_sweep(square, cases, tmp_path, namespace="t", scheduler="localhost:8786")
    with pytest.raises(TypeError, match="workers=1"):
        run_sweep(lambda p: {"y": 1}, cases, tmp_path, namespace="t", workers=2)


def test_progress_bar_shows_reused_and_computed(tmp_path, capsys):
    run_sweep(square, grid(x=[1, 2]), tmp_path, namespace="t", workers=1, description="demo")
    run_sweep(square, grid(x=[1, 2, 3]), tmp_path, namespace="t", workers=1, description="demo")
    err = capsys.readouterr().err
    assert "demo" in err and "reused 0, computed 2" in err and "reused 2, computed 1" in err


# ------------------------------------------------------------------ tables and datasets
def test_dataset_of_full_grid(tmp_path):
    cases = grid(x=[1.0, 2.0, 3.0], w=[0.5, 1.0])
    res = run_sweep(labelled, cases, tmp_path, namespace="t", workers=1, progress=False)
    ds = res.to_dataset()
    assert ds["pv_um"].dims == ("x", "w") and ds["pv_um"].shape == (3, 2)
    np.testing.assert_array_equal(ds["x"], [1.0, 2.0, 3.0])
    np.testing.assert_array_equal(ds["w"], [0.5, 1.0])
    assert ds["pv_um"].sel(x=3.0, w=0.5) == 1.5
    assert ds["sag_um"].dims == ("x", "w", "y_mm", "x_mm")
    np.testing.assert_array_equal(ds["x_mm"], [0.0, 0.5, 1.0])
    assert float(ds["sag_um"].sel(x=2.0, w=1.0, y_mm=1.0, x_mm=0.5)) == 3.5
    sq = run_sweep(square, grid(x=[1, 2], s=["a"]), tmp_path / "sq", namespace="t", workers=1,
                   progress=False).to_dataset()
    assert sq["arr"].dims == ("x", "s", "arr_dim0") and sq["arr"].shape == (2, 1, 3)
    assert list(sq["label"].values.ravel()) == ["x1", "x2"]


def test_dataset_of_non_grid_uses_case_dimension(tmp_path):
    cases = grid(x=[1.0, 2.0], w=[0.5, 1.0])[:3]
    ds = run_sweep(labelled, cases, tmp_path, namespace="t", workers=1, progress=False).to_dataset()
    assert ds["pv_um"].dims == ("case",) and ds["sag_um"].dims == ("case", "y_mm", "x_mm")
    np.testing.assert_array_equal(ds["x"], [1.0, 1.0, 2.0])
    np.testing.assert_array_equal(ds["w"], [0.5, 1.0, 0.5])
    np.testing.assert_array_equal(ds["pv_um"], [0.5, 1.0, 1.0])


def test_csv_and_netcdf(tmp_path):
    res = run_sweep(square, grid(x=[1, 2], s=["a", "b"]), tmp_path, namespace="t", workers=1, progress=False)
    assert res.to_table()[1] == {"x": 1, "s": "b", "y": 1, "label": "x1"}
    res.write_csv(tmp_path / "table.csv")
    with open(tmp_path / "table.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0]) == ["x", "s", "y", "label"]
    assert rows[3] == {"x": "2", "s": "b", "y": "4", "label": "x2"}
    res.write_netcdf(tmp_path / "res.nc")
    with xr.open_dataset(tmp_path / "res.nc") as back:
        xr.testing.assert_identical(back.load(), res.to_dataset())
    assert not list(tmp_path.glob(".*.tmp"))


# ------------------------------------------------------------------ Dask
def test_dask_local_cluster_equals_local_run(tmp_path):
    distributed = pytest.importorskip("distributed")
    cases = grid(x=[1.0, 2.0, 3.0], w=[0.5, 1.0])
    local = run_sweep(labelled, cases, tmp_path / "local", namespace="t", workers=1, progress=False)
    with distributed.LocalCluster(n_workers=2, processes=True, threads_per_worker=1,
                                  dashboard_address=None) as cluster:
        remote = run_sweep(labelled, cases, tmp_path / "dask", namespace="t",
                           scheduler=cluster.scheduler_address, progress=False)
    assert remote.n_computed == 6
    assert_same_results(local, remote)
    names = sorted(p.name for p in (tmp_path / "dask" / "cases").iterdir())
    assert names == sorted(p.name for p in (tmp_path / "local" / "cases").iterdir())
    # scheduler="local" starts (and closes) its own LocalCluster.
    own = run_sweep(labelled, cases, tmp_path / "own", namespace="t", scheduler="local", workers=2,
                    progress=False)
    assert own.n_computed == 6
    assert_same_results(local, own)


def test_unreachable_scheduler_fails_fast_and_clearly(tmp_path):
    pytest.importorskip("distributed")
    with socket.socket() as s:  # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    address = f"tcp://127.0.0.1:{port}"
    log = tmp_path / "calls.log"
    t0 = time.perf_counter()
    with pytest.raises(ConnectionError, match=f"cannot reach Dask scheduler at '{address}' within 1"):
        run_sweep(square, grid(x=[1], log=str(log)), tmp_path / "out", namespace="t",
                  scheduler=address, connect_timeout_s=1, progress=False)
    assert time.perf_counter() - t0 < 5
    assert not log.exists() and not list((tmp_path / "out" / "cases").iterdir())
