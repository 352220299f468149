"""Which displacement DOFs of a blank's mesh are held at zero.

Symmetry planes named ``sym_x``/``sym_y``/``sym_z`` fix the normal displacement;
whatever rigid-body motion survives them is removed by the minimum number of point
constraints (statically determinate, so they carry no load): none for the eighth model,
one for the quarter model, six (3-2-1) for the full body.

DOF layout: scalar P2 DOF ``d`` carries the displacement components at ``3*d + (0, 1, 2)``
(:mod:`fea.assembly`).
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import qr

from .coating import Coating
from .linsolve import rigid_modes

__all__ = ["SYMMETRY_COMPONENT", "check_symmetry", "constrained_dofs", "plane_constrained_dofs",
           "symmetry_constraints", "symmetry_planes"]

#: symmetry-plane boundary name → the displacement component normal to it
SYMMETRY_COMPONENT = {"sym_x": 0, "sym_y": 1, "sym_z": 2}


def symmetry_planes(mesh) -> tuple[str, ...]:
    """The symmetry planes (``sym_x``, ``sym_y``, ``sym_z``, in that order) that ``mesh`` has."""
    return tuple(s for s in SYMMETRY_COMPONENT if s in mesh.boundaries)


def symmetry_constraints(planes) -> dict[str, int]:
    """Boundary name → displacement component held at zero on each symmetry plane."""
    return {s: SYMMETRY_COMPONENT[s] for s in planes}


def plane_constrained_dofs(mesh, basis, constraints: dict[str, int]) -> np.ndarray:
    """Vector DOFs fixed by whole-boundary constraints.

    Parameters
    ----------
    mesh : skfem.MeshTet2 (or MeshTet)
        Mesh with the named boundaries.
    basis : skfem.CellBasis
        Scalar P2 basis on ``mesh``.
    constraints : dict
        Boundary name → displacement component (0, 1, 2) held at zero.

    Returns
    -------
    ndarray of int
        Sorted, unique vector DOF numbers (empty when there are no constraints).
    """
    fixed = [3 * basis.get_dofs(mesh.boundaries[s]).all() + c for s, c in constraints.items()]
    return np.unique(np.concatenate(fixed)) if fixed else np.zeros(0, dtype=int)


def constrained_dofs(coords_mm: np.ndarray, plane_fixed: np.ndarray) -> np.ndarray:
    """``plane_fixed`` plus the point constraints that remove the surviving rigid-body modes.

    Parameters
    ----------
    coords_mm : ndarray, shape (3, N)
        Scalar DOF positions (mm).
    plane_fixed : ndarray of int
        Vector DOFs already fixed (:func:`plane_constrained_dofs`).

    Returns
    -------
    ndarray of int
        Sorted, unique fixed vector DOFs. The extra point constraints are well separated
        DOFs chosen by QR with column pivoting among 400 nodes drawn with a fixed seed, so
        the choice is reproducible.

    Raises
    ------
    RuntimeError
        When no set of point constraints pins the surviving modes.
    """
    fixed = plane_fixed
    B = rigid_modes(coords_mm - coords_mm.mean(axis=1, keepdims=True))
    # rigid modes that survive the symmetry constraints
    if fixed.size:
        # s and V only: the full U (n_fixed × n_fixed) of the layer slice's ~13 000 fixed DOFs
        # is 1.3 GB and ~7 s; with fewer rows than modes, V's null rows need the full form
        _, s, Vt = np.linalg.svd(B[fixed], full_matrices=fixed.size < B.shape[1])
        rank = int((s > 1e-9 * s.max()).sum())
        null = Vt[rank:].T
    else:
        null = np.eye(6)
    k = null.shape[1]
    if k == 0:
        return fixed
    n_nodes = coords_mm.shape[1]
    rng = np.random.default_rng(0)
    cand_nodes = rng.choice(n_nodes, size=min(400, n_nodes), replace=False)
    cand = (3 * cand_nodes[:, None] + np.arange(3)).ravel()
    Bs = B[cand] @ null
    _, _, piv = qr(Bs.T, pivoting=True, mode="economic")
    extra = cand[piv[:k]]
    if np.linalg.matrix_rank(Bs[piv[:k]]) < k:
        raise RuntimeError("could not find point constraints that remove the rigid-body modes")
    return np.unique(np.concatenate([fixed, extra]))


def check_symmetry(coating: Coating, planes) -> None:
    """Refuse a coating that the mid-plane symmetry (``sym_z`` in ``planes``) cannot represent.

    Raises
    ------
    ValueError
        When the front and back polish differ on a model cut at the mid-plane.
    """
    if "sym_z" in planes and not coating.is_z_symmetric:
        raise ValueError(
            f"coating with polish_front={coating.polish_front} != polish_back={coating.polish_back} "
            "is not symmetric about the mid-plane; use a quarter or full mesh (MeshSpec(symmetry='quarter'))"
        )
