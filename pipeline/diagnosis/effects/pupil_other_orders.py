"""``pupil_other_orders``: pupil aberrations of other orders than the collimator's, the
diagnostic alternative a collimator finding is checked against
(:mod:`pipeline.diagnosis.pupil_orders`, which says why these four terms). Not a library
effect: never ranked or reported as an explanation, so it is not in :data:`.library.LIBRARY`,
but the spectrograph-image models take its parameters (:data:`.library.ALTERNATIVES`)."""

from __future__ import annotations

from .base import Effect, Parameter

__all__ = ["PUPIL_OTHER_ORDERS"]

#: parameter -> ((n, m), what the term is)
_TERMS = {"pupil_spherical_um": ((4, 0), "primary spherical"), "pupil_trefoil_0_um": ((3, 3), "trefoil (cos 3 theta)"),
          "pupil_trefoil_30_um": ((3, -3), "trefoil (sin 3 theta)"),
          "pupil_coma2_um": ((5, 1), "secondary coma (cos theta)")}

PUPIL_OTHER_ORDERS = Effect(
    "pupil_other_orders", ("line_profile", "psf_image"),
    tuple(Parameter(name, 0.0, -0.4, 0.4, floor=0.04, unit="µm", kinds=("line_profile", "psf_image"),
                    meaning=f"{what} wavefront Zernike Z({nm[0]},{nm[1]}), RMS-normalised over the 110 mm pupil")
          for name, (nm, what) in _TERMS.items()),
    description="pupil aberration of other orders than the collimator's (RMS-normalised Zernike over the 110 mm pupil)",
    vector=True, pupil_zernike=tuple((name, nm) for name, (nm, _) in _TERMS.items()))
