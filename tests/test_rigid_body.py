"""Rigid-body motion and low-order figure of point clouds (optics.rigid_body)."""

from __future__ import annotations

import numpy as np
import pytest

from optics.rigid_body import (
    URAD_PER_ARCSEC,
    RigidBodyMotion,
    fit_rigid_body,
    pv_rms_um,
    remove_low_order,
    rigid_displacement_um,
)


def test_arcsec_conversion():
    # 1 arcsec = pi / 648000 rad = 4.8481 µrad
    assert URAD_PER_ARCSEC == pytest.approx(4.84813681, rel=1e-8)
    assert RigidBodyMotion(0, 0, 0, 0, 0, 4.84813681).rz_arcsec == pytest.approx(1.0, rel=1e-8)


def test_sign_conventions():
    """rz > 0 turns +x towards +y (groove clocking); rx > 0 lifts +y; ry > 0 lowers +x."""
    p = np.array([[1.0, 0, 0], [0, 1.0, 0]])
    u = rigid_displacement_um(RigidBodyMotion(0, 0, 0, 0, 0, 1000.0), p)  # 1 mrad = 1 µm/mm
    np.testing.assert_allclose(u, [[0, 1, 0], [-1, 0, 0]], atol=1e-12)
    u = rigid_displacement_um(RigidBodyMotion(0, 0, 0, 1000.0, 1000.0, 0), p)
    np.testing.assert_allclose(u[:, 2], [-1, 1], atol=1e-12)


def test_fit_recovers_motion_from_noisy_cloud_about_an_origin():
    rng = np.random.default_rng(3)
    p = rng.uniform(-50, 50, (400, 3)) * [1, 1, 0.1]
    true = RigidBodyMotion(1.5, -0.7, 2.0, 12.0, -8.0, 30.0, origin_mm=(5.0, -3.0, 1.0))
    u = rigid_displacement_um(true, p) + rng.normal(0, 1e-3, p.shape)
    got = fit_rigid_body(p, u, rng.uniform(0.5, 2, len(p)), origin_mm=true.origin_mm)
    np.testing.assert_allclose(list(got.as_dict().values()), list(true.as_dict().values()), atol=0.05)
    assert got.minus(true).rz_urad == pytest.approx(got.rz_urad - 30.0)


def test_collinear_points_do_not_determine_the_motion():
    p = np.column_stack([np.linspace(0, 10, 5), np.zeros(5), np.zeros(5)])
    with pytest.raises(ValueError, match="rank"):
        fit_rigid_body(p, np.zeros_like(p))
    with pytest.raises(ValueError, match=r"shape \(n, 3\)"):
        fit_rigid_body(p[:, :2], np.zeros((5, 2)))


def test_power_removal():
    x, y = np.meshgrid(np.linspace(-41, 41, 83), np.linspace(-36, 36, 73))
    s = 0.3 + 0.01 * x - 0.02 * y + 2e-4 * (x**2 + y**2)
    r2, c2 = remove_low_order(x, y, s, remove=("piston", "tilt"))
    r3, c3 = remove_low_order(x, y, s, remove=("piston", "tilt", "power"))
    assert np.abs(r3).max() < 1e-12 and c3["power_um_per_mm2"] == pytest.approx(2e-4)
    # piston/tilt only leaves the bowl: P/V = 2e-4 (41² + 36²) on this symmetric grid
    assert pv_rms_um(r2)[0] == pytest.approx(2e-4 * (41**2 + 36**2))
    with pytest.raises(ValueError, match=r"remove=.*'coma'.*\['piston', 'tilt', 'power'\]"):
        remove_low_order(x, y, s, remove=("coma",))
