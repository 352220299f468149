"""The keyed result store and the caches built on it: nothing cached can be silently wrong.

Every fault is made by hand on the files (flipped byte, cut file, two files swapped,
sidecar deleted or taken from another key, an older format) and must lead to a
rebuild with a one-line warning naming the file, and to the numbers of a fresh
computation. The expected numbers are written out here (``y = x**2`` of a fake case
function, a hand-made sag map), never taken from an earlier run of the code.
"""

from __future__ import annotations

import csv
import hashlib
import json
import zipfile
from types import SimpleNamespace

import numpy as np
import pytest

from fea import store
from fea.store import CacheMiss, CacheWarning
from pipeline.sweeps.sweep import grid, run_sweep


# ----------------------------------------------------------------- keys
def test_key_is_sha256_of_namespace_and_canonical_json():
    want = hashlib.sha256(b'ns\n{"a":"s","x":200,"y":0.1}').hexdigest()
    assert store.entry_key("ns", {"y": 0.1, "x": 200.0, "a": "s"}) == want
    assert store.entry_key("ns", {"x": 0.1 + 0.2}) == store.entry_key("ns", {"x": 0.3})  # float noise
    assert store.entry_key("ns", {"x": True}) != store.entry_key("ns", {"x": 1})
    assert store.entry_key("ns", {"x": 1}) != store.entry_key("other", {"x": 1})
    nested = {"cases": [{"t0_um": 200.0, "mesh": None}], "file": "a.png"}
    want = hashlib.sha256(b'ns\n{"cases":[{"mesh":null,"t0_um":200}],"file":"a.png"}').hexdigest()
    assert store.entry_key("ns", nested) == want


def test_bad_params_are_refused_with_their_name():
    with pytest.raises(TypeError, match="unsupported parameter type"):
        store.entry_key("ns", {"x": object()})
    with pytest.raises(ValueError, match="non-finite"):
        store.entry_key("ns", {"x": float("nan")})
    with pytest.raises(ValueError, match="namespace"):
        store.Entry("", {}, "a.npz", "a.json")


# ----------------------------------------------------------------- the store itself
def _two_entries(tmp_path):
    a = store.entry(tmp_path, "ns", {"x": 1.0})
    b = store.entry(tmp_path, "ns", {"x": 2.0})
    store.save_arrays(a, {"v": np.array([1.0, 1.0])}, {"note": "a"})
    store.save_arrays(b, {"v": np.array([2.0, 4.0])}, {"note": "b"})
    return a, b


def _swap(p, q):
    tmp = p.with_suffix(".swap")
    p.rename(tmp)
    q.rename(p)
    tmp.rename(q)


def _corrupt(a, b):
    data = bytearray(a.payload.read_bytes())
    data[len(data) // 2] ^= 0xFF
    a.payload.write_bytes(bytes(data))


def _truncate(a, b):
    a.payload.write_bytes(a.payload.read_bytes()[:-40])


def _swap_payloads(a, b):
    _swap(a.payload, b.payload)


def _drop_sidecar(a, b):
    a.sidecar.unlink()


def _sidecar_of_other_key(a, b):
    a.sidecar.write_bytes(b.sidecar.read_bytes())


def _stale_format(a, b):
    side = json.loads(a.sidecar.read_text())
    side["format"] = a.format_version - 1
    a.sidecar.write_text(json.dumps(side))


def _edited_params(a, b):
    side = json.loads(a.sidecar.read_text())
    side["params"] = {"x": 3.0}
    a.sidecar.write_text(json.dumps(side))


FAULTS = {
    _corrupt: "checksum differs",
    _truncate: "truncated",
    _swap_payloads: "checksum differs",
    _drop_sidecar: "has no sidecar",
    _sidecar_of_other_key: "belongs to key",
    _stale_format: "format version",
    _edited_params: "describes namespace",
}


def test_round_trip_returns_arrays_and_metadata(tmp_path):
    a, _ = _two_entries(tmp_path)
    arrays, side = store.load_arrays(a)
    assert np.array_equal(arrays["v"], [1.0, 1.0]) and side["note"] == "a"
    assert side["key"] == a.key and side["params"] == {"x": 1.0} and side["namespace"] == "ns"
    assert side["sha256"] == hashlib.sha256(a.payload.read_bytes()).hexdigest()
    assert a.payload.name == f"{a.key}.npz" and a.sidecar.name == f"{a.key}.json"
    with pytest.raises(FileNotFoundError):  # nothing stored: a plain miss, no warning
        store.load_arrays(store.entry(tmp_path, "ns", {"x": 5.0}))
    with pytest.raises(ValueError, match="reserved"):
        store.save_arrays(a, {"v": np.zeros(1)}, {"sha256": "x"})


@pytest.mark.parametrize("fault", FAULTS, ids=lambda f: f.__name__.strip("_"))
def test_every_fault_is_a_cache_miss_with_its_reason(tmp_path, fault):
    a, b = _two_entries(tmp_path)
    fault(a, b)
    with pytest.raises(CacheMiss, match=FAULTS[fault]):
        store.load_arrays(a)


def test_a_payload_that_is_not_an_npz_is_a_cache_miss(tmp_path):
    e = store.entry(tmp_path, "ns", {"x": 1})
    store.write_bytes(e, b"not a zip file")  # checksum fine, content unreadable
    with pytest.raises(CacheMiss, match="unreadable"):
        store.load_arrays(e)


def test_a_caller_key_names_the_files_and_is_checked(tmp_path):
    key_a, key_b = "ab" * 32, "cd" * 32  # the same namespace and params under two caller keys
    a = store.entry(tmp_path, "ns", {"x": 1}, prefix="k-", key=key_a, key_chars=20)
    b = store.entry(tmp_path / "b", "ns", {"x": 1}, prefix="k-", key=key_b, key_chars=20)
    assert a.key == key_a and a.payload.name == "k-" + "ab" * 10 + ".npz" and a.sidecar.name == "k-" + "ab" * 10 + ".json"
    store.save_arrays(a, {"v": np.array([1.0])})
    store.save_arrays(b, {"v": np.array([2.0])})
    assert json.loads(a.sidecar.read_text())["key"] == key_a  # the whole key, not the file name's part
    assert store.load_arrays(a)[0]["v"].tolist() == [1.0]
    a.sidecar.write_bytes(b.sidecar.read_bytes())
    with pytest.raises(CacheMiss, match="belongs to key cdcd"):
        store.load_arrays(a)
    with pytest.raises(ValueError, match="key='XY'"):
        store.entry(tmp_path, "ns", {"x": 1}, key="XY")
    with pytest.raises(ValueError, match="key_chars=0"):
        store.entry(tmp_path, "ns", {"x": 1}, key_chars=0)


def _write_same_key_many_times(directory, value, n):
    e = store.entry(directory, "ns", {"x": 1})
    for _ in range(n):
        store.save_arrays(e, {"v": np.full(5000, float(value))}, {"writer": value})


def test_two_processes_writing_one_key_never_give_a_mixed_entry(tmp_path):
    """Each writer's payload and sidecar are whole (atomic renames); a reader between a
    payload of one and the sidecar of the other gets a CacheMiss, never the wrong arrays."""
    import multiprocessing

    ctx = multiprocessing.get_context("fork")
    writers = [ctx.Process(target=_write_same_key_many_times, args=(tmp_path, v, 200)) for v in (1, 2)]
    for w in writers:
        w.start()
    e = store.entry(tmp_path, "ns", {"x": 1})
    loads = misses = 0
    while any(w.is_alive() for w in writers) or loads + misses == 0:
        try:
            arrays, side = store.load_arrays(e)
        except FileNotFoundError:
            continue
        except CacheMiss:
            misses += 1
            continue
        loads += 1
        assert np.all(arrays["v"] == side["writer"])  # the arrays are the ones its sidecar describes
    for w in writers:
        w.join()
        assert w.exitcode == 0
    arrays, side = store.load_arrays(e)
    assert side["writer"] in (1, 2) and np.all(arrays["v"] == side["writer"])
    assert loads > 0 and sorted(p.name for p in tmp_path.iterdir()) == [e.sidecar.name, e.payload.name]


# ----------------------------------------------------------------- sweep cases
def square(params):
    x = params["x"]
    if "log" in params:
        with open(params["log"], "a") as f:
            f.write(f"{x}\n")
    return {"y": x * x, "curve": np.array([x, 2 * x, 3 * x])}


def _calls(log):
    return sorted(float(v) for v in log.read_text().split()) if log.exists() else []


def _files(out, case):
    """The store entry of one sweep case (payload format 2 of :mod:`pipeline.sweeps.cache`)."""
    return store.entry(out / "cases", "t", case.as_dict(), format_version=2)


@pytest.mark.parametrize("fault", FAULTS, ids=lambda f: f.__name__.strip("_"))
def test_a_damaged_case_file_is_recomputed_with_a_warning_and_the_right_numbers(tmp_path, fault):
    log = tmp_path / "calls.log"
    cases = grid(x=[1.0, 2.0, 3.0], log=str(log))
    run_sweep(square, cases, tmp_path / "out", namespace="t", workers=1, progress=False)
    a, b = _files(tmp_path / "out", cases[0]), _files(tmp_path / "out", cases[1])
    fault(a, b)
    log.unlink()
    with pytest.warns(CacheWarning) as record:
        res = run_sweep(square, cases, tmp_path / "out", namespace="t", workers=1, progress=False)
    broken = [1.0, 2.0] if fault is _swap_payloads else [1.0]
    assert _calls(log) == broken and res.n_computed == len(broken)
    assert len(record) == len(broken) and all(FAULTS[fault] in str(w.message) for w in record)
    assert "x=1.0" in str(record[0].message)
    assert [r["y"] for _, r in res] == [1.0, 4.0, 9.0]
    assert [list(r["curve"]) for _, r in res] == [[1, 2, 3], [2, 4, 6], [3, 6, 9]]
    again = run_sweep(square, cases, tmp_path / "out", namespace="t", workers=1, progress=False)
    assert again.n_reused == 3  # the rebuilt files verify


def test_two_swapped_case_files_do_not_exchange_rows_of_the_csv(tmp_path):
    cases = grid(x=[1.0, 2.0, 3.0, 4.0])
    out = tmp_path / "out"
    run_sweep(square, cases, out, namespace="t", workers=1, progress=False)
    _swap(_files(out, cases[1]).payload, _files(out, cases[3]).payload)
    with pytest.warns(CacheWarning) as record:
        res = run_sweep(square, cases, out, namespace="t", workers=1, progress=False)
    assert res.n_computed == 2 and res.n_reused == 2
    assert sorted(str(w.message).split("x=")[1][:3] for w in record) == ["2.0", "4.0"]
    res.write_csv(out / "sweep.csv")
    with open(out / "sweep.csv") as f:
        rows = [(float(r["x"]), float(r["y"])) for r in csv.DictReader(f)]
    assert rows == [(1.0, 1.0), (2.0, 4.0), (3.0, 9.0), (4.0, 16.0)]


# ----------------------------------------------------------------- planner
class Batched:
    """A case function that can be told the cases ahead (the FEA runner's shape)."""

    def __init__(self):
        self.planned = []

    def plan(self, params_list):
        self.planned.append([p["x"] for p in params_list])

    def __call__(self, params):
        return {"y": params["x"] ** 2}


def test_run_sweep_tells_the_planner_the_uncached_cases_only_when_asked(tmp_path):
    f = Batched()
    run_sweep(f, grid(x=[1, 2]), tmp_path, namespace="t", workers=1, progress=False)
    assert f.planned == []  # a .plan method is not probed: the planner is explicit
    res = run_sweep(f, grid(x=[1, 2, 3]), tmp_path, namespace="t", workers=1, progress=False,
                    planner=f.plan)
    assert f.planned == [[3]] and [r["y"] for _, r in res] == [1, 4, 9]
    with pytest.raises(TypeError, match="planner"):
        run_sweep(f, grid(x=[1]), tmp_path, namespace="t", workers=1, planner="plan")


# ----------------------------------------------------------------- diagnosis nominal maps
@pytest.fixture
def fake_fea(monkeypatch):
    """fea.api.prepare(...).solve replaced by a hand-made map, so a cache test costs no FEA."""
    import fea.api
    from optics.sagmap import SagMap

    calls = []
    x, y = np.linspace(-2.0, 2.0, 5), np.linspace(-1.0, 1.0, 3)
    sag = 0.1 * x[None, :] ** 2 + 0.2 * y[:, None]

    def solve(coating, film, load, stress_scale=None):
        calls.append(coating.t0_um)
        return SimpleNamespace(sag=SimpleNamespace(sag_map=lambda spacing_mm: SagMap(x, y, sag * coating.t0_um / 200)))

    monkeypatch.setattr(fea.api, "prepare", lambda *args, **kw: SimpleNamespace(solve=solve))
    return calls, sag


@pytest.mark.parametrize("fault", [_truncate, _corrupt, _swap_payloads, _drop_sidecar, _stale_format])
def test_a_damaged_nominal_map_is_rebuilt_with_a_warning(tmp_path, fake_fea, fault):
    from pipeline.diagnosis.nominal import fea_sag_map

    calls, sag = fake_fea
    first = fea_sag_map(200.0, 0.75, "all", 80.0, "coarse", cache_dir=tmp_path)
    other = fea_sag_map(100.0, 0.75, "all", 80.0, "coarse", cache_dir=tmp_path)
    assert calls == [200.0, 100.0] and np.allclose(other.sag_um, sag / 2)
    assert np.array_equal(fea_sag_map(200.0, 0.75, "all", 80.0, "coarse", cache_dir=tmp_path).sag_um,
                          first.sag_um) and len(calls) == 2  # reused
    (a,) = [p for p in tmp_path.glob("fea-*.npz")
            if json.loads(p.with_suffix(".json").read_text())["params"]["t0_um"] == 200]
    (b,) = set(tmp_path.glob("fea-*.npz")) - {a}
    ea = SimpleNamespace(payload=a, sidecar=a.with_suffix(".json"), format_version=1)
    eb = SimpleNamespace(payload=b, sidecar=b.with_suffix(".json"), format_version=1)
    fault(ea, eb)
    with pytest.warns(CacheWarning, match=f"nominal FEA map .*{a.name}") as record:
        back = fea_sag_map(200.0, 0.75, "all", 80.0, "coarse", cache_dir=tmp_path)
    assert len(record) == 1 and "\n" not in str(record[0].message)
    assert calls[2] == 200.0 and np.allclose(back.sag_um, sag)


# ----------------------------------------------------------------- renders and fields
def test_a_render_png_that_is_not_the_committed_one_is_redone(tmp_path):
    from pipeline.study import render3d

    params = [{"coverage": "all", "t0_um": 200.0, "polish": 0.75}]
    e = render3d._entry(tmp_path, "blank_3d.png", params)
    e.payload.write_bytes(b"\x89PNG fake render")
    store.commit(e, {"exaggeration": 1000.0})
    rebuilt = {}
    assert render3d._is_current(e, rebuilt) and rebuilt == {}
    assert not render3d._is_current(render3d._entry(tmp_path, "blank_3d.png", [{**params[0], "t0_um": 100.0}]),
                                    rebuilt)  # other cases: another key
    e.payload.write_bytes(b"\x89PNG fake rendeR")  # same size, other content
    assert not render3d._is_current(e, rebuilt) and "checksum" in rebuilt["blank_3d.png"]
    e.payload.write_bytes(b"\x89PNG a notice figure written over the render")
    assert not render3d._is_current(e, rebuilt) and "replaced" in rebuilt["blank_3d.png"]


def test_swapped_field_files_are_not_used(tmp_path):
    from pipeline.sweeps.fea_cases import field_path, load_field, save_field

    def result(scale):
        return SimpleNamespace(coords_mm=np.eye(3), displacement_mm=scale * np.ones((3, 3)), uniform_strain=1e-3,
                               info={"symmetry_planes": ["x"]})

    pa, pb = {"t0_um": 200.0}, {"t0_um": 100.0}
    ea, eb = field_path(tmp_path, pa), field_path(tmp_path, pb)
    save_field(ea, result(2.0))
    save_field(eb, result(1.0))
    assert np.allclose(load_field(ea).displacement_mm, 2.0) and load_field(ea).info == {"symmetry_planes": ["x"]}
    _swap(ea.payload, eb.payload)
    with pytest.warns(CacheWarning, match="displacement field .*checksum"):
        assert load_field(ea) is None
    assert load_field(field_path(tmp_path, {"t0_um": 50.0})) is None  # absent: no warning


def test_many_stale_case_files_give_a_bounded_number_of_warnings(tmp_path):
    cases = grid(x=[float(i) for i in range(14)])
    run_sweep(square, cases, tmp_path, namespace="t", workers=1, progress=False)
    for e in tmp_path.glob("cases/*.json"):
        side = json.loads(e.read_text())
        side["format"] = 1  # written by the format before checksums
        e.write_text(json.dumps(side))
    with pytest.warns(CacheWarning) as record:
        res = run_sweep(square, cases, tmp_path, namespace="t", workers=1, progress=False)
    assert res.n_computed == 14 and [r["y"] for _, r in res] == [float(i * i) for i in range(14)]
    assert len(record) == 11 and "4 more cases" in str(record[-1].message)


def test_a_nominal_map_cache_that_cannot_be_written_warns_and_the_map_is_returned(tmp_path, fake_fea):
    from pipeline.diagnosis.nominal import fea_sag_map

    calls, sag = fake_fea
    blocker = tmp_path / "cache"
    blocker.write_text("a file where the cache directory should be")
    with pytest.warns(CacheWarning, match="not cached in"):
        m = fea_sag_map(200.0, 0.75, "all", 80.0, "coarse", cache_dir=blocker)
    assert calls == [200.0] and np.allclose(m.sag_um, sag)


def test_open_checked_checks_the_sidecar_and_the_size_but_not_the_content(tmp_path):
    """For payloads whose format checks its own bytes (an npz: zip CRC-32 per member): the
    sidecar faults and a cut file are misses, a same-size flipped byte is left to the format."""
    a, b = _two_entries(tmp_path)
    fh, side = store.open_checked(a)
    with fh:
        assert fh.read() == a.payload.read_bytes() and side["key"] == a.key
    for fault in (_truncate, _drop_sidecar, _sidecar_of_other_key, _stale_format, _edited_params):
        a, b = _two_entries(tmp_path / fault.__name__)
        fault(a, b)
        with pytest.raises(CacheMiss, match=FAULTS[fault]):
            store.open_checked(a)
    a, b = _two_entries(tmp_path / "corrupt")
    _corrupt(a, b)
    fh, _ = store.open_checked(a)
    with fh, pytest.raises(zipfile.BadZipFile, match="CRC"):
        with np.load(fh, allow_pickle=False) as z:
            [z[k] for k in z.files]
    with pytest.raises(FileNotFoundError):
        store.open_checked(store.entry(tmp_path, "ns", {"x": 5.0}))


# ----------------------------------------------------------------- size budget


def _payload(directory, name, size, mtime):
    """A payload of ``size`` bytes with its sidecar, last used at ``mtime`` (seconds)."""
    import os

    path = directory / name
    path.write_bytes(b"x" * size)
    path.with_suffix(".json").write_text("{}")
    os.utime(path, (mtime, mtime))
    return path


def test_prune_keeps_the_most_recently_used_payloads_within_the_budget(tmp_path):
    old = _payload(tmp_path, "filmops-a.npz", 400, 1_000)
    mid = _payload(tmp_path, "filmops-b.npz", 400, 2_000)
    new = _payload(tmp_path, "filmops-c.npz", 400, 3_000)
    other = _payload(tmp_path, "blank-d.npz", 10_000, 500)  # another cache's: not counted, not deleted
    writing = tmp_path / ".filmops-e.npz.1234abcd.tmp.npz"  # a writer's temporary file
    writing.write_bytes(b"x" * 10_000)
    assert store.prune(tmp_path, "filmops-*.npz", 800) == [old]
    assert not old.exists() and not old.with_suffix(".json").exists()
    assert mid.exists() and new.exists() and other.exists() and writing.exists()
    assert mid.with_suffix(".json").exists()


def test_a_hit_makes_an_entry_recent_and_the_entry_just_written_is_kept(tmp_path):
    import os

    first = _payload(tmp_path, "filmops-a.npz", 400, 1_000)
    second = _payload(tmp_path, "filmops-b.npz", 400, 2_000)
    e = store.Entry("ns", {}, first, first.with_suffix(".json"))
    store.touch(e)  # used now: the newest
    assert first.stat().st_mtime > second.stat().st_mtime
    assert store.prune(tmp_path, "filmops-*.npz", 400) == [second]
    big = _payload(tmp_path, "filmops-c.npz", 5_000, os.stat(first).st_mtime + 10)
    assert store.prune(tmp_path, "filmops-*.npz", 100, keep=(big,)) == [first]
    assert big.exists()


@pytest.mark.parametrize("budget", [-1, 1.5, "1", True])
def test_prune_refuses_a_budget_that_is_not_a_byte_count(tmp_path, budget):
    with pytest.raises(ValueError, match="budget_bytes"):
        store.prune(tmp_path, "filmops-*.npz", budget)
