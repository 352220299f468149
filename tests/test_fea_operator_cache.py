"""On-disk film-operator cache: a second process gets identical operators, a corrupt or
foreign file is rebuilt, never used."""
import numpy as np
import pytest

from fea.coating import Coating
from fea.mesh import MeshSpec, blank_mesh
from fea.geometry import Blank
from fea.model import PreparedBlank

COARSE = MeshSpec(size_mm=5.0, size_bulk_mm=10.0)


@pytest.fixture(scope="module")
def mesh():
    return blank_mesh(Blank(), COARSE)


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
    with pytest.warns(UserWarning, match="unreadable film-operator cache"):
        ops = model.film_ops("front")
    ref = PreparedBlank(mesh, operator_cache=None).film_ops("front")
    assert abs(ops.A00 - ref.A00).max() == 0


def test_other_film_material_does_not_hit(mesh, tmp_path):
    from fea.materials import AL6061_T6

    PreparedBlank(mesh, operator_cache=tmp_path).film_ops("front")
    PreparedBlank(mesh, operator_cache=tmp_path).film_ops("front", film=AL6061_T6)
    assert len(list(tmp_path.glob("filmops-*.npz"))) == 2
