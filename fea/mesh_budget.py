"""How large a blank mesh will be, estimated before meshing, and whether it fits in memory.

The element size of :func:`fea.mesh.blank_mesh` is a known function of position: ``size_mm``
within ``fine_depth`` of the front/back faces and of the hole walls (on the walls at most
``2 pi r / hole_segments``), growing linearly to ``size_bulk_mm`` over ``2 size_bulk_mm``;
a wall between a hole and a face is never thinner than about one element, so the size there
is at most the wall's local thickness.
A tetrahedron of edge ``h`` has the volume ``h^3 / (6 sqrt 2)``, so the meshed part holds
about ``T = 6 sqrt(2) * integral(h^-3 dV)`` tetrahedra. A Delaunay tetrahedral mesh has
``T ~ 6 V`` (V vertices) and, by Euler's formula with ``F ~ 2 T`` faces, ``E ~ V + T``
edges; a quadratic element adds one node per edge, so there are ``V + E ~ (1 + 2/6) T``
nodes and three times as many displacement DOFs. The integral is a midpoint sum over a
grid of the meshed part (eighth, quarter or full blank). Real meshes are somewhat coarser
than regular tetrahedra, so the estimate errs high (by 10-60 % over the mesh-convergence
ladder, ``benchmarks/results_mesh_convergence.md``), which is the safe side for a refusal;
on the coarse 5/10 mm mesh, where the 2.5 mm walls set the size, it is within 10 %.

Memory: the direct solver's peak grows about linearly with the DOFs over the meshes in
use: 3.6 GB at 216 k DOFs (``benchmarks/results_tables.md``), about 9 GB at 858 k DOFs
(``benchmarks/results_mesh_convergence.md``), i.e. about 1 GB for the interpreter and
libraries plus about 10 kB per DOF (:data:`BYTES_PER_DOF`).
"""

from __future__ import annotations

import functools
import math
import os

import numpy as np

from .errors import ParameterError
from .geometry import Blank
from .mesh import MeshSpec

__all__ = ["estimate_dofs", "estimate_memory_bytes", "memory_budget_bytes", "check_mesh_budget",
           "BASE_BYTES", "BYTES_PER_DOF", "MEMORY_FRACTION"]

#: Fixed part of a solve's peak memory (interpreter, NumPy/SciPy, gmsh), bytes.
BASE_BYTES = 1.0e9
#: Peak memory per displacement DOF of the assembled, factorised model, bytes.
BYTES_PER_DOF = 10.0e3
#: Share of the machine's physical memory a single mesh may take by default.
MEMORY_FRACTION = 0.8
#: Nodes per tetrahedron: vertices (~T/6) plus, for quadratic elements, one per edge (~T + T/6).
_NODES_PER_TET = {1: 1.0 / 6.0, 2: 1.0 + 2.0 / 6.0}
#: Midpoint-rule samples per axis of the meshed part (bounds).
_SAMPLES_MIN, _SAMPLES_MAX = 24, 64


def _axis(lo: float, hi: float, spacing: float) -> tuple[np.ndarray, float]:
    n = int(np.clip(math.ceil((hi - lo) / spacing), _SAMPLES_MIN, _SAMPLES_MAX))
    step = (hi - lo) / n
    return lo + (np.arange(n) + 0.5) * step, step


@functools.lru_cache(maxsize=256)
def _size_integral(blank: Blank, spec: MeshSpec) -> float:
    """integral of h(x)^-3 over the meshed part (mm^-3 * mm^3 = count), h the target size."""
    half = np.array([blank.size_x_mm, blank.size_y_mm, blank.thickness_mm]) / 2
    lo = {"eighth": (0.0, 0.0, 0.0), "quarter": (0.0, 0.0, -half[2]), "full": tuple(-half)}[spec.symmetry]
    walls = [blank.wall_front_mm, blank.wall_back_mm]
    fine_depth = max(spec.size_mm, 0.5 * min(walls))
    r = blank.hole_radius_mm
    spacing = 0.5 * min(fine_depth, r if blank.has_holes else fine_depth)
    (x, dx), (y, dy), (z, dz) = (_axis(lo[i], half[i], spacing) for i in range(3))
    X, Y, Z = np.meshgrid(x, y, z, indexing="ij", sparse=True)

    def threshold(d, size_min):  # gmsh's Threshold field: constant, linear ramp, constant
        t = np.clip((d - fine_depth) / (2 * spec.size_bulk_mm), 0.0, 1.0)
        return size_min + t * (spec.size_bulk_mm - size_min)

    d_face = half[2] - np.abs(Z)
    h = threshold(d_face, spec.size_mm) * np.ones((x.size, y.size, 1))
    solid = np.ones(h.shape, bool)
    if blank.has_holes:
        d = np.full(h.shape, np.inf)
        zc = blank.hole_axis_z_mm
        for xi in blank.hole_x_positions_mm:
            d = np.minimum(d, np.hypot(X - xi, Z - zc) - r)
        for yj in blank.hole_y_positions_mm:
            d = np.minimum(d, np.hypot(Y - yj, Z - zc) - r)
        solid = d >= 0
        hole_size = min(spec.size_mm, 2 * math.pi * r / spec.hole_segments)
        h = np.minimum(h, threshold(np.maximum(d, 0.0), hole_size))
        # a wall between a hole and a face is at least about one element thick
        h = np.minimum(h, np.maximum(d + d_face, 0.0) + 1e-9 * spec.size_mm)
    h = np.minimum(h, spec.size_bulk_mm)
    return float(np.sum(h[solid] ** -3.0) * dx * dy * dz)


def estimate_dofs(blank: Blank, spec: MeshSpec) -> int:
    """Displacement DOFs of ``blank_mesh(blank, spec)``, estimated without meshing.

    Parameters
    ----------
    blank : Blank
    spec : MeshSpec
        Sizes (mm), symmetry and element order of the mesh.

    Returns
    -------
    int
        Estimated DOFs (3 per node); errs high by up to ~60 % on the blank's meshes.
    """
    tets = 6.0 * math.sqrt(2.0) * _size_integral(blank, spec)
    return int(round(3 * _NODES_PER_TET[spec.order] * tets))


def estimate_memory_bytes(dofs: int) -> float:
    """Peak memory (bytes) of preparing and solving a model with ``dofs`` DOFs."""
    return BASE_BYTES + BYTES_PER_DOF * float(dofs)


def memory_budget_bytes(fraction: float = MEMORY_FRACTION) -> float:
    """``fraction`` of this machine's physical memory (bytes); inf where the OS does not say."""
    try:
        total = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (AttributeError, ValueError, OSError):
        return math.inf
    return fraction * total if total > 0 else math.inf


def check_mesh_budget(blank: Blank, spec: MeshSpec, budget_bytes: float | None = None) -> int:
    """Refuse a mesh whose estimated memory exceeds ``budget_bytes``; return its estimated DOFs.

    Parameters
    ----------
    budget_bytes : float, optional
        Memory a solve may take, bytes; default :func:`memory_budget_bytes`.

    Raises
    ------
    ParameterError
        Naming ``mesh_size_mm``, the estimate and the budget.
    """
    budget = memory_budget_bytes() if budget_bytes is None else float(budget_bytes)
    whose = f" ({MEMORY_FRACTION:.0%} of this machine's memory)" if budget_bytes is None else ""
    dofs = estimate_dofs(blank, spec)
    need = estimate_memory_bytes(dofs)
    if need > budget:
        raise ParameterError(
            "mesh_size_mm", spec.size_mm,
            f"mesh_size_mm={spec.size_mm:g} (bulk {spec.size_bulk_mm:g} mm) on the "
            f"{blank.size_x_mm:g} x {blank.size_y_mm:g} x {blank.thickness_mm:g} mm blank: estimated "
            f"{dofs:.3g} DOFs and {need / 1e9:.3g} GB, more than the memory budget of {budget / 1e9:.3g} GB"
            f"{whose}; use larger elements")
    return dofs
