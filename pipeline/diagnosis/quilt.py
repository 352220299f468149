"""The quilt's harmonic content: the nominal deformation split into the quilt's two
fundamentals and its higher harmonics (the ``quilt_shape`` effect, :mod:`.effects`).

Why: the lightweighting pockets print through the plating as a periodic quilt at the
blank's pitch (21 mm along x, the dispersion; 18 mm along y, the rulings). The paper
finds that the amplitude of the quilt's fundamental drives the line profiles (the
ghost/satellite strength) while the other Fourier components set their widths, and a
real grating's quilt shape differs from the FEA's (its best J-band simulation is "slightly
wider, with a less pronounced central dip" than the measurement; a pure sinusoid "also
matches, but narrower"). So the shape is measured as the ratios of those components,
not assumed.

Decomposition: a least-squares Fourier fit (:func:`optics.fitting.fit_fourier`) of the
nominal map over the ``center`` aperture (82 x 72 mm, where the pockets are regular),
up to the third harmonic with cross terms, phases referred to the blank's origin:

* ``F_x``: component (1, 0), ``A cos(2 pi x / 21 mm - phi)``;
* ``F_y``: component (0, 1);
* ``H``: every other fitted component (the (1, ±1) cross terms, (2, 0), (0, 2), ...).

The components are periodic and evaluated wherever the nominal map is valid: the
pockets' pitch is the same over the whole blank, and the model change is a statement
about the quilt's shape, not about where it is. What the fit leaves (the blank's smooth
figure: edge roll-off, bow; ~8 % of the FEA map's variance over the centre) is not
changed by the effect.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from optics.fitting import FourierFit, fit_fourier
from optics.sagmap import SagMap

__all__ = ["QUILT_PERIOD_X_MM", "QUILT_PERIOD_Y_MM", "QUILT_HARMONICS", "QUILT_APERTURE", "QuiltComponents",
           "quilt_components", "quilt_change_um"]

#: The blank's pocket pitch (mm) along x (dispersion) and y (rulings).
QUILT_PERIOD_X_MM = 21.0
QUILT_PERIOD_Y_MM = 18.0
#: Highest harmonic of the decomposition (FEA map, 200 µm / 75 % at 80 K, default mesh:
#: components of the fourth and fifth harmonics are at most 1.4 nm; fitting them captures
#: 0.02 % more of the centre's variance).
QUILT_HARMONICS = 3
#: Aperture of the decomposition fit (optics.sagmap.REGIONS).
QUILT_APERTURE = "center"


@dataclass(frozen=True, eq=False)
class QuiltComponents:
    """The nominal map's quilt: fundamentals ``F_x``, ``F_y`` and the higher harmonics ``H``
    (module docstring), evaluable at any blank coordinates (mm) in µm."""

    fourier: FourierFit

    def _sum(self, x_mm, y_mm, comps) -> np.ndarray:
        f = self.fourier
        x = np.asarray(x_mm, float) - f.phase_origin_mm[0]
        y = np.asarray(y_mm, float) - f.phase_origin_mm[1]
        out = np.zeros(np.broadcast(x, y).shape)
        for (i, j) in comps:
            arg = 2 * np.pi * (i * x / f.period_x_mm + j * y / f.period_y_mm)
            out = out + f.amplitude_um[(i, j)] * np.cos(arg - f.phase_rad[(i, j)])
        return out

    @property
    def harmonic_terms(self) -> tuple:
        return tuple(c for c in self.fourier.components if c not in ((1, 0), (0, 1)))

    def fundamental_x_um(self, x_mm, y_mm) -> np.ndarray:
        return self._sum(x_mm, y_mm, ((1, 0),))

    def fundamental_y_um(self, x_mm, y_mm) -> np.ndarray:
        return self._sum(x_mm, y_mm, ((0, 1),))

    def harmonics_um(self, x_mm, y_mm) -> np.ndarray:
        return self._sum(x_mm, y_mm, self.harmonic_terms)

    def amplitudes_um(self) -> dict:
        """RMS over a period (µm) of ``F_x``, ``F_y`` and ``H``: what the effect scales."""
        a = self.fourier.amplitude_um
        return {"fundamental_x": float(a[(1, 0)] / np.sqrt(2)), "fundamental_y": float(a[(0, 1)] / np.sqrt(2)),
                "harmonics": float(np.sqrt(sum(a[c] ** 2 for c in self.harmonic_terms) / 2))}


def quilt_components(nominal: SagMap) -> QuiltComponents | None:
    """Decompose ``nominal`` (µm) into its quilt components; None where the map does not
    cover enough of the ``center`` aperture for the fit (the effect then has no leverage)."""
    try:
        f = fit_fourier(nominal, QUILT_PERIOD_X_MM, QUILT_PERIOD_Y_MM, harmonics=QUILT_HARMONICS,
                        aperture=QUILT_APERTURE, include_cross=True, include_plane=True)
    except ValueError:
        return None
    return QuiltComponents(f)


def quilt_change_um(quilt: QuiltComponents | None, x_mm, y_mm, fund_x: float = 1.0, fund_y: float = 1.0,
                    harmonics: float = 1.0) -> np.ndarray | float:
    """Change of the sag (µm) when ``F_x``, ``F_y`` and ``H`` are multiplied by ``fund_x``,
    ``fund_y`` and ``harmonics``: ``(fund_x - 1) F_x + (fund_y - 1) F_y + (harmonics - 1) H``."""
    if quilt is None or (fund_x == 1.0 and fund_y == 1.0 and harmonics == 1.0):
        return 0.0
    out = 0.0
    if fund_x != 1.0:
        out = out + (fund_x - 1.0) * quilt.fundamental_x_um(x_mm, y_mm)
    if fund_y != 1.0:
        out = out + (fund_y - 1.0) * quilt.fundamental_y_um(x_mm, y_mm)
    if harmonics != 1.0:
        out = out + (harmonics - 1.0) * quilt.harmonics_um(x_mm, y_mm)
    return out
