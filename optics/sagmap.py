"""Gridded surface sag maps that carry their coordinates, mask and named regions.

Conventions (fixed here, used everywhere in cryograting)
--------------------------------------------------------
* Grating frame: ``x`` is the dispersion direction (perpendicular to the grooves),
  ``y`` the ruling direction (along the grooves, i.e. along the slit image),
  ``z`` the outward normal of the front (ruled) face. Origin at the blank centre.
* Arrays are indexed ``[y, x]``; ``x_mm`` and ``y_mm`` are strictly increasing.
* ``sag_um`` is the surface displacement along +z in micrometres: positive sag
  moves the surface towards the incoming light. Invalid samples are NaN.
* Units: millimetres for coordinates, micrometres for sag.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from scipy.interpolate import RegularGridInterpolator

from optics.triangulation import linear_on_grid

__all__ = [
    "is_uniform_axis",
    "Region",
    "REGIONS",
    "SagMap",
    "quilt_sag_map",
    "resolve_region",
]


@dataclass(frozen=True)
class Region:
    """A named evaluation region on the grating face (mm, centred on the blank).

    Parameters
    ----------
    name : str
        Label used in reports.
    kind : {"rectangle", "circle", "all"}
        Shape of the region. ``"all"`` selects every valid sample.
    width_mm, height_mm : float
        Full size along x and y of a rectangle.
    diameter_mm : float
        Diameter of a circle.
    x0_mm, y0_mm : float
        Centre of the region.
    """

    name: str
    kind: Literal["rectangle", "circle", "all"] = "rectangle"
    width_mm: float = 0.0
    height_mm: float = 0.0
    diameter_mm: float = 0.0
    x0_mm: float = 0.0
    y0_mm: float = 0.0

    def __post_init__(self) -> None:
        if self.kind not in ("rectangle", "circle", "all"):
            raise ValueError(
                f"Region.kind={self.kind!r} is not valid; use 'rectangle', 'circle' or 'all'"
            )
        if self.kind == "rectangle" and not (self.width_mm > 0 and self.height_mm > 0):
            raise ValueError(
                f"Region {self.name!r}: width_mm={self.width_mm} and height_mm={self.height_mm} "
                "must both be > 0 for a rectangle"
            )
        if self.kind == "circle" and not self.diameter_mm > 0:
            raise ValueError(
                f"Region {self.name!r}: diameter_mm={self.diameter_mm} must be > 0 for a circle"
            )

    def contains(self, x_mm: np.ndarray, y_mm: np.ndarray, tol_mm: float = 1e-9) -> np.ndarray:
        """Boolean mask of the points (any matching shapes) inside the region (edges included)."""
        x = np.asarray(x_mm, dtype=float) - self.x0_mm
        y = np.asarray(y_mm, dtype=float) - self.y0_mm
        if self.kind == "all":
            return np.ones(np.broadcast(x, y).shape, dtype=bool)
        if self.kind == "circle":
            return x**2 + y**2 <= (0.5 * self.diameter_mm + tol_mm) ** 2
        return (np.abs(x) <= 0.5 * self.width_mm + tol_mm) & (
            np.abs(y) <= 0.5 * self.height_mm + tol_mm
        )


#: The paper's evaluation regions. ``center`` is the 82 x 72 mm rectangle over the
#: central 4 x 4 lightweighting cells (P/V_center); ``interferometer`` the 137 mm
#: cryostat window of the cryogenic measurement; ``full`` the whole face.
REGIONS: dict[str, Region] = {
    "center": Region("center", "rectangle", width_mm=82.0, height_mm=72.0),
    "full": Region("full", "all"),
    "interferometer": Region("interferometer", "circle", diameter_mm=137.0),
    "pupil": Region("pupil", "circle", diameter_mm=110.0),
}


def resolve_region(region: str | Region | None) -> Region:
    """Turn a region name (see :data:`REGIONS`), a :class:`Region` or None (full) into a Region."""
    if region is None:
        return REGIONS["full"]
    if isinstance(region, Region):
        return region
    try:
        return REGIONS[region]
    except KeyError:
        raise ValueError(
            f"region={region!r} is unknown; valid names are {sorted(REGIONS)} or a Region"
        ) from None


def _checked_sag(s: np.ndarray, ny: int, nx: int) -> np.ndarray:
    """``s`` if it is a valid sag array on an ``(ny, nx)`` grid, else ValueError."""
    if s.shape != (ny, nx):
        raise ValueError(f"SagMap.sag_um has shape {s.shape}; expected (len(y_mm), len(x_mm)) = {(ny, nx)}")
    if np.isinf(s).any():
        raise ValueError("SagMap.sag_um contains inf; use NaN for invalid samples")
    if not np.isfinite(s).any():
        raise ValueError("SagMap.sag_um has no valid (finite) samples")
    return s


def is_uniform_axis(v: np.ndarray) -> bool:
    """Whether the 1-D coordinates ``v`` (mm) are strictly increasing and uniformly spaced
    as a :class:`SagMap` needs them: every step within 1e-6 (relative) of the first."""
    d = np.diff(np.asarray(v, dtype=float))
    return bool(d.size and np.all(d > 0) and np.allclose(d, d[0], rtol=1e-6, atol=1e-9))


@dataclass(frozen=True)
class SagMap:
    """A surface sag map on a regular grid.

    Parameters
    ----------
    x_mm : ndarray, shape (nx,)
        Strictly increasing, uniformly spaced x coordinates (dispersion direction).
    y_mm : ndarray, shape (ny,)
        Strictly increasing, uniformly spaced y coordinates (ruling direction).
    sag_um : ndarray, shape (ny, nx)
        Sag along +z in micrometres, NaN where there is no valid sample.
    label : str
        Free-form description (case name, file name).
    """

    x_mm: np.ndarray
    y_mm: np.ndarray
    sag_um: np.ndarray
    label: str = ""
    meta: dict = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        x = np.asarray(self.x_mm, dtype=float)
        y = np.asarray(self.y_mm, dtype=float)
        s = np.asarray(self.sag_um, dtype=float)
        for name, v in (("x_mm", x), ("y_mm", y)):
            if v.ndim != 1 or v.size < 2:
                raise ValueError(f"SagMap.{name} must be 1-D with >= 2 samples, got shape {v.shape}")
            d = np.diff(v)
            if not np.all(d > 0):
                raise ValueError(f"SagMap.{name} must be strictly increasing")
            if not is_uniform_axis(v):
                raise ValueError(f"SagMap.{name} must be uniformly spaced (spacing {d.min()}..{d.max()} mm)")
        object.__setattr__(self, "x_mm", x)
        object.__setattr__(self, "y_mm", y)
        object.__setattr__(self, "sag_um", _checked_sag(s, y.size, x.size))

    # ------------------------------------------------------------------ geometry
    @property
    def dx_mm(self) -> float:
        return float(self.x_mm[1] - self.x_mm[0])

    @property
    def dy_mm(self) -> float:
        return float(self.y_mm[1] - self.y_mm[0])

    @property
    def mask(self) -> np.ndarray:
        """Boolean array, True where the sample is valid."""
        return np.isfinite(self.sag_um)

    def grid(self) -> tuple[np.ndarray, np.ndarray]:
        """Meshgrid ``(X_mm, Y_mm)`` of shape (ny, nx)."""
        return np.meshgrid(self.x_mm, self.y_mm)

    def region_mask(self, region: str | Region | None = None) -> np.ndarray:
        """Valid samples inside ``region`` (name, Region or None for all)."""
        X, Y = self.grid()
        return resolve_region(region).contains(X, Y) & self.mask

    def values(self, region: str | Region | None = None) -> np.ndarray:
        """Valid sag samples (µm) inside ``region`` as a 1-D array; raises if there are none."""
        m = self.region_mask(region)
        if not m.any():
            r = resolve_region(region)
            raise ValueError(f"SagMap {self.label!r} has no valid samples inside region {r.name!r}")
        return self.sag_um[m]

    # ------------------------------------------------------------------ statistics
    def pv_um(self, region: str | Region | None = None) -> float:
        """Peak-to-valley sag (µm) over the valid samples in ``region``."""
        v = self.values(region)
        return float(v.max() - v.min())

    def rms_um(self, region: str | Region | None = None) -> float:
        """RMS about the mean (µm) over the valid samples in ``region``."""
        v = self.values(region)
        return float(np.sqrt(np.mean((v - v.mean()) ** 2)))

    # ------------------------------------------------------------------ transforms
    def with_sag(self, sag_um: np.ndarray, label: str | None = None) -> "SagMap":
        """Copy with new sag values on the same grid."""
        # the grid was checked when this map was made; only the sag is new (a diagnosis
        # deforms the nominal tens of thousands of times, and the grid checks were a tenth
        # of a line profile's cost there)
        new = object.__new__(type(self))
        for name, v in (("x_mm", self.x_mm), ("y_mm", self.y_mm),
                        ("sag_um", _checked_sag(np.asarray(sag_um, dtype=float), self.y_mm.size, self.x_mm.size)),
                        ("label", self.label if label is None else label), ("meta", dict(self.meta))):
            object.__setattr__(new, name, v)
        return new

    def scaled(self, factor: float) -> "SagMap":
        """Copy with the sag multiplied by ``factor`` (e.g. an amplitude scale)."""
        return self.with_sag(self.sag_um * factor)

    def remove_piston_tilt(self, region: str | Region | None = None) -> "SagMap":
        """Subtract the least-squares plane fitted over ``region`` from the whole map."""
        X, Y = self.grid()
        m = self.region_mask(region)
        if m.sum() < 3:
            raise ValueError(f"SagMap {self.label!r}: fewer than 3 valid samples to fit a plane")
        A = np.column_stack([np.ones(m.sum()), X[m], Y[m]])
        c, *_ = np.linalg.lstsq(A, self.sag_um[m], rcond=None)
        return self.with_sag(self.sag_um - (c[0] + c[1] * X + c[2] * Y))

    def masked(self, region: str | Region) -> "SagMap":
        """Copy with samples outside ``region`` set to NaN."""
        m = self.region_mask(region)
        return self.with_sag(np.where(m, self.sag_um, np.nan))

    def sample(self, x_mm: np.ndarray, y_mm: np.ndarray) -> np.ndarray:
        """Bilinear interpolation at arbitrary points (NaN outside the grid or next to NaN)."""
        f = RegularGridInterpolator(
            (self.y_mm, self.x_mm), self.sag_um, method="linear", bounds_error=False, fill_value=np.nan
        )
        x = np.asarray(x_mm, dtype=float)
        y = np.asarray(y_mm, dtype=float)
        xb, yb = np.broadcast_arrays(x, y)
        return f(np.column_stack([yb.ravel(), xb.ravel()])).reshape(xb.shape)

    def resampled(self, x_mm: np.ndarray, y_mm: np.ndarray) -> "SagMap":
        """This map bilinearly resampled onto the grid ``x_mm`` × ``y_mm``."""
        X, Y = np.meshgrid(x_mm, y_mm)
        return SagMap(np.asarray(x_mm), np.asarray(y_mm), self.sample(X, Y), self.label, dict(self.meta))

    # ------------------------------------------------------------------ constructors
    @classmethod
    def from_scattered(
        cls,
        x_mm: np.ndarray,
        y_mm: np.ndarray,
        sag_um: np.ndarray,
        spacing_mm: float = 0.5,
        extent_mm: tuple[float, float, float, float] | None = None,
        label: str = "",
    ) -> "SagMap":
        """Grid scattered samples (e.g. FEA surface nodes) by linear interpolation.

        Parameters
        ----------
        x_mm, y_mm, sag_um : ndarray, shape (n,)
            Sample positions (mm) and sag (µm).
        spacing_mm : float
            Grid spacing of the result in both directions (mm).
        extent_mm : (xmin, xmax, ymin, ymax), optional
            Grid extent; defaults to the bounding box of the samples.
        """
        x = np.asarray(x_mm, float).ravel()
        y = np.asarray(y_mm, float).ravel()
        s = np.asarray(sag_um, float).ravel()
        if not (x.size == y.size == s.size) or x.size < 3:
            raise ValueError("from_scattered needs >= 3 samples with equal-length x_mm, y_mm, sag_um")
        if not spacing_mm > 0:
            raise ValueError(f"spacing_mm={spacing_mm} must be > 0")
        if extent_mm is None:
            extent_mm = (x.min(), x.max(), y.min(), y.max())
        x0, x1, y0, y1 = extent_mm
        nx = int(round((x1 - x0) / spacing_mm)) + 1
        ny = int(round((y1 - y0) / spacing_mm)) + 1
        gx = np.linspace(x0, x1, nx)
        gy = np.linspace(y0, y1, ny)
        return cls(gx, gy, linear_on_grid(x, y, s, gx, gy), label)


def quilt_sag_map(
    pv_um: float,
    form: Literal["product", "sum"] = "product",
    period_x_mm: float = 21.0,
    period_y_mm: float = 18.0,
    size_mm: tuple[float, float] = (160.0, 140.0),
    spacing_mm: float = 0.25,
    label: str | None = None,
) -> SagMap:
    """Analytic sinusoidal quilt: a stand-in for the lightweighting print-through.

    Two forms are provided because the P/V-to-amplitude ratio differs by 2x between
    them, which matters when a P/V is quoted without its form:

    * ``"product"``: ``sag = (pv/2) cos(2πx/Dx) cos(2πy/Dy)`` — an egg-crate whose
      only Fourier components are at (±1/Dx, ±1/Dy); amplitude a = pv/2.
    * ``"sum"``: ``sag = (pv/4) [cos(2πx/Dx) + cos(2πy/Dy)]`` — a separable quilt with
      components at (±1/Dx, 0) and (0, ±1/Dy); amplitude a = pv/4 per direction.

    Maxima sit at the origin, which the FEA puts over a hole crossing.

    Parameters
    ----------
    pv_um : float
        Peak-to-valley of the quilt (µm), >= 0.
    period_x_mm, period_y_mm : float
        Quilt periods along x and y (mm).
    size_mm : (float, float)
        Full extent of the map in x and y (mm), centred on the origin.
    spacing_mm : float
        Grid spacing (mm).
    """
    if not pv_um >= 0:
        raise ValueError(f"pv_um={pv_um} must be >= 0")
    for n, v in (("period_x_mm", period_x_mm), ("period_y_mm", period_y_mm), ("spacing_mm", spacing_mm)):
        if not v > 0:
            raise ValueError(f"{n}={v} must be > 0")
    if form not in ("product", "sum"):
        raise ValueError(f"form={form!r} is unknown; use 'product' or 'sum'")
    nx = int(round(size_mm[0] / spacing_mm)) + 1
    ny = int(round(size_mm[1] / spacing_mm)) + 1
    x = np.linspace(-size_mm[0] / 2, size_mm[0] / 2, nx)
    y = np.linspace(-size_mm[1] / 2, size_mm[1] / 2, ny)
    X, Y = np.meshgrid(x, y)
    cx, cy = np.cos(2 * np.pi * X / period_x_mm), np.cos(2 * np.pi * Y / period_y_mm)
    sag = 0.5 * pv_um * cx * cy if form == "product" else 0.25 * pv_um * (cx + cy)
    return SagMap(x, y, sag, label or f"quilt {form} P/V {pv_um:g} um",
                  {"form": form, "period_x_mm": period_x_mm, "period_y_mm": period_y_mm})
