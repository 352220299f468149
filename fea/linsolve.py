"""Sparse symmetric positive-definite solves with a residual check.

Two back-ends:

* ``pardiso`` — MKL PARDISO through pypardiso, real SPD (mtype 2) on the upper
  triangle: a sparse Cholesky, the fastest option on 2 cores (optional dependency
  ``cryograting[fast]``).
* ``amg`` — conjugate gradients preconditioned by pyamg smoothed aggregation with the
  six rigid-body modes as near-null space; pure Python wheels, works everywhere.

``auto`` picks pardiso when it imports. Every solve checks the relative residual and
raises :class:`SolverError` when it is not met: a result is never returned silently.

A sequence of neighbouring systems (coating cases of one mesh) shares one factor as CG
preconditioner (:class:`SharedFactor`); blocks of cases are solved in lockstep in
:mod:`fea.batch_solve`.
"""

from __future__ import annotations

import os
import weakref

import numpy as np
import scipy.sparse as sp

__all__ = ["SPDFactor", "SharedFactor", "SolverError", "available_backends", "resolve_backend", "restricted_sum",
           "rigid_modes", "solve_spd", "solve_spd_perturbed"]


class SolverError(RuntimeError):
    """The linear solve failed or did not reach the requested residual."""


def _have_pardiso() -> bool:
    try:
        import pypardiso  # noqa: F401
    except Exception:  # pragma: no cover - import failure modes vary by platform
        return False
    return True


def available_backends() -> list[str]:
    return (["pardiso"] if _have_pardiso() else []) + ["amg"]


def rigid_modes(coords_mm: np.ndarray) -> np.ndarray:
    """Six rigid-body modes on the DOF layout 3*d + i.

    Parameters
    ----------
    coords_mm : ndarray, shape (3, N)
        Node positions (mm); centre them first for well-conditioned rotations.

    Returns
    -------
    ndarray, shape (3N, 6)
        Translations x, y, z, then the rotations about z, x and y (mm per radian).
    """
    x, y, z = coords_mm
    N = x.size
    B = np.zeros((3 * N, 6))
    B[0::3, 0] = 1
    B[1::3, 1] = 1
    B[2::3, 2] = 1
    B[0::3, 3], B[1::3, 3] = -y, x
    B[1::3, 4], B[2::3, 4] = -z, y
    B[0::3, 5], B[2::3, 5] = z, -x
    return B


def solve_spd(K: sp.spmatrix, f: np.ndarray, backend: str = "auto", rtol: float = 1e-9,
              coords_mm: np.ndarray | None = None, free: np.ndarray | None = None) -> np.ndarray:
    """Solve K u = f for a symmetric positive-definite K (see :func:`solve_spd_perturbed`).

    Parameters
    ----------
    K : sparse matrix, shape (n, n)
        Condensed (constraints already removed) stiffness.
    f : ndarray, shape (n,)
        Load vector.
    backend : {"auto", "pardiso", "amg"}
    rtol : float
        Required relative residual ||K u − f|| / ||f||.
    coords_mm, free : ndarray, optional
        Node coordinates (3, N) and the free-DOF index, used to build the rigid-body
        near-null space for the ``amg`` back-end.

    Raises
    ------
    SolverError
        When the back-end fails or the residual exceeds ``rtol``.
    """
    return solve_spd_perturbed(K, None, f, backend=backend, rtol=rtol, coords_mm=coords_mm, free=free)


def resolve_backend(backend: str) -> str:
    """The back-end ``"pardiso"`` or ``"amg"`` that ``backend`` names ("auto": pardiso if installed).

    Raises
    ------
    ValueError
        For an unknown name.
    SolverError
        When pardiso is requested but pypardiso does not import.
    """
    if backend not in ("auto", "pardiso", "amg"):
        raise ValueError(f"backend={backend!r} is unknown; valid values are ['auto', 'pardiso', 'amg']")
    if backend == "auto":
        backend = "pardiso" if _have_pardiso() else "amg"
    if backend == "pardiso" and not _have_pardiso():
        raise SolverError("backend='pardiso' requested but pypardiso is not installed "
                          "(pip install 'cryograting[fast]')")
    return backend


def _set_pardiso_options(solver) -> None:
    """Explicit PARDISO options for an SPD factor used as solver and CG preconditioner.

    pypardiso leaves ``iparm(1) = 0`` ("use MKL's defaults"), which silently ignores every
    other iparm and, measured at 216 k P2 DOFs, makes each forward/backward substitution
    3-4x slower than with the options below (0.56 s vs 0.13-0.24 s per right-hand side on
    this 2-core machine; 16 right-hand sides 2.9 s vs 0.6 s). The solves keep a relative
    residual ~1e-11 (checked by the callers). Indices are PARDISO's 1-based ones.
    """
    solver.set_iparm(1, 1)    # use the values below instead of MKL's defaults
    solver.set_iparm(2, 2)    # nested-dissection (METIS) fill-in reducing ordering
    solver.set_iparm(10, 8)   # pivot perturbation 1e-8 (MKL's default for SPD)
    solver.set_iparm(18, -1)  # report the factor's non-zeros (diagnostics)
    solver.set_iparm(24, 1)   # two-level parallel factorisation (10, the improved variant, segfaults in this MKL)
    # iparm 8 = 0: no iterative refinement; a CG preconditioner does not need it and
    # direct solves check their own residual.


class SPDFactor:
    """A reusable preconditioner/solver for one sparse SPD matrix.

    PARDISO: sparse Cholesky of the upper triangle. AMG: a smoothed-aggregation
    V-cycle (an approximate inverse, only useful as a preconditioner).
    Call :meth:`free` to release the factor's memory (~0.7 GB at 216 k P2 DOFs); a factor
    collected unfreed releases it then.
    """

    def __init__(self, K: sp.csr_matrix, backend: str = "auto", coords_mm=None, free=None):
        backend = resolve_backend(backend)
        self.backend = backend
        self.shape = K.shape
        if backend == "pardiso":
            import pypardiso

            self._solver = pypardiso.PyPardisoSolver(mtype=2)
            # pypardiso finds MKL by a recursive glob of sys.prefix on *every* solver it
            # creates (~0.4 s each); its own environment variable skips that next time
            name = getattr(getattr(self._solver, "libmkl", None), "_name", None)
            if name and "PYPARDISO_MKL_RT" not in os.environ:
                os.environ["PYPARDISO_MKL_RT"] = name
            _set_pardiso_options(self._solver)
            self._K = sp.triu(K, format="csr")
            self._K.sort_indices()
            # PARDISO's factor lives in MKL's memory under the solver's handle and pypardiso
            # frees it only when asked: a factor dropped unfreed (a model kept a factor and
            # went out of scope) stayed for the life of the process, ~1 GB per default-mesh case
            self._release = weakref.finalize(self, self._solver.free_memory, True)
            try:
                self._solver.factorize(self._K)
            except Exception as exc:
                raise SolverError(f"PARDISO factorisation failed: {exc}") from exc
        else:
            import pyamg

            B = None
            if coords_mm is not None:
                B = rigid_modes(coords_mm)
                if free is not None:
                    B = B[free]
            self._ml = pyamg.smoothed_aggregation_solver(K, B=B, max_coarse=500)
            self._M = self._ml.aspreconditioner(cycle="V")

    def solve(self, b: np.ndarray) -> np.ndarray:
        b = np.asarray(b, dtype=float)
        if self.backend == "pardiso":
            return self._solver.solve(self._K, b)
        return self._M @ b

    def free(self) -> None:
        """Release the factor's memory now (it is also released when the factor is collected)."""
        if self.backend == "pardiso" and self._solver is not None:
            self._release()
            self._solver = None


def solve_spd_perturbed(K: sp.spmatrix, apply_extra, f: np.ndarray, backend: str = "auto",
                        rtol: float = 1e-9, maxiter: int = 200, coords_mm=None, free=None,
                        info: dict | None = None, factor: SPDFactor | None = None,
                        x0: np.ndarray | None = None) -> np.ndarray:
    """Solve (K + E) u = f where K is sparse SPD and E (SPSD) is only available as a product.

    Conjugate gradients on the full operator, preconditioned by a factorisation of K
    (PARDISO) or an AMG hierarchy of K. Used for the film offset couplings, whose
    explicit matrices would be ~5x denser than the bulk stiffness.

    Parameters
    ----------
    K : sparse matrix, shape (n, n)
    apply_extra : callable or None
        v ↦ E v for the remaining symmetric positive semi-definite part.
    f : ndarray, shape (n,)
    rtol : float
        Required relative residual of the full system.
    info : dict, optional
        Filled with ``iterations`` and ``residual``.
    factor : SPDFactor, optional
        Preconditioner to use instead of factorising ``K`` (e.g. the factor of a
        neighbouring case, shared across a sweep); the caller keeps and frees it.
    x0 : ndarray, optional
        Initial guess (e.g. a reduced-basis solution); default: the preconditioner
        applied to ``f``.

    Raises
    ------
    SolverError
        When CG does not reach ``rtol`` within ``maxiter`` iterations.
    """
    from scipy.sparse.linalg import LinearOperator, cg

    backend = factor.backend if factor is not None else resolve_backend(backend)
    K = sp.csr_matrix(K)
    fnorm = np.linalg.norm(f)
    if fnorm == 0:
        return np.zeros_like(f, dtype=float)
    n = K.shape[0]

    def matvec(v):
        v = np.ravel(v)
        out = K @ v
        if apply_extra is not None:
            out = out + apply_extra(v)
        return out

    A = LinearOperator((n, n), matvec=matvec, dtype=float)
    own = factor is None
    fac = SPDFactor(K, backend, coords_mm, free) if own else factor
    if fac.shape != K.shape:
        raise ValueError(f"factor of shape {fac.shape} does not match the system {K.shape}")
    try:
        M = LinearOperator((n, n), matvec=lambda b: fac.solve(np.ravel(b)), dtype=float)
        it = [0]
        if x0 is None and backend == "pardiso":
            x0 = fac.solve(f)
        res0 = 1.0 if x0 is None else float(np.linalg.norm(matvec(x0) - f) / fnorm)
        count = lambda xk: it.__setitem__(0, it[0] + 1)  # noqa: E731
        # CG's recursive residual drifts a little from the true one: stop at half the
        # target, and continue (rarely needed) when the true residual misses it
        u, code = cg(A, f, x0=x0, rtol=0.5 * rtol, maxiter=maxiter, M=M, callback=count)
        res = np.linalg.norm(matvec(u) - f) / fnorm
        if code == 0 and res > rtol:
            u, code = cg(A, f, x0=u, rtol=0.1 * rtol, maxiter=maxiter, M=M, callback=count)
            res = np.linalg.norm(matvec(u) - f) / fnorm
    finally:
        if own:
            fac.free()
    if info is not None:
        info.update(iterations=it[0], residual=float(res), initial_residual=res0, backend=backend)
    if code != 0 or not np.isfinite(res) or res > rtol:
        raise SolverError(f"preconditioned CG ({backend}) did not converge: residual {res:.3e} "
                          f"after {it[0]} iterations (rtol={rtol:.1e}, {n} unknowns)")
    return u


def restricted_sum(operators, free: np.ndarray, n: int):
    """v ↦ Σ_k A_k v on the free DOFs, for full-size operators given only as products.

    Parameters
    ----------
    operators : sequence of callable
        Each maps a full vector (n,) to A_k v (n,).
    free : ndarray of int
        Free DOF numbers; the constrained DOFs of v are zero.
    n : int
        Full number of DOFs.

    Returns
    -------
    callable or None
        (len(free),) → (len(free),); None when there are no operators.
    """
    if not operators:
        return None

    def apply(v_free):
        v = np.zeros(n)
        v[free] = v_free
        return sum(op(v) for op in operators)[free]

    return apply


class SharedFactor:
    """One SPD factorisation shared by a sequence of neighbouring systems as CG preconditioner.

    The coating cases of one mesh differ only in film thickness, so the factor of one
    case preconditions the next ones well and a case costs a few CG iterations instead
    of a factorisation. A case far from the factored one (more than
    ``refactor_after_iterations`` iterations) releases the factor, so the next case
    factorises its own matrix.

    Parameters
    ----------
    refactor_after_iterations : int
        Iterations beyond which a case that used the shared factor releases it.
    """

    def __init__(self, refactor_after_iterations: int = 14):
        self.refactor_after_iterations = refactor_after_iterations
        self._factor: SPDFactor | None = None
        self._backend: str | None = None

    def held(self, backend: str) -> SPDFactor | None:
        """The factor kept for ``backend``, or None; a factor kept for another back-end is
        released. Names are compared resolved (``"auto"`` is the back-end it picks), so a
        caller naming ``"auto"`` reuses a factor kept as ``"pardiso"``."""
        if self._factor is not None and self._backend != resolve_backend(backend):
            self.release()
        return self._factor

    def factorise(self, K: sp.spmatrix, backend: str, coords_mm=None, free=None) -> SPDFactor:
        """Factorise ``K`` and keep the factor for the following systems (see :class:`SPDFactor`)."""
        self.release()
        self._factor, self._backend = SPDFactor(K, backend, coords_mm, free), resolve_backend(backend)
        return self._factor

    def release(self) -> None:
        """Free the kept factor (~0.7 GB at 216 k P2 DOFs)."""
        if self._factor is not None:
            self._factor.free()
            self._factor = self._backend = None

    def solve(self, K: sp.spmatrix, apply_extra, f: np.ndarray, backend: str = "auto", rtol: float = 1e-9,
              coords_mm=None, free=None, info: dict | None = None, x0: np.ndarray | None = None) -> np.ndarray:
        """:func:`solve_spd_perturbed` preconditioned by the kept factor (factorising ``K``
        when none is kept); ``info`` also gets ``preconditioner`` ("own" or "shared")."""
        info = {} if info is None else info
        factor = self.held(backend)
        fresh = factor is None
        if fresh:
            factor = self.factorise(K, backend, coords_mm, free)
        u = solve_spd_perturbed(K, apply_extra, f, backend=backend, coords_mm=coords_mm, free=free,
                                info=info, rtol=rtol, factor=factor, x0=x0)
        info.update(preconditioner="own" if fresh else "shared")
        if not fresh and info.get("iterations", 0) > self.refactor_after_iterations:
            self.release()  # this case is far from the factored one: the next one refactors
        return u
