"""Reduced basis and surrogate: exact thickness polynomials, Galerkin reproduction,
the shared-preconditioner iterative solve against the direct one, and the surrogate
against full solves (coarse mesh)."""
import numpy as np
import pytest

from fea.api import prepare
from fea.calibration import STRESS_SCALE
from fea.coating import Coating
from fea.free_dofs import FreeStiffness
from fea.materials import NIP_HIGH_P as NIP
from fea.mesh import MeshSpec
from fea.model import ThermalLoad
from fea.reduced import FilmPolynomial, powers
from fea.surrogate import SurrogateDomain, build_surrogate

COARSE = MeshSpec(size_mm=5.0, size_bulk_mm=10.0)


@pytest.fixture(scope="module")
def model():
    return prepare(mesh=COARSE)


@pytest.fixture(scope="module")
def direct_pv(model):
    """P/V_center (µm) of the module model's direct solve of a coating at a stress scale.

    Memoised on the film thickness per surface group (all that the solve takes from the
    coating): the reference solves of the lockstep and sweep tests coincide there (a
    holes-only coating has no polished face), and each costs ~5 s of CPU.
    """
    memo = {}

    def pv(coating, stress_scale):
        assert model.ndof <= model.explicit_offset_max_dof  # a direct solve, not the CG under test
        key = (tuple(sorted(model.film_thickness_um(coating).items())), stress_scale)
        if key not in memo:
            memo[key] = model.solve(coating, stress_scale=stress_scale).sag.pv_um("center")
        return memo[key]

    return pv


def test_thickness_polynomial_is_exact(model):
    """The interpolated coefficients reproduce the film operators at any thickness."""
    ops = model.film_ops("holes_x", NIP)
    poly = FilmPolynomial(ops)
    rng = np.random.default_rng(0)
    V = rng.standard_normal((model.ndof, 2))
    for t_mm in (0.013, 0.2, 0.47):
        direct = ops.local_stiffness(t_mm) @ V + ops.apply_coupling(t_mm, V)
        interp = np.tensordot(powers(t_mm), poly.stiffness_coeffs_apply(V), axes=1)
        assert np.abs(interp - direct).max() <= 1e-9 * np.abs(direct).max()
        load = ops.load(t_mm, 1e-3)
        assert np.abs(1e-3 * powers(t_mm) @ poly.load_coeffs - load).max() <= 1e-9 * np.abs(load).max()


@pytest.mark.slow  # several FEA solves compared, among the slowest tests of the fast tier: the full tier
def test_iterative_shared_solve_equals_direct(model):
    """CG with a shared factor and reduced-basis start gives the direct solve's answer."""
    cases = [Coating.symmetric(200, 0.75, "all"), Coating.symmetric(100, 1.0, "holes"),
             Coating.symmetric(150, 0.5, "all"), Coating.symmetric(200, 1.0, "surfaces")]
    ref = [model.solve(c).sag.pv_um("center") for c in cases]
    saved = model.explicit_offset_max_dof
    model.explicit_offset_max_dof = 0
    try:
        got = [model.solve(c) for c in cases]
    finally:
        model.explicit_offset_max_dof = saved
        model.release_preconditioner()
    assert [g.info["solver"]["preconditioner"] for g in got][:2] == ["own", "shared"]
    for g, r in zip(got, ref):
        assert g.sag.pv_um("center") == pytest.approx(r, rel=1e-5)
        assert g.info["solver"]["residual"] <= 1e-5  # the default rtol


def test_galerkin_reproduces_a_snapshot(model):
    """A field in the basis is recovered exactly, at any mismatch strain (linearity)."""
    rb = model.reduced_basis(NIP)
    c = Coating.symmetric(180, 0.6, "all")
    saved = model.explicit_offset_max_dof
    model.explicit_offset_max_dof = 0
    try:
        u = model.solve(c).displacement_mm.T.ravel()
    finally:
        model.explicit_offset_max_dof = saved
        model.release_preconditioner()
    eps = model.mismatch_strain(NIP, ThermalLoad(), 1.0)
    t_mm = {g: t * 1e-3 for g, t in model.film_thickness_um(c).items()}
    for scale in (1.0, 0.37):
        a = rb.solve(t_mm, scale * eps)
        assert np.linalg.norm(rb.expand(a) - scale * u) <= 1e-5 * np.linalg.norm(u)
        assert rb.residual_norm(a, t_mm, scale * eps) <= 1e-5


def test_surrogate_matches_full_solves(model):
    """Greedy surrogate over a t0/polish box: P/V within 0.5 % of full solves at random points."""
    dom = SurrogateDomain(t0_um=(100, 200), polish=(0.5, 1.0), coverages=("all", "holes"))
    model.explicit_offset_max_dof = 0
    try:
        s = build_surrogate(model, dom, stress_scale=STRESS_SCALE, tol=2e-3, max_solves=16)
        assert s.build_info["converged"]
        rows = s.validate(3, seed=3)
    finally:
        model.explicit_offset_max_dof = 70_000
        model.release_preconditioner()
    for r in rows:
        assert abs(r["rel_error"]) < 5e-3, r
    c = Coating.symmetric(130, 0.8, "holes")
    sag = s.evaluate(c).sag
    st = s.statistics(c)
    for region in ("center", "full"):
        assert st[f"pv_{region}_um"] == pytest.approx(sag.pv_um(region), rel=1e-9)
        assert st[f"rms_{region}_um"] == pytest.approx(sag.rms_um(region), rel=1e-7)
    # temperature enters only through the load: P/V scales with the mismatch strain
    c = Coating.symmetric(150, 0.75, "all")
    cold = ThermalLoad(cold_K=150.0)
    ratio = (model.mismatch_strain(NIP, cold, STRESS_SCALE)
             / model.mismatch_strain(NIP, ThermalLoad(), STRESS_SCALE))
    assert s.pv_center_um(c, cold) == pytest.approx(ratio * s.pv_center_um(c), rel=1e-9)
    with pytest.raises(ValueError, match="outside the surrogate's domain"):
        s.evaluate(Coating.symmetric(300, 0.75, "all"))


def test_free_stiffness_on_bulk_pattern_equals_sparse_sum():
    """The per-case stiffness formed on the bulk's data array equals bulk + film local
    matrices, also when the bulk pattern lacks entries the film has (exact zeros that the
    bulk assembly dropped): the pattern is widened, not the entry lost."""
    m = prepare(mesh=COARSE)
    c = Coating.symmetric(200, 0.5, "all")
    used = m.film_thickness_um(c)
    fs = FreeStiffness(m.K_bulk, m.free)
    Kb = fs.bulk.copy()
    film_rows = m.film_ops("front", NIP).A00[m.free][:, m.free].tocoo()
    # drop a few bulk entries where the front film has entries (as exact zeros would be)
    Kb = Kb.tolil()
    for r, col in list(zip(film_rows.row, film_rows.col))[:50:7]:
        Kb[r, col] = 0.0
        Kb[col, r] = 0.0
    Kb = Kb.tocsr()
    Kb.eliminate_zeros()
    fs.bulk = Kb
    fast = fs.stiffness({g: (m.film_ops(g, NIP), t * 1e-3) for g, t in used.items()}, offset=True)
    ref = Kb.copy()
    for g, t in used.items():
        ref = ref + m.film_ops(g, NIP).local_stiffness(t * 1e-3)[m.free][:, m.free]
    assert fast.nnz > Kb.nnz
    assert abs(fast - ref).max() <= 1e-12 * abs(ref).max()


@pytest.mark.slow
def test_batched_statistics_equal_per_case(model):
    """statistics_many (one matrix product per chunk) gives statistics() per case."""
    s = build_surrogate(model, SurrogateDomain(), stress_scale=STRESS_SCALE, tol=5e-3)
    cases = SurrogateDomain().sample(7, np.random.default_rng(3))
    many = s.statistics_many(cases, chunk=3)
    for c, m in zip(cases, many):
        one = s.statistics(c)
        for k, v in one.items():
            assert m[k] == pytest.approx(v, rel=1e-10, abs=1e-14), k


@pytest.mark.slow  # several FEA solves compared, among the slowest tests of the fast tier: the full tier
def test_solve_many_lockstep_equals_one_by_one(model, direct_pv):
    """Block CG over several cases (one factor, block substitutions) = solve() per case."""
    cases = [Coating.symmetric(200, 0.75, "all"), Coating.symmetric(100, 1.0, "holes"),
             Coating.symmetric(150, 0.5, "all"), Coating.symmetric(200, 1.0, "surfaces"),
             Coating.symmetric(200, 1.0, "none")]
    ref = [direct_pv(c, STRESS_SCALE) for c in cases]  # small mesh: direct solves
    saved = model.explicit_offset_max_dof
    model.explicit_offset_max_dof = 0
    try:
        got = model.solve_many(cases, stress_scale=STRESS_SCALE)
    finally:
        model.explicit_offset_max_dof = saved
        model.release_preconditioner()
    for g, r, c in zip(got, ref, cases):
        assert g.info["coverage"] == c.coverage
        if c.coverage == "none":
            assert np.abs(g.displacement_mm).max() == 0
            continue
        assert g.info["solver"]["method"].startswith("block CG")
        assert g.info["solver"]["residual"] <= 1e-5
        assert g.sag.pv_um("center") == pytest.approx(r, rel=1e-5)


@pytest.mark.slow  # several FEA solves compared, among the slowest tests of the fast tier: the full tier
def test_sweep_runner_solves_planned_cases_in_blocks(tmp_path, direct_pv):
    """An inline sweep plans its cases: the FEA runner solves them as one lockstep block,
    with the answers of one-by-one solves."""
    from fea.case import FEACase
    from pipeline.sweeps.fea_cases import FEACaseRunner, fea_grid
    from pipeline.sweeps.sweep import run_sweep

    cases = fea_grid(coverage=["all", "holes"], t0_um=[200, 100], polish=[0.75],
                     mesh_size_mm=[COARSE.size_mm], mesh_bulk_mm=[COARSE.size_bulk_mm])
    runner = FEACaseRunner(with_maps=False)
    first = FEACase.from_params(cases[0].as_dict())
    model = runner.model(first.to_objects().blank, first.to_objects().mesh, first.substrate)
    model.explicit_offset_max_dof = 0  # the block path is for large meshes; force it here
    res = run_sweep(runner, cases, tmp_path, namespace="test-blocks", workers=1, progress=False,
                    planner=runner.plan)
    for case, out in res:
        coating = FEACase.from_params(case.as_dict()).to_objects().coating
        ref = direct_pv(coating, STRESS_SCALE)
        assert out["pv_center_um"] == pytest.approx(ref, rel=1e-5)
    assert not runner._planned and not runner._solved  # every planned case was used
