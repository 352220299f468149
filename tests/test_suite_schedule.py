"""The xdist schedule of tests/conftest.py: shared modules in one work unit, heavy units first."""
from pathlib import Path
from types import SimpleNamespace

import pytest

import conftest

ROOT = Path(__file__).resolve().parents[1]


def test_scheduled_modules_exist():
    """A renamed module would silently drop out of the shared unit or the heavy-first order."""
    names = set(conftest.SHARED_SCOPES) | {p for unit in conftest.HEAVY_FIRST for p in unit.split("+")}
    assert names and all((ROOT / n).is_file() for n in names), sorted(n for n in names if not (ROOT / n).is_file())


class _Node:
    def __init__(self, name):
        self.name, self.shutting_down, self.sent = name, False, []
        self.gateway = SimpleNamespace(id=name)

    def send_runtest_some(self, indexes):
        self.sent.extend(indexes)

    def shutdown(self):
        self.shutting_down = True


def _config(dist):
    opts = {"dist": dist, "tx": ["2*popen"]}
    return SimpleNamespace(getvalue=opts.get, option=SimpleNamespace(loadscopereorder=True))


def test_loadscope_runs_the_paper_modules_on_one_worker_and_heavy_units_first():
    pytest.importorskip("xdist")
    sched = conftest.pytest_xdist_make_scheduler(_config("loadscope"), None)
    # many short modules (listed first, more tests each) and the two heavy units
    collection = [f"tests/test_short{i}.py::test_{j}" for i in range(4) for j in range(8)]
    collection += ["tests/test_paper_tables.py::test_a", "tests/test_paper_claims.py::test_b[x]",
                   "tests/test_paper_claims.py::test_c", "tests/test_diagnosis_scenarios.py::test_d",
                   "tests/test_diagnosis_scenarios.py::test_e", "tests/test_diagnosis_scenarios.py::test_f"]
    nodes = [_Node("gw0"), _Node("gw1")]
    for n in nodes:
        sched.add_node(n)
    for n in nodes:
        sched.add_node_collection(n, collection)
    sched.schedule()
    first = [{collection[i].split("::")[0] for i in n.sent} for n in nodes]
    assert first[0] == {"tests/test_diagnosis_scenarios.py"}
    assert first[1] == {"tests/test_paper_claims.py", "tests/test_paper_tables.py"}
    assert sorted(i for n in nodes for i in n.sent) == sorted({i for n in nodes for i in n.sent})


def test_other_dist_modes_keep_the_xdist_scheduler():
    assert conftest.pytest_xdist_make_scheduler(_config("load"), None) is None


def _openblas_threads() -> dict:
    """Threads of every OpenBLAS that numpy and scipy bundle, as the loaded library reports
    them (file name -> count); empty when the wheels bundle none (another BLAS)."""
    import ctypes
    import glob
    import os

    import numpy
    import scipy
    import scipy.linalg  # noqa: F401  (loads scipy's own OpenBLAS)

    out = {}
    for pkg in (numpy, scipy):
        for lib in glob.glob(os.path.join(os.path.dirname(pkg.__file__), os.pardir, f"{pkg.__name__}.libs",
                                          "libscipy_openblas*.so*")):
            h = ctypes.CDLL(lib)  # the already loaded library (same file): no second copy
            for name in ("scipy_openblas_get_num_threads64_", "scipy_openblas_get_num_threads"):
                if hasattr(h, name):
                    out[os.path.basename(lib)] = getattr(h, name)()
                    break
    return out


def test_blas_runs_one_thread_per_test_process():
    """conftest sets OPENBLAS_NUM_THREADS=1 before numpy loads (two xdist workers on two cores:
    a second spinning BLAS thread per worker made the diagnosis fits several times slower)."""
    import os

    if os.environ.get("OPENBLAS_NUM_THREADS") != "1":
        pytest.skip(f"OPENBLAS_NUM_THREADS={os.environ.get('OPENBLAS_NUM_THREADS')!r} set by the user")
    threads = _openblas_threads()
    if not threads:
        pytest.skip("numpy and scipy bundle no OpenBLAS here")
    assert set(threads.values()) == {1}, threads
