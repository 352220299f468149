"""The library of candidate unmodelled effects.

One module per effect (or per family sharing a summary: :mod:`.rescaling`) holds its
:class:`Effect` declaration, its action on the forward models (the hooks of
:class:`Effect`: how it scales, moves, reshapes the deformation or changes the
spectrograph; :mod:`.base` lists them in the order the models call them), its report
summary and the constants it owns; :mod:`.base` the concepts (:class:`Parameter`,
:class:`Effect`, :class:`SpectrographOptics`, :class:`SummaryContext`); :mod:`.library`
the :data:`LIBRARY`, in its order, the :data:`ALTERNATIVES` (effect units a check fits
instead of a library effect, never candidates: :mod:`.pupil_other_orders`) and the
questions asked of them.

Each effect is a named set of parameters of the forward model (:mod:`pipeline.diagnosis.forward`) with a
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
slit_width          slit_image_width_um (27; 15…45 µm): the      the slit image width differs
                    J, H, K gratings' width, one for every       from the nominal (one slit for
                    grating (HK's: 29/27 of it; the summary      every grating: 27 µm J, H, K;
                    gives each measured grating's own, µm)       29 µm HK)
plating_gradient    plating_grad_x, plating_grad_y (0; ±0.1)     NiP thickness varies linearly
                    relative change of the deformation           across the blank: deformation
                    amplitude at x or y = +70 mm                 x (1 + gx x/70 + gy y/70)
                    (companion, below)
blank_bow           bow_defocus_um Z(2,0), bow_spherical_um      rotationally symmetric figure
                    Z(4,0) (0; ±0.2 µm), RMS-normalised over     change of the cold blank
                    a 70 mm radius disc in blank coordinates,    (front/back plating or polish
                    at the simulation's cold_K, scaled with the  imbalance bends it like a
                    deformation (companion, below)               bimetal; mount)
quilt_shape         quilt_fund_xy_ratio (1; 0.3…3; maps and      the quilt's harmonic content
                    PSF images only), quilt_harmonics_ratio,     differs from the FEA's
                    quilt_x_harmonics_ratio, quilt_cross_ratio   (:mod:`pipeline.diagnosis.quilt`, below;
                    (1; -1…3; all 0 = pure sinusoid),            background companion)
                    quilt_figure_ratio (1; -1…3)
==================  ===========================================  ============================

``quilt_shape`` changes the nominal map ``S`` into
``S + (rho - 1) F_y + (h - 1) H + (c - 1) C + (k - 1) H_x + (g - 1) R`` with ``F_x``, ``F_y``
the quilt's fundamentals (21 mm along x, 18 mm along y), ``C`` its (1, ±1) egg-crate cross
terms, ``H_x`` its harmonics along x ((2, 0), (3, 0)), ``H`` its other harmonics, from a
Fourier fit of the nominal over the 82 x 72 mm centre (:mod:`pipeline.diagnosis.quilt`), and
``R = S - F_x - F_y - H - C - H_x`` the smooth figure the fit leaves; ``rho =
quilt_fund_xy_ratio``, ``h = quilt_harmonics_ratio``, ``k = quilt_x_harmonics_ratio``, ``c =
quilt_cross_ratio``, ``g = quilt_figure_ratio``. The
fundamentals' amplitude is not a parameter of it: separate scales of ``F_x``, ``F_y`` and
``H`` would be degenerate with ``amplitude_scale`` on line profiles (measured, FEA map
200 µm / 75 % at 80 K, J 1.25 µm at 250/100/25 mas jointly: correlation -0.999 between
the scale of ``F_x`` and ``amplitude_scale``, -0.96 between ``H``'s scale and it, and a
scale of ``F_y`` has no leverage at all — a phase periodic along the rulings scatters
light along the slit, which a profile integrates). Held relative to the fundamentals,
``h`` and ``amplitude_scale`` correlate at 0.50 on those profiles and 0.21 on a 137 mm
map, so the amplitude of the quilt stays ``amplitude_scale``'s (or ``temperature``'s)
and ``quilt_shape`` says how its shape differs. ``rho`` scales ``F_y`` with ``F_x`` held;
it is only fitted where a map or a PSF image is in the data (``Parameter.kinds``).

``companion`` effects (``plating_gradient``, ``blank_bow``) are candidates on their own *and* are refitted
jointly with the best-ranked other candidates (:class:`~pipeline.diagnosis.criteria.Criteria`
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

``quilt_shape`` is a ``background`` companion: a real grating's quilt never has exactly the
FEA's shape (the paper's best J-band simulation is wider, with a shallower central dip,
than the measurement), so the shape is refitted beside every finding, as the plating
gradient and the bow are, and a finding is named for what it explains *beyond* the quilt's
shape. It is never half of a pair (``X + quilt_shape`` is the finding ``X`` fitted with
it). Its free ratios act on every periodic feature of a map and on the wings of every
line, so it takes up part of almost any gap (measured on independent truths: periodic
surface ripples and stray-light halos): read a ``quilt_shape`` verdict together with
``Diagnosis.unexplained_in`` and the finding's ``remaining_gap``.
Where several companions each lower the score, a larger set is adopted only if it beats
the best smaller one by ``companion_bic`` (each companion adopted must be supported).

``floor`` is the absolute tolerance used when judging parameter recovery
(relative error is ``|fit - true| / max(|true|, floor)``).
"""

from .base import SHAPE_STAGES, Effect, Parameter, SpectrographOptics, SummaryContext
from .blank_bow import BOW_REF_RADIUS_MM
from .collimator_wfe import COLLIMATOR_PUPIL_RADIUS_MM
from .library import (ALTERNATIVES, LIBRARY, applicable_effects, draw_campaign_truth, effect_parameters,
                      forward_effects, library_markdown, library_rows, parameter_spec, parameter_units,
                      physical_summary)
from .plating_gradient import PLATING_GRADIENT_REF_MM
from .slit_width import NOMINAL_SLIT_UM

__all__ = ["Parameter", "Effect", "SHAPE_STAGES", "SpectrographOptics", "LIBRARY", "ALTERNATIVES", "forward_effects",
           "PLATING_GRADIENT_REF_MM", "BOW_REF_RADIUS_MM", "COLLIMATOR_PUPIL_RADIUS_MM",
           "draw_campaign_truth", "effect_parameters", "parameter_spec", "parameter_units", "applicable_effects", "NOMINAL_SLIT_UM",
           "SummaryContext", "physical_summary", "library_rows", "library_markdown"]
