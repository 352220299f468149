"""The injection-recovery campaign's random truth of each library effect.

Each function draws the parameters of one effect as the campaign injects it, ``draw(rng,
kind, blank) -> {parameter: value}`` for a case whose measurement kind is ``kind``
("surface" or "line_profile") on grating blank ``blank``, with the parameter names of
:mod:`.effects` (a per-blank parameter named for ``blank``). :data:`.effects.LIBRARY`
wires each effect to its draw (``Effect.draw_truth``); :data:`DRAWS` lists them by effect
name for the independent truth (:mod:`.truth`, which does not import the library). The
campaign's truth generators (:mod:`.campaign`, :mod:`.truth`) apply the drawn values.

Values lie inside each parameter's prior, mostly away from its null (ratios below or above
1, offsets of either sign), so that a case asks whether a clear discrepancy is found rather
than where the detection limit lies. The random numbers are consumed in the order written here: a
campaign case is seeded by ``(seed, index)``, and changing the order changes every case
that follows in it.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["DRAWS", "signed_uniform", "amplitude_scale", "temperature", "quilt_shape", "astigmatism", "registration",
           "pupil_shift", "collimator_wfe", "slit_width"]


def signed_uniform(rng: np.random.Generator, lo: float, hi: float) -> float:
    """A magnitude uniform in [``lo``, ``hi``] with a random sign (sign drawn first)."""
    return float(rng.choice([-1.0, 1.0]) * rng.uniform(lo, hi))


def _check_kind(name: str, kind: str, kinds: tuple[str, ...]) -> None:
    if kind not in kinds:
        raise ValueError(f"{name} truth draw: kind={kind!r} is not one of {list(kinds)}")


def amplitude_scale(rng: np.random.Generator, kind: str, blank: str) -> dict:
    """``scale_<blank>`` 0.6-0.85 or 1.2-1.6 (a thinner or thicker NiP layer, a re-polished blank)."""
    _check_kind("amplitude_scale", kind, ("surface", "line_profile"))
    if not blank:
        raise ValueError("amplitude_scale truth draw: blank='' must name the grating blank (e.g. 'J', 'spare')")
    return {f"scale_{blank}": float(rng.choice([rng.uniform(0.6, 0.85), rng.uniform(1.2, 1.6)]))}


def temperature(rng: np.random.Generator, kind: str, blank: str) -> dict:
    """``temperature_offset_K``: ±20-50 K for a map (the campaign's maps are taken at
    128 K); +35-75 K for line profiles (taken at the simulation's cold temperature)."""
    _check_kind("temperature", kind, ("surface", "line_profile"))
    if kind == "surface":
        return {"temperature_offset_K": signed_uniform(rng, 20.0, 50.0)}
    return {"temperature_offset_K": rng.uniform(35.0, 75.0)}


def quilt_shape(rng: np.random.Generator, kind: str, blank: str) -> dict:
    """The quilt's higher harmonics times ``h``, 0-0.4 or 1.6-2.5: on a map all of them
    (``quilt_harmonics_ratio`` and ``quilt_x_harmonics_ratio`` both ``h``) and
    ``quilt_fund_xy_ratio`` 0.7-0.85 or 1.2-1.4 (drawn first); on a line profile the
    harmonics along x (``quilt_x_harmonics_ratio``) alone: a profile integrates along the
    rulings, so it does not see the y fundamental and sees the other harmonics only weakly."""
    _check_kind("quilt_shape", kind, ("surface", "line_profile"))
    out = {}
    if kind == "surface":
        out["quilt_fund_xy_ratio"] = float(rng.choice([rng.uniform(0.7, 0.85), rng.uniform(1.2, 1.4)]))
    h = float(rng.choice([rng.uniform(0.0, 0.4), rng.uniform(1.6, 2.5)]))
    if kind == "surface":
        out["quilt_harmonics_ratio"] = h
    out["quilt_x_harmonics_ratio"] = h
    return out


def astigmatism(rng: np.random.Generator, kind: str, blank: str) -> dict:
    """``astig_0_um``, ``astig_45_um``: an RMS of 0.04-0.15 µm at a uniform random angle."""
    _check_kind("astigmatism", kind, ("surface",))
    a, th = rng.uniform(0.04, 0.15), rng.uniform(0, 2 * np.pi)
    return {"astig_0_um": a * math.cos(th), "astig_45_um": a * math.sin(th)}


def registration(rng: np.random.Generator, kind: str, blank: str) -> dict:
    """``reg_dx_mm``, ``reg_dy_mm``: a shift of 1.5-5 mm in a uniform random direction;
    ``reg_rot_deg``: ±1.5°."""
    _check_kind("registration", kind, ("surface",))
    r, th = rng.uniform(1.5, 5.0), rng.uniform(0, 2 * np.pi)
    return {"reg_dx_mm": r * math.cos(th), "reg_dy_mm": r * math.sin(th), "reg_rot_deg": rng.uniform(-1.5, 1.5)}


def pupil_shift(rng: np.random.Generator, kind: str, blank: str) -> dict:
    """``pupil_x_mm`` ±3-8 mm (along the dispersion, where profiles see it at first order),
    ``pupil_y_mm`` uniform in ±3 mm."""
    _check_kind("pupil_shift", kind, ("line_profile",))
    return {"pupil_x_mm": signed_uniform(rng, 3.0, 8.0), "pupil_y_mm": rng.uniform(-3.0, 3.0)}


def collimator_wfe(rng: np.random.Generator, kind: str, blank: str) -> dict:
    """``coll_coma_um``, ``coll_defocus_um``, ``coll_astig45_um``: an isotropic random
    direction with an RMS wavefront error of 0.15-0.35 µm."""
    _check_kind("collimator_wfe", kind, ("line_profile",))
    v = rng.normal(size=3)
    v *= rng.uniform(0.15, 0.35) / np.linalg.norm(v)
    return {"coll_coma_um": v[0], "coll_defocus_um": v[1], "coll_astig45_um": v[2]}


def slit_width(rng: np.random.Generator, kind: str, blank: str) -> dict:
    """``slit_image_width_um`` 19-23 or 31-38 µm (the nominal is 27 µm)."""
    _check_kind("slit_width", kind, ("line_profile",))
    return {"slit_image_width_um": float(rng.choice([rng.uniform(19.0, 23.0), rng.uniform(31.0, 38.0)]))}


#: Every draw by library effect name (the same functions as ``Effect.draw_truth``).
DRAWS = {f.__name__: f for f in (amplitude_scale, temperature, quilt_shape, astigmatism, registration, pupil_shift,
                                 collimator_wfe, slit_width)}
