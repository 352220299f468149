"""Geometry of the lightweighted grating blank (paper §3.1).

One frozen dataclass, :class:`Blank`, describes the aluminium blank: a box
with two families of cross-drilled lightweighting holes.  Every parameter is
validated here, before any meshing, so that a bad recipe fails fast with a
message naming the field, its value and the valid range.

Coordinate convention (fixed here, used by the whole ``fea`` package):

* origin at the centre of the blank;
* x = dispersion direction, ``size_x_mm`` long;
* y = ruling direction, ``size_y_mm`` long;
* z = normal of the ruled face; the front (ruled) face is at
  ``z = +thickness_mm/2``, the back face at ``z = -thickness_mm/2``.

Hole families:

* "holes along y" (axis parallel to y) sit at ``x = hole_x_positions_mm``,
  there are ``n_holes_x`` of them, spaced by ``pitch_x_mm``;
* "holes along x" (axis parallel to x) sit at ``y = hole_y_positions_mm``,
  there are ``n_holes_y`` of them, spaced by ``pitch_y_mm``.

Both families have their axes at ``z = hole_axis_z_mm`` and intersect.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from .errors import ParameterError

__all__ = ["Blank", "MIN_WALL_MM"]

#: Thinnest wall (hole edge to face) accepted, mm.  Thinner walls cannot be
#: machined and would need sub-0.25 mm elements to resolve.
MIN_WALL_MM = 0.5


def _hole_positions_mm(n: int, pitch_mm: float) -> np.ndarray:
    # symmetric about 0 so that the symmetry cuts of fea.mesh are exact
    return (np.arange(n) - (n - 1) / 2.0) * pitch_mm


@dataclass(frozen=True)
class Blank:
    """Aluminium grating blank with cross-drilled lightweighting holes.

    Parameters
    ----------
    size_x_mm : float
        Extent along x (dispersion direction), mm.
    size_y_mm : float
        Extent along y (ruling direction), mm.
    thickness_mm : float
        Extent along z, mm.  Front face at ``+thickness_mm/2``.
    hole_diameter_mm : float
        Diameter of every lightweighting hole, mm.
    pitch_x_mm : float
        Spacing in x of the holes drilled along y, mm.
    n_holes_x : int
        Number of holes drilled along y (spaced in x).  0 = none.
    pitch_y_mm : float
        Spacing in y of the holes drilled along x, mm.
    n_holes_y : int
        Number of holes drilled along x (spaced in y).  0 = none.
    hole_axis_z_mm : float
        z of all hole axes, mm.  0 = mid-plane (the blank is then symmetric
        under z -> -z).

    Raises
    ------
    ValueError
        If a field is out of range; the message names the field, its value
        and the valid range.

    Examples
    --------
    >>> b = Blank()
    >>> float(b.wall_front_mm)
    2.5
    >>> Blank(n_holes_x=0, n_holes_y=0).is_z_symmetric
    True
    """

    size_x_mm: float = 160.0
    size_y_mm: float = 140.0
    thickness_mm: float = 20.0
    hole_diameter_mm: float = 15.0
    pitch_x_mm: float = 21.0
    n_holes_x: int = 7
    pitch_y_mm: float = 18.0
    n_holes_y: int = 7
    hole_axis_z_mm: float = 0.0

    def __post_init__(self):
        for name in ("size_x_mm", "size_y_mm", "thickness_mm",
                     "hole_diameter_mm", "pitch_x_mm", "pitch_y_mm",
                     "hole_axis_z_mm"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(
                    value, (int, float, np.integer, np.floating)):
                raise ParameterError(name, value, f"{name}={value!r}: must be a real number")
            if not math.isfinite(value):
                raise ParameterError(name, value, f"{name}={value!r}: must be finite")
        for name in ("size_x_mm", "size_y_mm", "thickness_mm",
                     "hole_diameter_mm", "pitch_x_mm", "pitch_y_mm"):
            value = getattr(self, name)
            if value <= 0:
                raise ParameterError(name, value, f"{name}={value!r}: valid range is > 0 mm")
        for name in ("n_holes_x", "n_holes_y"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(
                    value, (int, np.integer)):
                raise ParameterError(
                    name, value, f"{name}={value!r}: must be an integer >= 0")
            if value < 0:
                raise ParameterError(
                    name, value, f"{name}={value!r}: valid range is integers >= 0")
        if not self.has_holes:
            return
        d = self.hole_diameter_mm
        # clearance to the nearer face, for either sign of the axis offset
        max_d = self.thickness_mm - 2 * abs(self.hole_axis_z_mm) \
            - 2 * MIN_WALL_MM
        if d > max_d:
            raise ParameterError(
                "hole_diameter_mm", d,
                f"hole_diameter_mm={d!r}: with thickness_mm="
                f"{self.thickness_mm!r} and hole_axis_z_mm="
                f"{self.hole_axis_z_mm!r} the hole breaks through (or comes "
                f"within {MIN_WALL_MM} mm of) a face; valid range is "
                f"0 < hole_diameter_mm <= {max_d:g} mm "
                f"(thickness - 2*|hole_axis_z| - 2*{MIN_WALL_MM} mm walls)")
        for n_name, pitch_name, size_name in (
                ("n_holes_x", "pitch_x_mm", "size_x_mm"),
                ("n_holes_y", "pitch_y_mm", "size_y_mm")):
            n = getattr(self, n_name)
            pitch = getattr(self, pitch_name)
            size = getattr(self, size_name)
            if n >= 2 and d >= pitch:
                raise ParameterError(
                    pitch_name, pitch,
                    f"{pitch_name}={pitch!r}: neighbouring holes of diameter "
                    f"{d!r} mm overlap; valid range is {pitch_name} > "
                    f"hole_diameter_mm = {d!r} mm")
            if n >= 1:
                reach = (n - 1) / 2 * pitch + d / 2
                if reach >= size / 2:
                    raise ParameterError(
                        n_name, n,
                        f"{n_name}={n!r} (with {pitch_name}={pitch!r}, "
                        f"hole_diameter_mm={d!r}): the outermost hole edge is "
                        f"at {reach:g} mm, outside the side face at "
                        f"{size / 2:g} mm; valid range is (n-1)/2*pitch + "
                        f"diameter/2 < {size_name}/2")

    # --- derived quantities -------------------------------------------------
    @property
    def has_holes(self) -> bool:
        """True if at least one hole is drilled."""
        return self.n_holes_x > 0 or self.n_holes_y > 0

    @property
    def hole_radius_mm(self) -> float:
        """Hole radius, mm."""
        return self.hole_diameter_mm / 2.0

    @property
    def hole_x_positions_mm(self) -> np.ndarray:
        """x of the axes of the holes drilled along y, mm, shape (n_holes_x,)."""
        return _hole_positions_mm(self.n_holes_x, self.pitch_x_mm)

    @property
    def hole_y_positions_mm(self) -> np.ndarray:
        """y of the axes of the holes drilled along x, mm, shape (n_holes_y,)."""
        return _hole_positions_mm(self.n_holes_y, self.pitch_y_mm)

    @property
    def wall_front_mm(self) -> float:
        """Material between the hole tops and the front face, mm.

        Equals ``thickness_mm/2`` for a solid block.
        """
        if not self.has_holes:
            return self.thickness_mm / 2
        return self.thickness_mm / 2 - self.hole_axis_z_mm - self.hole_radius_mm

    @property
    def wall_back_mm(self) -> float:
        """Material between the hole bottoms and the back face, mm."""
        if not self.has_holes:
            return self.thickness_mm / 2
        return self.thickness_mm / 2 + self.hole_axis_z_mm - self.hole_radius_mm

    @property
    def is_z_symmetric(self) -> bool:
        """True if the blank is mirror-symmetric about z = 0."""
        return self.hole_axis_z_mm == 0.0 or not self.has_holes

    def volume_mm3(self) -> float:
        """Analytic volume of the full blank, mm^3.

        Box minus both hole families plus, for every crossing, the Steinmetz
        bicylinder ``16 r^3 / 3`` that was subtracted twice.
        """
        r = self.hole_radius_mm
        box = self.size_x_mm * self.size_y_mm * self.thickness_mm
        holes = math.pi * r**2 * (self.n_holes_x * self.size_y_mm
                                  + self.n_holes_y * self.size_x_mm)
        crossings = self.n_holes_x * self.n_holes_y * 16.0 * r**3 / 3.0
        return box - holes + crossings

    def key(self) -> dict:
        """All fields as a plain, JSON-able dict (stable for hashing)."""
        return {f.name: (int(v) if isinstance(v, (int, np.integer))
                         else float(v))
                for f in dataclasses.fields(self)
                for v in [getattr(self, f.name)]}
