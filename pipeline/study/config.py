"""Study configs: what ``cryograting run CONFIG.toml`` computes, read from TOML.

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

This module reads a file, a string, parsed TOML or a shipped preset, applies ``--set``
overrides, and builds the frozen dataclasses of the other modules, whose construction is
the validation: :mod:`pipeline.study.cases` (FEA case groups, selectors),
:mod:`pipeline.study.profile_specs` (line profiles), :mod:`pipeline.study.figure_specs`
(figures, output switches) and :mod:`pipeline.study.study_config` (the whole study,
cross-checked; ``pipeline.study.run.default_study()`` builds one in Python). Every error
is a :class:`~pipeline.study.schema.ConfigError` naming the config key it concerns.
"""

from __future__ import annotations

import copy
import re
import tomllib
from dataclasses import replace
from pathlib import Path

from pipeline.bounds import MAX_FEA_CASES
from pipeline.study.cases import CaseSelector, FEAGroup
from pipeline.study.figure_specs import FIGURE_KINDS, OutputOptions, ProfileFigure, SagMapFigure
from pipeline.study.profile_specs import ProfileSpec
from pipeline.study.schema import CAP_HINT, FEA_KEYS, PROFILE_KEYS, ConfigError, check_keys, closest, parse_axis
from pipeline.study.study_config import StudyConfig

__all__ = [
    "PRESET_DIR",
    "apply_overrides",
    "example_config_text",
    "list_presets",
    "load_study_config",
    "loads_study_config",
    "parse_override",
    "preset_path",
    "read_study_data",
    "study_config_from_dict",
]

#: Shipped configs (``cryograting run --preset NAME``) and the commented example.
PRESET_DIR = Path(__file__).with_name("configs")
_EXAMPLE = "example"
#: The top-level tables, and the keys of each figure kind.
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
                              f"valid range 1..{MAX_FEA_CASES}; {CAP_HINT}")
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
