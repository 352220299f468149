"""The paper, claim by claim: the status the scorecard reports for each claim is pinned.

The scorecard is computed once per session into the session's ``paper_fea_dir``
(tests/conftest.py), so the FEA cases (15 paper cases + AlSi40, solid and
doubled-period blanks) are solved once; test_paper_tables reloads the table cases from
there (under pytest-xdist both modules run on one worker). Each claim is one test: a change of the model that flips a claim
shows up here. The statuses follow from rules written in ``pipeline/paper/*_claims.py``
before the model numbers were looked at; the fast tests below check the measuring
functions on analytic inputs whose answers are known in closed form.
"""
import json

import numpy as np
import pytest

from optics.imaging import Profile
from optics.metrics import find_profile_peaks
from optics.sagmap import SagMap, quilt_sag_map
from pipeline.paper.claim import STATUSES, Claim, grade
from pipeline.paper.design_claims import stretched
from pipeline.paper.fea_claims import edge_pv_ratio
from pipeline.paper.optics_claims import double_peak_ok, satellites, shoulder_height

EXPECTED = {
    "table1": "reproduced",
    "table2_holes": "reproduced",
    "ratio_polish": "reproduced",
    "ratio_thickness": "reproduced",
    "ratio_holes": "reproduced",
    "table2_surfaces": "contradicted",
    "directions": "reproduced",
    "edge_pv": "contradicted",
    "satellite_positions": "reproduced",
    "satellite_flux_wavelength": "reproduced",
    "j_double_peak": "contradicted",
    "j25_asymmetric_shoulders": "partial",
    "k_shoulders": "partial",
    "h_shoulders_scales": "partial",
    "shoulders_smaller_25mas": "partial",
    "pupil_shift_scales": "contradicted",
    "pupil_shift_band": "reproduced",
    "multigrating_1p25": "partial",
    "collimator_left": "contradicted",
    "perfect_r": "reproduced",
    "sinusoid_058": "partial",
    "no_quilt_blanks": "reproduced",
    "period_doubled_same_amplitude": "reproduced",
    "period_doubled_fea": "reproduced",
}


# ---------------------------------------------------------------- fast: the measuring functions
def test_grade_and_claim_validation():
    assert grade(0.03, (0, 0.05), (0, 0.1)) == "reproduced"
    assert grade(0.07, (0, 0.05), (0, 0.1)) == "partial"
    assert grade(0.2, (0, 0.05), (0, 0.1)) == "contradicted"
    assert grade(float("nan"), (0, 0.05), (0, 0.1)) == "contradicted"
    with pytest.raises(ValueError, match="status='maybe'"):
        Claim("x", "c", "s", "p", "m", "maybe", "r", "fea")
    with pytest.raises(ValueError, match="source='guess'"):
        Claim("x", "c", "s", "p", "m", "partial", "r", "guess")


def test_double_peak_rule_on_hand_written_profiles():
    x = np.arange(-100.0, 100.5, 0.5)
    pair = np.exp(-0.5 * ((x - 20) / 8) ** 2) + np.exp(-0.5 * ((x + 20) / 8) ** 2)  # 40 µm apart, deep dip
    assert double_peak_ok(Profile(x, pair))[0]
    assert double_peak_ok(Profile(x, pair))[1] == pytest.approx(40.0, abs=0.5)
    close = np.exp(-0.5 * ((x - 12) / 8) ** 2) + np.exp(-0.5 * ((x + 12) / 8) ** 2)  # 24 µm: outside 36-45
    assert not double_peak_ok(Profile(x, close))[0]
    assert not double_peak_ok(Profile(x, np.exp(-0.5 * (x / 15) ** 2)))[0]


def test_shoulder_height_on_hand_written_profiles():
    """A clean flank has none; a side bump or a plateau shows on its own side only (+ = right)."""
    x = np.arange(-100.0, 100.5, 0.5)
    core = np.exp(-0.5 * (x / 10) ** 2)
    assert shoulder_height(x, core, 1) == 0.0 and shoulder_height(x, core, -1) == 0.0
    # a local maximum 10 % high at +30 µm: counted by its rise and fall, about 2 x 10 %
    bump = core + 0.1 * np.exp(-0.5 * ((x - 30) / 4) ** 2)
    assert 0.15 < shoulder_height(x, bump, 1) < 0.25 and shoulder_height(x, bump, -1) == 0.0
    assert shoulder_height(-x, bump, -1) == pytest.approx(shoulder_height(x, bump, 1))
    # an inflection shoulder: a 12 % plateau ending at -35 µm, no local maximum
    plateau = core + np.where(x < 0, 0.12 / (1 + np.exp((-x - 35) / 2.5)), 0.0)
    assert not find_profile_peaks(x, plateau)["offset_um"][1:]
    assert 0.01 < shoulder_height(x, plateau, -1) <= 0.12 and shoulder_height(x, plateau, 1) == 0.0
    # the scale (counts) does not matter; a trapezoid (slit x pixel) has none
    assert shoulder_height(x, 5e4 * bump, 1) == pytest.approx(shoulder_height(x, bump, 1), rel=1e-9)
    trap = np.convolve(np.clip((22.5 - np.abs(x)) / 18, 0, 1), np.exp(-0.5 * (np.arange(-20, 20.5, 0.5) / 3) ** 2),
                       mode="same")
    assert shoulder_height(x, trap, 1) < 1e-9
    with pytest.raises(ValueError, match="side=0"):
        shoulder_height(x, core, 0)


def test_satellites_of_an_analytic_quilt_sit_at_lambda_f_over_period():
    """Grating equation: order ±1 of a 21 mm period at λ f_cam anamorphic / (D_x cos α)."""
    from optics.grating import SPIFFI, get_grating

    g = get_grating("K")
    wl = 2.2
    anam = float(g.anamorphic_factor(wl))
    # the 21 mm period on the grating is 21 cos(alpha) mm in the incident beam
    expect = wl * SPIFFI.camera_focal_mm * anam / (21.0 * np.cos(np.radians(g.incidence_deg)))
    pos, _, _ = satellites("K", wl, quilt_sag_map(0.3, "sum", spacing_mm=0.5))
    assert pos == pytest.approx(expect, rel=0.03)


def test_edge_ratio_of_a_uniform_quilt_is_one_and_sees_an_edge_lip():
    q = quilt_sag_map(0.5, "product", spacing_mm=0.5)
    r, _, _ = edge_pv_ratio(q)
    assert r == pytest.approx(1.0, abs=0.02)
    X, _ = np.meshgrid(q.x_mm, q.y_mm)
    lip = q.with_sag(q.sag_um + np.where(X > 75, 0.5, 0.0))  # a 0.5 µm step along the +x edge only
    # P/V is a seminorm: PV(quilt + lip) <= PV(quilt) + PV(lip) = 2 PV(quilt); the lip raises it
    assert 1.5 < edge_pv_ratio(lip)[0] <= 2.0 + 1e-9


def test_stretched_map_has_twice_the_period():
    x = np.arange(-80, 80.01, 0.5)
    y = np.arange(-70, 70.01, 0.5)
    X, Y = np.meshgrid(x, y)
    m = SagMap(x, y, np.cos(2 * np.pi * X / 21.0))
    s = stretched(m, 2.0)
    # bilinear interpolation on the stretched 1 mm grid errs by <= (1 mm)² k² / 8 = 2.8e-3
    assert np.nanmax(np.abs(s.sag_um - np.cos(2 * np.pi * X / 42.0))) < 3e-3


# ---------------------------------------------------------------- slow: the scorecard itself
@pytest.fixture(scope="module")
def card(paper_fea_dir):
    from pipeline.paper import scorecard

    out = paper_fea_dir  # shared with test_paper_tables: same worker (conftest.SHARED_SCOPES), same session
    claims = scorecard(out, progress=False)
    return out, {c.id: c for c in claims}


@pytest.mark.slow
def test_scorecard_files_and_schema(card):
    out, claims = card
    data = json.loads((out / "scorecard.json").read_text())
    keys = {"id", "claim", "section", "paper", "model", "status", "reason", "source"}
    assert [c["id"] for c in data["claims"]] == list(claims)
    for c in data["claims"]:
        assert set(c) == keys and c["status"] in STATUSES and c["source"] in ("fea", "analytic")
    md = (out / "scorecard.md").read_text()
    assert all(f"| {cid} |" in md for cid in claims)
    for png in ("tables.png", "j_double_peak.png", "k_shoulders.png"):
        assert (out / png).read_bytes()[:4] == b"\x89PNG"
    assert set(claims) == set(EXPECTED)
    assert claims["sinusoid_058"].source == "analytic"
    assert sum(c.source == "analytic" for c in claims.values()) == 1


@pytest.mark.slow
@pytest.mark.parametrize("cid", list(EXPECTED))
def test_claim_status(card, cid):
    c = card[1][cid]
    assert c.status == EXPECTED[cid], f"{cid}: {c.status} ({c.model}; {c.reason})"


@pytest.mark.slow
def test_j_amplitude_factor_is_measured(card):
    """The model needs more than the paper's amplitude to double-peak J (README, physics)."""
    model = card[1]["j_double_peak"].model
    assert "needs the amplitude x" in model
    factor = float(model.split("needs the amplitude x")[1].split()[0])
    assert 1.0 < factor <= 2.5


@pytest.mark.slow
def test_cli_prints_the_table_from_the_cached_cases(card, capsys):
    from pipeline.cli import main

    out, claims = card
    assert main(["paper", "--out", str(out), "--quiet"]) == 0
    printed = capsys.readouterr().out
    assert all(cid in printed for cid in claims) and "scorecard.json" in printed
