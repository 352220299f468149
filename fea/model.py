"""Solve the cooled, NiP-plated blank: stiffness once per mesh, one solve per coating.

Units: mm for geometry and displacement inside the solver, µm for sag and film
thickness at the interface, kelvin for temperatures, MPa for stresses.

The substrate's own thermal contraction is uniform and stress-free in a free,
homogeneous body, so the problem is solved for the displacement *relative* to that
uniform contraction; only the film/substrate mismatch strain loads the body. The
uniform part is added back for VTU output (``total_displacement_mm``).

Boundary conditions: symmetry planes fix the normal displacement and point constraints
remove the rigid-body motion that survives them (:mod:`fea.constraints`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from functools import cached_property
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from .assembly import FilmOperators, bulk_stiffness, film_operators, scalar_basis
from .batch_solve import block_pcg, film_block_operator, thickness_powers
from .coating import SURFACE_GROUPS, Coating
from .constraints import (check_symmetry, constrained_dofs, plane_constrained_dofs, symmetry_constraints,
                          symmetry_planes)
from .linsolve import SharedFactor, SolverError, resolve_backend, restricted_sum, solve_spd
from .materials import AL6061_T6, NIP_HIGH_P, Material, get_material
from .errors import ParameterError
from .free_dofs import FreeStiffness
from .mesh_cache import default_cache_dir
from .operator_cache import load_film_ops, operator_entry, save_film_ops
from .reduced import FilmPolynomial, ReducedBasis
from .surface import FrontSag, FrontSampler

__all__ = ["FEAResult", "PreparedBlank", "ThermalLoad"]


@dataclass(frozen=True)
class ThermalLoad:
    """Uniform cool-down from ``warm_K`` to ``cold_K`` (K).

    ``cold_K`` must lie below ``warm_K``: a "cold" temperature above the stress-free one
    is a heating case, which the model solves just as well (linear in the strain) but
    which is almost always a swapped pair of numbers, so it needs ``heating=True``.
    """

    warm_K: float = 293.0
    cold_K: float = 80.0
    heating: bool = False

    def __post_init__(self) -> None:
        for name in ("warm_K", "cold_K"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ParameterError(name, v, f"{name}={v} must be a positive temperature in kelvin")
        if not self.heating and not self.cold_K < self.warm_K:
            raise ParameterError("cold_K", self.cold_K, f"cold_K={self.cold_K:g} K must be below warm_K={self.warm_K:g} K (a cool-down); "
                             "a warm-up is solved only through the API, with ThermalLoad(heating=True)")


@dataclass(frozen=True)
class FEAResult:
    """Displacement field and front-surface sag of one solved case.

    Attributes
    ----------
    coords_mm : ndarray, shape (3, N)
        Positions of the P2 nodes of the (symmetry part of the) mesh.
    displacement_mm : ndarray, shape (3, N)
        Displacement relative to the uniform contraction of the substrate.
    uniform_strain : float
        Substrate thermal strain warm → cold (adds ``uniform_strain * x`` to the total).
    sag : FrontSag
        Front-face sag, mirrored onto the whole face.
    info : dict
        Case parameters, mismatch strain, DOF count, timings.
    """

    coords_mm: np.ndarray
    displacement_mm: np.ndarray
    uniform_strain: float
    sag: FrontSag
    info: dict = field(default_factory=dict)

    @property
    def total_displacement_mm(self) -> np.ndarray:
        return self.displacement_mm + self.uniform_strain * self.coords_mm


class PreparedBlank:
    """A meshed blank with its bulk stiffness assembled, ready to solve many coatings.

    Parameters
    ----------
    mesh : skfem.MeshTet2 (or MeshTet)
        Mesh in mm with named boundaries (``front`` required; film groups and
        ``sym_*`` planes as present).
    substrate : Material or str
        Blank material.
    intorder : int
        Volume quadrature order.
    constraints : dict, optional
        Boundary name → displacement component (0, 1, 2) held at zero. Defaults to
        the symmetry planes present (``sym_x``→0, ``sym_y``→1, ``sym_z``→2). Rigid
        modes that survive are removed by point constraints.
    operator_cache : "auto", path or None
        Directory where the assembled film operators are kept between processes
        (:mod:`fea.operator_cache`); "auto" is the mesh cache directory, None disables it.
    """

    def __init__(self, mesh, substrate: Material | str = AL6061_T6, intorder: int = 2,
                 constraints: dict[str, int] | None = None, operator_cache: str | Path | None = "auto"):
        t0 = time.perf_counter()
        #: where assembled film operators are kept between processes (None: nowhere)
        self.operator_cache = (default_cache_dir() if operator_cache == "auto"
                               else None if operator_cache is None else Path(operator_cache))
        self.mesh = mesh
        self.substrate = get_material(substrate)
        if "front" not in mesh.boundaries:
            raise ValueError("the mesh has no 'front' boundary; cannot extract the sag")
        self.basis = scalar_basis(mesh, intorder)
        self.ndof = 3 * self.basis.N
        self.coords_mm = self.basis.doflocs
        self.K_bulk = bulk_stiffness(self.basis, self.substrate.youngs_modulus_Pa * 1e-6,
                                     self.substrate.poisson_ratio)
        self.symmetry_planes = symmetry_planes(mesh)
        # boundary name -> displacement component held at zero (symmetry planes by default)
        self.constraints = (symmetry_constraints(self.symmetry_planes)
                            if constraints is None else dict(constraints))
        self.plane_fixed = plane_constrained_dofs(mesh, self.basis, self.constraints)
        self.fixed = constrained_dofs(self.coords_mm, self.plane_fixed)
        self.free = np.setdiff1d(np.arange(self.ndof), self.fixed)
        self._film_ops: dict[tuple, FilmOperators] = {}
        #: systems up to this size get the offset coupling assembled explicitly
        self.explicit_offset_max_dof = 70_000
        # larger systems: one factorisation is shared by the following cases as CG preconditioner
        self._preconditioner = SharedFactor()
        self._reduced: dict[tuple, ReducedBasis] = {}
        self.assembly_s = time.perf_counter() - t0

    def film_ops(self, group: str, film: Material | str = NIP_HIGH_P) -> FilmOperators:
        """Thickness-independent film operators of one surface group (assembled once)."""
        film = get_material(film)
        key = (group, film.youngs_modulus_Pa, film.poisson_ratio)
        if key not in self._film_ops:
            if group not in self.mesh.boundaries:
                raise ValueError(f"surface group {group!r} is not a boundary of this mesh "
                                 f"(available: {sorted(self.mesh.boundaries)})")
            facets = self.mesh.boundaries[group]
            E_MPa = film.youngs_modulus_Pa * 1e-6
            entry = (operator_entry(self.operator_cache, self.mesh, facets, E_MPa, film.poisson_ratio,
                                    self.plane_fixed) if self.operator_cache is not None else None)
            ops = load_film_ops(entry) if entry is not None else None
            if ops is None:
                ops = film_operators(self.mesh, facets, E_MPa, film.poisson_ratio, self.coords_mm)
                # On a symmetry plane the surface normal lies in the plane and u_k ≡ 0 there, so
                # θ_k = ∂u_k/∂n = 0 exactly; nodal averaging over elements that only touch the plane
                # along an edge would not give that, and would load the film ends with a spurious moment.
                keep = np.ones(self.ndof)
                keep[self.plane_fixed] = 0.0
                ops = replace(ops, R=(sp.diags(keep) @ ops.R).tocsr())
                if entry is not None:
                    save_film_ops(entry, ops)
            self._film_ops[key] = ops
        return self._film_ops[key]

    def coatable_groups(self) -> tuple[str, ...]:
        """Surface groups a film can be put on in this (symmetry part of the) mesh."""
        return tuple(g for g in SURFACE_GROUPS if g in self.mesh.boundaries
                     and not (g == "back" and "sym_z" in self.symmetry_planes))

    def reduced_basis(self, film: Material | str = NIP_HIGH_P, offset: bool = True) -> ReducedBasis:
        """The Galerkin reduced model of this mesh for ``film`` (grows with every solve)."""
        film = get_material(film)
        key = (film.youngs_modulus_Pa, film.poisson_ratio, offset)
        if key not in self._reduced:
            films = {g: FilmPolynomial(self.film_ops(g, film), offset) for g in self.coatable_groups()}
            self._reduced[key] = ReducedBasis(self.K_bulk, films, self.free)
        return self._reduced[key]

    @cached_property
    def free_stiffness(self) -> FreeStiffness:
        """Bulk + local film stiffness on the free DOFs (:mod:`fea.free_dofs`)."""
        return FreeStiffness(self.K_bulk, self.free)

    def _free_stiffness(self, used_um: dict[str, float], film: Material, offset: bool) -> sp.csr_matrix:
        """Bulk + local film stiffness on the free DOFs for film thicknesses ``used_um`` (µm)."""
        return self.free_stiffness.stiffness(
            {(g, film.youngs_modulus_Pa, film.poisson_ratio): (self.film_ops(g, film), t_um * 1e-3)
             for g, t_um in used_um.items()}, offset)

    def release_preconditioner(self) -> None:
        """Free the shared factorisation (~0.7 GB at the default mesh)."""
        self._preconditioner.release()

    # ------------------------------------------------------------------ solve
    def solve(self, coating: Coating, film: Material | str = NIP_HIGH_P,
              load: ThermalLoad = ThermalLoad(), stress_scale: float = 1.0,
              backend: str = "auto", offset: bool = True,
              thickness_override_um: dict[str, float] | None = None,
              rtol: float = 1e-5) -> FEAResult:
        """Solve one coating case.

        Parameters
        ----------
        coating : Coating
            Film layout (thicknesses per surface group).
        film : Material or str
            Film material.
        load : ThermalLoad
            Warm and cold temperatures (K).
        stress_scale : float
            Multiplier on the film mismatch strain: the model's one calibration constant
            (see :mod:`fea.calibration`); 1.0 means the nominal material data.
        backend : str
            Linear solver back-end (:func:`fea.linsolve.solve_spd`).
        offset : bool
            Film integrated through its thickness (True) or as a surface membrane.
        thickness_override_um : dict, optional
            Explicit film thickness per surface group, replacing ``coating.thickness_um()``
            (for investigations such as uncoated side faces).
        rtol : float
            Relative residual the iterative solve must reach (large meshes). Measured on
            the default mesh (holes-only 200 µm, the slowest case): residual 1e-5 → P/V
            within 1e-6 of the fully converged one, 4e-5 → 7e-6, 1e-3 → 2e-4 (CG run to
            rtol/10); CG stops at rtol/2: at 1e-5, P/V within 7e-7 relative
            on four table cases (holes-only 200 µm: 2e-8); so 1e-5
            keeps the solver error 1000x below the discretisation error.

        Notes
        -----
        Large systems are solved by conjugate gradients preconditioned by a sparse
        Cholesky factor that is kept and shared by the following cases (they differ only
        in film thickness), starting from the Galerkin solution on the span of the
        previous cases' solutions (:class:`fea.reduced.ReducedBasis`). The answer is the
        full solve's to ``rtol`` whatever the order of the cases.
        """
        film = get_material(film)
        self._check_inputs(film, load, stress_scale)
        check_symmetry(coating, self.symmetry_planes)
        t0 = time.perf_counter()
        eps_mis = self.mismatch_strain(film, load, stress_scale)
        used = self.film_thickness_um(coating, thickness_override_um)
        f = np.zeros(self.ndof)
        couplings = []  # (t, FilmOperators) of each film, for the non-local offset terms
        for group, t_um in used.items():
            ops = self.film_ops(group, film)
            t = t_um * 1e-3
            f = f + ops.load(t, eps_mis, offset)
            if offset:
                couplings.append((t, ops))
        explicit = self.ndof <= self.explicit_offset_max_dof and bool(couplings)
        if used and eps_mis != 0 and not explicit:
            Kff = self._free_stiffness(used, film, offset)
        t_asm = time.perf_counter() - t0
        u = np.zeros(self.ndof)
        solve_info: dict = {}
        if used and eps_mis != 0:
            fr = self.free
            if explicit:
                # small system: the denser coupled matrix is affordable; a direct solve is
                # robust even when elements are as thin as the film (CG then converges slowly)
                K = self.K_bulk
                for t, ops in couplings:
                    K = K + ops.local_stiffness(t, offset) + ops.coupling_matrix(t)
                u[fr] = solve_spd(K[fr][:, fr], f[fr], backend=backend, coords_mm=self.coords_mm, free=fr)
                solve_info = {"method": "direct (explicit offset coupling)"}
                rb = self._reduced.get((film.youngs_modulus_Pa, film.poisson_ratio, offset))
                if rb is not None:  # a surrogate is training on this model: it needs these solves
                    rb.add(u)
            else:
                # start from the Galerkin solution on the span of the previous cases' solutions
                rb = self.reduced_basis(film, offset)
                x0 = rb.expand(rb.solve({g: t * 1e-3 for g, t in used.items()}, eps_mis))[fr] if rb.size else None
                offset_terms = restricted_sum([ops.coupling_operator(t) for t, ops in couplings], fr, self.ndof)
                u[fr] = self._preconditioner.solve(Kff, offset_terms, f[fr], backend=backend, rtol=rtol,
                                                   coords_mm=self.coords_mm, free=fr, info=solve_info, x0=x0)
                solve_info.update(reduced_basis_size=rb.size)
                rb.add(u)
        t_solve = time.perf_counter() - t0 - t_asm
        return self._result(coating, film, load, stress_scale, offset, used, eps_mis, u,
                            t_asm, t_solve, solve_info)

    def _check_inputs(self, film: Material, load: ThermalLoad, stress_scale: float) -> None:
        self.substrate.check_temperature(load.warm_K, "warm_K")
        self.substrate.check_temperature(load.cold_K, "cold_K")
        film.check_temperature(load.cold_K, "cold_K")
        if not (np.isfinite(stress_scale) and stress_scale >= 0):
            raise ValueError(f"stress_scale={stress_scale} must be a finite number >= 0")

    def _result(self, coating, film, load, stress_scale, offset, used, eps_mis, u, t_asm, t_solve,
                solve_info) -> FEAResult:
        disp = u.reshape(-1, 3).T
        sag = self.front_sampler()(disp)
        info = {
            "coverage": coating.coverage, "t0_um": coating.t0_um,
            "polish_front": coating.polish_front, "polish_back": coating.polish_back,
            "film_thickness_um": used, "warm_K": load.warm_K, "cold_K": load.cold_K,
            "substrate": self.substrate.name, "film": film.name,
            "mismatch_strain": eps_mis, "stress_scale": stress_scale,
            "ndof": self.ndof, "assembly_s": t_asm, "solve_s": t_solve,
            "symmetry_planes": list(self.symmetry_planes), "offset": offset,
            "solver": solve_info,
        }
        eps_sub = self.substrate.strain_between(load.warm_K, load.cold_K)
        return FEAResult(self.coords_mm, disp, eps_sub, sag, info)

    def solve_many(self, coatings, film: Material | str = NIP_HIGH_P, load: ThermalLoad = ThermalLoad(),
                   stress_scale: float = 1.0, backend: str = "auto", rtol: float = 1e-5,
                   maxiter: int = 200) -> list[FEAResult]:
        """Solve several coatings together; same answers as :meth:`solve` one by one.

        Large meshes: conjugate gradients in lockstep on all cases with the shared PARDISO
        factor (:mod:`fea.batch_solve`). Small meshes, the AMG back-end and cases CG cannot
        finish fall back to :meth:`solve`.
        """
        film = get_material(film)
        coatings = list(coatings)
        fallback = (len(coatings) < 2 or self.ndof <= self.explicit_offset_max_dof
                    or resolve_backend(backend) != "pardiso")
        if fallback:
            return [self.solve(c, film, load, stress_scale, backend, rtol=rtol) for c in coatings]
        self._check_inputs(film, load, stress_scale)
        for c in coatings:
            check_symmetry(c, self.symmetry_planes)
        t0 = time.perf_counter()
        eps_mis = self.mismatch_strain(film, load, stress_scale)
        fr = self.free
        used = [self.film_thickness_um(c) for c in coatings]
        groups = sorted({g for u_ in used for g in u_})
        F = np.zeros((fr.size, len(coatings)))
        for j, u_ in enumerate(used):
            f = np.zeros(self.ndof)
            for g, t_um in u_.items():
                f += self.film_ops(g, film).load(t_um * 1e-3, eps_mis)
            F[:, j] = f[fr]
        apply = film_block_operator(self.free_stiffness.bulk, fr, self.ndof,
                                    [(self.film_ops(g, film), thickness_powers([u_.get(g, 0.0) * 1e-3 for u_ in used]))
                                     for g in groups])
        solve_case = [j for j in range(len(coatings)) if used[j] and eps_mis != 0]
        own = self._preconditioner.held("pardiso") is None
        if own and solve_case:
            self._preconditioner.factorise(self._free_stiffness(used[solve_case[0]], film, True), "pardiso",
                                           self.coords_mm, fr)
        t_asm = time.perf_counter() - t0
        X = np.zeros_like(F)
        it = np.zeros(len(coatings), dtype=int)
        res0 = np.full(len(coatings), np.nan)
        cases = np.array(solve_case, dtype=int)
        if solve_case:
            X[:, cases], it[cases], res0[cases] = block_pcg(lambda V, cols: apply(V, cases[cols]), F[:, cases],
                                                            self._preconditioner.held("pardiso"), rtol, maxiter)
        t_solve = time.perf_counter() - t0 - t_asm
        results = []
        checked = apply(X[:, cases], cases) if solve_case else None
        for j, c in enumerate(coatings):
            u = np.zeros(self.ndof)
            solve_info = {}
            if j in solve_case:
                k = solve_case.index(j)
                res = float(np.linalg.norm(checked[:, k] - F[:, j]) / np.linalg.norm(F[:, j]))
                if not np.isfinite(res) or res > rtol:  # rare: finish this case on its own
                    try:
                        results.append(self.solve(c, film, load, stress_scale, backend, rtol=rtol))
                        continue
                    except SolverError as exc:
                        raise SolverError(f"case {j} ({c.coverage} t0={c.t0_um} polish={c.polish_front}): "
                                          f"{exc}") from None
                u[fr] = X[:, j]
                solve_info = {"method": "block CG (lockstep, shared factor)", "iterations": int(it[j]),
                              "residual": res, "initial_residual": float(res0[j]),
                              "backend": "pardiso", "preconditioner": "own" if own else "shared",
                              "block_size": len(solve_case)}
            results.append(self._result(c, film, load, stress_scale, True, used[j], eps_mis, u,
                                        t_asm / len(coatings), t_solve / len(coatings), solve_info))
        return results

    def front_sampler(self) -> FrontSampler:
        """Front-face sag of a displacement field on this mesh (built once)."""
        return self._front_sampler

    @cached_property
    def _front_sampler(self) -> FrontSampler:
        return FrontSampler(self.mesh, self.basis, self.symmetry_planes)

    def mismatch_strain(self, film: Material | str = NIP_HIGH_P, load: ThermalLoad = ThermalLoad(),
                        stress_scale: float = 1.0) -> float:
        """Film/substrate mismatch strain warm → cold, times the calibration scale."""
        film = get_material(film)
        return stress_scale * (film.strain_between(load.warm_K, load.cold_K)
                               - self.substrate.strain_between(load.warm_K, load.cold_K))

    def film_thickness_um(self, coating: Coating,
                          thickness_override_um: dict[str, float] | None = None) -> dict[str, float]:
        """Film thickness (µm) per surface group of this mesh that carries a film."""
        thick = coating.thickness_um() if thickness_override_um is None else dict(thickness_override_um)
        used = {}
        for group, t_um in thick.items():
            if t_um <= 0:
                continue
            if group == "back" and "sym_z" in self.symmetry_planes:
                continue  # the mirror image of the front film through the mid-plane
            if group in SURFACE_GROUPS and group not in self.mesh.boundaries:
                continue  # e.g. hole walls of a blank without lightweighting holes
            used[group] = float(t_um)
        return used
