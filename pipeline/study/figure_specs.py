"""What a study draws and writes: the PNG figure kinds (sag maps, PSFs, line profiles,
comparisons) and the output switches (figures, HTML report, exports).

Each figure checks its own values on construction; whether its selectors and sets exist
in the study is checked by :class:`pipeline.study.study_config.StudyConfig`.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass

from optics.grating import get_grating
from pipeline.study.cases import CaseSelector
from pipeline.study.schema import PROFILE_KEYS, ConfigError, check_keys, parse_axis

__all__ = ["FIGURE_KINDS", "CompareFigure", "OutputOptions", "ProfileFigure", "PsfFigure", "SagMapFigure"]


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
