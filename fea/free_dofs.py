"""The stiffness of one coating case on the free DOFs, formed without sparse algebra.

Every case of a mesh has the same bulk stiffness and differs only in the film
thicknesses. The film's element matrices live on the bulk's pattern (a facet's DOFs are
those of its tetrahedron), so bulk + film is formed on the ``data`` array of the bulk
matrix restricted once to the free DOFs: no sparse additions or slicing per case (those
cost ~1.5 s per case at the default mesh, more than the CG iterations of a neighbouring
case). What has to be known for that is where each film entry lands in the bulk's
``data``: its *layout*, found once per film operator set.
"""

from __future__ import annotations

from functools import cached_property
from typing import Hashable

import numpy as np
import scipy.sparse as sp

from .assembly import FilmOperators, renumbered, shared_csr

__all__ = ["FreeStiffness", "pattern_ones"]


def pattern_ones(A: sp.csr_matrix) -> sp.csr_matrix:
    """The sparsity pattern of ``A`` with every stored entry set to 1 (shares its index arrays)."""
    return shared_csr(np.ones(A.indices.size), A.indices, A.indptr, A.shape)


class FreeStiffness:
    """Bulk + local film stiffness restricted to the free DOFs, per film thickness.

    Parameters
    ----------
    K_bulk : sparse matrix, shape (n, n)
        Bulk stiffness on all DOFs (N/mm). A CSR matrix is put into canonical form in
        place (sorted, summed duplicates: the layouts rely on it).
    free : ndarray of int
        Sorted free DOF numbers.

    Notes
    -----
    Films are named by a hashable key chosen by the caller (e.g. surface group and film
    elastic constants); a key must always name the same :class:`FilmOperators`.
    """

    def __init__(self, K_bulk: sp.spmatrix, free: np.ndarray):
        self.K_bulk = K_bulk
        self.free = np.asarray(free)
        self._layouts: dict[Hashable, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}

    @cached_property
    def to_free(self) -> np.ndarray:
        """Full DOF number → free DOF number (−1 for constrained DOFs)."""
        m = np.full(self.K_bulk.shape[0], -1, dtype=np.int64)
        m[self.free] = np.arange(self.free.size)
        return m

    @cached_property
    def bulk(self) -> sp.csr_matrix:
        """Bulk stiffness on the free DOFs; widened by explicit zeros where a film needs it."""
        K = self.K_bulk.tocsr()
        K.sum_duplicates()  # canonical (sorted, unique) indices: the layouts rely on them
        return renumbered(K, self.to_free, self.to_free, (self.free.size,) * 2)[0]

    def stiffness(self, films: dict[Hashable, tuple[FilmOperators, float]], offset: bool = True) -> sp.csr_matrix:
        """Bulk + local film stiffness on the free DOFs.

        Parameters
        ----------
        films : dict
            Key → (film operators, film thickness in mm) of every film of the case.
        offset : bool
            Film integrated through its thickness (True) or as a surface membrane.

        Returns
        -------
        csr_matrix, shape (n_free, n_free)
            Shares the index arrays of :attr:`bulk`.
        """
        layouts = self.layouts({k: ops for k, (ops, _) in films.items()})  # may widen the bulk: first
        Kb = self.bulk
        data = Kb.data.copy()
        for key, (ops, t) in films.items():
            keep, pos, pos_t = layouts[key]
            if offset:
                S, C = ops.power_data(t)
                data[pos] += S[keep] + C[keep]
                data[pos_t] += C[keep]
            else:
                data[pos] += t * ops.A00.data[keep]
        return shared_csr(data, Kb.indices, Kb.indptr, Kb.shape)

    def layouts(self, films: dict[Hashable, FilmOperators]) -> dict[Hashable, tuple]:
        """Where the entries of each film's matrices land in ``bulk.data``.

        Per key (keep, pos, pos_t): the entries of ``A00.data`` with a free row and
        column, and the positions of those entries and of their transposes in the bulk's
        data (all six film matrices share ``A00``'s pattern).

        Raises
        ------
        RuntimeError
            When a film's six matrices do not share one pattern.
        """
        need = [k for k in films if k not in self._layouts]
        if not need:
            return {k: self._layouts[k] for k in films}
        free, to_free = self.free, self.to_free
        patterns = {}
        for k in need:
            ops = films[k]
            if not ops.shares_pattern():
                raise RuntimeError(f"film operators {k!r} do not share one sparsity pattern")
            A = ops.A00
            # the film's entries on the free DOFs, carrying their entry numbers in A00.data
            ids = shared_csr(np.arange(1, A.nnz + 1, dtype=float), A.indices, A.indptr, A.shape)
            F, _ = renumbered(ids, to_free, to_free, (free.size, free.size))
            FT = F.T.tocsr()
            FT.sort_indices()
            patterns[k] = (A.nnz, F, FT)
        Kb = self.bulk
        # The bulk assembly drops entries that happen to be exactly zero; the film's are
        # kept: widen the bulk pattern by explicit zeros where needed (sums of patterns of
        # ones never cancel, so the union is exact)
        union = pattern_ones(Kb)
        for _, F, _ in patterns.values():
            union = union + pattern_ones(F)
        if union.nnz != Kb.nnz:
            union.sum_duplicates()
            union_ids = shared_csr(np.arange(1, union.nnz + 1, dtype=float), union.indices,
                                   union.indptr, union.shape)
            at = union_ids.multiply(pattern_ones(Kb)).tocsr().data.astype(np.int64) - 1
            data = np.zeros(union.nnz)
            data[at] = Kb.data
            Kb = self.bulk = shared_csr(data, union.indices, union.indptr, union.shape)
            self._layouts.clear()  # positions moved; other films are redone on demand
            need = list(films)
            if any(k not in patterns for k in films):
                return self.layouts(films)
        # positions by sparse products (linear merges of sorted rows): the bulk's data
        # carries its entry numbers, a film pattern of ones picks them out
        bulk_ids = shared_csr(np.arange(1, Kb.nnz + 1, dtype=float), Kb.indices, Kb.indptr, Kb.shape)
        for k in need:
            nnz, F, FT = patterns[k]
            hit = bulk_ids.multiply(pattern_ones(F)).tocsr()
            hit_t = bulk_ids.multiply(pattern_ones(FT)).tocsr()
            if hit.nnz != F.nnz or hit_t.nnz != FT.nnz:
                raise RuntimeError(f"film pattern {k!r} is not inside the widened bulk pattern")
            keep = F.data.astype(np.int64) - 1
            by_entry = np.empty(nnz, dtype=np.int64)
            by_entry[FT.data.astype(np.int64) - 1] = hit_t.data.astype(np.int64) - 1
            self._layouts[k] = (keep, hit.data.astype(np.int64) - 1, by_entry[keep])
        return {k: self._layouts[k] for k in films}
