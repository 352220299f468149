"""The diagnosis fit's Jacobian: forward differences with the position nuisances of different
measurements perturbed in one evaluation.

The fit keeps its own difference loop (not ``least_squares``' built-in ``diff_step``) for one
reason that a test states: scipy's dense differences perturb one column per evaluation, and its
grouped (sparse) differences force an iterative trust-region solver (``tr_solver="lsmr"``;
``"exact"`` is refused beside ``jac_sparsity``), which takes other steps. Here the grouped
differences must give, number for number, the Jacobian scipy's dense differences give, so the
fit takes exactly the steps it took before, with one evaluation for all the profiles' offset
shifts instead of one each.
"""
import numpy as np
import pytest
from scipy.optimize import least_squares
from scipy.optimize._numdiff import approx_derivative  # the reference the fit must reproduce

from pipeline.diagnosis.fitting import DIFF_STEP, fd_steps, grouped_fd_jacobian


def _blocks_problem():
    """Two effect parameters acting on every row, and one position-like parameter per block
    acting on its own block's rows only (like a profile's offset shift)."""
    rng = np.random.default_rng(7)
    sizes = (40, 25, 60)
    edges = np.cumsum((0,) + sizes)
    blocks = [slice(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:])]
    t = [np.linspace(-1, 1, n) for n in sizes]
    data = [np.exp(-((u - 0.1) / 0.3) ** 2) * 1.2 + rng.normal(0, 0.01, u.size) for u in t]

    def fun(z):
        a, w = z[0], z[1]
        out = [np.exp(-((u - 0.05 * z[2 + i]) / (0.3 + 0.1 * w)) ** 2) * (1 + a) - d
               for i, (u, d) in enumerate(zip(t, data))]
        return np.concatenate(out)

    groups = [[(0, None)], [(1, None)], [(2 + i, b) for i, b in enumerate(blocks)]]
    return fun, groups


@pytest.mark.parametrize("z", [
    np.array([0.0, 0.0, 0.0, 0.0, 0.0]),  # the null start: sqrt(eps) steps
    np.array([0.3, -0.2, 1.5, -2.0, 0.7]),
    np.array([1.0, -1.0, 4.5, -4.5, 4.49999]),  # at and next to the bounds: steps turned inward
    np.array([0.999999999, 1e-12, -3.0, 2.0, -4.5]),
])
def test_grouped_differences_equal_scipys_column_by_column(z):
    fun, groups = _blocks_problem()
    lo = np.array([-1.0, -1.0, -4.5, -4.5, -4.5])
    hi = np.array([1.0, 1.0, 4.5, 4.5, 4.5])
    f0 = fun(z)
    ref = approx_derivative(fun, z, method="2-point", rel_step=DIFF_STEP, f0=f0, bounds=(lo, hi))
    got = grouped_fd_jacobian(fun, z, f0, fd_steps(z, lo, hi), groups)
    assert got.shape == ref.shape
    assert np.array_equal(got, ref)  # the same numbers, not close ones


def test_one_evaluation_serves_every_block_position():
    fun, groups = _blocks_problem()
    calls = []

    def counted(z):
        calls.append(1)
        return fun(z)

    z = np.array([0.3, -0.2, 1.5, -2.0, 0.7])
    lo, hi = np.full(5, -5.0), np.full(5, 5.0)
    grouped_fd_jacobian(counted, z, fun(z), fd_steps(z, lo, hi), groups)
    assert len(calls) == 3  # two effect columns, one for the three position columns


def test_a_fit_with_the_grouped_jacobian_takes_scipys_steps():
    """``least_squares`` with this Jacobian ends where it ends with its own ``diff_step``
    differences, to the last bit, and after as many evaluations."""
    fun, groups = _blocks_problem()
    lo = np.array([-1.0, -1.0, -4.5, -4.5, -4.5])
    hi = np.array([1.0, 1.0, 4.5, 4.5, 4.5])
    z0 = np.zeros(5)
    ref = least_squares(fun, z0, bounds=(lo, hi), method="trf", diff_step=DIFF_STEP, x_scale=1.0, xtol=1e-6,
                        ftol=1e-6)

    def jac(z):
        return grouped_fd_jacobian(fun, z, fun(z), fd_steps(z, lo, hi), groups)

    got = least_squares(fun, z0, jac=jac, bounds=(lo, hi), method="trf", x_scale=1.0, xtol=1e-6, ftol=1e-6)
    assert np.array_equal(got.x, ref.x) and got.nfev == ref.nfev and got.cost == ref.cost



def test_groups_whose_columns_would_mix_are_refused():
    fun, _ = _blocks_problem()
    z = np.array([0.3, -0.2, 1.5, -2.0, 0.7])
    h = fd_steps(z, np.full(5, -5.0), np.full(5, 5.0))
    f0 = fun(z)
    for groups in ([[(0, None), (2, slice(0, 40))]], [[(2, slice(0, 40)), (3, slice(30, 65))]]):
        with pytest.raises(ValueError, match=r"group \[\d, \d\] perturbs columns whose rows overlap"):
            grouped_fd_jacobian(fun, z, f0, h, groups)
    with pytest.raises(ValueError, match="h has 4 steps for 5 parameters"):
        grouped_fd_jacobian(fun, z, f0, h[:4], [[(0, None)]])
