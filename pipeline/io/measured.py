"""Measured spectrograph data: line profiles (``offset_um,intensity``) and point-source
images (``x_um,y_um,intensity``), read the way laboratories deliver them — counts in any
normalisation, a pedestal or background-subtracted negative samples, any grid, any row
order, any length unit and delimiter (:func:`pipeline.io.common.read_csv_columns`); a
profile's samples at one offset are averaged, an image's ``nan`` intensities are masked
pixels (left out). Only other non-finite values, duplicate image points and a total flux
<= 0 are refused.
"""

from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np

from pipeline.io.columns import INTENSITY, PIXEL_OFFSET_COLUMNS, WAVELENGTH_COLUMNS
from pipeline.io.common import atomic_write, parse_error, read_csv_choices

__all__ = ["PIXEL_OFFSET_COLUMNS", "WAVELENGTH_COLUMNS", "IMAGE_PIXEL_COLUMNS", "profile_offsets_um", "checked_profile",
           "checked_psf_image", "read_line_profile", "read_psf_image", "write_line_profile_csv", "write_psf_image_csv"]


def profile_offsets_um(values: np.ndarray, axis: str, path: Path, pixel_um: float | None,
                       dispersion_um_per_um: float | None, source: str = "",
                       line_wavelength_um: float | None = None) -> np.ndarray:
    """Offsets (µm along the dispersion) of a profile's axis ``values``: ``axis`` is
    ``"offset_um"`` (already a length in µm), ``"pixel"`` (detector pixels, times
    ``pixel_um``) or ``"wavelength_um"`` (times ``dispersion_um_per_um``, about the line's
    wavelength ``line_wavelength_um``, or the axis's median wavelength where the line's is
    not given). A missing conversion, and a line wavelength outside the axis, are refused
    naming it, the file and ``source`` (where the axis came from, e.g. ``"column 'pixel'"``).

    Why about the line's wavelength: a spectrum's window is rarely centred on its line to
    a fraction of a pixel, so offsets about the window's median carry that misplacement
    (an outside lab's 1-D spectra at a 0.37-pixel phase read offset shifts all 6.7 µm off)."""
    where = f" ({source})" if source else ""
    v = np.asarray(values, float)
    if axis == "pixel":
        if pixel_um is None or not (np.isfinite(pixel_um) and pixel_um > 0):
            raise parse_error(path, None, f"offsets in detector pixels{where} need pixel_um, the pixel pitch in µm (> 0); "
                                          f"got pixel_um={pixel_um!r}")
        return v * pixel_um
    if axis == "wavelength_um":
        if dispersion_um_per_um is None or not (np.isfinite(dispersion_um_per_um) and dispersion_um_per_um != 0):
            raise parse_error(path, None, f"a wavelength axis{where} needs the linear dispersion (detector µm per µm of "
                                          f"wavelength, signed); got {dispersion_um_per_um!r}")
        if line_wavelength_um is None:
            return (v - np.median(v)) * dispersion_um_per_um
        lo, hi = float(np.nanmin(v)), float(np.nanmax(v))
        if not (np.isfinite(line_wavelength_um) and lo <= line_wavelength_um <= hi):
            raise parse_error(path, None, f"the line's wavelength_um={line_wavelength_um!r} lies outside the file's "
                                          f"wavelength axis{where}, {lo:.6g}..{hi:.6g} µm; state the line the file holds")
        return (v - line_wavelength_um) * dispersion_um_per_um
    if axis != "offset_um":
        raise ValueError(f"axis={axis!r} must be one of 'offset_um', 'pixel', 'wavelength_um'")
    return v


def _profile_columns(path: Path, pixel_um: float | None, dispersion_um_per_um: float | None = None,
                     line_wavelength_um: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``offset_um, intensity`` of a profile table, the offset in a length unit, in
    detector pixels (times ``pixel_um``) or a wavelength (times ``dispersion_um_per_um``,
    about ``line_wavelength_um``: :func:`profile_offsets_um`)."""
    axis_hint = (f"offsets in detector pixels may be a column {PIXEL_OFFSET_COLUMNS[0]!r} or 'pixel', a "
                 f"wavelength axis {WAVELENGTH_COLUMNS[0]!r} (any length unit)")

    def hint(missing, header):
        return "; ".join(axis_hint if m == "offset_um" else INTENSITY.refusal(header) for m in missing)

    v, lines, (name, _) = read_csv_choices(
        path, "line profile", (("offset_um", *PIXEL_OFFSET_COLUMNS, *WAVELENGTH_COLUMNS), INTENSITY.names()), hint)
    axis = "pixel" if name in PIXEL_OFFSET_COLUMNS else "wavelength_um" if name in WAVELENGTH_COLUMNS else "offset_um"
    v[:, 0] = profile_offsets_um(v[:, 0], axis, path, pixel_um, dispersion_um_per_um, f"column {name!r}",
                                 line_wavelength_um)
    return v, lines


def read_line_profile(path: str | Path, normalise: bool = True, pixel_um: float | None = None,
                      dispersion_um_per_um: float | None = None,
                      line_wavelength_um: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Read a measured line profile from a CSV with columns ``offset_um,intensity``.

    Measured profiles come in counts (any normalisation), background-subtracted (so
    with negative noise samples) or on a constant pedestal, on any grid of offsets
    (non-uniform, any range, line centred anywhere), in any row order and with several
    samples at one offset (exposures merged into one table: they are averaged): all are
    accepted. Flux, background and centring are nuisances of the diagnosis fit. The
    offsets may be in nm, µm, mm or m (``offset_nm``, ``Offset [mm]``, ...; converted).

    Parameters
    ----------
    path : str or Path
        CSV file with a header naming ``offset_um`` and ``intensity`` (any order,
        case-insensitive, other columns ignored). The intensity may also be named
        ``flux``, ``counts``, ``signal``, ``data`` or ``value``, with or without a unit
        (``Flux [ADU]``, ``intensity [counts]``; :mod:`pipeline.io.columns`).
    normalise : bool
        Divide the intensity by its total flux (trapezoid rule over ``offset_um``),
        the unit-area normalisation of :mod:`optics.imaging` profiles.
    pixel_um : float, optional
        Detector pixel pitch (µm) that turns offsets given in pixels (a column
        ``offset_px``, ``Offset [px]`` or ``pixel``) into µm; such a file without it is
        refused naming it.
    dispersion_um_per_um : float, optional
        Signed linear dispersion, detector offset (µm) per µm of wavelength, that turns a
        wavelength axis (``wavelength_nm``, ``Wavelength [um]``, ``lambda_nm``) into offsets
        (for the SPIFFI orders it is negative: longer wavelengths land at more negative
        offsets, :mod:`optics.pupil`).
    line_wavelength_um : float, optional
        The line's wavelength (µm): a wavelength axis's offsets are taken about it (refused
        if outside the axis); without it, about the axis's median wavelength.

    Returns
    -------
    offset_um, intensity : ndarray, shape (n,)
        Sorted by increasing offset.

    Raises
    ------
    ValueError
        Naming file and (where it applies) line: missing columns, non-numeric values, an
        infinite intensity or a non-finite offset, fewer than 5 distinct offsets, total
        flux <= 0. A ``nan`` intensity is a masked sample and is left out.
    """
    path = Path(path)
    v, lines = _profile_columns(path, pixel_um, dispersion_um_per_um, line_wavelength_um)
    return checked_profile(path, v[:, 0], v[:, 1], normalise, lines)


def _unreadable_and_masked(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rows of ``v`` (coordinates, then the intensity last) that are refused (a non-finite
    coordinate or an infinite intensity) and that are masked samples (a NaN intensity at
    finite coordinates: a bad pixel a pipeline flagged), as two boolean arrays."""
    coords_ok = np.isfinite(v[:, :-1]).all(axis=1)
    return ~coords_ok | np.isinf(v[:, -1]), coords_ok & np.isnan(v[:, -1])


def checked_profile(path: Path, offset_um, intensity, normalise: bool = True,
                    lines: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """A profile's samples as every reader returns them: sorted by offset, samples at one
    offset averaged, samples whose intensity is NaN left out (a bad pixel a pipeline masked
    is a missing sample, not an error), refused (naming ``path`` and, where given, the line)
    for fewer than 5 distinct offsets, an infinite intensity, a non-finite offset or a total
    flux <= 0; divided by the flux when ``normalise``."""
    v = np.column_stack([np.asarray(offset_um, float).ravel(), np.asarray(intensity, float).ravel()])
    nonfinite, masked = _unreadable_and_masked(v)
    if nonfinite.any():
        where = int(lines[nonfinite][0]) if lines is not None else None
        raise parse_error(path, where, "offset_um must be a finite number and intensity finite or nan (masked)")
    v = v[~masked]
    if v.shape[0] < 5:
        raise parse_error(path, None, f"needs >= 5 samples, found {v.shape[0]}"
                          + (f" ({int(masked.sum())} more masked as nan)" if masked.any() else ""))
    # samples at one offset (exposures merged into one table) are averaged
    x, inverse = np.unique(v[:, 0], return_inverse=True)
    y = np.bincount(inverse, weights=v[:, 1]) / np.bincount(inverse)
    if x.size < 5:
        raise parse_error(path, None, f"needs >= 5 distinct offsets, found {x.size}")
    flux = float(np.trapezoid(y, x))
    if not flux > 0:
        raise parse_error(path, None, f"no flux: the total flux (integral of intensity over offset_um) "
                          f"is {flux:g}, must be > 0")
    return x, (y / flux if normalise else y)


def write_line_profile_csv(path: str | Path, offset_um, intensity) -> None:
    """Write a line profile as the CSV :func:`read_line_profile` reads, atomically.

    Both columns are written in Python's shortest round-trip form (``repr`` of the
    float), so the file reads back to the very same floats: sub-pixel sample phases a
    hair apart stay distinct, and no rounding of the writer's enters a fit.

    Parameters
    ----------
    path : str or Path
        Destination ``.csv``; replaced only once the whole file is written.
    offset_um : array_like, shape (n,)
        Sample offsets along the dispersion (µm), any order, all distinct.
    intensity : array_like, shape (n,)
        Intensity at each offset (any unit: counts or unit area).

    Raises
    ------
    ValueError
        Naming the parameter: not 1-D arrays of one length, no samples, a non-finite
        value, or a duplicate offset (two samples at one offset are one sample twice).
    """
    x = np.asarray(offset_um, dtype=float)
    y = np.asarray(intensity, dtype=float)
    if x.ndim != 1 or y.shape != x.shape:
        raise ValueError(f"offset_um and intensity must be 1-D arrays of one length; got shapes {x.shape} "
                         f"and {y.shape}")
    if x.size == 0:
        raise ValueError("offset_um is empty; a line profile needs at least one sample")
    for name, v in (("offset_um", x), ("intensity", y)):
        bad = np.flatnonzero(~np.isfinite(v))
        if bad.size:
            raise ValueError(f"{name}[{bad[0]}] = {float(v[bad[0]])!r}; every value must be a finite number")
    xs = np.sort(x)
    dup = np.flatnonzero(np.diff(xs) == 0)
    if dup.size:
        raise ValueError(f"offset_um has duplicate samples ({float(xs[dup[0]])!r} appears more than once); "
                         "each offset must be distinct")
    with atomic_write(Path(path)) as fh:
        fh.write("offset_um,intensity\n")
        fh.writelines(f"{a!r},{b!r}\n" for a, b in zip(x.tolist(), y.tolist()))


def _load_npz_columns(path: Path, names: tuple[str, ...]) -> np.ndarray:
    """Arrays ``names`` of an ``.npz`` flattened into columns; errors name the file."""
    try:
        with np.load(path, allow_pickle=False) as z:
            missing = [k for k in names if k not in z.files]
            if missing:
                raise parse_error(path, None, f"lacks arrays {missing}; has {sorted(z.files)}")
            cols = [np.ravel(z[k]) for k in names]
    except FileNotFoundError:
        raise parse_error(path, None, "file does not exist") from None
    except (OSError, EOFError, zipfile.BadZipFile, ValueError) as exc:
        if isinstance(exc, ValueError) and str(path) in str(exc):
            raise
        raise parse_error(path, None, f"is not a readable .npz: {exc}") from None
    for k, c in zip(names, cols):
        if np.iscomplexobj(c) or not np.issubdtype(c.dtype, np.number):
            raise parse_error(path, None, f"array {k!r} has dtype {c.dtype}; expected real numbers")
    if len({c.size for c in cols}) != 1:
        raise parse_error(path, None, f"arrays {list(names)} have different sizes {[c.size for c in cols]}")
    return np.column_stack([c.astype(float) for c in cols])


#: Table columns of an image's coordinates in detector pixels (after ``[px]`` -> ``_px``).
IMAGE_PIXEL_COLUMNS = {"x": ("x_px", "x_pixel", "x_pixels", "x_pix"), "y": ("y_px", "y_pixel", "y_pixels", "y_pix")}


def read_psf_image(path: str | Path, pixel_um: float | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Read a measured point-source image: CSV ``x_um,y_um,intensity`` (header, any
    column order, other columns ignored; the coordinates in another length unit, or in
    detector pixels, ``x_px``/``X [px]``, times ``pixel_um``) or ``.npz`` with arrays
    ``x_um``, ``y_um``, ``intensity`` (which may be named as a profile's, e.g. ``counts``,
    ``Flux [ADU]``). ``x`` is along the dispersion, ``y`` along the slit (detector µm).
    Like line profiles: counts, negative (background-subtracted) samples, a pedestal and
    any grid are accepted; a point whose intensity is ``nan`` is a masked pixel, left out.

    Parameters
    ----------
    path : str or Path
        The CSV (or other delimited text) or ``.npz`` file.
    pixel_um : float, optional
        Detector pixel pitch (µm), for coordinates in pixels.

    Returns
    -------
    x_um, y_um, intensity : ndarray, shape (n,)
        Sorted by (y, x); intensities as given.

    Raises
    ------
    ValueError
        Naming file and (where it applies) line: missing columns or arrays, non-finite
        coordinates, infinite intensities, fewer than 25 valid samples, duplicate points,
        total flux (sum) <= 0.
    """
    path = Path(path)
    if path.suffix.lower() == ".npz":
        v = _load_npz_columns(path, ("x_um", "y_um", "intensity"))
        lines = np.zeros(v.shape[0], int)
    else:
        v, lines, (xn, yn, _) = read_csv_choices(
            path, "PSF image", (("x_um", *IMAGE_PIXEL_COLUMNS["x"]), ("y_um", *IMAGE_PIXEL_COLUMNS["y"]),
                                INTENSITY.names()),
            lambda missing, header: INTENSITY.refusal(header) if "intensity" in missing else
            "coordinates in detector pixels may be columns x_px, y_px (with pixel_um)")
        for k, name in enumerate((xn, yn)):
            if name != ("x_um", "y_um")[k]:
                v[:, k] = profile_offsets_um(v[:, k], "pixel", path, pixel_um, None, f"column {name!r}")
    return checked_psf_image(path, v, lines)


def checked_psf_image(path: Path, v: np.ndarray, lines: np.ndarray | None = None
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """An image's points ``v[:, (x_um, y_um, intensity)]`` as every reader returns them:
    sorted by (y, x), points whose intensity is NaN left out (masked pixels: bad pixels,
    cosmic rays), refused (naming ``path`` and, where given, the line) for a non-finite
    coordinate, an infinite intensity, fewer than 25 valid samples, a duplicate point or a
    total flux <= 0."""
    v = np.asarray(v, float)
    lines = np.zeros(v.shape[0], int) if lines is None else np.asarray(lines)
    line = (lambda k: int(lines[k]) if lines[k] else None)
    bad, masked = _unreadable_and_masked(v)
    if bad.any():
        raise parse_error(path, line(int(np.flatnonzero(bad)[0])), "x_um and y_um must be finite numbers and "
                                                                  "intensity finite or nan (masked)")
    v, lines = v[~masked], lines[~masked]
    if v.shape[0] < 25:
        raise parse_error(path, None, f"needs >= 25 valid samples, found {v.shape[0]}")
    order = np.lexsort((v[:, 0], v[:, 1]))
    v, lines = v[order], lines[order]
    dup = np.flatnonzero((np.diff(v[:, 0]) == 0) & (np.diff(v[:, 1]) == 0))
    if dup.size:
        raise parse_error(path, line(dup[0] + 1), f"duplicate point x_um={v[dup[0], 0]:g}, y_um={v[dup[0], 1]:g}")
    flux = float(v[:, 2].sum())
    if not flux > 0:
        raise parse_error(path, None, f"no flux: the total flux (sum of intensity) is {flux:g}, must be > 0")
    return v[:, 0], v[:, 1], v[:, 2]


def write_psf_image_csv(path: str | Path, x_um: np.ndarray, y_um: np.ndarray, intensity: np.ndarray) -> None:
    """CSV ``x_um,y_um,intensity`` (header, one sample per line), written atomically."""
    with atomic_write(Path(path)) as fh:
        fh.write("x_um,y_um,intensity\n")
        for a, b, c in zip(np.ravel(x_um), np.ravel(y_um), np.ravel(intensity)):
            fh.write(f"{a:.3f},{b:.3f},{c:.6g}\n")
