"""On-disk cache of the assembled film operators of a mesh.

Why: assembling the thickness-independent film operators of the five coatable surface
groups takes ~12 s at the default mesh, and every new process (each CLI call, each
sweep worker, each test worker) paid it again. A warm load reads the ~690 MB once and checks
them with the zip CRC-32 of every member (:func:`fea.store.open_checked`), not with a second
sha256 pass over the file.

An entry holds one :class:`fea.assembly.FilmOperators` (one surface group, one film
material, after the symmetry-plane treatment of :meth:`fea.model.PreparedBlank.film_ops`)
and is a :mod:`fea.store` entry (payload, then checksummed sidecar, both atomic)::

    <cache_dir>/filmops-<sha256[:24]>.npz    the arrays, and the key itself as ``key``
    <cache_dir>/filmops-<sha256[:24]>.json   the store's sidecar

The key (:func:`operator_key`) hashes the mesh arrays themselves (node positions,
connectivity, the group's facets), the film's elastic constants, the constrained DOFs,
:data:`fea.MODEL_VERSION` and :data:`FORMAT_VERSION`: a file can only be found for
exactly the operators it holds. The store checks the sidecar and the payload's size, every
member is read to its end (zipfile then checks its CRC-32) and the stored ``key`` member must
be the entry's; a missing, corrupt, truncated or inconsistent entry is rebuilt with a
:class:`fea.store.CacheWarning`, never used. A payload without a sidecar whose own
``key`` member matches and whose arrays read back whole (zip CRC of every member) is a
complete entry written without the store's sidecar; the sidecar is added to it instead
of assembling again.

The film operators are large (~690 MB for the default mesh, ~1.3 GB for the finest
mesh of the convergence study) and a sweep over geometries makes a new set per
geometry, so the cache is bounded: after each write, the least recently used entries
(a hit refreshes an entry's time) are deleted until the film operators take at most
:func:`budget_bytes` (``$CRYOGRATING_OPERATOR_CACHE_MB``, default
:data:`DEFAULT_BUDGET_MB`). The default holds every group of the default mesh; within
one process a :class:`fea.model.PreparedBlank` keeps its operators in memory, so an
eviction only costs a later process an assembly.
"""

from __future__ import annotations

import hashlib
import io
import os
import warnings
import zipfile
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from . import MODEL_VERSION, store
from .assembly import FilmOperators, shared_csr

__all__ = ["FORMAT_VERSION", "NAMESPACE", "DEFAULT_BUDGET_MB", "BUDGET_ENV", "budget_bytes", "operator_key", "operator_entry", "load_film_ops", "save_film_ops"]

#: Bump when the stored arrays or their meaning change; old files then miss.
FORMAT_VERSION = 1
#: Store namespace of the film operators.
NAMESPACE = "fea.operator_cache/film-operators"

#: Largest total size of the stored film operators of one cache directory, MB (10^6 bytes).
DEFAULT_BUDGET_MB = 1024
#: Environment variable that sets it.
BUDGET_ENV = "CRYOGRATING_OPERATOR_CACHE_MB"
_PAYLOADS = "filmops-*.npz"

_PATTERNED = ("A00", "A00k", "A0C", "A0Ck", "ACC", "ACCk")
_VECTORS = ("f0", "f0k", "fC", "fCk", "gL0", "gL0k", "gLC", "gLCk")


def budget_bytes() -> int:
    """The film-operator cache's size budget, bytes: ``$CRYOGRATING_OPERATOR_CACHE_MB``
    (a number >= 0 of MB; 0 keeps only the entry just written) or :data:`DEFAULT_BUDGET_MB`."""
    raw = os.environ.get(BUDGET_ENV, "").strip()
    if not raw:
        return DEFAULT_BUDGET_MB * 10**6
    try:
        mb = float(raw)
    except ValueError:
        mb = float("nan")
    if not (mb >= 0 and np.isfinite(mb)):
        raise ValueError(f"{BUDGET_ENV}={raw!r} must be a number of MB >= 0 (default {DEFAULT_BUDGET_MB})")
    return int(mb * 10**6)


def operator_key(mesh, facets: np.ndarray, youngs_modulus_MPa: float, poisson_ratio: float,
                 fixed_dofs: np.ndarray) -> str:
    """sha256 hex digest identifying one group's film operators on ``mesh``."""
    h = hashlib.sha256()
    h.update(f"filmops v{FORMAT_VERSION} model v{MODEL_VERSION} {type(mesh).__name__} "
             f"E={youngs_modulus_MPa!r} nu={poisson_ratio!r}".encode())
    for a in (mesh.doflocs, mesh.t, np.sort(facets), np.sort(fixed_dofs)):
        a = np.ascontiguousarray(a)
        h.update(f"{a.dtype.str}{a.shape}".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def operator_entry(cache_dir: Path, mesh, facets: np.ndarray, youngs_modulus_MPa: float,
                   poisson_ratio: float, fixed_dofs: np.ndarray) -> store.Entry:
    """The store entry of one group's film operators on ``mesh`` (key: :func:`operator_key`).

    Its parameters name what a reader can check by eye (film constants, model version,
    sizes); the key also covers the arrays.
    """
    budget_bytes()  # a bad budget fails here, before an assembly whose result it would refuse
    key = operator_key(mesh, facets, youngs_modulus_MPa, poisson_ratio, fixed_dofs)
    params = {"youngs_modulus_MPa": float(youngs_modulus_MPa), "poisson_ratio": float(poisson_ratio),
              "model_version": MODEL_VERSION, "mesh_type": type(mesh).__name__,
              "n_nodes": int(mesh.doflocs.shape[1]), "n_facets": int(np.size(facets)),
              "n_fixed_dofs": int(np.size(fixed_dofs))}
    return store.entry(cache_dir, NAMESPACE, params, prefix="filmops-", format_version=FORMAT_VERSION,
                       key=key, key_chars=24)


def save_film_ops(e: store.Entry, ops: FilmOperators) -> Path | None:
    """Store ``ops`` as the entry ``e``; returns the payload path, or None when it cannot be
    cached (operators without one shared pattern, or an unwritable directory: a warning)."""
    if not ops.shares_pattern():
        return None
    arrays = {"key": np.array(e.key), "indices": ops.A00.indices, "indptr": ops.A00.indptr,
              "shape": np.array(ops.A00.shape), "R_data": ops.R.data, "R_indices": ops.R.indices,
              "R_indptr": ops.R.indptr,
              "scalars": np.array([ops.youngs_modulus_MPa, ops.poisson_ratio, ops.b_n])}
    arrays.update({name: getattr(ops, name).data for name in _PATTERNED})
    arrays.update({name: np.broadcast_to(np.asarray(getattr(ops, name), float), ops.f0.shape)
                   for name in _VECTORS})
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    try:
        store.write_bytes(e, buf.getvalue())
    except (OSError, ValueError) as exc:  # ValueError: the atomic writer's unwritable directory
        warnings.warn(f"film operators not cached in {e.payload.parent}: {exc}", stacklevel=2)
        return None
    store.prune(e.payload.parent, _PAYLOADS, budget_bytes(), keep=(e.payload,))
    return e.payload


def _ops(fh, e: store.Entry) -> FilmOperators:
    """The operators in the payload open as ``fh`` (every member read in full, so zipfile
    checks its CRC-32); CacheMiss when unreadable, corrupt or inconsistent."""
    try:
        with np.load(fh, allow_pickle=False) as z:
            if str(z["key"]) != e.key:
                raise ValueError("stored key differs")
            shape = tuple(int(s) for s in z["shape"])
            indices, indptr = z["indices"], z["indptr"]
            mats = {name: shared_csr(z[name], indices, indptr, shape) for name in _PATTERNED}
            if any(m.data.size != indices.size for m in mats.values()) or indptr.size != shape[0] + 1:
                raise ValueError("array sizes are inconsistent")
            R = sp.csr_matrix((z["R_data"], z["R_indices"], z["R_indptr"]), shape=shape)
            vecs = {name: z[name] for name in _VECTORS}
            E, nu, b_n = (float(v) for v in z["scalars"])
    except zipfile.BadZipFile as exc:
        raise store.CacheMiss(f"{e.payload.name} fails its zip checks (CRC-32 checksum or structure): {exc}; "
                              "corrupt") from None
    except (OSError, ValueError, KeyError, EOFError) as exc:
        raise store.CacheMiss(f"{e.payload.name} unreadable: {type(exc).__name__}: {exc}") from None
    return FilmOperators(R=R, youngs_modulus_MPa=E, poisson_ratio=nu, b_n=b_n, **mats, **vecs)


def load_film_ops(e: store.Entry) -> FilmOperators | None:
    """The stored operators of ``e``, or None when absent; a damaged entry is None with a
    :class:`fea.store.CacheWarning` (the caller assembles and stores them again)."""
    try:
        fh, _ = store.open_checked(e)
        with fh:
            ops = _ops(fh, e)
        store.touch(e)
        return ops
    except FileNotFoundError:
        return None
    except store.CacheMiss as exc:
        ops = _without_sidecar(e)
        if ops is None:
            store.warn_rebuild(e, exc, "film-operator cache")
        return ops


def _without_sidecar(e: store.Entry) -> FilmOperators | None:
    """The operators of a payload that has no sidecar but is whole and holds ``e.key``
    (its sidecar is then written), else None."""
    if e.sidecar.exists() or not e.payload.is_file():
        return None
    try:
        data = e.payload.read_bytes()
        ops = _ops(io.BytesIO(data), e)
    except (OSError, store.CacheMiss):
        return None
    try:
        store.commit(e, data=data)
    except (OSError, ValueError):  # a read-only cache: the operators are still good
        pass
    return ops
