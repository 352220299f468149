"""Slow: the paper's three diagnoses on the bundled synthetic scenarios. The scenario truths
come from the refined FEA mesh (1.0/2.0 mm) + a random shape discrepancy; the diagnosed
model is the default mesh (see pipeline/scenarios). The reduced injection-recovery
campaign is in test_diagnosis_campaign_reduced.py."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pipeline.diagnosis import diagnose
from pipeline.io.registry import read_sag_map
from optics.zernike import zernike_xy

SCEN = Path(__file__).resolve().parents[1] / "pipeline" / "scenarios"
pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def cache(nominal_fea_cache):
    return nominal_fea_cache


def test_cryo_map_astigmatism(cache):
    """§3.3: P/V_center 0.80 um, ~0.60 um once the oblique astigmatism is removed."""
    d = diagnose(SCEN / "cryo_astigmatism" / "manifest.toml", cache_dir=cache)
    assert d.verdict == "explained" and d.best.effect == "astigmatism"
    c45, c0 = d.best.parameters["astig_45_um"], d.best.parameters["astig_0_um"]
    assert abs(c45) > 5 * abs(c0)  # oblique (45 deg), not 0 deg
    m = read_sag_map(SCEN / "cryo_astigmatism" / "cryo_map.int")
    X, Y = m.grid()
    assert m.remove_piston_tilt("center").pv_um("center") == pytest.approx(0.80, abs=0.05)
    clean = m.with_sag(m.sag_um - c45 * zernike_xy(2, -2, X, Y, 68.5) - c0 * zernike_xy(2, 2, X, Y, 68.5))
    assert clean.remove_piston_tilt("center").pv_um("center") == pytest.approx(0.60, abs=0.05)
    assert d.best.heldout_shrink_fraction > 0.5 and not d.best.overfit


def test_j_grating_larger_amplitude_and_pupil_shift(cache):
    """§5.3: the J grating needs a larger deformation amplitude and a ~4 mm pupil shift."""
    d = diagnose(SCEN / "j_repolished" / "manifest.toml", cache_dir=cache)
    assert d.verdict == "explained"
    assert set(d.best.effects) == {"amplitude_scale", "pupil_shift"}
    p = d.best.parameters
    assert 1.4 < p["scale_J"] < 2.3          # quilt-fundamental truth ratio 1.57 (P/V ratio 1.5)
    assert p["pupil_x_mm"] == pytest.approx(4.0, abs=2.0)
    assert d.best.heldout_shrink_fraction > 0.3 and not d.best.overfit


@pytest.fixture(scope="module")
def hk_clean(cache):
    # neither H/K test reads the held-out check (the J and cryo scenarios test it)
    return diagnose(SCEN / "hk_amplitude" / "manifest.toml", cache_dir=cache, heldout=False)


def test_hk_gratings_amplitude_1p2(hk_clean):
    """§5.4: the 1.25 um line on H (order -3) and K (order -4) needs ~1.2x the amplitude."""
    d = hk_clean
    assert d.verdict == "explained" and d.best.effect == "amplitude_scale"
    for g in ("H", "K"):
        assert d.best.parameters[f"scale_{g}"] == pytest.approx(1.20, rel=0.1)  # 1.2 x (refined/default quilt 1.000)
    assert abs(d.best.parameters["scale_H"] - d.best.parameters["scale_K"]) < 0.1  # H and K alike
    # A common cold-temperature change cannot do it: it ends at its prior's bound (-60 K) and
    # fits worse by more than any finding must beat the nominal by (measured: by 34 with the
    # profiles' inter-pixel coupling fitted, by more than 50 without it).
    t = d.finding("temperature")
    assert "temperature_offset_K" in t.at_bound and t.delta_bic > d.best.delta_bic + d.criteria.min_delta_bic


def test_hk_scenario_as_a_lab_delivers_it(hk_clean, cache, tmp_path):
    """The hk_amplitude scenario's profiles rewritten as a lab would deliver them: ADU
    (x37), every other profile on a 500-count pedestal and the others over-subtracted
    (floor at the 40th percentile, so the wings are negative noise), offsets shifted by
    7.3 µm (the sparse offsets are already non-uniform), rows shuffled, written with a
    plain text writer. Rule fixed before the first run: same verdict and top effect as the
    clean files, its parameters within 2 % (flux, background and shift are nuisances; only
    the optimiser's start moves). What the lab changes is what every model fits as
    nuisances, so the lab files are diagnosed with the clean run's top model only (its
    effects and companions): the library's ranking on these profiles is the clean run's test
    (``test_hk_gratings_amplitude_1p2``); measured on 2 busy cores, 21 s against 95 s with the
    whole library."""
    import shutil

    scen = SCEN / "hk_amplitude"
    shutil.copy(scen / "manifest.toml", tmp_path)
    rng = np.random.default_rng(11)
    for i, f in enumerate(sorted(scen.glob("*.csv"))):
        u, y = np.loadtxt(f, delimiter=",", skiprows=1, unpack=True)
        y2 = 37.0 * y + 500.0 if i % 2 else 37.0 * (y - np.percentile(y, 40))
        o = rng.permutation(u.size)
        np.savetxt(tmp_path / f.name, np.column_stack([(u + 7.3)[o], y2[o]]), delimiter=",",
                   header="offset_um,intensity", comments="", fmt="%.6g")
    clean = hk_clean
    lab = diagnose(tmp_path / "manifest.toml", cache_dir=cache, heldout=False,
                   effects=clean.best.effects + clean.best.companions)
    assert (lab.verdict, lab.best.effect) == (clean.verdict, clean.best.effect)
    for k, v in clean.best.parameters.items():
        assert lab.best.parameters[k] == pytest.approx(v, rel=0.02), k
