"""gmsh -> scikit-fem conversion and the on-disk mesh cache.

Shared by :mod:`fea.mesh` (the blank) and :mod:`fea.verification.cell` (the verification
slice).  Two questions live here because both are about *getting a
``MeshTet2`` into memory*: from a live gmsh model, or from a verified file.

Cache layout (see ``meshes/README.md``)::

    <cache_dir>/<kind>-<sha256[:20]>.npz   doflocs, t, b_<boundary>, s_<subdomain>
    <cache_dir>/<kind>-<sha256[:20]>.json  recipe, gmsh version, date, npz sha256

The key is the sha256 of the canonical JSON of the recipe (every geometry and
mesh parameter, the gmsh version and :data:`FORMAT_VERSION`).
"""

from __future__ import annotations

import contextlib
import datetime
import hashlib
import io
import json
import os
import tempfile
import uuid
import warnings
from pathlib import Path
from typing import Callable

import numpy as np
from skfem import MeshTet1, MeshTet2

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
def _sha256_file(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


@contextlib.contextmanager
def atomic_file(path: Path):
    """Binary file handle whose content replaces ``path`` only when the block succeeds
    (temporary file beside it, fsync, rename); on error no file is left behind."""
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name + ".",
                               suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def _atomic_write(path: Path, data: bytes) -> None:
    with atomic_file(path) as fh:
        fh.write(data)


def _store(mesh: MeshTet2, npz: Path, sidecar: Path, recipe: dict,
           key: str) -> None:
    arrays = {"doflocs": mesh.doflocs, "t": mesh.t}
    arrays.update({"b_" + k: np.asarray(v) for k, v in
                   (mesh.boundaries or {}).items()})
    arrays.update({"s_" + k: np.asarray(v) for k, v in
                   (mesh.subdomains or {}).items()})
    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays)
    _atomic_write(npz, buf.getvalue())
    meta = {
        "key": key,
        "recipe": recipe,
        "created_utc": datetime.datetime.now(datetime.timezone.utc)
        .isoformat(timespec="seconds"),
        "npz_sha256": _sha256_file(npz),
        "n_vertices": int(mesh.nvertices),
        "n_elements": int(mesh.nelements),
        "n_dofs_vector_p2": int(3 * mesh.doflocs.shape[1]),
    }
    # the sidecar is written last: it marks the npz as complete
    _atomic_write(sidecar, (json.dumps(meta, indent=1, sort_keys=True)
                            + "\n").encode())


def _load(npz: Path, sidecar: Path, key: str) -> MeshTet2:
    """Load and verify; raise ValueError with the reason on any mismatch."""
    meta = json.loads(sidecar.read_text())
    if meta.get("key") != key:
        raise ValueError("sidecar key does not match the recipe")
    if _sha256_file(npz) != meta.get("npz_sha256"):
        raise ValueError("npz checksum mismatch (corrupt or truncated)")
    with np.load(npz) as data:
        arrays = {k: data[k] for k in data.files}
    doflocs, t = arrays["doflocs"], arrays["t"]
    if doflocs.ndim != 2 or doflocs.shape[0] != 3 or t.ndim != 2 \
            or t.shape[0] != 4 or not np.all(np.isfinite(doflocs)):
        raise ValueError("array shapes are inconsistent")
    if t.min() < 0 or t.max() >= doflocs.shape[1]:
        raise ValueError("connectivity indexes missing nodes")
    boundaries = {k[2:]: v for k, v in arrays.items() if k.startswith("b_")}
    subdomains = {k[2:]: v for k, v in arrays.items() if k.startswith("s_")}
    mesh = MeshTet2(doflocs, t, _boundaries=boundaries,
                    _subdomains=subdomains)
    if doflocs.shape[1] != mesh.nvertices + mesh.nedges:
        raise ValueError("node count does not match the P2 dof count")
    for v in boundaries.values():
        if v.size and (v.min() < 0 or v.max() >= mesh.nfacets):
            raise ValueError("boundary facet index out of range")
    for v in subdomains.values():
        if v.size and (v.min() < 0 or v.max() >= mesh.nelements):
            raise ValueError("subdomain element index out of range")
    if meta.get("n_elements") != mesh.nelements:
        raise ValueError("element count differs from the sidecar")
    return mesh


def cached_mesh(kind: str, recipe: dict, build: Callable[[], MeshTet2],
                cache_dir: Path | None = None) -> MeshTet2:
    """Return the mesh for ``recipe`` from ``cache_dir``, building if needed.

    A missing, corrupt, truncated or stale file is rebuilt (with a
    ``UserWarning`` for the damaged cases), never used.
    """
    cache_dir = Path(cache_dir) if cache_dir is not None \
        else default_cache_dir()
    cache_dir.mkdir(parents=True, exist_ok=True)
    key = recipe_key(recipe)
    stem = f"{kind}-{key[:20]}"
    npz, sidecar = cache_dir / f"{stem}.npz", cache_dir / f"{stem}.json"
    if npz.exists() and sidecar.exists():
        try:
            return _load(npz, sidecar, key)
        except Exception as exc:  # any damage means: rebuild
            warnings.warn(f"mesh cache entry {npz} is unusable ({exc}); "
                          "rebuilding it", stacklevel=3)
    elif npz.exists() or sidecar.exists():
        warnings.warn(f"mesh cache entry {stem} is incomplete; rebuilding it",
                      stacklevel=3)
    mesh = build()
    _store(mesh, npz, sidecar, recipe, key)
    return mesh
