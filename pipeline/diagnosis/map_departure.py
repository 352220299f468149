"""What a measured cold map says about its blank's quilt beyond the model's blank shape
(:func:`map_departure`), carried into the line-profile and PSF-image models of the same
blank.

Why: the library's ``quilt_shape`` rescales the nominal quilt's parts (fundamentals, cross
terms, harmonic groups, smooth figure) and nothing else, while a real blank's pockets each
print through a little differently (wall thickness, plating inside each hole) and its ribs
need not have the FEA's profile. A line profile is formed by exactly the quilt under the
beam, so a model that cannot hold that quilt reads its difference as some other effect
(measured on the campaign's pocket-jitter truths: pupil shifts of 6.35 and 4.2 mm along x
read 3.2 and 3.1 mm from the profiles with the map beside them). Where the same blank's
map is measured, its departure from every shape the library can fit is a measurement of
the grating, and the spectrograph-image models use it.

What is carried: the map minus its least-squares fit by

* the nominal quilt's parts (:func:`.forward.quilt_parts`: ``F_x``, ``F_y``, cross terms,
  harmonic groups) and the smooth figure ``S0 - F``: everything ``quilt_shape`` and the
  rescalings reach;
* ``x S0`` and ``y S0`` (a plating gradient across the blank);
* ``dS0/dx``, ``dS0/dy`` and ``x dS0/dy - y dS0/dx`` (the map's registration on the blank's
  pocket lattice, to first order: the model's quilt sits on the blank's holes, so the
  departure is taken in that frame);
* the bivariate polynomials up to degree :data:`POLYNOMIAL_DEGREE` (piston, tilt, the
  astigmatism and bow the library fits, any other smooth figure),

divided by the fitted scale of the nominal, so that it is a shape per unit deformation
factor: the image models add it to the blank's shape before their own factor (temperature,
amplitude) multiplies the sum. What is left is the part of the quilt that no library
parameter changes: each pocket's own print-through, harmonics above the third, and the
shape differences inside a harmonic group. The library's effects stay in the fit as before,
so nothing is counted twice: the departure is orthogonal to everything they change in the
map (to first order).

The map's noise is carried with it, unfiltered: a 10 nm white noise on a 1 mm grid
scatters about 1 % of the light over the whole detector period and changes a J profile by
0.3 % of its peak (``tests/test_map_departure.py``), below a profile's noise, while a filter
would blunt the sharp ribs' harmonics the profiles do see. Where the map does not reach
(outside the convex hull of its points) the departure is 0, i.e. the model's shape.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from optics.sagmap import SagMap
from optics.triangulation import linear_on_grid

from .forward import quilt_parts

__all__ = ["POLYNOMIAL_DEGREE", "MapDeparture", "departure_columns", "map_departure"]

#: Highest total degree of the smooth polynomial terms removed from the map (15 terms at 4:
#: piston to the fourth-order figure; the quilt's fundamental period is 21 mm, 6.5 periods
#: across the 137 mm map, so a quartic cannot hold a quilt component).
POLYNOMIAL_DEGREE = 4


@dataclass(frozen=True)
class MapDeparture:
    """A map's departure from the model's blank shape.

    Attributes
    ----------
    measurement : str
        Name of the map measurement.
    blank : str
        The blank it measures (the image models of this blank carry it).
    shape_um : ndarray
        Departure on the nominal map's grid, per unit deformation factor (µm at factor 1);
        0 where the map does not reach.
    scale : float
        Least-squares scale of the nominal's deformation in the map (the map's deformation
        factor) the departure was divided by.
    rms_um : float
        RMS of the departure at the map's points, at the map's own factor (µm).
    fraction : float
        Its share of the map's RMS after piston and tilt.
    """

    measurement: str
    blank: str
    shape_um: np.ndarray
    scale: float
    rms_um: float
    fraction: float

    def summary(self) -> dict:
        """The report's record: measurement, blank, scale, RMS (µm), share of the map."""
        return {"measurement": self.measurement, "blank": self.blank, "scale": self.scale,
                "rms_um": self.rms_um, "fraction_of_map": self.fraction}


def departure_columns(nominal: SagMap, quilt, x_mm: np.ndarray, y_mm: np.ndarray, radius_mm: float) -> tuple:
    """What the departure is orthogonal to (module docstring) at the points ``x_mm``,
    ``y_mm``: ``(shape, smooth)``, the blank-shape columns (n, m), the nominal's sag
    first, and the smooth polynomial columns (n, q), piston and the two tilts first.
    ``quilt``: :func:`.quilt.quilt_components` of ``nominal`` (None: the nominal's sag alone
    stands for the quilt)."""
    s = np.where(np.isfinite(nominal.sag_um), nominal.sag_um, 0.0)
    gy, gx = np.gradient(s, nominal.y_mm, nominal.x_mm)
    s0, dx, dy = (nominal.with_sag(a).sample(x_mm, y_mm) for a in (s, gx, gy))
    cols = [s0]
    parts = quilt_parts(quilt, x_mm, y_mm)
    if parts is not None:
        whole = parts.pop("whole")
        cols += [whole - sum(parts.values())] + list(parts.values()) + [s0 - whole]  # F_x, the others, the figure
    cols += [x_mm / radius_mm * s0, y_mm / radius_mm * s0, dx, dy, x_mm * dy - y_mm * dx]
    u, v = x_mm / radius_mm, y_mm / radius_mm
    smooth = [u**i * v**(d - i) for d in range(POLYNOMIAL_DEGREE + 1) for i in range(d + 1)]
    return np.column_stack(cols), np.column_stack(smooth)


def _lstsq_residual(A: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    c, *_ = np.linalg.lstsq(A, d, rcond=None)
    return d - A @ c, c


def map_departure(surface, nominal: SagMap) -> MapDeparture | None:
    """The departure of a map measurement from the model's blank shape (module docstring).

    Parameters
    ----------
    surface : .forward.SurfaceForward
        The map's forward model (its points, blank, aperture and the nominal's quilt).
    nominal : SagMap
        The nominal deformation (µm) at the simulation's cold temperature; the departure
        is returned on its grid.

    Returns
    -------
    MapDeparture or None
        None where the map holds no measurable deformation of the nominal's shape (a
        fitted scale that is not positive, or too few points for the fit).
    """
    S, Q = departure_columns(nominal, surface.quilt, surface.x, surface.y, surface.radius_mm)
    good = np.all(np.isfinite(S), axis=1) & np.isfinite(surface.data)
    if good.sum() <= 2 * (S.shape[1] + Q.shape[1]):
        return None
    x, y, d, S, Q = surface.x[good], surface.y[good], surface.data[good], S[good], Q[good]
    # The scale: the nominal's least-squares amplitude in the map beside the smooth terms
    # (what the rescalings read); the departure is divided by it to be a shape.
    scale = float(_lstsq_residual(np.column_stack([S[:, :1], Q]), d)[1][0])
    if not scale > 0.0:
        return None
    r, _ = _lstsq_residual(np.column_stack([S, Q]), d)
    total = float(np.sqrt(np.mean(_lstsq_residual(Q[:, :3], d)[0] ** 2)))
    rms = float(np.sqrt(np.mean(r**2)))
    on_grid = linear_on_grid(x, y, r / scale, nominal.x_mm, nominal.y_mm)
    shape = np.where(np.isfinite(on_grid) & np.isfinite(nominal.sag_um), on_grid, 0.0)
    return MapDeparture(surface.name, surface.blank, shape, scale, rms, rms / total if total > 0 else 0.0)
