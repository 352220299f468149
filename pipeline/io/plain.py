"""Sag maps in plain files no design code owns: a CSV point table, NetCDF and NumPy ``.npz``.

======== ================================== ==============================
suffix   layout                             precision
======== ================================== ==============================
``.csv`` ``x_mm,y_mm,sag_um`` table, a row    12 significant digits
         per point (masked or scattered ok)
``.nc``  NetCDF4 (xarray): ``sag_um[y_mm,     float64, exact
         x_mm]`` with units attributes
``.npz`` arrays ``x_mm``, ``y_mm``,           float64, exact
         ``sag_um[y, x]``, ``label``
======== ================================== ==============================

Readers take files other tools wrote (other units, descending or meshgrid axes,
masked or scattered points, a table under ``.txt``/``.tsv`` with any delimiter, the
quantities under other names: :mod:`pipeline.io.columns`); every writer is atomic
(:mod:`pipeline.io.common`).
The registry of every format is :mod:`pipeline.io.registry`.
"""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

import numpy as np

from optics.sagmap import SagMap
from pipeline.io import columns
from pipeline.io.common import atomic_path, atomic_write, parse_error, read_csv_choices
from pipeline.io.gridding import (SAG_UNITS_TO_UM, ScatteredPoints, grid_points, length_unit_factor, sag_unit_factor,
                                  scattered_points, uniform_axis)

__all__ = ["write_sag_csv", "read_sag_csv", "read_sag_csv_points", "write_sag_netcdf", "read_sag_netcdf", "write_sag_npz", "read_sag_npz"]

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


def _refusal(quantities: dict[str, columns.Quantity]):
    """``hint(missing, header)`` for :func:`read_csv_choices`: what each missing column accepts."""
    return lambda missing, header: "; ".join(quantities[m].refusal(header) for m in missing)


def read_sag_csv(path: str | Path, spacing_mm: float | None = None, wavelength_um: float | None = None) -> SagMap:
    """Read a table of points ``x_mm,y_mm,sag_um`` (header names case-insensitive, any
    column order, extra columns ignored, rows in any order; comma, semicolon, tab or
    whitespace delimited).

    The sag column may be named ``sag``, ``height`` or ``z`` and the coordinates ``x``,
    ``y``, each with its unit (``Height [nm]``, ``z_um``, ``X (m)``; converted), the sag
    also in waves (``sag [waves]``, with ``wavelength_um``); a name without its unit is
    refused, the error listing the accepted ones (:mod:`pipeline.io.columns`).

    Points on a uniform grid, complete or not (a masked export lists only the points
    inside its aperture), are put back on that grid with NaN at the absent nodes and at
    ``nan`` sag values; truly scattered points are interpolated linearly onto a grid of
    ``spacing_mm`` (default: one node per point over their convex hull, ``sqrt(area / n)``),
    NaN outside that hull, and their white noise before interpolation is kept in
    ``meta["points_noise_um"]``, the nodes' share of it in ``meta["node_noise_factor"]``
    (:func:`pipeline.io.gridding.grid_points`).
    ``meta["gridding"]`` says which. :func:`read_sag_csv_points` also returns the points.

    Parameters
    ----------
    path : str or Path
        The CSV file.
    spacing_mm : float, optional
        Grid spacing (mm) for scattered points; unused when the points form a grid.
    wavelength_um : float, optional
        Wavelength (µm) of one wave, for a sag column in waves.
    """
    return read_sag_csv_points(path, spacing_mm, wavelength_um)[0]


def read_sag_csv_points(path: str | Path, spacing_mm: float | None = None,
                        wavelength_um: float | None = None) -> tuple[SagMap, ScatteredPoints | None]:
    """:func:`read_sag_csv`'s map and, when the file holds scattered points, the points
    themselves (:class:`pipeline.io.gridding.ScatteredPoints`: what a fit should use, the
    grid being their interpolation); None when the points lie on a grid. Parameters as
    :func:`read_sag_csv`'s.
    """
    path = Path(path)
    v, lines, (_, _, sag_name) = read_csv_choices(
        path, "sag CSV", (columns.X.names("mm"), columns.Y.names("mm"), columns.SAG.names("um")),
        _refusal({"x_mm": columns.X, "y_mm": columns.Y, "sag_um": columns.SAG}))
    unit = columns.split_unit(sag_name)[1]
    if unit not in SAG_UNITS_TO_UM:  # in waves: the reader converted every length unit to µm
        try:
            v[:, 2] *= sag_unit_factor(unit, wavelength_um)
        except ValueError as exc:
            raise parse_error(path, None, f"column {sag_name!r}: {exc}") from None
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
    sagmap = _sagmap(path, gx, gy, sag, path.stem, {"format": "csv", **meta})
    return sagmap, scattered_points(v[:, 0], v[:, 1], v[:, 2], meta)


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
    return _sagmap(path, uniform_axis(x), uniform_axis(y), sag, label, meta)


def write_sag_netcdf(sagmap: SagMap, path: str | Path) -> Path:
    """NetCDF via xarray: variable ``sag_um`` on dims ``(y_mm, x_mm)`` with units attrs."""
    import xarray as xr

    ds = xr.Dataset(
        {"sag_um": (("y_mm", "x_mm"), sagmap.sag_um,
                    {"units": "um", "long_name": "surface sag along +z (NaN = no data)"})},
        coords={"x_mm": ("x_mm", sagmap.x_mm, {"units": "mm", "long_name": "x, dispersion direction", "axis": "X"}),
                "y_mm": ("y_mm", sagmap.y_mm, {"units": "mm", "long_name": "y, ruling direction", "axis": "Y"})},
        attrs={"Conventions": "CF-1.8", "label": sagmap.label,
               "comment": "cryograting optics.sagmap frame: x along the dispersion, y along the rulings, sag along "
                          "the outward normal +z",
               "meta_json": json.dumps(sagmap.meta, default=str)},
    )
    path = Path(path)
    with atomic_path(path) as tmp:
        # CF: coordinates have no missing values (xarray would give them a NaN _FillValue)
        ds.to_netcdf(tmp, encoding={"x_mm": {"_FillValue": None}, "y_mm": {"_FillValue": None}})
    return path


#: NetCDF attributes stating the wavelength of one wave, and their factor to µm.
_WAVELENGTH_ATTRIBUTES = (("wavelength_um", 1.0), ("wavelength_nm", 1e-3))


def _wavelength_um(path: Path, field: str, given: float | None, *attrs) -> float | None:
    """The wavelength (µm) of one wave for a NetCDF sag: ``given`` (the caller's), else the
    first of :data:`_WAVELENGTH_ATTRIBUTES` on the variable, then on the file; a stated one
    that is not a number, or that contradicts ``given`` (relative 1e-6), is refused."""
    found = next(((key, a[key], factor) for a in attrs for key, factor in _WAVELENGTH_ATTRIBUTES if key in a), None)
    if found is None:
        return given
    key, value, factor = found
    try:
        stated = (key, float(np.asarray(value).ravel()[0]) * factor)
    except (TypeError, ValueError, IndexError):
        raise ValueError(f"{path}: {field!r}: attribute {key}={value!r} is not a number") from None
    if given is not None and abs(given - stated[1]) > 1e-6 * abs(stated[1]):
        raise ValueError(f"{path}: {field!r}: wavelength_um={given!r} contradicts the file's {stated[0]} "
                         f"({stated[1]:g} µm); give one wavelength")
    return stated[1]


def read_sag_netcdf(path: str | Path, wavelength_um: float | None = None) -> SagMap:
    """Read a NetCDF sag map: variable ``sag_um`` (or ``sag``, ``height``, ``z``, bare or
    with a unit, :mod:`pipeline.io.columns`) on dims ``(y_mm, x_mm)`` (or ``(y, x)``), NaN
    or ``_FillValue`` = no data.

    The sag's ``units`` attribute is honoured (nm, um/µm, mm, m, or waves with
    ``wavelength_um``: the argument, else the variable's or the file's ``wavelength_um`` or
    ``wavelength_nm`` attribute) and converted to µm; without one, the unit in the variable's name
    is (``sag_um``, ``height_nm``), and a bare name (``sag``, ``height``) is refused.
    Coordinate ``units`` (nm, µm, mm, m; default mm) are honoured too. Descending
    coordinates are flipped.

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
        variables = [str(n) for n in ds.data_vars]
        found = columns.SAG.find(variables, bare=True)  # a bare name's unit is its 'units' attribute
        if found is None:
            raise ValueError(f"{path}: no sag variable; found {sorted(variables)}; accepted "
                             f"{columns.SAG.describe()}, or the unit in a 'units' attribute")
        field, name_unit = found
        da = ds[field]
        dims = next((d for d in (("y_mm", "x_mm"), ("y", "x")) if set(da.dims) == set(d)), None)
        if dims is None:
            raise ValueError(f"{path}: {field!r} has dims {da.dims}; expected ('y_mm', 'x_mm') or ('y', 'x')")
        da = da.transpose(*dims)
        units = da.attrs.get("units", name_unit or None)
        wavelength_um = _wavelength_um(path, field, wavelength_um, da.attrs, ds.attrs)
        if units is None:
            raise ValueError(f"{path}: variable {field!r} has no 'units' attribute; give units (nm, um, mm, m, "
                             f"waves) or put the unit in its name ({field.lower()}_um)")
        try:
            factor = sag_unit_factor(units, wavelength_um)
        except ValueError as exc:
            raise ValueError(f"{path}: {field!r}: {exc}") from None
        axes = []
        for d in dims[::-1]:
            cu = da[d].attrs.get("units") if d in da.coords else None
            try:
                axes.append(da[d].values * (1.0 if cu is None else length_unit_factor(cu)) if d in da.coords
                            else None)
            except ValueError as exc:
                raise ValueError(f"{path}: coordinate {d!r}: {exc}") from None
        if axes[0] is None or axes[1] is None:
            raise ValueError(f"{path}: {field!r} lacks coordinate values for {dims}")
        try:
            meta = json.loads(ds.attrs.get("meta_json", "{}"))
        except json.JSONDecodeError:
            meta = {}
        meta = {**meta, "source_units": str(units)}
        return _axes_map(path, field, axes[0], axes[1], np.asarray(da.values) * factor,
                         str(ds.attrs.get("label", path.stem)), meta)


def write_sag_npz(sagmap: SagMap, path: str | Path) -> Path:
    """NumPy ``.npz`` with arrays ``x_mm``, ``y_mm``, ``sag_um[y, x]`` and ``label``."""
    path = Path(path)
    with atomic_write(path, "wb") as fh:  # a file object: np.savez would append .npz to a tmp name
        np.savez(fh, x_mm=sagmap.x_mm, y_mm=sagmap.y_mm, sag_um=sagmap.sag_um, label=np.str_(sagmap.label))
    return path


def read_sag_npz(path: str | Path, wavelength_um: float | None = None) -> SagMap:
    """Read a ``.npz`` sag map: arrays ``x_mm``, ``y_mm`` (1-D, or 2-D meshgrids),
    ``sag_um[y, x]`` (µm, NaN = no data) and optional ``label``. Complex arrays are
    refused; descending axes are flipped.

    The arrays may carry other names with their unit (:mod:`pipeline.io.columns`):
    ``x_m``, ``y_um``, ``height_nm``, ``z_um``, ``sag_waves`` (with ``wavelength_um``);
    converted. A name without its unit (``x``, ``z``) is refused, naming the accepted ones.

    Parameters
    ----------
    path : str or Path
        The ``.npz`` file.
    wavelength_um : float, optional
        Wavelength (µm) of one wave, for a sag array in waves.
    """
    path = Path(path)
    if not path.exists():
        raise ValueError(f"{path}: file does not exist")
    try:
        with np.load(path, allow_pickle=False) as d:
            found = [(q, q.find(d.files)) for q in (columns.X, columns.Y, columns.SAG)]
            missing = [q for q, f in found if f is None]
            if missing:
                raise ValueError(f"{path}: no array for the {', '.join(q.what for q in missing)}; found "
                                 f"{sorted(d.files)}; " + "; ".join(q.refusal(d.files) for q in missing))
            label = str(d["label"]) if "label" in d.files else path.stem
            (x_name, x_unit), (y_name, y_unit), (field, sag_unit) = (f for _, f in found)
            x, y, sag = d[x_name], d[y_name], d[field]
    except (OSError, EOFError, zipfile.BadZipFile) as exc:
        raise ValueError(f"{path}: not a readable .npz file ({type(exc).__name__}: {exc})") from None
    except ValueError as exc:
        if str(path) in str(exc):
            raise
        raise ValueError(f"{path}: not a readable .npz file ({exc})") from None
    try:
        factors = length_unit_factor(x_unit), length_unit_factor(y_unit), sag_unit_factor(sag_unit, wavelength_um)
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}") from None
    meta = {} if (x_name, y_name, field) == ("x_mm", "y_mm", "sag_um") else {"source_units": sag_unit}
    # scaled only where the unit differs, so a file in mm and µm reads back bit for bit; a
    # non-numeric array is left for _axes_map to refuse by name
    x, y, sag = ((a * f if f != 1.0 and np.issubdtype(a.dtype, np.number) else a)
                 for a, f in zip((x, y, sag), factors))
    return _axes_map(path, field, x, y, sag, label, meta)
