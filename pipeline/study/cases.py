"""FEA cases of a study: ``[[fea.cases]]`` groups, the selectors that pick cases, and the
study's distinct cases with their labels.

Every combination a group spans goes through :meth:`fea.case.FEACase.from_params` on
construction (the blank, coating, mesh, thermal load, the materials' temperature range,
the caps and the mesh's memory estimate), its error re-worded to name the config key.
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping
from dataclasses import dataclass, field

from fea import case as fea_case  # (this module's FEACase is a study's case, not the model's)
from fea.errors import ParameterError
from pipeline.bounds import MAX_FEA_CASES, product_count
from fea.store import canonical_token
from pipeline.study.schema import CAP_HINT, FEA_KEYS, ConfigError, closest, parse_axis

__all__ = ["CaseSelector", "FEACase", "FEAGroup", "expand_cases", "resolve_case"]

#: Parameters that name every case (in labels and in the cache key), in this order.
_CORE = ("coverage", "t0_um", "polish")


def resolve_case(combo: dict) -> dict:
    """A group's combination → every FEA parameter with its effective value (paper defaults
    for the unset ones)."""
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
                              f"1..{MAX_FEA_CASES}; {CAP_HINT}")
        for combo in self.combinations():
            alias = {("polish_front" if k == "polish" and "polish_front" in keys else k): v for k, v in combo.items()}
            _check_case(alias, resolve_case(combo))

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
        return all((case.group == v) if k == "group" else canonical_token(case.full[k]) == canonical_token(v)
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
        default = resolve_case({})
        return self.full["polish_back"] == self.full["polish"] and all(
            canonical_token(v) == canonical_token(default[k])
            for k, v in self.full.items() if k not in free | {"polish_back"})


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


def expand_cases(groups) -> list[FEACase]:
    """Cases of all groups, duplicates dropped, labelled by what varies across the study."""
    seen, rows = set(), []
    for g in groups:
        for combo in g.combinations():
            full = resolve_case(combo)
            tok = tuple(canonical_token(v) for v in full.values())
            if tok not in seen:
                seen.add(tok)
                rows.append((g, full))
    default = resolve_case({})
    extras = [k for k in default if k not in _CORE and any(
        canonical_token(full[k]) != canonical_token(full["polish"] if k == "polish_back" else default[k])
        for _, full in rows)]
    varying = [k for k in extras if len({canonical_token(full[k]) for _, full in rows}) > 1]
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
