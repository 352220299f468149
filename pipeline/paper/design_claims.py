"""The paper's design conclusions (section 6) on re-solved FEA blanks.

Acceptance rules (fixed before the model numbers were looked at):

* AlSi40 blank and a solid (un-lightweighted) Al blank, 200 µm / 50 %: the P/V_center and
  the quilt's 21 mm fundamental both below 10 % of the paper's blank ``reproduced``,
  below 30 % ``partial``.
* Lightweighting period doubled, J 1.25 µm at 100 and 250 mas, judged like the paper
  (orders inside the slit image, flux outside the slit image) and by R: first the same
  deformation at twice the period (the 200/50 FEA map stretched ×2), then the re-solved
  42 × 36 mm blank. Flux outside the slit image lower *and* FWHM-R higher than the paper's
  blank at both scales ``reproduced``; one of the two at both scales ``partial``.
"""

from __future__ import annotations

from optics.fitting import fit_fourier
from optics.metrics import profile_metrics
from optics.sagmap import SagMap
from pipeline.paper.claim import Claim, grade
from pipeline.paper.fea_claims import PaperFEA
from pipeline.paper.optics_claims import ProfileBook, satellites

__all__ = ["design_claims", "stretched"]

QUILT_FRACTION = (0.10, 0.30)


def stretched(sag: SagMap, factor: float) -> SagMap:
    """The same sag pattern with every period ``factor`` times longer, on the same grid."""
    src = SagMap(sag.x_mm * factor, sag.y_mm * factor, sag.sag_um, f"{sag.label} stretched x{factor:g}")
    return src.resampled(sag.x_mm, sag.y_mm)


def _fundamental(sag: SagMap) -> float:
    return float(fit_fourier(sag, harmonics=3, aperture="center").component(1, 0)[0])


def _no_quilt(fea: PaperFEA) -> Claim:
    ref = fea.maps[("all", 200.0, 0.5)]
    pv0, f0 = ref.pv_um("center"), _fundamental(ref)
    vals = {k: (fea.extra[k].pv_um("center") / pv0, abs(_fundamental(fea.extra[k])) / abs(f0))
            for k in ("alsi40", "solid")}
    worst = max(max(v) for v in vals.values())
    st = grade(worst, (0.0, QUILT_FRACTION[0]), (0.0, QUILT_FRACTION[1]))
    return Claim("no_quilt_blanks", "An AlSi40 blank or a blank without lightweighting removes the quilt",
                 "Sec. 6", "quilt removed / bimetallic bending much reduced",
                 "; ".join(f"{k}: P/V_center {100 * a:.1f} %, 21 mm fundamental {100 * b:.1f} % of the Al 6061 "
                           f"blank's" for k, (a, b) in vals.items()), st,
                 "200 µm / 50 %, re-solved FEA blanks; rule: both below 10 % reproduced, 30 % partial", "fea")


def _period_claim(cid, text, book: ProfileBook, name: str, sat_um: float) -> Claim:
    better_flux, better_r, parts = [], [], []
    for mas in (100, 250):
        a = profile_metrics(book.get("200/50", "J", 1.25, mas))
        b = profile_metrics(book.get(name, "J", 1.25, mas))
        better_flux.append(b["outside_slit_fraction"] < a["outside_slit_fraction"])
        better_r.append(b["resolving_power"] > a["resolving_power"])
        parts.append(f"{mas} mas: outside slit {100 * a['outside_slit_fraction']:.0f} -> "
                     f"{100 * b['outside_slit_fraction']:.0f} %, R {a['resolving_power']:.0f} -> "
                     f"{b['resolving_power']:.0f}")
    st = ("reproduced" if all(better_flux) and all(better_r)
          else "partial" if all(better_flux) or all(better_r) else "contradicted")
    return Claim(cid, text, "Sec. 6", "first orders inside the slit image, profiles significantly improved",
                 f"first satellite at {sat_um:.1f} µm (slit image half-width 13.5 µm); " + "; ".join(parts), st,
                 "J 1.25 µm vs the paper's 200/50 blank; rule: less flux outside the slit image and higher "
                 "FWHM-R at 100 and 250 mas reproduced, one of the two partial", "fea")


def design_claims(fea: PaperFEA, book: ProfileBook) -> list[Claim]:
    """AlSi40 / solid blank, and the doubled lightweighting period (two rows)."""
    book.sags.setdefault("200/50 stretched x2", stretched(fea.maps[("all", 200.0, 0.5)], 2.0))
    book.sags.setdefault("period doubled", fea.extra["period_doubled"])
    s1 = satellites("J", 1.25, book.sags["200/50 stretched x2"])[0]
    s2 = satellites("J", 1.25, book.sags["period doubled"])[0]
    pv2 = fea.extra["period_doubled"].pv_um("center")
    return [_no_quilt(fea),
            _period_claim("period_doubled_same_amplitude", "Doubled lightweighting period improves the profiles: "
                          "the same deformation at twice the period", book, "200/50 stretched x2", s1),
            _period_claim("period_doubled_fea", "Doubled lightweighting period improves the profiles: the re-solved "
                          f"42 x 36 mm blank (P/V_center {pv2:.2f} µm)", book, "period doubled", s2)]
