"""One-call FEA entry points: prepare a meshed blank, solve a case.

Units: µm for film thickness, K for temperatures, fractions for polish.

Example
-------
>>> from fea.api import prepare, solve
>>> model = prepare()                              # default SPIFFI blank, default mesh
>>> r = solve(t0_um=200, polish=0.75, prepared=model)
>>> round(r.sag.pv_um("center"), 2)                # doctest: +SKIP
0.55
>>> sag_map = r.sag.sag_map(spacing_mm=0.5)        # optics.sagmap.SagMap
"""

from __future__ import annotations

from .case import PARAMETERS, FEACase, mesh_spec_for
from .geometry import Blank
from .materials import Material, get_material
from .mesh import MeshSpec, blank_mesh
from .mesh_budget import check_mesh_budget
from .model import FEAResult, PreparedBlank

__all__ = ["prepare", "solve", "mesh_spec_for"]


def prepare(blank: Blank | None = None, mesh: MeshSpec | None = None,
            substrate: Material | str = "Al6061-T6", progress: bool = False) -> PreparedBlank:
    """Mesh the blank (cached on disk) and assemble its bulk stiffness.

    Parameters
    ----------
    blank : Blank, optional
        Geometry; the SPIFFI blank by default.
    mesh : MeshSpec, optional
        Element sizes and symmetry; the default converged mesh by default.
    substrate : Material or str
        Blank material (``"Al6061-T6"``, ``"AlSi40"``, or a Material).
    """
    blank = blank or Blank()
    mesh = mesh or MeshSpec()
    return PreparedBlank(blank_mesh(blank, mesh, progress=progress), get_material(substrate))


def solve(t0_um: float = PARAMETERS["t0_um"].default, polish: float = PARAMETERS["polish"].default,
          coverage: str = PARAMETERS["coverage"].default, cold_K: float = PARAMETERS["cold_K"].default,
          warm_K: float = PARAMETERS["warm_K"].default, polish_back: float | None = None, *,
          blank: Blank | None = None, mesh: MeshSpec | None = None,
          substrate: Material | str = PARAMETERS["substrate"].default, film: Material | str = PARAMETERS["film"].default,
          stress_scale: float | None = None, backend: str = "auto",
          prepared: PreparedBlank | None = None) -> FEAResult:
    """Solve one cool-down case of the NiP-plated blank.

    The case is checked as a :class:`fea.case.FEACase` (ranges, caps and, when a mesh is
    to be built, its memory estimate) before any meshing.

    Parameters
    ----------
    t0_um : float
        As-plated NiP thickness (µm).
    polish : float
        Fraction of t0 left on the front face (and on the back face unless
        ``polish_back`` is given), in (0, 1].
    coverage : {"all", "holes", "surfaces", "faces", "none"}
        Which surfaces carry film (see :mod:`fea.coating`).
    cold_K, warm_K : float
        Cool-down end points (K).
    stress_scale : float, optional
        Film mismatch-stress multiplier; defaults to the calibrated
        :data:`fea.calibration.STRESS_SCALE`. Use 1.0 for nominal material data.
    prepared : PreparedBlank, optional
        A model from :func:`prepare` to reuse (its blank/mesh/substrate win).

    Returns
    -------
    FEAResult
        ``.sag`` holds the front-face sag (``pv_um("center")``, ``sag_map()``).
    """
    params = dict(t0_um=t0_um, polish=polish, coverage=coverage, cold_K=cold_K, warm_K=warm_K,
                  polish_back=polish_back, stress_scale=stress_scale, **(blank.key() if blank else {}))
    # a Material object (not one of the named ones) is checked by the model, not by name
    for name, mat in (("substrate", substrate), ("film", film)):
        if isinstance(mat, str):
            params[name] = mat
    if mesh is not None and prepared is None:
        params.update(mesh_size_mm=mesh.size_mm, mesh_bulk_mm=mesh.size_bulk_mm)
    objects = FEACase.from_params(params, check_memory=False).to_objects(mesh)
    if prepared is None:
        check_mesh_budget(objects.blank, objects.mesh)  # the mesh actually built (its symmetry too)
        prepared = prepare(objects.blank, objects.mesh, substrate)
    return prepared.solve(objects.coating, get_material(film), objects.load, stress_scale=objects.stress_scale,
                          backend=backend)
