"""Interchange of sag maps, Zernike lists and measured line profiles with other tools.

One reader/writer pair per sag-map format, registered in :data:`SAG_FORMATS`;
:func:`write_sag_map` / :func:`read_sag_map` dispatch on the file suffix.

======== ================================ ======================================
suffix   format                           module / quantisation
======== ================================ ======================================
``.int`` CODE V grid interferogram (GRD)  :mod:`pipeline.io.codev`; 16 bit, max|v|/65532
``.dat`` Zemax Grid Sag                   :mod:`pipeline.io.zemax`; 12 digits
``.csv`` ``x_mm,y_mm,sag_um`` table        here; 12 significant digits
``.nc``  NetCDF4 (xarray, default engine)  here; float64, exact
``.npz`` NumPy arrays                     here; float64, exact
======== ================================ ======================================

Every writer goes through a temporary file in the target directory and
``os.replace`` (atomic). All maps follow :mod:`optics.sagmap`: ``x`` dispersion,
``y`` ruling direction, ``sag_um[y, x]`` along +z, NaN invalid.

Sign and frame when loading into a lens file
--------------------------------------------
Values are written in the grating frame unchanged: ``+z`` is the outward normal of
the ruled face (positive sag moves the surface *towards* the incoming light), x is
the dispersion direction, y the ruling direction. CODE V and Zemax measure sag along
the surface's *local* +Z, which for a mirror met by light travelling along +Z points
*away* from the incoming light; if the grating is set up that way the design code
needs ``-sag`` (and, to stay right-handed, one of x/y mirrored). That depends on the
lens file, so no flip is applied here; the orientation tests pin our own layout.

Also here (re-exported): Zernike coefficient lists (:mod:`pipeline.io.zernike`),
measured line profiles and PSF images (:mod:`pipeline.io.measured`), and
:func:`load_sag_map` used by the ``--sag`` option of the CLI. Point lists and units:
:mod:`pipeline.io.gridding`.
"""

from __future__ import annotations

import inspect
import json
from pathlib import Path
from typing import Callable

import numpy as np

from optics.sagmap import SagMap
from pipeline.io.codev import read_codev_int, write_codev_int
from pipeline.io.common import atomic_path, atomic_write, parse_error, read_csv_columns
from pipeline.io.gridding import grid_points, length_unit_factor, sag_unit_factor
from pipeline.io.measured import read_line_profile, read_psf_image, write_psf_image_csv
from pipeline.io.zemax import read_zemax_grid_sag, write_zemax_grid_sag
from pipeline.io.zernike import (ZERNIKE_CONVENTIONS, convert_normalisation, read_zernike_list,
                                 write_zernike_list)

__all__ = [
    "SAG_FORMATS",
    "read_psf_image",
    "write_psf_image_csv",
    "write_sag_map",
    "read_sag_map",
    "load_sag_map",
    "write_codev_int",
    "read_codev_int",
    "write_zemax_grid_sag",
    "read_zemax_grid_sag",
    "write_sag_csv",
    "read_sag_csv",
    "write_sag_netcdf",
    "read_sag_netcdf",
    "write_sag_npz",
    "read_sag_npz",
    "ZERNIKE_CONVENTIONS",
    "convert_normalisation",
    "write_zernike_list",
    "read_zernike_list",
    "read_line_profile",
]

_CSV_COLUMNS = ("x_mm", "y_mm", "sag_um")


# ------------------------------------------------------------------ CSV
def write_sag_csv(sagmap: SagMap, path: str | Path) -> Path:
    """Write every grid point as ``x_mm,y_mm,sag_um`` (NaN written as ``nan``, so the
    reader recovers the full grid and its holes). Rows: y increasing, x fastest."""
    X, Y = sagmap.grid()
    path = Path(path)
    with atomic_write(path) as fh:
        fh.write(",".join(_CSV_COLUMNS) + "\n")
        np.savetxt(fh, np.column_stack([X.ravel(), Y.ravel(), sagmap.sag_um.ravel()]),
                   fmt="%.12g", delimiter=",")
    return path


def read_sag_csv(path: str | Path, spacing_mm: float | None = None) -> SagMap:
    """Read a table of points ``x_mm,y_mm,sag_um`` (header names case-insensitive, any
    column order, extra columns ignored, rows in any order).

    Points on a uniform grid, complete or not (a masked export lists only the points
    inside its aperture), are put back on that grid with NaN at the absent nodes and at
    ``nan`` sag values; truly scattered points are interpolated linearly onto a grid of
    ``spacing_mm`` (default: their median nearest-neighbour distance), NaN outside their
    convex hull (:func:`pipeline.io.gridding.grid_points`). ``meta["gridding"]`` says which.

    Parameters
    ----------
    path : str or Path
        The CSV file.
    spacing_mm : float, optional
        Grid spacing (mm) for scattered points; unused when the points form a grid.
    """
    path = Path(path)
    v, lines = read_csv_columns(path, "sag CSV", _CSV_COLUMNS)
    if v.shape[0] < 3:
        raise parse_error(path, None, f"needs >= 3 data rows, found {v.shape[0]}")
    bad = ~np.isfinite(v[:, :2]).all(axis=1)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise parse_error(path, int(lines[k]), f"x_mm={v[k, 0]:g}, y_mm={v[k, 1]:g}: coordinates must be finite")
    inf = np.isinf(v[:, 2])
    if inf.any():
        raise parse_error(path, int(lines[inf][0]), "sag_um is infinite; write nan (or leave the point out) for no data")
    gx, gy, sag, meta = grid_points(v[:, 0], v[:, 1], v[:, 2], spacing_mm=spacing_mm, lines=lines, source=str(path))
    return _sagmap(path, gx, gy, sag, path.stem, {"format": "csv", **meta})


def _sagmap(path: Path, x_mm, y_mm, sag_um, label: str, meta: dict) -> SagMap:
    """SagMap whose construction errors name the file."""
    try:
        return SagMap(x_mm, y_mm, sag_um, label, meta)
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}") from None


def _axes_map(path: Path, field: str, x, y, sag, label: str, meta: dict) -> SagMap:
    """A map from axis arrays (1-D, or 2-D meshgrids) and ``sag[y, x]`` as stored in
    NetCDF/NPZ: refuses complex or non-finite coordinates, flips descending axes."""
    x, y, sag = np.asarray(x), np.asarray(y), np.asarray(sag)
    for name, a in ((field, sag), ("x_mm", x), ("y_mm", y)):
        if np.iscomplexobj(a):
            raise ValueError(f"{path}: {name!r} is complex ({a.dtype}); a sag map must be real "
                             "(write the real part, or the modulus, explicitly)")
        if not (np.issubdtype(a.dtype, np.number) or a.dtype == bool):
            raise ValueError(f"{path}: {name!r} has non-numeric dtype {a.dtype}")
    if sag.ndim != 2:
        raise ValueError(f"{path}: {field!r} has shape {sag.shape}; expected 2-D [y, x]")
    if x.ndim == 2 and x.shape == sag.shape:
        x = x[0]  # meshgrid layout
    if y.ndim == 2 and y.shape == sag.shape:
        y = y[:, 0]
    x, y, sag = x.astype(float), y.astype(float), sag.astype(float)
    for name, a in (("x_mm", x), ("y_mm", y)):
        if not np.isfinite(a).all():
            k = int(np.flatnonzero(~np.isfinite(a))[0])
            raise ValueError(f"{path}: {name}[{k}]={a[k]!r}; coordinates must be finite")
    if np.isinf(sag).any():
        raise ValueError(f"{path}: {field!r} has {int(np.isinf(sag).sum())} infinite values; use NaN for no data")
    if x.ndim == 1 and x.size > 1 and x[0] > x[-1]:
        x, sag = x[::-1], sag[:, ::-1]
    if y.ndim == 1 and y.size > 1 and y[0] > y[-1]:
        y, sag = y[::-1], sag[::-1]
    return _sagmap(path, x, y, sag, label, meta)


def write_sag_netcdf(sagmap: SagMap, path: str | Path) -> Path:
    """NetCDF via xarray: variable ``sag_um`` on dims ``(y_mm, x_mm)`` with units attrs."""
    import xarray as xr

    ds = xr.Dataset(
        {"sag_um": (("y_mm", "x_mm"), sagmap.sag_um,
                    {"units": "um", "long_name": "surface sag along +z (NaN = no data)"})},
        coords={"x_mm": ("x_mm", sagmap.x_mm, {"units": "mm", "long_name": "x, dispersion direction"}),
                "y_mm": ("y_mm", sagmap.y_mm, {"units": "mm", "long_name": "y, ruling direction"})},
        attrs={"label": sagmap.label, "conventions": "cryograting optics.sagmap frame",
               "meta_json": json.dumps(sagmap.meta, default=str)},
    )
    path = Path(path)
    with atomic_path(path) as tmp:
        ds.to_netcdf(tmp)  # engine left to xarray: h5netcdf needs h5py, absent here; netCDF4 is used
    return path


def read_sag_netcdf(path: str | Path, wavelength_um: float | None = None) -> SagMap:
    """Read a NetCDF sag map: variable ``sag_um`` (or ``sag``) on dims ``(y_mm, x_mm)``
    (or ``(y, x)``), NaN or ``_FillValue`` = no data.

    The sag's ``units`` attribute is honoured (nm, um/µm, mm, m, or waves with
    ``wavelength_um``) and converted to µm; without one, ``sag_um`` is taken as µm and
    ``sag`` is refused. Coordinate ``units`` (nm, µm, mm, m; default mm) are honoured
    too. Descending coordinates are flipped.

    Parameters
    ----------
    path : str or Path
        The ``.nc`` file.
    wavelength_um : float, optional
        Wavelength (µm) of one wave, for ``units = "waves"``.
    """
    import xarray as xr

    path = Path(path)
    if not path.exists():
        raise ValueError(f"{path}: file does not exist")
    try:
        ds = xr.open_dataset(path)
    except Exception as exc:  # netCDF4/h5 raise OSError, ValueError, KeyError... on a garbage file
        raise ValueError(f"{path}: not a readable NetCDF file ({type(exc).__name__}: {exc})") from None
    with ds:
        field = next((n for n in ("sag_um", "sag") if n in ds.data_vars), None)
        if field is None:
            raise ValueError(f"{path}: no variable 'sag_um' (or 'sag'); found {sorted(map(str, ds.data_vars))}")
        da = ds[field]
        dims = next((d for d in (("y_mm", "x_mm"), ("y", "x")) if set(da.dims) == set(d)), None)
        if dims is None:
            raise ValueError(f"{path}: {field!r} has dims {da.dims}; expected ('y_mm', 'x_mm') or ('y', 'x')")
        da = da.transpose(*dims)
        units = da.attrs.get("units")
        if units is None and field == "sag":
            raise ValueError(f"{path}: variable 'sag' has no 'units' attribute; give units (nm, um, mm, m, waves) "
                             "or name the variable 'sag_um'")
        try:
            factor = 1.0 if units is None else sag_unit_factor(units, wavelength_um)
            axes = []
            for d in dims[::-1]:
                cu = da[d].attrs.get("units") if d in da.coords else None
                axes.append(da[d].values * (1.0 if cu is None else length_unit_factor(cu)) if d in da.coords
                            else None)
        except ValueError as exc:
            raise ValueError(f"{path}: {field!r}: {exc}") from None
        if axes[0] is None or axes[1] is None:
            raise ValueError(f"{path}: {field!r} lacks coordinate values for {dims}")
        try:
            meta = json.loads(ds.attrs.get("meta_json", "{}"))
        except json.JSONDecodeError:
            meta = {}
        if units is not None:
            meta = {**meta, "source_units": str(units)}
        return _axes_map(path, field, axes[0], axes[1], np.asarray(da.values) * factor,
                         str(ds.attrs.get("label", path.stem)), meta)


def write_sag_npz(sagmap: SagMap, path: str | Path) -> Path:
    """NumPy ``.npz`` with arrays ``x_mm``, ``y_mm``, ``sag_um[y, x]`` and ``label``."""
    path = Path(path)
    with atomic_write(path, "wb") as fh:  # a file object: np.savez would append .npz to a tmp name
        np.savez(fh, x_mm=sagmap.x_mm, y_mm=sagmap.y_mm, sag_um=sagmap.sag_um, label=np.str_(sagmap.label))
    return path


def read_sag_npz(path: str | Path) -> SagMap:
    """Read a ``.npz`` sag map: arrays ``x_mm``, ``y_mm`` (1-D, or 2-D meshgrids),
    ``sag_um[y, x]`` (µm, NaN = no data) and optional ``label``. Complex arrays are
    refused; descending axes are flipped."""
    import zipfile

    path = Path(path)
    if not path.exists():
        raise ValueError(f"{path}: file does not exist")
    try:
        with np.load(path, allow_pickle=False) as d:
            missing = {"x_mm", "y_mm", "sag_um"} - set(d.files)
            if missing:
                raise ValueError(f"{path}: missing arrays {sorted(missing)}; found {sorted(d.files)}")
            label = str(d["label"]) if "label" in d.files else path.stem
            x, y, sag = d["x_mm"], d["y_mm"], d["sag_um"]
    except (OSError, EOFError, zipfile.BadZipFile) as exc:
        raise ValueError(f"{path}: not a readable .npz file ({type(exc).__name__}: {exc})") from None
    except ValueError as exc:
        if str(path) in str(exc):
            raise
        raise ValueError(f"{path}: not a readable .npz file ({exc})") from None
    return _axes_map(path, "sag_um", x, y, sag, label, {})


# ------------------------------------------------------------------ registry
#: suffix -> (reader(path, **options) -> SagMap, writer(sagmap, path, **options) -> Path)
SAG_FORMATS: dict[str, tuple[Callable[..., SagMap], Callable[..., Path]]] = {
    ".int": (read_codev_int, write_codev_int),
    ".dat": (read_zemax_grid_sag, write_zemax_grid_sag),
    ".csv": (read_sag_csv, write_sag_csv),
    ".nc": (read_sag_netcdf, write_sag_netcdf),
    ".npz": (read_sag_npz, write_sag_npz),
}
_WRITERS = {w for _, w in SAG_FORMATS.values()}


def _check_options(func: Callable, path: Path, options: dict) -> None:
    """Unknown keyword options become a ValueError listing the valid ones for the format."""
    params = list(inspect.signature(func).parameters)[2 if func in _WRITERS else 1:]
    bad = sorted(set(options) - set(params))
    if bad:
        raise ValueError(f"{path}: option(s) {bad} are not valid for {func.__name__} "
                         f"({path.suffix} files); valid are {params}")


def _format_for(path: Path) -> tuple[Callable, Callable]:
    try:
        return SAG_FORMATS[path.suffix.lower()]
    except KeyError:
        raise ValueError(
            f"{path}: unknown sag-map format {path.suffix!r}; valid suffixes are {sorted(SAG_FORMATS)}"
        ) from None


def write_sag_map(sagmap: SagMap, path: str | Path, **options) -> Path:
    """Write ``sagmap`` in the format given by the suffix of ``path``.

    Parameters
    ----------
    sagmap : SagMap
        The map.
    path : str or Path
        Output file; suffix one of :data:`SAG_FORMATS`.
    **options
        Passed to the format's writer (e.g. ``kind``, ``wavelength_um`` for ``.int``).
    """
    path = Path(path)
    writer = _format_for(path)[1]
    if not isinstance(sagmap, SagMap):
        raise ValueError(f"sagmap must be an optics.sagmap.SagMap, got {type(sagmap).__name__}")
    _check_options(writer, path, options)
    try:
        return writer(sagmap, path, **options)
    except OSError as exc:  # e.g. a directory in the way, disk full
        raise ValueError(f"cannot write {path}: {exc.strerror or exc}") from None


def read_sag_map(path: str | Path, **options) -> SagMap:
    """Read a sag map, choosing the reader by the suffix of ``path``.

    ``**options`` go to the reader (``extent_mm``/``spacing_mm``, ``quantity``,
    ``wfr_to_sag_factor`` for ``.int``, ``spacing_mm`` for scattered ``.csv``,
    ``wavelength_um`` for a ``.nc`` in waves); an option the format does not use is
    refused naming the valid ones.
    """
    path = Path(path)
    reader = _format_for(path)[0]
    _check_options(reader, path, options)
    if not path.exists():
        raise ValueError(f"{path}: file does not exist")
    return reader(path, **options)


def load_sag_map(path: str | Path) -> SagMap:
    """Sag map for the CLI ``--sag FILE`` option (any :data:`SAG_FORMATS` suffix);
    errors are prefixed with ``--sag``."""
    from pipeline.io.codev import GridUnknownError

    try:
        return read_sag_map(path)
    except GridUnknownError as exc:  # the command line has no grid options: the title must carry it
        remedy = "add EXTENT_MM x0 x1 y0 y1 (mm, first/last sample centres) to the title"
        raise ValueError(f"--sag {exc.with_remedy(remedy)}") from None
    except ValueError as exc:
        raise ValueError(f"--sag {exc}") from None
