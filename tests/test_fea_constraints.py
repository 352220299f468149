"""Constraints of the symmetry models: the symmetry planes plus the fewest point
constraints that leave no rigid-body motion (statics: 3-2-1 for a free body, one for a
body cut by x = 0 and y = 0, none for one cut by three planes). A unit cube stands in
for the blank, so these tests need no gmsh."""
import numpy as np
import pytest
from skfem import MeshTet

from fea.assembly import scalar_basis
from fea.coating import Coating
from fea.constraints import (check_symmetry, constrained_dofs, plane_constrained_dofs, symmetry_constraints,
                             symmetry_planes)
from fea.linsolve import rigid_modes


def _cube(planes):
    where = {"sym_x": lambda x: np.isclose(x[0], 0), "sym_y": lambda x: np.isclose(x[1], 0),
             "sym_z": lambda x: np.isclose(x[2], 0), "front": lambda x: np.isclose(x[2], 1)}
    return MeshTet().refined(2).with_boundaries({k: v for k, v in where.items() if k in planes + ("front",)})


@pytest.mark.parametrize("planes, n_points", [(("sym_x", "sym_y", "sym_z"), 0), (("sym_x", "sym_y"), 1), ((), 6)])
def test_point_constraints_remove_exactly_the_surviving_rigid_modes(planes, n_points):
    mesh = _cube(planes)
    basis = scalar_basis(mesh)
    assert symmetry_planes(mesh) == planes
    plane = plane_constrained_dofs(mesh, basis, symmetry_constraints(planes))
    # each plane holds its normal component: DOF 3*d + component
    for name, comp in symmetry_constraints(planes).items():
        nodes = basis.get_dofs(mesh.boundaries[name]).all()
        assert np.isin(3 * nodes + comp, plane).all()
        assert not np.isin(3 * nodes + (comp + 1) % 3, plane).all()
    fixed = constrained_dofs(basis.doflocs, plane)
    assert fixed.size - plane.size == n_points
    assert np.isin(plane, fixed).all()
    # no rigid motion survives: the six modes are independent on the fixed DOFs
    assert np.linalg.matrix_rank(rigid_modes(basis.doflocs)[fixed]) == 6


def test_mid_plane_symmetry_refuses_an_asymmetric_coating():
    asym = Coating(200, 0.5, 0.75)
    check_symmetry(asym, ("sym_x", "sym_y"))  # a quarter model carries both faces
    check_symmetry(Coating.symmetric(200, 0.5, "all"), ("sym_x", "sym_y", "sym_z"))
    with pytest.raises(ValueError, match="not symmetric about the mid-plane"):
        check_symmetry(asym, ("sym_x", "sym_y", "sym_z"))
