"""On-disk cache of sweep cases: canonical keys, result validation, atomic files.

One case is two files in ``<out_dir>/cases/``:

``<key>.npz``
    every output as an array (scalars as 0-d arrays), written with
    ``allow_pickle=False`` semantics so loading never executes code;
``<key>.json``
    the params, namespace, key, elapsed seconds, library version and a manifest of
    the outputs (kind and, for labelled arrays, dimension names).

The ``.npz`` is written first and the ``.json`` last, each through a temporary file
in the same directory and :func:`os.replace` (:func:`pipeline.io_common.atomic_write`), so the ``.json`` is the commit marker:
a case counts as done only when both files exist, load cleanly and agree with the
requested params.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from pipeline.io_common import atomic_write

__all__ = [
    "canonical_token",
    "canonical_json",
    "case_key",
    "normalise_result",
    "save_case",
    "load_case",
    "CacheMiss",
    "library_version",
]

# JSON manifest format of the per-case .json file; bump when the layout changes.
FORMAT_VERSION = 1
COORD_PREFIX = "coord:"


class CacheMiss(Exception):
    """A cached case cannot be used; ``str(exc)`` says why (shown in the warning)."""


def library_version() -> str:
    """Installed cryograting version, or ``"unknown"`` when not installed."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("cryograting")
    except PackageNotFoundError:
        return "unknown"


def canonical_token(value: object) -> str:
    """JSON text of one parameter value, identical for numerically equal numbers.

    Integral numbers are written as integers (so ``200 == 200.0``) and other floats
    with 12 significant digits, so values that differ only by floating-point noise
    (``0.1 + 0.2`` vs ``0.3``, a range built by repeated addition) share a cache
    entry. Booleans and strings stay distinct from numbers (``True != 1``,
    ``"200" != 200``) because JSON types them differently.
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


def canonical_json(params: Mapping[str, object]) -> str:
    """Canonical JSON of ``params``: sorted keys, no spaces, canonical numbers."""
    items = (f"{json.dumps(k, ensure_ascii=False)}:{canonical_token(params[k])}" for k in sorted(params))
    return "{" + ",".join(items) + "}"


def case_key(namespace: str, params: Mapping[str, object]) -> str:
    """sha256 hex digest of ``namespace`` and the canonical JSON of ``params``."""
    import hashlib

    # The newline separates namespace from JSON so ("a", '{"b"...') can't alias.
    return hashlib.sha256(f"{namespace}\n{canonical_json(params)}".encode()).hexdigest()


def normalise_result(result: object, param_names=()) -> dict:
    """Validate a case function's return value and bring it to canonical form.

    Returns a dict whose values are Python scalars (``bool``/``int``/``float``/``str``),
    ``np.ndarray`` or ``(dims, np.ndarray)`` with ``dims`` a tuple of str. Keys starting
    with ``"coord:"`` must be 1-D arrays (coordinates of labelled dimensions).

    Raises
    ------
    TypeError, ValueError
        naming the offending output; the sweep reports it as a failure of the case.
    """
    if not isinstance(result, Mapping):
        raise TypeError(f"case function must return a dict of outputs, got {type(result).__name__}")
    out: dict = {}
    for name, value in result.items():
        if not isinstance(name, str) or not name or "/" in name:
            raise ValueError(f"output name {name!r} must be a non-empty str without '/'")
        if name in param_names:
            raise ValueError(f"output {name!r} has the same name as a parameter; rename one of them")
        out[name] = _normalise_value(name, value)
        if name.startswith(COORD_PREFIX) and not (isinstance(out[name], np.ndarray) and out[name].ndim == 1):
            raise ValueError(f"coordinate output {name!r} must be a 1-D np.ndarray, got {value!r:.60}")
    return out


def _normalise_value(name: str, value: object):
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, (bool, int, float, str)):
        return value
    if isinstance(value, np.ndarray):
        return _check_array(name, value)
    if (isinstance(value, tuple) and len(value) == 2 and isinstance(value[0], (tuple, list))
            and all(isinstance(d, str) for d in value[0])):
        dims, arr = tuple(value[0]), np.asarray(value[1])
        _check_array(name, arr)
        if len(dims) != arr.ndim or len(set(dims)) != len(dims):
            raise ValueError(f"output {name!r}: dims {dims} must be {arr.ndim} distinct names for shape {arr.shape}")
        return dims, arr
    raise TypeError(
        f"output {name!r} has unsupported type {type(value).__name__}; use a scalar "
        "(float/int/str/bool), an np.ndarray, or (dims_tuple, array)"
    )


def _check_array(name: str, arr: np.ndarray) -> np.ndarray:
    # Object arrays would need pickle to store; refuse them rather than risk code execution on load.
    if arr.dtype.hasobject:
        raise TypeError(f"output {name!r}: object arrays are not supported (dtype {arr.dtype})")
    return arr


def save_case(cases_dir: Path, key: str, namespace: str, params: dict, result: dict, elapsed_s: float,
              version: str) -> None:
    """Store one normalised ``result`` as ``<key>.npz`` then ``<key>.json`` (the commit marker).

    ``version`` is the library version recorded in the json (looked up once per sweep
    by the caller: :func:`library_version` costs ~1 ms).
    """
    arrays, manifest = {}, {}
    for name, value in result.items():
        if isinstance(value, tuple):
            arrays[name] = value[1]
            manifest[name] = {"kind": "labelled", "dims": list(value[0])}
        else:
            arrays[name] = np.asarray(value)
            manifest[name] = {"kind": "array" if isinstance(value, np.ndarray) else "scalar"}
    with atomic_write(cases_dir / f"{key}.npz", "wb") as fh:
        np.savez(fh, **arrays)
    meta = {
        "format": FORMAT_VERSION,
        "key": key,
        "namespace": namespace,
        "params": params,
        "elapsed_s": elapsed_s,
        "version": version,
        "outputs": manifest,
    }
    text = json.dumps(meta, indent=1, ensure_ascii=False).encode()
    with atomic_write(cases_dir / f"{key}.json", "wb") as fh:
        fh.write(text)


def load_case(cases_dir: Path, key: str, namespace: str, params: dict) -> tuple[dict, dict]:
    """Load a cached case as ``(result, meta)``.

    Raises
    ------
    FileNotFoundError
        neither file exists (a plain miss, not worth a warning).
    CacheMiss
        the files exist but are incomplete, corrupt or describe other params.
    """
    npz, js = cases_dir / f"{key}.npz", cases_dir / f"{key}.json"
    if not npz.exists() and not js.exists():
        raise FileNotFoundError(npz)
    try:
        meta = json.loads(js.read_text())
    except FileNotFoundError:
        raise CacheMiss(f"{npz.name} has no {js.name} (run killed between the two writes?)") from None
    except (OSError, ValueError) as exc:
        raise CacheMiss(f"{js.name} unreadable: {exc}") from None
    try:
        same = (meta["key"] == key and meta["namespace"] == namespace
                and canonical_json(meta["params"]) == canonical_json(params))
        manifest = meta["outputs"]
    except (KeyError, TypeError, ValueError) as exc:
        raise CacheMiss(f"{js.name} malformed: {exc!r}") from None
    if not same:
        raise CacheMiss(f"{js.name} describes namespace {meta.get('namespace')!r}, params {meta.get('params')}")
    try:
        # Reading every member checks each zip CRC, so a truncated file is caught here.
        # Our own file handle: np.load leaks its handle when the zip directory is bad.
        with open(npz, "rb") as f, np.load(f, allow_pickle=False) as data:
            arrays = {name: data[name] for name in data.files}
    except Exception as exc:  # zipfile.BadZipFile, OSError, ValueError, EOFError, ...
        raise CacheMiss(f"{npz.name} unreadable: {type(exc).__name__}: {exc}") from None
    if set(arrays) != set(manifest):
        raise CacheMiss(f"{npz.name} holds {sorted(arrays)}, {js.name} lists {sorted(manifest)}")
    result = {}
    for name, info in manifest.items():
        arr = arrays[name]
        kind = info.get("kind")
        if kind == "scalar":
            result[name] = arr.item()
        elif kind == "labelled":
            result[name] = (tuple(info["dims"]), arr)
        else:
            result[name] = arr
    return result, meta
