"""FITS files (``astropy.io.fits``): line profiles, point-source images and sag maps as
astronomical detectors, their pipelines and many laboratory tools write them.

What is read
------------
* **Line profile**: the first HDU holding a 1-D image (a degenerate axis of length 1 is
  dropped, so a ``1 x n`` extraction is 1-D too), else the first binary table with an
  intensity column (``intensity``, ``flux``, ``counts``, ``signal``, ``data``, ``value``,
  with or without a unit in the name, :mod:`pipeline.io.columns`) and an axis column
  (``offset``, ``wave``/``wavelength``/``lambda``, ``pixel``) — a table of one
  row whose cells are arrays (the ESO spectroscopic data-product layout) is read as those
  arrays —, else a 2-D detector cut-out around the line, summed along the slit as the line
  profiles are. The cut-out's dispersion is the axis its WCS declares spectral (a wavelength
  ``CTYPE``: ``WAVE``, ``AWAV``…, or a ``CUNIT`` in nm or Angstrom), along ``NAXIS1`` or
  ``NAXIS2``; with no spectral axis (no WCS, or pixel / linear axes) ``NAXIS1`` is the
  dispersion and ``NAXIS2`` the slit. Two spectral axes, or a spectral axis of one pixel
  (an image at one wavelength), are refused naming the ``CTYPE``/``CUNIT`` keys. The
  profile's axis comes from the WCS (``CRVALi``, ``CRPIXi``, ``CDELTi`` or ``CDi_i``,
  ``PCi_i``, ``CUNITi``, ``CTYPEi``, via ``astropy.wcs``; a length ``CUNITi`` in another
  spelling, ``Angstroms``, ``micron``, ``nanometer``, is read as the standard's) or the
  column's ``TUNIT``.
* **Point-source image**: the first 2-D image HDU; ``NAXIS1`` is x (dispersion), ``NAXIS2``
  y (along the slit). NaN pixels (or ``BLANK`` in integer data) are masked points and are
  left out.
* **Sag map**: the first 2-D image HDU; ``NAXIS1`` is x, ``NAXIS2`` y, NaN or ``BLANK`` no
  data; the sag unit is ``BUNIT`` (nm, µm, mm, m, Angstrom, or waves with the reader's
  ``wavelength_um``).

Axes and units
--------------
An axis is a **wavelength** if its ``CTYPE`` is a wavelength type (``WAVE``, ``AWAV``,
``LAMBDA``, ``WAVELENGTH``…) or its unit is Angstrom or nm (no detector offset is given in
those), a **length** (µm, mm, m; detector offset or map coordinate) if it has such a unit
(a profile's offsets spanning under 1 µm are refused: a wavelength in µm without its
``CTYPE``), and in
**pixels** if it has no WCS on that axis or its unit is ``pixel``: a profile's pixels
are the detector's (``pixel_um``), an image's too; a map in pixels needs ``spacing_mm`` or
``extent_mm`` as a CODE V INT file does. ``BSCALE``/``BZERO`` are applied by astropy;
counts in any normalisation, negative background-subtracted samples and pedestals are
data (the diagnosis fits flux and background). Rotated or skewed WCS (off-diagonal
``CD``/``PC`` terms), IRAF's log-linear (``DC-FLAG = 1``) and multispec dispersions, tabulated
(``-TAB``) axes, and
non-length, non-wavelength axes are refused by name: resample to a linear, axis-aligned
grid first.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from optics.sagmap import SagMap
from pipeline.io.columns import INTENSITY, TABLE_AXIS_STEMS
from pipeline.io.common import ascii_label, atomic_path, parse_error
from pipeline.io.gridding import SAG_UNITS_TO_UM, GridUnknownError, grid_from_options, sag_unit_factor
from pipeline.io.measured import checked_profile, checked_psf_image, profile_offsets_um

__all__ = ["FITS_SUFFIXES", "read_line_profile_fits", "read_psf_image_fits", "read_sag_fits", "write_sag_fits"]

#: Suffixes of FITS files.
FITS_SUFFIXES = (".fits", ".fit", ".fts")
#: CTYPE prefixes of wavelength axes (FITS WCS paper III: vacuum, air, velocity-wavelength);
#: a type starting ``WAVELEN`` (``WAVELENGTH``, which pipelines write outside the standard) too.
_WAVELENGTH_CTYPES = ("WAVE", "AWAV", "VWAV", "LAMBDA", "WAVELEN")
#: CTYPE prefixes of spectral axes that are not a wavelength (refused on a profile's axis).
_OTHER_SPECTRAL_CTYPES = ("FREQ", "ENER", "WAVN", "VRAD", "VOPT", "ZOPT", "VELO", "BETA")
#: Length units (to µm): the project's spellings (Angstrom among them) and the FITS ``um``.
_LENGTH_TO_UM = dict(SAG_UNITS_TO_UM)
#: Units that are a wavelength on a profile's axis, not a detector offset: Angstrom and nm in
#: any spelling (no detector offset is given in those).
_WAVELENGTH_UNITS = frozenset(u for u, f in _LENGTH_TO_UM.items() if f <= 1e-3)
#: The FITS standard's spelling of each length unit (WCS paper I), by its factor to µm: wcslib
#: refuses ``Angstroms``, ``micron`` or ``nanometer`` on a spectral axis, which files carry.
_FITS_LENGTH_UNITS = {1e-4: "Angstrom", 1e-3: "nm", 1.0: "um", 1e3: "mm", 1e6: "m"}
#: Narrowest span (µm) of a profile's offsets: no line at the detector is narrower (its
#: diffraction core alone is ``wavelength x f-number`` >= 1 µm in the near infrared), while
#: a window of a spectrum in µm of wavelength spans a small fraction of one.
_MIN_OFFSET_SPAN_UM = 1.0
#: CTYPE prefixes of an axis in detector pixels.
_PIXEL_CTYPES = ("PIXEL", "PIX", "PX")
#: Header keywords that put an axis ``i`` under a WCS (without any of them it is in pixels).
_WCS_KEYS = ("CTYPE{i}", "CUNIT{i}", "CRVAL{i}", "CDELT{i}", "CD{i}_{i}")


def _open(path: Path):
    from astropy.io import fits

    if not path.exists():
        raise ValueError(f"{path}: file does not exist")
    try:
        hdul = fits.open(path, memmap=False)
        hdul.verify("silentfix")
        return hdul
    except (OSError, ValueError, TypeError) as exc:
        raise ValueError(f"{path}: not a readable FITS file ({type(exc).__name__}: {exc})") from None


def _images(hdul) -> list:
    """(index, data as float with masked values NaN, header) of every image HDU with data."""
    from astropy.io import fits

    out = []
    for i, h in enumerate(hdul):
        if isinstance(h, (fits.PrimaryHDU, fits.ImageHDU, fits.CompImageHDU)) and h.data is not None:
            data = np.asarray(h.data)
            if np.iscomplexobj(data) or not np.issubdtype(data.dtype, np.number):
                continue
            out.append((i, data.astype(float), h.header))
    return out


def _image(path: Path, hdul, ndim: int, what: str) -> tuple[np.ndarray, object, list[int]]:
    """The first image HDU with ``ndim`` non-degenerate axes: (data squeezed, header, the
    FITS axis numbers (1-based) kept, in FITS order)."""
    shapes = []
    for i, data, header in _images(hdul):
        axes = [k for k in range(1, data.ndim + 1) if data.shape[data.ndim - k] > 1]
        shapes.append(f"HDU {i}: {data.shape}")
        if len(axes) == ndim:
            return data.squeeze(), header, axes
    found = "; ".join(shapes) if shapes else "no image data"
    raise parse_error(path, None, f"no {ndim}-D image for a {what} (found {found})")


def _image_2d(path: Path, what: str, unit_needed: bool = True) -> tuple[np.ndarray, list, object]:
    """The first 2-D image of a FITS file: (data[y, x] as float, masked values NaN;
    [(pixel-or-WCS values, the same in µm or None where the axis is in pixels)] for x and
    y; its header)."""
    with _open(path) as hdul:
        data, header, axes = _image(path, hdul, 2, what)
        naxis = header.get("NAXIS", 2)
        out = []
        for k, n in zip(axes, (data.shape[1], data.shape[0])):
            v, unit, _ = _axis(path, header, k, n, naxis, unit_needed)
            try:
                f = _unit_to_um(unit)
            except ValueError as exc:
                raise parse_error(path, None, f"axis {k}: {exc}") from None
            out.append((v, None if f is None else v * f))
        return data, out, header.copy()


def _unit_to_um(unit: str) -> float | None:
    """µm per unit of a length ``unit`` string, None for pixels / no unit; an unknown
    unit is a ValueError naming it."""
    u = str(unit).strip()
    if u.lower() in ("", "pixel", "pixels", "pix", "px"):
        return None
    if u.lower() in _LENGTH_TO_UM:
        return _LENGTH_TO_UM[u.lower()]
    import astropy.units as au

    try:
        q = au.Unit(u, parse_strict="raise")
    except ValueError:
        q = None
    if q is None or q.physical_type != "length":
        raise ValueError(f"unit {u!r} is not a length (valid: Angstrom, nm, um, mm, m, or pixel)")
    return float(q.to(au.um))


def _axis(path: Path, header, axis: int, n: int, naxis: int, unit_needed: bool = True) -> tuple[np.ndarray, str, str]:
    """Values of FITS axis ``axis`` (1-based) of ``n`` samples: (values, unit, ctype). The
    unit is "" for an axis without a WCS (pixel numbers 1..n). A WCS without a unit (no
    ``CUNIT``, none in IRAF's ``WAT`` cards) whose step is not one (pixel numbers) is
    refused where ``unit_needed`` (a profile's or an image's axis, which would otherwise be
    read as pixels; a sag map's axes in pixels need ``spacing_mm`` anyway)."""
    from astropy.wcs import WCS

    if not any(k.format(i=axis) in header for k in _WCS_KEYS):
        return np.arange(1.0, n + 1.0), "", ""
    header = _standard_units(header, naxis)
    if str(header.get(f"CTYPE{axis}", "")).strip().upper().endswith("-TAB"):
        # its coordinates are in another HDU's table, which a header alone does not give
        raise parse_error(path, None, f"axis {axis}: CTYPE{axis}={header[f'CTYPE{axis}']!r} is a tabulated (-TAB) axis, "
                                      "which is not read; write the profile as a binary table with a wavelength "
                                      "column and its TUNIT, or resample it onto a linear axis (CRVAL/CDELT)")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            w = WCS(header, naxis=naxis, relax=True, fix=True)
            scale = np.asarray(w.pixel_scale_matrix)
            if naxis > 1 and np.any(scale[~np.eye(scale.shape[0], dtype=bool)] != 0):
                raise parse_error(path, None, "rotated or skewed WCS (off-diagonal CD/PC terms) is not supported; "
                                              "resample the image to axis-aligned rows and columns")
            sub = w.sub([axis])
            values = np.asarray(sub.pixel_to_world_values(np.arange(n, dtype=float)), float).ravel()
            unit = str(sub.wcs.cunit[0])
            ctype = str(sub.wcs.ctype[0]).upper()
    except ValueError as exc:
        if str(path) in str(exc):
            raise
        raise parse_error(path, None, f"axis {axis}: WCS not readable ({' '.join(str(exc).split())})") from None
    if not np.isfinite(values).all():
        raise parse_error(path, None, f"axis {axis}: the WCS gives non-finite coordinates")
    if not unit and f"CUNIT{axis}" not in header:
        wat = _iraf_unit(header, axis)
        if wat is not None:  # IRAF writes the unit in its WAT cards, not in CUNIT
            return values, wat, ctype if ctype and ctype != "LINEAR" else "WAVE"
        # a step of one is pixel numbers (a cut-out keeps the detector's: CRVAL 1024); any
        # other step is a physical axis whose unit the file does not say
        if (unit_needed and ctype.split("-")[0] not in _PIXEL_CTYPES
                and not np.allclose(np.abs(np.diff(values)), 1.0, rtol=0.0, atol=1e-9)):
            keys = ", ".join(f"{k.format(i=axis)}={header[k.format(i=axis)]!r}" for k in _WCS_KEYS
                             if k.format(i=axis) in header)
            raise parse_error(path, None, f"axis {axis} has a WCS ({keys}) but no unit, so its coordinates "
                                          f"({values[0]:g}, {values[1] if n > 1 else values[0]:g}, ...) could be "
                                          f"a wavelength, a length or pixels; add CUNIT{axis} (Angstrom, nm, um, "
                                          "mm, or pixel)")
    return values, unit, ctype


def _standard_units(header, naxis: int):
    """``header``, or a copy with each ``CUNITi`` that is a length in another spelling
    (``Angstroms``, ``micron``, ``nanometer``: :data:`_LENGTH_TO_UM`) written as the FITS
    standard spells it, which wcslib requires of a spectral axis."""
    fixes = {}
    for i in range(1, naxis + 1):
        u = str(header.get(f"CUNIT{i}", "")).strip()
        f = _LENGTH_TO_UM.get(u.lower())
        if f in _FITS_LENGTH_UNITS and u != _FITS_LENGTH_UNITS[f]:
            fixes[f"CUNIT{i}"] = _FITS_LENGTH_UNITS[f]
    if not fixes:
        return header
    header = header.copy()
    for k, v in fixes.items():
        header[k] = v
    return header


def _iraf_unit(header, axis: int) -> str | None:
    """The length unit IRAF's ``WAT<axis>_nnn`` cards give (``units=angstroms``), else None."""
    wat = "".join(str(header[k]) for k in sorted(k for k in header if k.startswith(f"WAT{axis}_")))
    for word in wat.split():
        key, _, value = word.partition("=")
        if key.lower() == "units":  # "angstroms", "nanometers", "microns": spellings _LENGTH_TO_UM holds
            u = value.strip().lower()
            return u if u in _LENGTH_TO_UM else None
    return None


def _is_wavelength(ctype: str, unit: str) -> bool:
    """Whether an axis of this ``CTYPE`` and unit is a wavelength (see the module notes)."""
    head = str(ctype).strip().upper().split("-")[0]
    return (head in _WAVELENGTH_CTYPES or head.startswith("WAVELEN")
            or str(unit).strip().lower() in _WAVELENGTH_UNITS)


def _is_spectral(header, axis: int) -> bool:
    """Whether the header declares FITS axis ``axis`` spectral: a wavelength (:func:`_is_wavelength`)
    or another spectral ``CTYPE`` (frequency, energy, velocity...)."""
    ctype, unit = str(header.get(f"CTYPE{axis}", "")), str(header.get(f"CUNIT{axis}", ""))
    return _is_wavelength(ctype, unit) or ctype.strip().upper().split("-")[0] in _OTHER_SPECTRAL_CTYPES


def _dispersion_axis(path: Path, header, axes: list[int]) -> int:
    """The FITS axis (1-based) along the dispersion among the image's ``axes``: the one the
    WCS declares spectral; without any spectral axis the first (``NAXIS1``). Two spectral
    axes, or a spectral axis only among the degenerate ones (an image at one wavelength),
    are refused naming the header keys."""
    naxis = int(header.get("NAXIS", len(axes)))
    spectral = [k for k in range(1, naxis + 1) if _is_spectral(header, k)]
    kept = [k for k in spectral if k in axes]

    def keys(ks):
        return ", ".join(f"{key}{k}={header[f'{key}{k}']!r}" for k in ks for key in ("CTYPE", "CUNIT")
                         if f"{key}{k}" in header)

    accepted = ("a profile image needs exactly one spectral axis along the dispersion (CTYPE "
                f"{'/'.join(_WAVELENGTH_CTYPES)}, or CUNIT nm/Angstrom) with the other along the slit, "
                "or no spectral axis at all, when NAXIS1 is the dispersion")
    if len(kept) > 1:
        raise parse_error(path, None, f"ambiguous dispersion axis: axes {kept} are all spectral ({keys(kept)}); "
                                      + accepted)
    if kept:
        return kept[0]
    if spectral:
        raise parse_error(path, None, f"the spectral axis ({keys(spectral)}) has a single pixel: the image is at one "
                                      "wavelength, not a line profile; " + accepted)
    return axes[0]


def _profile_axis(path: Path, values: np.ndarray, unit: str, ctype: str, source: str = "the axis",
                  declare: str = "CTYPE = 'WAVE'") -> tuple[np.ndarray, str]:
    """(values in µm or pixels, axis kind for :func:`profile_offsets_um`). A length axis not
    declared a wavelength whose values span less than :data:`_MIN_OFFSET_SPAN_UM` is refused:
    such offsets hold no line, while a wavelength in µm of a line's window does span so
    little, so the file is asked to ``declare`` it (``source`` names the axis)."""
    is_wave = _is_wavelength(ctype, unit)
    try:
        f = _unit_to_um(unit)
    except ValueError as exc:
        raise parse_error(path, None, f"axis ({ctype or 'no CTYPE'}): {exc}") from None
    if ctype and ctype.split("-")[0] in _OTHER_SPECTRAL_CTYPES:
        raise parse_error(path, None, f"axis CTYPE {ctype!r} is not a wavelength or a length; give the profile on "
                                      "a wavelength (WAVE), detector-offset (µm) or pixel axis")
    if f is None:
        if is_wave:
            raise parse_error(path, None, f"wavelength axis CTYPE {ctype!r} has no unit (CUNIT)")
        return values, "pixel"
    span_um = float(np.nanmax(values) - np.nanmin(values)) * f if values.size else 0.0
    if not is_wave and span_um < _MIN_OFFSET_SPAN_UM:
        raise parse_error(path, None, f"{source} (unit {unit!r}, CTYPE {ctype or 'none'}) reads as detector offsets "
                                      f"spanning {span_um:.3g} µm, below the {_MIN_OFFSET_SPAN_UM:g} µm of any line at "
                                      f"the detector: if it is a wavelength, declare it ({declare})")
    return values * f, ("wavelength_um" if is_wave else "offset_um")


def _profile_image(path: Path, hdul, ndim: int) -> tuple | None:
    """(axis values, intensity, unit, ctype, (the axis in words, how to declare it a
    wavelength)) of the first ``ndim``-D image, else None. A
    2-D frame is summed along the slit, as the line profiles are: each slit line's valid
    pixels, scaled to the full line where some are masked (a line with none is left out).
    The dispersion is the axis the WCS declares spectral (:func:`_dispersion_axis`),
    ``NAXIS1`` when none is."""
    try:
        data, header, axes = _image(path, hdul, ndim, "line profile")
    except ValueError:
        return None
    dispersion = _dispersion_axis(path, header, axes)
    if ndim == 2:
        np_axis = {k: len(axes) - 1 - i for i, k in enumerate(axes)}  # numpy lists the FITS axes last first
        slit = np_axis[next(k for k in axes if k != dispersion)]
        valid = np.isfinite(data).sum(axis=slit)
        with np.errstate(invalid="ignore", divide="ignore"):
            y = np.where(valid > 0, np.nansum(data, axis=slit) * data.shape[slit] / valid, np.nan)
    else:
        y = data.ravel()
    ctype = str(header.get(f"CTYPE{dispersion}", "")).upper()
    if header.get("DC-FLAG", 0) == 1 or ctype.startswith("MULTISPE"):
        # IRAF's log-linear and multispec dispersions look linear to a WCS reader
        raise parse_error(path, None, "IRAF log-linear (DC-FLAG = 1) or multispec wavelength axis; resample the "
                                      f"spectrum onto a linear axis (CRVAL{dispersion}/CDELT{dispersion}) or "
                                      "write it as a table")
    a, unit, ctype = _axis(path, header, dispersion, y.size, header.get("NAXIS", ndim))
    return a, y, unit, ctype, (f"axis {dispersion}", f"CTYPE{dispersion} = 'WAVE', or 'AWAV' in air")


def _table_profile(path: Path, hdul) -> tuple | None:
    """(axis values, intensity, unit, axis kind name, (the column in words, how to declare it
    a wavelength)) of the first binary table with an intensity and an axis column, else None."""
    from astropy.io import fits

    for h in hdul:
        if not isinstance(h, fits.BinTableHDU) or h.data is None or len(h.data) == 0:
            continue
        names = {n.lower(): n for n in h.columns.names}
        iname = (INTENSITY.find(h.columns.names) or (None,))[0]
        axis = next(((names[k], kind) for stem, kind in TABLE_AXIS_STEMS for k in names
                     if k == stem or k.startswith(stem + "_")), None)
        if iname is None or axis is None:
            continue
        aname, kind = axis
        col = h.columns[aname]
        a = np.asarray(h.data[aname], float)
        y = np.asarray(h.data[iname], float)
        if a.ndim == 2 and a.shape[0] == 1:  # one row of arrays (ESO data products)
            a, y = a[0], y[0]
        unit = col.unit or ""
        suffix = aname.lower().rpartition("_")[2]
        if not unit and aname.lower() != kind and suffix in _LENGTH_TO_UM:  # wave_nm, offset_mm
            unit = suffix
        ctype = "WAVE" if kind == "wavelength_um" else ("PIXEL" if kind == "pixel" else "")
        if not unit and kind == "offset_um":
            raise parse_error(path, None, f"table column {aname!r} has no unit (TUNIT), so its values could be "
                                          "µm, mm or pixels; give its TUNIT (um, mm) or name it offset_um, or "
                                          "put the axis in a pixel column")
        return (a.ravel(), y.ravel(), unit, ctype,
                (f"table column {aname!r}", "name the column WAVELENGTH, WAVE or LAMBDA"))
    return None


def read_line_profile_fits(path: str | Path, normalise: bool = True, pixel_um: float | None = None,
                           dispersion_um_per_um: float | None = None,
                           line_wavelength_um: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Read a line profile from a FITS file (a 1-D image with a WCS, a binary table, or a
    2-D cut-out summed along the slit: the dispersion is the axis the WCS declares
    spectral, ``NAXIS1`` when none is).

    Parameters
    ----------
    path : str or Path
        The FITS file.
    normalise : bool
        Divide by the total flux (unit area over ``offset_um``).
    pixel_um : float, optional
        Detector pixel pitch (µm) for an axis in pixels (no WCS, ``CUNIT1 = 'pixel'``).
    dispersion_um_per_um : float, optional
        Signed linear dispersion (detector µm per µm of wavelength) for a wavelength
        axis.
    line_wavelength_um : float, optional
        The line's wavelength (µm): a wavelength axis's offsets are taken about it;
        without it, about the axis's median wavelength
        (:func:`pipeline.io.measured.profile_offsets_um`).

    Returns
    -------
    offset_um, intensity : ndarray, shape (n,)
        Sorted by offset; as :func:`pipeline.io.measured.read_line_profile`.

    Raises
    ------
    ValueError
        Naming the file: no 1-D image or profile table, an axis that is neither a
        wavelength, a length nor pixels, a cut-out with two spectral axes or a spectral
        axis of one pixel, a missing ``pixel_um``/dispersion, non-finite
        values, fewer than 5 offsets, total flux <= 0.
    """
    path = Path(path)
    with _open(path) as hdul:
        found = _profile_image(path, hdul, 1) or _table_profile(path, hdul) or _profile_image(path, hdul, 2)
    if found is None:
        raise parse_error(path, None, "no 1-D or 2-D image and no binary table with an intensity column "
                                      f"({INTENSITY.describe()}) and an axis column (offset, wavelength, pixel)")
    a, y, unit, ctype, (source, declare) = found
    values, kind = _profile_axis(path, a, unit, ctype, source, declare)
    x = profile_offsets_um(values, kind, path, pixel_um, dispersion_um_per_um, "FITS axis", line_wavelength_um)
    return checked_profile(path, x, y, normalise)  # masks NaN samples, refuses inf


def read_psf_image_fits(path: str | Path, pixel_um: float | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Read a point-source image from the first 2-D image HDU of a FITS file.

    Parameters
    ----------
    path : str or Path
        The FITS file; ``NAXIS1`` along the dispersion, ``NAXIS2`` along the slit.
    pixel_um : float, optional
        Sample pitch (µm) of axes in pixels (no WCS or ``CUNIT = 'pixel'``): the
        detector's pixel for a detector frame.

    Returns
    -------
    x_um, y_um, intensity : ndarray, shape (n,)
        The valid pixels (NaN / ``BLANK`` left out), sorted by (y, x).
    """
    path = Path(path)
    data, axes, _ = _image_2d(path, "point-source image")
    coords = []
    for k, (v, um) in enumerate(axes, start=1):
        if um is None:
            if pixel_um is None or not (np.isfinite(pixel_um) and pixel_um > 0):
                raise parse_error(path, None, f"axis {k} is in pixels: give pixel_um, the sample pitch in µm "
                                              f"(> 0), or a WCS in µm (CUNIT{k}, CDELT{k}); got "
                                              f"pixel_um={pixel_um!r}")
            um = v * pixel_um
        coords.append(um)
    X, Y = np.meshgrid(coords[0], coords[1])
    return checked_psf_image(path, np.column_stack([X.ravel(), Y.ravel(), data.ravel()]))  # masks NaN pixels


def read_sag_fits(path: str | Path, spacing_mm=None, extent_mm=None, wavelength_um: float | None = None) -> SagMap:
    """Read a sag map from the first 2-D image HDU of a FITS file.

    Parameters
    ----------
    path : str or Path
        The FITS file: ``sag[y, x]`` with ``NAXIS1`` along x (dispersion), NaN or
        ``BLANK`` = no data, the sag unit in ``BUNIT``.
    spacing_mm, extent_mm : optional
        Grid of an image without a length WCS (as for CODE V INT files); refused
        when the WCS gives one.
    wavelength_um : float, optional
        Wavelength (µm) of one wave, for ``BUNIT = 'waves'``.

    Raises
    ------
    GridUnknownError
        The image has no length WCS and neither grid option is given.
    ValueError
        Naming the file: no 2-D image, no or unknown ``BUNIT``, a rotated WCS.
    """
    path = Path(path)
    data, axes, header = _image_2d(path, "sag map", unit_needed=False)
    bunit = str(header.get("BUNIT", "")).strip()
    axes_mm = [None if um is None else um * 1e-3 for _, um in axes]
    units = [str(header.get(f"CUNIT{k}", "")) for k in (1, 2)]
    if not bunit:
        raise parse_error(path, None, "BUNIT (the sag unit: nm, um, mm, m, Angstrom or waves) is missing")
    try:
        factor = _LENGTH_TO_UM[bunit.lower()] if bunit.lower() in _LENGTH_TO_UM else sag_unit_factor(bunit, wavelength_um)
    except ValueError as exc:
        raise parse_error(path, None, f"BUNIT: {exc}") from None
    grid = "header WCS"
    if any(a is None for a in axes_mm):
        given = grid_from_options(data.shape[1], data.shape[0], extent_mm, spacing_mm)
        if given is None:
            raise GridUnknownError(f"{path}: the image's axes are in pixels (no length CUNIT/CDELT)")
        axes_mm[0], axes_mm[1], grid = given
    elif spacing_mm is not None or extent_mm is not None:
        raise parse_error(path, None, f"spacing_mm/extent_mm given, but the header's WCS already gives the grid "
                                      f"(CUNIT {units}); leave them out")
    if np.isinf(data).any():
        raise parse_error(path, None, f"{int(np.isinf(data).sum())} infinite sag values; use NaN for no data")
    x, y, sag = axes_mm[0], axes_mm[1], data * factor
    if x.size > 1 and x[0] > x[-1]:
        x, sag = x[::-1], sag[:, ::-1]
    if y.size > 1 and y[0] > y[-1]:
        y, sag = y[::-1], sag[::-1]
    try:
        return SagMap(x, y, sag, path.stem, {"format": "fits", "source_units": bunit, "grid_source": grid})
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}") from None


def write_sag_fits(sagmap: SagMap, path: str | Path) -> Path:
    """Write ``sagmap`` as a FITS primary image ``sag[y, x]`` in µm (``BUNIT = 'um'``), NaN
    no data, with a linear WCS in mm (``CRPIX = 1`` at the first sample, ``CDELT`` the
    grid steps), atomically."""
    from astropy.io import fits

    hdu = fits.PrimaryHDU(np.asarray(sagmap.sag_um, dtype=np.float64))
    h = hdu.header
    h["BUNIT"] = ("um", "surface sag along +z, NaN = no data")
    for i, (name, a) in enumerate((("x, dispersion", sagmap.x_mm), ("y, ruling direction", sagmap.y_mm)), start=1):
        step = float(a[1] - a[0]) if a.size > 1 else 1.0
        h[f"CTYPE{i}"] = ("LINEAR", name)
        h[f"CUNIT{i}"] = "mm"
        h[f"CRPIX{i}"] = 1.0
        h[f"CRVAL{i}"] = float(a[0])
        h[f"CDELT{i}"] = step
    h["OBJECT"] = ascii_label(sagmap.label, 68)  # a FITS card is printable ASCII
    path = Path(path)
    with atomic_path(path) as tmp:
        hdu.writeto(tmp, overwrite=True)
    return path
