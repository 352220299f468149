"""Sweep cases in the keyed result store: result validation and the case files.

One case is one :mod:`fea.store` entry in ``<out_dir>/cases/``:

``<key>.npz``
    every output as an array (scalars as 0-d arrays), loaded with
    ``allow_pickle=False`` so loading never executes code;
``<key>.json``
    the store's sidecar (namespace, params, key, sha256 of the ``.npz``, format and
    library version) plus the elapsed seconds and a manifest of the outputs (kind
    and, for labelled arrays, dimension names).

The ``.npz`` is written first and the ``.json`` last, both atomically, so the
``.json`` is the commit marker: a case counts as done only when both files exist,
the ``.json`` describes the requested params and the ``.npz`` bytes match its checksum.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np

from fea.store import (
    CacheMiss,
    canonical_json,
    canonical_token,
    entry,
    entry_key,
    library_version,
    load_arrays,
    save_arrays,
)

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

#: Payload format of a case entry; bump when the stored outputs change layout.
#: 2: the sidecar carries the payload's sha256 (entries of format 1 are recomputed).
FORMAT_VERSION = 2
COORD_PREFIX = "coord:"

#: Cache key of one case: sha256 of the namespace and the canonical JSON of the params.
case_key = entry_key


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


def _entry(cases_dir: Path, namespace: str, params: Mapping):
    return entry(cases_dir, namespace, params, suffix=".npz", format_version=FORMAT_VERSION)


def save_case(cases_dir: Path, key: str, namespace: str, params: dict, result: dict, elapsed_s: float) -> None:
    """Store one normalised ``result`` as ``<key>.npz`` then ``<key>.json`` (the commit marker).

    ``key`` must be :func:`case_key` of ``namespace`` and ``params`` (checked).
    """
    e = _entry(cases_dir, namespace, params)
    if e.key != key:
        raise ValueError(f"key {key[:12]}... is not the key of namespace {namespace!r} and params {params}")
    arrays, manifest = {}, {}
    for name, value in result.items():
        if isinstance(value, tuple):
            arrays[name] = value[1]
            manifest[name] = {"kind": "labelled", "dims": list(value[0])}
        else:
            arrays[name] = np.asarray(value)
            manifest[name] = {"kind": "array" if isinstance(value, np.ndarray) else "scalar"}
    save_arrays(e, arrays, {"elapsed_s": elapsed_s, "outputs": manifest})


def load_case(cases_dir: Path, key: str, namespace: str, params: dict) -> tuple[dict, dict]:
    """Load a cached case as ``(result, sidecar)``, verified against its key and checksum.

    Raises
    ------
    FileNotFoundError
        neither file exists (a plain miss, not worth a warning).
    CacheMiss
        the files exist but are incomplete, corrupt, of another format, another key's
        or describe other params.
    """
    e = _entry(cases_dir, namespace, params)
    if e.key != key:
        raise CacheMiss(f"key {key[:12]}... is not the key of namespace {namespace!r} and params {params}")
    arrays, meta = load_arrays(e)
    manifest = meta.get("outputs")
    if not isinstance(manifest, dict) or set(arrays) != set(manifest):
        raise CacheMiss(f"{e.payload.name} holds {sorted(arrays)}, {e.sidecar.name} lists "
                        f"{sorted(manifest) if isinstance(manifest, dict) else manifest!r}")
    result = {}
    for name, info in manifest.items():
        arr = arrays[name]
        kind = info.get("kind") if isinstance(info, dict) else None
        if kind == "scalar":
            result[name] = arr.item()
        elif kind == "labelled":
            result[name] = (tuple(info["dims"]), arr)
        else:
            result[name] = arr
    return result, meta
