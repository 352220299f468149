"""The diagnosis on line profiles an outside lab made with its own code
(``tests/data/outside_lab/README.md``): counts on a pedestal, a pedestal subtracted (negative
samples), offsets in pixels, decimal commas, Poisson and read noise, the noise left to the
diagnosis to estimate."""

from __future__ import annotations

from pathlib import Path

import pytest

from pipeline.diagnosis import diagnose
from pipeline.diagnosis.report import verdict_text

DATA = Path(__file__).resolve().parent / "data" / "outside_lab"

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def cache(nominal_fea_cache):
    return nominal_fea_cache


def test_nominal_profiles_with_photon_noise_hold_no_gap(cache):
    """Nothing injected. The 25 mas profile's noise, estimated from its 89 samples, reads 24 %
    low (0.00230 of the peak against the lab's 0.00302), so its residual is 1.31 x the
    estimate; against the estimate's one-sigma upper bound (3.2/sqrt(89) = 34 % above it) that
    is noise, as the chi^2 test says (1.1 sigma)."""
    d = diagnose(DATA / "nominal" / "manifest.toml", cache_dir=cache, heldout=False)
    assert d.verdict == "no_gap", (d.verdict, d.unexplained_in)
    assert d.baseline["noise"]["J_1p25_25mas"] == pytest.approx(0.0023, rel=0.05)


def test_box_broadened_profiles_are_not_called_fully_explained(cache):
    """The lab's profiles convolved with an 18 µm box (a trapezoid the library's slit cannot
    make). Rule fixed before the run of the wording: either no finding explains them, or the
    verdict's words say where the gap remains beyond noise after the finding."""
    d = diagnose(DATA / "box18" / "manifest.toml", cache_dir=cache, heldout=False)
    assert d.verdict != "no_gap"
    if d.verdict == "explained":
        assert d.unexplained_in
        assert "Part of the gap remains beyond noise after it" in verdict_text(d)
