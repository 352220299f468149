"""The one registry of file formats: every format the toolkit reads or writes.

:data:`FORMATS` lists each format once — what it holds (``kind``), its suffixes, its
reader and writer and the module that implements them; ``python -m pipeline.io.registry``
prints the table. Sag maps are dispatched on the suffix: :func:`read_sag_map` /
:func:`write_sag_map` (and :func:`load_sag_map` for the CLI's ``--sag FILE``) use
:data:`SAG_FORMATS` (the ``"sag map"`` rows read and written) and :data:`SAG_READERS`
(read only: interferometer exports). Where two sag-map formats share a suffix (a Zygo
MetroPro ``.dat`` and a Zemax Grid Sag ``.dat``) the row with a ``sniff`` test is tried
first and chosen by the file's content. Other kinds share suffixes with sag maps (a
CODE V ``ZFR`` deck is an ``.int`` like a ``GRD`` grid), so their readers are called by
name.

Adding a format: write its reader/writer in a module of this package and add one
:class:`Format` row below; a sag-map row makes it readable by ``--sag``, diagnosis
manifests and :func:`read_sag_map` at once.

The names each reader accepts for a quantity inside a file (a sag column ``Height [nm]``,
an intensity ``Flux [ADU]``, a NetCDF variable ``height``) are one table too,
:mod:`pipeline.io.columns`; ``python -m pipeline.io.registry`` prints it after the formats.

Sign and frame when loading into a lens file
--------------------------------------------
Sag maps follow :mod:`optics.sagmap`: ``x`` dispersion, ``y`` ruling direction,
``sag_um[y, x]`` along +z (the outward normal of the ruled face: positive sag moves
the surface *towards* the incoming light), NaN invalid. CODE V and Zemax measure sag
along the surface's *local* +Z, which for a mirror met by light travelling along +Z
points *away* from the incoming light; if the grating is set up that way the design
code needs ``-sag`` (and, to stay right-handed, one of x/y mirrored). That depends on
the lens file, so no flip is applied here; the orientation tests pin our own layout.
"""

from __future__ import annotations

import inspect
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from optics.sagmap import SagMap
from pipeline.io.ansys_listing import ANSYS_LISTING_SUFFIXES, is_ansys_listing, read_ansys_listing
from pipeline.io.codev import read_codev_int, write_codev_int
from pipeline.io.codev_zfr import read_codev_zernike, write_codev_zernike
from pipeline.io.columns import names_table
from pipeline.io.fe import read_fe_result
from pipeline.io.fe_nodes import NODE_TABLE_SUFFIXES, read_node_table
from pipeline.io.fits import (FITS_SUFFIXES, read_line_profile_fits, read_psf_image_fits, read_sag_fits,
                              write_sag_fits)
from pipeline.io.gridding import GridUnknownError
from pipeline.io.measured import read_line_profile, read_psf_image, write_line_profile_csv, write_psf_image_csv
from pipeline.io.plain import (read_sag_csv, read_sag_csv_points, read_sag_netcdf, read_sag_npz, write_sag_csv, write_sag_netcdf,
                               write_sag_npz)
from pipeline.io.zemax import read_zemax_grid_sag, read_zemax_zernike, write_zemax_grid_sag, write_zemax_zernike
from pipeline.io.zernike import read_zernike_list, write_zernike_list
from pipeline.io.zygo import is_zygo_dat, read_zygo_ascii, read_zygo_dat, read_zygo_datx

__all__ = ["KINDS", "Format", "FORMATS", "SAG_FORMATS", "SAG_READERS", "formats", "format_table", "write_sag_map", "read_sag_map",
           "read_sag_map_points", "load_sag_map", "read_measured"]

#: What a file holds.
KINDS = ("sag map", "zernike list", "line profile", "psf image", "fe result")


@dataclass(frozen=True)
class Format:
    """One file format.

    Attributes
    ----------
    kind : str
        What the file holds, one of :data:`KINDS`.
    suffixes : tuple of str
        File suffixes (lower case, with the dot).
    name : str
        The format as its users call it.
    reader, writer : callable or None
        ``reader(path, **options)``; for sag maps ``writer(sagmap, path, **options) -> Path``,
        for the other kinds the writer's own signature. None: not read / not written.
    notes : str
        Precision, quantisation or what the reader accepts.
    sniff : callable or None
        ``sniff(path) -> bool``: the file is in this format (by its content). A format
        that shares a suffix with another has one; it is tried before the other.
    points_reader : callable or None
        For a sag-map format that may hold scattered points: ``points_reader(path,
        **options) -> (SagMap, ScatteredPoints or None)``, the reader's map and the points
        themselves (:func:`read_sag_map_points`).
    """

    kind: str
    suffixes: tuple[str, ...]
    name: str
    reader: Callable | None
    writer: Callable | None
    notes: str = ""
    sniff: Callable | None = None
    points_reader: Callable | None = None

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"kind={self.kind!r} is not one of {KINDS}")

    @property
    def module(self) -> str:
        """The module that implements the format."""
        return (self.reader or self.writer).__module__


#: Every format, once.
FORMATS: tuple[Format, ...] = (
    Format("sag map", (".int",), "CODE V grid interferogram (GRD), SUR or WFR", read_codev_int, write_codev_int,
           "16 bit, max|v|/65532"),
    Format("sag map", (".dat",), "Zemax Grid Sag", read_zemax_grid_sag, write_zemax_grid_sag, "12 digits"),
    Format("sag map", (".dat",), "Zygo MetroPro binary interferogram", read_zygo_dat, None,
           "counts x S x O x wavelength / R; invalid pixels NaN; told from Zemax by its magic number",
           sniff=is_zygo_dat),
    Format("sag map", (".datx",), "Zygo Mx HDF5 interferogram", read_zygo_datx, None, "needs h5py"),
    Format("sag map", (".asc",), "Zygo MetroPro ASCII interferogram", read_zygo_ascii, None,
           "counts x S x O x wavelength / R; invalid pixels NaN"),
    Format("sag map", (".csv",), "x_mm,y_mm,sag_um point table", read_sag_csv, write_sag_csv,
           "12 significant digits; masked or scattered points gridded", points_reader=read_sag_csv_points),
    Format("sag map", (".txt", ".tsv"), "x_mm,y_mm,sag_um point table as text (any delimiter)", read_sag_csv, None,
           "as .csv: comma, semicolon, tab or whitespace delimited", points_reader=read_sag_csv_points),
    Format("sag map", (".nc",), "NetCDF4 sag_um[y_mm, x_mm]", read_sag_netcdf, write_sag_netcdf,
           "float64, exact; units attributes honoured"),
    Format("sag map", (".npz",), "NumPy arrays x_mm, y_mm, sag_um", read_sag_npz, write_sag_npz, "float64, exact"),
    Format("sag map", FITS_SUFFIXES, "FITS image sag[y, x], BUNIT, linear WCS", read_sag_fits, write_sag_fits,
           "float64, exact; BLANK/NaN no data; a map in pixels needs spacing_mm or extent_mm"),
    Format("zernike list", (".txt",), "project Zernike list (Fringe or Noll, header says which)", read_zernike_list,
           write_zernike_list, "self-describing: convention, normalisation, radius"),
    Format("zernike list", (".int",), "CODE V Zernike deck (ZFR), Fringe order", read_codev_zernike,
           write_codev_zernike, "37 terms, unnormalised, waves"),
    Format("zernike list", (".dat",), "Zemax Zernike Standard / Fringe Sag extra data", read_zemax_zernike,
           write_zemax_zernike, "Extra Data Editor order, mm"),
    Format("line profile", (".csv",), "measured line profile offset_um,intensity", read_line_profile,
           write_line_profile_csv, "counts, pedestal, negative noise, any grid accepted; written exact"),
    Format("line profile", FITS_SUFFIXES, "FITS 1-D spectrum (WCS axis) or profile table", read_line_profile_fits,
           None, "wavelength, length or pixel axis; NaN samples masked"),
    Format("psf image", (".csv", ".npz"), "measured point-source image x_um,y_um,intensity", read_psf_image,
           write_psf_image_csv, "counts, pedestal, negative noise, any grid accepted"),
    Format("psf image", FITS_SUFFIXES, "FITS 2-D image (NAXIS1 dispersion, NAXIS2 slit)", read_psf_image_fits,
           None, "length or pixel axes; NaN/BLANK pixels masked"),
    Format("fe result", (".vtu", ".vtk", ".xdmf", ".exo", ".e", ".msh", ".inp", ".bdf", ".nas"),
           "another FE solver's mesh with nodal displacements (meshio)", read_fe_result, None,
           ".inp/.bdf/.nas with a node_id,ux,uy,uz CSV; cryograting import-fe"),
    Format("fe result", NODE_TABLE_SUFFIXES, "another FE solver's nodal table x,y,z,ux,uy,uz (no mesh)",
           read_node_table, None, "columns by header names; the face: a plane, triangulated; cryograting import-fe"),
    Format("fe result", ANSYS_LISTING_SUFFIXES, "ANSYS Mechanical APDL PRNSOL,U listing with the NLIST of its nodes",
           read_ansys_listing, None, "any name, told by content; 5 significant digits as printed; paired by node "
           "number, then read as a table of nodes; cryograting import-fe --nodes", sniff=is_ansys_listing),
)


def formats(kind: str | None = None) -> tuple[Format, ...]:
    """The formats of one ``kind`` (all of them for None)."""
    if kind is not None and kind not in KINDS:
        raise ValueError(f"kind={kind!r} is not one of {KINDS}")
    return tuple(f for f in FORMATS if kind is None or f.kind == kind)


def format_table() -> str:
    """Plain-text table of :data:`FORMATS`: kind, suffixes, name, reader, writer, module."""
    rows = [("kind", "suffixes", "format", "reader", "writer", "module")]
    rows += [(f.kind, " ".join(f.suffixes), f.name, f.reader.__name__ if f.reader else "-",
              f.writer.__name__ if f.writer else "-", f.module) for f in FORMATS]
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    return "\n".join("  ".join(c.ljust(w) for c, w in zip(r, widths)).rstrip() for r in rows)


#: suffix -> (reader(path, **options) -> SagMap, writer(sagmap, path, **options) -> Path) of the
#: sag-map formats read and written (for a shared suffix, the one without a ``sniff``)
SAG_FORMATS: dict[str, tuple[Callable[..., SagMap], Callable[..., Path]]] = {
    s: (f.reader, f.writer) for f in formats("sag map") if f.writer and not f.sniff for s in f.suffixes}
#: suffix -> reader of the sag-map formats read only (interferometer exports)
SAG_READERS: dict[str, Callable[..., SagMap]] = {
    s: f.reader for f in formats("sag map") if not f.writer and not f.sniff for s in f.suffixes}
#: suffix -> [(sniff, reader)] tried, in order, before the suffix's own format
_SNIFFED: dict[str, list] = {}
for _f in formats("sag map"):
    if _f.sniff:
        for _s in _f.suffixes:
            _SNIFFED.setdefault(_s, []).append((_f.sniff, _f.reader))
_WRITERS = {w for _, w in SAG_FORMATS.values()}


def _check_options(func: Callable, path: Path, options: dict) -> None:
    """Unknown keyword options become a ValueError listing the valid ones for the format."""
    params = list(inspect.signature(func).parameters)[2 if func in _WRITERS else 1:]
    bad = sorted(set(options) - set(params))
    if bad:
        raise ValueError(f"{path}: option(s) {bad} are not valid for {func.__name__} "
                         f"({path.suffix} files); valid are {params}")


def _format_for(path: Path, writing: bool = True) -> tuple[Callable, Callable]:
    try:
        return SAG_FORMATS[path.suffix.lower()]
    except KeyError:
        if path.suffix.lower() in SAG_READERS:
            raise ValueError(f"{path}: {path.suffix!r} files are read, not written; write one of "
                             f"{sorted(SAG_FORMATS)}") from None
        valid = set(SAG_FORMATS) | (set() if writing else set(SAG_READERS))
        raise ValueError(f"{path}: unknown sag-map format {path.suffix!r}; valid suffixes are {sorted(valid)}") from None


def _reader_for(path: Path) -> Callable:
    """The reader of ``path``: a content test first where the suffix is shared, then the suffix."""
    suffix = path.suffix.lower()
    for sniff, reader in _SNIFFED.get(suffix, ()):
        if sniff(path):  # a missing file is no format's: read_sag_map then names it
            return reader
    if suffix in SAG_READERS:
        return SAG_READERS[suffix]
    return _format_for(path, writing=False)[0]


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
    ``wfr_to_sag_factor`` for ``.int``, ``spacing_mm`` for scattered ``.csv``/``.txt``,
    ``wavelength_um`` for a ``.csv``, ``.txt``, ``.nc`` or ``.npz`` sag in waves,
    ``spacing_mm`` for a Zygo map without a lateral scale); an option the format does not
    use is refused naming the valid ones.
    """
    path = Path(path)
    reader = _reader_for(path)
    _check_options(reader, path, options)
    if not path.exists():
        raise ValueError(f"{path}: file does not exist")
    return reader(path, **options)


def read_sag_map_points(path: str | Path, **options) -> tuple:
    """:func:`read_sag_map`'s map and, for a file of scattered points, the points
    themselves (:class:`pipeline.io.gridding.ScatteredPoints`), else None: the points are
    the measurement, the map their interpolation onto a grid (for what needs one).

    Parameters
    ----------
    path : str or Path
        The sag-map file.
    **options
        As for :func:`read_sag_map`.

    Returns
    -------
    (SagMap, ScatteredPoints or None)
    """
    path = Path(path)
    reader = _reader_for(path)
    _check_options(reader, path, options)
    if not path.exists():
        raise ValueError(f"{path}: file does not exist")
    row = next((f for f in formats("sag map") if f.reader is reader), None)
    if row is None or row.points_reader is None:
        return reader(path, **options), None
    return row.points_reader(path, **options)


def read_measured(kind: str, path: str | Path, **instrument):
    """Read a measured ``"line profile"`` or ``"psf image"`` file with the reader of its
    suffix; a file under a suffix no format claims (``.txt``, ``.dat``, ``.tsv``) is read
    as a delimited table, the CSV reader taking any delimiter.

    ``**instrument`` are facts about the instrument, not about the file (``pixel_um``,
    the detector's pixel pitch; ``dispersion_um_per_um``, the linear dispersion at the
    line): a manifest gives them for every file, and each reader takes the ones its
    format can need (a CSV image in µm needs neither), so those a reader does not use
    are left out rather than refused.
    """
    if kind not in ("line profile", "psf image"):
        raise ValueError(f"kind={kind!r} must be 'line profile' or 'psf image'")
    path = Path(path)
    if not path.exists():
        raise ValueError(f"{path}: file does not exist")
    rows = formats(kind)
    suffix = path.suffix.lower()
    chosen = next((f for f in rows if suffix in f.suffixes), None) or next(f for f in rows if ".csv" in f.suffixes)
    takes = inspect.signature(chosen.reader).parameters
    return chosen.reader(path, **{k: v for k, v in instrument.items() if k in takes})


def load_sag_map(path: str | Path) -> SagMap:
    """Sag map for the CLI ``--sag FILE`` option (any :data:`SAG_FORMATS` suffix);
    errors are prefixed with ``--sag``."""
    try:
        return read_sag_map(path)
    except GridUnknownError as exc:  # the command line has no grid options: the title must carry it
        remedy = "add EXTENT_MM x0 x1 y0 y1 (mm, first/last sample centres) to the title"
        raise ValueError(f"--sag {exc.with_remedy(remedy)}") from None
    except ValueError as exc:
        raise ValueError(f"--sag {exc}") from None


if __name__ == "__main__":
    sys.stdout.write(format_table() + "\n\nNames accepted inside files (pipeline.io.columns):\n"
                     + names_table() + "\n")
