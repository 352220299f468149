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
* ``C``: the egg-crate cross terms (1, 1) and (1, -1), the product of the two
  fundamentals: a sum-form quilt has none, a product-form quilt is made of them;
* ``H_x``: the harmonics along the dispersion, (2, 0) and (3, 0): the rib profile across
  the dispersion, sharper or blunter than a sinusoid;
* ``H``: every other fitted component ((0, 2), (2, ±1), (1, ±2), ...).

``C`` is split from ``H`` because the two change the line shape differently: the cross
terms scatter light into the satellites of the fundamental along the slit, the higher
harmonics into the second and third satellites (``benchmarks/results_j_gap.md``: the J
double peak depends mostly on the cross terms). ``H_x`` is split from ``H`` because a line
profile integrates along the rulings: of the higher harmonics it sees the ones along x
most, and a real rib profile changes them independently of the rest. Measured on the
campaign's independent truths (sharp ribs printing through, ``truth.lattice``): a rib
profile ``|cos|^4.6`` mixed into the FEA quilt turns the (2, 0) component's sign
(-0.39 of the nominal's) while (0, 3) grows 4.5-fold; one ratio for both made a 37 µm slit
read 41 µm beside it, and on a sum-form mixture left a narrow slit to the detector terms.

The components are periodic and evaluated wherever the nominal map is valid: the
pockets' pitch is the same over the whole blank, and the model change is a statement
about the quilt's shape, not about where it is. What the fit leaves, ``R`` (the blank's
smooth figure: edge roll-off, bow; ~8 % of the FEA map's variance over the centre), is
the fourth part: the quilt is the pockets printing through the plating, the smooth figure
the plate bending as a whole under the plating's mismatch strain and at its free edges,
and the two need not scale alike on a real blank (pocket depth and rib width against
plating thickness and symmetry).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from optics.fitting import FourierFit, fit_fourier
from optics.sagmap import SagMap

__all__ = ["QUILT_PERIOD_X_MM", "QUILT_PERIOD_Y_MM", "QUILT_HARMONICS", "QUILT_APERTURE", "CROSS_TERMS", "QuiltComponents",
           "quilt_components", "projection_weights", "projection_factor"]

#: The blank's pocket pitch (mm) along x (dispersion) and y (rulings).
QUILT_PERIOD_X_MM = 21.0
QUILT_PERIOD_Y_MM = 18.0
#: Highest harmonic of the decomposition (FEA map, 200 µm / 75 % at 80 K, default mesh:
#: components of the fourth and fifth harmonics are at most 1.4 nm; fitting them captures
#: 0.02 % more of the centre's variance).
QUILT_HARMONICS = 3
#: Aperture of the decomposition fit (optics.sagmap.REGIONS).
QUILT_APERTURE = "center"
#: The egg-crate cross terms ``C`` (module docstring).
CROSS_TERMS = ((1, 1), (1, -1))


@dataclass(frozen=True, eq=False)
class QuiltComponents:
    """The nominal map's quilt: fundamentals ``F_x``, ``F_y``, cross terms ``C``, harmonics
    along x ``H_x`` and the other harmonics ``H`` (module docstring), evaluable at any blank
    coordinates (mm) in µm; ``weights``: each
    part's share of the nominal's least-squares amplitude over the centre
    (:func:`projection_weights`)."""

    fourier: FourierFit
    weights: dict = field(default_factory=dict)

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
    def cross_terms(self) -> tuple:
        return tuple(c for c in self.fourier.components if c in CROSS_TERMS)

    @property
    def harmonic_terms(self) -> tuple:
        return tuple(c for c in self.fourier.components
                     if c not in ((1, 0), (0, 1)) + CROSS_TERMS and not (c[1] == 0 and c[0] >= 2))

    @property
    def x_harmonic_terms(self) -> tuple:
        return tuple(c for c in self.fourier.components if c[1] == 0 and c[0] >= 2)

    def x_harmonics_um(self, x_mm, y_mm) -> np.ndarray:
        return self._sum(x_mm, y_mm, self.x_harmonic_terms)

    def fundamental_x_um(self, x_mm, y_mm) -> np.ndarray:
        return self._sum(x_mm, y_mm, ((1, 0),))

    def fundamental_y_um(self, x_mm, y_mm) -> np.ndarray:
        return self._sum(x_mm, y_mm, ((0, 1),))

    def cross_um(self, x_mm, y_mm) -> np.ndarray:
        return self._sum(x_mm, y_mm, self.cross_terms)

    def harmonics_um(self, x_mm, y_mm) -> np.ndarray:
        return self._sum(x_mm, y_mm, self.harmonic_terms)

    def parts_um(self, x_mm, y_mm) -> dict:
        """Every part at blank coordinates (mm), µm: ``fundamental_x``, ``fundamental_y``,
        ``cross``, ``harmonics``, ``x_harmonics`` (they add up to the fitted quilt)."""
        return {"fundamental_x": self.fundamental_x_um(x_mm, y_mm), "fundamental_y": self.fundamental_y_um(x_mm, y_mm),
                "cross": self.cross_um(x_mm, y_mm), "harmonics": self.harmonics_um(x_mm, y_mm),
                "x_harmonics": self.x_harmonics_um(x_mm, y_mm)}

    def amplitudes_um(self) -> dict:
        """RMS over a period (µm) of ``F_x``, ``F_y``, ``C``, ``H`` and ``H_x``: what the effect scales."""
        a = self.fourier.amplitude_um
        return {"fundamental_x": float(a[(1, 0)] / np.sqrt(2)), "fundamental_y": float(a[(0, 1)] / np.sqrt(2)),
                "cross": float(np.sqrt(sum(a[c] ** 2 for c in self.cross_terms) / 2)),
                "harmonics": float(np.sqrt(sum(a[c] ** 2 for c in self.harmonic_terms) / 2)),
                "x_harmonics": float(np.sqrt(sum(a[c] ** 2 for c in self.x_harmonic_terms) / 2))}


def quilt_components(nominal: SagMap) -> QuiltComponents | None:
    """Decompose ``nominal`` (µm) into its quilt components; None where the map does not
    cover enough of the ``center`` aperture for the fit (the effect then has no leverage)."""
    try:
        f = fit_fourier(nominal, QUILT_PERIOD_X_MM, QUILT_PERIOD_Y_MM, harmonics=QUILT_HARMONICS,
                        aperture=QUILT_APERTURE, include_cross=True, include_plane=True)
    except ValueError:
        return None
    q = QuiltComponents(f)
    return QuiltComponents(f, projection_weights(nominal, q))


def projection_weights(nominal: SagMap, q: QuiltComponents) -> dict:
    """Each part ``P`` of the nominal ``S`` (``F_x``, ``F_y``, ``C``, ``H``, ``H_x`` and the
    smooth figure ``R = S - F_x - F_y - C - H - H_x``) as its share ``<P, S> / <S, S>`` of the nominal's
    least-squares amplitude over the ``center`` aperture (piston removed from both).

    The shares add up to 1 exactly (the parts add up to ``S``); where the parts are
    orthogonal over the aperture (whole periods; ``R`` is the Fourier fit's residual) each
    share is the part's fraction of the variance. They convert the amplitude a fit reports
    with ``F_x`` held (``amplitude_scale``, ``temperature`` beside ``quilt_shape``) into
    the amplitude a least-squares projection of the same deformation on the nominal gives
    (:func:`projection_factor`)."""
    X, Y = nominal.grid()
    m = nominal.region_mask(QUILT_APERTURE)
    s = nominal.sag_um[m] - nominal.sag_um[m].mean()
    parts = q.parts_um(X[m], Y[m])
    parts["figure"] = nominal.sag_um[m] - sum(parts.values())
    ss = float(s @ s)
    return {k: float((v - v.mean()) @ s / ss) for k, v in parts.items()} if ss > 0 else {}


def projection_factor(weights: dict, part_ratios: dict) -> float:
    """Least-squares projection on the nominal of the nominal with each part scaled by its
    ratio in ``part_ratios`` (part name -> ratio; a part missing there keeps ratio 1),
    relative to the nominal: ``w_Fx + rho w_Fy + c w_C + h w_H + k w_Hx + g w_R`` (``weights`` from
    :func:`projection_weights`; which effect parameter scales which part is the
    ``quilt_shape`` effect's :func:`~pipeline.diagnosis.effects.quilt_shape.part_ratios`).

    1 when the shape change leaves the projection unchanged. A deformation fitted as
    ``a`` times the reshaped nominal (``F_x`` held by the shape, so ``a`` is the x
    fundamental's amplitude) has projection amplitude ``a * projection_factor``."""
    return float(sum(w * part_ratios.get(k, 1.0) for k, w in weights.items()))
