"""Fitting combinations of library effects and ranking them: singles, pairs among the best
singles, companions refitted beside the best findings, ranked by BIC (``docs/diagnosis.md``,
steps 2, 3 and 5)."""

from __future__ import annotations

import itertools
import math
from dataclasses import replace

from .criteria import Criteria
from .effects import LIBRARY, effect_parameters
from .finding import Finding
from .fitting import FitOutcome, Problem, fit
from .gap import excesses, noise_per_dof, recount

__all__ = ["parameters_of", "in_library_order", "fit_effects", "rank", "pair_singles", "pairs_to_fit", "predictions",
           "mismatch_errors", "best_rescaling", "rescaling_companions", "rank_key",
           "restart_from_nested", "NESTED_RTOL", "model_of", "one_model_each"]


def in_library_order(effects) -> tuple:
    """Library effects ``effects`` in the library's order: a combination's members as the
    diagnosis names it (``"+".join`` of them is the finding's ``effect``)."""
    order = list(LIBRARY)
    return tuple(sorted(effects, key=order.index))


def parameters_of(names, forwards) -> tuple:
    """The concrete parameters of library effects ``names`` for the data's forward models
    (a per-blank effect gets one copy per blank seen by a measurement kind it changes)."""
    kinds = {f.kind for f in forwards}
    return tuple(q for n in names for q in effect_parameters(
        LIBRARY[n], tuple(dict.fromkeys(f.blank for f in forwards if f.kind in LIBRARY[n].kinds)), kinds))


#: Relative excess of a joint fit's objective over the fit it nests beyond which the joint fit
#: is restarted from the nested one (:func:`fit_effects`): far above the local fit's own
#: tolerance, far below any difference the score can see.
NESTED_RTOL = 1e-6


def fit_effects(prob: Problem, nom: FitOutcome, names: tuple, criteria: Criteria, start: dict | None = None,
                memo: dict | None = None, regrid: tuple = (), nested: tuple = (), warm: tuple = ()):
    """Fit one combination of library effects; returns (Finding, FitOutcome). ``memo``:
    fits by (names, start, regrid) to reuse (valid while the weights are the same);
    ``regrid``: parameters grid-searched beside the warm ``start`` (:func:`.fitting.fit`);
    ``nested``: fits of combinations this one contains (:func:`restart_from_nested`);
    ``warm``: fits of the same data made elsewhere (:func:`rank`), used as ``nested`` where
    their parameters are among this combination's."""
    params = parameters_of(names, prob.forwards)
    names_here = {q.name for q in params}
    nested = tuple(nested) + tuple(w for w in warm if w.parameters and set(w.parameters) <= names_here)
    key = (tuple(names), tuple(sorted((start or {}).items())), tuple(regrid))
    if memo is not None and key in memo:
        fo = recount(prob, memo[key])
    else:
        fo = restart_from_nested(prob, params, fit(prob, params, start=start, regrid=tuple(regrid)), nested)
        if memo is not None:
            memo[key] = fo
    before, after, ratio, per = _stats(prob, nom, fo)
    dbic = fo.bic(prob.weights) - nom.bic(prob.weights)
    ve = 1 - ratio**2
    f = Finding("+".join(names), tuple(names), fo.parameters, fo.errors, fo.bic(prob.weights), dbic, before, after, 1 - ratio, ve,
                per_measurement=per, significant=bool(dbic <= -criteria.min_delta_bic), **excesses(prob, nom, fo, names))
    return f, fo


def restart_from_nested(prob: Problem, params: tuple, fo: FitOutcome, nested: tuple) -> FitOutcome:
    """``fo``, the fit of ``params``, or where its objective (``FitOutcome.weighted_rss``) ends
    above that of the best of the ``nested`` fits (of combinations whose parameters are among
    ``params``) by more than :data:`NESTED_RTOL`, the lower-objective of it and a fit started
    from that nested fit (its parameters and position nuisances) with the other parameters
    at their null values.

    Why: a joint fit holds the fit it nests (its other parameters at their nulls), so it can
    never be worse at its optimum, but a local fit from a combined start can end in a worse
    basin. Measured on a collimator error on a quilt 1.127 x the simulation's (profiles and a
    point image): collimator + amplitude scale from the collimator's fit and the amplitude
    single's 1.194 ended at delta BIC -105.8, the collimator alone at -243.6
    (``benchmarks/results_rescaling_companion.md``). Judged on the objective, not the BIC:
    the BIC carries the extra parameters' penalty, so a joint fit at its optimum may score
    above the fit it nests (``benchmarks/results_pair_restart.md``)."""
    w = prob.weights
    inner = min(nested, key=lambda o: o.weighted_rss(w), default=None)
    if inner is None or fo.weighted_rss(w) <= inner.weighted_rss(w) * (1.0 + NESTED_RTOL):
        return fo
    again = fit(prob, params, start={q.name: inner.parameters.get(q.name, q.null) for q in params},
                start_deltas_um=inner.deltas_um)
    return again if again.weighted_rss(w) < fo.weighted_rss(w) else fo


def rank(prob: Problem, nom: FitOutcome, cands, criteria: Criteria, memo: dict,
         warm: tuple = ()) -> tuple[list, dict, dict]:
    """Steps 2, 3 and 5 of ``docs/diagnosis.md`` (fit singles, pairs, companions; rank):
    (findings best first, fits, joint fits). ``memo`` keeps every fit by (effects, start):
    a re-count changes the scores, not the fits. ``warm``: fits of these data's measurements
    made before (:class:`.departure_choice.DepartureChoice`'s refit without the map's
    departure); every fit whose parameters hold one's is restarted from it where it ends
    above it (:func:`restart_from_nested`), so the ranking never reads a model at a worse
    optimum than one already found."""
    fits, findings = {}, []
    for e in cands:
        f, fo = fit_effects(prob, nom, (e.name,), criteria, memo=memo, warm=warm)
        findings.append(f)
        fits[f.effect] = fo
    for a, b in pairs_to_fit(findings, criteria.pair_from, criteria.pair_forward, criteria.pair_second):
        names = in_library_order(a.effects + b.effects)
        # With the forward step, b, the weaker single, is also grid-searched beside a's fit:
        # alone it may have taken up what a explains and sit in the wrong basin
        # (:func:`.fitting.fit`). Both are off by default, as measured together.
        regrid = tuple(b.parameters) if criteria.pair_forward else ()
        f, fo = fit_effects(prob, nom, names, criteria, start={**a.parameters, **b.parameters}, memo=memo,
                            regrid=regrid, nested=(fits[a.effect], fits[b.effect]), warm=warm)
        findings.append(f)
        fits[f.effect] = fo
    findings.sort(key=lambda f: rank_key(f, criteria))
    joint_fits = {}
    findings = _with_companions(prob, nom, findings, fits, cands, criteria, joint_fits, memo, warm)
    findings.sort(key=lambda f: rank_key(f, criteria))
    return one_model_each(findings), fits, joint_fits


def model_of(f: Finding) -> frozenset:
    """The effects ``f`` fits: its own and its companions'."""
    return frozenset(f.effects) | frozenset(f.companions)


def one_model_each(findings) -> list:
    """``findings`` (ranked best first, order kept) with each model (:func:`model_of`) once:
    of several findings with one model, the one with the fewest effects of its own (the
    single with its companions; the better-ranked among equals).

    Why: a single that adopts the rescaling companion (step 5) is the same model as the pair
    of that rescaling and the single (step 2), fitted from another start; listed twice, each
    is found degenerate with the other, and a reader (and the campaign's strict score) takes
    the pair as naming its member on its own. The single is kept, not the pair: what reads
    findings by their labels (the two-part error model's source, ``error_model.error_source``;
    the Occam check of a pair on top) then sees the finding it saw without the pair (a map
    with oblique astigmatism under the two-part model was left ``unexplained`` when the pair
    was kept: the error source moved to the temperature alone)."""
    keep = {}
    for i, f in enumerate(findings):
        m = model_of(f)
        if m not in keep or len(f.effects) < len(findings[keep[m]].effects):
            keep[m] = i
    chosen = set(keep.values())
    return [f for i, f in enumerate(findings) if i in chosen]


def pair_singles(findings, n: int) -> list:
    """The ``n`` best significant, not background-only singles of ``findings`` (lowest
    score first) among which pairs are formed, keeping only the best of the rescaling
    effects (``Effect.rescales``).

    Why: temperature and amplitude_scale are exactly degenerate on one blank (the
    per-blank scales absorb any common temperature factor, exactly for one cold
    temperature per blank), so their pair is redundant and is never formed; when both
    were among the best singles they would take two of the slots and shut a real pair
    out. The other one still competes as a single."""
    out, rescaling = [], False
    for f in sorted((f for f in findings if f.significant and not _background_only(f)), key=lambda f: f.score):
        r = _rescales(f)
        if r and rescaling:
            continue
        rescaling |= r
        out.append(f)
    return out[:n]


def pairs_to_fit(findings, n: int, forward: bool = False, second: str = "significant") -> list:
    """The pairs of singles to fit, better single first: every pair among the ``n`` best
    of :func:`pair_singles`, and with ``forward`` the best one with each further one (none
    for ``n < 2``): each further significant one, or with ``second = "improving"`` each
    further single that lowers the BIC at all (``Criteria.pair_second``), best first.

    Why the best with every other: a second effect whose signature is small beside the
    first's ranks low on its own (alone it can only take up part of what the first
    explains), and a pair formed only among the best singles never meets it (measured: the
    paper's J scenario, a 1.5x amplitude and a 4 mm pupil shift, under the two-part
    weights: pupil shift alone fifth of the singles, so the pair was never fitted). This
    is one forward-selection step from the best single (``Criteria.pair_forward``).

    The step never adds a rescaling (``Effect.rescales``): a rescaling that ranks below the
    ``n`` best singles explains almost nothing of the gap alone, yet beside the right effect
    it takes up the part of the quilt's mismatch that lies along the nominal quilt
    (measured on single-effect line-profile truths: a pupil shift named amplitude + pupil
    shift twice and a slit width temperature + slit width, the rescaling alone 9th and
    10th of the singles, explaining 1-7 % of the excess; ``benchmarks/results_pairs.md``).
    A rescaling among the ``n`` best still pairs."""
    if n < 2:
        return []
    eligible = pair_singles(findings, len(findings))
    pairs = list(itertools.combinations(eligible[:n], 2))
    if not forward or not eligible:
        return pairs
    if second == "significant":
        further = eligible[n:]
    else:
        best, formed = eligible[0], {frozenset(a.effects + b.effects) for a, b in pairs}
        further = sorted((f for f in findings if len(f.effects) == 1 and f is not best and f.delta_bic < 0
                          and not _background_only(f) and frozenset(best.effects + f.effects) not in formed),
                         key=lambda f: f.score)
    return pairs + [(eligible[0], b) for b in further if not _rescales(b)]


def rescaling_companions(f: Finding) -> tuple:
    """The companions of ``f`` that rescale the deformation (``Effect.rescales``): the quilt's
    amplitude adopted beside it (``Criteria.rescaling_companion``)."""
    return tuple(n for n in f.companions if LIBRARY[n].rescales)


def _rescales(f: Finding) -> bool:
    """Whether one of ``f``'s effects rescales the deformation (``Effect.rescales``)."""
    return any(LIBRARY[e].rescales for e in f.effects)


def _with_companions(prob: Problem, nom: FitOutcome, findings: list, fits: dict, cands, c: Criteria,
                     joint_fits: dict | None = None, memo: dict | None = None, warm: tuple = ()) -> list:
    """Refit the ``c.companion_top`` best findings (and every significant single where a
    companion alone is significant) jointly with the companion effects, and, beside a finding
    that does not rescale, with the best rescaling (:func:`best_rescaling`, with
    ``c.rescaling_companion``) (``docs/diagnosis.md``, step 5); ``findings`` ranked best
    first, ``fits`` updated in place;
    every joint fit (adopted or not) is appended to ``joint_fits[effect]`` as
    ``(names, fit)`` for the sign test.

    Each companion is tried on its own beside the finding, and all of them together when
    more than one lowered the BIC: the cheapest joint model the data support is adopted
    (a plating gradient and a bow are independent claims; making every finding pay for
    both would hide either one on a smooth map, where the effective sample count is small)."""
    comp = tuple(e.name for e in cands if e.companion)
    resc = best_rescaling(findings) if c.rescaling_companion else None
    if not (comp or resc) or c.companion_top <= 0:
        return findings
    joint_fits = {} if joint_fits is None else joint_fits
    w = prob.weights
    # A companion the data see on its own leaks into every other single's score (each
    # mimics some of its signature), so the first ranking no longer says which effect
    # explains what the companion leaves: then every single is refitted too (a slit-width
    # campaign case, map + PSF image: slit_width ranked below pupil_shift and
    # collimator_wfe, which took up part of the bow, and was never refitted with it).
    # Significant alone or not: the companion's signature can also pull a single the wrong
    # way (line profiles of a 50 K warmer blank whose quilt has fewer cross terms and
    # harmonics than the nominal's: temperature alone -18 K and not significant, with
    # quilt_shape beside it +36 K and the best finding by a delta BIC of 100).
    seen = any(f.significant and set(f.effects) <= set(comp) for f in findings)
    out, done = list(findings), 0
    for i, f in enumerate(findings):
        if set(f.effects) & set(comp):
            continue
        if done >= c.companion_top and not (seen and len(f.effects) == 1):
            continue
        # the quilt's amplitude is never exactly the simulation's either: the best rescaling
        # is tried beside every finding that does not rescale itself
        own_comp = comp + ((resc,) if resc and not _rescales(f) else ())
        if not own_comp:
            continue
        done += 1
        tried = []  # (joint finding, fit, companion subset)
        for sub in [(n,) for n in own_comp]:
            start = {**f.parameters, **(fits[sub[0]].parameters if sub[0] in fits else {})}
            tried.append((*fit_effects(prob, nom, tuple(f.effects) + sub, c, start=start, memo=memo,
                                       nested=(fits[f.effect],), warm=warm), sub))
        better = [t for t in tried if t[0].score < f.score]  # single companions, in library order
        helping = tuple(sub[0] for _, _, sub in better)
        for size in range(2, len(helping) + 1):
            for sub in itertools.combinations(helping, size):
                start = {k: v for t in better if set(t[2]) <= set(sub) for k, v in t[0].parameters.items()}
                inner = (fits[f.effect],) + tuple(o for _, o, s in tried if set(s) < set(sub))
                tried.append((*fit_effects(prob, nom, tuple(f.effects) + sub, c, start=start, memo=memo,
                                           nested=inner, warm=warm), sub))
        joint_fits.setdefault(f.effect, []).extend((tuple(f.effects) + sub, fo) for _, fo, sub in tried)
        joint, fo, sub = _supported_companions(tried, c)
        if not joint.score <= f.score - c.companion_bic:
            out[i] = replace(f, uncertainties=mismatch_errors(f, [j for j, _, s in tried if len(s) == 1],
                                                              f.parameters))
            continue
        joint = replace(joint, uncertainties=mismatch_errors(joint, [j for j, _, _ in tried if j is not joint],
                                                               f.parameters))
        # Evidence and excess for the finding itself: measured from the companions alone
        # (the best of each alone and the adopted set alone).
        key = "+".join(sub)
        if key not in fits:
            fits[key] = fit_effects(prob, nom, sub, c, start=fo.parameters, memo=memo,
                                    nested=tuple(fits[n] for n in sub if n in fits), warm=warm)[1]
        ref = [fits[n] for n in set(own_comp) | {key} if n in fits]
        base = min(ref, key=lambda o: o.bic(w), default=nom)
        base_bic = min(base.bic(w), nom.bic(w))
        sig = bool(joint.score - base_bic <= -c.min_delta_bic)
        out[i] = replace(joint, effect=f.effect, effects=f.effects, companions=sub, significant=sig,
                         **excesses(prob, base, fo, f.effects))
        fits[f.effect] = fo
    return out


def best_rescaling(findings) -> str | None:
    """The rescaling effect (``Effect.rescales``) whose single among ``findings`` has the
    lowest BIC, if it lowers the BIC at all (``Criteria.rescaling_companion``); else None."""
    singles = [f for f in findings if len(f.effects) == 1 and not f.companions and _rescales(f) and f.delta_bic < 0]
    return min(singles, key=lambda f: f.score).effect if singles else None


def _supported_companions(tried: list, c: Criteria) -> tuple:
    """The joint fit ``(finding, fit, companion set)`` to adopt among ``tried``: the best
    single companion, replaced by a larger set only where that set beats the best smaller
    one by ``c.companion_bic`` (each companion adopted must be supported by the data, as
    the first one must beat the finding alone)."""
    best = None
    for size in sorted({len(t[2]) for t in tried}):
        top = min((t for t in tried if len(t[2]) == size), key=lambda t: t[0].score)
        if best is None or top[0].score <= best[0].score - c.companion_bic:
            best = top
    return best


def _background_only(f: Finding) -> bool:
    """Whether every effect of ``f`` is a ``background`` effect (:mod:`.effects`)."""
    return all(LIBRARY[e].background for e in f.effects)


def mismatch_errors(chosen: Finding, alternatives: list, own) -> dict:
    """Uncertainties of ``chosen``'s ``own`` parameters with the model-choice term: the
    largest move of each parameter to an alternative model the data do not rule out,
    added in quadrature.

    Alternatives: the finding refitted with each companion it did not adopt (a plating
    gradient or a bow is present at some level on every real blank, and the data not
    supporting it does not exclude a small one) — but not the finding without the
    companion it adopted (ruled out by ``companion_bic``). Mismatch absorbed *into* a
    parameter is invisible to any residual-based estimate; this is the part of it that
    can be measured. Measured alternative: BIC-weighted model averaging of the same
    fits is narrower and covered the truth less often in the campaign (81 % within 2
    sigma against 84 %: the BIC's weights are over-confident with correlated residuals),
    so the conservative rule stays."""
    out = dict(chosen.uncertainties)
    for q in own:
        v = chosen.parameters[q]
        moves = [abs(m.parameters[q] - v) for m in alternatives if q in m.parameters]
        if moves and q in out:
            out[q] = float(math.hypot(out[q], max(moves)))
    return out


def rank_key(f: Finding, c: Criteria) -> float:
    """The score ``f`` is ranked by: its BIC plus ``pair_extra_bic`` per claimed change beyond
    the first (an effect, or a rescaling companion)."""
    # a rescaling companion is a second claimed change, so it ranks as a pair member does
    claims = len(f.effects) + len(rescaling_companions(f))
    return f.score + (c.pair_extra_bic * (claims - 1))


def predictions(prob: Problem, fo: FitOutcome) -> dict:
    """Each measurement's fitted curve (or map, or image) under ``fo``, nuisances included."""
    return {f.name: f.fitted(fo.parameters, fo.deltas_um.get(f.name, f.delta0_um)) if f.n_shift
            else f.fitted(fo.parameters) for f in prob.forwards}


def _stats(prob: Problem, nom: FitOutcome, fo: FitOutcome):
    wb = nom.weighted_rss(prob.weights)
    wa = fo.weighted_rss(prob.weights)
    ratio = math.sqrt(wa / wb) if wb > 0 else 1.0
    per = []
    for f in prob.forwards:
        m, sig = f.name, noise_per_dof(prob, f)
        before, after = math.sqrt(nom.rss[m] / nom.n[m]), math.sqrt(fo.rss[m] / fo.n[m])
        per.append({"measurement": m, "unit": "um" if f.kind == "surface" else "fraction_of_peak",
                    "rms_before": before, "rms_after": after, "noise": sig,
                    "chi2_red_before": (before / sig) ** 2 if sig > 0 else None,
                    "chi2_red_after": (after / sig) ** 2 if sig > 0 else None})
    units = {p["unit"] for p in per}
    if len(units) == 1:  # one unit: overall RMS in that unit
        before = math.sqrt(sum(nom.rss.values()) / sum(nom.n.values()))
        after = before * ratio
    else:
        before, after = 1.0, ratio
    return before, after, ratio, tuple(per)
