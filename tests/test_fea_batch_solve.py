"""Lockstep block CG and the shared-factor policy on small SPD systems whose answer a
dense solve gives independently."""
import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from fea.batch_solve import block_pcg, thickness_powers
from fea.linsolve import SharedFactor, available_backends, restricted_sum


class _ExactFactor:
    """The exact inverse of K (a sparse LU) as preconditioner."""

    def __init__(self, K):
        self.lu = splu(sp.csc_matrix(K))

    def solve(self, b):
        return self.lu.solve(np.asarray(b, dtype=float))


def _system(n=60, k=4, seed=0):
    rng = np.random.default_rng(seed)
    K = sp.diags([-1.0, 2.5, -1.0], [-1, 0, 1], shape=(n, n)).tocsr()
    # per-case SPSD perturbations c_j W Wᵀ (the films of different thickness)
    W = rng.standard_normal((n, 3)) / np.sqrt(n)
    c = np.linspace(0.1, 2.0, k)
    F = rng.standard_normal((n, k))
    return K, W, c, F


def test_block_pcg_equals_dense_solves_per_column():
    K, W, c, F = _system()
    E = W @ W.T

    def apply(V, cols):
        return K @ V + (E @ V) * c[cols]

    X, it, res0 = block_pcg(apply, F, _ExactFactor(K), rtol=1e-10, maxiter=100)
    for j in range(F.shape[1]):
        ref = np.linalg.solve(K.toarray() + c[j] * E, F[:, j])
        assert np.abs(X[:, j] - ref).max() <= 1e-8 * np.abs(ref).max()
    # a rank-3 perturbation: CG with the exact inverse of K needs at most 3 (+1) steps
    assert (it <= 4).all() and (it >= 1).all()
    assert (res0 > 1e-10).all()  # the preconditioner alone is not the answer


def test_thickness_powers_and_restricted_sum():
    T = thickness_powers([0.0, 0.2])
    assert T.shape == (4, 2)
    assert (T[:, 0] == 0).all() and T[:, 1] == pytest.approx([0.2, 0.04, 0.008, 0.0016])
    A = np.arange(16.0).reshape(4, 4)
    free = np.array([0, 2, 3])
    op = restricted_sum([lambda v: A @ v, lambda v: 2 * v], free, 4)
    v = np.array([1.0, -1.0, 0.5])
    assert op(v) == pytest.approx((A[np.ix_(free, free)] + 2 * np.eye(3)) @ v)
    assert restricted_sum([], free, 4) is None


@pytest.mark.skipif("pardiso" not in available_backends(), reason="needs pypardiso")
def test_shared_factor_is_reused_then_released_for_a_far_case():
    K, W, c, F = _system(n=200, k=2)
    E = W @ W.T
    shared = SharedFactor(refactor_after_iterations=14)
    infos = []
    for cj in (0.1, 0.2):
        info = {}
        u = shared.solve(K, lambda v: cj * (E @ v), F[:, 0], backend="pardiso", rtol=1e-10, info=info)
        assert np.abs(u - np.linalg.solve(K.toarray() + cj * E, F[:, 0])).max() <= 1e-8
        infos.append(info)
    assert [i["preconditioner"] for i in infos] == ["own", "shared"]
    assert shared.held("pardiso") is not None
    assert shared.held("amg") is None  # another back-end's request releases the kept factor
    strict = SharedFactor(refactor_after_iterations=0)
    strict.solve(K, None, F[:, 0], backend="pardiso", rtol=1e-10)
    strict.solve(K, lambda v: 0.5 * (E @ v), F[:, 0], backend="pardiso", rtol=1e-10)
    assert strict.held("pardiso") is None  # a shared-factor case with > 0 iterations released it


@pytest.mark.skipif("pardiso" not in available_backends(), reason="needs pypardiso")
def test_shared_factor_kept_as_pardiso_serves_a_caller_naming_auto():
    """"auto" resolves to pardiso when it is installed: the same back-end, so the kept factor
    is reused instead of refactorising."""
    K, W, c, F = _system(n=200, k=1)
    shared = SharedFactor(refactor_after_iterations=14)
    shared.solve(K, None, F[:, 0], backend="pardiso", rtol=1e-10)
    assert shared.held("auto") is not None
    info = {}
    shared.solve(K, None, F[:, 0], backend="auto", rtol=1e-10, info=info)
    assert info["preconditioner"] == "shared"


@pytest.mark.skipif("pardiso" not in available_backends(), reason="needs pypardiso")
def test_a_pardiso_factor_is_released_once_whether_freed_or_collected(monkeypatch):
    """MKL keeps a PARDISO factor until it is asked to free it: a model that went out of scope
    holding its factor kept ~1 GB per default-mesh case for the life of the process. A factor
    freed explicitly releases once; one collected unfreed releases when collected."""
    import gc

    import pypardiso

    from fea.linsolve import SPDFactor

    released = []
    original = pypardiso.PyPardisoSolver.free_memory

    def counting(solver, everything=False):
        released.append(everything)
        return original(solver, everything=everything)

    monkeypatch.setattr(pypardiso.PyPardisoSolver, "free_memory", counting)
    K, W, c, F = _system(n=200, k=1)
    freed = SPDFactor(K, "pardiso")
    freed.free()
    del freed
    gc.collect()
    assert released == [True]
    dropped = SPDFactor(K, "pardiso")
    assert np.abs(K @ dropped.solve(F[:, 0]) - F[:, 0]).max() <= 1e-10
    del dropped
    gc.collect()
    assert released == [True, True]
