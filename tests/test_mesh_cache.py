"""The mesh cache on the keyed store (:mod:`fea.mesh_cache` over :mod:`fea.store`).

A hand-made P2 mesh of a unit box stands in for gmsh (the meshing itself is tested in
``test_geometry_mesh.py``), so a rebuild is visible as a call of ``build``. The cases:
a cut or flipped file is rebuilt with a warning; an entry whose sidecar is a plain
mesh-cache one (written out here field by field, as ``meshes/README.md`` describes it)
is taken over without meshing again, unless its checksum fails; and the store's sidecar
still carries the fields such a plain reader checks.
"""

from __future__ import annotations

import hashlib
import io
import json
import warnings

import numpy as np
import pytest
from skfem import MeshTet1, MeshTet2

from fea.mesh_cache import cached_mesh, recipe_key
from fea.store import CacheWarning

RECIPE = {"kind": "box", "size_mm": 1.0, "n": 3, "gmsh_version": "test", "format_version": 1}


def _box() -> MeshTet2:
    m1 = MeshTet1.init_tensor(np.linspace(0, 1, 3), np.linspace(0, 1, 3), np.linspace(0, 1, 2))
    return (MeshTet2.from_mesh(m1).with_boundaries({"front": lambda x: np.isclose(x[2], 1.0)})
            .with_subdomains({"blank": lambda x: np.ones(x.shape[1], bool)}))


class Builder:
    """``build`` for cached_mesh that counts its calls."""

    def __init__(self):
        self.calls = 0

    def __call__(self) -> MeshTet2:
        self.calls += 1
        return _box()


def _same(a: MeshTet2, b: MeshTet2) -> None:
    assert np.array_equal(a.doflocs, b.doflocs) and np.array_equal(a.t, b.t)
    assert np.array_equal(a.boundaries["front"], b.boundaries["front"])
    assert np.array_equal(a.subdomains["blank"], b.subdomains["blank"])


def _files(tmp_path):
    stem = f"box-{recipe_key(RECIPE)[:20]}"
    return tmp_path / f"{stem}.npz", tmp_path / f"{stem}.json"


def _quiet_load(tmp_path, build):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        return cached_mesh("box", RECIPE, build, tmp_path)


def test_a_second_call_loads_the_mesh_without_building(tmp_path):
    build = Builder()
    first = cached_mesh("box", RECIPE, build, tmp_path)
    _same(_quiet_load(tmp_path, build), first)
    assert build.calls == 1
    npz, sidecar = _files(tmp_path)
    side = json.loads(sidecar.read_text())
    assert side["store"] == 1 and side["namespace"] == "fea.mesh_cache/box" and side["params"] == RECIPE
    # the fields a plain mesh-cache reader checks: the whole recipe key, the npz checksum, the count
    assert side["key"] == recipe_key(RECIPE) == hashlib.sha256(json.dumps(
        RECIPE, sort_keys=True, separators=(",", ":")).encode()).hexdigest()
    assert side["npz_sha256"] == hashlib.sha256(npz.read_bytes()).hexdigest()
    assert side["n_elements"] == 24


@pytest.mark.parametrize("damage", ["truncate", "flip_byte", "drop_sidecar"])
def test_a_damaged_mesh_file_is_rebuilt_with_a_warning(tmp_path, damage):
    build = Builder()
    good = cached_mesh("box", RECIPE, build, tmp_path)
    npz, sidecar = _files(tmp_path)
    raw = npz.read_bytes()
    if damage == "truncate":
        npz.write_bytes(raw[: len(raw) // 2])
    elif damage == "flip_byte":
        npz.write_bytes(raw[:100] + bytes([raw[100] ^ 0xFF]) + raw[101:])
    else:
        sidecar.unlink()
    with pytest.warns(CacheWarning, match=f"rebuilding mesh cache entry .*{npz.name}"):
        rebuilt = cached_mesh("box", RECIPE, build, tmp_path)
    assert build.calls == 2
    _same(rebuilt, good)
    _same(_quiet_load(tmp_path, build), good)  # the rebuilt entry is whole again
    assert build.calls == 2


def _plain_entry(tmp_path, mesh: MeshTet2) -> bytes:
    """The mesh as a plain mesh-cache entry: compressed npz, then a sidecar with the recipe,
    its key, the npz checksum and the counts (meshes/README.md)."""
    npz, sidecar = _files(tmp_path)
    buf = io.BytesIO()
    np.savez_compressed(buf, doflocs=mesh.doflocs, t=mesh.t, b_front=mesh.boundaries["front"],
                        s_blank=mesh.subdomains["blank"])
    npz.write_bytes(buf.getvalue())
    sidecar.write_text(json.dumps({
        "created_utc": "2020-01-02T03:04:05+00:00", "key": recipe_key(RECIPE), "recipe": RECIPE,
        "npz_sha256": hashlib.sha256(buf.getvalue()).hexdigest(), "n_vertices": 18, "n_elements": 24,
        "n_dofs_vector_p2": 225}, indent=1, sort_keys=True) + "\n")
    return buf.getvalue()


def test_a_plain_mesh_cache_entry_is_taken_over_without_meshing(tmp_path):
    build = Builder()
    payload = _plain_entry(tmp_path, _box())
    _same(_quiet_load(tmp_path, build), _box())
    assert build.calls == 0
    npz, sidecar = _files(tmp_path)
    side = json.loads(sidecar.read_text())  # now the store's sidecar, for the same bytes
    assert side["store"] == 1 and side["sha256"] == hashlib.sha256(payload).hexdigest()
    assert side["created_utc"] == "2020-01-02T03:04:05+00:00" and npz.read_bytes() == payload
    _same(_quiet_load(tmp_path, build), _box())
    assert build.calls == 0


def test_a_plain_entry_whose_checksum_fails_is_rebuilt(tmp_path):
    build = Builder()
    payload = _plain_entry(tmp_path, _box())
    npz, _ = _files(tmp_path)
    npz.write_bytes(payload[:-30])
    with pytest.warns(CacheWarning, match="rebuilding mesh cache entry"):
        _same(cached_mesh("box", RECIPE, build, tmp_path), _box())
    assert build.calls == 1
