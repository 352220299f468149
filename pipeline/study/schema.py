"""The keys of a study config, their types and units, and how a value becomes a sweep axis.

A study config (:mod:`pipeline.study.config`) is TOML; every parameter value in it may be

* a scalar: ``t0_um = 200``;
* a list: ``t0_um = [200, 150, 100]``;
* a range table, stop included: ``polish = {start = 0.5, stop = 1.0, step = 0.25}`` or
  ``polish = {start = 0.5, stop = 1.0, num = 3}`` (evenly spaced);
* a range string as on the command line: ``"100:200:50"``, ``"0.5:1:3n"``, ``"100,150"``.

Each becomes a tuple of values (an *axis*). Errors are :class:`ConfigError`: they name
the key by its dotted path in the file, the value, the problem and what is allowed.
"""

from __future__ import annotations

import difflib
import math
from dataclasses import dataclass

from fea.case import PARAMETERS
from pipeline.sweeps.sweep import parse_range

__all__ = [
    "CAP_HINT",
    "FEA_KEYS",
    "PROFILE_KEYS",
    "ConfigError",
    "Param",
    "check_keys",
    "closest",
    "parse_axis",
]

#: The hint of every "too many cases / profiles" error: what usually blows a study up.
CAP_HINT = "check the ranges (a step too small, a list repeated?)"


class ConfigError(ValueError):
    """A study config that cannot be used: names the key (dotted path), value and what is allowed.

    Parameters
    ----------
    path : str
        Dotted path of the key in the TOML file, e.g. ``"fea.cases[1].t0_um"``
        (array indices count from 0); ``""`` for the whole file.
    value : object
        The offending value (shown with ``repr``); ``...`` to omit it.
    problem : str
        What is wrong and what is allowed.
    source : str
        File (or other origin) of the config, prefixed to the message.
    """

    def __init__(self, path: str, value: object, problem: str, source: str = ""):
        self.path, self.value, self.problem, self.source = path, value, problem, source
        super().__init__(self._text())

    def _text(self) -> str:
        where = f"{self.source}: " if self.source else ""
        if not self.path:
            return f"{where}{self.problem}"
        shown = "" if self.value is ... else f" = {_short(self.value)}"
        return f"{where}{self.path}{shown}: {self.problem}"

    def within(self, prefix: str = "", source: str | None = None) -> ConfigError:
        """The same error with ``prefix`` put in front of the path (and a source set)."""
        path = ".".join(p for p in (prefix, self.path) if p).replace(".[", "[")
        return ConfigError(path, self.value, self.problem, self.source if source is None else source)


def _short(value: object, limit: int = 120) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[:limit - 3] + "..."


def closest(name: str, allowed) -> str:
    """``"; did you mean 'x'?"`` for the closest allowed name, or ``""``."""
    match = difflib.get_close_matches(str(name), [str(a) for a in allowed], n=1, cutoff=0.5)
    return f"; did you mean {match[0]!r}?" if match else ""


def check_keys(table: dict, allowed, path: str) -> None:
    """Raise for the first key of ``table`` that is not in ``allowed`` (with a suggestion)."""
    for key in table:
        if key not in allowed:
            raise ConfigError(f"{path}.{key}" if path else key, ..., f"unknown key{closest(key, allowed)} "
                              f"(allowed here: {', '.join(allowed)})")


@dataclass(frozen=True)
class Param:
    """One configurable parameter.

    Parameters
    ----------
    kind : {"float", "int", "str"}
        Scalar type. ``float`` accepts TOML integers too; ``int`` only integers.
    unit : str
        Unit of the value (``""`` for dimensionless or names).
    meaning : str
        What it is, for the commented example and the error messages.
    allowed : str
        The valid values or range, in words.
    choices : tuple of str, optional
        The only valid values of a ``str`` parameter.
    """

    kind: str
    unit: str
    meaning: str
    allowed: str
    choices: tuple[str, ...] = ()


#: Every FEA parameter a config may set ([fea] defaults and each [[fea.cases]] table): the
#: FEA case's own parameters (:data:`fea.case.PARAMETERS`), plus ``polish_front``.
FEA_KEYS: dict[str, Param] = {}
for _p in PARAMETERS.values():
    FEA_KEYS[_p.name] = Param(_p.kind, _p.unit, _p.doc, _p.valid, _p.choices)
    if _p.name == "polish":
        FEA_KEYS["polish_front"] = Param("float", "", "fraction of t0 left on the front face (instead of polish)",
                                         _p.valid)
del _p

#: The keys of one [[profiles]] table (besides ``set`` and ``deformation``).
PROFILE_KEYS: dict[str, Param] = {
    "grating": Param("str", "", "SPIFFI grating", "J, H, K or HK", ("J", "H", "K", "HK")),
    "order": Param("int", "", "diffraction order, or \"blaze\" for the grating's own (-2; HK -1)",
                   "non-zero integer with a propagating beam at every wavelength"),
    "wavelength_um": Param("float", "µm", "line wavelength, or \"band\" (short, centre, long) or \"centre\"",
                           "> 0 and propagating in the order"),
    "pixel_scale_mas": Param("int", "mas", "SPIFFI pixel scale (sets the slit illumination NA)",
                             "25, 100 or 250"),
    "pupil_shift_x_mm": Param("float", "mm", "pupil footprint shift on the grating along x",
                              "footprint (110 mm pupil / cos alpha) stays on the blank"),
    "pupil_shift_y_mm": Param("float", "mm", "pupil footprint shift along y", "footprint stays on the blank"),
}

_RANGE_KEYS = ("start", "stop", "step", "num")
#: strings some numeric keys accept instead of numbers
_WORDS = {"order": ("blaze",), "wavelength_um": ("band", "centre", "center")}


def _scalar(path: str, value: object, name: str, p: Param):
    """Check one scalar against its parameter; returns it (ints as float for float kinds)."""
    if isinstance(value, str) and value.lower() in _WORDS.get(name, ()):
        return "centre" if value.lower() == "center" else value.lower()
    if p.kind == "str":
        if not isinstance(value, str):
            raise ConfigError(path, value, f"must be a string ({p.allowed})")
        if p.choices:
            match = next((c for c in p.choices if c.lower() == value.lower()), None)
            if match is None:
                raise ConfigError(path, value, f"unknown value{closest(value, p.choices)} (allowed: {p.allowed})")
            return match
        return value
    words = " or ".join(f'"{w}"' for w in _WORDS.get(name, ()))
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        what = "an integer" if p.kind == "int" else "a number"
        raise ConfigError(path, value, f"must be {what}{' or ' + words if words else ''} "
                          f"({p.unit + ', ' if p.unit else ''}{p.allowed})")
    if p.kind == "int":
        if isinstance(value, float):
            raise ConfigError(path, value, f"must be an integer ({p.allowed})")
        return int(value)
    if not math.isfinite(value):
        raise ConfigError(path, value, f"must be finite ({p.unit + ', ' if p.unit else ''}{p.allowed})")
    return float(value)


def _range(path: str, table: dict, name: str, p: Param) -> list:
    if p.kind == "str":
        raise ConfigError(path, table, f"a range needs a numeric parameter; give a list ({p.allowed})")
    check_keys(table, _RANGE_KEYS, path)
    if "start" not in table or "stop" not in table or ("step" in table) == ("num" in table):
        raise ConfigError(path, table, "a range is {start, stop, step} or {start, stop, num} "
                          "(stop included)")
    for k, v in table.items():
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise ConfigError(f"{path}.{k}", v, "must be a finite number")
    if "num" in table and (isinstance(table["num"], float) or table["num"] < 1):
        raise ConfigError(f"{path}.num", table["num"], "must be an integer >= 1")
    if table.get("num") == 1:
        if table["start"] != table["stop"]:
            raise ConfigError(path, table, "num = 1 needs start == stop (one value)")
        values = [float(table["start"])]
    else:
        third = f"{table['num']}n" if "num" in table else repr(float(table["step"]))
        try:
            values = parse_range(f"{float(table['start'])!r}:{float(table['stop'])!r}:{third}")
        except ValueError as exc:
            raise ConfigError(path, table, f"empty or invalid range: {str(exc).split(';')[0]}") from None
    return values


def parse_axis(path: str, raw: object, name: str, p: Param) -> tuple:
    """One config value → tuple of checked scalars (the sweep axis).

    Raises
    ------
    ConfigError
        Empty list or range, wrong type, unknown choice, repeated value.
    """
    if hasattr(raw, "tolist") and not isinstance(raw, str):  # NumPy arrays and scalars from Python callers
        raw = raw.tolist()
    if isinstance(raw, tuple):
        raw = list(raw)
    if isinstance(raw, dict):
        values = _range(path, raw, name, p)
    elif isinstance(raw, list):
        if not raw:
            raise ConfigError(path, raw, f"empty list; give at least one value ({p.allowed})")
        values = raw
        for i, v in enumerate(raw):
            if isinstance(v, (list, dict)):
                raise ConfigError(f"{path}[{i}]", v, f"list items must be scalars ({p.allowed})")
    elif isinstance(raw, str) and p.kind != "str" and raw.lower() not in _WORDS.get(name, ()):
        try:
            values = parse_range(raw)
        except ValueError as exc:
            raise ConfigError(path, raw, f"{exc} ({p.unit + ', ' if p.unit else ''}{p.allowed})") from None
    else:
        values = [raw]
    if p.kind == "int":  # ranges give floats; whole numbers are fine for integer parameters
        values = [int(v) if isinstance(v, float) and v.is_integer() and isinstance(raw, (dict, str)) else v
                  for v in values]
    out = tuple(_scalar(f"{path}[{i}]" if isinstance(raw, list) else path, v, name, p)
                for i, v in enumerate(values))
    seen = set()
    for v in out:
        token = v if isinstance(v, str) else round(float(v), 12)
        if token in seen:
            raise ConfigError(path, raw, f"repeats the value {v!r}; each value once")
        seen.add(token)
    return out
