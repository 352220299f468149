"""On-disk film-operator cache (a :mod:`fea.store` entry): a second process gets identical
operators; a corrupt, cut or foreign file is rebuilt, never used; a whole payload that
only lacks the store's sidecar is taken over."""
import json
import warnings

import numpy as np
import pytest

from fea.coating import Coating
from fea.mesh import MeshSpec, blank_mesh
from fea.geometry import Blank
from fea.model import PreparedBlank
from fea.store import CacheWarning

COARSE = MeshSpec(size_mm=5.0, size_bulk_mm=10.0)


@pytest.fixture(scope="module")
def mesh():
    return blank_mesh(Blank(), COARSE)


@pytest.mark.slow
def test_cached_operators_equal_assembled(mesh, tmp_path):
    fresh = PreparedBlank(mesh, operator_cache=None)
    first = PreparedBlank(mesh, operator_cache=tmp_path)
    first.film_ops("holes_x")
    assert len(list(tmp_path.glob("filmops-*.npz"))) == 1
    second = PreparedBlank(mesh, operator_cache=tmp_path)
    a, b = fresh.film_ops("holes_x"), second.film_ops("holes_x")
    assert b.shares_pattern()
    for name in ("A00", "A00k", "A0C", "A0Ck", "ACC", "ACCk", "R"):
        assert abs(getattr(a, name) - getattr(b, name)).max() == 0, name
    for name in ("f0", "fC", "gL0", "gLCk"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    c = Coating.symmetric(200, 0.5, "all")
    assert second.solve(c).sag.pv_um("center") == fresh.solve(c).sag.pv_um("center")


def test_corrupt_cache_file_is_rebuilt(mesh, tmp_path):
    PreparedBlank(mesh, operator_cache=tmp_path).film_ops("front")
    (path,) = tmp_path.glob("filmops-*.npz")
    raw = bytearray(path.read_bytes())
    raw[len(raw) // 2] ^= 0xFF  # flip a byte inside one stored array
    path.write_bytes(bytes(raw))
    model = PreparedBlank(mesh, operator_cache=tmp_path)
    with pytest.warns(CacheWarning, match=f"rebuilding film-operator cache .*{path.name}.*checksum"):
        ops = model.film_ops("front")
    ref = PreparedBlank(mesh, operator_cache=None).film_ops("front")
    assert abs(ops.A00 - ref.A00).max() == 0


def _same_ops(a, b):
    for name in ("A00", "A0C", "ACCk", "R"):
        assert abs(getattr(a, name) - getattr(b, name)).max() == 0, name
    np.testing.assert_array_equal(a.gLC, b.gLC)


def test_truncated_cache_file_is_rebuilt(mesh, tmp_path):
    PreparedBlank(mesh, operator_cache=tmp_path).film_ops("front")
    (path,) = tmp_path.glob("filmops-*.npz")
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    with pytest.warns(CacheWarning, match="truncated"):
        ops = PreparedBlank(mesh, operator_cache=tmp_path).film_ops("front")
    _same_ops(ops, PreparedBlank(mesh, operator_cache=None).film_ops("front"))
    with warnings.catch_warnings():  # the rebuilt entry is whole again
        warnings.simplefilter("error")
        _same_ops(PreparedBlank(mesh, operator_cache=tmp_path).film_ops("front"), ops)


def test_payload_without_sidecar_is_taken_over_when_it_holds_the_key(mesh, tmp_path):
    PreparedBlank(mesh, operator_cache=tmp_path).film_ops("front")
    (path,) = tmp_path.glob("filmops-*.npz")
    sidecar = path.with_suffix(".json")
    sidecar.unlink()  # a whole payload with its own key member, but no store sidecar
    payload = path.read_bytes()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ops = PreparedBlank(mesh, operator_cache=tmp_path).film_ops("front")
    _same_ops(ops, PreparedBlank(mesh, operator_cache=None).film_ops("front"))
    assert sidecar.is_file() and path.read_bytes() == payload  # sidecar added, payload kept


def test_another_keys_payload_without_sidecar_is_rebuilt(mesh, tmp_path):
    PreparedBlank(mesh, operator_cache=tmp_path).film_ops("front")
    PreparedBlank(mesh, operator_cache=tmp_path).film_ops("holes_x")
    front, holes = (next(p for p in tmp_path.glob("filmops-*.npz")
                         if json.loads(p.with_suffix(".json").read_text())["params"]["n_facets"] == n)
                    for n in (mesh.boundaries["front"].size, mesh.boundaries["holes_x"].size))
    front.with_suffix(".json").unlink()
    front.write_bytes(holes.read_bytes())  # the other group's file under this name, no sidecar
    with pytest.warns(CacheWarning, match="has no sidecar"):
        ops = PreparedBlank(mesh, operator_cache=tmp_path).film_ops("front")
    _same_ops(ops, PreparedBlank(mesh, operator_cache=None).film_ops("front"))


def test_other_film_material_does_not_hit(mesh, tmp_path):
    from fea.materials import AL6061_T6

    PreparedBlank(mesh, operator_cache=tmp_path).film_ops("front")
    PreparedBlank(mesh, operator_cache=tmp_path).film_ops("front", film=AL6061_T6)
    assert len(list(tmp_path.glob("filmops-*.npz"))) == 2


def test_a_flipped_byte_in_any_stored_array_is_rebuilt(mesh, tmp_path):
    """A warm load checks the payload's size and every member's zip CRC-32, not a sha256 of
    the file: a byte flipped at the start or the end of any member's data is found all the same."""
    import zipfile

    from fea import store
    from fea.operator_cache import load_film_ops

    PreparedBlank(mesh, operator_cache=tmp_path).film_ops("front")
    (path,) = tmp_path.glob("filmops-*.npz")
    side = json.loads(path.with_suffix(".json").read_text())
    e = store.Entry(side["namespace"], side["params"], path, path.with_suffix(".json"), side["format"], side["key"])
    good = path.read_bytes()
    assert load_film_ops(e) is not None
    with zipfile.ZipFile(path) as z:
        members = z.infolist()
    for info in members:
        # the member's data start after its local header (30 bytes + name + extra field)
        n_name, n_extra = (int.from_bytes(good[info.header_offset + k:info.header_offset + k + 2], "little")
                           for k in (26, 28))
        start = info.header_offset + 30 + n_name + n_extra
        for pos in (start, start + info.compress_size - 1):
            raw = bytearray(good)
            raw[pos] ^= 0x01
            path.write_bytes(bytes(raw))
            with pytest.warns(CacheWarning, match="rebuilding film-operator cache"):
                assert load_film_ops(e) is None, (info.filename, pos - start)
    path.write_bytes(good)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert load_film_ops(e) is not None


def test_the_cache_keeps_within_its_budget_the_operators_used_last(mesh, tmp_path, monkeypatch):
    """With a budget of 0 MB only the entry just written stays; the operators a process
    has in memory are still its own."""
    from fea.materials import AL6061_T6
    from fea.operator_cache import BUDGET_ENV

    monkeypatch.setenv(BUDGET_ENV, "0")
    blank = PreparedBlank(mesh, operator_cache=tmp_path)
    blank.film_ops("front")
    (first,) = tmp_path.glob("filmops-*.npz")
    blank.film_ops("front", film=AL6061_T6)
    (second,) = tmp_path.glob("filmops-*.npz")
    assert second != first and not first.with_suffix(".json").exists()
    assert blank.film_ops("front") is blank.film_ops("front")


@pytest.mark.parametrize("raw", ["-5", "lots", "nan", "inf"])
def test_a_bad_budget_is_refused_before_any_assembly(mesh, tmp_path, monkeypatch, raw):
    from fea.operator_cache import BUDGET_ENV

    monkeypatch.setenv(BUDGET_ENV, raw)
    with pytest.raises(ValueError, match=f"{BUDGET_ENV}='{raw}' must be a number of MB >= 0"):
        PreparedBlank(mesh, operator_cache=tmp_path).film_ops("front")
    assert not list(tmp_path.iterdir())
