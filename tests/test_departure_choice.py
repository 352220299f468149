"""Whether a measured map's departure is carried into the line profiles of its blank
(``pipeline.diagnosis.departure_choice``): where the map sees the grating's own quilt the
profiles fit better with it; where the map's departure is the map's own error the profiles
fit better without it.

The profiles are made by the independent truth's 2-D Abbe sum (``tests/diagnosis_cases.py``),
the map written here from the analytic sum-form quilt; neither uses the diagnosis' optics.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter

from pipeline.diagnosis.criteria import Criteria
from pipeline.diagnosis.departure_choice import departure_choice
from pipeline.diagnosis.engine import build_problem, fit_effects
from pipeline.diagnosis.manifest import load_data, load_manifest
from diagnosis_cases import abbe_profiles_manifest, nominal_map, sag_function_of

RADIUS_MM = 68.5
MAP_NOISE_UM = 0.002


def _cell(x, y, x0, y0):
    """1 over the lattice cell centred at ``(x0, y0)`` (21 x 18 mm), 0 outside, the edges
    blended over ~1.5 mm."""
    from scipy.special import erf

    def edge(u, half):
        return 0.5 * (erf((u + half) / (1.5 * np.sqrt(2))) - erf((u - half) / (1.5 * np.sqrt(2))))
    return edge(x - x0, 10.5) * edge(y - y0, 9.0)


def _stronger_pockets(x, y):
    """The pockets under the beam print through unevenly: the centre's 30 % more, its
    neighbours along the dispersion 20 % less."""
    return 1.0 + 0.3 * _cell(x, y, 0.0, 0.0) - 0.2 * _cell(x, y, 21.0, 0.0) - 0.2 * _cell(x, y, -21.0, 0.0)


def _with_map(tmp_path, sag_um_at):
    """Add to the profiles' manifest a map (1 mm grid over the 137 mm aperture, as the valid
    points of an interferometer export, with white noise) whose sag is ``sag_um_at(x, y)``."""
    ax = np.arange(-68.0, 68.5, 1.0)
    X, Y = np.meshgrid(ax, ax)
    sag = sag_um_at(X, Y) + np.random.default_rng(3).normal(0.0, MAP_NOISE_UM, X.shape)
    keep = X**2 + Y**2 <= RADIUS_MM**2
    np.savetxt(tmp_path / "map.csv", np.column_stack([X[keep], Y[keep], sag[keep]]), delimiter=",",
               header="x_mm,y_mm,sag_um", comments="")
    p = tmp_path / "m.toml"
    p.write_text(p.read_text() + '\n[[measurement]]\nkind = "surface"\nfile = "map.csv"\ngrating = "J"\n'
                 f'temperature_K = 80\naperture_diameter_mm = 137\nnoise_um = {MAP_NOISE_UM}\n')
    return p


def _map_error_case(tmp_path):
    """(manifest path, nominal): Abbe-sum profiles of the nominal quilt, and a map of it with a
    correlated error (white noise smoothed over 3 mm, 15 nm RMS) on its 1 mm grid."""
    nominal = nominal_map(tmp_path)
    abbe_profiles_manifest(tmp_path, (250, 25), 5)
    sag = sag_function_of(nominal)
    ax = np.arange(-68.0, 68.5, 1.0)
    err = gaussian_filter(np.random.default_rng(11).normal(size=(ax.size, ax.size)), 3.0)
    err *= 0.015 / err.std()
    return _with_map(tmp_path, lambda x, y: sag(x, y) + err), nominal  # x, y: the map's own grid


def _choice(path, nominal):
    manifest = load_manifest(path)
    prob, nom = build_problem(manifest, load_data(manifest), nominal, map_in_optics=True)
    finding, fo = fit_effects(prob, nom, ("slit_width",), Criteria())
    return departure_choice(prob, finding, fo, Criteria())


def test_a_map_of_the_gratings_own_quilt_is_carried(tmp_path):
    """Truth: pockets under the beam printing through 30 % more and 20 % less than the
    lattice's; the map measures them. The profiles fit the slit-width finding better with
    the departure than without it by more than the choice's margin."""
    nominal = nominal_map(tmp_path)
    abbe_profiles_manifest(tmp_path, (250, 25), 5, sag_factor=_stronger_pockets)
    sag = sag_function_of(nominal)
    c = _choice(_with_map(tmp_path, lambda x, y: _stronger_pockets(x, y) * sag(x, y)), nominal)
    assert c.carried
    assert c.bic_without - c.bic_with > Criteria().degenerate_bic


def test_a_maps_own_error_is_not_carried(tmp_path):
    """Truth: the nominal quilt; the map carries a correlated error of the interferometer
    (white noise smoothed over 3 mm, 15 nm RMS: mid-spatial frequencies in the quilt's band).
    The profiles fit better without the departure by more than the margin. Measured: at 3-8 nm
    the same error is rejected for one of two noise draws (by 3-13 in BIC); for the other the
    profiles fit with and without it within 1.5, where carrying it costs nothing."""
    path, nominal = _map_error_case(tmp_path)
    c = _choice(path, nominal)
    assert not c.carried
    assert c.bic_with - c.bic_without > Criteria().degenerate_bic
    # the refit is kept for the ranking redone without the departure, which restarts from it
    assert c.without is not None and set(c.without.parameters) == {"slit_image_width_um"}


def test_the_diagnosis_says_whether_it_carried_the_departure(tmp_path):
    """The map's own error above, diagnosed: the departure is computed, not carried (the
    diagnosis is the one made without it), and the report says so with both BICs."""
    from html import unescape

    from pipeline.diagnosis import diagnose
    from pipeline.diagnosis.report import write_report

    path, _ = _map_error_case(tmp_path)
    d = diagnose(path, effects=("slit_width",), heldout=False, keep_curves=False)
    choice = d.baseline["map_departure_choice"]
    assert choice["carried"] is False and choice["bic_without"] < choice["bic_with"] - 2.0
    assert len(d.baseline["map_departures"]) == 1
    without = diagnose(path, effects=("slit_width",), heldout=False, keep_curves=False,
                       criteria=Criteria(map_in_optics=False))
    assert [f.effect for f in d.findings] == [f.effect for f in without.findings]
    assert d.findings[0].parameters == pytest.approx(without.findings[0].parameters, rel=1e-9)
    _, page = write_report(d, tmp_path / "out")
    assert "The map's departure is not carried: slit_width fits the images" in unescape(page.read_text())


def test_a_fit_restarts_from_a_warm_fit_it_nests(tmp_path):
    """``fit_effects(..., warm=...)``: J profiles of a 6 mm pupil shift, fitted from a start at
    -6 mm, end at the prior's -10 mm bound with about twice the objective of the multi-start
    fit; given that fit as ``warm`` the combination ends at its optimum, and a warm fit with a
    parameter the combination does not hold is ignored."""
    from dataclasses import replace

    from diagnosis_cases import profile_image_case

    from pipeline.diagnosis.fitting import fit
    from pipeline.diagnosis.nominal import nominal_sag_map
    from pipeline.diagnosis.ranking import parameters_of

    manifest = load_manifest(profile_image_case(tmp_path, {"pupil_x_mm": 6.0, "pupil_y_mm": 1.0}, psf=False))
    nominal = nominal_sag_map(manifest.simulation, None)
    prob, nom = build_problem(manifest, load_data(manifest), nominal)
    good = fit(prob, parameters_of(("pupil_shift",), prob.forwards))
    start = {"pupil_x_mm": -6.0, "pupil_y_mm": 1.0}
    w = prob.weights
    _, cold = fit_effects(prob, nom, ("pupil_shift",), Criteria(), start=start)
    assert cold.weighted_rss(w) > 1.5 * good.weighted_rss(w)  # the start's basin is a worse one
    _, warm = fit_effects(prob, nom, ("pupil_shift",), Criteria(), start=start, warm=(good,))
    assert warm.weighted_rss(w) <= good.weighted_rss(w) * (1 + 1e-6)
    other = replace(good, parameters={**good.parameters, "slit_image_width_um": 30.0})
    _, ignored = fit_effects(prob, nom, ("pupil_shift",), Criteria(), start=start, warm=(other,))
    assert ignored.weighted_rss(w) == pytest.approx(cold.weighted_rss(w), rel=1e-9)
