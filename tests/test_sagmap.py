"""SagMap: regions, statistics and the analytic quilt forms (P/V ↔ amplitude)."""
import numpy as np
import pytest

from optics.sagmap import REGIONS, Region, SagMap, quilt_sag_map


def test_quilt_forms_have_requested_pv_and_amplitude():
    for form, amp in (("product", 0.41), ("sum", 0.205)):
        q = quilt_sag_map(0.82, form=form, spacing_mm=0.25)
        # 82 x 72 mm holds whole periods (84/21 is 4, 72/18 is 4) so P/V is exact on the grid
        assert q.pv_um("center") == pytest.approx(0.82, rel=1e-9)
        assert np.nanmax(q.sag_um) == pytest.approx(2 * amp if form == "sum" else amp, rel=1e-9)


def test_center_region_is_82_by_72():
    r = REGIONS["center"]
    assert r.contains(np.array([41.0, 41.1]), np.array([36.0, 0.0])).tolist() == [True, False]


def test_piston_tilt_removal_and_nan_handling():
    x = np.linspace(-10, 10, 21)
    y = np.linspace(-5, 5, 11)
    X, Y = np.meshgrid(x, y)
    s = 1.0 + 0.1 * X - 0.2 * Y
    s[0, 0] = np.nan
    m = SagMap(x, y, s).remove_piston_tilt()
    assert np.nanmax(np.abs(m.sag_um)) < 1e-12
    assert np.isnan(m.sag_um[0, 0])


def test_bad_input_names_the_field():
    with pytest.raises(ValueError, match="sag_um has shape"):
        SagMap(np.arange(3.0), np.arange(2.0), np.zeros((3, 3)))
    with pytest.raises(ValueError, match="no valid"):
        SagMap(np.arange(3.0), np.arange(2.0), np.full((2, 3), np.nan))
    m = SagMap(np.arange(3.0), np.arange(2.0), np.zeros((2, 3)), "m", {"k": 1})
    for bad, match in ((np.zeros((3, 3)), "sag_um has shape"), (np.full((2, 3), np.nan), "no valid"),
                       (np.full((2, 3), np.inf), "contains inf")):
        with pytest.raises(ValueError, match=match):  # a new sag on a checked grid is checked too
            m.with_sag(bad)
    w = m.with_sag([[1, 2, 3], [4, 5, 6]])
    assert w.sag_um.dtype == float and w.label == "m" and w.meta == {"k": 1} and w.meta is not m.meta
    assert w == SagMap(m.x_mm, m.y_mm, w.sag_um, "m")
    with pytest.raises(ValueError, match="region='middle'"):
        quilt_sag_map(1.0).pv_um("middle")
    with pytest.raises(ValueError, match="diameter_mm"):
        Region("c", "circle")


def test_no_samples_in_region_is_an_error_not_a_zero():
    m = SagMap(np.array([100.0, 101.0]), np.array([100.0, 101.0]), np.ones((2, 2)))
    with pytest.raises(ValueError, match="no valid samples inside region 'center'"):
        m.pv_um("center")
