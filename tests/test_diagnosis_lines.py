"""Line-profile measurements of every grating: the manifest refuses a line its grating does
not put on the detector, naming the measurement and the field, and the ``slit_width``
finding reports each measured grating's own slit image width (27 µm J, H, K; 29 µm HK)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from optics.grating import GRATINGS
from pipeline.diagnosis import diagnose
from pipeline.diagnosis.effects import SummaryContext, physical_summary
from pipeline.diagnosis.manifest import load_manifest
from pipeline.diagnosis.synth import synthetic_profile
from pipeline.io.measured import write_line_profile_csv

from diagnosis_cases import nominal_map


def _manifest(tmp_path, grating, wl, order):
    write_line_profile_csv(tmp_path / "p.csv", np.linspace(-100, 100, 101), np.exp(-0.5 * np.linspace(-10, 10, 101) ** 2))
    p = tmp_path / "m.toml"
    p.write_text('[simulation]\ncold_K = 80\n[[measurement]]\nkind = "line_profile"\nfile = "p.csv"\n'
                 f'grating = "{grating}"\norder = {order}\nwavelength_um = {wl}\npixel_scale_mas = 100\n')
    return p


@pytest.mark.parametrize("grating, wl, order", [
    ("J", 1.10, -2), ("J", 1.40, -2), ("H", 1.45, -2), ("K", 2.45, -2), ("HK", 1.45, -1), ("HK", 2.45, -1),
    ("H+K", 1.95, -1), ("H", 1.25, -3), ("K", 1.25, -4)])  # band edges; off-band lines in other orders (turned)
def test_lines_on_the_detector_are_accepted(tmp_path, grating, wl, order):
    m = load_manifest(_manifest(tmp_path, grating, wl, order)).measurements[0]
    assert (m.wavelength_um, m.order) == (wl, order)


@pytest.mark.parametrize("grating, wl, order, fragments", [
    ("K", 1.65, -2, ("wavelength_um=1.65", "K's band 1.95..2.45 µm")),
    ("J", 1.0999, -2, ("wavelength_um=1.0999", "J's band 1.1..1.4 µm")),
    ("H", 2.4, -2, ("wavelength_um=2.4", "H's band 1.45..1.85 µm")),
    ("HK", 1.95, -2, ("order=-2", "wavelength_um=1.95", "turned by")),
    ("H", 1.65, 2, ("order=2", "wavelength_um=1.65", "no propagating order 2")),
    ("HK", 1.95, 0, ("order=0", "non-zero integer")),
    ("H", 1.65, 0, ("order=0", "non-zero integer")),
])
def test_lines_off_the_detector_are_refused_by_name(tmp_path, grating, wl, order, fragments):
    with pytest.raises(ValueError) as e:
        load_manifest(_manifest(tmp_path, grating, wl, order))
    assert str(e.value).startswith("measurement 'p': ")
    for f in fragments:
        assert f in str(e.value)


def test_summary_gives_each_measured_gratings_own_width():
    # the nominal slit: each grating's design width (optics.grating.GRATINGS)
    s = physical_summary(("slit_width",), {"slit_image_width_um": 27.0}, SummaryContext(80.0, gratings=("J", "HK")))
    assert s["slit_width"]["slit_image_width_J_um"] == pytest.approx(27.0)
    assert s["slit_width"]["slit_image_width_HK_um"] == pytest.approx(29.0)
    # one slit 10 % wider: every grating's image 10 % wider
    s = physical_summary(("slit_width",), {"slit_image_width_um": 29.7}, SummaryContext(80.0, gratings=("HK",)))
    assert s["slit_width"]["slit_image_width_HK_um"] == pytest.approx(31.9)
    assert s["slit_width"]["slit_width_factor"] == pytest.approx(1.1)


@pytest.mark.parametrize("width_um", [35.0, 29.0])
def test_hk_slit_width_is_reported_in_the_hk_gratings_own_micrometres(tmp_path, width_um):
    """HK profiles (1.95 µm, order -1, 250 and 25 mas, 1 % noise) made with the HK grating's
    own slit image width set to ``width_um`` (not through the effect's parameter). The
    finding's summary reads that width; the parameter is the J, H, K gratings' width of the
    same slit, ``width_um * 27 / 29``. Tolerance: 3 sigma of the fit plus 0.1 µm (the
    profiles are computed with converged LSF settings, the fit with its faster ones).
    Measured (seeds 1, 2): 35 -> 34.97, 35.06 (sigma 0.22, 0.25); 29 -> 28.98, 29.02."""
    nom = nominal_map(tmp_path)
    rng = np.random.default_rng(1)
    g = replace(GRATINGS["HK"], slit_image_width_um=width_um)
    lines = ['[simulation]\nsag_file = "nominal.npz"\ncold_K = 80\n']
    for ps in (250, 25):
        u, y, _ = synthetic_profile(g, 1.95, -1, ps, nom, rng, noise_rel=0.01)
        write_line_profile_csv(tmp_path / f"p{ps}.csv", u, y)
        lines.append(f'[[measurement]]\nkind = "line_profile"\nfile = "p{ps}.csv"\ngrating = "HK"\norder = -1\n'
                     f'wavelength_um = 1.95\npixel_scale_mas = {ps}\n')
    (tmp_path / "m.toml").write_text("\n".join(lines))
    f = diagnose(tmp_path / "m.toml", effects=("slit_width",), heldout=False).finding("slit_width")
    sigma_hk_um = f.uncertainties["slit_image_width_um"] * 29.0 / 27.0
    assert f.summary["slit_width"]["slit_image_width_HK_um"] == pytest.approx(width_um, abs=3 * sigma_hk_um + 0.1)
    assert f.parameters["slit_image_width_um"] == pytest.approx(width_um * 27.0 / 29.0, abs=3 * sigma_hk_um + 0.1)
