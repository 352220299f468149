"""The nominal simulation: one FEA sag map per manifest, cached, and exact thermal rescaling.

Why one map is enough: the FEA sag is exactly linear in the film mismatch strain
``eps_m(T) = film.strain_between(warm, T) - substrate.strain_between(warm, T)``, so the
map at any other cold temperature is ``eps_m(T) / eps_m(cold_K)`` times the map at
``cold_K``. The same linearity makes a temperature change and an amplitude scale
indistinguishable on a single surface map.
"""

from __future__ import annotations

import functools
import warnings
from pathlib import Path

from optics.sagmap import SagMap
from fea import store

from .manifest import MESH_SPECS, Simulation

__all__ = ["mismatch_strain", "thermal_factor", "nominal_sag_map", "fea_sag_map", "case_sag_map", "MESH_SPECS",
           "DEFAULT_MATERIALS"]

#: (substrate, film) of the FEA case's defaults: Al 6061-T6 plated with NiP.
DEFAULT_MATERIALS = ("Al6061-T6", "NiP")

#: Parameters every nominal-map cache key names (its other parameters only when they differ
#: from the default, so the keys of the default blank and materials stay what they were).
_KEYED = ("t0_um", "polish", "coverage", "cold_K", "warm_K")
#: Store namespace of the nominal maps (the FEA model version is among the parameters).
_NAMESPACE = "diagnosis-fea-sag-map"


def mismatch_strain(temperature_K: float, warm_K: float = 293.0, substrate: str = DEFAULT_MATERIALS[0],
                    film: str = DEFAULT_MATERIALS[1]) -> float:
    """Film-minus-substrate thermal strain from ``warm_K`` to ``temperature_K`` (dimensionless)."""
    from fea.materials import get_material

    return float(get_material(film).strain_between(warm_K, temperature_K)
                 - get_material(substrate).strain_between(warm_K, temperature_K))


def thermal_factor(temperature_K: float, reference_K: float, warm_K: float = 293.0,
                   substrate: str = DEFAULT_MATERIALS[0], film: str = DEFAULT_MATERIALS[1]) -> float:
    """Sag at ``temperature_K`` divided by the sag at ``reference_K`` (exact for the linear FEA)."""
    try:
        return _thermal_factor(temperature_K, reference_K, warm_K, substrate, film)
    except TypeError:  # unhashable arguments: not memoised
        return _thermal_factor.__wrapped__(temperature_K, reference_K, warm_K, substrate, film)


@functools.lru_cache(maxsize=4096)
def _thermal_factor(temperature_K, reference_K, warm_K, substrate, film) -> float:
    # Memoised: every model evaluation of a diagnosis fit asks for the factor of the same few
    # temperatures (about 5 % of a diagnosis's time was spent in the strain tables).
    return (mismatch_strain(temperature_K, warm_K, substrate, film)
            / mismatch_strain(reference_K, warm_K, substrate, film))


def fea_sag_map(t0_um: float, polish: float, coverage: str, cold_K: float, mesh: str = "coarse",
                spacing_mm: float = 0.5, cache_dir: str | Path | None = None, warm_K: float = 293.0) -> SagMap:
    """Front-face sag map (µm on a ``spacing_mm`` grid) of one FEA case of the default blank
    and materials, cached as npz (see :func:`case_sag_map`).

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
        Directory for ``fea-<key>.npz`` and its sidecar (:mod:`fea.store`); None
        disables the disk cache. A damaged or mismatched file is rebuilt with a warning.
    """
    sim = Simulation.from_params(dict(t0_um=t0_um, polish=polish, coverage=coverage, cold_K=cold_K,
                                      warm_K=warm_K, mesh=mesh))
    return case_sag_map(sim, spacing_mm, cache_dir)


def case_sag_map(sim: Simulation, spacing_mm: float = 0.5, cache_dir: str | Path | None = None) -> SagMap:
    """Front-face sag map (µm on a ``spacing_mm`` grid) of the simulation's FEA case on its
    named mesh, cached as ``cache_dir/fea-<hash>.npz`` (None: no disk cache)."""
    from fea import MODEL_VERSION
    from fea.case import PARAMETERS

    case, mesh = sim.case, sim.mesh
    resolved = case.resolved()
    key = {k: getattr(case, k) for k in _KEYED}
    key.update(mesh=mesh, spacing_mm=float(spacing_mm), stress_scale=float(resolved.stress_scale),
               fea_model_version=MODEL_VERSION)
    key.update({k: v for k, v in case.as_params().items() if k not in key and k not in
                ("mesh_size_mm", "mesh_bulk_mm") and v != PARAMETERS[k].default})
    other = "".join(f" {case.as_params()[k]}" for k in ("substrate", "film") if k in key)
    label = (f"FEA {case.coverage} t0={case.t0_um:g} polish={case.polish:g} {case.cold_K:g} K"
             f"{other} ({mesh} mesh)")
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
    from fea.api import prepare

    o = case.to_objects()
    r = prepare(o.blank, o.mesh, o.substrate).solve(o.coating, o.film, o.load, stress_scale=o.stress_scale)
    sm = r.sag.sag_map(spacing_mm)
    out = SagMap(sm.x_mm, sm.y_mm, sm.sag_um, label, dict(key))
    if entry is not None:
        # atomic, with a unique temporary name per writer: parallel campaign workers may race on one key
        try:
            store.save_arrays(entry, {"x_mm": out.x_mm, "y_mm": out.y_mm, "sag_um": out.sag_um})
        except OSError as exc:  # the map is computed: a cache that cannot be written costs a re-solve, not the run
            warnings.warn(f"nominal FEA map not cached in {entry.payload.parent}: {exc.strerror or exc}",
                          store.CacheWarning, stacklevel=2)
    return out


def nominal_sag_map(sim: Simulation, cache_dir: str | Path | None = None) -> SagMap:
    """The nominal sag map at ``sim.cold_K``: ``sim.sag_file`` if given, else the FEA case."""
    if sim.sag_file is not None:
        from pipeline.io.registry import read_sag_map

        try:
            return read_sag_map(sim.sag_file)
        except ValueError as exc:
            raise ValueError(f"[simulation] sag_file={str(sim.sag_file)!r}: {exc}") from None
    return case_sag_map(sim, cache_dir=cache_dir)
