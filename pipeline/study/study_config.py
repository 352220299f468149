"""A whole study as one frozen dataclass: FEA case groups, line profiles, figures and
output options, cross-checked on construction (selectors must match cases, the pupil
footprint must stay on every blank it is used with, figures must name existing sets).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field, replace

from optics.grating import SPIFFI, get_grating
from pipeline.bounds import MAX_FEA_CASES, MAX_PROFILE_JOBS, product_count
from fea.store import canonical_token
from pipeline.study.cases import CaseSelector, FEACase, FEAGroup, expand_cases
from pipeline.study.figure_specs import CompareFigure, OutputOptions, ProfileFigure, PsfFigure, SagMapFigure
from pipeline.study.profile_specs import ProfileJob, ProfileSpec
from pipeline.study.schema import CAP_HINT, ConfigError, closest
from pipeline.sweeps.fea_cases import SAG_GRID_X_MM, SAG_GRID_Y_MM

__all__ = ["StudyConfig"]


@dataclass(frozen=True)
class StudyConfig:
    """A whole study: FEA case groups, line profiles, figures and output options.

    Cross-references are checked on construction (selectors must match cases, the
    pupil footprint must stay on every blank it is used with, figures must name
    existing sets); errors name the key as in the TOML file.
    """

    title: str = "cryograting study"
    description: str = ""
    fea: tuple = field(default_factory=lambda: (FEAGroup(),))
    profiles: tuple = ()
    figures: tuple = ()
    output: OutputOptions = OutputOptions()

    def __post_init__(self):
        for name in ("fea", "profiles", "figures"):
            object.__setattr__(self, name, tuple(getattr(self, name)))
        for name in ("title", "description"):
            if not isinstance(getattr(self, name), str):
                raise ConfigError(f"study.{name}", getattr(self, name), "must be a string")
        if not self.fea:
            raise ConfigError("fea", ..., "no FEA case groups")
        n = sum(product_count(len(v) for _, v in g.axes) for g in self.fea)
        if n > MAX_FEA_CASES:
            raise ConfigError("fea", ..., f"{n} FEA cases in the study is outside the valid range "
                              f"1..{MAX_FEA_CASES}; {CAP_HINT}")
        object.__setattr__(self, "_cases", expand_cases(self.fea))
        object.__setattr__(self, "_index", {})
        for i, spec in enumerate(self.profiles):
            self._check_profile(i, spec)
        n = self.n_profile_jobs()
        if n > MAX_PROFILE_JOBS:
            raise ConfigError("profiles", ..., f"{n} line profiles in the study is outside the valid range "
                              f"1..{MAX_PROFILE_JOBS}; {CAP_HINT}")
        names = set()
        for i, fig in enumerate(self.figures):
            if fig.file in names:
                raise ConfigError(f"figures[{i}].file", fig.file, "used by two figures")
            names.add(fig.file)
            self._check_figure(i, fig)

    # ---------------------------------------------------------------- expansion
    def cases(self) -> list[FEACase]:
        """The study's distinct FEA cases, in group and product order."""
        return list(self._cases)

    def select(self, selector: CaseSelector | None) -> list[FEACase | None]:
        """Cases matched by ``selector`` (``[None]`` for the perfect grating), as
        :meth:`CaseSelector.matches` would find them, through a per-key index of the
        cases' values: a study with a selector per case stays linear in its size."""
        if selector is None:
            return [None]
        hits = None
        for k, v in selector.params:
            found = self._value_index(k).get(v if k == "group" else canonical_token(v), ())
            hits = set(found) if hits is None else hits & set(found)
        return [self._cases[i] for i in sorted(hits)]

    def _value_index(self, key: str) -> dict:
        """``value token -> indices of the cases with it`` for one parameter (or ``group``)."""
        if key not in self._index:
            index: dict = {}
            for i, c in enumerate(self._cases):
                index.setdefault(c.group if key == "group" else canonical_token(c.full[key]), []).append(i)
            self._index[key] = index
        return self._index[key]

    def n_profile_jobs(self) -> int:
        """How many line profiles :meth:`profile_jobs` gives, counted without listing them."""
        n = 0
        for spec in self.profiles:
            cases = sum(len(self.select(d)) for d in spec.deformation)
            for g in spec.grating:
                n += product_count((len(spec.order), len(spec.wavelengths_for(g)), len(spec.pixel_scale_mas),
                                    len(spec.pupil_shift_x_mm), len(spec.pupil_shift_y_mm), cases))
        return n

    def profile_jobs(self) -> list[ProfileJob]:
        """Every line profile of the study, table by table, in product order."""
        jobs = []
        for spec in self.profiles:
            for g in spec.grating:
                for o, wl, mas, sx, sy, d in itertools.product(
                        spec.order, spec.wavelengths_for(g), spec.pixel_scale_mas, spec.pupil_shift_x_mm,
                        spec.pupil_shift_y_mm, spec.deformation):
                    for case in self.select(d):
                        jobs.append(ProfileJob(spec.set, g, o, wl, mas, (sx, sy), case))
        return jobs

    def with_mesh(self, size_mm: float | None = None, bulk_mm: float | None = None) -> StudyConfig:
        """A copy whose every FEA case uses these element sizes (mm); None keeps them."""
        sizes = {k: v for k, v in (("mesh_size_mm", size_mm), ("mesh_bulk_mm", bulk_mm)) if v is not None}
        if not sizes:
            return self
        groups = tuple(replace(g, axes={**dict(g.axes), **sizes}) for g in self.fea)
        return replace(self, fea=groups)

    def summary(self) -> str:
        """One line: how many FEA cases, profiles and figures."""
        return (f"{self.title}: {len(self._cases)} FEA case(s), {self.n_profile_jobs()} line profile(s), "
                f"{len(self.figures) if self.output.figures else 0} figure(s)")

    # ---------------------------------------------------------------- checks
    def _check_profile(self, i: int, spec: ProfileSpec) -> None:
        R = 0.5 * SPIFFI.pupil_diameter_mm
        for j, d in enumerate(spec.deformation):
            matched = self.select(d)
            if not matched:
                raise ConfigError(f"profiles[{i}].deformation[{j}]", ..., f"the selector {d} matches no FEA "
                                  f"case (cases: {', '.join(repr(c.label) for c in self._cases)})")
            for case in matched:
                if case is None:
                    continue
                # the footprint must lie on the blank and on the fixed sag-map grid
                hx = min(case.full["size_x_mm"] / 2, SAG_GRID_X_MM[-1])
                hy = min(case.full["size_y_mm"] / 2, SAG_GRID_Y_MM[-1])
                for g in spec.grating:
                    fx = R / math.cos(math.radians(get_grating(g).incidence_deg))
                    for key, shifts, half, h in (("pupil_shift_x_mm", spec.pupil_shift_x_mm, fx, hx),
                                                 ("pupil_shift_y_mm", spec.pupil_shift_y_mm, R, hy)):
                        bad = [s for s in shifts if abs(s) + half > h + 1e-9]
                        if bad:
                            raise ConfigError(f"profiles[{i}].{key}", bad[0], f"the {g} pupil footprint "
                                              f"(half-width {half:.1f} mm) leaves the {case.label!r} blank "
                                              f"(half-width {h:g} mm); allowed |shift| <= {h - half:.2f} mm")

    def _check_figure(self, i: int, fig) -> None:
        path = f"figures[{i}]"
        sets = {s.set: s for s in self.profiles}
        if isinstance(fig, SagMapFigure):
            n = 0
            for j, sel in enumerate(fig.cases):
                k = len(self.select(sel))
                if k == 0:
                    raise ConfigError(f"{path}.cases[{j}]", ..., f"the selector {sel} matches no FEA case")
                n += k
            if fig.titles and len(fig.titles) != n:
                raise ConfigError(f"{path}.titles", list(fig.titles), f"needs one title per panel ({n})")
        elif isinstance(fig, PsfFigure):
            if len(self.select(fig.case)) != 1:
                raise ConfigError(f"{path}.case", ..., f"the selector {fig.case} must match exactly one FEA "
                                  f"case, matches {len(self.select(fig.case))}")
        else:
            if fig.set not in sets:
                raise ConfigError(f"{path}.set", fig.set, f"no [[profiles]] table has this set"
                                  f"{closest(fig.set, sets)} (sets: {', '.join(sets) or 'none'})")
            specs = [s for s in self.profiles if s.set == fig.set]
            if isinstance(fig, ProfileFigure) and fig.grating and not any(fig.grating in s.grating for s in specs):
                raise ConfigError(f"{path}.grating", fig.grating, f"set {fig.set!r} has no profiles on this grating")
            if isinstance(fig, CompareFigure) and not any(fig.pixel_scale_mas in s.pixel_scale_mas for s in specs):
                raise ConfigError(f"{path}.pixel_scale_mas", fig.pixel_scale_mas,
                                  f"set {fig.set!r} has no profiles at this pixel scale")
