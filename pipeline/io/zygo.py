"""Zygo interferometer maps: MetroPro binary (``.dat``), Mx HDF5 (``.datx``) and MetroPro
ASCII (``.asc``) files, read into a :class:`optics.sagmap.SagMap`.

What the three have in common (MetroPro Reference Guide, "Data Format"):

* the phase map is stored in integer *counts*; a height in metres is
  ``counts * S * O * lambda / R`` with ``S`` the interferometric scale factor (0.5 for a
  surface measured in reflection: the map is then the surface's height), ``O`` the
  obliquity factor, ``lambda`` the wavelength (m) and ``R`` the phase resolution
  (4096, 32768 or 131072 for the header's ``PhaseRes`` 0, 1, 2); ``DataSign`` 1 inverts it;
* a count at or above 2147483640 marks an invalid pixel (NaN here: masked points are data);
* rows are stored from the top of the camera frame down, left to right: the first row
  gets the largest ``y``, so ``x`` runs right and ``y`` up as the instrument displays them;
* the lateral scale is the camera resolution (m per pixel); a file without one (0: the
  instrument was not calibrated) needs ``spacing_mm``.

The map's origin is the centre of the valid pixels' bounding box (an interferometer has
no absolute frame; the part's aperture is centred that way), recorded in
``meta["origin_pixel"]`` with the scale factors read. The ``.dat`` files are read with
prysm (``pip install 'cryograting[zygo]'``), the ``.datx`` files with h5py (prysm's reader
takes fewer of their units and layouts); prysm has no reader of the ASCII export, so that
one is ours. A Zygo ``.dat`` is told from a Zemax Grid Sag
``.dat`` by its first four bytes (:func:`is_zygo_dat`), never by the suffix.
"""

from __future__ import annotations

import re
import shlex
import struct
from pathlib import Path

import numpy as np

from optics.sagmap import SagMap
from pipeline.io.common import parse_error, read_text

__all__ = ["ZYGO_DAT_MAGIC", "INVALID_COUNTS", "PHASE_RESOLUTION", "is_zygo_dat", "read_zygo_dat",
           "read_zygo_datx", "read_zygo_ascii", "DATX_UNITS_UM"]

#: First four bytes (big-endian) of a MetroPro binary file, header formats 1, 2 and 3.
ZYGO_DAT_MAGIC = (0x881B036F, 0x881B0370, 0x881B0371)
#: Counts at or above this mark an invalid pixel.
INVALID_COUNTS = 2147483640
#: ``PhaseRes`` header value -> counts per wave ``R``.
PHASE_RESOLUTION = {0: 4096, 1: 32768, 2: 131072}

_INSTALL = "pip install 'cryograting[zygo]'"


def is_zygo_dat(path: str | Path) -> bool:
    """True when ``path`` starts with a MetroPro binary file's magic number."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(4)
    except OSError:
        return False
    return len(head) == 4 and struct.unpack(">I", head)[0] in ZYGO_DAT_MAGIC


def _check_spacing(spacing_mm) -> float | None:
    if spacing_mm is None:
        return None
    try:
        v = float(spacing_mm)
    except (TypeError, ValueError):
        v = float("nan")
    if not (np.isfinite(v) and v > 0):
        raise ValueError(f"spacing_mm={spacing_mm!r} must be a finite number of mm > 0")
    return v


def _to_map(path: Path, height_um: np.ndarray, resolution_m: float, spacing_mm: float | None,
            meta: dict) -> SagMap:
    """The map of ``height_um`` (rows from the top of the frame) with pixels of
    ``resolution_m`` (or ``spacing_mm`` when given), centred on the valid pixels."""
    if spacing_mm is None:
        if not (np.isfinite(resolution_m) and resolution_m > 0):
            raise ValueError(f"{path}: the file gives no lateral scale (camera resolution {resolution_m!r} m "
                             "per pixel); pass spacing_mm, the pixel pitch on the part in mm")
        spacing_mm = resolution_m * 1e3
    valid = np.isfinite(height_um)
    if not valid.any():
        raise ValueError(f"{path}: every pixel of the phase map is marked invalid")
    rows, cols = np.nonzero(valid)
    r0, c0 = 0.5 * (rows.min() + rows.max()), 0.5 * (cols.min() + cols.max())
    ny, nx = height_um.shape
    x = (np.arange(nx) - c0) * spacing_mm
    y = (r0 - np.arange(ny))[::-1] * spacing_mm
    meta = {**meta, "spacing_mm": spacing_mm, "origin_pixel": [float(c0), float(r0)],
            "frame": "x right, y up as displayed; origin at the centre of the valid pixels"}
    return SagMap(x, y, height_um[::-1].copy(), path.stem, meta)


def _height_um(counts: np.ndarray, scale: float, obliquity: float, wavelength_m: float, phase_res: int,
               sign: int, path: Path) -> np.ndarray:
    """Heights (µm) of integer phase counts, NaN at the invalid marker."""
    if phase_res not in PHASE_RESOLUTION:
        raise ValueError(f"{path}: PhaseRes={phase_res!r} is not one of {sorted(PHASE_RESOLUTION)}")
    for name, v in (("IntfScaleFactor", scale), ("ObliquityFactor", obliquity), ("WavelengthIn", wavelength_m)):
        if not (np.isfinite(v) and v > 0):
            raise ValueError(f"{path}: {name}={v!r} must be > 0 to turn counts into heights")
    counts = np.asarray(counts, dtype=np.int64)
    h = counts.astype(float) * (scale * obliquity * wavelength_m / PHASE_RESOLUTION[phase_res]) * 1e6
    h[counts >= INVALID_COUNTS] = np.nan
    return -h if sign == 1 else h


# ------------------------------------------------------------------ binary (.dat, .datx)
def _prysm_io(path: Path):
    try:
        from prysm import io
    except ModuleNotFoundError:
        raise ValueError(f"{path}: reading Zygo binary files needs prysm ({_INSTALL})") from None
    return io


def read_zygo_dat(path: str | Path, spacing_mm: float | None = None) -> SagMap:
    """Read a MetroPro binary ``.dat`` file (header formats 1–3) as a surface map.

    Parameters
    ----------
    path : str or Path
        The file.
    spacing_mm : float, optional
        Pixel pitch on the part, mm; overrides the file's camera resolution (needed when
        the file has none).
    """
    path = Path(path)
    spacing_mm = _check_spacing(spacing_mm)
    if not is_zygo_dat(path):
        raise ValueError(f"{path}: not a MetroPro binary file (its first four bytes are not one of "
                         f"{[hex(m) for m in ZYGO_DAT_MAGIC]})")
    io = _prysm_io(path)
    raw = path.read_bytes()
    try:
        meta = io.read_zygo_metadata(raw)
    except (struct.error, UnicodeDecodeError, IndexError) as exc:
        raise ValueError(f"{path}: MetroPro header unreadable ({type(exc).__name__}: {exc}); truncated?") from None
    header_len = int(meta["header"]["size"])
    ac, cn = meta["ac"], meta["cn"]
    n_int = int(ac["width"]) * int(ac["height"]) * max(int(ac["n_buckets"]), 1)
    pw, ph = int(cn["width"]), int(cn["height"])
    if pw * ph == 0:
        raise ValueError(f"{path}: the file holds no phase map (phase width x height = {pw} x {ph})")
    start = header_len + 2 * n_int
    if len(raw) < start + 4 * pw * ph:
        raise ValueError(f"{path}: {len(raw)} bytes; a {pw} x {ph} phase map after a {header_len}-byte header and "
                         f"{n_int} intensity samples needs {start + 4 * pw * ph} (truncated)")
    # counts straight from the file: prysm's own conversion ignores DataSign
    counts = np.frombuffer(raw, dtype=">i4", count=pw * ph, offset=start).reshape(ph, pw)
    h = _height_um(counts, float(meta["scale_factor"]), float(meta["obliquity_factor"]), float(meta["wavelength"]),
                   int(meta["phase_res"]), int(meta["sign"]), path)
    info = {"format": "zygo-dat", "intf_scale_factor": float(meta["scale_factor"]),
            "obliquity_factor": float(meta["obliquity_factor"]), "wavelength_um": float(meta["wavelength"]) * 1e6,
            "phase_res": int(meta["phase_res"]), "data_sign": int(meta["sign"])}
    return _to_map(path, h, float(meta["lateral_resolution"]), spacing_mm, info)


#: Mx ``Unit`` of a ``.datx`` surface -> µm per unit (``Fringes`` is scaled by the file's
#: factors instead, :func:`_datx_height_um`).
DATX_UNITS_UM = {"NanoMeters": 1e-3, "MicroMeters": 1.0, "MilliMeters": 1e3, "Meters": 1e6, "Angstroms": 1e-4}


def _attr(attrs, key, default=None):
    """A scalar HDF5 attribute (Mx stores each as a one-element array), bytes decoded."""
    if key not in attrs:
        return default
    v = np.asarray(attrs[key]).ravel()
    v = v[0] if v.size else default
    return v.decode("utf-8", "replace") if isinstance(v, bytes) else v


def _datx_height_um(phase: np.ndarray, attrs, path: Path) -> tuple[np.ndarray, dict]:
    """Heights (µm) of a ``.datx`` surface dataset with its attributes; NaN at ``No Data``."""
    unit = str(_attr(attrs, "Unit", "Fringes"))
    no_data = _attr(attrs, "No Data", INVALID_COUNTS)
    h = np.asarray(phase, dtype=float)
    h[~np.isfinite(h) | (h >= float(no_data))] = np.nan
    info = {"unit": unit}
    if unit == "Fringes":
        scale = float(_attr(attrs, "Interferometric Scale Factor", np.nan))
        obliquity = float(_attr(attrs, "Obliquity Factor", 1.0))
        wavelength_m = float(_attr(attrs, "Wavelength", np.nan))
        for name, v in (("Interferometric Scale Factor", scale), ("Obliquity Factor", obliquity),
                        ("Wavelength", wavelength_m)):
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"{path}: surface attribute {name!r}={v!r} must be > 0 to turn fringes into heights")
        info.update(intf_scale_factor=scale, obliquity_factor=obliquity, wavelength_um=wavelength_m * 1e6)
        return h * (scale * obliquity * wavelength_m * 1e6), info
    if unit not in DATX_UNITS_UM:
        raise ValueError(f"{path}: surface Unit={unit!r} is not one this reader knows; valid are "
                         f"{['Fringes', *DATX_UNITS_UM]}")
    return h * DATX_UNITS_UM[unit], info


def _datx_resolution_m(f, surface) -> float:
    """The lateral resolution (m per pixel): the ``Attributes`` group's ``Lateral
    Resolution`` (Mx), else the surface's ``X Converter`` (its parameter 1, as MetroPro's
    HDF5 export and older files keep it); NaN where neither gives one."""
    for group in f.get("Attributes", {}).values():
        for key, value in group.attrs.items():
            # "Data Context.Lateral Resolution:Value", "Data Context.Data Attributes.Resolution:Value"
            if re.search(r"(^|\.)(Lateral )?Resolution:Value$", key):
                try:
                    v = float(np.asarray(value).ravel()[0])
                except (TypeError, ValueError, IndexError):
                    raise ValueError(f"{f.filename}: attribute {key}={value!r} is not a lateral resolution "
                                     "(m per pixel > 0); pass spacing_mm, the pixel pitch on the part in mm") from None
                if np.isfinite(v) and v > 0:
                    return v
    conv = surface.attrs.get("X Converter")
    try:
        v = float(np.asarray(conv).ravel()[0]["Parameters"][1])
    except (TypeError, ValueError, IndexError, KeyError):
        return float("nan")
    return v if np.isfinite(v) and v > 0 else float("nan")


def read_zygo_datx(path: str | Path, spacing_mm: float | None = None) -> SagMap:
    """Read a Zygo Mx ``.datx`` (HDF5) file's surface as a map (h5py).

    The surface is the first dataset of ``Data/Surface`` (``Measurement/Surface`` in older
    files), in ``Fringes`` (times the interferometric scale factor, the obliquity factor and
    the wavelength) or in a length unit (:data:`DATX_UNITS_UM`); values at or above its
    ``No Data`` attribute, and NaN, are invalid. The lateral scale is the ``Attributes``
    group's lateral resolution, else the surface's ``X Converter``.
    Ours rather than prysm's ``read_zygo_datx``, which takes only fringes and nanometres and
    needs the ``Attributes`` group (``tests/test_zygo.py`` shows both).

    Parameters as :func:`read_zygo_dat`.
    """
    path = Path(path)
    spacing_mm = _check_spacing(spacing_mm)
    try:
        import h5py
    except ModuleNotFoundError:
        raise ValueError(f"{path}: reading .datx files needs h5py ({_INSTALL})") from None
    try:
        f = h5py.File(path, "r")
    except OSError as exc:
        raise ValueError(f"{path}: not an HDF5 file, so not a Zygo .datx ({exc})") from None
    with f:
        group = next((f[g] for g in ("Data/Surface", "Measurement/Surface") if g in f), None)
        if isinstance(group, h5py.Group):
            group = next((group[k] for k in group if isinstance(group[k], h5py.Dataset)), None)
        if not isinstance(group, h5py.Dataset) or group.ndim != 2:
            raise ValueError(f"{path}: no 2-D surface dataset under 'Data/Surface' or 'Measurement/Surface'; "
                             f"the file holds {sorted(f)}")
        height_um, info = _datx_height_um(group[()], group.attrs, path)
        res = _datx_resolution_m(f, group) if spacing_mm is None else float("nan")  # spacing_mm overrides it
    return _to_map(path, height_um, res, spacing_mm, {"format": "zygo-datx", **info})


# ------------------------------------------------------------------ ASCII (.asc)
def _header_tokens(path: Path, lines: list[str], k: int, n: int, what: str) -> list[str]:
    """The first ``n`` whitespace tokens of header line ``k`` (1-based), quoted strings kept whole."""
    try:
        tok = shlex.split(lines[k - 1], posix=True)
    except (ValueError, IndexError):
        tok = []
    if len(tok) < n:
        raise parse_error(path, k, f"expected the {n} fields {what}")
    return tok


def _number(path: Path, k: int, token: str, name: str, kind=float):
    """Header field ``name`` of line ``k`` as a float, or (``kind=int``) as an integer."""
    try:
        v = float(token)
    except ValueError:
        raise parse_error(path, k, f"{name}={token!r} is not a number") from None
    if kind is int:
        if not (np.isfinite(v) and v == int(v)):
            raise parse_error(path, k, f"{name}={token!r} must be an integer")
        return int(v)
    return v


def read_zygo_ascii(path: str | Path, spacing_mm: float | None = None) -> SagMap:
    """Read a MetroPro ASCII export (``Zygo ASCII Data File - Format 2``) as a surface map.

    The 14 header lines give the intensity and phase frames (line 3: origin, width,
    height, buckets; line 4: phase origin, width, height), the scale factors (line 8:
    source, ``S``, wavelength in m, NA, ``O``, magnification, camera resolution in m) and
    line 11 ``PhaseRes`` ... ``DataSign``; ``#`` ends the intensity block and the phase
    block (module docstring for the units). Parameters as :func:`read_zygo_dat`.
    """
    path = Path(path)
    spacing_mm = _check_spacing(spacing_mm)
    text = read_text(path, "Zygo ASCII file")
    lines = text.split("\n")
    if not lines[0].strip().lower().startswith("zygo ascii data file"):
        raise parse_error(path, 1, f"expected 'Zygo ASCII Data File - Format 2', found {lines[0][:40]!r}")
    if len(lines) < 15:
        raise parse_error(path, len(lines), "the file ends inside its 14-line header")
    t3 = _header_tokens(path, lines, 3, 5, "IntensOriginX IntensOriginY IntensWidth IntensHeight NBuckets")
    t4 = _header_tokens(path, lines, 4, 4, "PhaseOriginX PhaseOriginY PhaseWidth PhaseHeight")
    t8 = _header_tokens(path, lines, 8, 7, "Source IntfScaleFactor WavelengthIn NumericAperture ObliquityFactor "
                                           "Magnification CameraRes")
    t11 = _header_tokens(path, lines, 11, 8, "PhaseRes PhaseAvgs MinimumAreaSize DisconAction DisconFilter "
                                             "ConnectionOrder RemoveTiltBias DataSign")
    iw, ih, nb = (_number(path, 3, t3[i], n, int) for i, n in ((2, "IntensWidth"), (3, "IntensHeight"),
                                                                 (4, "NBuckets")))
    pw, ph = (_number(path, 4, t4[i], n, int) for i, n in ((2, "PhaseWidth"), (3, "PhaseHeight")))
    scale, wl_m, obl, res_m = (_number(path, 8, t8[i], n) for i, n in ((1, "IntfScaleFactor"), (2, "WavelengthIn"),
                                                                      (4, "ObliquityFactor"), (6, "CameraRes")))
    phase_res, sign = _number(path, 11, t11[0], "PhaseRes", int), _number(path, 11, t11[7], "DataSign", int)
    if pw <= 0 or ph <= 0:
        raise parse_error(path, 4, f"the file holds no phase map (PhaseWidth x PhaseHeight = {pw} x {ph})")
    n_int = iw * ih * max(nb, 1) if iw > 0 and ih > 0 else 0
    # blocks end with '#'; a writer may leave an empty block where there is no intensity
    blocks = [b.split() for b in "\n".join(lines[14:]).split("#")]
    blocks = [b for b in blocks if b]
    if n_int and blocks and len(blocks[0]) == n_int:
        blocks = blocks[1:]
    if not blocks or len(blocks[0]) != pw * ph:
        found = len(blocks[0]) if blocks else 0
        raise parse_error(path, None, f"the phase block holds {found} values; PhaseWidth x PhaseHeight "
                                      f"= {pw} x {ph} = {pw * ph} expected")
    try:
        counts = np.array(blocks[0], dtype=np.int64).reshape(ph, pw)
    except ValueError:
        bad = next(t for t in blocks[0] if not t.lstrip("+-").isdigit())
        raise parse_error(path, None, f"phase count {bad!r} is not an integer") from None
    h = _height_um(counts, scale, obl, wl_m, phase_res, sign, path)
    info = {"format": "zygo-ascii", "intf_scale_factor": scale, "obliquity_factor": obl,
            "wavelength_um": wl_m * 1e6, "phase_res": phase_res, "data_sign": sign}
    return _to_map(path, h, res_m, spacing_mm, info)
