"""Fixtures shared across test modules, the order in which pytest-xdist hands them out, and
one BLAS thread per test process."""
import os

# One OpenBLAS thread per process (numpy's and scipy's bundled OpenBLAS read this when they
# load, so it must be set before anything imports numpy; pytest loads this file first and the
# xdist workers inherit it). The suite runs two xdist workers on two cores, so a second BLAS
# thread per worker has no core of its own, and OpenBLAS threads spin while they wait: the
# diagnosis fits (an SVD of a tall Jacobian per trust-region step) then spend most of their time
# waiting. Measured with ``pytest -n 0`` on a loaded 2-core machine: the bow-beside-every-single
# diagnosis 365 s -> 44 s, the fast tier of test_diagnosis_bow.py 41 s -> 12 s (CPU time 27 s ->
# 8 s). An OPENBLAS_NUM_THREADS already set by the user is kept.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
# MKL (the PARDISO FEA solver) likewise, but only in xdist workers (xdist names them before it
# loads this file): run alone, its second thread shortens a solve; beside a second worker it
# only adds CPU time. Measured with ``pytest -n 0`` on the FEA blank and layer modules (idle
# 2-core machine): 2 threads 131 s wall, 161 s CPU; 1 thread 143 s wall, 142 s CPU.
if os.environ.get("PYTEST_XDIST_WORKER"):
    os.environ.setdefault("MKL_NUM_THREADS", "1")

import pytest  # noqa: E402

# Modules that share session-scoped work run as one xdist work unit (one worker): the
# paper scorecard solves the Table 1 and 2 cases into ``paper_fea_dir`` and the table and
# mesh-record checks reload them from there instead of solving them again on the other worker.
PAPER_UNIT = "tests/test_paper_claims.py+tests/test_paper_tables.py+tests/test_fea_mesh_convergence.py"
SHARED_SCOPES = {m: PAPER_UNIT for m in PAPER_UNIT.split("+")}
# The work units that hold most of the suite's CPU time (diagnosis campaigns and fits, FEA
# table solves), handed out first and longest first, so that the many short modules fill the
# other worker meanwhile instead of leaving one long module running alone at the end (xdist's
# own order is by number of tests, which puts these few-test modules last). The first two start
# together on the two workers; the others follow by their time on one worker (``pytest
# --durations=0 -n 2``, one BLAS thread: scenarios ~250 s, paper claims, tables and the mesh record ~200 s,
# fea_blank ~120 s, fea_reduced ~90 s, quilt ~90 s, bow ~70 s, surrogate_sweep ~55 s, reduced
# campaign ~50 s with its own two worker processes, psf ~35 s,
# diagnosis and study_dataset ~30 s, fea_layer ~15 s, plating ~10 s). Not strictly by time:
# the reduced campaign's two processes go beside the short modules' single ones, not beside
# a heavy unit's (three fitting processes on two cores slow all three: measured when it was
# 135 s, with bow beside it 890.5 s for the whole suite against 772.6 s with fea_blank).
# Re-rank when a heavy module is added, and time the whole suite.
HEAVY_FIRST = (
    "tests/test_diagnosis_scenarios.py",
    PAPER_UNIT,
    "tests/test_fea_blank.py",
    "tests/test_diagnosis_bow.py",
    "tests/test_fea_reduced.py",
    "tests/test_surrogate_sweep.py",
    "tests/test_diagnosis_quilt.py",
    "tests/test_diagnosis_campaign_reduced.py",
    "tests/test_diagnosis_psf.py",
    "tests/test_fea_layer.py",
    "tests/test_diagnosis.py",
    "tests/test_study_dataset.py",
    "tests/test_diagnosis_plating.py",
    "tests/test_optics_on_fea.py",
)


@pytest.hookimpl(optionalhook=True, tryfirst=True)
def pytest_xdist_make_scheduler(config, log):
    """``--dist loadscope`` with :data:`SHARED_SCOPES` merged and :data:`HEAVY_FIRST` first."""
    if config.getvalue("dist") != "loadscope":
        return None
    from xdist.scheduler import LoadScopeScheduling

    class SharedHeavyFirstScheduling(LoadScopeScheduling):
        def _split_scope(self, nodeid):
            scope = super()._split_scope(nodeid)
            return SHARED_SCOPES.get(scope.split("::", 1)[0], scope)

        def _assign_work_unit(self, node):
            for scope in reversed(HEAVY_FIRST):
                if scope in self.workqueue:
                    self.workqueue.move_to_end(scope, last=False)
            super()._assign_work_unit(node)

    return SharedHeavyFirstScheduling(config, log)


@pytest.fixture(scope="session")
def paper_fea_dir(tmp_path_factory):
    """One directory for the paper's FEA cases (Tables 1 and 2 on the default mesh, and the
    scorecard's extra cases), so the modules that check them solve each case once. Under
    pytest-xdist both modules run on one worker (:data:`SHARED_SCOPES`)."""
    return tmp_path_factory.mktemp("paper")


@pytest.fixture(scope="session")
def nominal_fea_cache(tmp_path_factory):
    """One nominal-map FEA cache (:func:`pipeline.diagnosis.nominal.case_sag_map`) for the
    whole run, shared by the xdist workers: the scenario diagnoses and the reduced campaign
    diagnose against the same default-mesh case, and a second solve of it costs ~35 s of
    CPU. The cache writes each map atomically under a name of its own, so two workers that
    miss it together both solve and either file is the same map."""
    root = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        root = root.parent  # the workers' base directories share this one
    path = root / "nominal-fea-cache"
    path.mkdir(exist_ok=True)
    return path


class CoarseEighth:
    """The eighth model of the default blank on the tests' coarse mesh (5 mm walls, 10 mm
    bulk), built on first use, and its cases at the calibrated stress, each solved once."""

    def __init__(self):
        self._model = None
        self._results: dict = {}

    @property
    def model(self):
        """The :class:`fea.model.PreparedBlank` (mesh and bulk stiffness)."""
        if self._model is None:
            from fea.api import prepare
            from fea.mesh import MeshSpec

            self._model = prepare(mesh=MeshSpec.coarse())
        return self._model

    def solve(self, t0_um: float, polish: float):
        """The :class:`fea.model.FEAResult` of ``fea.api.solve(t0_um, polish)`` (µm, fraction)
        on :attr:`model`; callers share it, so they must not change its arrays."""
        key = (float(t0_um), float(polish))
        if key not in self._results:
            from fea.api import solve

            self._results[key] = solve(t0_um, polish, prepared=self.model)
        return self._results[key]


@pytest.fixture(scope="session")
def coarse_eighth():
    """One :class:`CoarseEighth` per test process: several modules solve the same coarse
    cases (200 µm at 50 % and at 75 % polish), a direct solve costing ~7 s of CPU each.
    The model's solves are direct (a small mesh), so a case gives the same arrays whichever
    module solves it first."""
    return CoarseEighth()


@pytest.fixture(autouse=True, scope="module")
def _return_freed_memory():
    """After each module, collect its garbage and hand the heap it freed back to the system.

    A worker runs many heavy modules in turn and glibc keeps what they freed: measured after
    the paper's scorecard (Tables 1 and 2 on the default mesh), a process held 2.7 GB, of
    which ``malloc_trim`` returned 2.4 GB (a solver factor's MKL memory goes when its factor
    is collected: :class:`fea.linsolve.SPDFactor`). Two workers each holding their largest
    module's peak must fit a small machine: over the whole suite each peaks at 4.8 GB."""
    yield
    import ctypes
    import ctypes.util
    import gc

    gc.collect()
    name = ctypes.util.find_library("c")
    libc = ctypes.CDLL(name) if name else None
    if hasattr(libc, "malloc_trim"):
        libc.malloc_trim(0)
