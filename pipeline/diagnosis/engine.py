"""The diagnosis: where the gap lies, which effect explains it, how far it shrinks, and
whether that holds on withheld data (:func:`diagnose`).

The decision logic, step by step, and its thresholds (:class:`Criteria`, passed
explicitly) are described in ``docs/diagnosis.md``. The steps live in :mod:`.gap` (the gap
and its noise), :mod:`.ranking` (fits and ranking, companions), :mod:`.identifiability`
(degeneracies, signs, absorbed effects) and :mod:`.heldout`, a finding's tests in
:mod:`.verdict`; this module builds the problem, runs the steps and gives the verdict.
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field, replace

import numpy as np

from .criteria import N_EFF_SOURCES, Criteria
from .alone import fits_alone
from .departure_choice import departure_choice
from .effects import SummaryContext, applicable_effects, library_rows, parameter_units, physical_summary
from .amplitude_or_shape import amplitude_degeneracies
from .error_model import error_source, errors_summary, measure_errors, model_for_kinds, two_part_problem, weights_settled
from .finding import Finding, all_effects
from .fitting import FitOutcome, Problem, fit, nominal_weights
from .forward import ProfileForward, SurfaceForward
from .gap import acting_on, gap_statistics, gaps, has_gap, post_fit_n_eff, recount, recounted, residual_n_eff
from .heldout import heldout_check
from .identifiability import absorbed, degeneracies, sign_degeneracies, unconstrained
from .manifest import Manifest, load_data, load_manifest, read_summary
from .map_departure import map_departure
from .nominal import nominal_sag_map
from .plausibility import at_prior_bound, check_measurements
from .psf_image import PsfImageForward
from .verdict import explains, own_parameters
from .pupil_orders import checks, other_orders_check, with_check
from .ranking import fit_effects, parameters_of, predictions, rank, rescaling_companions
from . import wings as wings_alternative
from .where import measurement_parts, profile_parts, psf_image_parts, satellite_spacing_um, surface_parts

# Public names of the diagnosis, re-exported here from the modules that define them.
__all__ = ["Criteria", "N_EFF_SOURCES", "post_fit_n_eff", "recounted", "Finding", "Diagnosis", "diagnose",
           "build_problem", "fit_effects", "all_effects", "parameters_of", "summary_context", "unconstrained",
           "acting_on", "gap_statistics", "gaps", "has_gap", "explains", "member_explains", "members_of"]


@dataclass(frozen=True, eq=False)
class Diagnosis:
    """Result of :func:`diagnose`; ``to_dict()`` is the content of ``diagnosis.json``."""

    verdict: str
    findings: tuple
    where: tuple
    where_after: tuple
    baseline: dict
    measurements: tuple
    criteria: Criteria
    timings_s: dict
    manifest: str = ""
    curves: dict = field(default_factory=dict, repr=False)
    #: Measurements whose residual is still beyond noise after the best finding (or the
    #: nominal when there is none): the part of the gap nothing in the library explains.
    unexplained_in: tuple = ()
    #: Why the top finding is not the best by BIC (a pair's member explains; see
    #: :func:`member_explains`), why a collimator finding does not explain
    #: (:mod:`.pupil_orders`), and the check of a line-profile finding against light the
    #: detector side adds (:mod:`.wings`), else "".
    ranking_note: str = ""
    #: The best finding refitted on each kind of measurement alone (each measurement where
    #: all are of one kind), where its joint fit leaves a gap in some measurement
    #: (:func:`.alone.fits_alone`): whether the parts read one value or the gap is a
    #: missing effect.
    parts_alone: tuple = ()
    #: The outcome of each check the best finding went through, by name (``pupil_orders``:
    #: :class:`.pupil_orders.PupilOrdersCheck`, ``wings``: :class:`.wings.WingsCheck`), as
    #: plain numbers, whether or not it changed the verdict.
    checks: dict = field(default_factory=dict)

    @property
    def best(self) -> Finding | None:
        return self.findings[0] if self.findings else None

    def finding(self, effect: str) -> Finding | None:
        return next((f for f in self.findings if f.effect == effect), None)

    def to_dict(self) -> dict:
        def clean(v):
            if isinstance(v, float):
                return v if math.isfinite(v) else None
            if isinstance(v, dict):
                return {k: clean(x) for k, x in v.items()}
            if isinstance(v, (list, tuple)):
                return [clean(x) for x in v]
            return v

        return clean({"verdict": self.verdict, "unexplained_in": list(self.unexplained_in),
                      "ranking_note": self.ranking_note,
                      "parts_alone": [p.to_dict() for p in self.parts_alone], "checks": self.checks,
                      "findings": [asdict(f) for f in self.findings],
                      "where": list(self.where), "where_after_best": list(self.where_after),
                      "baseline": self.baseline, "measurements": list(self.measurements),
                      "criteria": asdict(self.criteria), "timings_s": self.timings_s, "manifest": self.manifest,
                      "effect_library": library_rows()})


def build_problem(manifest: Manifest, data: tuple, nominal, weight_scale: str = "measurement",
                  map_in_optics: bool = Criteria.map_in_optics) -> tuple[Problem, FitOutcome]:
    """Forward models, the nominal (nuisance-only) fit, noise, n_eff and weights
    (``weight_scale``: :func:`.fitting.nominal_weights`); with ``map_in_optics`` the image
    models of a blank whose map is measured carry its departure (:func:`carry_map_departures`)."""
    sim = manifest.simulation
    kinds = {"surface": SurfaceForward, "line_profile": ProfileForward, "psf_image": PsfImageForward}
    fws = [kinds[d.measurement.kind](d, nominal, sim.cold_K, sim.warm_K, materials=sim.materials) for d in data]
    if map_in_optics:
        carry_map_departures(fws, nominal)
    prob = Problem(fws, {f.name: 1.0 for f in fws}, {f.name: float(f.n) for f in fws})
    nom = fit(prob, ())
    for f in fws:
        r = f.residual({}, nom.deltas_um.get(f.name, f.delta0_um))
        prob.n_eff[f.name] = residual_n_eff(f, r)
        prob.noise[f.name] = float(f.noise_known or f.estimate_noise(r))
    prob.weights.update(nominal_weights({f.name: f.kind for f in fws}, {f.name: f.n for f in fws}, nom.rss,
                                        prob.n_eff, prob.noise, weight_scale))
    return prob, fit(prob, ())


def carry_map_departures(forwards: list, nominal) -> tuple:
    """Give each spectrograph-image model the departure (:mod:`.map_departure`) of the map
    measured of its blank; returns the departures carried. With two maps of one blank the
    one with more points is used (they measure the same grating)."""
    maps = {}
    for f in forwards:
        if f.kind == "surface" and (f.blank not in maps or f.n > maps[f.blank].n):
            maps[f.blank] = f
    images = [f for f in forwards if f.kind != "surface" and f.blank in maps]
    carried = {}
    for f in images:
        if f.blank not in carried:
            carried[f.blank] = map_departure(maps[f.blank], nominal)
        if carried[f.blank] is not None:
            f.carry_departure(carried[f.blank])
    return tuple(d for d in carried.values() if d is not None)


def _data_notes(data, forward) -> dict:
    """How a measurement's samples came to be the diagnosed ones, for the report: ``gridding``
    (scattered points interpolated onto a grid, a point list put back on its grid; None for
    a file holding its grid or for a profile) and ``noise_from`` (where its noise comes from)."""
    counts = data.measurement.noise_counts
    default = ("the data" if not forward.noise_known else "manifest" if counts is None
               else f"manifest: noise_counts {counts:g} in the file's units")
    source = getattr(forward, "noise_from", default)
    cn = forward.correlated_noise
    if cn is not None:
        source += (f"; beside it a stated correlated noise of {cn.rms_rel:.3g} of the peak over "
                   f"{cn.length_um:g} µm (manifest)")
    return {"gridding": getattr(data, "gridding", None), "noise_from": source}


def summary_context(prob: Problem, cold_K: float) -> SummaryContext:
    """What :func:`.effects.physical_summary` needs from the data and the simulation."""
    quilt = next((f.quilt for f in prob.forwards if getattr(f, "quilt", None) is not None), None)
    fw = prob.forwards[0]
    return SummaryContext(cold_K=float(cold_K), blanks=tuple(dict.fromkeys(f.blank for f in prob.forwards)),
                          surface_radii_mm=tuple(f.radius_mm for f in prob.forwards if f.kind == "surface"),
                          quilt_rms_um=quilt.amplitudes_um() if quilt is not None else None,
                          quilt_weights=quilt.weights or None if quilt is not None else None,
                          warm_K=float(fw.warm_K), materials=tuple(fw.materials),
                          gratings=tuple(dict.fromkeys(f.m.grating for f in prob.forwards if f.kind == "line_profile")))


_N_EFF_PASSES = 2  # re-counts (Criteria.n_eff_from = "best_fit")
_N_EFF_RTOL = 0.1  # count changes smaller than this are not worth a re-ranking


def _with_heldout(prob: Problem, f: Finding, c: Criteria) -> Finding:
    """``f`` with its held-out shrink and ``overfit`` flag (``docs/diagnosis.md``, step 8)."""
    h, note = heldout_check(prob, f, c)
    over = h is not None and f.shrink_fraction > 0.05 and h < c.heldout_ratio * f.shrink_fraction
    return replace(f, heldout_shrink_fraction=h, heldout_note=note, overfit=bool(over))


def members_of(f: Finding) -> tuple:
    """The effects of ``f`` that :func:`member_explains` may put in its place: its own and
    the rescaling it adopted as a companion."""
    return tuple(f.effects) + rescaling_companions(f)


def member_explains(prob: Problem, findings: list, c: Criteria, heldout: bool) -> tuple[list, str]:
    """Occam for a pair on top that does not explain the gap: if one of its members alone
    does (significant, ``min_variance_explained`` of the excess where it acts, not overfit
    on held-out data), that member is the explanation and moves to the top; the pair
    stays listed below it. Returns (findings, note).

    Why: a pair's extra member can win the BIC by taking up part of a residual that
    nothing in the library explains in another measurement, and the pair is then judged
    over that measurement too. Campaign (profiles + map + focal-plane image, out-of-library
    trefoil discrepancy): a slit width explained ~0.92 of the profiles' excess, but
    collimator_wfe, pupil_shift or temperature beside it took up part of the trefoil in the
    image or map (delta BIC ~30 better) and the pair explained only 0.35-0.49 where it acts,
    so 6 of 22 slit-width cases ended ``unexplained``.

    A rescaling adopted as a companion (:func:`.ranking.rescaling_companions`) is a member
    too: a finding's share of the excess is measured from its companions' own fit, so beside
    a rescaling that already fits to the noise it explains 0 % of what is left, though the
    pair lowers the BIC further (measured on an outside lab's pixel-sampled J profiles of a
    1.15× quilt: ``collimator_wfe`` + amplitude ranked first, ΔBIC −301, explaining 0 %, while
    ``amplitude_scale`` alone, ΔBIC −276, read 1.151 and explained all of it; the case ended
    ``unexplained``). A background companion (``quilt_shape``, a bow, a plating gradient) is
    not: real blanks carry them beside whatever else is wrong."""
    pair = findings[0]
    members = members_of(pair)
    for i, f in enumerate(findings[1:], start=1):
        if len(f.effects) != 1 or f.effects[0] not in members or not explains(f, c):
            continue
        if heldout and f.heldout_shrink_fraction is None and not f.heldout_note:
            f = findings[i] = _with_heldout(prob, f, c)
        if f.overfit:
            continue
        beside = f" beside {' + '.join(pair.companions)}" if pair.companions else ""
        note = (f"{pair.effect}{beside} ranks higher (delta BIC {pair.delta_bic:.1f} against {f.delta_bic:.1f}) but explains "
                f"only {pair.excess_explained:.2f} of the excess over noise where it acts; {f.effect} alone explains "
                f"{f.excess_explained:.2f} where it acts and is the explanation (Occam)")
        return [f] + findings[:i] + findings[i + 1:], note
    return findings, ""


def _where(prob: Problem, fo: FitOutcome) -> list[dict]:
    out = []
    wr = {}
    for f in prob.forwards:
        d = fo.deltas_um.get(f.name, f.delta0_um)
        r = f.residual(fo.parameters, d)
        wr[f.name] = prob.weights[f.name] ** 2 * float(np.sum(r**2))
        if f.kind == "surface":
            out += surface_parts(f.name, f.x, f.y, r, f.radius_mm, prob.noise[f.name])
        elif f.kind == "psf_image":
            out += psf_image_parts(f.name, f.x, f.y, r, d)
        else:
            sp = satellite_spacing_um(f.m.grating, f.m.wavelength_um, f.m.order)
            out += profile_parts(f.name, f.x, r, d, sp)
    if len(prob.forwards) > 1:
        out += measurement_parts(wr)
    return out


@dataclass(frozen=True, eq=False)
class _Ranking:
    """The problem and the ranked fits of one pass of :func:`diagnose` (the error model's and
    the counts' re-rankings done)."""

    prob: Problem
    nom: FitOutcome
    findings: list
    fits: dict
    joint_fits: dict
    errors: dict
    model: str
    base_forwards: tuple  # one per measurement, in the manifest's order


def _ranked(manifest: Manifest, data: tuple, nominal, criteria: Criteria, cands, map_in_optics: bool,
            warm: tuple = ()) -> _Ranking:
    """Build the problem (the image models carrying a measured map's departure where
    ``map_in_optics``), fit and rank the candidate effects ``cands``, re-ranking under the
    error model (``docs/diagnosis.md``, steps 1-5); ``warm``: fits of the same model made
    before, restarted from (:func:`.ranking.rank`), as is each re-weighted pass from the
    pass before it."""
    prob, nom = build_problem(manifest, data, nominal, criteria.weight_scale, map_in_optics)
    base_forwards = tuple(prob.forwards)  # one per measurement, in the manifest's order
    kinds = {f.kind for f in prob.forwards}
    memo, errors = {}, {}
    model = model_for_kinds(criteria.error_model, kinds)
    if model == "two_part":
        base_prob = prob
        errors = measure_errors(base_prob, nom)  # first pass: the nominal residual (signal counts as mismatch)
        prob = two_part_problem(base_prob, errors)
        nom = fit(prob, ())
    findings, fits, joint_fits = rank(prob, nom, cands, criteria, memo, warm)
    if model == "two_part":
        for _ in range(_N_EFF_PASSES):
            errs = measure_errors(base_prob, fits[error_source(findings).effect])
            new = two_part_problem(base_prob, errs)
            if weights_settled(prob, new, _N_EFF_RTOL):
                break
            # New weights: every fit is redone, and each restarts from the previous pass's fit
            # of a model it holds where it would end above it: the per-measurement residuals
            # of a fit do not depend on the weights, so that fit is a point of this objective
            # too, and a fit from scratch under new weights can land in a worse basin.
            before = tuple(fits.values()) + tuple(fo for tried in joint_fits.values() for _, fo in tried)
            prob, errors, memo = new, errs, {}
            nom = fit(prob, ())
            findings, fits, joint_fits = rank(prob, nom, cands, criteria, memo, warm + before)
    elif criteria.n_eff_from == "best_fit":
        for _ in range(_N_EFF_PASSES):
            count = post_fit_n_eff(prob, fits[findings[0].effect])
            old = prob.n_count or prob.n_eff
            if all(abs(count[m] / old[m] - 1.0) <= _N_EFF_RTOL for m in count):
                break
            prob = recounted(prob, count)
            nom = recount(prob, nom)
            findings, fits, joint_fits = rank(prob, nom, cands, criteria, memo, warm)
    return _Ranking(prob, nom, findings, fits, joint_fits, errors, model, base_forwards)


def _couplings(prob: Problem, nominal: FitOutcome, after: FitOutcome) -> dict:
    """Each line profile's and detector PSF image's inter-pixel coupling (fraction to each x
    neighbour; an image's to each of four) with the nominal (``"nominal"``) and with the fit
    the verdict rests on (``"after"``: the explaining finding's, else the nominal's), fitted
    unless the manifest states it (``"stated"``: the measurements whose coupling was held at
    the manifest's value): a detector's measured coupling can be set beside the fitted ones."""
    out = {"nominal": {}, "after": {}, "stated": {}}
    for f in prob.forwards:
        if getattr(f, "stated_coupling", None) is not None:
            out["stated"][f.name] = float(f.stated_coupling)
        if f.kind == "line_profile" or (f.kind == "psf_image" and f.pixel_um > 0):
            for key, fo in (("nominal", nominal), ("after", after)):
                out[key][f.name] = float(f.coupling(fo.parameters, fo.deltas_um.get(f.name, f.delta0_um)))
    return out


def diagnose(manifest_path_or_obj, *, effects: tuple | None = None, criteria: Criteria = Criteria(),
             cache_dir=None, heldout: bool = True, nominal=None, keep_curves: bool = True) -> Diagnosis:
    """Diagnose the sim-to-real gap of a manifest's measurements.

    Parameters
    ----------
    manifest_path_or_obj : path, dict or Manifest
        The measurement manifest (:mod:`.manifest`).
    effects : tuple of str, optional
        Library effects to try (default: all applicable).
    criteria : Criteria
        Decision thresholds.
    cache_dir : path, optional
        Disk cache for the nominal FEA map.
    heldout : bool
        Run the held-out validation of the ``criteria.heldout_top`` best findings.
    nominal : SagMap, optional
        Nominal map at the simulation's cold_K (skips the FEA; used by the campaign).

    Returns
    -------
    Diagnosis
    """
    t = {"start": time.perf_counter()}
    manifest = load_manifest(manifest_path_or_obj)
    data = load_data(manifest)
    if nominal is None:
        nominal = nominal_sag_map(manifest.simulation, cache_dir)
    check_measurements(manifest, data, nominal)
    t["load_s"] = time.perf_counter() - t["start"]
    kinds = {m.kind for m in manifest.measurements}
    cands = applicable_effects(kinds, effects)
    r = _ranked(manifest, data, nominal, criteria, cands, criteria.map_in_optics)
    departures = {f.departure.measurement: f.departure.summary() for f in r.base_forwards
                  if f.kind != "surface" and f.departure is not None}
    choice = None
    if departures and r.findings:  # do the images hold the map's departure?
        choice = departure_choice(r.prob, r.findings[0], r.fits[r.findings[0].effect], criteria)
        if not choice.carried:
            r = _ranked(manifest, data, nominal, criteria, cands, False, warm=(choice.without,))
    prob, nom, findings, fits, joint_fits, errors, model = (r.prob, r.nom, r.findings, r.fits, r.joint_fits,
                                                            r.errors, r.model)
    base_forwards = r.base_forwards
    t["fit_s"] = time.perf_counter() - t["start"] - t["load_s"]
    priors = parameters_of(tuple(e.name for e in cands), prob.forwards)
    half = {q.name: 0.5 * q.width for q in priors}
    bounds = {q.name: (q.lo, q.hi) for q in priors}

    def at_bound(f):
        own = own_parameters(f)
        return at_prior_bound({q: v for q, v in f.parameters.items() if q in own}, bounds)

    findings = [replace(f, unconstrained=unconstrained(f, half), at_bound=at_bound(f),
                        remaining_gap=tuple(g["measurement"] for g in gaps(prob, fits[f.effect], criteria)))
                for f in findings]
    findings = degeneracies(findings, fits, prob, criteria)
    findings = amplitude_degeneracies(prob, findings)  # shape alone or amplitude too
    findings = [replace(f, sign_degenerate=sign_degeneracies(prob, f, fits[f.effect], criteria,
                                                             joint_fits.get(f.effect)))
                if len(f.effects) == 1 and f.significant else f for f in findings]
    t0 = time.perf_counter()
    for i, f in enumerate(findings[:max(criteria.heldout_top, 1)]):
        if f.significant:  # pairs too: a pair can take up an unidentifiable effect as well
            ab, eff = absorbed(prob, f, fits[f.effect], criteria, kinds)
            findings[i] = replace(f, absorbs=ab, degenerate_with=tuple(dict.fromkeys(f.degenerate_with + eff)))
    t["absorb_s"] = time.perf_counter() - t0
    if heldout:
        for i, f in enumerate(findings[:criteria.heldout_top]):
            findings[i] = _with_heldout(prob, f, criteria)
    t["heldout_s"] = time.perf_counter() - t["start"] - t["load_s"] - t["fit_s"] - t["absorb_s"]
    ctx = summary_context(prob, manifest.simulation.cold_K)
    findings = [replace(f, parameter_units=parameter_units(f.parameters),
                        summary=physical_summary(all_effects(f), f.parameters, ctx)) for f in findings]
    gap = has_gap(prob, nom, criteria)
    note = ""
    if gap and findings and len(members_of(findings[0])) > 1 and not explains(findings[0], criteria):
        findings, note = member_explains(prob, findings, criteria, heldout)
    best = findings[0] if findings else None
    done = {}
    if gap and checks(best) and explains(best, criteria):  # is the pupil aberration the collimator's?
        pupil = other_orders_check(prob, best, fits[best.effect], criteria)
        best = findings[0] = with_check(best, pupil)
        note = "; ".join(n for n in (note, pupil.note if pupil.ambiguous else "") if n)
        done["pupil_orders"] = pupil.summary()
    if gap and wings_alternative.checks(prob, best) and explains(best, criteria):
        side = wings_alternative.wings_check(prob, best, fits[best.effect], criteria)  # detector side's light?
        best = findings[0] = wings_alternative.with_check(best, side)
        note = "; ".join(n for n in (note, side.note) if n)
        done["wings"] = side.summary()
    if not gap:
        verdict = "no_gap"
    elif best and explains(best, criteria):  # the checks' outcomes are in best (verdict.failed_tests)
        verdict = "explained"
    else:
        verdict = "unexplained"
    after = fits[best.effect] if best is not None and verdict == "explained" else nom
    alone = ()
    if gap and best is not None and best.significant and best.remaining_gap:
        alone = fits_alone(prob, best, fits[best.effect], criteria)
    unexplained_in = tuple(gaps(prob, after, criteria)) if gap else ()
    where = _where(prob, nom)
    where_after = tuple(_where(prob, fits[best.effect])) if best else ()
    baseline = {"bic": nom.bic(prob.weights), "offset_shift_um": nom.deltas_um,
                "noise": dict(prob.noise), "n": dict(nom.n), "n_eff": dict(prob.n_eff),
                "n_count": dict(prob.n_count or prob.n_eff), "n_eff_from": criteria.n_eff_from,
                "error_model": criteria.error_model, "error_model_used": model, "errors": errors_summary(errors),
                "weights": dict(prob.weights), "nominal_map": nominal.label,
                "map_departures": list(departures.values()),
                "map_departure_choice": choice.summary() if choice is not None else None,
                "interpixel_coupling": _couplings(prob, nom, after)}
    ms = tuple({"name": m.name, "kind": m.kind, "file": str(m.file), "blank": m.blank, "grating": m.grating,
                "wavelength_um": m.wavelength_um, "pixel_scale_mas": m.pixel_scale_mas,
                "temperature_K": m.temperature_K, "read": read_summary(d), **_data_notes(d, f)}
               for m, d, f in zip(manifest.measurements, data, base_forwards))
    curves = {}
    if keep_curves:
        curves = {"nominal": predictions(prob, nom), "data": {f.name: (f.x, getattr(f, "y", None), f.data) for f in prob.forwards},
                  "kinds": {f.name: f.kind for f in prob.forwards}}
        if best:
            curves["best"] = predictions(prob, fits[best.effect])
    t["total_s"] = time.perf_counter() - t.pop("start")
    return Diagnosis(verdict, tuple(findings), tuple(where), where_after, baseline, ms, criteria,
                     {k: round(v, 3) for k, v in t.items()}, manifest.source, curves, unexplained_in, note, alone,
                     done)
