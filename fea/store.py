"""One keyed result store: every disk cache of cryograting keeps its results here.

An entry is a *payload* file (any bytes: an ``.npz`` of arrays, a PNG) and a JSON
*sidecar* beside it. The key is the sha256 of a namespace (what the result means:
the code and model version that produced it) and the canonical JSON of the
parameters (see :func:`entry_key`); a cache whose parameters include whole arrays
(the film operators hash the mesh) or whose file names are fixed otherwise (the
meshes, ``meshes/README.md``) passes its own ``key`` instead. The sidecar records::

    store      layout version of the sidecar itself (:data:`STORE_FORMAT`)
    format     the caller's payload format version
    namespace, key, params
    payload    file name of the payload
    sha256     checksum of the payload bytes, size_bytes their number
    version    cryograting version that wrote it (recorded, never compared)

plus any extra fields of the caller. The payload is written first and the sidecar
last, each atomically (temporary file + :func:`os.replace`), so the sidecar is the
commit marker. Loading checks every field against the request and the checksum
against the payload's bytes *as read*, so a file that is truncated, corrupt, stale
or that belongs to another key (two files swapped) is never used: it raises
:class:`CacheMiss` with the reason, and the caller warns (:func:`warn_rebuild`) and
rebuilds.

A payload whose format checks its own bytes as they are read (an ``.npz``: zipfile
compares every member's CRC-32 with the one stored beside it when the member has been
read to its end) may be opened with :func:`open_checked` instead: the sidecar and the
payload's size are checked, the content is left to the format's own checksums, and the
sha256 pass over the whole file is skipped (the film operators: ~700 MB, the sha256 pass
was most of a warm load). The sidecar still records the sha256; :func:`verify` checks it.

It lives in the FEA layer so that the mesh and film-operator caches
(:mod:`fea.mesh_cache`, :mod:`fea.operator_cache`) use it as well as the pipeline's
caches (sweep cases, nominal maps, kept fields, renders), without an upward import.
"""

from __future__ import annotations

import functools
import hashlib
import io
import json
import math
import os
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .atomic import atomic_write

__all__ = [
    "STORE_FORMAT", "CacheMiss", "CacheWarning", "Entry", "entry", "entry_key", "canonical_token",
    "canonical_json", "library_version", "write_bytes", "commit", "read_sidecar", "read_bytes", "open_checked",
    "verify", "save_arrays", "load_arrays", "warn_rebuild", "touch", "prune",
]

#: Layout of the sidecar; bump when its fields change (every entry then rebuilds with a warning).
STORE_FORMAT = 1
#: Sidecar fields owned by the store; caller metadata may not use these names.
_RESERVED = ("store", "format", "namespace", "key", "params", "payload", "sha256", "size_bytes", "version")


class CacheMiss(Exception):
    """A stored entry cannot be used; ``str(exc)`` names the file and says why."""


class CacheWarning(UserWarning):
    """A stored entry was incomplete, corrupt, stale or another key's, and is being rebuilt."""


@functools.lru_cache(maxsize=1)  # ~1 ms per lookup, and every entry records it
def library_version() -> str:
    """Installed cryograting version, or ``"unknown"`` when not installed."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("cryograting")
    except PackageNotFoundError:
        return "unknown"


def canonical_token(value: object) -> str:
    """JSON text of one scalar parameter value, identical for numerically equal numbers.

    Integral numbers are written as integers (so ``200 == 200.0``) and other floats
    with 12 significant digits, so values that differ only by floating-point noise
    (``0.1 + 0.2`` vs ``0.3``, a range built by repeated addition) share a cache
    entry. Booleans and strings stay distinct from numbers (``True != 1``,
    ``"200" != 200``) because JSON types them differently.

    Raises
    ------
    ValueError
        a non-finite float.
    TypeError
        anything but bool, int, float or str.
    """
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if not math.isfinite(value):
            raise ValueError(f"non-finite value {value!r} has no canonical form")
        if value.is_integer():
            return str(int(value))
        return format(value, ".12g")
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)
    raise TypeError(f"unsupported parameter type {type(value).__name__}")


def _canonical(value: object) -> str:
    # Nested parameters (a render's list of cases) and None are allowed inside a key;
    # scalars go through canonical_token so a flat key is the same as before nesting existed.
    if value is None:
        return "null"
    if isinstance(value, Mapping):
        return canonical_json(value)
    if isinstance(value, (list, tuple)):
        return "[" + ",".join(_canonical(v) for v in value) + "]"
    return canonical_token(value)


def canonical_json(params: Mapping[str, object]) -> str:
    """Canonical JSON of ``params``: sorted keys, no spaces, canonical numbers (also nested)."""
    for k in params:
        if not isinstance(k, str):
            raise TypeError(f"parameter name {k!r} must be a str")
    items = (f"{json.dumps(k, ensure_ascii=False)}:{_canonical(params[k])}" for k in sorted(params))
    return "{" + ",".join(items) + "}"


def entry_key(namespace: str, params: Mapping[str, object]) -> str:
    """sha256 hex digest of ``namespace`` and the canonical JSON of ``params``."""
    # The newline separates namespace from JSON so ("a", '{"b"...') can't alias.
    return hashlib.sha256(f"{namespace}\n{canonical_json(params)}".encode()).hexdigest()


@dataclass(frozen=True)
class Entry:
    """Where one keyed result lives, and what it must be.

    Parameters
    ----------
    namespace : str
        Meaning of the result (code and model version); part of the key.
    params : mapping
        Parameters of the result (JSON-able: scalars, None, lists and dicts of them).
    payload : Path
        The result file.
    sidecar : Path
        Its JSON sidecar.
    format_version : int
        The caller's payload format; an entry written in another format is rebuilt.
    key : str, optional
        Hex digest that identifies the result; by default :func:`entry_key` of
        ``namespace`` and ``params``. A cache passes its own when its key covers more
        than JSON-able parameters (the film operators hash the mesh arrays) or its
        file names are fixed by another rule (the meshes); the sidecar's namespace and
        parameters are still checked.
    """

    namespace: str
    params: Mapping
    payload: Path
    sidecar: Path
    format_version: int = 1
    key: str | None = field(default=None, compare=False)

    def __post_init__(self):
        if not isinstance(self.namespace, str) or not self.namespace:
            raise ValueError(f"namespace={self.namespace!r} must be a non-empty str")
        object.__setattr__(self, "params", dict(self.params))
        object.__setattr__(self, "payload", Path(self.payload))
        object.__setattr__(self, "sidecar", Path(self.sidecar))
        if self.key is None:
            object.__setattr__(self, "key", entry_key(self.namespace, self.params))
        elif not (isinstance(self.key, str) and self.key and all(c in "0123456789abcdef" for c in self.key)):
            raise ValueError(f"key={self.key!r} must be a non-empty lower-case hex digest")


def entry(directory, namespace: str, params: Mapping, *, suffix: str = ".npz", prefix: str = "",
          format_version: int = 1, key: str | None = None, key_chars: int = 64) -> Entry:
    """The entry ``<directory>/<prefix><key><suffix>`` with sidecar ``<prefix><key>.json``.

    ``key`` as in :class:`Entry`; ``key_chars`` leading hex digits of it name the files
    (the whole key is in the sidecar and is checked on load).
    """
    key = entry_key(namespace, params) if key is None else key
    if not isinstance(key_chars, int) or not 1 <= key_chars <= 64:
        raise ValueError(f"key_chars={key_chars!r} must be an int in [1, 64]")
    stem = prefix + key[:key_chars]
    directory = Path(directory)
    return Entry(namespace, params, directory / f"{stem}{suffix}", directory / f"{stem}.json", format_version, key)


def _sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def commit(e: Entry, meta: Mapping | None = None, *, data: bytes | None = None) -> dict:
    """Write the sidecar of a payload already in place (the commit marker); returns it.

    ``data`` are the payload bytes when the caller has them (saves reading the file back).
    ``meta`` are extra JSON fields (e.g. elapsed seconds), returned again on load.
    """
    meta = dict(meta or {})
    clash = sorted(set(meta) & set(_RESERVED))
    if clash:
        raise ValueError(f"sidecar fields {clash} are reserved by the store; rename them")
    if data is None:
        data = e.payload.read_bytes()
    side = {"store": STORE_FORMAT, "format": e.format_version, "namespace": e.namespace, "key": e.key,
            "params": e.params, "payload": e.payload.name, "sha256": _sha256(data), "size_bytes": len(data),
            "version": library_version(), **meta}
    e.sidecar.parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(e.sidecar, "wb") as fh:
        fh.write(json.dumps(side, indent=1, ensure_ascii=False, default=str).encode())
    return side


def write_bytes(e: Entry, data: bytes, meta: Mapping | None = None) -> dict:
    """Store ``data`` as the payload, then its sidecar; returns the sidecar."""
    e.payload.parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(e.payload, "wb") as fh:
        fh.write(data)
    return commit(e, meta, data=data)


def read_sidecar(e: Entry) -> dict:
    """The sidecar of ``e``, checked against the request (not yet against the payload).

    Raises
    ------
    FileNotFoundError
        neither file exists (a plain miss, not worth a warning).
    CacheMiss
        the sidecar is missing, unreadable, of another format, or describes another
        key, namespace, parameters or payload.
    """
    if not e.sidecar.exists():
        if not e.payload.exists():
            raise FileNotFoundError(e.payload)
        raise CacheMiss(f"{e.payload.name} has no sidecar {e.sidecar.name} (killed before the commit?)")
    try:
        side = json.loads(e.sidecar.read_bytes())
    except (OSError, ValueError) as exc:
        raise CacheMiss(f"{e.sidecar.name} unreadable: {exc}") from None
    if not isinstance(side, dict):
        raise CacheMiss(f"{e.sidecar.name} malformed: not a JSON object")
    got = (side.get("store"), side.get("format"))
    if got != (STORE_FORMAT, e.format_version):
        raise CacheMiss(f"{e.sidecar.name} is in store/format version {got[0]}/{got[1]}, "
                        f"this version reads {STORE_FORMAT}/{e.format_version}")
    if side.get("key") != e.key:
        raise CacheMiss(f"{e.sidecar.name} belongs to key {str(side.get('key'))[:12]}..., "
                        f"not {e.key[:12]}...")
    try:
        same = side["namespace"] == e.namespace and canonical_json(side["params"]) == canonical_json(e.params)
    except (KeyError, TypeError, ValueError) as exc:
        raise CacheMiss(f"{e.sidecar.name} malformed: {exc!r}") from None
    if not same:
        raise CacheMiss(f"{e.sidecar.name} describes namespace {side.get('namespace')!r}, "
                        f"params {side.get('params')}")
    if side.get("payload") != e.payload.name:
        raise CacheMiss(f"{e.sidecar.name} is the sidecar of {side.get('payload')!r}, not {e.payload.name!r}")
    return side


def read_bytes(e: Entry) -> tuple[bytes, dict]:
    """The verified payload bytes of ``e`` and its sidecar.

    The checksum is taken over the bytes returned, so nothing can change between the
    check and the use.

    Raises
    ------
    FileNotFoundError, CacheMiss
        as :func:`read_sidecar`; also a missing payload, or one whose size or sha256
        differs from the sidecar's (truncated, corrupt, or another key's file).
    """
    side = read_sidecar(e)
    try:
        data = e.payload.read_bytes()
    except OSError as exc:
        raise CacheMiss(f"{e.payload.name} unreadable: {exc.strerror or exc}") from None
    if len(data) != side.get("size_bytes"):
        raise CacheMiss(f"{e.payload.name} has {len(data)} bytes, its sidecar records {side.get('size_bytes')} "
                        "(truncated or replaced)")
    if _sha256(data) != side.get("sha256"):
        raise CacheMiss(f"{e.payload.name} checksum differs from its sidecar's (corrupt, or another key's file)")
    return data, side


def open_checked(e: Entry):
    """The payload of ``e`` opened for binary reading, with its sidecar checked and its size
    (of the file opened, so nothing can swap it after the check) equal to the sidecar's;
    returns ``(file object, sidecar)``, the caller closes the file.

    The content is *not* hashed: only for payloads whose format checks its own bytes on
    reading (every member of an ``.npz`` read to its end: zip CRC-32), read in full by the
    caller (module docstring).

    Raises
    ------
    FileNotFoundError, CacheMiss
        as :func:`read_sidecar`; also a missing payload, or one whose size differs from the
        sidecar's (truncated or replaced).
    """
    side = read_sidecar(e)
    try:
        fh = open(e.payload, "rb")
    except OSError as exc:
        raise CacheMiss(f"{e.payload.name} unreadable: {exc.strerror or exc}") from None
    size = os.fstat(fh.fileno()).st_size
    if size != side.get("size_bytes"):
        fh.close()
        raise CacheMiss(f"{e.payload.name} has {size} bytes, its sidecar records {side.get('size_bytes')} "
                        "(truncated or replaced)")
    return fh, side


def verify(e: Entry) -> dict:
    """Check ``e`` as :func:`read_bytes` does; returns the sidecar."""
    return read_bytes(e)[1]


def save_arrays(e: Entry, arrays: Mapping[str, np.ndarray], meta: Mapping | None = None) -> dict:
    """Store named arrays as an uncompressed ``.npz`` payload; returns the sidecar."""
    buf = io.BytesIO()
    np.savez(buf, **{k: np.asarray(v) for k, v in arrays.items()})
    return write_bytes(e, buf.getvalue(), meta)


def load_arrays(e: Entry) -> tuple[dict, dict]:
    """The verified arrays of an ``.npz`` entry and its sidecar (no pickles are loaded).

    Raises
    ------
    FileNotFoundError, CacheMiss
        as :func:`read_bytes`, or a payload that is not a readable ``.npz``.
    """
    data, side = read_bytes(e)
    try:
        with np.load(io.BytesIO(data), allow_pickle=False) as z:
            arrays = {name: z[name] for name in z.files}
    except Exception as exc:  # zipfile.BadZipFile, ValueError, EOFError, ...
        raise CacheMiss(f"{e.payload.name} unreadable: {type(exc).__name__}: {exc}") from None
    return arrays, side


def warn_rebuild(e: Entry | Path, why: object, what: str = "cache entry", stacklevel: int = 3) -> None:
    """One-line :class:`CacheWarning`: which file is rebuilt and why."""
    path = e.payload if isinstance(e, Entry) else Path(e)
    warnings.warn(f"rebuilding {what} {path}: {why}", CacheWarning, stacklevel=stacklevel)


def touch(e: Entry) -> None:
    """Mark ``e`` as just used (its payload's modification time is now): :func:`prune`
    evicts the entries used longest ago first. A read-only cache is left as it is."""
    try:
        os.utime(e.payload)
    except OSError:
        pass


def prune(directory, pattern: str, budget_bytes: int, keep: tuple[Path, ...] = ()) -> list[Path]:
    """Delete the least recently used entries whose payloads match ``pattern`` in
    ``directory`` until their payloads take at most ``budget_bytes``; returns the
    payloads deleted.

    Recency is the payload's modification time (written, or :func:`touch`-ed on a
    hit). Payloads in ``keep`` (the entry just written) are never deleted, even when
    they alone exceed the budget. The payload goes first and its sidecar second, so a
    concurrent reader sees a missing payload (a miss, rebuilt) and never a sidecar's
    promise of a file that is half gone; a reader that already has the file open keeps
    reading it. Temporary files of writers in progress start with a dot and never match
    a pattern that starts with the cache's prefix.

    Parameters
    ----------
    directory : path
        The cache directory.
    pattern : str
        Glob of the payloads, e.g. ``"filmops-*.npz"``.
    budget_bytes : int
        Largest total size of the matching payloads kept, bytes (>= 0).
    keep : tuple of Path
        Payloads never deleted.
    """
    if not isinstance(budget_bytes, (int, np.integer)) or isinstance(budget_bytes, bool) or budget_bytes < 0:
        raise ValueError(f"budget_bytes={budget_bytes!r} must be an int >= 0")
    keep_names = {Path(k).name for k in keep}
    found = []
    for path in Path(directory).glob(pattern):
        if path.name.startswith(".") or path.suffix == ".json":
            continue
        try:
            st = path.stat()
        except OSError:  # deleted by another process meanwhile
            continue
        found.append((st.st_mtime, st.st_size, path))
    found.sort(key=lambda t: (t[0], t[2].name), reverse=True)  # newest first
    total, deleted = 0, []
    for _, size, path in found:
        total += size
        if total <= budget_bytes or path.name in keep_names:
            continue
        total -= size
        for victim in (path, path.with_suffix(".json")):
            try:
                victim.unlink()
            except FileNotFoundError:
                pass
            except OSError:  # read-only cache: nothing can be evicted
                return deleted
        deleted.append(path)
    return deleted
