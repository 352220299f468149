"""Out-of-library effects of the independent truths, drawn from the families written down
in ``benchmarks/truth_families.md`` (not made orthogonal to any library effect).

Surface families return ``(truth parameters, extra(x_mm, y_mm) -> µm)``; line-profile
families return ``(truth parameters, distortion(u_um, y) -> y or None, camera Zernike
terms or None, artefact(x, counts, rng) -> counts or None)``.
"""

from __future__ import annotations

import math

import numpy as np

from .abbe import zernike_noll

__all__ = ["SURFACE_OOL", "PROFILE_OOL", "draw_surface_ool", "draw_profile_ool"]

SURFACE_OOL = ("ool_defect", "ool_loworder", "ool_periodic")
PROFILE_OOL = ("ool_stray", "ool_detector", "ool_camera")
WINDOW_RADIUS_MM = 68.5


def _sign(rng) -> float:
    return float(rng.choice([-1.0, 1.0]))


def _defect(rng):
    if rng.random() < 1.0 / 3.0:
        d, w, L = _sign(rng) * rng.uniform(0.05, 0.2), rng.uniform(1.0, 3.0), rng.uniform(20.0, 60.0)
        th, r, ph = rng.uniform(0, np.pi), rng.uniform(0, 45.0), rng.uniform(0, 2 * np.pi)
        x0, y0 = r * math.cos(ph), r * math.sin(ph)
        truth = {"scratch_depth_um": d, "width_mm": w, "length_mm": L, "angle_rad": th, "x0_mm": x0, "y0_mm": y0}

        def extra(x, y):
            a = (x - x0) * math.cos(th) + (y - y0) * math.sin(th)
            b = -(x - x0) * math.sin(th) + (y - y0) * math.cos(th)
            return d * np.exp(-0.5 * (b / w) ** 2) * (np.abs(a) <= 0.5 * L)
        return truth, extra
    bumps = []
    for _ in range(int(rng.integers(1, 4))):
        r, ph = rng.uniform(0, 55.0), rng.uniform(0, 2 * np.pi)
        bumps.append((_sign(rng) * rng.uniform(0.05, 0.3), rng.uniform(4.0, 15.0), r * math.cos(ph), r * math.sin(ph)))

    def extra(x, y):
        return sum(h * np.exp(-((x - x0) ** 2 + (y - y0) ** 2) / (2 * s * s)) for h, s, x0, y0 in bumps)
    return {"bumps": [list(b) for b in bumps]}, extra


def _loworder(rng):
    terms = [(n, m) for n in (3, 4, 5) for m in range(-n, n + 1, 2)]
    c = rng.normal(size=len(terms))
    c *= rng.uniform(0.04, 0.15) / np.linalg.norm(c)
    coeffs = {f"{n},{m}": float(v) for (n, m), v in zip(terms, c)}

    def extra(x, y):
        rho, th = np.hypot(x, y) / WINDOW_RADIUS_MM, np.arctan2(y, x)
        return sum(v * zernike_noll(n, m, rho, th) for (n, m), v in zip(terms, c))
    return {"zernike_um": coeffs, "rms_um": float(np.linalg.norm(c))}, extra


def _periodic(rng):
    period = rng.uniform(5.0, 12.0) if rng.random() < 0.5 else rng.uniform(30.0, 60.0)
    a, th, ph = rng.uniform(0.02, 0.08), rng.uniform(0, np.pi), rng.uniform(0, 2 * np.pi)

    def extra(x, y):
        return a * np.cos(2 * np.pi * (x * math.cos(th) + y * math.sin(th)) / period + ph)
    return {"period_mm": period, "amplitude_um": a, "angle_rad": th}, extra


def draw_surface_ool(effect: str, rng: np.random.Generator):
    """(truth parameters, extra(x, y) -> µm) of a surface family in :data:`SURFACE_OOL`."""
    fn = {"ool_defect": _defect, "ool_loworder": _loworder, "ool_periodic": _periodic}.get(effect)
    if fn is None:
        raise ValueError(f"draw_surface_ool: effect={effect!r} is not one of {list(SURFACE_OOL)}")
    return fn(rng)


def _stray(rng):
    kind = rng.choice(["halo", "ghost", "slope"])
    if kind == "halo":
        f, g = rng.uniform(0.02, 0.06), rng.uniform(20.0, 60.0)

        def dist(u, y):
            lor = g / np.pi / ((u) ** 2 + g * g)
            return y + f * np.sum(y) / np.sum(lor) * lor
        return {"halo_fraction": f, "halo_hwhm_um": g}, dist
    if kind == "ghost":
        f, u0 = rng.uniform(0.03, 0.08), _sign(rng) * rng.uniform(40.0, 100.0)

        def dist(u, y):
            return y + f * np.interp(u - u0, u, y, left=0.0, right=0.0)
        return {"ghost_fraction": f, "ghost_offset_um": u0}, dist
    s = _sign(rng) * rng.uniform(0.02, 0.05)

    def dist(u, y):
        return y + s * y.max() * u / 120.0
    return {"background_slope_rel": s}, dist


def _detector(rng):
    kind = rng.choice(["tail", "nonlinear", "bad_pixels"])
    if kind == "tail":
        f, tau, side = rng.uniform(0.02, 0.06), rng.uniform(10.0, 30.0), _sign(rng)

        def dist(u, y):
            du = u[1] - u[0]
            k = np.exp(-np.arange(0.0, 8 * tau, du) / tau)
            k /= k.sum()
            t = np.convolve(y if side > 0 else y[::-1], k)[: y.size]
            return (1 - f) * y + f * (t if side > 0 else t[::-1])
        return {"tail_fraction": f, "tail_decay_um": tau, "tail_side": side}, dist, None
    if kind == "nonlinear":
        beta = rng.uniform(0.03, 0.08)

        def dist(u, y):
            return y * (1.0 - beta * y / y.max())
        return {"nonlinearity": beta}, dist, None
    n = int(rng.integers(1, 4))
    amps = [_sign(rng) * rng.uniform(0.2, 0.6) for _ in range(n)]

    def artefact(x, counts, rng2):
        idx = rng2.choice(np.flatnonzero(np.abs(x) <= 60.0), size=n, replace=False)
        out = counts.copy()
        out[idx] = out[idx] + np.asarray(amps) * counts.max()
        return out
    return {"bad_pixels_rel": amps}, None, artefact


def draw_profile_ool(effect: str, rng: np.random.Generator):
    """(truth parameters, distortion or None, camera terms or None, artefact or None) of a
    line-profile family in :data:`PROFILE_OOL`."""
    if effect == "ool_stray":
        t, d = _stray(rng)
        return t, d, None, None
    if effect == "ool_detector":
        t, d, a = _detector(rng)
        return t, d, None, a
    if effect == "ool_camera":
        a = rng.uniform(0.1, 0.3)
        nm = [(4, 0), (3, 3), (3, -3)][int(rng.integers(0, 3))]
        return {"camera_zernike": f"{nm[0]},{nm[1]}", "camera_um": a}, None, {nm: a}, None
    raise ValueError(f"draw_profile_ool: effect={effect!r} is not one of {list(PROFILE_OOL)}")
