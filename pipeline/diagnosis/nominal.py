"""The nominal simulation: one FEA sag map per manifest, cached, and exact thermal rescaling.

Why one map is enough: the FEA sag is exactly linear in the film mismatch strain
``eps_m(T) = NiP.strain_between(warm, T) - Al6061.strain_between(warm, T)``, so the
map at any other cold temperature is ``eps_m(T) / eps_m(cold_K)`` times the map at
``cold_K``. The same linearity makes a temperature change and an amplitude scale
indistinguishable on a single surface map.
"""

from __future__ import annotations

from pathlib import Path

from optics.sagmap import SagMap
from pipeline import store

from .manifest import Simulation

__all__ = ["mismatch_strain", "thermal_factor", "nominal_sag_map", "fea_sag_map", "MESH_SPECS"]

#: Named FEA meshes (element size near surfaces / in the bulk, mm); see
#: ``benchmarks/results_mesh_convergence.md``: P/V_center of "default" is 1.2-1.6 %,
#: of "refined" 0.4-1.0 % below the Richardson-extrapolated value.
MESH_SPECS = {"coarse": dict(size_mm=5.0, size_bulk_mm=10.0), "default": dict(size_mm=1.4, size_bulk_mm=2.8),
              "refined": dict(size_mm=1.0, size_bulk_mm=2.0)}
#: Store namespace of the nominal maps (the FEA model version is among the parameters).
_NAMESPACE = "diagnosis-fea-sag-map"


def mismatch_strain(temperature_K: float, warm_K: float = 293.0) -> float:
    """Film-minus-substrate thermal strain from ``warm_K`` to ``temperature_K`` (dimensionless)."""
    from fea.materials import AL6061_T6, NIP_HIGH_P

    return float(NIP_HIGH_P.strain_between(warm_K, temperature_K) - AL6061_T6.strain_between(warm_K, temperature_K))


def thermal_factor(temperature_K: float, reference_K: float, warm_K: float = 293.0) -> float:
    """Sag at ``temperature_K`` divided by the sag at ``reference_K`` (exact for the linear FEA)."""
    return mismatch_strain(temperature_K, warm_K) / mismatch_strain(reference_K, warm_K)


def fea_sag_map(t0_um: float, polish: float, coverage: str, cold_K: float, mesh: str = "coarse",
                spacing_mm: float = 0.5, cache_dir: str | Path | None = None, warm_K: float = 293.0) -> SagMap:
    """Front-face sag map (µm on a ``spacing_mm`` grid) of one FEA case, cached as npz.

    Parameters
    ----------
    t0_um, polish, coverage, cold_K, warm_K
        The FEA case (see :func:`fea.api.solve`).
    mesh : {"coarse", "default", "refined"}
        :meth:`fea.mesh.MeshSpec.coarse` (~2 s), the default mesh 1.4/2.8 mm (~20-60 s), or
        the refined 1.0/2.0 mm level of the mesh-convergence study (~2-3 min, 480 k DOFs;
        used for the *truths* of synthetic data so that they come from a different
        discretisation than the default-mesh nominal they are diagnosed against).
    cache_dir : path, optional
        Directory for ``fea-<key>.npz`` and its sidecar (:mod:`pipeline.store`); None
        disables the disk cache. A damaged or mismatched file is rebuilt with a warning.
    """
    from fea import MODEL_VERSION
    from fea.calibration import STRESS_SCALE

    key = dict(t0_um=float(t0_um), polish=float(polish), coverage=coverage, cold_K=float(cold_K),
               warm_K=float(warm_K), mesh=mesh, spacing_mm=float(spacing_mm), stress_scale=float(STRESS_SCALE),
               fea_model_version=MODEL_VERSION)
    label = f"FEA {coverage} t0={t0_um:g} polish={polish:g} {cold_K:g} K ({mesh} mesh)"
    entry = None
    if cache_dir is not None:
        entry = store.entry(cache_dir, _NAMESPACE, key, prefix="fea-")
        try:
            d, _ = store.load_arrays(entry)
            return SagMap(d["x_mm"], d["y_mm"], d["sag_um"], label, dict(key))
        except FileNotFoundError:
            pass
        except (store.CacheMiss, KeyError, ValueError) as exc:  # KeyError/ValueError: arrays not a map
            store.warn_rebuild(entry, exc, "nominal FEA map")
    from fea.api import prepare, solve
    from fea.mesh import MeshSpec

    if mesh not in MESH_SPECS:
        raise ValueError(f"mesh={mesh!r} is unknown; valid: {list(MESH_SPECS)}")
    spec = MeshSpec(**MESH_SPECS[mesh])
    from fea.api import mesh_spec_for
    from fea.coating import Coating

    spec = mesh_spec_for(Coating(t0_um=t0_um, polish_front=polish, polish_back=polish, coverage=coverage), spec)
    r = solve(t0_um, polish, coverage, cold_K, warm_K, prepared=prepare(mesh=spec))
    sm = r.sag.sag_map(spacing_mm)
    out = SagMap(sm.x_mm, sm.y_mm, sm.sag_um, label, dict(key))
    if entry is not None:
        # atomic, with a unique temporary name per writer: parallel campaign workers may race on one key
        store.save_arrays(entry, {"x_mm": out.x_mm, "y_mm": out.y_mm, "sag_um": out.sag_um})
    return out


def nominal_sag_map(sim: Simulation, cache_dir: str | Path | None = None) -> SagMap:
    """The nominal sag map at ``sim.cold_K``: ``sim.sag_file`` if given, else the FEA case."""
    if sim.sag_file is not None:
        from pipeline.interchange import read_sag_map

        try:
            return read_sag_map(sim.sag_file)
        except ValueError as exc:
            raise ValueError(f"[simulation] sag_file={str(sim.sag_file)!r}: {exc}") from None
    return fea_sag_map(sim.t0_um, sim.polish, sim.coverage, sim.cold_K, sim.mesh, cache_dir=cache_dir,
                       warm_K=sim.warm_K)
