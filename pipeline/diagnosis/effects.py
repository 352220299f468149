"""The library of candidate unmodelled effects.

Each effect is a named set of parameters of the forward model (:mod:`.forward`) with a
physical meaning, a null value (the nominal model) and a prior range (fit bounds).
All effects act on the same parameter vector, so a pair of effects is simply the union
of their parameters.

==================  ===========================================  ============================
effect              parameters (null; prior)                     physical meaning
==================  ===========================================  ============================
astigmatism         astig_0_um, astig_45_um (0; ±1 µm)           mount-induced surface Zernike
                                                                 astigmatism Z(2,2), Z(2,-2)
                                                                 (RMS-normalised, aperture disc)
amplitude_scale     scale_<blank> (1; 0.3…3), one per blank      coating thickness / polish
                                                                 differ (e.g. re-polishing)
temperature         temperature_offset_K (0; -60…+80 K)           cold temperature differs from
                                                                 the stated one (all data)
registration        reg_dx_mm, reg_dy_mm (0; ±10 mm),            measured map shifted/rotated
                    reg_rot_deg (0; ±5°)                         against the model
pupil_shift         pupil_x_mm, pupil_y_mm (0; ±10 mm)           beam footprint offset on the
                                                                 grating
collimator_wfe      coll_coma_um Z(3,1), coll_defocus_um Z(2,0), extra spectrograph WFE on top
                    coll_astig45_um Z(2,-2) (0; ±0.4 µm)         of the default collimator
slit_width          slit_image_width_um (27; 15…45 µm)           slit image width ≠ 27 µm
                                                                 (29 µm grating HK scaled alike)
plating_gradient    plating_grad_x, plating_grad_y (0; ±0.1)     NiP thickness varies linearly
                    relative change of the deformation           across the blank: deformation
                    amplitude at x or y = +70 mm                 x (1 + gx x/70 + gy y/70)
                    (companion, below)
blank_bow           bow_defocus_um Z(2,0), bow_spherical_um      rotationally symmetric figure
                    Z(4,0) (0; ±0.2 µm), RMS-normalised over     change of the cold blank
                    a 70 mm radius disc in blank coordinates,    (front/back plating or polish
                    at the simulation's cold_K, scaled with the  imbalance bends it like a
                    deformation (companion, below)               bimetal; mount)
==================  ===========================================  ============================

``companion`` effects (``plating_gradient``, ``blank_bow``) are candidates on their own *and* are refitted
jointly with the best-ranked other candidates (:class:`~pipeline.diagnosis.engine.Criteria`
``companion_top``); the joint fit replaces a finding only where the data support it
(BIC lower by ``companion_bic``). The finding keeps its own name and lists the companion in
``Finding.companions``. Reason: a plating-thickness gradient is present at some level on
every real blank (the scenarios' truths, and the campaign's with ``discrepancy="companions"``,
carry a random ±1.5–3 % one), so it is a
nuisance-like discrepancy that biases the other effects' parameters (collimator defocus,
the sign of pupil_y) unless it is fitted alongside them; it is not a nuisance of the
forward model (piston/tilt, offset shift, flux, background), because those are removed
from every fit including the nominal, while the gradient must be *tested* (it is a
physical claim about the blank and costs parameters in the BIC). A ``blank_bow`` is the same kind of discrepancy: the FEA
predicts the quilting and the edge roll-off of a symmetric plating well, but a small
front/back imbalance of the plating thickness or of the polished-off fraction bends the
blank like a bimetal strip, adding power and spherical aberration that the nominal
model does not have (measured in the campaign: a bow of 0.01 µm RMS biased the
temperature fitted on one 128 K map by 8–13 K, and collimator defocus on line profiles
by up to 0.09 µm). On line profiles alone the bow is degenerate with collimator defocus
(both curve the wavefront along the dispersion; measured: with the bow free, the
defocus error of a campaign case grew from 0.01 to 0.35 µm), so it is only tried where
a surface map is in the data (``requires``), which pins it down (on profiles alone the
finding that takes it up lists it in ``degenerate_with`` and reports how much of it its
parameters contain, ``Finding.absorbs``); it then acts on every
measurement (one bow for all blanks: a per-blank bow would need one map per blank).

``floor`` is the absolute tolerance used when judging parameter recovery
(relative error is ``|fit - true| / max(|true|, floor)``).
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Parameter", "Effect", "LIBRARY", "PLATING_GRADIENT_REF_MM", "BOW_REF_RADIUS_MM", "effect_parameters", "applicable_effects", "NOMINAL_SLIT_UM"]

NOMINAL_SLIT_UM = 27.0


@dataclass(frozen=True)
class Parameter:
    """One fit parameter: name (with unit), null value, prior bounds, start values for a
    coarse grid search, and the absolute recovery tolerance ``floor``."""

    name: str
    null: float
    lo: float
    hi: float
    starts: tuple[float, ...] = ()
    floor: float = 0.0

    def __post_init__(self) -> None:
        if not self.lo <= self.null <= self.hi:
            raise ValueError(f"Parameter {self.name!r}: null={self.null} outside [{self.lo}, {self.hi}]")

    @property
    def width(self) -> float:
        return self.hi - self.lo


@dataclass(frozen=True)
class Effect:
    """A candidate unmodelled effect.

    Parameters
    ----------
    name : str
        Library key.
    kinds : tuple of str
        Measurement kinds it changes ("surface", "line_profile", "psf_image").
    parameters : tuple of Parameter
        Its parameters; for ``per_blank`` effects a template whose name gets ``_<blank>``.
    per_blank : bool
        One copy of the parameter per grating blank in the data.
    description : str
        Physical meaning, for reports.
    companion : bool
        Also refitted jointly with the best other candidates (module docstring).
    vector : bool
        The parameters are the components of one vector in a common unit whose norm is
        the effect's physical magnitude: coefficients of RMS-normalised (orthonormal)
        Zernike terms, whose norm is the RMS of the added surface or wavefront error, or a
        displacement in mm. The campaign also judges recovery on the vector
        (:func:`pipeline.diagnosis.campaign.recovery_errors`).
    requires : tuple of str
        Measurement kinds that must be in the data for the effect to be tried: the kinds
        that can identify it (it still changes every kind in ``kinds``).
    """

    name: str
    kinds: tuple[str, ...]
    parameters: tuple[Parameter, ...]
    per_blank: bool = False
    description: str = ""
    vector: bool = False
    companion: bool = False
    requires: tuple[str, ...] = ()


LIBRARY: dict[str, Effect] = {e.name: e for e in (
    Effect("astigmatism", ("surface",),
           (Parameter("astig_0_um", 0.0, -1.0, 1.0, floor=0.02), Parameter("astig_45_um", 0.0, -1.0, 1.0, floor=0.02)),
           description="mount-induced surface astigmatism (Zernike (2,2) and (2,-2), RMS-normalised over the aperture)",
           vector=True),
    Effect("amplitude_scale", ("surface", "line_profile", "psf_image"),
           (Parameter("scale", 1.0, 0.3, 3.0, floor=0.05),), per_blank=True,
           description="deformation amplitude differs (NiP thickness or polish; e.g. a re-polished blank)"),
    Effect("temperature", ("surface", "line_profile", "psf_image"),
           (Parameter("temperature_offset_K", 0.0, -60.0, 80.0, floor=5.0),),
           description="true cold temperature = stated + offset (exact rescaling by the mismatch strain)"),
    Effect("registration", ("surface",),
           (Parameter("reg_dx_mm", 0.0, -10.0, 10.0, (-6.0, 0.0, 6.0), floor=0.5),
            Parameter("reg_dy_mm", 0.0, -10.0, 10.0, (-5.0, 0.0, 5.0), floor=0.5),
            Parameter("reg_rot_deg", 0.0, -5.0, 5.0, floor=0.3)),
           description="measured map shifted/rotated against the model (model feature at p appears at R p + d)"),
    Effect("pupil_shift", ("line_profile", "psf_image"),
           (Parameter("pupil_x_mm", 0.0, -10.0, 10.0, (-7.0, -3.5, 0.0, 3.5, 7.0), floor=1.0),
            Parameter("pupil_y_mm", 0.0, -10.0, 10.0, (0.0, 4.5), floor=3.0)),
           description="beam footprint offset on the grating (x dispersion, y ruling), common to all profiles",
           vector=True),
    Effect("collimator_wfe", ("line_profile", "psf_image"),
           (Parameter("coll_coma_um", 0.0, -0.4, 0.4, floor=0.04), Parameter("coll_defocus_um", 0.0, -0.4, 0.4, floor=0.04),
            Parameter("coll_astig45_um", 0.0, -0.4, 0.4, floor=0.06)),
           description="extra low-order spectrograph WFE (RMS-normalised Zernike over the 110 mm pupil)",
           vector=True),
    Effect("slit_width", ("line_profile",),
           (Parameter("slit_image_width_um", NOMINAL_SLIT_UM, 15.0, 45.0, floor=1.0),),
           description="geometric slit image width differs from 27 µm (29 µm for HK, scaled alike)"),
    Effect("plating_gradient", ("surface", "line_profile", "psf_image"),
           (Parameter("plating_grad_x", 0.0, -0.1, 0.1, floor=0.01), Parameter("plating_grad_y", 0.0, -0.1, 0.1, floor=0.01)),
           description="NiP thickness gradient across the blank: deformation x (1 + gx x/70 mm + gy y/70 mm) "
                       "(blank coordinates; gx, gy = relative amplitude change at the blank's half-width)",
           vector=True, companion=True),
    Effect("blank_bow", ("surface", "line_profile", "psf_image"),
           (Parameter("bow_defocus_um", 0.0, -0.2, 0.2, floor=0.01), Parameter("bow_spherical_um", 0.0, -0.2, 0.2, floor=0.01)),
           description="rotationally symmetric figure change of the cold blank: Zernike (2,0) and (4,0), "
                       "RMS-normalised over a 70 mm radius disc in blank coordinates, at the simulation's cold_K "
                       "(scaled with the deformation)",
           vector=True, companion=True, requires=("surface",)),
)}

#: Half-width (mm) at which ``plating_grad_x/y`` are the relative amplitude change.
PLATING_GRADIENT_REF_MM = 70.0
#: Radius (mm, blank coordinates) of the disc over which the ``blank_bow`` Zernike terms
#: are RMS-normalised: half the blank's 140 mm height, independent of any measurement.
BOW_REF_RADIUS_MM = 70.0


def effect_parameters(effect: Effect, blanks: tuple[str, ...]) -> tuple[Parameter, ...]:
    """The concrete parameters of ``effect`` for data seeing ``blanks``."""
    if not effect.per_blank:
        return effect.parameters
    from dataclasses import replace

    return tuple(replace(p, name=f"{p.name}_{b}") for p in effect.parameters for b in blanks)


def applicable_effects(kinds: set[str], names: tuple[str, ...] | None = None) -> tuple[Effect, ...]:
    """Library effects that change at least one of the measurement ``kinds`` present."""
    unknown = set(names or ()) - set(LIBRARY)
    if unknown:
        raise ValueError(f"effects {sorted(unknown)} are unknown; valid: {sorted(LIBRARY)}")
    chosen = LIBRARY if names is None else {n: LIBRARY[n] for n in names}
    return tuple(e for e in chosen.values() if set(e.kinds) & kinds and set(e.requires) <= kinds)
