"""Vectorised assembly of the thermo-elastic system on quadratic tetrahedra.

Units: millimetres for lengths, MPa (N/mm²) for moduli and stresses, so stiffness
matrices are in N/mm, loads in N and displacements in mm.

Degrees of freedom: scalar P2 DOF ``d`` (scikit-fem numbering of ``ElementTetP2``)
carries displacement components at global indices ``3*d + (0, 1, 2)``.

Why not scikit-fem's ``BilinearForm`` for the bulk: a vector P2 form loops in Python
over the 30 x 30 local basis pairs; here the element matrices come from one batched
matrix product over elements (measured ~20x faster on the blank meshes, see
benchmarks/). scikit-fem still provides the mesh, the isoparametric mapping, the
quadrature and the basis gradients.

Thin NiP film
-------------
The film (thickness t ≪ wall thickness) is a bonded layer: its displacement at height
z above the surface is u + z θ (Kirchhoff kinematics, no shear in the film), so on a
flat face its in-plane strain is ε_s(u) + z ε_s(θ) and its energy per unit area,

    ½ ∫₀ᵗ (ε(z) − ε_m P) : C_f : (ε(z) − ε_m P) dz,

with plane-stress C_f, tangential projector P = I − n nᵀ and mismatch strain ε_m, is
a polynomial in t, integrated exactly. This keeps the film's membrane stiffness, its
lever arm t/2 and its own bending stiffness; a membrane on the surface drops the
last two, an error of ≈ t/h (8 % for 200 µm on a 2.5 mm wall).

θ must be *continuous* over the surface. Taking ∂u/∂n element by element (it jumps
across element edges for C0 elements) leaves spurious moments at every element edge:
the discrete problem is then inconsistent (the exact bilayer field does not satisfy
it) and errs by several % when elements are as thin as the film is thick. θ is
therefore recovered at the surface nodes by averaging over the adjacent facets; only its
tangential part is taken from the substrate. On curved faces (the holes) two further
terms of order t/R matter: the metric of the offset surface (area and strain scale with
1 + z·curvature) and the film's own plane-stress normal strain, which differs from the
substrate's ∂u_n/∂n and, through the curvature, changes the film's hoop strain. With
both, the thin film matches an explicitly meshed NiP layer in a hole within 0.45 %
(without them: −1.7 % at 200 µm); see :class:`FilmOperators` for the exact terms.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
import scipy.sparse as sp
from skfem import CellBasis, ElementTetP2, FacetBasis

__all__ = ["scalar_basis", "bulk_stiffness", "film_operators", "FilmOperators", "combine", "renumbered",
           "shared_csr"]

def scalar_basis(mesh, intorder: int = 2) -> CellBasis:
    """Scalar P2 basis on ``mesh`` (isoparametric on a MeshTet2)."""
    return CellBasis(mesh, ElementTetP2(), intorder=intorder)


def _vector_dofs(scalar_dofs: np.ndarray) -> np.ndarray:
    """(10, n) scalar element DOFs → (n, 30) vector DOFs ordered (a, i) with i fastest."""
    return (3 * scalar_dofs.T[:, :, None] + np.arange(3)[None, None, :]).reshape(scalar_dofs.shape[1], 30)


def _scatter(local: np.ndarray, vdofs: np.ndarray, ndof: int) -> sp.csr_matrix:
    """Sum element matrices (n, 30, 30) into a global CSR matrix of size 3*ndof."""
    rows = np.repeat(vdofs, 30, axis=1).ravel()
    cols = np.tile(vdofs, (1, 30)).ravel()
    return sp.csr_matrix((local.ravel(), (rows, cols)), shape=(3 * ndof, 3 * ndof))


class _Scatter:
    """The CSR pattern of element matrices (n, 30, 30) on vector DOFs ``vdofs`` (n, 30).

    Built once per set of elements, so that every operator assembled on them shares one
    ``indices``/``indptr`` pair: sums of such operators are then sums of their ``data``
    arrays (:func:`combine`), not sparse additions.
    """

    def __init__(self, vdofs: np.ndarray, ndof: int):
        n3 = 3 * ndof
        rows = np.repeat(vdofs, 30, axis=1).ravel().astype(np.int64)
        cols = np.tile(vdofs, (1, 30)).ravel()
        keys, self._inverse = np.unique(rows * n3 + cols, return_inverse=True)
        r = keys // n3
        self.indices = (keys - r * n3).astype(np.int32)
        self.indptr = np.searchsorted(r, np.arange(n3 + 1)).astype(np.int32)
        self.shape = (n3, n3)

    def __call__(self, local: np.ndarray) -> sp.csr_matrix:
        data = np.bincount(self._inverse.ravel(), weights=local.ravel(), minlength=self.indices.size)
        return shared_csr(data, self.indices, self.indptr, self.shape)


def shared_csr(data, indices, indptr, shape) -> sp.csr_matrix:
    """A CSR matrix that keeps (does not copy or re-check) the given index arrays.

    Parameters
    ----------
    data : ndarray, shape (nnz,)
        Entry values.
    indices, indptr : ndarray of int
        A canonical (sorted, duplicate-free) CSR pattern; kept by reference, so several
        matrices can share it and their sums stay sums of ``data`` (:func:`combine`).
    shape : tuple of int
    """
    A = sp.csr_matrix(shape, dtype=float)
    A.data, A.indices, A.indptr = data, indices, indptr
    A.has_sorted_indices = True
    A.has_canonical_format = True
    return A


def renumbered(A: sp.csr_matrix, row_map: np.ndarray, col_map: np.ndarray, shape) -> tuple[sp.csr_matrix, np.ndarray]:
    """``A`` restricted to the rows/columns whose map is >= 0, renumbered by the maps.

    The maps must increase over the kept indices (e.g. full → free DOF numbers), so the
    canonical order of ``A`` carries over: O(nnz), no sorting (``A[rows][:, cols]`` costs
    ~0.1 s per matrix at the default mesh). Returns the matrix and the positions in
    ``A.data`` of its entries.
    """
    rows = row_map[np.repeat(np.arange(A.shape[0]), np.diff(A.indptr))]
    cols = col_map[A.indices]
    keep = np.flatnonzero((rows >= 0) & (cols >= 0))
    indptr = np.zeros(shape[0] + 1, dtype=np.int64)
    np.cumsum(np.bincount(rows[keep], minlength=shape[0]), out=indptr[1:])
    B = shared_csr(A.data[keep], cols[keep].astype(np.int32), indptr.astype(np.int32), shape)
    return B, keep


def combine(coefs, mats) -> sp.csr_matrix:
    """Σ c_i A_i; a ``data`` sum when the matrices share one pattern (see :class:`_Scatter`)."""
    first = mats[0]
    if all(A.indices is first.indices and A.indptr is first.indptr for A in mats):
        data = sum(c * A.data for c, A in zip(coefs, mats))
        return shared_csr(data, first.indices, first.indptr, first.shape)
    return sum((c * A for c, A in zip(coefs, mats)), sp.csr_matrix(first.shape)).tocsr()


def _isotropic_local(T: np.ndarray, w: np.ndarray, lam: float, mu: float) -> np.ndarray:
    """Element stiffness matrices of an isotropic solid in batched form.

    Parameters
    ----------
    T : ndarray, shape (n, q, 10, 3)
        Basis gradients per element, quadrature point, basis function and direction.
    w : ndarray, shape (n, q)
        Quadrature weights times Jacobian.
    lam, mu : float
        Lamé constants (MPa).

    Returns
    -------
    ndarray, shape (n, 30, 30)
        K[(a,i),(b,j)] = Σ w [λ T_ai T_bj + μ T_aj T_bi + μ δ_ij (T_a·T_b)].
    """
    n, q = w.shape
    Tf = T.reshape(n, q, 30)
    A5 = np.einsum("nqm,nqk->nmk", Tf * w[:, :, None], Tf, optimize=True).reshape(n, 10, 3, 10, 3)
    K = lam * A5 + mu * A5.transpose(0, 1, 4, 3, 2)
    D = np.einsum("nqac,nqbc->nab", T * w[:, :, None, None], T, optimize=True)  # Σ w (T_a·T_b)
    K += mu * D[:, :, None, :, None] * np.eye(3)[None, None, :, None, :]
    return K.reshape(n, 30, 30)


def bulk_stiffness(basis: CellBasis, youngs_modulus_MPa: float, poisson_ratio: float,
                   chunk: int = 20000) -> sp.csr_matrix:
    """Linear-elastic stiffness (N/mm) of the whole mesh for one isotropic material."""
    E, nu = youngs_modulus_MPa, poisson_ratio
    lam = E * nu / ((1 + nu) * (1 - 2 * nu))
    mu = E / (2 * (1 + nu))
    G = np.stack([basis.basis[a][0].grad for a in range(basis.Nbfun)])  # (10, 3, n, q)
    vd = _vector_dofs(basis.element_dofs)
    K = None
    for s in range(0, basis.nelems, chunk):
        sl = slice(s, s + chunk)
        T = np.ascontiguousarray(G[:, :, sl, :].transpose(2, 3, 0, 1))  # (n, q, 10, 3)
        Kc = _scatter(_isotropic_local(T, basis.dx[sl], lam, mu), vd[sl], basis.N)
        K = Kc if K is None else K + Kc
    return K


@dataclass(frozen=True)
class FilmOperators:
    """Thickness-independent pieces of a bonded film on one surface group.

    With L = ∇_s n (surface curvature, k = tr L), B0 u = ε_s(u) (tangential strain),
    R u = θ_t (continuous tangential ∂u/∂n) and the curvature operator
    B_C u = −sym(∇_s u · L) + a tr(ε_s(u)) L (a = −ν/(1−ν), the film's own normal strain),
    the film strain at height z is, to first order in z·curvature,
    ε(z) = B0 u + z (B0 R u + B_C u), with area weight 1 + k z and eigenstrain
    ε_m (P − z b L), b = (1+ν)/(1−ν) (the film thickens and its outer layers move along n).

    Attributes
    ----------
    A00, A0C, ACC : csr_matrix, shape (3N, 3N)
        ∫ B0ᵀ C B0, ∫ B0ᵀ C B_C, ∫ B_Cᵀ C B_C over the surface (plane-stress C, MPa·mm²).
    A00k, A0Ck, ACCk : csr_matrix
        The same weighted by k (1/mm).
    f0, f0k, fC, fCk : ndarray, shape (3N,)
        ∫ tr(B0 v), ∫ k tr(B0 v), ∫ tr(B_C v), ∫ k tr(B_C v) (per unit mismatch stress).
    gL0, gL0k, gLC, gLCk : ndarray, shape (3N,)
        ∫ (λ k tr X + 2μ L:X)/(2λ+2μ) for X = B0 v, B_C v, unweighted and weighted by k
        (the load of the eigenstrain's −z b L part).
    R : csr_matrix, shape (3N, 3N)
        Continuous recovery of θ_t at the surface nodes; zero rows off the surface.
    """

    A00: sp.csr_matrix
    A0C: sp.csr_matrix
    ACC: sp.csr_matrix
    A00k: sp.csr_matrix
    A0Ck: sp.csr_matrix
    ACCk: sp.csr_matrix
    f0: np.ndarray
    f0k: np.ndarray
    fC: np.ndarray
    fCk: np.ndarray
    R: sp.csr_matrix
    youngs_modulus_MPa: float
    poisson_ratio: float
    gL0: np.ndarray | float = 0.0
    gL0k: np.ndarray | float = 0.0
    gLC: np.ndarray | float = 0.0
    gLCk: np.ndarray | float = 0.0
    b_n: float = 0.0

    def mismatch_stress(self, mismatch_strain: float) -> float:
        """Biaxial stress (MPa) of the film held at the substrate's strain: E/(1−ν) ε_m."""
        return self.youngs_modulus_MPa / (1 - self.poisson_ratio) * mismatch_strain

    def local_stiffness(self, t: float, offset: bool = True) -> sp.csr_matrix:
        """The part of the film stiffness with the sparsity of a surface element matrix.

        Moments of the through-thickness weight: ∫₀ᵗ (1+kz) z^p dz."""
        if not offset:
            return t * self.A00
        c1, c2, c3 = t**2 / 2, t**3 / 3, t**4 / 4
        A0C = combine((c1, c2), (self.A0C, self.A0Ck))
        return (combine((t, c1, c2, c3), (self.A00, self.A00k, self.ACC, self.ACCk)) + A0C
                + A0C.T).tocsr()

    def power_data(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """``data`` of the local stiffness on the shared pattern of ``A00``: (S, C) with
        ``local_stiffness(t) = S + C + Cᵀ`` (offset film); see :class:`_Scatter`."""
        c1, c2, c3 = t**2 / 2, t**3 / 3, t**4 / 4
        S = t * self.A00.data + c1 * self.A00k.data + c2 * self.ACC.data + c3 * self.ACCk.data
        C = c1 * self.A0C.data + c2 * self.A0Ck.data
        return S, C

    def shares_pattern(self) -> bool:
        """All six local matrices share ``A00``'s index arrays (assembled by one scatter)."""
        A = self.A00
        return all(M.indices is A.indices and M.indptr is A.indptr
                   for M in (self.A00k, self.A0C, self.A0Ck, self.ACC, self.ACCk))

    @cached_property
    def _active(self):
        """The operators restricted to the DOFs they touch (those of the tetrahedra on the
        surface): products then cost their non-zeros, not the 3N rows of the whole mesh
        (2-3x faster at the default mesh, where a surface group touches ~10 % of the DOFs)."""
        rows = np.flatnonzero(np.diff(self.A00.indptr) | np.diff(self.R.indptr))
        idx = np.unique(np.concatenate([rows, self.A00.indices, self.R.indices]))
        to_active = np.full(self.A00.shape[0], -1, dtype=np.int64)
        to_active[idx] = np.arange(idx.size)
        shape = (idx.size, idx.size)
        R, _ = renumbered(self.R.tocsr(), to_active, to_active, shape)
        if not self.shares_pattern():
            mats = [renumbered(M.tocsr(), to_active, to_active, shape)[0]
                    for M in (self.A00, self.A00k, self.A0C, self.A0Ck, self.ACC, self.ACCk)]
            return (idx, *mats, R)
        # one pattern, renumbered once and shared: t-weighted sums stay data sums (combine)
        A00, keep = renumbered(self.A00, to_active, to_active, shape)
        mats = [A00] + [shared_csr(M.data[keep], A00.indices, A00.indptr, shape)
                        for M in (self.A00k, self.A0C, self.A0Ck, self.ACC, self.ACCk)]
        return (idx, *mats, R)

    def apply_power_terms(self, V: np.ndarray, offset: bool = True) -> np.ndarray:
        """Coefficients of t, t², t³, t⁴ of the whole film stiffness applied to ``V``.

        ``local_stiffness(t) V + apply_coupling(t, V) = Σ_k t^k terms[k-1]``, formed from
        products with the stored matrices only (no new matrices: at the default mesh the
        t-weighted sums would cost ~3 GB per set of four thicknesses). Tested against the
        two methods it expands (tests/test_fea_reduced.py).

        Returns
        -------
        ndarray, shape (4, *V.shape)
        """
        V = np.asarray(V)
        out = np.zeros((4,) + V.shape)
        out[:, self._active[0]] = self.apply_power_terms_active(V, offset)
        return out

    def apply_with_powers(self, V: np.ndarray, T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Whole film stiffness of column j's thickness applied to column j of ``V``.

        ``T`` (4, m) holds t_j, t_j², t_j³, t_j⁴ (mm) per column; returns the DOFs the film
        touches and the product on them, (idx, (len(idx), m)): the columns of a block of
        cases with different thicknesses in one set of sparse products.
        """
        terms = self.apply_power_terms_active(V)
        return self._active[0], np.einsum("km,knm->nm", T, terms, optimize=True)

    def apply_power_terms_active(self, V: np.ndarray, offset: bool = True) -> np.ndarray:
        """:meth:`apply_power_terms` on the touched DOFs only, shape (4, len(idx), *V.shape[1:])."""
        idx, A00, A00k, A0C, A0Ck, ACC, ACCk, R = self._active
        V = np.asarray(V)[idx]
        out = np.zeros((4,) + V.shape)
        A00V = A00 @ V
        out[0] = A00V
        if not offset:
            return out
        RV = R @ V
        RT = R.T
        A00kV, A0CV, A0CkV = A00k @ V, A0C @ V, A0Ck @ V
        A00RV = A00 @ RV
        out[1] = 0.5 * (A00kV + A0CV + A0C.T @ V) + 0.5 * (A00RV + RT @ A00V)
        out[2] = (A0CkV + A0Ck.T @ V + ACC @ V) / 3 \
            + (A00k @ RV + RT @ (A00kV + A00RV + A0CV) + A0C.T @ RV) / 3
        out[3] = 0.25 * (ACCk @ V) + 0.25 * (RT @ (A00k @ RV + A0CkV) + A0Ck.T @ RV)
        return out

    def coupling_parts(self, t: float):
        """(X, Y, Z) with the non-local film stiffness = X R + Rᵀ X + Rᵀ Y R + Rᵀ Z + Zᵀ R."""
        c1, c2, c3 = t**2 / 2, t**3 / 3, t**4 / 4
        return (combine((c1, c2), (self.A00, self.A00k)), combine((c2, c3), (self.A00, self.A00k)),
                combine((c2, c3), (self.A0C, self.A0Ck)))

    def apply_coupling(self, t: float, v: np.ndarray) -> np.ndarray:
        """The non-local part applied to ``v`` without forming it (large systems)."""
        return self.coupling_operator(t)(v)

    def coupling_operator(self, t: float):
        """v ↦ (non-local part) v for thickness ``t`` (mm); the t-weighted sparse sums are
        formed once here, not on every product (they cost ~5x the products themselves)."""
        idx, A00, A00k, A0C, A0Ck, _, _, R = self._active
        c1, c2, c3 = t**2 / 2, t**3 / 3, t**4 / 4
        X, Y, Z = combine((c1, c2), (A00, A00k)), combine((c2, c3), (A00, A00k)), combine((c2, c3), (A0C, A0Ck))
        RT, ZT = R.T, Z.T  # transposed views: CSC products cost the same
        n = self.A00.shape[0]

        def apply(v: np.ndarray) -> np.ndarray:
            vs = v[idx]
            Rv = R @ vs
            out = np.zeros((n,) + np.shape(v)[1:])
            out[idx] = X @ Rv + RT @ (X @ vs + Y @ Rv + Z @ vs) + ZT @ Rv
            return out

        return apply

    def coupling_matrix(self, t: float) -> sp.csr_matrix:
        """The non-local part assembled explicitly (≈5x denser; for small systems)."""
        X, Y, Z = self.coupling_parts(t)
        R = self.R
        XR, ZtR = X @ R, Z.T @ R
        return (XR + XR.T + R.T @ (Y @ R) + ZtR.T + ZtR).tocsr()

    def load(self, t: float, mismatch_strain: float, offset: bool = True) -> np.ndarray:
        """Mismatch load (N): σ_m ∫₀ᵗ (1+kz) tr ε(z)(v) dz."""
        sigma = self.mismatch_stress(mismatch_strain)
        if not offset:
            return sigma * t * self.f0
        c1, c2, c3 = t**2 / 2, t**3 / 3, t**4 / 4
        b = self.b_n
        # ε*(z) = ε_m (P − z b L): the film's own thickening moves its outer layers along n
        g0 = t * self.f0 + c1 * self.f0k - b * (c1 * self.gL0 + c2 * self.gL0k)
        g1 = c1 * self.f0 + c2 * self.f0k - b * (c2 * self.gL0 + c3 * self.gL0k)
        gC = c1 * self.fC + c2 * self.fCk - b * (c2 * self.gLC + c3 * self.gLCk)
        return sigma * (g0 + self.R.T @ g1 + gC)

    def system(self, thickness_mm: float, mismatch_strain: float, offset: bool = True):
        """Full film stiffness (N/mm) and load (N), assembled explicitly (tests, small meshes)."""
        K = self.local_stiffness(thickness_mm, offset)
        if offset:
            K = K + self.coupling_matrix(thickness_mm)
        return K.tocsr(), self.load(thickness_mm, mismatch_strain, offset)


# Node positions of the quadratic reference triangle (vertices, then edge midpoints).
_TRI6 = np.array([[0.0, 1.0, 0.0, 0.5, 0.5, 0.0], [0.0, 0.0, 1.0, 0.0, 0.5, 0.5]])


def _normal_derivative_recovery(mesh, facets: np.ndarray, ndof: int, doflocs: np.ndarray) -> sp.csr_matrix:
    """Sparse map U → θ = ∂u/∂n averaged at the surface nodes of ``facets``.

    Each facet evaluates ∂u/∂n at its six nodes from its own element; nodes shared by
    several facets take the mean. The result is a continuous P2 field on the surface,
    which is what makes the offset film energy consistent (see module docstring).
    """
    fb = FacetBasis(mesh, ElementTetP2(), facets=facets, quadrature=(_TRI6, np.ones(6) / 6))
    n = np.asarray(fb.normals)  # (3, nf, 6)
    D = np.stack([np.einsum("ifp,ifp->fp", fb.basis[a][0].grad, n) for a in range(fb.Nbfun)])  # (10, nf, 6)
    ed = fb.element_dofs  # (10, nf)
    x = fb.mapping.G(fb.X, find=fb.find)  # (3, nf, 6)
    cand = doflocs[:, ed]  # (3, 10, nf)
    dist = ((cand[:, :, :, None] - x[:, None, :, :]) ** 2).sum(axis=0)  # (10, nf, 6)
    node = np.take_along_axis(ed[:, :, None], dist.argmin(axis=0)[None], axis=0)[0]  # (nf, 6)
    rows = np.broadcast_to(node[None], D.shape).ravel()
    cols = np.broadcast_to(ed[:, :, None], D.shape).ravel()
    Rs = sp.csr_matrix((D.ravel(), (rows, cols)), shape=(ndof, ndof))
    count = np.bincount(node.ravel(), minlength=ndof).astype(float)
    scale = np.divide(1.0, count, out=np.zeros_like(count), where=count > 0)
    Rs = sp.diags(scale) @ Rs
    return sp.kron(Rs, sp.eye(3), format="csr")  # DOF 3*d + i, component-wise


def _nodal_normals(mesh, facets: np.ndarray, ndof: int, doflocs: np.ndarray) -> np.ndarray:
    """Unit outward normals (3, N) at the surface nodes of ``facets`` (zero elsewhere)."""
    fb = FacetBasis(mesh, ElementTetP2(), facets=facets, quadrature=(_TRI6, np.ones(6) / 6))
    n = np.asarray(fb.normals)  # (3, nf, 6)
    ed = fb.element_dofs
    x = fb.mapping.G(fb.X, find=fb.find)
    dist = ((doflocs[:, ed][:, :, :, None] - x[:, None, :, :]) ** 2).sum(axis=0)
    node = np.take_along_axis(ed[:, :, None], dist.argmin(axis=0)[None], axis=0)[0]  # (nf, 6)
    N = np.zeros((3, ndof))
    for i in range(3):
        N[i] = np.bincount(node.ravel(), weights=n[i].ravel(), minlength=ndof)
    norm = np.linalg.norm(N, axis=0)
    return np.divide(N, norm, out=np.zeros_like(N), where=norm > 0)


def _strain_local(X: np.ndarray, Y: np.ndarray, w: np.ndarray, lam: float, mu: float) -> np.ndarray:
    """Element matrices Σ_q w [λ tr X_A tr Y_B + 2μ X_A : Y_B] for strain-tensor sets (n, q, 30, 3, 3)."""
    trX = np.einsum("nqAii->nqA", X)
    trY = np.einsum("nqAii->nqA", Y)
    K = lam * np.einsum("nqA,nqB->nAB", trX * w[:, :, None], trY, optimize=True)
    n, q = w.shape
    Xf = (X * w[:, :, None, None, None]).reshape(n, q, 30, 9)
    K += 2 * mu * np.einsum("nqAk,nqBk->nAB", Xf, Y.reshape(n, q, 30, 9), optimize=True)
    return K


def film_operators(mesh, facets: np.ndarray, youngs_modulus_MPa: float, poisson_ratio: float,
                   doflocs: np.ndarray, intorder: int = 3) -> FilmOperators:
    """Assemble the thickness-independent film operators on boundary ``facets``.

    Parameters
    ----------
    mesh : skfem.MeshTet2 or MeshTet
        Substrate mesh (mm).
    facets : ndarray of int
        Boundary facets carrying the film (one smooth surface group).
    youngs_modulus_MPa, poisson_ratio : float
        Film elastic constants.
    doflocs : ndarray, shape (3, N)
        Scalar P2 DOF positions of the volume basis.
    """
    fb = FacetBasis(mesh, ElementTetP2(), facets=facets, intorder=intorder)
    ndof = fb.N
    E, nu = youngs_modulus_MPa, poisson_ratio
    if len(fb.find) == 0:
        z = sp.csr_matrix((3 * ndof, 3 * ndof))
        v = np.zeros(3 * ndof)
        return FilmOperators(z, z, z, z, z, z, v, v, v, v, z, E, nu)
    mu = E / (2 * (1 + nu))
    lam_ps = E * nu / (1 - nu**2)  # plane-stress λ
    a_n = -nu / (1 - nu)  # film normal strain per unit tr(ε_s) (plane stress)
    b_n = (1 + nu) / (1 - nu)  # ... and per unit isotropic eigenstrain
    n = np.asarray(fb.normals)  # (3, nf, q), outward
    P = np.eye(3)[None, None] - np.einsum("ifq,jfq->fqij", n, n)  # (nf, q, 3, 3)
    g = np.stack([fb.basis[a][0].grad for a in range(fb.Nbfun)])  # (10, 3, nf, q)
    T = np.einsum("fqij,ajfq->fqai", P, g, optimize=True)  # tangential gradients
    Nn = _nodal_normals(mesh, facets, ndof, doflocs)
    N = Nn[:, fb.element_dofs]  # (3, 10, nf)
    Lraw = np.einsum("iaf,fqaj->fqij", N, T, optimize=True)
    L = np.einsum("fqik,fqkl,fqlj->fqij", P, 0.5 * (Lraw + Lraw.transpose(0, 1, 3, 2)), P, optimize=True)
    k = np.einsum("fqii->fq", L)
    S = np.einsum("fqij,fqaj->fqai", L, T, optimize=True)  # s_a = L t_a
    nf, q = fb.dx.shape

    def sym_p(vecs):  # strain sets sym(p_i ⊗ v_a), shape (nf, q, 30, 3, 3)
        X = 0.5 * (np.einsum("fqki,fqal->fqaikl", P, vecs) + np.einsum("fqak,fqli->fqaikl", vecs, P))
        return X.reshape(nf, q, 30, 3, 3)

    E0 = sym_p(T)
    # curvature part of dε/dz other than θ_t: −sym(∇u L) + θ_n L, θ_n = a tr ε_s(u) (+ b ε_m in the load)
    EC = -sym_p(S) + a_n * np.einsum("fqai,fqkl->fqaikl", T, L).reshape(nf, q, 30, 3, 3)
    w = fb.dx
    vd = _vector_dofs(fb.element_dofs)
    scatter = _Scatter(vd, ndof)

    def mat(w_, X, Y):
        return scatter(_strain_local(X, Y, w_, lam_ps, mu))

    def vec(w_, X):  # ∫ w tr X per basis function (the load per unit biaxial mismatch stress)
        loc = np.einsum("fq,fqAii->fA", w_, X)
        return np.bincount(vd.ravel(), weights=loc.ravel(), minlength=3 * ndof)

    def vecL(w_, X):  # ∫ w [λ k tr X + 2μ L:X] / (2λ+2μ): eigenstrain-gradient load, normalised
        c = 2 * lam_ps + 2 * mu
        loc = np.einsum("fq,fqA->fA", w_, (lam_ps * k[:, :, None] * np.einsum("fqAii->fqA", X)
                                           + 2 * mu * np.einsum("fqkl,fqAkl->fqA", L, X)) / c)
        return np.bincount(vd.ravel(), weights=loc.ravel(), minlength=3 * ndof)

    # θ_t: tangential part of the recovered ∂u/∂n (the normal part is the film's own strain)
    R = _normal_derivative_recovery(mesh, facets, ndof, doflocs)
    rows = np.repeat(np.arange(ndof), 9) * 3 + np.tile(np.repeat(np.arange(3), 3), ndof)
    cols = np.repeat(np.arange(ndof), 9) * 3 + np.tile(np.tile(np.arange(3), 3), ndof)
    Pn = (np.eye(3)[None] - np.einsum("in,jn->nij", Nn, Nn)) * (np.linalg.norm(Nn, axis=0) > 0)[:, None, None]
    Pnode = sp.csr_matrix((Pn.ravel(), (rows, cols)), shape=(3 * ndof, 3 * ndof))
    Rt = (Pnode @ R).tocsr()
    ops = FilmOperators(
        A00=mat(w, E0, E0), A0C=mat(w, E0, EC), ACC=mat(w, EC, EC), A00k=mat(w * k, E0, E0),
        A0Ck=mat(w * k, E0, EC), ACCk=mat(w * k, EC, EC), f0=vec(w, E0), f0k=vec(w * k, E0),
        fC=vec(w, EC), fCk=vec(w * k, EC), R=Rt, youngs_modulus_MPa=E, poisson_ratio=nu,
        # loads of the eigenstrain's through-thickness part −z b ε_m L (film thickening on curved faces)
        gL0=vecL(w, E0), gL0k=vecL(w * k, E0), gLC=vecL(w, EC), gLCk=vecL(w * k, EC), b_n=b_n)
    return ops
