"""The slit's partially coherent illumination of each pupil row as a few coherent modes.

The Abbe sum of :func:`optics.imaging.partially_coherent_lsf` adds one FFT per source
point: on pupil row ``j`` the detector intensity is

    I(u) = sum_k w_jk |FT{P_j(xi) T(xi - s_k)}(u)|^2 = FT-quadratic form of M_j,
    M_j(xi, xi') = sum_k w_jk T(xi - s_k) T(xi' - s_k),

where ``P_j`` is the pupil field on the row and ``T`` the slit's spectrum. ``M_j`` (the
mutual intensity the slit lays on the row) does not depend on the pupil field, and its
eigen-expansion ``M_j = sum_m phi_m phi_m^T`` gives the same intensity as
``sum_m |FT{P_j phi_m}|^2`` (Hopkins' transmission cross-coefficients; in lithography the
"sum of coherent systems"). Shifted slit spectra overlap, so a row of ``n`` sources holds
far fewer modes that carry any light: on SPIFFI's J grating at 1.25 µm the 6180 sources of
250 mas hold 1174 modes above 1e-12 of the largest eigenvalue, the 1028 of 100 mas 356, the 216
of 25 mas 102. The modes are computed once per illumination (cached) and reused for every
pupil field a fit tries.

Truncation: modes whose eigenvalue is below :data:`MODE_RTOL` of the largest eigenvalue of
all rows are dropped; the intensity they carry is at most their eigenvalue sum relative to
the total (``tests/test_slit_modes.py`` checks the modal sum against the literal Abbe sum).
"""

from __future__ import annotations

import hashlib
import threading
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np

__all__ = ["MODE_RTOL", "SlitModes", "slit_modes"]

#: Eigenvalues below this fraction of the largest are dropped (float64 keeps ~1e-16 of the
#: largest through the Gram matrix, so the kept modes are exact to far below any noise).
MODE_RTOL = 1e-12

#: Illuminations kept (a fit varies the pupil field, not the slit or the source grid; a
#: diagnosis holds a few wavelengths and pixel scales at once).
_CACHE_SIZE = 64
_CACHE: OrderedDict = OrderedDict()
_LOCK = threading.Lock()  # a threaded sweep may compute profiles side by side


@dataclass(frozen=True)
class SlitModes:
    """Coherent modes of the slit's illumination, row by row.

    ``row`` (n_modes,) is the source row (index into the pupil rows) each mode lights;
    ``field`` (n_modes, n_xi) is the mode's real amplitude across the pupil, scaled so that
    ``sum_m field_m(xi) field_m(xi')`` over a row's modes is that row's ``M_j``;
    ``n_sources`` the number of source points they replace; ``dropped_fraction`` the
    eigenvalue sum dropped relative to the total (the bound on the intensity left out)."""

    row: np.ndarray
    field: np.ndarray
    n_sources: int
    dropped_fraction: float


def _decompose(xi_mm: np.ndarray, s_x_mm: np.ndarray, weights: np.ndarray, scale_per_mm: float,
               rtol: float) -> SlitModes:
    T = np.sinc(scale_per_mm * (xi_mm[None, :] - s_x_mm[:, None]))  # (n_sx, n_xi)
    per_row = []
    for j in range(weights.shape[0]):
        k = np.flatnonzero(weights[j] > 0)
        if k.size == 0:
            continue
        A = np.sqrt(weights[j, k])[:, None] * T[k]  # M_j = A^T A
        lam, U = np.linalg.eigh(A @ A.T)  # the Gram matrix: n_k x n_k, n_k <= n_sx
        per_row.append((j, lam, U, A))
    if not per_row:
        return SlitModes(np.zeros(0, int), np.zeros((0, xi_mm.size)), 0, 0.0)
    top = max(float(lam[-1]) for _, lam, _, _ in per_row)
    total = sum(float(np.clip(lam, 0, None).sum()) for _, lam, _, _ in per_row)
    rows, fields, dropped = [], [], 0.0
    for j, lam, U, A in per_row:
        keep = lam > rtol * top
        dropped += float(np.clip(lam[~keep], 0, None).sum())
        fields.append(U[:, keep].T @ A)  # u_m^T A: norm^2 = lam_m, sum of outer products = A^T A
        rows.append(np.full(int(keep.sum()), j))
    n_sources = int(np.count_nonzero(weights > 0))
    row, field = np.concatenate(rows), np.concatenate(fields)
    row.flags.writeable = field.flags.writeable = False  # cached and shared by every caller
    return SlitModes(row, field, n_sources, dropped / total if total > 0 else 0.0)


def slit_modes(xi_mm, s_x_mm, weights, scale_per_mm: float, rtol: float = MODE_RTOL) -> SlitModes:
    """Coherent modes of each source row's illumination (cached per illumination).

    Parameters
    ----------
    xi_mm : ndarray, shape (n_xi,)
        Pupil coordinate across the slit's spectrum (mm).
    s_x_mm : ndarray, shape (n_sx,)
        Source positions along xi (mm).
    weights : ndarray, shape (n_rows, n_sx)
        Source weights (0 = no source).
    scale_per_mm : float
        The slit spectrum's ``T(xi) = sinc(scale_per_mm * xi)`` (1/mm: slit width over
        wavelength times collimator focal length).
    rtol : float
        Eigenvalues below ``rtol`` times the largest are dropped.

    Returns
    -------
    SlitModes

    Raises
    ------
    ValueError
        If ``weights`` is not (n_rows, n_sx) for the ``n_sx`` source positions, or holds a
        negative or non-finite weight; if ``rtol`` is not in [0, 1).
    """
    xi = np.ascontiguousarray(xi_mm, float)
    sx = np.ascontiguousarray(s_x_mm, float)
    w = np.ascontiguousarray(weights, float)
    if w.ndim != 2 or w.shape[1] != sx.size:
        raise ValueError(f"slit_modes: weights has shape {w.shape}, must be (n_rows, n_sx={sx.size})")
    bad = w[~(np.isfinite(w) & (w >= 0))]
    if bad.size:
        raise ValueError(f"slit_modes: weights must be finite and >= 0 (source areas); it holds {bad[0]:g}")
    if not 0 <= rtol < 1:
        raise ValueError(f"slit_modes: rtol={rtol!r} must be in [0, 1)")
    h = hashlib.blake2b(digest_size=16)
    for a in (np.array([scale_per_mm, rtol], float), np.array(w.shape, float), xi, sx, w):
        h.update(a.tobytes())
    key = h.digest()
    with _LOCK:
        hit = _CACHE.get(key)
        if hit is not None:
            _CACHE.move_to_end(key)
            return hit
    out = _decompose(xi, sx, w, float(scale_per_mm), float(rtol))
    with _LOCK:
        _CACHE[key] = out
        while len(_CACHE) > _CACHE_SIZE:
            _CACHE.popitem(last=False)
    return out
