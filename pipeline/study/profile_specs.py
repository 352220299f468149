"""Line profiles of a study: a ``[[profiles]]`` table (every combination of its values)
and the single profile job it expands to.

Every line is checked on construction against the grating equation of
:mod:`optics.grating`, the error naming the config key.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from optics.grating import get_grating
from pipeline.bounds import MAX_PROFILE_JOBS, product_count
from pipeline.study.cases import CaseSelector, FEACase
from pipeline.study.schema import CAP_HINT, PROFILE_KEYS, ConfigError, parse_axis

__all__ = ["ProfileJob", "ProfileSpec"]


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
                              f"1..{MAX_PROFILE_JOBS}; {CAP_HINT}")
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
