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

Filtering (:func:`filtered`): the departure is taken to the nominal's grid (piecewise
linear; 0 outside the convex hull of the map's points, i.e. the model's shape there) and
then

* band-limited to the lattice's first :data:`DEPARTURE_HARMONICS` harmonics along each axis
  (flat to the fourth, a cos² taper to zero at the fifth): a ripple of ``h`` cycles per pitch
  along x sends light ``h`` satellite spacings from the line (34 µm per harmonic in J at
  1.25 µm), so the fourth lands at 138 µm, at the edge of the fit's 150 µm window, and what
  lies beyond is light the model's window does not hold (its FFT period wraps it back);
* cut below half a lattice harmonic (radially; a cos² ramp over a quarter harmonic each
  side, :data:`LOW_CUT_HARMONICS`): what varies more slowly than over two pitches is figure,
  which the library's smooth effects (bow, astigmatism, plating gradient, the quilt's figure
  ratio, the collimator's wavefront) describe, and where an interferometer's own smooth
  errors (air, retrace) lie; the quilt's own departures sit about its harmonics;
* weighted per spatial frequency by the Wiener gain ``max(0, 1 - N/P)``, ``P`` the
  departure's power spectrum and ``N`` that of the map's white noise (its estimated sigma,
  drawn at the map's points and gridded the same way), both smoothed over
  :data:`SMOOTHING_BINS` frequency bins. Why: the map's noise inside the band is what
  changes a profile (a 10 nm white noise changes a J profile by 0.27 % of its peak, as much
  as a profile's own noise; the band limit alone leaves 0.23 %; with the gain 0.03 %), while
  a real departure gathers about the lattice's fundamentals: on a campaign map of a
  pocket-jitter truth, 96 % of the departure's power without the white noise lies in the
  fifth of the band's bins where it exceeds the white noise's, and the gain brings the
  departure's error against it over the pupil from 9.3 nm (5.1 nm band-limited) to 2.6 nm,
  for 8.2 nm of departure. The map's *correlated* errors (air, retrace) are not in ``N``
  and pass where they share the quilt's band (``tests/test_map_departure.py``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import uniform_filter

from optics.sagmap import SagMap
from optics.triangulation import linear_on_grid

from .forward import lstsq_residual, quilt_parts
from .quilt import QUILT_PERIOD_X_MM, QUILT_PERIOD_Y_MM

__all__ = ["POLYNOMIAL_DEGREE", "DEPARTURE_HARMONICS", "LOW_CUT_HARMONICS", "SMOOTHING_BINS", "NOISE_SEED", "MapDeparture",
           "departure_columns", "filtered", "map_departure"]

#: Highest total degree of the smooth polynomial terms removed from the map (15 terms at 4:
#: piston to the fourth-order figure; the quilt's fundamental period is 21 mm, 6.5 periods
#: across the 137 mm map, so a quartic cannot hold a quilt component).
POLYNOMIAL_DEGREE = 4
#: Lattice harmonics the departure keeps along each axis (module docstring: filtering).
DEPARTURE_HARMONICS = 4
#: Below this many harmonics (radially, in lattice harmonics) the departure is not carried
#: (module docstring: filtering): a cos² ramp from 0 a quarter harmonic below to 1 a
#: quarter above.
LOW_CUT_HARMONICS = 0.5
#: Width (bins of the twice zero-padded grid's spectrum, 1/(2 extent) apart: 0.33 of a
#: harmonic on the 160 mm nominal map) of the box the Wiener gain's power spectra are
#: smoothed over.
SMOOTHING_BINS = 5
#: Seed of the noise drawn to measure the noise's power spectrum (a given map's departure
#: is then the same on every run).
NOISE_SEED = 20261129


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
        RMS of the map's residual after the fit at its points, at the map's own factor (µm),
        noise included.
    fraction : float
        Its share of the map's RMS after piston and tilt.
    noise_um : float
        The map's white-noise sigma the filter used (µm).
    carried_rms_um : float
        RMS of the filtered departure over the map, at the map's own factor (µm).
    """

    measurement: str
    blank: str
    shape_um: np.ndarray
    scale: float
    rms_um: float
    fraction: float
    noise_um: float
    carried_rms_um: float

    def summary(self) -> dict:
        """The report's record: measurement, blank, scale, the residual's RMS (µm) and share
        of the map, the noise sigma (µm) and the carried departure's RMS (µm)."""
        return {"measurement": self.measurement, "blank": self.blank, "scale": self.scale,
                "rms_um": self.rms_um, "fraction_of_map": self.fraction, "noise_um": self.noise_um,
                "carried_rms_um": self.carried_rms_um}


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


def _falling(h: np.ndarray, start: float, width: float) -> np.ndarray:
    """1 up to ``|h| = start``, a cos² ramp to 0 at ``start + width``, 0 beyond."""
    t = np.clip((np.abs(h) - start) / width, 0.0, 1.0)
    return np.cos(0.5 * np.pi * t) ** 2


def filtered(sag_um: np.ndarray, noise_um: np.ndarray | None, x_mm: np.ndarray, y_mm: np.ndarray,
             harmonics: float = DEPARTURE_HARMONICS) -> np.ndarray:
    """``sag_um`` (on the uniform grid ``x_mm``, ``y_mm``, mm; no NaN) band-limited to
    ``harmonics`` of the lattice pitch along each axis, cut below :data:`LOW_CUT_HARMONICS`
    and, given ``noise_um`` (a realisation of the noise on the same grid), weighted by the
    Wiener gain ``max(0, 1 - N/P)`` of the smoothed power spectra (module docstring).
    Zero-padded to twice the grid: nothing wraps."""
    ny, nx = sag_um.shape
    pad = (2 * ny, 2 * nx)
    fx = np.fft.rfftfreq(pad[1], float(x_mm[1] - x_mm[0])) * QUILT_PERIOD_X_MM
    fy = np.fft.fftfreq(pad[0], float(y_mm[1] - y_mm[0])) * QUILT_PERIOD_Y_MM
    spectrum = np.fft.rfft2(sag_um, s=pad)
    gain = np.outer(_falling(fy, harmonics, 1.0), _falling(fx, harmonics, 1.0))
    gain = gain * (1.0 - _falling(np.hypot(*np.meshgrid(fx, fy)), LOW_CUT_HARMONICS - 0.25, 0.5))
    if noise_um is not None:
        def smooth(a):  # over neighbouring frequencies, the y axis made contiguous first
            return np.fft.ifftshift(uniform_filter(np.fft.fftshift(a, axes=0), SMOOTHING_BINS, mode="nearest"), axes=0)
        power = smooth(np.abs(spectrum) ** 2)
        noise = smooth(np.abs(np.fft.rfft2(noise_um, s=pad)) ** 2)
        gain = gain * np.clip(1.0 - noise / np.where(power > 0, power, np.inf), 0.0, 1.0)
    return np.fft.irfft2(spectrum * gain, s=pad)[:ny, :nx]


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
    scale = float(lstsq_residual(np.column_stack([S[:, :1], Q]), d)[1][0])
    if not scale > 0.0:
        return None
    r, _ = lstsq_residual(np.column_stack([S, Q]), d)
    total = float(np.sqrt(np.mean(lstsq_residual(Q[:, :3], d)[0] ** 2)))
    rms = float(np.sqrt(np.mean(r**2)))
    sigma = float(surface.noise_known or surface.estimate_noise(r))
    on_map = np.isfinite(linear_on_grid(x, y, np.zeros_like(x), nominal.x_mm, nominal.y_mm))

    def gridded(v):
        return np.where(on_map, linear_on_grid(x, y, v, nominal.x_mm, nominal.y_mm), 0.0)

    noise = np.random.default_rng(NOISE_SEED).normal(0.0, sigma / scale, x.size)
    carried = filtered(gridded(r / scale), gridded(noise), nominal.x_mm, nominal.y_mm)
    shape = np.where(np.isfinite(nominal.sag_um), carried, 0.0)
    carried_rms = scale * float(np.sqrt(np.mean(shape[on_map] ** 2))) if on_map.any() else 0.0
    return MapDeparture(surface.name, surface.blank, shape, scale, rms, rms / total if total > 0 else 0.0,
                        sigma, carried_rms)
