"""Reduced-basis model of the plated blank: exact thickness polynomials, Galerkin projection.

Units: mm for film thickness and displacement (as in :mod:`fea.model`), MPa.

With the mesh fixed, the system of one coating is

    K(t) u = ε_m f(t),   K(t) = K_b + Σ_g Σ_{k=1..4} t_g^k K_{g,k},   f(t) = Σ_g Σ_k t_g^k f_{g,k}

where g runs over the plated surface groups (front/back faces, hole walls, side
faces), t_g is the group's film thickness and ε_m the mismatch strain: the film's
through-thickness integrals are exact polynomials of degree ≤ 4 in t
(:class:`fea.assembly.FilmOperators`). The coefficients are not written out here: the
stiffness ones come from :meth:`fea.assembly.FilmOperators.apply_power_terms` (tested
against ``local_stiffness`` + ``apply_coupling``), the load ones from evaluating
``load`` at four thicknesses and inverting the exact Vandermonde system.

A :class:`ReducedBasis` keeps an orthonormal basis Q of displacement fields and the
projected pieces QᵀK_bQ, QᵀK_{g,k}Q, Qᵀf_{g,k}; the Galerkin solution for any
thicknesses and mismatch strain then costs a few dense m × m operations
(m ≈ 10–40). It serves two purposes: the initial guess that makes the iterative
full solve of a sweep's next case cheap (:meth:`fea.model.PreparedBlank.solve`),
and the millisecond surrogate of :mod:`fea.surrogate`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .assembly import FilmOperators

__all__ = ["FilmPolynomial", "ReducedBasis"]

#: thickness scale of the polynomial coefficients (mm): keeps the Vandermonde system
#: well conditioned for films of 10–500 µm
T_REF_MM = 0.1
_NODES = np.array([0.5, 1.0, 1.5, 2.0])  # interpolation nodes in units of T_REF_MM
_VINV = np.linalg.inv(_NODES[:, None] ** np.arange(1, 5)[None, :])  # coefficients from samples


@dataclass
class FilmPolynomial:
    """The thickness polynomial of one surface group's film.

    Attributes
    ----------
    ops : FilmOperators
        The group's thickness-independent operators.
    offset : bool
        Film integrated through its thickness (True) or a surface membrane.
    """

    ops: FilmOperators
    offset: bool = True

    def __post_init__(self):
        # load per unit mismatch strain, coefficients of (t/T_REF)^k, k = 1..4
        samples = np.array([self.ops.load(s * T_REF_MM, 1.0, self.offset) for s in _NODES])
        self.load_coeffs = _VINV @ samples

    def stiffness_coeffs_apply(self, V: np.ndarray) -> np.ndarray:
        """K_{g,k} V for k = 1..4 (coefficients of (t/T_REF)^k), shape (4, *V.shape)."""
        terms = self.ops.apply_power_terms(V, self.offset)
        scale = T_REF_MM ** np.arange(1, 5)
        return terms * scale.reshape((4,) + (1,) * (terms.ndim - 1))


def powers(t_mm: float) -> np.ndarray:
    """(t/T_REF)^k for k = 1..4."""
    return (t_mm / T_REF_MM) ** np.arange(1, 5)


class ReducedBasis:
    """Galerkin reduced model on a growing orthonormal basis of displacement fields.

    Parameters
    ----------
    K_bulk : sparse matrix, shape (n, n)
        Coating-independent bulk stiffness (full DOF layout).
    films : dict
        Surface group → :class:`FilmPolynomial`.
    free : ndarray of int
        Free DOFs; basis vectors vanish on the others.
    max_size : int
        Basis vectors kept; beyond it, new vectors are not added (the basis of a
        sweep saturates long before).
    sketch_size : int
        Rows of the random sketch used to estimate residual norms without a full
        product (0: no sketch).
    seed : int
        Seed of the sketch.

    Notes
    -----
    The residual estimate uses a CountSketch Θ (each free DOF hashed to one of
    ``sketch_size`` rows with a random sign): ||Θ r|| equals ||r|| in expectation with
    a relative spread of about sqrt(2 / sketch_size) (9 % at 256), enough to rank
    candidate points in a greedy construction. The sketched pieces ΘK_bQ, ΘK_{g,k}Q,
    Θf_{g,k} are kept, so an estimate costs O(sketch_size · m).
    """

    def __init__(self, K_bulk: sp.spmatrix, films: dict[str, FilmPolynomial], free: np.ndarray,
                 max_size: int = 60, sketch_size: int = 256, seed: int = 0):
        self.K_bulk = sp.csr_matrix(K_bulk)
        self.films = dict(films)
        self.free = np.asarray(free)
        self.n = self.K_bulk.shape[0]
        self.max_size = max_size
        self._mask = np.zeros(self.n, bool)
        self._mask[self.free] = True
        self.Q = np.zeros((self.n, 0))
        self.Kb = np.zeros((0, 0))
        self.Kg = {g: np.zeros((4, 0, 0)) for g in self.films}
        self.fg = {g: np.zeros((4, 0)) for g in self.films}
        self.sketch = None
        if sketch_size:
            rng = np.random.default_rng(seed)
            sign = rng.choice([-1.0, 1.0], self.n) * self._mask
            self.sketch = sp.csr_matrix((sign, (rng.integers(0, sketch_size, self.n), np.arange(self.n))),
                                        shape=(sketch_size, self.n))
            self.sKb = np.zeros((sketch_size, 0))
            self.sKg = {g: np.zeros((4, sketch_size, 0)) for g in self.films}
            self.sfg = {g: self.sketch @ poly.load_coeffs.T for g, poly in self.films.items()}  # (k, 4)

    @property
    def size(self) -> int:
        return self.Q.shape[1]

    def add(self, vectors: np.ndarray, tol: float = 1e-8) -> int:
        """Orthonormalise ``vectors`` (n,) or (n, k) against the basis and add them.

        Returns the number of vectors added (those already in the span to ``tol``
        relative, or beyond ``max_size``, are skipped).
        """
        V = np.array(vectors, dtype=float, ndmin=2)
        if V.shape[0] != self.n:
            V = V.T
        V = V * self._mask[:, None]
        new = []
        for v in V.T:
            nv = np.linalg.norm(v)
            if nv == 0 or self.size + len(new) >= self.max_size:
                continue
            basis = np.column_stack([self.Q] + new) if new else self.Q
            for _ in range(2):  # twice is enough (Kahan–Parlett)
                v = v - basis @ (basis.T @ v)
            if np.linalg.norm(v) > tol * nv:
                new.append(v / np.linalg.norm(v))
        if not new:
            return 0
        N = np.column_stack(new)
        m0 = self.size
        Qn = np.column_stack([self.Q, N])
        # symmetric operators: the new rows/columns are Qnᵀ (A N)
        Kb = np.zeros((Qn.shape[1],) * 2)
        Kb[:m0, :m0] = self.Kb
        KN = self.K_bulk @ N
        col = Qn.T @ KN
        if self.sketch is not None:
            self.sKb = np.column_stack([self.sKb, self.sketch @ KN])
        Kb[:, m0:] = col
        Kb[m0:, :] = col.T
        self.Kb = 0.5 * (Kb + Kb.T)
        for g, poly in self.films.items():
            AN = poly.stiffness_coeffs_apply(N)  # (4, n, k)
            Kg = np.zeros((4,) + (Qn.shape[1],) * 2)
            Kg[:, :m0, :m0] = self.Kg[g]
            col = np.einsum("na,knb->kab", Qn, AN)
            if self.sketch is not None:
                self.sKg[g] = np.concatenate([self.sKg[g], np.array([self.sketch @ a for a in AN])], axis=2)
            Kg[:, :, m0:] = col
            Kg[:, m0:, :] = np.transpose(col, (0, 2, 1))
            self.Kg[g] = 0.5 * (Kg + np.transpose(Kg, (0, 2, 1)))
            self.fg[g] = poly.load_coeffs @ Qn
        self.Q = Qn
        return N.shape[1]

    def reduced_system(self, thickness_mm: dict[str, float], mismatch_strain: float):
        """(K_r, f_r) of the Galerkin system for the given group thicknesses (mm)."""
        unknown = set(thickness_mm) - set(self.films)
        if unknown:
            raise ValueError(f"thickness given for groups {sorted(unknown)} that the reduced "
                             f"model does not have (available: {sorted(self.films)})")
        K = self.Kb.copy()
        f = np.zeros(self.size)
        for g, t in thickness_mm.items():
            if t <= 0:
                continue
            p = powers(t)
            K += np.tensordot(p, self.Kg[g], axes=1)
            f += p @ self.fg[g]
        return K, mismatch_strain * f

    def solve(self, thickness_mm: dict[str, float], mismatch_strain: float) -> np.ndarray:
        """Reduced coefficients a (u ≈ Q a) for the given thicknesses (mm) and strain."""
        if self.size == 0:
            return np.zeros(0)
        K, f = self.reduced_system(thickness_mm, mismatch_strain)
        try:
            return np.linalg.solve(K, f)
        except np.linalg.LinAlgError:
            return np.linalg.lstsq(K, f, rcond=None)[0]

    def expand(self, coeffs: np.ndarray) -> np.ndarray:
        """Full displacement vector Q a (mm)."""
        return self.Q @ coeffs if self.size else np.zeros(self.n)

    def full_operator(self, thickness_mm: dict[str, float]):
        """v ↦ K(t) v on the full DOF layout (for residuals)."""
        mats = []
        for g, t in thickness_mm.items():
            if t > 0:
                poly = self.films[g]
                mats.append((poly, powers(t)))

        def apply(v):
            out = self.K_bulk @ v
            for poly, p in mats:
                out = out + np.tensordot(p, poly.stiffness_coeffs_apply(v), axes=1)
            return out

        return apply

    def full_load(self, thickness_mm: dict[str, float], mismatch_strain: float) -> np.ndarray:
        f = np.zeros(self.n)
        for g, t in thickness_mm.items():
            if t > 0:
                f += powers(t) @ self.films[g].load_coeffs
        return mismatch_strain * f

    def residual_norm(self, coeffs: np.ndarray, thickness_mm: dict[str, float],
                      mismatch_strain: float) -> float:
        """Relative residual ||f − K Q a|| / ||f|| on the free DOFs (one full product)."""
        f = self.full_load(thickness_mm, mismatch_strain)[self.free]
        r = f - self.full_operator(thickness_mm)(self.expand(coeffs))[self.free]
        fn = np.linalg.norm(f)
        return float(np.linalg.norm(r) / fn) if fn > 0 else 0.0

    def residual_estimate(self, coeffs: np.ndarray, thickness_mm: dict[str, float],
                          mismatch_strain: float) -> float:
        """Sketched relative residual ||Θ(f − K Q a)|| / ||Θ f|| (no full product)."""
        if self.sketch is None:
            raise ValueError("this reduced basis was built without a sketch (sketch_size=0)")
        r = -(self.sKb @ coeffs) if self.size else np.zeros(self.sketch.shape[0])
        f = np.zeros_like(r)
        for g, t in thickness_mm.items():
            if t <= 0:
                continue
            p = powers(t)
            f += mismatch_strain * (self.sfg[g] @ p)
            if self.size:
                r -= np.tensordot(p, self.sKg[g], axes=1) @ coeffs
        r += f
        fn = np.linalg.norm(f)
        return float(np.linalg.norm(r) / fn) if fn > 0 else 0.0
