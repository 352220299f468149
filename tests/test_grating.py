"""Grating equation, dispersion and the instrument tables (paper Table 2, §4.1)."""

import math

import numpy as np
import pytest

from optics.grating import GRATINGS, PIXEL_SCALES, Grating, PixelScale, get_grating, get_pixel_scale


@pytest.mark.parametrize("name", sorted(GRATINGS))
def test_beta_minus_alpha_is_45_deg_at_band_centre(name):
    g = GRATINGS[name]
    assert abs(g.beta_deg(g.centre_um) - g.incidence_deg - 45.0) < 0.01


def test_j_band_beta_and_dispersion():
    g = GRATINGS["J"]
    assert g.beta_deg(1.25) == pytest.approx(8.909, abs=2e-3)
    # d beta / d lambda = m / (d cos beta), signed: negative for the -2 blaze order.
    cb = math.cos(math.radians(g.beta_deg(1.25)))
    assert g.angular_dispersion_rad_per_um(1.25) == pytest.approx(-2 / (5.758 * cb))
    assert g.linear_dispersion_um_per_nm(1.25) == pytest.approx(342e3 * 2 / (5.758 * cb) * 1e-3)
    assert g.anamorphic_factor(1.25) == pytest.approx(math.cos(math.radians(-36.0908)) / cb)


def test_beta_matches_numerical_derivative():
    g = GRATINGS["K"]
    h = 1e-5
    num = math.radians(g.beta_deg(2.2 + h) - g.beta_deg(2.2 - h)) / (2 * h)
    assert g.angular_dispersion_rad_per_um(2.2) == pytest.approx(num, rel=1e-6)


@pytest.mark.parametrize("name,order", [("H", -3), ("K", -4)])
def test_non_blaze_orders_at_1p25um(name, order):
    g = GRATINGS[name]
    beta = g.beta_deg(1.25, order)
    assert math.sin(math.radians(g.incidence_deg)) + math.sin(math.radians(beta)) == pytest.approx(
        order * 1.25 / g.groove_spacing_um)
    # Appendix A turns the grating "by no more than a few degrees"; at the table alpha beta moves by that much.
    assert abs(beta - g.beta_deg(g.centre_um)) < 4.0  # 3.4 (H), 3.6 (K) deg at the table alpha
    assert g.slit_image_width_at_um(1.25, order) == pytest.approx(27.0, abs=1.0)


def test_slit_image_width_is_27_or_29_at_band_centre():
    for g in GRATINGS.values():
        assert g.slit_image_width_at_um(g.centre_um) == pytest.approx(g.slit_image_width_um)
    assert GRATINGS["HK"].slit_image_width_um == 29.0


def test_evanescent_order_error_names_wavelength_order_and_range():
    g = GRATINGS["J"]
    with pytest.raises(ValueError, match=r"wavelength_um=5\.0 .*order -2.*valid range.*4\.57"):
        g.beta_deg(5.0)
    with pytest.raises(ValueError, match="order -4"):
        g.beta_deg(3.0, -4)
    with pytest.raises(ValueError, match="non-zero integer"):
        g.beta_deg(1.25, 0)


def test_unknown_names_list_valid_ones():
    with pytest.raises(ValueError, match=r"\['H', 'HK', 'J', 'K'\]"):
        get_grating("Z")
    assert get_grating("h+k") is GRATINGS["HK"]
    with pytest.raises(ValueError, match=r"\[25, 100, 250\]"):
        get_pixel_scale(50)
    with pytest.raises(ValueError, match="valid values"):
        get_pixel_scale("fast")
    assert get_pixel_scale("25mas").relative_na == 0.1
    assert [PIXEL_SCALES[k].relative_na for k in (250, 100, 25)] == [1.0, 0.4, 0.1]


def test_dataclass_validation():
    with pytest.raises(ValueError, match="groove_spacing_um"):
        Grating("X", -1.0, -2, -30.0, (1.0, 1.1, 1.2))
    with pytest.raises(ValueError, match="band_um"):
        Grating("X", 5.0, -2, -30.0, (1.2, 1.1, 1.0))
    with pytest.raises(ValueError, match="relative_na"):
        PixelScale(10, 1.5)
    assert np.all(np.isfinite(GRATINGS["J"].beta_deg(np.array(GRATINGS["J"].band_um))))


def test_scalar_angles_are_those_of_the_array_path_and_errors_repeat():
    """A scalar wavelength's angle is memoised: the same value as through an array, for
    equal gratings built apart, and a refused wavelength is refused on every call."""
    from dataclasses import replace

    g = GRATINGS["H"]
    twin = replace(g, slit_image_width_um=g.slit_image_width_um)
    for wl in (1.25, 1.6, np.float64(1.75), 2):
        ref = g.beta_deg(np.array([wl], dtype=float))[0]
        assert g.beta_deg(wl) == ref and twin.beta_deg(wl) == ref and g.beta_deg(wl, g.order) == ref
    for _ in range(2):
        with pytest.raises(ValueError, match="no propagating order"):
            g.beta_deg(50.0)
