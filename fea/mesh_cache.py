"""gmsh -> scikit-fem conversion and the on-disk mesh cache.

Shared by :mod:`fea.mesh` (the blank) and :mod:`fea.verification.cell` (the verification
slice).  Two questions live here because both are about *getting a
``MeshTet2`` into memory*: from a live gmsh model, or from a verified file.

Cache layout (see ``meshes/README.md``): each mesh is one :mod:`fea.store` entry::

    <cache_dir>/<kind>-<sha256[:20]>.npz   doflocs, t, b_<boundary>, s_<subdomain>
    <cache_dir>/<kind>-<sha256[:20]>.json  the store's sidecar: recipe, key, sha256, counts, date

The key is the sha256 of the sorted, compact JSON of the recipe (every geometry and
mesh parameter, the gmsh version and :data:`FORMAT_VERSION`), :func:`recipe_key`.
"""

from __future__ import annotations

import contextlib
import ctypes
import datetime
import hashlib
import io
import json
import os
import signal
import threading
import uuid
from pathlib import Path
from typing import Callable

import numpy as np
from skfem import MeshTet1, MeshTet2

from . import store

__all__ = ["FORMAT_VERSION", "default_cache_dir", "recipe_key",
           "cached_mesh", "gmsh_session", "tet2_from_gmsh"]

#: Bump when the stored arrays or their meaning change; old files then miss.
FORMAT_VERSION = 1

# gmsh element type 11 = 10-node tetrahedron, 9 = 6-node triangle.  Local
# node k >= 4 of a gmsh tet10 is the midpoint of these corner pairs
# (gmsh.model.mesh.getElementProperties(11)); checked in tet2_from_gmsh.
_GMSH_TET10_EDGES = ((0, 1), (1, 2), (2, 0), (3, 0), (3, 2), (3, 1))


def default_cache_dir() -> Path:
    """``$CRYOGRATING_MESH_CACHE`` or ``<repo>/meshes/cache``."""
    env = os.environ.get("CRYOGRATING_MESH_CACHE")
    if env:
        return Path(env)
    return Path(__file__).resolve().parent.parent / "meshes" / "cache"


def recipe_key(recipe: dict) -> str:
    """sha256 hex digest of the canonical JSON of ``recipe``."""
    blob = json.dumps(recipe, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(blob.encode()).hexdigest()


# --- gmsh ------------------------------------------------------------------
def reapply_python_sigpipe() -> None:
    """Give SIGPIPE back the disposition Python believes it has (call after ``gmsh.initialize``).

    ``gmsh.initialize`` resets SIGPIPE to the default action, terminate the process, in C and
    behind Python's back: ``signal.getsignal`` still reports ``SIG_IGN``. From then on a write
    to a pipe whose reader has gone kills the process with no traceback instead of raising
    ``BrokenPipeError``: a sweep whose worker process dies (segfault, OOM kill) took the
    parent with it, exit status 141. Dispositions are process-wide; ``signal.signal`` may only
    be called from the main thread, so other threads restore the startup ``SIG_IGN`` through
    libc.
    """
    if not hasattr(signal, "SIGPIPE"):
        return
    handler = signal.getsignal(signal.SIGPIPE)
    if handler is None:  # installed outside Python: not ours to change
        return
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGPIPE, handler)
    elif handler == signal.SIG_IGN:
        libc_signal = ctypes.CDLL(None).signal
        libc_signal.restype = ctypes.c_void_p
        libc_signal(int(signal.SIGPIPE), ctypes.c_void_p(int(signal.SIG_IGN)))


@contextlib.contextmanager
def gmsh_session(progress: bool = False, n_threads: int = 1):
    """Initialise gmsh (if needed), open a fresh model, always clean up.

    If the caller already initialised gmsh we only add and remove our own
    model, so their state survives; otherwise we finalise on exit.
    ``n_threads=1`` by default because threaded HXT meshing is not
    reproducible (measured: 2 threads give a different mesh on every run,
    and were not faster on this problem size).
    """
    import gmsh
    owns = not gmsh.isInitialized()
    if owns:
        # interruptible=False: gmsh must not install a SIGINT handler when
        # called from worker threads (pytest-xdist, notebooks)
        gmsh.initialize(readConfigFiles=False, interruptible=False)
        reapply_python_sigpipe()
    try:
        gmsh.option.setNumber("General.Terminal", 1 if progress else 0)
        gmsh.option.setNumber("General.Verbosity", 5 if progress else 1)
        gmsh.option.setNumber("General.NumThreads", n_threads)
        gmsh.model.add(f"cryograting-{uuid.uuid4().hex}")
        try:
            yield gmsh
        finally:
            gmsh.model.remove()
    finally:
        if owns:
            gmsh.finalize()


def _lookup(keys_sorted, order, query, what):
    pos = np.searchsorted(keys_sorted, query)
    pos = np.clip(pos, 0, len(keys_sorted) - 1)
    if not np.all(keys_sorted[pos] == query):
        raise RuntimeError(f"{what}: {np.sum(keys_sorted[pos] != query)} "
                           "gmsh entities have no match in the skfem mesh")
    return order[pos]


def tet2_from_gmsh(gmsh, surface_groups: dict, volume_groups: dict) -> MeshTet2:
    """Convert the current gmsh model (second-order tets) to ``MeshTet2``.

    Mid-edge nodes are taken from gmsh, so they lie on curved CAD surfaces.

    Parameters
    ----------
    gmsh : module
        The initialised gmsh module with a meshed model of order 2.
    surface_groups : dict[str, int]
        Boundary name -> physical-group tag (dim 2).
    volume_groups : dict[str, int]
        Subdomain name -> physical-group tag (dim 3).

    Returns
    -------
    skfem.MeshTet2
        With ``boundaries`` (skfem facet indices) and ``subdomains``
        (element indices).
    """
    node_tags, coords, _ = gmsh.model.mesh.getNodes()
    coords = coords.reshape(-1, 3)
    tag_to_row = np.full(int(node_tags.max()) + 1, -1, dtype=np.int64)
    tag_to_row[node_tags.astype(np.int64)] = np.arange(len(node_tags))

    elem_tags, elem_nodes = gmsh.model.mesh.getElementsByType(11)
    if len(elem_tags) == 0:
        raise RuntimeError("gmsh produced no 10-node tetrahedra")
    t10 = tag_to_row[elem_nodes.astype(np.int64).reshape(-1, 10)]
    corners, t4 = np.unique(t10[:, :4], return_inverse=True)
    t4 = np.ascontiguousarray(t4.reshape(-1, 4).T, dtype=np.int64)
    row_to_vertex = np.full(len(node_tags), -1, dtype=np.int64)
    row_to_vertex[corners] = np.arange(len(corners))
    nv = len(corners)
    if nv**3 >= 2**63:  # facet keys below are base-nv triples in int64
        raise RuntimeError(f"{nv} vertices: too many for the facet lookup")

    m1 = MeshTet1(np.ascontiguousarray(coords[corners].T), t4)
    doflocs = MeshTet2.from_mesh(m1).doflocs.copy()

    # every gmsh mid-edge node, keyed by its sorted corner pair
    a = np.concatenate([t10[:, i] for i, _ in _GMSH_TET10_EDGES])
    b = np.concatenate([t10[:, j] for _, j in _GMSH_TET10_EDGES])
    mid = np.concatenate([t10[:, 4 + k] for k in range(6)])
    va, vb = row_to_vertex[a], row_to_vertex[b]
    straight = 0.5 * (coords[a] + coords[b])
    length = np.linalg.norm(coords[a] - coords[b], axis=1)
    if np.any(np.linalg.norm(coords[mid] - straight, axis=1) > 0.3 * length):
        raise RuntimeError("gmsh tet10 node ordering not as expected")
    lo, hi = np.minimum(va, vb), np.maximum(va, vb)
    keys = lo * nv + hi
    keys, first = np.unique(keys, return_index=True)
    edges = m1.edges  # (2, nedges), sorted per column
    rows = _lookup(keys, mid[first], edges[0].astype(np.int64) * nv
                   + edges[1], "mid-edge nodes")
    m2 = MeshTet2(doflocs, m1.t)
    doflocs[:, m2.dofs.edge_dofs[0]] = coords[rows].T

    # facets: key = sorted vertex triple in base nv
    f = np.sort(m1.facets.astype(np.int64), axis=0)
    fkeys = (f[0] * nv + f[1]) * nv + f[2]
    forder = np.argsort(fkeys)
    fkeys_sorted = fkeys[forder]
    boundaries = {}
    for name, ptag in surface_groups.items():
        tri = [gmsh.model.mesh.getElementsByType(9, s)[1]
               for s in gmsh.model.getEntitiesForPhysicalGroup(2, ptag)]
        tri = np.concatenate(tri).astype(np.int64).reshape(-1, 6)[:, :3]
        tri = np.sort(row_to_vertex[tag_to_row[tri]], axis=1).T
        q = (tri[0] * nv + tri[1]) * nv + tri[2]
        boundaries[name] = np.sort(_lookup(fkeys_sorted, forder, q,
                                           f"boundary {name!r}"))
    etag_to_elem = np.full(int(elem_tags.max()) + 1, -1, dtype=np.int64)
    etag_to_elem[elem_tags.astype(np.int64)] = np.arange(len(elem_tags))
    subdomains = {}
    for name, ptag in volume_groups.items():
        tags = [gmsh.model.mesh.getElementsByType(11, v)[0]
                for v in gmsh.model.getEntitiesForPhysicalGroup(3, ptag)]
        tags = np.concatenate(tags) if tags else np.zeros(0, np.int64)
        subdomains[name] = np.sort(etag_to_elem[tags.astype(np.int64)])
    return MeshTet2(doflocs, m1.t, _boundaries=boundaries,
                    _subdomains=subdomains)


# --- cache -----------------------------------------------------------------
def _entry(cache_dir: Path, kind: str, recipe: dict) -> store.Entry:
    """The store entry ``<kind>-<key[:20]>.npz`` + ``.json`` of ``recipe``."""
    return store.entry(cache_dir, f"fea.mesh_cache/{kind}", recipe, prefix=f"{kind}-",
                       format_version=FORMAT_VERSION, key=recipe_key(recipe), key_chars=20)


def _arrays(mesh: MeshTet2) -> dict:
    arrays = {"doflocs": mesh.doflocs, "t": mesh.t}
    arrays.update({"b_" + k: np.asarray(v) for k, v in (mesh.boundaries or {}).items()})
    arrays.update({"s_" + k: np.asarray(v) for k, v in (mesh.subdomains or {}).items()})
    return arrays


def _store(mesh: MeshTet2, e: store.Entry) -> None:
    buf = io.BytesIO()
    np.savez_compressed(buf, **_arrays(mesh))
    data = buf.getvalue()
    # npz_sha256 repeats the store's sha256 under the name a plain mesh-cache sidecar
    # uses, so readers of that layout sharing the directory keep finding the mesh
    store.write_bytes(e, data, {"created_utc": _now_utc(), "npz_sha256": hashlib.sha256(data).hexdigest(),
                                **_counts(mesh)})


def _now_utc() -> str:
    return datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")


def _counts(mesh: MeshTet2) -> dict:
    return {"n_vertices": int(mesh.nvertices), "n_elements": int(mesh.nelements),
            "n_dofs_vector_p2": int(3 * mesh.doflocs.shape[1])}


def _mesh(data: bytes, name: str) -> MeshTet2:
    """The mesh in verified ``.npz`` bytes; :class:`fea.store.CacheMiss` when inconsistent."""
    try:
        with np.load(io.BytesIO(data), allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
        doflocs, t = arrays["doflocs"], arrays["t"]
    except Exception as exc:  # zipfile.BadZipFile, KeyError, ValueError, ...
        raise store.CacheMiss(f"{name} unreadable: {type(exc).__name__}: {exc}") from None
    if doflocs.ndim != 2 or doflocs.shape[0] != 3 or t.ndim != 2 \
            or t.shape[0] != 4 or not np.all(np.isfinite(doflocs)):
        raise store.CacheMiss(f"{name}: array shapes are inconsistent")
    if t.min() < 0 or t.max() >= doflocs.shape[1]:
        raise store.CacheMiss(f"{name}: connectivity indexes missing nodes")
    boundaries = {k[2:]: v for k, v in arrays.items() if k.startswith("b_")}
    subdomains = {k[2:]: v for k, v in arrays.items() if k.startswith("s_")}
    mesh = MeshTet2(doflocs, t, _boundaries=boundaries, _subdomains=subdomains)
    if doflocs.shape[1] != mesh.nvertices + mesh.nedges:
        raise store.CacheMiss(f"{name}: node count does not match the P2 dof count")
    for v in boundaries.values():
        if v.size and (v.min() < 0 or v.max() >= mesh.nfacets):
            raise store.CacheMiss(f"{name}: boundary facet index out of range")
    for v in subdomains.values():
        if v.size and (v.min() < 0 or v.max() >= mesh.nelements):
            raise store.CacheMiss(f"{name}: subdomain element index out of range")
    return mesh


def _plain_sidecar(e: store.Entry) -> tuple[bytes, dict] | None:
    """The payload and sidecar of ``e`` when the sidecar is a plain mesh-cache one (``key``, ``recipe``,
    ``npz_sha256``, no store fields) that matches the key and the payload; else None.

    Such an entry is a complete mesh (its sidecar was also written last, atomically), so
    it is taken over by writing the store's sidecar instead of running gmsh again.
    """
    try:
        side = json.loads(e.sidecar.read_bytes())
        # the key is the sha256 of the recipe, so an equal key means an equal recipe
        if not isinstance(side, dict) or "store" in side or side.get("key") != e.key:
            return None
        data = e.payload.read_bytes()
    except (OSError, ValueError):
        return None
    return (data, side) if hashlib.sha256(data).hexdigest() == side.get("npz_sha256") else None


def _load(e: store.Entry) -> MeshTet2:
    """The verified mesh of ``e``; FileNotFoundError (plain miss) or CacheMiss (damaged)."""
    try:
        data, side = store.read_bytes(e)
    except store.CacheMiss:
        plain = _plain_sidecar(e)
        if plain is None:
            raise
        data, side = plain
        mesh = _mesh(data, e.payload.name)
        store.commit(e, {"created_utc": side.get("created_utc") or _now_utc(),
                         "npz_sha256": side["npz_sha256"], **_counts(mesh)}, data=data)
        return mesh
    mesh = _mesh(data, e.payload.name)
    if side.get("n_elements") != mesh.nelements:
        raise store.CacheMiss(f"{e.payload.name}: element count differs from the sidecar")
    return mesh


def cached_mesh(kind: str, recipe: dict, build: Callable[[], MeshTet2],
                cache_dir: Path | None = None) -> MeshTet2:
    """Return the mesh for ``recipe`` from ``cache_dir``, building if needed.

    The mesh is a :mod:`fea.store` entry named ``<kind>-<recipe_key[:20]>`` (namespace
    ``fea.mesh_cache/<kind>``, parameters the recipe). A missing, corrupt, truncated or
    stale file is rebuilt (with a :class:`fea.store.CacheWarning` for the damaged cases),
    never used.
    """
    cache_dir = Path(cache_dir) if cache_dir is not None \
        else default_cache_dir()
    cache_dir.mkdir(parents=True, exist_ok=True)
    e = _entry(cache_dir, kind, recipe)
    try:
        return _load(e)
    except FileNotFoundError:
        pass
    except store.CacheMiss as exc:
        store.warn_rebuild(e, exc, "mesh cache entry")
    mesh = build()
    _store(mesh, e)
    return mesh
