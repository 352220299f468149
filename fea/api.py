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

from .calibration import STRESS_SCALE
from .coating import Coating
from .geometry import Blank
from .materials import Material, get_material
from .mesh import MeshSpec, blank_mesh
from .model import FEAResult, PreparedBlank, ThermalLoad

__all__ = ["prepare", "solve", "mesh_spec_for"]


def mesh_spec_for(coating: Coating, spec: MeshSpec | None = None, blank: Blank | None = None) -> MeshSpec:
    """The mesh spec to use: eighth model when the film and the blank are symmetric about
    the mid-plane, quarter model otherwise (front and back polish differ, or the holes are
    off the mid-plane)."""
    spec = spec or MeshSpec()
    symmetric = coating.is_z_symmetric and (blank is None or blank.is_z_symmetric)
    if not symmetric and spec.symmetry == "eighth":
        from dataclasses import replace

        spec = replace(spec, symmetry="quarter")
    return spec


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


def solve(t0_um: float = 200.0, polish: float = 0.75, coverage: str = "all", cold_K: float = 80.0,
          warm_K: float = 293.0, polish_back: float | None = None, *, blank: Blank | None = None,
          mesh: MeshSpec | None = None, substrate: Material | str = "Al6061-T6",
          film: Material | str = "NiP", stress_scale: float | None = None,
          backend: str = "auto", prepared: PreparedBlank | None = None) -> FEAResult:
    """Solve one cool-down case of the NiP-plated blank.

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
    coating = Coating(t0_um=t0_um, polish_front=polish,
                      polish_back=polish if polish_back is None else polish_back, coverage=coverage)
    load = ThermalLoad(warm_K=warm_K, cold_K=cold_K)
    film = get_material(film)
    if prepared is None:
        prepared = prepare(blank, mesh_spec_for(coating, mesh, blank), substrate)
    scale = STRESS_SCALE if stress_scale is None else stress_scale
    return prepared.solve(coating, film, load, stress_scale=scale, backend=backend)
