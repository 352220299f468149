"""Study configs: what ``cryograting run CONFIG.toml`` computes, as frozen dataclasses.

A config has five tables (all optional; ``cryograting config --example`` prints every
key with its meaning, unit and range)::

    [study]          title, description of the report
    [fea]            FEA parameters shared by all case groups (any key of FEA_KEYS)
    [[fea.cases]]    one group of FEA cases: every combination of its values
    [[profiles]]     line profiles: gratings x orders x wavelengths x pixel scales x
                     pupil shifts x deformations (FEA cases chosen by selectors)
    [[figures]]      PNG figures (kinds: sag_maps, psf, profiles, compare); without
                     this key one sag-map figure and one profile figure per set and grating
    [output]         figures, report, exports (booleans)

Values are scalars, lists or ranges (:mod:`pipeline.study.schema`). FEA cases are
selected for profiles and figures by *selectors*, inline tables of parameter values
(``{t0_um = 200, polish = 0.75}``) that match every case with those values; the key
``group`` matches a ``[[fea.cases]]`` table's ``name``.

:func:`load_study_config` reads and validates a file; :class:`StudyConfig` can also be
built in Python (``pipeline.study.run.default_study()`` does). Validation happens on
construction: every FEA case goes through :meth:`fea.case.FEACase.from_params` (the
blank, coating, mesh, thermal load, the materials' temperature range, the caps and the
mesh's memory estimate), every line through the grating equation of
:mod:`optics.grating`, each error re-worded to name the config key it concerns.
"""

from __future__ import annotations

import copy
import itertools
import math
import re
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path

from fea import case as fea_case  # (this module's FEACase is a study's case, not the model's)
from fea.errors import ParameterError
from optics.grating import SPIFFI, get_grating
from pipeline.bounds import MAX_FEA_CASES, MAX_PROFILE_JOBS, product_count
from fea.store import canonical_token
from pipeline.study.schema import (
    FEA_KEYS,
    PROFILE_KEYS,
    ConfigError,
    check_keys,
    closest,
    parse_axis,
)
from pipeline.sweeps.fea_cases import SAG_GRID_X_MM, SAG_GRID_Y_MM

__all__ = [
    "PRESET_DIR",
    "CaseSelector",
    "CompareFigure",
    "ConfigError",
    "FEACase",
    "FEAGroup",
    "OutputOptions",
    "ProfileFigure",
    "ProfileJob",
    "ProfileSpec",
    "PsfFigure",
    "SagMapFigure",
    "StudyConfig",
    "example_config_text",
    "list_presets",
    "load_study_config",
    "loads_study_config",
    "preset_path",
    "study_config_from_dict",
]

#: Shipped configs (``cryograting run --preset NAME``) and the commented example.
PRESET_DIR = Path(__file__).with_name("configs")
_EXAMPLE = "example"
#: Parameters that name every case (in labels and in the cache key), in this order.
_CORE = ("coverage", "t0_um", "polish")
_CAP_HINT = "check the ranges (a step too small, a list repeated?)"


def _token(v) -> str:
    return canonical_token(v)


def _resolve(combo: dict) -> dict:
    """A group's combination → every FEA parameter with its effective value."""
    full = fea_case.resolve_params(combo)
    return {k: full[k] for k in fea_case.PARAMETERS}


def _check_case(combo: dict, full: dict) -> None:
    """Run one resolved case through the FEA case's checks; blame the config key they name."""
    try:
        fea_case.FEACase.from_params(full)
    except ValueError as exc:
        key = exc.parameter if isinstance(exc, ParameterError) else None
        if key == "polish" and "polish" not in combo and "polish_front" in combo:
            key = "polish_front"
        case = ", ".join(f"{k}={v!r}" for k, v in combo.items())
        if key in combo:
            raise ConfigError(key, combo[key], f"{exc} (in the case {case})") from None
        raise ConfigError("", ..., f"invalid case {case}: {exc}") from None


def _case_params(full: dict, extras) -> dict:
    """The case's parameters as the sweep cache sees them: the core three, then ``extras``."""
    return {k: full[k] for k in (*_CORE, *(k for k in FEA_KEYS if k in extras and k not in _CORE))}


@dataclass(frozen=True)
class FEAGroup:
    """One group of FEA cases: every combination of its axes, the first axis outermost.

    Parameters
    ----------
    name : str
        Label of the group (shown in case labels when the study varies more than
        coverage, t0 and polish; matched by the selector key ``group``).
    axes : mapping or tuple of (key, values) pairs
        FEA parameter (:data:`pipeline.study.schema.FEA_KEYS`) → value, list or range.
        ``polish_front`` is stored as ``polish``. Unset parameters take the paper's
        values (Al 6061 blank 160 x 140 x 20 mm, 7 x 7 holes of 15 mm at 21 x 18 mm,
        NiP 200 µm / 75 %, 293 K → 80 K, default mesh).

    Examples
    --------
    >>> g = FEAGroup("table1", {"t0_um": [200, 100], "polish": {"start": 0.5, "stop": 1, "num": 2}})
    >>> [(c["t0_um"], c["polish"]) for c in g.combinations()]
    [(200.0, 0.5), (200.0, 1.0), (100.0, 0.5), (100.0, 1.0)]
    """

    name: str = ""
    axes: tuple = ()

    def __post_init__(self):
        raw = list(self.axes.items() if isinstance(self.axes, Mapping) else self.axes)
        keys = [k for k, _ in raw]
        if "polish" in keys and "polish_front" in keys:
            raise ConfigError("polish_front", ..., "give either polish (both faces) or polish_front, not both")
        axes = []
        for key, values in raw:
            if key not in FEA_KEYS:
                raise ConfigError(key, ..., f"unknown FEA parameter{closest(key, FEA_KEYS)} "
                                  f"(allowed: {', '.join(FEA_KEYS)})")
            values = list(values) if isinstance(values, tuple) else values
            axes.append(("polish" if key == "polish_front" else key, parse_axis(key, values, key, FEA_KEYS[key])))
        if not isinstance(self.name, str):
            raise ConfigError("name", self.name, "must be a string")
        object.__setattr__(self, "axes", tuple(axes))
        n = product_count(len(v) for _, v in axes)
        if n > MAX_FEA_CASES:  # before any case is validated: that alone is linear in n
            raise ConfigError("", ..., f"{n} FEA cases in one group is outside the valid range "
                              f"1..{MAX_FEA_CASES}; {_CAP_HINT}")
        for combo in self.combinations():
            alias = {("polish_front" if k == "polish" and "polish_front" in keys else k): v for k, v in combo.items()}
            _check_case(alias, _resolve(combo))

    def combinations(self) -> list[dict]:
        """Every combination of the axes as a dict (parameter → value), in product order."""
        names = [k for k, _ in self.axes]
        return [dict(zip(names, combo)) for combo in itertools.product(*(v for _, v in self.axes))]


@dataclass(frozen=True)
class CaseSelector:
    """Selects FEA cases of a study by parameter values (``group`` = a group's name).

    >>> CaseSelector({"t0_um": 200, "polish": 0.75})
    CaseSelector(params=(('t0_um', 200.0), ('polish', 0.75)))
    """

    params: tuple = ()

    def __post_init__(self):
        raw = list(self.params.items() if isinstance(self.params, Mapping) else self.params)
        if not raw:
            raise ConfigError("", {}, 'an empty selector; give parameter values or "perfect"')
        out = []
        for key, value in raw:
            if key == "group":
                if not isinstance(value, str):
                    raise ConfigError(key, value, "must be the name of a [[fea.cases]] table")
                out.append((key, value))
                continue
            if key not in FEA_KEYS:
                raise ConfigError(key, ..., f"unknown selector key{closest(key, [*FEA_KEYS, 'group'])} "
                                  f"(allowed: group, {', '.join(FEA_KEYS)})")
            if isinstance(value, (list, dict)):
                raise ConfigError(key, value, "a selector value is one scalar")
            out.append(("polish" if key == "polish_front" else key, parse_axis(key, value, key, FEA_KEYS[key])[0]))
        object.__setattr__(self, "params", tuple(out))

    def matches(self, case: FEACase) -> bool:
        return all((case.group == v) if k == "group" else _token(case.full[k]) == _token(v)
                   for k, v in self.params)

    def __str__(self) -> str:
        return "{" + ", ".join(f"{k} = {v!r}" for k, v in self.params) + "}"


@dataclass(frozen=True)
class FEACase:
    """One FEA case of a study: its label, its group, the parameters as cached (``params``)
    and every parameter's effective value (``full``)."""

    label: str
    group: str
    params: dict = field(hash=False)
    full: dict = field(hash=False)

    @property
    def is_paper_setup(self) -> bool:
        """True when only the coating, the mesh and the stress scale may differ from the paper's
        setup (blank, materials, 293 K → 80 K) and both faces are polished alike."""
        free = {"coverage", "t0_um", "polish", "mesh_size_mm", "mesh_bulk_mm", "stress_scale"}
        default = _resolve({})
        return self.full["polish_back"] == self.full["polish"] and all(
            _token(v) == _token(default[k]) for k, v in self.full.items() if k not in free | {"polish_back"})


def _label(full: dict, group: str, varying: list[str], group_varying: set[str]) -> str:
    t0, p, pb = full["t0_um"], full["polish"], full["polish_back"]
    if full["coverage"] == "all":
        core = f"{t0:g}/{100 * p:g}" + (f" (back {100 * pb:g})" if pb != p else "")
    else:
        core = f"{full['coverage']} {t0:g}"
    shown = [k for k in varying if k != "polish_back" and (not group or k in group_varying)]
    parts = [core + (f" {group}" if group and varying else "")]
    parts += [f"{k}={full[k]:g}" if isinstance(full[k], float) else f"{k}={full[k]}" for k in shown]
    return ", ".join(parts)


def _expand_cases(groups) -> list[FEACase]:
    """Cases of all groups, duplicates dropped, labelled by what varies across the study."""
    seen, rows = set(), []
    for g in groups:
        for combo in g.combinations():
            full = _resolve(combo)
            tok = tuple(_token(v) for v in full.values())
            if tok not in seen:
                seen.add(tok)
                rows.append((g, full))
    default = _resolve({})
    extras = [k for k in default if k not in _CORE and any(
        _token(full[k]) != _token(full["polish"] if k == "polish_back" else default[k]) for _, full in rows)]
    varying = [k for k in extras if len({_token(full[k]) for _, full in rows}) > 1]
    cases = []
    for g, full in rows:
        in_group = {k for k, v in g.axes if len(v) > 1}
        cases.append(FEACase(_label(full, g.name, varying, in_group), g.name, _case_params(full, extras), full))
    labels: set[str] = set()
    dup = next((c.label for c in cases if c.label in labels or labels.add(c.label)), None)
    if dup is not None:
        raise ConfigError("fea.cases", ..., f"two different cases get the label {dup!r}; "
                          "give the [[fea.cases]] tables distinct names")
    return cases


@dataclass(frozen=True)
class ProfileSpec:
    """One [[profiles]] table: line profiles for every combination of its values.

    Parameters
    ----------
    set : str
        Name of the profile set (figures and tables group by it; several tables may
        share a set).
    grating, order, wavelength_um, pixel_scale_mas, pupil_shift_x_mm, pupil_shift_y_mm
        Scalars, lists or ranges (see :data:`pipeline.study.schema.PROFILE_KEYS`);
        ``order = "blaze"`` (stored as None) is the grating's own order,
        ``wavelength_um = "band"`` its (short, centre, long) wavelengths.
    deformation : list of "perfect" or CaseSelector/mapping
        Grating surfaces: ``"perfect"`` (stored as None) or FEA cases by selector.
    """

    set: str = "profiles"
    grating: tuple = ("J",)
    order: tuple = ("blaze",)
    wavelength_um: tuple = ("centre",)
    pixel_scale_mas: tuple = (250, 100, 25)
    pupil_shift_x_mm: tuple = (0.0,)
    pupil_shift_y_mm: tuple = (0.0,)
    deformation: tuple = ("perfect",)

    def __post_init__(self):
        if not isinstance(self.set, str) or not self.set:
            raise ConfigError("set", self.set, "must be a non-empty string")
        for key, p in PROFILE_KEYS.items():
            v = getattr(self, key)
            v = list(v) if isinstance(v, tuple) else v
            if key == "order":  # None is the blaze order, as stored
                v = ["blaze" if o is None else o for o in v] if isinstance(v, list) else ("blaze" if v is None else v)
            axis = parse_axis(key, v, key, p)
            if key == "order":
                axis = tuple(None if o in ("blaze", None) else o for o in axis)
                if 0 in axis:
                    raise ConfigError(key, 0, 'must be a non-zero integer or "blaze"')
            if key == "pixel_scale_mas":
                for mas in axis:
                    if mas not in (25, 100, 250):
                        raise ConfigError(key, mas, f"unknown pixel scale (allowed: {p.allowed})")
            object.__setattr__(self, key, axis)
        defs = self.deformation
        defs = list(defs) if isinstance(defs, (list, tuple)) else [defs]
        if not defs:
            raise ConfigError("deformation", [], 'empty list; give "perfect" and/or FEA case selectors')
        out = []
        for i, d in enumerate(defs):
            if d is None or (isinstance(d, str) and d.lower() == "perfect"):
                out.append(None)
            elif isinstance(d, CaseSelector):
                out.append(d)
            elif isinstance(d, Mapping):
                try:
                    out.append(CaseSelector(d))
                except ConfigError as exc:
                    raise exc.within(f"deformation[{i}]") from None
            else:
                raise ConfigError(f"deformation[{i}]", d, 'must be "perfect" or a selector table such as '
                                  "{t0_um = 200, polish = 0.75}")
        object.__setattr__(self, "deformation", tuple(out))
        n = product_count((len(self.grating), len(self.order), len(self.wavelength_um), len(self.pixel_scale_mas),
                           len(self.pupil_shift_x_mm), len(self.pupil_shift_y_mm), len(self.deformation)))
        if n > MAX_PROFILE_JOBS:  # before the grating equation runs on every wavelength
            raise ConfigError("", ..., f"{n} line profiles in one [[profiles]] table is outside the valid range "
                              f"1..{MAX_PROFILE_JOBS}; {_CAP_HINT}")
        for g in self.grating:
            for o in self.order:
                for wl in self.wavelengths_for(g):
                    try:
                        get_grating(g).check_in_domain(wl, o)
                    except ValueError as exc:
                        raise ConfigError("wavelength_um", wl, str(exc)) from None

    def wavelengths_for(self, grating: str) -> list[float]:
        """The wavelengths (µm) of this table on ``grating`` ("band"/"centre" resolved)."""
        band = get_grating(grating).band_um
        out = []
        for w in self.wavelength_um:
            for v in (band if w == "band" else (band[1],) if w == "centre" else (w,)):
                if v not in out:
                    out.append(v)
        return out


@dataclass(frozen=True)
class ProfileJob:
    """One line profile to compute: a grating, order (None = blaze), wavelength (µm),
    pixel scale (mas), pupil shift (mm) and an FEA case (None = perfect grating)."""

    set: str
    grating: str
    order: int | None
    wavelength_um: float
    pixel_scale_mas: int
    pupil_shift_mm: tuple[float, float]
    case: FEACase | None

    @property
    def deformation(self) -> str:
        return "perfect" if self.case is None else self.case.label


def _file_name(path: str, value) -> str:
    if not isinstance(value, str) or not re.fullmatch(r"[\w.+-]+\.png", value):
        raise ConfigError(path, value, "must be a PNG file name without directories, e.g. \"sag_maps.png\"")
    return value


def _set_name(value) -> None:
    if not isinstance(value, str) or not value:
        raise ConfigError("set", value, "must be the (non-empty) set name of [[profiles]] tables")


def _strings(path: str, value) -> tuple:
    value = list(value) if isinstance(value, (list, tuple)) else [value]
    for i, v in enumerate(value):
        if not isinstance(v, str):
            raise ConfigError(f"{path}[{i}]", v, "must be a string")
    return tuple(value)


def _selectors(path: str, value) -> tuple:
    value = list(value) if isinstance(value, (list, tuple)) else [value]
    if not value:
        raise ConfigError(path, [], "empty list; give at least one FEA case selector")
    out = []
    for i, v in enumerate(value):
        try:
            out.append(v if isinstance(v, CaseSelector) else CaseSelector(v))
        except (ConfigError, TypeError) as exc:
            raise (exc.within(f"{path}[{i}]") if isinstance(exc, ConfigError) else
                   ConfigError(f"{path}[{i}]", v, "must be a selector table such as {t0_um = 200}")) from None
    return tuple(out)


@dataclass(frozen=True)
class SagMapFigure:
    """Sag maps side by side (82 x 72 mm box, µm colour bar): one panel per matched case."""

    file: str
    cases: tuple = ()
    titles: tuple = ()
    heading: str = "Sag maps"
    kind = "sag_maps"

    def __post_init__(self):
        _file_name("file", self.file)
        object.__setattr__(self, "cases", _selectors("cases", self.cases))
        object.__setattr__(self, "titles", _strings("titles", self.titles))


@dataclass(frozen=True)
class PsfFigure:
    """Point-source PSFs (log scale) of one FEA case: ``lines`` = ((grating, wavelength_um), ...)."""

    file: str
    case: object = None
    lines: tuple = ()
    titles: tuple = ()
    heading: str = "Point-spread functions"
    kind = "psf"

    def __post_init__(self):
        _file_name("file", self.file)
        object.__setattr__(self, "case", _selectors("case", self.case)[0])
        lines = []
        for i, line in enumerate(self.lines if isinstance(self.lines, (list, tuple)) else [self.lines]):
            if isinstance(line, Mapping):
                check_keys(line, ("grating", "wavelength_um"), f"lines[{i}]")
                line = (line.get("grating"), line.get("wavelength_um"))
            if not (isinstance(line, (list, tuple)) and len(line) == 2):
                raise ConfigError(f"lines[{i}]", line, "must be a table {grating = ..., wavelength_um = ...}")
            try:
                g = parse_axis(f"lines[{i}].grating", line[0], "grating", PROFILE_KEYS["grating"])[0]
                wl = float(parse_axis(f"lines[{i}].wavelength_um", line[1], "", PROFILE_KEYS["wavelength_um"])[0])
                get_grating(g).check_in_domain(wl)
            except ValueError as exc:
                raise (exc if isinstance(exc, ConfigError) else ConfigError(f"lines[{i}]", line, str(exc))) from None
            lines.append((g, wl))
        if not lines:
            raise ConfigError("lines", [], "give at least one {grating, wavelength_um}")
        object.__setattr__(self, "lines", tuple(lines))
        object.__setattr__(self, "titles", _strings("titles", self.titles))
        if self.titles and len(self.titles) != len(lines):
            raise ConfigError("titles", list(self.titles), f"needs one title per line ({len(lines)})")


@dataclass(frozen=True)
class ProfileFigure:
    """Line profiles of a set: panels wavelength x pixel scale, one curve per deformation."""

    file: str
    set: str = "profiles"
    grating: str = ""
    heading: str = "Detected line profiles"
    kind = "profiles"

    def __post_init__(self):
        _file_name("file", self.file)
        _set_name(self.set)
        if self.grating:
            object.__setattr__(self, "grating", parse_axis("grating", self.grating, "grating",
                                                           PROFILE_KEYS["grating"])[0])


@dataclass(frozen=True)
class CompareFigure:
    """All profiles of a set at one pixel scale in one panel (e.g. one line on several gratings)."""

    file: str
    set: str = "profiles"
    pixel_scale_mas: int = 250
    title: str = ""
    heading: str = "Comparison"
    kind = "compare"

    def __post_init__(self):
        _file_name("file", self.file)
        _set_name(self.set)
        parse_axis("pixel_scale_mas", self.pixel_scale_mas, "pixel_scale_mas", PROFILE_KEYS["pixel_scale_mas"])


FIGURE_KINDS = {"sag_maps": SagMapFigure, "psf": PsfFigure, "profiles": ProfileFigure, "compare": CompareFigure}


@dataclass(frozen=True)
class OutputOptions:
    """What ``run`` writes besides the tables and ``study.nc``: PNG figures, the HTML
    report, and the exports for optical design codes (``exports/``: CODE V INT, Zemax
    Grid Sag DAT, Zernike lists)."""

    figures: bool = True
    report: bool = True
    exports: bool = True

    def __post_init__(self):
        for name in ("figures", "report", "exports"):
            if not isinstance(getattr(self, name), bool):
                raise ConfigError(name, getattr(self, name), "must be true or false")


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
                              f"1..{MAX_FEA_CASES}; {_CAP_HINT}")
        object.__setattr__(self, "_cases", _expand_cases(self.fea))
        object.__setattr__(self, "_index", {})
        for i, spec in enumerate(self.profiles):
            self._check_profile(i, spec)
        n = self.n_profile_jobs()
        if n > MAX_PROFILE_JOBS:
            raise ConfigError("profiles", ..., f"{n} line profiles in the study is outside the valid range "
                              f"1..{MAX_PROFILE_JOBS}; {_CAP_HINT}")
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
            found = self._value_index(k).get(v if k == "group" else _token(v), ())
            hits = set(found) if hits is None else hits & set(found)
        return [self._cases[i] for i in sorted(hits)]

    def _value_index(self, key: str) -> dict:
        """``value token -> indices of the cases with it`` for one parameter (or ``group``)."""
        if key not in self._index:
            index: dict = {}
            for i, c in enumerate(self._cases):
                index.setdefault(c.group if key == "group" else _token(c.full[key]), []).append(i)
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


# --------------------------------------------------------------------- loading
_TOP = ("study", "fea", "profiles", "figures", "output")
_FIG_KEYS = {"sag_maps": ("kind", "file", "heading", "cases", "titles"),
             "psf": ("kind", "file", "heading", "case", "lines", "titles"),
             "profiles": ("kind", "file", "heading", "set", "grating"),
             "compare": ("kind", "file", "heading", "set", "pixel_scale_mas", "title")}


def _table(data, path: str) -> dict:
    if not isinstance(data, dict):
        raise ConfigError(path, data, "must be a table")
    return data


def _tables(data, path: str) -> list:
    if not isinstance(data, list) or not all(isinstance(t, dict) for t in data):
        raise ConfigError(path, data, f"must be an array of tables ([[{path}]])")
    return data


def _axes_count(axes: dict) -> int:
    """Cases of a group's axes as written (a value the group will refuse counts as one)."""
    n = 1
    for k, v in axes.items():
        try:
            n *= len(parse_axis(k, v, k, FEA_KEYS[k])) if k in FEA_KEYS else 1
        except ConfigError:
            pass
    return n


def _groups(fea: dict) -> tuple:
    check_keys(fea, (*FEA_KEYS, "cases"), "fea")
    shared = {k: v for k, v in fea.items() if k != "cases"}
    for k, v in shared.items():  # type errors of shared keys are theirs, whatever group uses them
        parse_axis(f"fea.{k}", v, k, FEA_KEYS[k])
    tables = _tables(fea.get("cases", [{}]), "fea.cases")
    groups, total = [], 0
    for i, t in enumerate(tables):
        path = f"fea.cases[{i}]" if "cases" in fea else "fea"
        check_keys(t, ("name", *FEA_KEYS), path)
        own = {k: v for k, v in t.items() if k != "name"}
        axes = {k: v for k, v in shared.items() if not (k in ("polish", "polish_front") and
                                                        ({"polish", "polish_front"} & own.keys()))}
        axes.update(own)
        total += _axes_count(axes)
        if total > MAX_FEA_CASES:  # before this group's cases are validated
            raise ConfigError(path, ..., f"{total} FEA cases{' up to this table' if i else ''} is outside the "
                              f"valid range 1..{MAX_FEA_CASES}; {_CAP_HINT}")
        try:
            groups.append(FEAGroup(t.get("name", ""), axes))
        except ConfigError as exc:
            root = re.split(r"[.\[]", exc.path)[0]
            if root and root not in t and "cases" in fea:
                raise ConfigError(f"fea.{exc.path}", exc.value, f"{exc.problem} (with {path})") from None
            raise exc.within(path) from None
    return tuple(groups)


def _figure(i: int, t: dict):
    path = f"figures[{i}]"
    kind = t.get("kind")
    if not isinstance(kind, str) or kind not in FIGURE_KINDS:
        raise ConfigError(f"{path}.kind", kind if "kind" in t else ..., f"{'unknown' if 'kind' in t else 'missing'} "
                          f"figure kind{closest(kind, FIGURE_KINDS) if isinstance(kind, str) else ''} "
                          f"(allowed: {', '.join(FIGURE_KINDS)})")
    check_keys(t, _FIG_KEYS[kind], path)
    if "file" not in t:
        raise ConfigError(f"{path}.file", ..., "missing: the PNG file name")
    try:
        return FIGURE_KINDS[kind](**{k: v for k, v in t.items() if k != "kind"})
    except ConfigError as exc:
        raise exc.within(path) from None
    except TypeError as exc:
        raise ConfigError(path, ..., str(exc)) from None


def _auto_figures(config: StudyConfig) -> tuple:
    """Without [[figures]]: the first four cases' sag maps, one profile figure per set and grating."""
    figs = [SagMapFigure("sag_maps.png", tuple(CaseSelector(dict(c.params)) for c in config.cases()[:4]))]
    done = []
    for s in config.profiles:
        for g in s.grating:
            if (s.set, g) not in done:
                done.append((s.set, g))
                figs.append(ProfileFigure(f"profiles_{s.set}_{g}.png", s.set, g))
    return tuple(figs)


def study_config_from_dict(data: dict, source: str = "") -> StudyConfig:
    """Validate parsed TOML (nested dicts/lists) into a :class:`StudyConfig`.

    Raises
    ------
    ConfigError
        Naming the dotted key, the value and what is allowed, prefixed by ``source``.
    """
    try:
        _table(data, "")
        check_keys(data, _TOP, "")
        study = _table(data.get("study", {}), "study")
        check_keys(study, ("title", "description"), "study")
        groups = _groups(_table(data.get("fea", {}), "fea"))
        profiles = []
        for i, t in enumerate(_tables(data.get("profiles", []), "profiles")):
            check_keys(t, ("set", "deformation", *PROFILE_KEYS), f"profiles[{i}]")
            try:
                profiles.append(ProfileSpec(**t))
            except ConfigError as exc:
                raise exc.within(f"profiles[{i}]") from None
        figures = [_figure(i, t) for i, t in enumerate(_tables(data.get("figures", []), "figures"))]
        out = _table(data.get("output", {}), "output")
        check_keys(out, ("figures", "report", "exports"), "output")
        try:
            output = OutputOptions(**out)
        except ConfigError as exc:
            raise exc.within("output") from None
        config = StudyConfig(study.get("title", "cryograting study"), study.get("description", ""),
                             groups, tuple(profiles), tuple(figures), output)
        if "figures" not in data:
            config = replace(config, figures=_auto_figures(config))
        return config
    except ConfigError as exc:
        raise exc.within(source=source) from None


def loads_study_config(text: str, source: str = "<string>") -> StudyConfig:
    """Parse TOML text into a validated :class:`StudyConfig` (see :func:`load_study_config`)."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError("", ..., f"malformed TOML: {exc}", source) from None
    return study_config_from_dict(data, source)


_SET_KEY = re.compile(r"^(study|fea|profiles|figures|output)((?:\[\d+\])?)(?:\.(cases)(\[\d+\])?)?\.([A-Za-z_][A-Za-z0-9_]*)$")


def parse_override(text: str) -> tuple[str, object]:
    """``KEY=VALUE`` from the command line → (dotted key, parsed value).

    VALUE is read as a TOML value (``200``, ``[100, 150]``, ``"J"``, ``{start = 0.5, stop = 1,
    num = 3}``); otherwise a comma list (``J,K`` or ``250,100,25``) or a plain string (a range
    string such as ``100:200:50`` or ``-10:10:5n``, a name such as ``AlSi40``).
    """
    key, sep, raw = str(text).partition("=")
    key, raw = key.strip(), raw.strip()
    if not sep or not key or not raw:
        raise ConfigError("", text, "an override must look like KEY=VALUE, e.g. fea.t0_um=100:200:50 "
                          "or profiles.pupil_shift_x_mm=[-4,0,4]", "--set")

    def value(v: str):
        try:
            return tomllib.loads(f"v = {v}")["v"]
        except tomllib.TOMLDecodeError:
            return v

    if "," in raw and raw[0] not in "[{\"'":
        return key, [value(v.strip()) for v in raw.split(",")]
    return key, value(raw)


def apply_overrides(data: dict, overrides) -> dict:
    """A copy of parsed config ``data`` with ``--set`` overrides applied.

    Keys: ``section.key`` (``study``, ``fea``, ``output``, ...), ``fea.cases[i].key`` (one FEA
    table), ``profiles.key`` (every ``[[profiles]]`` table) or ``profiles[i].key`` (one).
    The result is validated like a file (:func:`study_config_from_dict`).
    """
    data = copy.deepcopy(data)
    for item in overrides or ():
        key, val = item if isinstance(item, tuple) else parse_override(item)
        m = _SET_KEY.match(key)
        if not m:
            raise ConfigError(key, val, "unknown override key; use section.key (study, fea, output), "
                              "fea.cases[i].key, profiles.key or profiles[i].key", "--set")
        section, index, cases, case_index, name = m.groups()
        if section == "profiles":
            tables = data.setdefault("profiles", [])
            if not isinstance(tables, list) or not tables:
                raise ConfigError(key, val, "the config has no [[profiles]] table to set it in", "--set")
            chosen = tables if not index else _pick(tables, index, key, val)
            for t in chosen:
                t[name] = val
        elif cases:
            tables = data.setdefault("fea", {}).get("cases", [])
            chosen = tables if not case_index else _pick(tables, case_index, key, val)
            if not chosen:
                raise ConfigError(key, val, "the config has no [[fea.cases]] table to set it in", "--set")
            for t in chosen:
                t[name] = val
        elif index:
            raise ConfigError(key, val, f"[{section}] is a single table: no index", "--set")
        else:
            data.setdefault(section, {})[name] = val
            if section == "fea":  # every FEA table: also where a [[fea.cases]] table sets it
                for t in data["fea"].get("cases", []):
                    if isinstance(t, dict) and name in t:
                        t[name] = val
    return data


def _pick(tables: list, index: str, key: str, val) -> list:
    i = int(index.strip("[]"))
    if i >= len(tables):
        raise ConfigError(key, val, f"there are only {len(tables)} such tables (indices from 0)", "--set")
    return [tables[i]]


def read_study_data(path=None) -> dict:
    """The parsed TOML of a config file, or of the built-in default (``paper_default``)."""
    p = PRESET_DIR / "paper_default.toml" if path is None else Path(path)
    try:
        return tomllib.loads(p.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError("", ..., f"malformed TOML: {exc}", str(p)) from None


def load_study_config(path) -> StudyConfig:
    """Read and validate a study config file.

    Parameters
    ----------
    path : str or Path
        A TOML file (see ``cryograting config --example``).

    Raises
    ------
    FileNotFoundError
        No such file.
    ConfigError (a ValueError)
        Malformed TOML (the message names the line) or an invalid value (it names the
        key, the value and what is allowed).
    """
    p = Path(path)
    if p.is_dir():
        raise ConfigError("", ..., "is a directory, not a config file", str(p))
    if not p.is_file():
        hint = f"; did you mean --preset {p.stem}?" if p.stem in list_presets() and not p.exists() else ""
        raise FileNotFoundError(f"config file {str(p)!r} not found{hint}")
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError("", ..., f"cannot read the config: {exc}", str(p)) from None
    return loads_study_config(text, str(p))


def list_presets() -> list[str]:
    """Names of the shipped study configs (``cryograting run --preset NAME``)."""
    return sorted(p.stem for p in PRESET_DIR.glob("*.toml") if p.stem != _EXAMPLE)


def preset_path(name: str) -> Path:
    """The file of a shipped config, e.g. ``preset_path("whatif_alsi40")``."""
    name = str(name).removesuffix(".toml")
    if name not in list_presets():
        raise FileNotFoundError(f"unknown preset {name!r}{closest(name, list_presets())} "
                                f"(presets: {', '.join(list_presets())})")
    return PRESET_DIR / f"{name}.toml"


def example_config_text() -> str:
    """The commented example config printed by ``cryograting config --example``."""
    return (PRESET_DIR / f"{_EXAMPLE}.toml").read_text(encoding="utf-8")
