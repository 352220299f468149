"""Material data and coating presets."""
import pytest

from fea.coating import Coating
from fea.materials import AL6061_T6, ALSI40, NIP_HIGH_P, get_material


def test_nist_6061_contraction_at_80K():
    # NIST fit: -0.386 % from 293 K to 80 K
    assert AL6061_T6.strain_between(293, 80) == pytest.approx(-3.86e-3, abs=0.01e-3)
    assert AL6061_T6.thermal_strain(293.0) == pytest.approx(0.0, abs=1e-12)
    assert AL6061_T6.cte_293K_per_K == pytest.approx(22.6e-6, rel=0.01)


def test_nip_contracts_less_than_aluminium_and_alsi40_is_matched():
    mis = NIP_HIGH_P.strain_between(293, 80) - AL6061_T6.strain_between(293, 80)
    assert 1.0e-3 < mis < 2.5e-3  # film ends in compression
    assert abs(ALSI40.cte_293K_per_K - NIP_HIGH_P.cte_293K_per_K) <= 0.5e-6 + 1e-12


def test_coverage_presets():
    c = Coating.symmetric(200, 0.5)
    assert c.thickness_um() == {"front": 100, "back": 100, "side_x": 200, "side_y": 200,
                                "holes_x": 200, "holes_y": 200}
    assert Coating.symmetric(150, 1.0, "holes").thickness_um() == {"holes_x": 150, "holes_y": 150}
    assert set(Coating.symmetric(100, 1.0, "surfaces").thickness_um()) == {"front", "back", "side_x", "side_y"}
    assert Coating.symmetric(100, 1.0, "none").thickness_um() == {}
    assert not Coating(200, 0.5, 0.75).is_z_symmetric


@pytest.mark.parametrize("kwargs, match", [
    (dict(t0_um=0), r"t0_um=0 is outside the valid range \(0, 2000\]"),
    (dict(t0_um=-5), r"t0_um=-5"),
    (dict(polish_front=1.2), r"polish_front=1.2 is outside the valid range \(0, 1\]"),
    (dict(polish_back=0.0), r"polish_back=0.0"),
    (dict(coverage="inside"), r"coverage='inside' is unknown"),
])
def test_bad_coating_is_refused(kwargs, match):
    with pytest.raises(ValueError, match=match):
        Coating(**kwargs)


def test_unknown_material_and_bad_temperature():
    with pytest.raises(ValueError, match="material='steel' is unknown"):
        get_material("steel")
    with pytest.raises(ValueError, match=r"warm_K=400 K is outside"):
        AL6061_T6.strain_between(400, 80)
