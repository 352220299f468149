"""On-disk cache of the assembled film operators of a mesh.

Why: assembling the thickness-independent film operators of the five coatable surface
groups takes ~12 s at the default mesh, and every new process (each CLI call, each
sweep worker, each test worker) paid it again; loading them takes well under a second.

A file holds one :class:`fea.assembly.FilmOperators` (one surface group, one film
material, after the symmetry-plane treatment of :meth:`fea.model.PreparedBlank.film_ops`)::

    <cache_dir>/filmops-<sha256[:24]>.npz

The key hashes the mesh arrays themselves (node positions, connectivity, the group's
facets), the film's elastic constants, the constrained DOFs, :data:`fea.MODEL_VERSION`
and :data:`FORMAT_VERSION`: a file can only be found for exactly the operators it holds.
Corruption is caught by the zip CRC of every member (``numpy.load`` reads whole members);
an unreadable or inconsistent file is ignored and rebuilt, never used.
"""

from __future__ import annotations

import hashlib
import os
import warnings
import zipfile
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from . import MODEL_VERSION
from .assembly import FilmOperators, shared_csr
from .mesh_cache import atomic_file

__all__ = ["FORMAT_VERSION", "operator_key", "load_film_ops", "save_film_ops"]

#: Bump when the stored arrays or their meaning change; old files then miss.
FORMAT_VERSION = 1

_PATTERNED = ("A00", "A00k", "A0C", "A0Ck", "ACC", "ACCk")
_VECTORS = ("f0", "f0k", "fC", "fCk", "gL0", "gL0k", "gLC", "gLCk")


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


def _path(cache_dir: Path, key: str) -> Path:
    return Path(cache_dir) / f"filmops-{key[:24]}.npz"


def save_film_ops(cache_dir: Path, key: str, ops: FilmOperators) -> Path | None:
    """Store ``ops`` atomically; returns the path, or None when it cannot be cached
    (operators without one shared pattern, or an unwritable directory: a warning)."""
    if not ops.shares_pattern():
        return None
    arrays = {"key": np.array(key), "indices": ops.A00.indices, "indptr": ops.A00.indptr,
              "shape": np.array(ops.A00.shape), "R_data": ops.R.data, "R_indices": ops.R.indices,
              "R_indptr": ops.R.indptr,
              "scalars": np.array([ops.youngs_modulus_MPa, ops.poisson_ratio, ops.b_n])}
    arrays.update({name: getattr(ops, name).data for name in _PATTERNED})
    arrays.update({name: np.broadcast_to(np.asarray(getattr(ops, name), float), ops.f0.shape)
                   for name in _VECTORS})
    path = _path(cache_dir, key)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_file(path) as fh:
            np.savez(fh, **arrays)
        os.chmod(path, 0o666 & ~_umask())
    except OSError as exc:
        warnings.warn(f"film operators not cached in {path.parent}: {exc}", stacklevel=2)
        return None
    return path


def load_film_ops(cache_dir: Path, key: str) -> FilmOperators | None:
    """The stored operators for ``key``, or None when absent, stale or unreadable."""
    path = _path(cache_dir, key)
    if not path.is_file():
        return None
    try:
        with np.load(path, allow_pickle=False) as z:
            if str(z["key"]) != key:
                raise ValueError("stored key differs")
            shape = tuple(int(s) for s in z["shape"])
            indices, indptr = z["indices"], z["indptr"]
            mats = {name: shared_csr(z[name], indices, indptr, shape) for name in _PATTERNED}
            if any(m.data.size != indices.size for m in mats.values()) or indptr.size != shape[0] + 1:
                raise ValueError("array sizes are inconsistent")
            R = sp.csr_matrix((z["R_data"], z["R_indices"], z["R_indptr"]), shape=shape)
            vecs = {name: z[name] for name in _VECTORS}
            E, nu, b_n = (float(v) for v in z["scalars"])
    except (OSError, ValueError, KeyError, zipfile.BadZipFile, EOFError) as exc:
        warnings.warn(f"ignoring unreadable film-operator cache {path.name} ({exc}); rebuilding",
                      stacklevel=2)
        return None
    return FilmOperators(R=R, youngs_modulus_MPa=E, poisson_ratio=nu, b_n=b_n, **mats, **vecs)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask
