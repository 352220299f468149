"""The slit's coherent modes (optics.slit_modes) give the Abbe sum over sources.

Expected values are from the sum itself, written here source by source (one FFT per
source point, the definition in optics.imaging's module docstring), and from Parseval's
theorem for what truncation may leave out: the dropped modes carry at most their share of
the eigenvalue sum of the flux when the pupil field has unit modulus.
"""

from __future__ import annotations

import re

import numpy as np
import pytest

from optics.grating import GRATINGS, SPIFFI
from optics.imaging import partially_coherent_lsf, source_points
from optics.lineprofile import LsfSettings, line_profile, pupil_rows
from optics.pupil import centred_axis
from optics.sagmap import quilt_sag_map
from optics.slit_modes import slit_modes

#: Relative illumination NA of the pixel scales (paper: 0.1, 0.4, 1.0 at 25, 100, 250 mas).
RELATIVE_NA = {25: 0.1, 100: 0.4, 250: 1.0}


def sampling(lam, mas, s=LsfSettings()):
    """J grating: (grating, beta_deg, anamorphic, pupil step mm, xi, s_x, s_y, weights, slit scale 1/mm),
    sampled as line_profile's defaults sample it."""
    g = GRATINGS["J"]
    anam = g.anamorphic_factor(lam)
    d_xi = lam * SPIFFI.camera_focal_mm * anam / (s.n_fft * s.detector_step_um)
    R = 0.5 * SPIFFI.pupil_diameter_mm
    r_src = RELATIVE_NA[mas] * R
    sx, sy, w = source_points(r_src, min(s.source_step_mm, r_src / s.min_source_rows))
    scale = g.slit_width_collimator_um(SPIFFI) * 1e-3 / (lam * 1e-3 * SPIFFI.collimator_focal_mm)
    return g, g.beta_deg(lam), anam, d_xi, centred_axis(d_xi, R), sx, sy, w, scale


def abbe_sum(rows, xi, sx, w, scale_per_mm, n_fft):
    """Sum over every source point of |FFT(P_j T(xi - s_k))|^2, weighted (unshifted axis)."""
    acc = np.zeros(n_fft)
    for j in range(w.shape[0]):
        for k in range(w.shape[1]):
            if w[j, k] > 0:
                acc += w[j, k] * np.abs(np.fft.fft(rows[j] * np.sinc(scale_per_mm * (xi - sx[k])), n_fft)) ** 2
    return np.fft.fftshift(acc)


@pytest.mark.parametrize("mas", [25, 100, 250])
def test_modal_sum_is_the_abbe_sum_on_an_aberrated_quilted_pupil(mas):
    lam, s = 1.25, LsfSettings()
    g, beta, anam, d_xi, xi, sx, sy, w, scale = sampling(lam, mas)
    rows = pupil_rows(g, lam, xi, sy, beta, quilt_sag_map(0.82, form="product"), (1.5, -0.5),
                      {(3, 1): 0.1, (2, -2): 0.05}, SPIFFI, d_xi)
    w_coll = g.slit_width_collimator_um(SPIFFI)
    ref = abbe_sum(rows, xi, sx, w, scale, s.n_fft)
    got = partially_coherent_lsf(rows, xi, sx, w, lam, w_coll, SPIFFI.collimator_focal_mm,
                                 SPIFFI.camera_focal_mm, anam, s.n_fft).intensity
    ref, got = ref / ref.sum(), got / got.sum()
    modes = slit_modes(xi, sx, w, scale)
    # Parseval: the dropped modes' flux share is at most their eigenvalue share (|P| <= 1),
    # relative to a total that the aperture can cut to no less than a tenth of the sum.
    assert np.abs(got - ref).sum() <= 10 * modes.dropped_fraction + 1e-12
    assert modes.n_sources == np.count_nonzero(w) == line_profile("J", lam, mas).info["n_sources"]


def test_fewer_modes_than_sources_where_slit_spectra_overlap():
    """Shifted slit spectra overlap (first zero 13 mm, 110 mm pupil): at 250 mas a row of up
    to 88 sources holds far fewer modes with any light."""
    _, _, _, _, xi, sx, _, w, scale = sampling(1.25, 250)
    modes = slit_modes(xi, sx, w, scale)
    assert modes.row.size < modes.n_sources / 3
    assert modes.dropped_fraction < 1e-10


def test_modes_reproduce_each_rows_mutual_intensity():
    """sum_m phi_m phi_m^T over a row's modes is sum_k w_k T_k T_k^T (the definition)."""
    xi = np.linspace(-20.0, 20.0, 81)
    sx, _, w = source_points(6.0, 1.0)
    scale = 1 / 5.0
    modes = slit_modes(xi, sx, w, scale, rtol=0.0)
    T = np.sinc(scale * (xi[None, :] - sx[:, None]))
    for j in range(w.shape[0]):
        m_ref = (T.T * w[j]) @ T
        phi = modes.field[modes.row == j]
        assert np.allclose(phi.T @ phi, m_ref, atol=1e-12 * np.abs(m_ref).max())


def test_one_illumination_is_decomposed_once():
    xi = np.linspace(-20.0, 20.0, 81)
    sx, _, w = source_points(6.0, 1.0)
    a = slit_modes(xi, sx, w, 0.2)
    assert slit_modes(xi.copy(), sx.copy(), w.copy(), 0.2) is a
    assert slit_modes(xi, sx, w, 0.21) is not a


@pytest.mark.parametrize("weights, rtol, words", [
    (np.ones((3, 4)), 1e-12, "weights has shape (3, 4), must be (n_rows, n_sx=5)"),
    (-np.ones((3, 5)), 1e-12, "weights must be finite and >= 0"),
    (np.full((3, 5), np.nan), 1e-12, "weights must be finite and >= 0"),
    (np.ones((3, 5)), 1.5, "rtol=1.5 must be in [0, 1)"),
])
def test_bad_illumination_is_refused_by_name(weights, rtol, words):
    with pytest.raises(ValueError, match=re.escape(words)):
        slit_modes(np.linspace(-10.0, 10.0, 21), np.linspace(-2.0, 2.0, 5), weights, 0.2, rtol=rtol)
