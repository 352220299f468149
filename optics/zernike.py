"""Zernike polynomials on the unit disc and their single-index conventions.

Internally a Zernike term is only ever the pair ``(n, m)``: ``n >= 0`` the radial
degree, ``|m| <= n`` with ``n - |m|`` even the azimuthal frequency. ``m > 0`` is the
cosine term ``R_n^|m|(rho) cos(m theta)``, ``m < 0`` the sine term
``R_n^|m|(rho) sin(|m| theta)``. On the grating ``theta`` is measured from +x
(dispersion) towards +y (ruling direction), so ``(1, 1)`` is an x tilt and ``(1, -1)``
a y tilt (see :mod:`optics.sagmap` for the frame).

Single indices are converted at the edge with:

* :func:`noll_to_nm` / :func:`nm_to_noll` — Noll (1976), starting at j = 1; even j are
  cosine terms, odd j sine terms. Zemax "Zernike Standard" uses Noll order *and*
  the RMS normalisation (``norm=True``).
* :func:`ansi_to_nm` / :func:`nm_to_ansi` — ANSI Z80.28 / OSA, starting at j = 0,
  ``j = (n (n + 2) + m) / 2``.
* :func:`fringe_to_nm` / :func:`nm_to_fringe` — University of Arizona Fringe, as
  CODE V ``ZFR`` and Zemax "Zernike Fringe": 37 terms only, starting at Z1. Terms
  are grouped by ``(n + |m|) / 2``, within a group by decreasing ``|m|``, cosine
  before sine. The 37-term set is *not* the full group 6: Z36 is (10, 0) and Z37 is
  (12, 0) (the 12th-power spherical term), whereas a naive group formula would give
  (6, 6) for j = 37. Fringe coefficients from CODE V / Zemax are *unnormalised*
  (peak 1 at the rim): evaluate them with ``norm=False``.

The radial polynomial is evaluated with the three-term Jacobi recurrence
``R_n^m(rho) = (-1)^k rho^m P_k^{(m,0)}(1 - 2 rho^2)``, ``k = (n - m)/2``, which is
stable to high order, unlike the explicit factorial sum whose alternating integer
coefficients cancel catastrophically near the rim.
"""

from __future__ import annotations

import math
from typing import Iterable, Mapping

import numpy as np

__all__ = [
    "radial",
    "zernike",
    "zernike_xy",
    "zernike_basis_xy",
    "wavefront_from_coefficients",
    "noll_to_nm",
    "nm_to_noll",
    "ansi_to_nm",
    "nm_to_ansi",
    "fringe_to_nm",
    "nm_to_fringe",
    "FRINGE_NM",
    "zernike_name",
    "norm_factor",
]


def _check_nm(n: int, m: int) -> tuple[int, int]:
    n_i, m_i = int(n), int(m)
    if n_i != n or m_i != m:
        raise ValueError(f"(n, m)=({n}, {m}) must be integers")
    if n_i < 0 or abs(m_i) > n_i or (n_i - abs(m_i)) % 2:
        raise ValueError(
            f"(n, m)=({n}, {m}) is not a Zernike term; need n >= 0, |m| <= n and n - |m| even"
        )
    return n_i, m_i


def norm_factor(n: int, m: int) -> float:
    """Noll RMS normalisation ``sqrt(2 (n + 1) / (1 + delta_m0))`` (unit RMS on the disc)."""
    n, m = _check_nm(n, m)
    return math.sqrt((n + 1) if m == 0 else 2 * (n + 1))


def radial(n: int, m: int, rho: np.ndarray) -> np.ndarray:
    """Unnormalised radial polynomial ``R_n^|m|(rho)`` with ``R(1) = 1``.

    Parameters
    ----------
    n, m : int
        Zernike indices (sign of ``m`` ignored).
    rho : array_like
        Normalised radius (any shape); values > 1 are evaluated, not masked.
    """
    n, m = _check_nm(n, m)
    m = abs(m)
    rho = np.asarray(rho, dtype=float)
    k = (n - m) // 2
    x = 1.0 - 2.0 * rho**2
    # Jacobi P_k^{(a, 0)}(x) by the standard three-term recurrence (b = 0).
    a = m
    p_prev = np.ones_like(x)
    if k == 0:
        p = p_prev
    else:
        p = (a + 1) + (a + 2) * (x - 1) / 2
        for kk in range(2, k + 1):
            s = 2 * kk + a
            c1 = 2 * kk * (kk + a) * (s - 2)
            c2 = (s - 1) * (s * (s - 2) * x + a * a)
            c3 = 2 * (kk + a - 1) * (kk - 1) * s
            p, p_prev = (c2 * p - c3 * p_prev) / c1, p
    sign = -1.0 if k % 2 else 1.0
    return sign * rho**m * p


def zernike(n: int, m: int, rho: np.ndarray, theta: np.ndarray, norm: bool = True) -> np.ndarray:
    """Zernike polynomial ``Z_n^m(rho, theta)`` in polar coordinates.

    Parameters
    ----------
    n, m : int
        Radial degree and signed azimuthal frequency (m > 0 cosine, m < 0 sine).
    rho : array_like
        Normalised radius; points with ``rho > 1`` are still evaluated (caller masks).
    theta : array_like
        Azimuth in radians from +x towards +y; broadcast against ``rho``.
    norm : bool
        True: RMS-normalised over the unit disc (Noll). False: radial part has
        peak 1 at ``rho = 1`` (Fringe / Born & Wolf form).

    Returns
    -------
    ndarray
        Broadcast shape of ``rho`` and ``theta``.
    """
    n, m = _check_nm(n, m)
    r = radial(n, m, rho)
    theta = np.asarray(theta, dtype=float)
    if m > 0:
        az = np.cos(m * theta)
    elif m < 0:
        az = np.sin(-m * theta)
    else:
        az = np.ones_like(theta)
    out = r * az
    return out * norm_factor(n, m) if norm else out


def _polar(x, y, radius):
    if not np.isscalar(radius) or not radius > 0:
        raise ValueError(f"radius={radius!r} must be a positive scalar (same unit as x, y)")
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    return np.hypot(x, y) / radius, np.arctan2(y, x)


def zernike_xy(n: int, m: int, x: np.ndarray, y: np.ndarray, radius: float, norm: bool = True) -> np.ndarray:
    """Zernike polynomial at Cartesian points ``(x, y)`` on a disc of ``radius`` (same units).

    ``theta = atan2(y, x)``, i.e. from +x towards +y. Shape: broadcast of x and y.
    """
    rho, theta = _polar(x, y, radius)
    return zernike(n, m, rho, theta, norm)


def zernike_basis_xy(
    terms: Iterable[tuple[int, int]], x: np.ndarray, y: np.ndarray, radius: float, norm: bool = True
) -> np.ndarray:
    """Stack of Zernike terms at Cartesian points, shape ``(len(terms),) + broadcast(x, y).shape``."""
    rho, theta = _polar(x, y, radius)
    rho, theta = np.broadcast_arrays(rho, theta)
    terms = [tuple(t) for t in terms]
    out = np.empty((len(terms),) + rho.shape)
    cache: dict[tuple[int, int], np.ndarray] = {}  # radial part shared by the cos and sin term
    for i, (n, m) in enumerate(terms):
        key = _check_nm(n, abs(m))
        if key not in cache:
            cache[key] = radial(*key, rho)
        az = np.cos(m * theta) if m > 0 else (np.sin(-m * theta) if m < 0 else 1.0)
        out[i] = cache[key] * az * (norm_factor(n, m) if norm else 1.0)
    return out


def wavefront_from_coefficients(
    coeffs: Mapping[tuple[int, int], float],
    x: np.ndarray,
    y: np.ndarray,
    radius_mm: float,
    norm: bool = True,
) -> np.ndarray:
    """Sum of Zernike terms ``sum_c c * Z_n^m`` at points ``(x, y)`` (mm).

    Parameters
    ----------
    coeffs : mapping (n, m) -> float
        Coefficients in µm (or any unit; the result has the same unit).
    x, y : array_like
        Point coordinates in mm relative to the disc centre; broadcast together.
    radius_mm : float
        Normalisation radius of the Zernike disc (mm).
    norm : bool
        Whether the coefficients refer to RMS-normalised (Noll) terms.
    """
    shape = np.broadcast(np.asarray(x), np.asarray(y)).shape
    if not coeffs:
        return np.zeros(shape)
    keys = list(coeffs)
    basis = zernike_basis_xy(keys, x, y, radius_mm, norm)
    c = np.array([coeffs[k] for k in keys], dtype=float)
    return np.tensordot(c, basis, axes=1)


# --------------------------------------------------------------------- index conventions
def _check_index(j, lo: int, name: str, hi: int | None = None) -> int:
    j_i = int(j)
    if j_i != j or j_i < lo or (hi is not None and j_i > hi):
        rng = f"{lo}..{hi}" if hi is not None else f">= {lo}"
        raise ValueError(f"{name}={j!r} must be an integer in {rng}")
    return j_i


def noll_to_nm(j: int) -> tuple[int, int]:
    """Noll index (j >= 1) to ``(n, m)``. Even j cosine (m > 0), odd j sine (m < 0)."""
    j = _check_index(j, 1, "j (Noll)")
    n = 0
    while (n + 1) * (n + 2) // 2 < j:
        n += 1
    k = j - n * (n + 1) // 2 - 1  # position within radial order n, |m| non-decreasing
    am = 2 * ((k + 1) // 2) if n % 2 == 0 else 2 * (k // 2) + 1
    if am == 0:
        return n, 0
    return n, am if j % 2 == 0 else -am


def nm_to_noll(n: int, m: int) -> int:
    """``(n, m)`` to Noll index (inverse of :func:`noll_to_nm`)."""
    n, m = _check_nm(n, m)
    base = n * (n + 1) // 2 + 1
    am = abs(m)
    if am == 0:
        return base
    # the two positions holding |m| in this row; parity picks cos (even j) or sin (odd j)
    for j in (base + am - 1, base + am):
        if (j % 2 == 0) == (m > 0):
            return j
    raise AssertionError("unreachable")  # pragma: no cover


def ansi_to_nm(j: int) -> tuple[int, int]:
    """ANSI Z80.28 / OSA index (j >= 0) to ``(n, m)``."""
    j = _check_index(j, 0, "j (ANSI)")
    n = int(math.ceil((-3 + math.sqrt(9 + 8 * j)) / 2))
    m = 2 * j - n * (n + 2)
    return n, m


def nm_to_ansi(n: int, m: int) -> int:
    """``(n, m)`` to ANSI Z80.28 / OSA index ``(n (n + 2) + m) / 2``."""
    n, m = _check_nm(n, m)
    return (n * (n + 2) + m) // 2


def _fringe_table() -> tuple[tuple[int, int], ...]:
    out = []
    for g in range(6):  # groups (n + |m|)/2 = 0..5 are complete in the 37-term set
        for am in range(g, -1, -1):
            n = 2 * g - am
            out.extend([(n, am), (n, -am)] if am else [(n, 0)])
    out.append((12, 0))  # Z37: the one term taken from group 6
    return tuple(out)


#: The 37 University of Arizona Fringe terms, ``FRINGE_NM[j - 1] = (n, m)``.
FRINGE_NM: tuple[tuple[int, int], ...] = _fringe_table()
_FRINGE_INV = {nm: j + 1 for j, nm in enumerate(FRINGE_NM)}


def fringe_to_nm(j: int) -> tuple[int, int]:
    """Fringe index (1..37, CODE V ZFR / Zemax Fringe) to ``(n, m)``."""
    j = _check_index(j, 1, "j (Fringe)", 37)
    return FRINGE_NM[j - 1]


def nm_to_fringe(n: int, m: int) -> int:
    """``(n, m)`` to Fringe index; raises for terms outside the 37-term Fringe set."""
    n, m = _check_nm(n, m)
    try:
        return _FRINGE_INV[(n, m)]
    except KeyError:
        raise ValueError(f"(n, m)=({n}, {m}) is not one of the 37 Fringe terms") from None


# --------------------------------------------------------------------- names
_ORDINAL = ["", "secondary ", "tertiary ", "quaternary ", "quinary "]
_FOIL = {2: "astigmatism", 3: "trefoil", 4: "tetrafoil", 5: "pentafoil", 6: "hexafoil"}


def _rank(k: int) -> str:
    return _ORDINAL[k] if k < len(_ORDINAL) else f"{k + 1}th-order "


def zernike_name(n: int, m: int) -> str:
    """Human-readable name, e.g. ``(2, 2) -> 'astigmatism 0°'``, ``(3, -1) -> 'coma y'``."""
    n, m = _check_nm(n, m)
    am = abs(m)
    if n == 0:
        return "piston"
    if am == 0:
        return "defocus" if n == 2 else f"{_rank(n // 2 - 2)}spherical"
    if am == 1:
        axis = "x" if m > 0 else "y"
        return f"tilt {axis}" if n == 1 else f"{_rank((n - 3) // 2)}coma {axis}"
    base = _FOIL.get(am, f"{am}-foil")
    angle = "0°" if m > 0 else f"{90 / am:g}°"
    return f"{_rank((n - am) // 2)}{base} {angle}"
