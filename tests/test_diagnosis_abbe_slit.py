"""A wider slit, seen in line profiles made by the independent truth's 2-D finite-slit Abbe
sum (:mod:`pipeline.diagnosis.truth.abbe`), not by the diagnosis's own strip model: the slit
width effect's other tests make their profiles with the diagnosis's forward model."""

from __future__ import annotations

import pytest

from pipeline.diagnosis import diagnose
from pipeline.diagnosis.effects import NOMINAL_SLIT_UM
from pipeline.diagnosis.truth.generate import COLLIMATOR_UM

from diagnosis_cases import abbe_profiles_manifest

TRUTH_SLIT_UM = 35.0


@pytest.mark.slow
def test_a_wider_slit_in_abbe_made_profiles_is_named_slit_width(tmp_path):
    """Profiles at 250, 100 and 25 mas of the nominal quilt with a 35 µm slit image (27 µm
    nominal), photon and read noise, background, inter-pixel coupling and sub-pixel phases.
    Rule fixed before the first run, the campaign's: the best finding has ``slit_width`` and
    no other library effect (a background companion allowed), the verdict is ``explained``,
    and the width is within 20 % of the truth's offset from the nominal (33.4-36.6 µm).
    Measured: ``slit_width`` alone, 35.6 µm, delta BIC -177.6."""
    path = abbe_profiles_manifest(tmp_path, (250, 100, 25), 13, collimator_um=dict(COLLIMATOR_UM),
                                  slit_image_width_um=TRUTH_SLIT_UM)
    d = diagnose(path, heldout=False)
    b = d.best
    assert "slit_width" in b.effects and set(b.effects) - {"slit_width"} <= {"quilt_shape"}, b.effect
    assert d.verdict == "explained"
    offset = TRUTH_SLIT_UM - NOMINAL_SLIT_UM
    assert b.parameters["slit_image_width_um"] == pytest.approx(TRUTH_SLIT_UM, abs=0.2 * offset)
