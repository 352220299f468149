"""The independent truth's lattice grating families (``pocket_jitter``, ``sharp_ribs``;
benchmarks/truth_families.md), the selection of families per campaign, and the truth's
line-profile CSV writer, against hand-made maps and analytic expectations."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import quad

from pipeline.diagnosis.truth.generate import FAMILIES, GRATING_FAMILIES, check_families, truth_grating
from pipeline.diagnosis.truth.gratings import central, harmonic_distance
from pipeline.diagnosis.truth.lattice import (BLEND_SIGMA_MM, cell_field, cell_index, pocket_jitter, rib_harmonics,
                                              rib_profile, sharp_ribs, smooth_figure)
from pipeline.io.measured import write_line_profile_csv

AX_X = np.arange(-80.0, 80.0 + 0.25, 0.5)
AX_Y = np.arange(-70.0, 70.0 + 0.25, 0.5)
X, Y = np.meshgrid(AX_X, AX_Y)
KX, KY = 2 * np.pi / 21.0, 2 * np.pi / 18.0
#: A plane (the smooth figure a period average keeps exactly) plus a quilt with sum and
#: product terms and a second harmonic.
PLANE = 0.03 + 0.02 * X / 80.0 - 0.01 * Y / 70.0
QUILT = (0.10 * np.cos(KX * X) + 0.07 * np.cos(KY * Y) + 0.03 * np.cos(KX * X) * np.cos(KY * Y)
         + 0.02 * np.cos(2 * KX * X))
MAP = PLANE + QUILT


class _Map:
    def __init__(self, sag):
        self.x_mm, self.y_mm, self.sag_um = AX_X, AX_Y, sag


def test_period_average_keeps_the_plane_and_removes_the_quilt():
    fig = smooth_figure(AX_X, AX_Y, MAP)
    inner = (np.abs(X) <= 80 - 10.5) & (np.abs(Y) <= 70 - 9.0)  # full window inside the map
    assert np.max(np.abs(fig - PLANE)[inner]) < 1e-12
    with pytest.raises(ValueError, match="must divide the period"):
        smooth_figure(np.arange(0, 50, 0.4), AX_Y, np.zeros((AX_Y.size, 125)))


def test_cell_field_is_one_plus_eps_inside_each_cell():
    i, j = cell_index(AX_X, AX_Y)
    eps = np.random.default_rng(0).normal(0, 0.1, (j.max() - j.min() + 1, i.max() - i.min() + 1))
    f = cell_field(AX_X, AX_Y, eps)
    for ci, cj in ((0, 0), (1, -2), (-3, 3)):
        # 3 blend sigmas from the cell's edges the blend's tail is < exp(-4.5) of the step
        inner = (np.abs(X - 21 * ci) <= 10.5 - 3 * BLEND_SIGMA_MM) & (np.abs(Y - 18 * cj) <= 9 - 3 * BLEND_SIGMA_MM)
        e = eps[cj - j.min(), ci - i.min()]
        assert np.max(np.abs(f[inner] - (1 + e))) < 0.015 * np.ptp(eps)
    with pytest.raises(ValueError, match="cells"):
        cell_field(AX_X, AX_Y, np.zeros((2, 2)))


def test_pocket_jitter_per_cell_amplitudes_recovered_by_least_squares():
    """In each central cell, the truth's quilt (truth minus the plane) is ``a_c`` times the
    map's quilt with ``a_c`` proportional to ``1 + eps_c`` (the common factor is the
    normalisation to the nominal's scale 1)."""
    g = pocket_jitter(AX_X, AX_Y, MAP, MAP, np.random.default_rng(3))
    eps = np.asarray(g.params["eps"])
    assert 0.05 <= g.params["sigma"] <= 0.15 and g.family == "pocket_jitter"
    a, want = [], []
    for ci in range(-1, 2):
        for cj in range(-1, 2):
            inner = (np.abs(X - 21 * ci) <= 6.0) & (np.abs(Y - 18 * cj) <= 4.5)
            q = QUILT[inner]
            a.append(float(q @ (g.sag_um[inner] - g.params["scale"] * PLANE[inner]) / (q @ q)))
            want.append(1 + eps[cj - g.params["cell_j0"], ci - g.params["cell_i0"]])
    a, want = np.array(a), np.array(want)
    c = float(a @ want / (want @ want))
    assert c == pytest.approx(g.params["scale"], rel=1e-3)
    assert np.max(np.abs(a / c - want)) < 1e-3


def test_pocket_jitter_distance_follows_sigma_and_scale_is_one():
    """Harmonic distance ~ sigma x (the quilt's share of the map's norm) x sqrt(1 - 1/N)
    for iid cell factors over the ~16 central cells; the nominal's scale in the truth is 1."""
    mask = central(AX_X, AX_Y)
    qn = QUILT[mask] - QUILT[mask].mean()
    mn = MAP[mask] - MAP[mask].mean()
    share = np.linalg.norm(qn) / np.linalg.norm(mn)
    ratios = []
    for seed in range(30):
        g = pocket_jitter(AX_X, AX_Y, MAP, MAP, np.random.default_rng(seed))
        d, k = harmonic_distance(g.sag_um, MAP, mask)
        assert k == pytest.approx(1.0, abs=1e-9) and d == pytest.approx(g.distance, rel=1e-9)
        ratios.append(d / (g.params["sigma"] * share * math.sqrt(1 - 1 / 16)))
    assert 0.7 <= np.median(ratios) <= 1.2 and max(ratios) < 2.0


@pytest.mark.parametrize("p", [3.3, 4.0, 7.5, 16.0])
def test_rib_harmonics_match_the_profile_fourier_series(p):
    """Coefficients by quadrature of ``|cos t|^p cos 2nt`` over a period; the analytic
    series vanishes beyond n = p/2 for even p."""
    a = rib_harmonics(p, 6)
    for n in range(7):
        c = quad(lambda t: abs(math.cos(t)) ** p * math.cos(2 * n * t), 0, math.pi, limit=200)[0] / math.pi
        assert a[n] == pytest.approx(c * (1 if n == 0 else 2), abs=1e-9)
    if p == 4.0:
        assert a[3:] == pytest.approx(0.0, abs=1e-15) and a[:3] == pytest.approx([3 / 8, 1 / 2, 1 / 8])
    with pytest.raises(ValueError, match="p="):
        rib_harmonics(-1.0, 3)


def test_sharp_ribs_truth_carries_the_rib_series_and_hits_its_distance():
    """On a map of pure fundamentals, the truth's x harmonics n >= 2 along a row come only
    from the rib profile: their ratios to each other are the analytic series' (about the
    wall, so the sign alternates as (-1)^n about the hole axis)."""
    fund = 0.1 * np.cos(KX * X) + 0.07 * np.cos(KY * Y)
    mask = central(AX_X, AX_Y)
    g = sharp_ribs(AX_X, AX_Y, fund, fund, 0.2, np.random.default_rng(4))
    d, k = harmonic_distance(g.sag_um, fund, mask)
    assert d == pytest.approx(0.2, rel=1e-3) and k == pytest.approx(1.0, abs=1e-9)
    p = g.params["p_x"]
    assert 4.0 <= p <= 16.0 and 4.0 <= g.params["p_y"] <= 16.0
    row = g.sag_um[AX_Y.size // 2]
    n = np.arange(13)
    A = np.column_stack([np.cos(KX * np.outer(AX_X, n)), np.sin(KX * np.outer(AX_X, n[1:]))])
    c = np.linalg.lstsq(A, row, rcond=None)[0]
    want = rib_harmonics(p, 4) * (-1.0) ** np.arange(5)
    assert c[3] / c[2] == pytest.approx(want[3] / want[2], rel=1e-3)
    assert c[4] / c[2] == pytest.approx(want[4] / want[2], rel=2e-3)
    assert np.max(np.abs(c[13:])) < 1e-9 * np.max(np.abs(c))  # even about the hole axis


def test_family_selection_and_default_draw_order():
    """The default families are the two mixtures drawn as before (one integer for the
    family, then the distance); a selection draws only its own families."""
    nom = _Map(MAP)
    fea = _Map(MAP + 0.002 * np.cos(2 * np.pi * X / 7.0))
    g = truth_grating(nom, fea, np.random.default_rng(9))
    r = np.random.default_rng(9)
    fam = FAMILIES[int(r.integers(0, 2))]
    assert g.family == fam and g.distance == pytest.approx(r.uniform(0.05, 0.30), rel=1e-3)
    for fam in ("pocket_jitter", "sharp_ribs"):
        assert {truth_grating(nom, fea, np.random.default_rng(s), (fam,)).family for s in range(2)} == {fam}
    assert check_families("sharp_ribs") == ("sharp_ribs",) and set(GRATING_FAMILIES) >= set(FAMILIES)
    assert check_families("pocket_jitter, sharp_ribs") == ("pocket_jitter", "sharp_ribs")  # as typed on a command line
    for bad in (("nope",), (), ("sum_mix", "sum_mix"), "sum_mix,,sharp_ribs"):
        with pytest.raises(ValueError, match="truth_families="):
            check_families(bad)


def test_campaign_config_truth_families():
    from pipeline.diagnosis.campaign import CampaignConfig

    assert CampaignConfig().truth_families == FAMILIES
    assert CampaignConfig(truth_families=["pocket_jitter", "sharp_ribs"]).truth_families == ("pocket_jitter",
                                                                                             "sharp_ribs")
    with pytest.raises(ValueError, match="fea_variants"):
        CampaignConfig(truth_families=("fea_variants",))


def test_profile_csv_keeps_subpixel_samples_1e5_um_apart_distinct(tmp_path):
    """Two sub-pixel phases 1e-5 µm apart (and one 1e-9 µm) stay two samples at their
    own offsets through the project's line-profile reader."""
    from pipeline.io.measured import read_line_profile

    x = np.array([-126.123456, -18.0, 0.0, 35.999995, 36.000005, 36.000005 + 1e-9, 90.5])
    y = np.array([10.0, 200.0, 1000.0, 400.0, 401.0, 402.0, 5.0])
    write_line_profile_csv(tmp_path / "p.csv", x, y)
    xr, yr = read_line_profile(tmp_path / "p.csv", normalise=False)
    assert np.array_equal(xr, x) and np.array_equal(yr, y)
    with pytest.raises(ValueError, match="duplicate"):
        write_line_profile_csv(tmp_path / "q.csv", [1.0, 1.0, 2.0], [1.0, 2.0, 3.0])


def test_make_case_draws_a_selected_family_and_records_it(tmp_path):
    """A surface case of the independent truth with only the lattice families selected
    (the generator alone: nothing is diagnosed): the map is written and the case's
    record names the family and its drawn parameters."""
    import json

    from pipeline.diagnosis.campaign import CampaignConfig
    from pipeline.diagnosis.truth.generate import make_case

    cfg = CampaignConfig(truth_families=("pocket_jitter", "sharp_ribs"))
    nom, fea = _Map(MAP), _Map(MAP + 0.002 * np.cos(2 * np.pi * X / 7.0))
    seen = set()
    for seed in range(4):
        out = tmp_path / str(seed)
        out.mkdir()
        man, truth = make_case("surface", "astigmatism", np.random.default_rng(seed), nom, fea, out, cfg)
        info = truth["_truth"]
        seen.add(info["family"])
        assert truth["_present"] == ["quilt_shape"] and (out / "map.npz").exists()
        assert ("sigma" in info) if info["family"] == "pocket_jitter" else ("p_x" in info)
        json.dumps(info)
    assert seen == {"pocket_jitter", "sharp_ribs"}
