"""Independent truths for the injection-recovery campaign (``diagnose --validate``).

Independence: the list of code paths the generator does NOT share with the diagnosis
forward model (:mod:`pipeline.diagnosis.forward`, :mod:`.synth`, :mod:`.psf_image`):

* optics: :mod:`.abbe` is a literal 2-D finite-slit Abbe sum in numpy (its own grating
  equation from the paper's table, slit and source sampling, pupil grid with grey rim
  from sub-sampled cells, Zernike polynomials, grating phase, Fraunhofer propagation
  evaluated per source, along-slit collapse, pixel integration by its transfer
  function). It does not import :mod:`optics.imaging`, :mod:`optics.lineprofile`,
  :mod:`optics.grating`, :mod:`optics.pupil` functions, :mod:`optics.zernike`,
  :mod:`optics.sagmap` or :mod:`pipeline.diagnosis.forward`; the forward model's
  infinite-slit strip, ``LsfSettings`` discretisation, ``box_convolve`` and sag
  resampling are not used. A point-source image (``CampaignConfig.psf_image``) is the
  same pupil field propagated once (:func:`.abbe.point_image`), not
  :func:`optics.lineprofile.point_psf` or :mod:`pipeline.diagnosis.psf_image`;
* grating maps: :mod:`.gratings` mixes the FEA map with analytic sum- and product-form
  quilts fitted to it (own least squares), at a drawn harmonic distance from the nominal,
  and interpolates with scipy; :mod:`.lattice` jitters the FEA map's quilt per cell of the
  hole lattice (its own period-average figure) or mixes it with sharp rib profiles; the
  model's ``blank_shape_um``, bow and plating terms and the library's quilt decomposition
  (:mod:`pipeline.diagnosis.quilt`) are not used;
* detector and interferometer: :mod:`.detector` and :func:`.generate.measured_map`
  (super-sampled pixels at random sub-pixel phases, inter-pixel coupling, counts with
  Poisson and read noise, correlated noise, pedestal or background subtraction; an
  image's dithered lattice, counts, background and missing samples; map piston/tilt,
  correlated noise, dropouts) — not :mod:`.synth`;
* out-of-library effects: :mod:`.families` (``benchmarks/truth_families.md``), not the
  model campaign's coma/bump/ghost/distortion.

Shared (deliberately, as data or physics the diagnosis is meant to assume):

* the FEA solver (:func:`pipeline.diagnosis.nominal.fea_sag_map`): the truth's FEA map
  comes from another mesh (``CampaignConfig.truth_mesh``) of the same code;
* :func:`pipeline.diagnosis.nominal.thermal_factor` (the mismatch-strain ratio from the
  material tables) for temperature truths;
* the instrument's default collimator wavefront (the numbers of
  :data:`optics.pupil.DEFAULT_COLLIMATOR_ZERNIKE_UM`), the effects' parameter
  conventions (so the injected values mean what the library's do), and the manifest
  and file formats the diagnosis reads, with their writers in :mod:`pipeline.io` (file
  I/O, not model: a line profile goes out through
  :func:`pipeline.io.measured.write_line_profile_csv`, an image through
  :func:`pipeline.io.measured.write_psf_image_csv`);
* the random magnitudes of the library effects' truths (:data:`pipeline.diagnosis.effect_draws.DRAWS`,
  random numbers only), so that both truths inject the same effects at the same sizes.
"""

from .abbe import AbbeSettings, abbe_line_profile
from .generate import CASE_TYPES, PAIR_CASE_TYPES, make_case

__all__ = ["AbbeSettings", "abbe_line_profile", "CASE_TYPES", "PAIR_CASE_TYPES", "make_case"]
