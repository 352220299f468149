"""The FEA case model: defaults, round trip, every refusal, and the mesh estimate before meshing."""

import math

import pytest

from fea.case import PARAMETERS, FEACase, resolve_params
from fea.errors import ParameterError
from fea.geometry import Blank
from fea.mesh import MeshSpec
from fea.mesh_budget import check_mesh_budget, estimate_dofs, estimate_memory_bytes

#: The paper's setup (George et al. §3: 160 x 140 x 20 mm Al 6061 blank, 7 x 7 holes of 15 mm
#: at 21 x 18 mm; 200 µm NiP polished to 75 %; 293 K -> 80 K) and the defaults the parameter
#: table had before it moved here (None = the model's own default).
PAPER_DEFAULTS = {
    "coverage": "all", "t0_um": 200.0, "polish": 0.75, "polish_back": None, "cold_K": 80.0, "warm_K": 293.0,
    "substrate": "Al6061-T6", "film": "NiP", "stress_scale": None,
    "size_x_mm": 160.0, "size_y_mm": 140.0, "thickness_mm": 20.0, "hole_diameter_mm": 15.0,
    "pitch_x_mm": 21.0, "n_holes_x": 7, "pitch_y_mm": 18.0, "n_holes_y": 7, "hole_axis_z_mm": 0.0,
    "mesh_size_mm": None, "mesh_bulk_mm": None,
}


def test_defaults_are_the_papers_setup():
    assert FEACase().as_params() == PAPER_DEFAULTS
    assert {k: p.default for k, p in PARAMETERS.items()} == PAPER_DEFAULTS
    full = FEACase().resolved()
    assert (full.polish_back, full.stress_scale, full.mesh_size_mm, full.mesh_bulk_mm) == (0.75, 0.7913, 1.4, 2.8)
    assert resolve_params({"polish": 0.5})["polish_back"] == 0.5


def test_round_trip_and_cache_key():
    case = FEACase.from_params({"t0_um": 150, "polish": 0.5, "polish_back": 1.0, "substrate": "AlSi40",
                                "pitch_x_mm": 42, "n_holes_x": 3.0, "mesh_size_mm": 5, "mesh_bulk_mm": 10})
    assert FEACase.from_params(case.as_params()) == case
    assert case.n_holes_x == 3 and isinstance(case.n_holes_x, int) and case.pitch_x_mm == 42.0
    # two spellings of one case share a key; another case does not
    assert FEACase.from_params({}).cache_key() == FEACase.from_params(
        {"polish_back": 0.75, "stress_scale": 0.7913, "mesh_size_mm": 1.4}).cache_key()
    assert FEACase.from_params({"t0_um": 150}).cache_key() != FEACase().cache_key()


def test_to_objects_builds_what_the_solver_takes():
    o = FEACase.from_params({"t0_um": 150, "polish": 0.5, "polish_back": 1.0, "cold_K": 100,
                             "mesh_size_mm": 5, "mesh_bulk_mm": 10}).to_objects()
    assert o.blank == Blank()
    assert (o.coating.t0_um, o.coating.polish_front, o.coating.polish_back) == (150.0, 0.5, 1.0)
    assert (o.load.warm_K, o.load.cold_K) == (293.0, 100.0)
    assert o.mesh == MeshSpec(5.0, 10.0, symmetry="quarter")   # front and back differ: no mid-plane symmetry
    assert (o.substrate.name, o.film.name, o.stress_scale) == ("Al6061-T6", "NiP", 0.7913)
    assert FEACase().to_objects().mesh == MeshSpec()               # symmetric: the eighth model


BIG = 2e30  # a memory budget nothing exceeds: these refusals are about the values


@pytest.mark.parametrize("params, key, message", [
    ({"t0_mu": 1}, "t0_mu", r"unknown FEA parameter\(s\) \['t0_mu'\]; did you mean 't0_um'\? valid names are"),
    ({"bogus": 1}, "bogus", r"unknown FEA parameter\(s\) \['bogus'\]; valid names are \['cold_K'"),
    ({"t0_um": "thick"}, "t0_um", r"t0_um='thick' must be a number \(\(0, 2000\]\)"),
    ({"t0_um": math.nan}, "t0_um", r"t0_um=nan must be finite"),
    ({"n_holes_x": 3.5}, "n_holes_x", r"n_holes_x=3\.5 must be an integer"),
    ({"polish": None}, "polish", r"polish=None: give a value"),
    ({"coverage": "hole"}, "coverage", r"coverage='hole' is unknown; valid values are \['all', 'holes'"),
    ({"substrate": "steel"}, "substrate", r"substrate='steel' is unknown; valid values are \['Al6061-T6'"),
    ({"film": 3}, "film", r"film=3 must be a string"),
    ({"t0_um": -10}, "t0_um", r"t0_um=-10\.0 is outside the valid range \(0, 2000\] µm"),
    ({"polish": 1.5}, "polish", r"polish=1\.5 is outside the valid range \(0, 1\]"),
    ({"polish_back": 0}, "polish_back", r"polish_back=0\.0 is outside the valid range \(0, 1\]"),
    ({"cold_K": 500}, "cold_K", r"cold_K=500\.0 K is outside the thermal-strain data range of Al6061-T6 \(4\.\.300 K\)"),
    ({"cold_K": 290, "warm_K": 200}, "cold_K", r"cold_K=290 K must be below warm_K=200 K"),
    ({"stress_scale": 0}, "stress_scale", r"stress_scale=0\.0 is outside the valid range > 0"),
    ({"size_x_mm": 1e6}, "size_x_mm", r"size_x_mm=1000000\.0 is outside the valid range \[10, 1000\] mm"),
    ({"size_y_mm": 5, "n_holes_y": 0}, "size_y_mm", r"size_y_mm=5\.0 is outside the valid range \[10, 1000\] mm"),
    ({"thickness_mm": 400, "hole_diameter_mm": 15}, "thickness_mm", r"thickness_mm=400\.0 is outside .*\[2, 300\] mm"),
    ({"hole_diameter_mm": 0.5}, "hole_diameter_mm", r"hole_diameter_mm=0\.5 is outside .*\[1, 300\] mm"),
    ({"hole_diameter_mm": 25}, "hole_diameter_mm", r"hole_diameter_mm=25\.0: .*breaks through"),
    ({"pitch_x_mm": 10}, "pitch_x_mm", r"pitch_x_mm=10\.0: neighbouring holes .* overlap"),
    ({"n_holes_x": 101, "pitch_x_mm": 2, "hole_diameter_mm": 1, "size_x_mm": 1000}, "n_holes_x",
     r"n_holes_x=101 is outside the valid range \[0, 100\]"),
    ({"n_holes_y": -1}, "n_holes_y", r"n_holes_y=-1: valid range is integers >= 0"),
    ({"mesh_size_mm": 0}, "mesh_size_mm", r"size_mm=0\.0: valid range is a finite number > 0 mm"),
    ({"mesh_size_mm": 2, "mesh_bulk_mm": 1}, "mesh_bulk_mm", r"mesh_bulk_mm=1\.0: valid range is >= mesh_size_mm=2\.0"),
    ({"mesh_size_mm": 30, "mesh_bulk_mm": 40}, "mesh_size_mm", r"mesh_size_mm=30 is larger than the blank's "
     r"thickness_mm=20; valid range is 0 < mesh_size_mm <= thickness_mm"),
    ({"mesh_bulk_mm": 200}, "mesh_bulk_mm", r"mesh_bulk_mm=200 is larger than the blank \(160 mm\); valid range"),
])
def test_every_refusal_names_the_key_the_value_and_the_range(params, key, message):
    with pytest.raises(ParameterError, match=message) as info:
        FEACase.from_params(params, memory_budget_bytes=BIG)
    assert info.value.parameter == key
    assert isinstance(info.value, ValueError) and "\n" not in str(info.value)


@pytest.mark.parametrize("name", [k for k, p in PARAMETERS.items() if p.low is not None or p.high is not None])
def test_every_stated_range_is_enforced(name):
    """Each bound in the parameter table refuses the first value past it (the other parameters
    made roomy enough that only this one is wrong)."""
    p = PARAMETERS[name]
    roomy = {"size_x_mm": 1000.0, "size_y_mm": 1000.0, "thickness_mm": 300.0, "hole_diameter_mm": 1.0,
             "n_holes_x": 0, "n_holes_y": 0, "pitch_x_mm": 2.0, "pitch_y_mm": 2.0, "mesh_size_mm": 1.0,
             "mesh_bulk_mm": 100.0}
    for bound, step in ((p.low, -1e-6 if not p.low_open else 0.0), (p.high, 1)):
        if bound is None:
            continue
        value = bound + step
        with pytest.raises(ParameterError) as info:
            FEACase.from_params({**roomy, name: value}, memory_budget_bytes=BIG)
        assert info.value.parameter == name and f"{name}=" in str(info.value)
    inside = p.low + 1 if p.low is not None else p.high - 1
    FEACase.from_params({**roomy, name: int(inside) if p.kind == "int" else inside}, memory_budget_bytes=BIG)


def test_a_mesh_past_the_memory_budget_is_refused_before_meshing():
    with pytest.raises(ParameterError, match=r"mesh_size_mm=0\.01 .*estimated .* DOFs and .* GB, more than the "
                                             r"memory budget of 16 GB; use larger elements") as info:
        FEACase.from_params({"mesh_size_mm": 0.01, "mesh_bulk_mm": 0.02}, memory_budget_bytes=16e9)
    assert info.value.parameter == "mesh_size_mm"
    FEACase.from_params({}, memory_budget_bytes=16e9)             # the default mesh fits 16 GB
    with pytest.raises(ParameterError, match="memory budget of 2 GB"):
        FEACase.from_params({}, memory_budget_bytes=2e9)
    dofs = check_mesh_budget(Blank(), MeshSpec(), 16e9)
    assert estimate_memory_bytes(dofs) < 16e9


@pytest.mark.parametrize("blank, spec", [
    (Blank(), MeshSpec.coarse()),                                                       # holes, eighth model
    (Blank(n_holes_x=0, n_holes_y=0, thickness_mm=12.0), MeshSpec(3.0, 6.0, "quarter")),  # solid, quarter
])
def test_dof_estimate_is_within_a_factor_two_of_real_meshes(blank, spec):
    """Acceptance rule fixed before the run: 1/2 <= estimate / actual <= 2 on two meshes of
    different shape, symmetry and element size (the estimate has no fitted constant)."""
    from skfem import Basis, ElementTetP2

    from fea.mesh import blank_mesh

    actual = 3 * Basis(blank_mesh(blank, spec), ElementTetP2()).N
    assert 0.5 <= estimate_dofs(blank, spec) / actual <= 2.0, (estimate_dofs(blank, spec), actual)


def test_dof_estimate_follows_the_mesh_convergence_ladder():
    """The DOF counts of the eighth model in benchmarks/results_mesh_convergence.md (real meshes
    at four element sizes): the estimate stays within a factor of two at every level."""
    for size, bulk, dofs in ((2.0, 4.0, 91038), (1.4, 2.8, 216096), (1.0, 2.0, 480015), (0.8, 1.6, 858429)):
        assert 0.5 <= estimate_dofs(Blank(), MeshSpec(size, bulk)) / dofs <= 2.0


def test_a_manifest_substrate_reaches_the_diagnosis_nominal_model(monkeypatch):
    """[simulation] substrate = "AlSi40": the nominal FEA map is meshed with it, and the
    thermal rescaling of the nominal uses the film-minus-AlSi40 mismatch."""
    import fea.api
    from fea.materials import ALSI40, NIP_HIGH_P
    from pipeline.diagnosis.manifest import Simulation
    from pipeline.diagnosis.nominal import nominal_sag_map, thermal_factor

    sim = Simulation.from_params({"substrate": "AlSi40", "cold_K": 80, "mesh": "coarse"})
    assert sim.materials == ("AlSi40", "NiP") and sim.case.mesh_size_mm == 5.0

    seen = {}

    def fake_prepare(blank, mesh, substrate):
        seen.update(blank=blank, mesh=mesh, substrate=substrate)
        raise RuntimeError("stop before meshing")

    monkeypatch.setattr(fea.api, "prepare", fake_prepare)
    with pytest.raises(RuntimeError, match="stop before meshing"):
        nominal_sag_map(sim)
    assert seen["substrate"] is ALSI40 and seen["mesh"] == MeshSpec.coarse()

    # the mismatch ratio written out from the material data (AlSi40 follows the 6061 curve
    # scaled by its room-temperature CTE)
    def eps(T):
        return NIP_HIGH_P.strain_between(293, T) - ALSI40.strain_between(293, T)

    assert thermal_factor(128, 80, 293, *sim.materials) == pytest.approx(eps(128) / eps(80), rel=1e-12)
    # (the library's materials share the 6061 curve's shape, so this factor equals the Al 6061
    # one; a material with another shape would change it)


@pytest.mark.slow
def test_alsi40_nominal_map_bends_by_its_smaller_mismatch():
    """Two coarse-mesh solves (~5 s idle). The sag is linear in the film mismatch strain and,
    for a thin film, inversely proportional to the substrate's modulus (Stoney), so the AlSi40
    map's P/V over the Al 6061 one lies between (E_Al / E_AlSi40) x and 1 x the ratio of
    their mismatch strains (0.75 ... 1, with margin for the plate not being a thin film)."""
    import numpy as np

    from fea.materials import ALSI40, AL6061_T6
    from pipeline.diagnosis.manifest import Simulation
    from pipeline.diagnosis.nominal import mismatch_strain, nominal_sag_map

    def pv(sim):
        s = nominal_sag_map(sim).sag_um
        return float(np.nanmax(s) - np.nanmin(s))

    ratio = pv(Simulation.from_params({"substrate": "AlSi40", "mesh": "coarse"})) / pv(
        Simulation.from_params({"mesh": "coarse"}))
    mismatch = mismatch_strain(80, 293, "AlSi40") / mismatch_strain(80, 293)
    stiffer = AL6061_T6.youngs_modulus_Pa / ALSI40.youngs_modulus_Pa
    assert 0.8 * stiffer * mismatch <= ratio <= mismatch


def test_nominal_map_cache_key_of_the_paper_case_names_only_its_physics(tmp_path):
    """The diagnosis cache of the default blank and materials is keyed by the FEA case's
    physical parameters alone (those left at their defaults are not named): a map stored
    in the keyed store under the key written out by hand is found without solving anything."""
    import numpy as np

    from fea import store

    from fea import MODEL_VERSION
    from fea.calibration import STRESS_SCALE
    from pipeline.diagnosis.manifest import parse_manifest
    from pipeline.diagnosis.nominal import nominal_sag_map

    key = dict(t0_um=200.0, polish=0.75, coverage="all", cold_K=80.0, warm_K=293.0, mesh="default",
               spacing_mm=0.5, stress_scale=float(STRESS_SCALE), fea_model_version=MODEL_VERSION)
    x, y = np.linspace(-1, 1, 3), np.linspace(-2, 2, 5)
    entry = store.entry(tmp_path, "diagnosis-fea-sag-map", key, prefix="fea-")
    store.save_arrays(entry, {"x_mm": x, "y_mm": y, "sag_um": np.full((5, 3), 0.123)})
    (tmp_path / "m.csv").write_text("offset_um,intensity\n0,1\n")
    man = parse_manifest({"simulation": {"coverage": "all", "t0_um": 200, "polish": 0.75, "cold_K": 80,
                                         "mesh": "default"},
                          "measurement": [{"kind": "line_profile", "file": "m.csv", "grating": "J", "order": -2,
                                           "wavelength_um": 1.25, "pixel_scale_mas": 250}]}, tmp_path)
    m = nominal_sag_map(man.simulation, cache_dir=tmp_path)
    assert np.all(m.sag_um == 0.123)
