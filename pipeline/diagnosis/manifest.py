"""Measurement manifests (TOML) for the sim-to-real diagnosis, and loading their data.

A manifest names the nominal simulation and the measurements it is compared with::

    [simulation]              # the nominal model: any FEA case parameter (fea.case.PARAMETERS)
    coverage = "all"          # all | holes | surfaces | faces | none
    t0_um = 200
    polish = 0.75
    cold_K = 80
    substrate = "Al6061-T6"   # optional, as every other FEA parameter (blank geometry, film, warm_K)
    mesh = "default"          # optional: coarse | default | refined (FEA mesh of the nominal model)
    sag_file = "nominal.npz"  # optional: use this map (at cold_K) instead of solving the FEA

    [[measurement]]
    kind = "surface"          # cold-minus-warm sag map (CODE V .int, Zemax/Zygo .dat, CSV, .nc, .npz, .fits)
    file = "cryo_map.int"
    temperature_K = 128
    aperture_diameter_mm = 137
    # optional, for a file that does not carry its grid (a CODE V INT without the
    # EXTENT_MM title): spacing_mm = 0.5 (or [dx, dy]), or instead
    # extent_mm = [-68.5, 68.5, -60, 60]  (first/last sample centres x0, x1, y0, y1, mm)
    # optional: centre_mm = [68.5, 60]  (map coordinates of the blank's centre; needed
    # when the map counts from a corner: a map read mostly off the blank is refused)
    # optional: sag_sign = -1  (the file's heights are along -z, e.g. a surface height)

    [[measurement]]
    kind = "line_profile"     # CSV offset_um,intensity (offset in nm/mm, offset_px in 18 µm pixels,
                              # or wavelength_nm through the grating's dispersion at the line),
                              # or FITS (1-D spectrum with a WCS axis, or a table)
    file = "J_1p25_250mas.csv"
    grating = "J"
    order = -2
    wavelength_um = 1.25
    pixel_scale_mas = 250
    slit_position = 0.0

    [[measurement]]
    kind = "psf_image"        # image of a point source (pinhole at the slit centre)
    file = "J_1p25_psf.csv"   # CSV x_um,y_um,intensity (x dispersion, y along the slit), .npz or FITS
    grating = "J"
    order = -2
    wavelength_um = 1.25
    pixel_um = 18             # optional: detector pixel the image is integrated over (default 18)

A profile's or image's ``wavelength_um`` lies in its grating's band (``band_um`` of
:data:`optics.grating.GRATINGS`, edges included) when ``order`` is the blaze order (the
default); in another order (an off-band line, the grating turned) it must need a turn
within the optical model's domain (:meth:`optics.grating.Grating.check_in_domain`).

Optional per measurement: ``name`` (default: file stem), ``blank`` (which grating blank
the data see; default the grating for profiles, ``grating`` or "spare" for surfaces),
``noise_um`` (surface) / ``noise_rel`` (profile or PSF image, fraction of the peak) or
``noise_counts`` (profile or PSF image: the RMS noise in the file's own intensity units,
turned into ``noise_rel`` with the floor and peak the data are scaled by) when known;
``interpixel_coupling`` (the fraction of a pixel's signal read in each neighbour, valid
0-0.25) where the detector is characterised: a profile's model holds it instead of fitting
it (its two x neighbours), a PSF image's holds it on its four neighbours (an image needs
``pixel_um > 0``; without a stated one a detector image's coupling is fitted, 0-5 %, and a
focal-plane image has none); for a profile, a correlated noise the detector is known to add
(flat-field residual, fringing: ``correlated_noise_rel``, a fraction of the line's peak, or
``correlated_noise_counts``, with ``correlation_length_um``, the squared-exponential
correlation length at the detector), which the gap test then expects of a right model
beside the white noise. A PSF image is a dithered (sub-pixel sampled) image of the
pixel-integrated PSF; its white noise is estimated from the power beyond the optical
cut-off when it lies on a regular grid finer than ``wavelength f_cam / (2 D)`` (≈ 2 µm in
J), else along the image rows (biased high where the Airy rings are not smooth on the
sample step), so a coarser image, or one that is not on rows of >= 5 samples, should give
``noise_rel`` or ``noise_counts``.
Surfaces may also give ``wavelength_um`` (for a sag in waves: a NetCDF ``units = "waves"``, a
table column ``sag [waves]``);
``spacing_mm`` / ``extent_mm`` / ``wavelength_um`` go to the sag-map reader, which
refuses those its format does not use. Profiles and images may be in counts, with a
pedestal, negative (background-subtracted) samples, any centring and any offset grid;
they are handed to the fit with a robust floor (20th percentile) removed and scaled to
unit line peak, so ``noise_rel`` is a fraction of the line's peak above background, and
a line far from the origin (in detector coordinates) is moved to it (``origin_um``).
Relative paths are relative to the manifest, and every path must stay in the manifest's
directory (no absolute path elsewhere, no ``..``) unless ``--allow-outside-paths``
(``allow_outside=True``) is given. Every error names the measurement and the field;
unknown fields are refused with the valid ones.
"""

from __future__ import annotations

import difflib
import math
import tomllib
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from fea.case import PARAMETERS, FEACase
from optics.sagmap import SagMap

from .noise import CorrelatedNoise

__all__ = ["Simulation", "MESH_SPECS", "NOMINAL_SIMULATION", "Measurement", "Manifest", "SurfaceData", "ProfileData",
           "PsfImageData", "MEASUREMENT_KEYS", "SIMULATION_KEYS", "NOISE_RANGES", "COUPLING_RANGE", "ALLOW_OUTSIDE_FLAG",
           "recentre", "read_summary", "resolve_data_path", "unit_line_peak", "unknown_keys_error", "load_manifest", "parse_manifest",
           "load_data"]

#: Named FEA meshes of the nominal model (element size near surfaces / in the bulk, mm); see
#: ``benchmarks/results_mesh_convergence.md``: P/V_center of "default" is 1.2-1.6 %,
#: of "refined" 0.4-1.0 % below the Richardson-extrapolated value.
MESH_SPECS = {"coarse": dict(size_mm=5.0, size_bulk_mm=10.0), "default": dict(size_mm=1.4, size_bulk_mm=2.8),
              "refined": dict(size_mm=1.0, size_bulk_mm=2.0)}
#: The [simulation] table the synthetic generators write (campaign, scenarios): the FEA
#: case's defaults, the paper's 200 µm / 75 % "all" coating at 80 K, named explicitly.
NOMINAL_SIMULATION = {k: PARAMETERS[k].default for k in ("coverage", "t0_um", "polish", "cold_K")}
#: FEA parameters a [simulation] table may set: all but the element sizes, which ``mesh`` names.
_SIMULATION_FEA_KEYS = tuple(k for k in PARAMETERS if k not in ("mesh_size_mm", "mesh_bulk_mm"))
_KINDS = ("surface", "line_profile", "psf_image")
_PIXEL_SCALES = (25, 100, 250)
_COMMON_KEYS = ("name", "kind", "file", "blank")
#: Valid fields of a [[measurement]] table, per kind.
MEASUREMENT_KEYS = {
    "surface": _COMMON_KEYS + ("grating", "temperature_K", "aperture_diameter_mm", "noise_um", "spacing_mm",
                               "extent_mm", "wavelength_um", "centre_mm", "sag_sign", "wfr_to_sag_factor"),
    "line_profile": _COMMON_KEYS + ("grating", "order", "wavelength_um", "pixel_scale_mas", "slit_position",
                                    "noise_rel", "noise_counts", "interpixel_coupling", "correlated_noise_rel",
                                    "correlated_noise_counts", "correlation_length_um"),
    "psf_image": _COMMON_KEYS + ("grating", "order", "wavelength_um", "pixel_um", "noise_rel", "noise_counts",
                                 "interpixel_coupling"),
}
SIMULATION_KEYS = (*_SIMULATION_FEA_KEYS, "mesh", "sag_file")
#: Fraction of a profile's or image's samples at or below its floor (background estimate).
FLOOR_PERCENTILE = 20.0
#: Valid noise levels: ``noise_rel`` is a fraction of the line's peak (1e-6: a 20-bit
#: detector's quantisation; 1: the noise as large as the line), ``noise_um`` a map's RMS
#: noise in µm (1e-6 µm = 1 pm, far below any interferometer; 10 µm, 40x the nominal
#: map's RMS). Outside them the fit's weights (1/noise^2) overflow or the data hold no line.
NOISE_RANGES = {"noise_rel": (1e-6, 1.0), "noise_um": (1e-6, 10.0)}
#: Valid stated correlation length of a profile's correlated noise (µm at the detector):
#: below 0.1 µm it is white noise (far below any sample step), beyond 1000 µm (55 pixels)
#: it is a constant over any profile's window, which the background nuisance takes.
CORRELATION_LENGTH_RANGE_UM = (0.1, 1000.0)
#: Valid stated inter-pixel coupling (fraction of a pixel's signal read in each x neighbour):
#: the kernel ``[c, 1 - 2c, c]`` stays positive to 0.5; 0.25 is far beyond any measured
#: infrared array (HAWAII-type: 0.01-0.02), so a larger value is a typing error (a percentage).
COUPLING_RANGE = (0.0, 0.25)
#: The flag that lets a manifest name files outside its own directory (CLI; the API's is
#: ``allow_outside=True``).
ALLOW_OUTSIDE_FLAG = "--allow-outside-paths"


@dataclass(frozen=True)
class Simulation:
    """The nominal model: an FEA case on a named mesh, or a given sag map at ``case.cold_K``.

    Build it with :meth:`from_params` (a [simulation] table); ``cold_K``, ``warm_K`` and the
    other case parameters are read through the case (``sim.case.substrate``).
    """

    case: FEACase = FEACase(mesh_size_mm=MESH_SPECS["default"]["size_mm"],
                            mesh_bulk_mm=MESH_SPECS["default"]["size_bulk_mm"])
    mesh: str = "default"
    sag_file: Path | None = None

    @classmethod
    def from_params(cls, params: dict) -> Simulation:
        """Validate a [simulation] table (keys :data:`SIMULATION_KEYS`); errors name the field."""
        mesh = params.get("mesh", "default")
        if mesh not in MESH_SPECS:
            raise ValueError(f"[simulation] mesh={mesh!r} is unknown; valid: {list(MESH_SPECS)}")
        fea = {k: v for k, v in params.items() if k in _SIMULATION_FEA_KEYS}
        sizes = MESH_SPECS[mesh]
        try:
            case = FEACase.from_params({**fea, "mesh_size_mm": sizes["size_mm"],
                                        "mesh_bulk_mm": sizes["size_bulk_mm"]})
        except ValueError as exc:
            raise ValueError(f"[simulation] {exc}") from None
        return cls(case, mesh, params.get("sag_file"))

    @property
    def cold_K(self) -> float:
        """Temperature of the nominal map (K)."""
        return self.case.cold_K

    @property
    def warm_K(self) -> float:
        """Stress-free temperature of the nominal model (K)."""
        return self.case.warm_K

    @property
    def materials(self) -> tuple[str, str]:
        """(substrate, film) names: their mismatch strain rescales the nominal in temperature."""
        return self.case.substrate, self.case.film


@dataclass(frozen=True)
class Measurement:
    """One measurement entry (units in the field names). ``blank`` groups measurements
    that see the same grating blank (its deformation amplitude is one parameter)."""

    name: str
    kind: str
    file: Path
    blank: str
    temperature_K: float | None = None
    aperture_diameter_mm: float | None = None
    grating: str | None = None
    order: int | None = None
    wavelength_um: float | None = None
    pixel_scale_mas: int | None = None
    slit_position: float = 0.0
    noise_um: float | None = None
    noise_rel: float | None = None
    #: The RMS white noise in the file's own intensity units (counts, ADU, electrons), as a
    #: detector is characterised; the reader turns it into ``noise_rel`` with the same floor
    #: and peak it scales the data by.
    noise_counts: float | None = None
    #: The detector's inter-pixel coupling at the line (fraction to each x neighbour) where it
    #: is characterised; None: every line-profile model fits it (0-5 %).
    interpixel_coupling: float | None = None
    #: A correlated noise along a profile's offsets where the detector is characterised
    #: (flat-field residual, fringing): its RMS as a fraction of the line's peak above
    #: background, or in the file's units (turned into the fraction as ``noise_counts``),
    #: and its squared-exponential correlation length (:class:`.noise.CorrelatedNoise`).
    correlated_noise_rel: float | None = None
    correlated_noise_counts: float | None = None
    correlation_length_um: float | None = None
    pixel_um: float | None = None
    spacing_mm: float | tuple[float, float] | None = None
    extent_mm: tuple[float, float, float, float] | None = None
    #: Map coordinates (mm) of the blank's centre; None: the map is taken as centred on
    #: the blank and checked (:data:`OFF_CENTRE_LIMIT_MM`).
    centre_mm: tuple[float, float] | None = None
    #: +1, or -1 for a map whose heights are measured the other way (surface height along
    #: -z, the grating's sag along +z): multiplies the file's values.
    sag_sign: int = 1
    #: ``sag = factor * wavefront`` for a CODE V ``WFR`` file (a grating measured in
    #: reflection: ``-1 / (cos alpha + cos beta)`` of the test's angles); None: a sag file.
    wfr_to_sag_factor: float | None = None

    @property
    def correlated_noise(self) -> CorrelatedNoise | None:
        """The stated correlated noise (None: none stated)."""
        if self.correlated_noise_rel is None or self.correlation_length_um is None:
            return None
        return CorrelatedNoise(self.correlated_noise_rel, self.correlation_length_um)

    @property
    def read_options(self) -> dict:
        """Keyword options for :func:`pipeline.io.registry.read_sag_map` (surfaces)."""
        if self.kind != "surface":
            return {}
        opts = {"spacing_mm": self.spacing_mm, "extent_mm": self.extent_mm, "wavelength_um": self.wavelength_um,
                "wfr_to_sag_factor": self.wfr_to_sag_factor}
        return {k: v for k, v in opts.items() if v is not None}


@dataclass(frozen=True)
class Manifest:
    """A parsed manifest: the simulation, the measurements, the directory files are relative to."""

    simulation: Simulation
    measurements: tuple[Measurement, ...]
    base_dir: Path = Path(".")
    source: str = ""


@dataclass(frozen=True, eq=False)
class SurfaceData:
    """Valid samples of a surface map inside its aperture (mm, µm), plus the map itself.

    For a file of scattered points (``scattered``) the samples are the measured points
    themselves, the map their linear interpolation onto a grid (for plots and exports):
    the fit then meets the points' own, independent noise, and no interpolation error. For
    any other file they are the map's valid grid nodes."""

    measurement: Measurement
    x_mm: np.ndarray
    y_mm: np.ndarray
    sag_um: np.ndarray
    sagmap: object = field(repr=False, default=None)
    scattered: bool = False

    @property
    def gridding(self) -> str | None:
        """How the file's samples were put on the map's grid (``meta["gridding"]`` of the
        point-list reader: put back on their grid, or scattered and interpolated), or None
        for a file that holds its grid."""
        return (getattr(self.sagmap, "meta", None) or {}).get("gridding")

    @property
    def points_noise_um(self) -> float | None:
        """White-noise sigma (µm) of scattered points estimated from the points themselves
        (:func:`pipeline.io.gridding.grid_points`), else None."""
        v = (getattr(self.sagmap, "meta", None) or {}).get("points_noise_um")
        return float(v) if v is not None and np.isfinite(v) and v > 0 else None

    @property
    def node_noise_factor(self) -> float | None:
        """White noise of grid nodes interpolated from scattered points over that of the
        points (dimensionless, :func:`pipeline.io.gridding.node_noise_factor`) when the
        samples are such nodes (a gridded map of scattered points saved to a grid format),
        else None (the samples are points, or a grid measured as such)."""
        if self.scattered:
            return None
        v = (getattr(self.sagmap, "meta", None) or {}).get("node_noise_factor")
        return float(v) if v is not None and np.isfinite(v) and v > 0 else None

    @property
    def samples_noise_um(self) -> float | None:
        """White-noise sigma (µm) of the samples known from how they were made, else None:
        the points' own (:attr:`points_noise_um`) for scattered points; for grid nodes
        interpolated from them, that times :attr:`node_noise_factor` (a node averages its
        triangle's three points); None for a grid measured as such (its own rows give it)."""
        sigma = self.points_noise_um
        if sigma is None or self.scattered:
            return sigma
        return sigma * (self.node_noise_factor or 1.0)

    @property
    def n_points(self) -> int | None:
        """Number of scattered points in the file (None for a file holding a grid)."""
        v = (getattr(self.sagmap, "meta", None) or {}).get("n_points")
        return None if v is None else int(v)


@dataclass(frozen=True, eq=False)
class ProfileData:
    """A measured line profile sorted by offset (µm), intensity minus its floor scaled to
    unit line peak (:func:`unit_line_peak`)."""

    measurement: Measurement
    offset_um: np.ndarray
    intensity: np.ndarray
    #: offset (µm, file's frame) subtracted from the file's offsets (:func:`recentre`)
    origin_um: float = 0.0


@dataclass(frozen=True, eq=False)
class PsfImageData:
    """A measured point-source image (detector µm, x dispersion, y along the slit),
    intensity minus its floor scaled to unit peak (:func:`unit_line_peak`)."""

    measurement: Measurement
    x_um: np.ndarray
    y_um: np.ndarray
    intensity: np.ndarray
    #: (x, y) µm subtracted from the file's coordinates (:func:`recentre`)
    origin_um: tuple[float, float] = (0.0, 0.0)


def _err(name: str, fld: str, value, valid: str) -> ValueError:
    return ValueError(f"measurement {name!r}: {fld}={value!r} {valid}")


def _check_line(name: str, g, wl: float, order: int) -> None:
    """Refuse a line that grating ``g`` does not put on the detector as the optical model
    describes it; every error names the measurement ``name``, the fields and their values.

    In the blaze order the line must lie in the grating's band (``band_um``, edges
    included): the band is what the detector covers at the design angle, so a line
    outside it is not on the detector (e.g. 1.65 µm on the K grating is the H band's).
    In another order the line is an off-band measurement with the grating turned (the
    paper's 1.25 µm on the H grating in order -3): it must propagate and need no more than
    the optical model's largest turn (:meth:`optics.grating.Grating.check_in_domain`).
    """
    lo, _, hi = g.band_um
    if order == g.order:
        if not lo <= wl <= hi:
            raise _err(name, "wavelength_um", wl, f"is outside grating {g.name}'s band {lo:g}..{hi:g} µm "
                       f"(order {order}, its blaze order)")
        return
    try:
        g.check_in_domain(wl, order)
    except ValueError as exc:
        raise ValueError(f"measurement {name!r}: order={order!r}, wavelength_um={wl!r}: grating {g.name} "
                         f"(blaze order {g.order}, band {lo:g}..{hi:g} µm) cannot take this line: {exc}") from None


def _number(entry: dict, key: str, name: str, default=None, required: bool = False):
    if key not in entry:
        if required:
            raise ValueError(f"measurement {name!r}: field {key!r} is required")
        return default
    v = entry[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v):
        raise _err(name, key, v, "must be a finite number")
    return v


def unknown_keys_error(where: str, unknown, valid) -> ValueError:
    """Unknown fields named with a did-you-mean and the valid list."""
    parts = []
    for k in sorted(map(str, unknown)):
        close = difflib.get_close_matches(k, valid, n=1)
        parts.append(f"{k!r}" + (f" (did you mean {close[0]!r}?)" if close else ""))
    return ValueError(f"{where}: unknown field(s) {', '.join(parts)}; valid: {list(valid)}")


def _numbers(entry: dict, key: str, name: str, sizes: tuple[int, ...]):
    """A number or a list of ``sizes`` finite numbers (``spacing_mm``, ``extent_mm``)."""
    if key not in entry:
        return None
    v = entry[key]
    if 1 in sizes and isinstance(v, (int, float)) and not isinstance(v, bool):
        v = [v]
    ok = (isinstance(v, list) and len(v) in sizes
          and all(isinstance(a, (int, float)) and not isinstance(a, bool) and np.isfinite(a) for a in v))
    if not ok:
        raise _err(name, key, v, f"must be {' or '.join(('a number' if s == 1 else f'a list of {s} numbers') for s in sizes)} (mm)")
    return tuple(float(a) for a in v)


def _grid_options(entry: dict, name: str) -> tuple:
    sp = _numbers(entry, "spacing_mm", name, (1, 2))
    if sp is not None and not all(a > 0 for a in sp):
        raise _err(name, "spacing_mm", entry["spacing_mm"], "must be > 0 mm")
    ext = _numbers(entry, "extent_mm", name, (4,))
    if ext is not None and not (ext[1] > ext[0] and ext[3] > ext[2]):
        raise _err(name, "extent_mm", entry["extent_mm"], "must be [x0, x1, y0, y1] with x1 > x0 and y1 > y0 (mm)")
    if sp is not None and ext is not None:
        raise ValueError(f"measurement {name!r}: give spacing_mm or extent_mm, not both")
    return (sp[0] if sp is not None and len(sp) == 1 else sp), ext


def resolve_data_path(raw, base: Path, contained: bool, what: str) -> Path:
    """A manifest's file path resolved against ``base`` (the manifest's directory).

    With ``contained``, a path that leaves ``base`` (absolute elsewhere, ``..``, a link
    pointing out) is refused: a manifest from elsewhere must not make the toolkit read any
    file on the disk. ``what`` names the field in the message."""
    path = Path(str(raw))
    path = path if path.is_absolute() else base / path
    if contained and not path.resolve().is_relative_to(base.resolve()):
        raise ValueError(f"{what}={str(raw)!r} leaves the manifest's directory {base} (resolved to "
                         f"{path.resolve()}); move the file beside the manifest, or allow it with "
                         f"{ALLOW_OUTSIDE_FLAG} (API: allow_outside=True)")
    return path


def _measurement(entry: dict, index: int, base: Path, contained: bool = False) -> Measurement:
    if not isinstance(entry, dict):
        raise ValueError(f"[[measurement]] #{index + 1} is a {type(entry).__name__}, not a table")
    file = entry.get("file", f"#{index}")
    if not isinstance(file, str):
        raise ValueError(f"[[measurement]] #{index + 1}: file={file!r} must be one path, a string "
                         "(one measurement per [[measurement]] table)")
    name = str(entry.get("name", Path(file).stem))
    kind = entry.get("kind")
    if kind not in _KINDS:
        raise _err(name, "kind", kind, f"is unknown; valid: {list(_KINDS)}")
    unknown = set(entry) - set(MEASUREMENT_KEYS[kind])
    if unknown:
        raise unknown_keys_error(f"measurement {name!r} (kind {kind!r})", unknown, MEASUREMENT_KEYS[kind])
    if "file" not in entry:
        raise ValueError(f"measurement {name!r}: field 'file' is required")
    path = resolve_data_path(entry["file"], base, contained, f"measurement {name!r}: file")
    if not path.is_file():
        raise _err(name, "file", str(entry["file"]), f"does not exist (resolved to {path})")
    noise_um = _number(entry, "noise_um", name)
    noise_rel = _number(entry, "noise_rel", name)
    noise_counts = _number(entry, "noise_counts", name)
    if noise_counts is not None:
        if noise_rel is not None:
            raise _err(name, "noise_counts", noise_counts, f"and noise_rel = {noise_rel:g} are both given: state the "
                       "noise once, in the file's intensity units (noise_counts) or as a fraction of the line's "
                       "peak above background (noise_rel)")
        if not (math.isfinite(noise_counts) and noise_counts > 0):
            raise _err(name, "noise_counts", noise_counts, "must be a finite number > 0 (the RMS white noise in "
                       "the file's intensity units)")
    for k, v in (("noise_um", noise_um), ("noise_rel", noise_rel)):
        lo, hi = NOISE_RANGES[k]
        if v is not None and not lo <= v <= hi:
            raise _err(name, k, v, f"is outside the valid range [{lo:g}, {hi:g}]"
                       + (" µm" if k == "noise_um" else " (fraction of the line's peak)"))
    if kind == "surface":
        t = _number(entry, "temperature_K", name, required=True)
        if not 20 <= t < 293:
            raise _err(name, "temperature_K", t, "must be in [20, 293) K (cold map temperature)")
        ap = _number(entry, "aperture_diameter_mm", name, 137.0)
        if not 0 < ap <= 300:
            raise _err(name, "aperture_diameter_mm", ap, "must be in (0, 300] mm")
        grating = _grating_key(entry, name, required=False)
        blank = _blank(entry, grating or "spare")
        spacing, extent = _grid_options(entry, name)
        wl = _number(entry, "wavelength_um", name)
        if wl is not None and not wl > 0:
            raise _err(name, "wavelength_um", wl, "must be > 0 µm")
        centre = _numbers(entry, "centre_mm", name, (2,))
        if centre is not None and not all(abs(v) <= 300.0 for v in centre):
            raise _err(name, "centre_mm", list(centre), "must be [x0, y0] with |x0|, |y0| <= 300 mm")
        sign = entry.get("sag_sign", 1)
        if isinstance(sign, bool) or sign not in (1, -1):
            raise _err(name, "sag_sign", sign, "must be 1 or -1 (-1: the file's heights are along -z)")
        wfr = _number(entry, "wfr_to_sag_factor", name)
        if wfr is not None and not (math.isfinite(wfr) and wfr != 0):
            raise _err(name, "wfr_to_sag_factor", wfr, "must be a finite non-zero number (sag = factor x "
                       "wavefront; a reflective grating: -1 / (cos alpha + cos beta) of the test's angles)")
        return Measurement(name, kind, path, blank, temperature_K=float(t), aperture_diameter_mm=float(ap),
                           grating=grating, noise_um=noise_um, spacing_mm=spacing, extent_mm=extent,
                           wavelength_um=None if wl is None else float(wl),
                           centre_mm=None if centre is None else (float(centre[0]), float(centre[1])),
                           sag_sign=int(sign), wfr_to_sag_factor=None if wfr is None else float(wfr))
    from optics.grating import GRATINGS

    key = _grating_key(entry, name, required=True)
    wl = _number(entry, "wavelength_um", name, required=True)
    order = entry.get("order", GRATINGS[key].order)
    if isinstance(order, bool) or not isinstance(order, int) or order == 0:
        raise _err(name, "order", order, "must be a non-zero integer")
    _check_line(name, GRATINGS[key], float(wl), order)
    ipc = _number(entry, "interpixel_coupling", name)
    if ipc is not None and not COUPLING_RANGE[0] <= ipc <= COUPLING_RANGE[1]:
        raise _err(name, "interpixel_coupling", ipc, f"is outside the valid range [{COUPLING_RANGE[0]:g}, "
                   f"{COUPLING_RANGE[1]:g}] (fraction of a pixel's signal read in each neighbour, not a percentage)")
    if kind == "psf_image":
        pix = _number(entry, "pixel_um", name, 18.0)
        if not 0 <= pix <= 100:
            raise _err(name, "pixel_um", pix, "must be in [0, 100] µm (0: the PSF itself)")
        if ipc is not None and pix == 0:
            raise _err(name, "interpixel_coupling", ipc, "needs a detector pixel: pixel_um = 0 is a focal-plane "
                       "image, which no detector's pixels couple (give pixel_um > 0, or leave the coupling out)")
        return Measurement(name, kind, path, _blank(entry, key), grating=key, order=int(order),
                           wavelength_um=float(wl), noise_rel=noise_rel, noise_counts=noise_counts, pixel_um=float(pix),
                           interpixel_coupling=ipc)
    corr = _correlated_noise(entry, name)
    ps = entry.get("pixel_scale_mas")
    if ps not in _PIXEL_SCALES:
        raise _err(name, "pixel_scale_mas", ps, f"is unknown; valid: {list(_PIXEL_SCALES)}")
    sp = _number(entry, "slit_position", name, 0.0)
    if not -1 <= sp <= 1:
        raise _err(name, "slit_position", sp, "must be in [-1, 1]")
    return Measurement(name, kind, path, _blank(entry, key), grating=key, order=int(order),
                       wavelength_um=float(wl), pixel_scale_mas=int(ps), slit_position=float(sp),
                       noise_rel=noise_rel, noise_counts=noise_counts, interpixel_coupling=ipc, **corr)


def _grating_key(entry: dict, name: str, required: bool) -> str | None:
    """The measurement's ``grating`` as :data:`optics.grating.GRATINGS` spells it (``"j"``,
    ``"H+K"`` -> ``"J"``, ``"HK"``); None if absent and not ``required``; an unknown one refused."""
    from optics.grating import GRATINGS

    g = entry.get("grating")
    if g is None and not required:
        return None
    key = str(g).upper().replace("+", "") if isinstance(g, str) else None
    if key not in GRATINGS:
        raise _err(name, "grating", g, f"is unknown; valid: {sorted(GRATINGS)}")
    return key


def _blank(entry: dict, default: str) -> str:
    """The grating blank a measurement sees: ``blank``, else ``default``; a blank named as a
    grating is spelled as the grating is (``"j"`` is blank ``"J"``: one blank, one amplitude)."""
    from optics.grating import GRATINGS

    b = str(entry.get("blank", default))
    key = b.upper().replace("+", "")
    return key if key in GRATINGS else b


def _correlated_noise(entry: dict, name: str) -> dict:
    """A profile's stated correlated noise as Measurement fields (empty: none stated): an RMS
    as a fraction of the line's peak (``correlated_noise_rel``) or in the file's units
    (``correlated_noise_counts``), with its ``correlation_length_um``; one needs the other."""
    rel = _number(entry, "correlated_noise_rel", name)
    counts = _number(entry, "correlated_noise_counts", name)
    length = _number(entry, "correlation_length_um", name)
    if rel is not None and counts is not None:
        raise _err(name, "correlated_noise_counts", counts, f"and correlated_noise_rel = {rel:g} are both given: "
                   "state the correlated noise once, in the file's intensity units or as a fraction of the line's "
                   "peak above background")
    rms = rel if rel is not None else counts
    if rms is None and length is None:
        return {}
    if rms is None:
        raise _err(name, "correlation_length_um", length, "is given without the noise it describes: give "
                   "correlated_noise_rel (fraction of the line's peak) or correlated_noise_counts (the file's units)")
    key = "correlated_noise_rel" if rel is not None else "correlated_noise_counts"
    if length is None:
        raise _err(name, key, rms, "needs correlation_length_um: the distance (µm at the detector) over which the "
                   "noise's correlation falls to exp(-1/2)")
    lo, hi = CORRELATION_LENGTH_RANGE_UM
    if not lo <= length <= hi:
        raise _err(name, "correlation_length_um", length, f"is outside the valid range [{lo:g}, {hi:g}] µm")
    if rel is not None:
        lo, hi = NOISE_RANGES["noise_rel"]
        if not lo <= rel <= hi:
            raise _err(name, "correlated_noise_rel", rel, f"is outside the valid range [{lo:g}, {hi:g}] (fraction "
                       "of the line's peak)")
    elif not (math.isfinite(counts) and counts > 0):
        raise _err(name, "correlated_noise_counts", counts, "must be a finite number > 0 (the RMS correlated noise "
                   "in the file's intensity units)")
    return {"correlated_noise_rel": rel, "correlated_noise_counts": counts, "correlation_length_um": float(length)}


def parse_manifest(data: dict, base_dir: str | Path | None = None, source: str = "",
                   allow_outside: bool = False) -> Manifest:
    """Validate a manifest given as a dict (the parsed TOML); paths relative to ``base_dir``.

    With a ``base_dir`` (the manifest's directory), file paths must stay inside it unless
    ``allow_outside``; without one, paths are taken as given (relative to the working
    directory), as a Python caller wrote them."""
    if not isinstance(data, dict):
        raise TypeError(f"parse_manifest: data={data!r:.80} must be a dict (the parsed TOML); read a manifest file "
                        "with load_manifest(path)")
    contained = base_dir is not None and not allow_outside
    base = Path("." if base_dir is None else base_dir)
    top = set(data) - {"simulation", "measurement"}
    if top:
        raise unknown_keys_error("manifest", top, ("simulation", "measurement"))
    sim = data.get("simulation", {})
    if not isinstance(sim, dict):
        raise ValueError(f"[simulation] is a {type(sim).__name__} ({sim!r:.60}), not a table: write it as "
                         "[simulation] followed by key = value lines (once, not [[simulation]])")
    sim = dict(sim)
    unknown = set(sim) - set(SIMULATION_KEYS)
    if unknown:
        raise unknown_keys_error("[simulation]", unknown, SIMULATION_KEYS)
    if "sag_file" in sim:
        p = Path(str(sim["sag_file"]))
        sim["sag_file"] = resolve_data_path(p, base, contained, "[simulation] sag_file")
        if not sim["sag_file"].is_file():
            raise ValueError(f"[simulation] sag_file={str(p)!r} does not exist (resolved to {sim['sag_file']})")
    simulation = Simulation.from_params(sim)
    entries = data.get("measurement", [])
    if not isinstance(entries, list) or not entries:
        raise ValueError("manifest has no [[measurement]] entries")
    from pipeline.bounds import MAX_MEASUREMENTS

    if len(entries) > MAX_MEASUREMENTS:  # before any file is looked at
        raise ValueError(f"manifest has {len(entries)} [[measurement]] entries, outside the valid range "
                         f"1..{MAX_MEASUREMENTS}")
    ms = tuple(_measurement(e, i, base, contained) for i, e in enumerate(entries))
    names = [m.name for m in ms]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise ValueError(f"measurement names {dup} are used twice; give each a unique 'name'")
    return Manifest(simulation, ms, base, source)


def load_manifest(path_or_obj, allow_outside: bool = False) -> Manifest:
    """A :class:`Manifest` from a TOML path, a dict, or a Manifest (returned as is).

    A file's data paths are relative to its directory and must stay inside it unless
    ``allow_outside`` (CLI: ``--allow-outside-paths``)."""
    if isinstance(path_or_obj, Manifest):
        return path_or_obj
    if isinstance(path_or_obj, dict):
        return parse_manifest(path_or_obj, allow_outside=allow_outside)
    path = Path(path_or_obj)
    if not path.is_file():
        raise ValueError(f"manifest {path} does not exist")
    raw = path.read_bytes()
    if raw[:2] in (b"\xff\xfe", b"\xfe\xff"):
        raise ValueError(f"manifest {path}: is UTF-16 text; a TOML manifest must be UTF-8 (save it as UTF-8)")
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise ValueError(f"manifest {path}: is not UTF-8 text (undecodable byte 0x{raw[exc.start]:02x} at offset "
                         f"{exc.start}); a TOML manifest must be UTF-8") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"manifest {path}: invalid TOML: {exc}") from None
    return parse_manifest(data, path.parent, str(path), allow_outside)


def _read_surface(m: Measurement) -> SurfaceData:
    from pipeline.io.registry import read_sag_map_points
    from pipeline.io.gridding import GridUnknownError

    try:
        sm, points = read_sag_map_points(m.file, **m.read_options)
    except GridUnknownError as exc:
        remedy = "give extent_mm = [x0, x1, y0, y1] or spacing_mm = 0.5 (or [dx, dy]) (mm) in its [[measurement]]"
        raise ValueError(f"measurement {m.name!r}: file={str(m.file)!r}: {exc.with_remedy(remedy)}") from None
    except ValueError as exc:
        raise ValueError(f"measurement {m.name!r}: file={str(m.file)!r}: {exc}") from None
    c = m.centre_mm or (0.0, 0.0)
    if m.centre_mm is not None or m.sag_sign != 1:
        sm = SagMap(sm.x_mm - c[0], sm.y_mm - c[1], m.sag_sign * sm.sag_um, sm.label, dict(sm.meta))
    if points is None:
        X, Y = sm.grid()
        x, y, sag = X[sm.mask], Y[sm.mask], sm.sag_um[sm.mask]
    else:  # the measured points, not their interpolation: independent noise, no interpolation error
        x, y, sag = points.x_mm - c[0], points.y_mm - c[1], m.sag_sign * points.sag_um
    inside = x**2 + y**2 <= (0.5 * m.aperture_diameter_mm) ** 2
    _check_centred(m, x, y, inside)
    if inside.sum() < 50:
        what = "points" if points is not None else "pixels"
        raise _err(m.name, "aperture_diameter_mm", m.aperture_diameter_mm,
                   f"leaves {int(inside.sum())} valid {what} of {m.file.name} (need >= 50); "
                   f"the map covers x {sm.x_mm[0]:.1f}..{sm.x_mm[-1]:.1f} mm, y {sm.y_mm[0]:.1f}..{sm.y_mm[-1]:.1f} mm")
    return SurfaceData(m, x[inside], y[inside], sag[inside], sm, scattered=points is not None)


#: A map whose valid points are centred farther than this (mm) from the blank's centre
#: (its (0, 0), or ``centre_mm``) *and* mostly outside the aperture is refused: twice the
#: ``registration`` effect's ±10 mm prior, so an offset that effect can fit is never refused.
OFF_CENTRE_LIMIT_MM = 20.0


def _check_centred(m: Measurement, x: np.ndarray, y: np.ndarray, inside: np.ndarray) -> None:
    """Refuse a map read mostly off the blank: centred far from the blank's centre with
    less than half its valid points inside the aperture. Interferometer exports often
    count from a corner (measured: a 0..136 mm map kept 2 629 of 14 505 points and fitted
    registration at its bounds), and a ``centre_mm`` taken from the wrong corner does the
    same. A map of part of the blank (all inside) or one wider than the blank but centred
    passes. ``x``, ``y``: the valid samples (mm, blank frame); ``inside``: those in the aperture."""
    cx, cy = float(np.mean(x)), float(np.mean(y))
    if math.hypot(cx, cy) > OFF_CENTRE_LIMIT_MM and 2 * int(inside.sum()) < x.size:
        c = m.centre_mm or (0.0, 0.0)
        given = f"centre_mm = [{c[0]:g}, {c[1]:g}]" if m.centre_mm is not None else "no centre_mm"
        raise _err(m.name, "centre_mm", None if m.centre_mm is None else list(m.centre_mm),
                   f"puts the blank off the map: with {given}, only {int(inside.sum())} of the {x.size} valid "
                   f"points of {m.file.name} fall inside the {m.aperture_diameter_mm:g} mm aperture, and they are "
                   f"centred at x {cx:.1f}, y {cy:.1f} mm from the blank's centre (offsets up to "
                   f"{OFF_CENTRE_LIMIT_MM:g} mm are fitted as registration); give centre_mm = [{c[0] + cx:.1f}, "
                   f"{c[1] + cy:.1f}] (the map coordinates of the blank's centre, mm)")


def unit_line_peak(intensity: np.ndarray, what: str, name: str, file: Path) -> tuple[np.ndarray, float]:
    """Intensity minus its floor (the :data:`FLOOR_PERCENTILE` percentile, a background
    estimate) over the line's peak above it, and that peak (the file's units). The fit's
    flux and background nuisances absorb any error in the floor; removing it makes
    ``noise_rel`` a fraction of the line's peak whatever the pedestal, and keeps a
    centroid from being pulled to the middle of the window by it."""
    v = np.asarray(intensity, float)
    floor = float(np.percentile(v, FLOOR_PERCENTILE))
    peak = float(v.max()) - floor
    if not peak > 0:
        raise _err(name, "file", str(file), f"has no {what} above its background: every sample equals {floor:g}")
    return (v - floor) / peak, peak


def _noise_as_fraction(m: Measurement, peak: float) -> Measurement:
    """``m`` with a ``noise_counts`` (the file's units) stated as ``noise_rel``, a fraction of
    the ``peak`` the data were scaled by (file units), and a ``correlated_noise_counts`` as
    ``correlated_noise_rel`` likewise. The floor a small window reads can be
    the line's own wing (a J PSF image of 18 µm pixels cut at +-30 µm: 0.45 of the peak above
    the true background), so a noise known in counts is not the file's maximum times
    ``noise_rel``."""
    lo, hi = NOISE_RANGES["noise_rel"]
    for counts_key, rel_key in (("noise_counts", "noise_rel"), ("correlated_noise_counts", "correlated_noise_rel")):
        counts = getattr(m, counts_key)
        if counts is None:
            continue
        rel = counts / peak
        if not lo <= rel <= hi:
            raise _err(m.name, counts_key, counts, f"is {rel:.3g} of the line's peak above background "
                       f"({peak:.6g} in the file's units), outside the valid range [{lo:g}, {hi:g}]")
        m = replace(m, **{rel_key: rel})
    return m


#: Lines found farther than this from the origin (µm) are moved to it: half the range of
#: the fits' initial position search (profiles +-40 µm, PSF images +-20 µm), whose
#: position nuisance is bounded (+-45 µm), so a profile in detector coordinates fits.
RECENTRE_BEYOND_UM = {"line_profile": 20.0, "psf_image": 10.0}


def half_max_centre(coords: np.ndarray, unit_peak: np.ndarray) -> float:
    """Intensity-weighted mean position of the samples above half the (unit) peak."""
    hi = unit_peak >= 0.5
    return float(np.sum(unit_peak[hi] * coords[hi]) / np.sum(unit_peak[hi]))


def recentre(coords: np.ndarray, unit_peak: np.ndarray, beyond_um: float) -> float:
    """Centre of the samples above half the peak (:func:`half_max_centre`), rounded to
    0.1 µm, when it lies farther than ``beyond_um`` from 0; else 0. The position is a
    fitted nuisance in every model, so moving the data changes no finding."""
    c = half_max_centre(coords, unit_peak)
    return round(c, 1) if abs(c) > beyond_um else 0.0


def _read_profile(m: Measurement) -> ProfileData:
    from pipeline.io.registry import read_measured

    from optics.grating import GRATINGS, SPIFFI

    # offsets in detector pixels are the model's pixels; a wavelength axis goes through the
    # model's own signed dispersion at the line, about the line's stated wavelength
    # (optics.pupil: +offset is the image of +x_g)
    g = GRATINGS[str(m.grating).upper().replace("+", "")]
    dispersion = float(g.angular_dispersion_rad_per_um(m.wavelength_um, m.order)) * SPIFFI.camera_focal_mm * 1e3
    try:
        u, y = read_measured("line profile", m.file, normalise=False, pixel_um=SPIFFI.pixel_um,
                             dispersion_um_per_um=dispersion, line_wavelength_um=m.wavelength_um)
    except ValueError as exc:
        raise ValueError(f"measurement {m.name!r}: file={str(m.file)!r}: {exc}") from None
    if u.size < 10:
        raise _err(m.name, "file", str(m.file), f"has {u.size} samples; need >= 10")
    v, peak = unit_line_peak(y, "line", m.name, m.file)
    m = _noise_as_fraction(m, peak)
    u = np.asarray(u, float)
    c = recentre(u, v, RECENTRE_BEYOND_UM["line_profile"])
    return ProfileData(m, u - c, v, c)


def _read_psf_image(m: Measurement) -> PsfImageData:
    from pipeline.io.registry import read_measured

    try:
        # a frame in detector pixels is sampled at its pixel's pitch; a focal-plane image
        # (pixel_um = 0) has no such pitch and needs a WCS in µm
        x, y, v = read_measured("psf image", m.file, pixel_um=m.pixel_um or None)
    except ValueError as exc:
        raise ValueError(f"measurement {m.name!r}: file={str(m.file)!r}: {exc}") from None
    if m.noise_rel is None and m.noise_counts is None:
        _, counts = np.unique(np.round(y, 6), return_counts=True)
        if (counts >= 5).sum() < 5:
            raise _err(m.name, "noise_rel", None, f"is required: the {x.size} samples of {m.file.name} are not on "
                       "rows of >= 5 points, so the noise cannot be estimated from the image (or give "
                       "noise_counts, in the file's intensity units)")
    v, peak = unit_line_peak(v, "image", m.name, m.file)
    m = _noise_as_fraction(m, peak)
    cx, cy = (recentre(a, v, RECENTRE_BEYOND_UM["psf_image"]) for a in (x, y))
    return PsfImageData(m, x - cx, y - cy, v, (cx, cy))


_READERS = {"surface": _read_surface, "line_profile": _read_profile, "psf_image": _read_psf_image}


def _g(v: float) -> float:
    return float(f"{v:.4g}")


def read_summary(d) -> dict:
    """What was read from one measurement's file, as the diagnosis uses it (units in the
    keys), for the report: a wrong unit, axis or origin shows here before it shows as a
    strange finding.

    Surfaces: grid size and step, valid points inside the aperture of those in the file
    (scattered points: the points themselves, the grid being their interpolation for
    display), the valid data's extent, P/V and RMS of the sag used (µm, piston removed) and the centre shift
    applied (how scattered points were gridded is the measurement's ``gridding``). Profiles: samples, step, offset range, the line's
    centre (intensity-weighted over the samples above half the peak, file frame) and the
    shift applied. PSF images: samples, extent and the shift applied."""
    m = d.measurement
    out = {"file": m.file.name}
    if isinstance(d, SurfaceData):
        sm, s = d.sagmap, d.sag_um - float(np.mean(d.sag_um))
        # the valid data's extent, not the grid's NaN padding
        xv, yv = sm.x_mm[sm.mask.any(axis=0)], sm.y_mm[sm.mask.any(axis=1)]
        out.update({"grid": f"{sm.x_mm.size} x {sm.y_mm.size}",
                    "step_mm": f"{_g(sm.x_mm[1] - sm.x_mm[0])} x {_g(sm.y_mm[1] - sm.y_mm[0])}",
                    "points_used": int(d.sag_um.size),
                    "points_valid_in_file": int(d.n_points if d.scattered else sm.mask.sum()),
                    "x_range_mm": [_g(xv.min()), _g(xv.max())], "y_range_mm": [_g(yv.min()), _g(yv.max())],
                    "pv_um": _g(float(s.max() - s.min())), "rms_um": _g(float(np.sqrt(np.mean(s**2))))})
        if m.centre_mm is not None:
            out["centre_mm"] = f"({m.centre_mm[0]:g}, {m.centre_mm[1]:g}) subtracted"
    elif isinstance(d, ProfileData):
        u, v = d.offset_um, d.intensity
        out.update({"samples": int(u.size), "step_um": _g(float(np.median(np.diff(u)))),
                    "offset_range_um": [_g(u[0] + d.origin_um), _g(u[-1] + d.origin_um)],
                    "line_centre_um": _g(half_max_centre(u, v) + d.origin_um),
                    "shift_applied_um": _g(d.origin_um)})
    else:
        out.update({"samples": int(d.x_um.size),
                    "x_range_um": [_g(d.x_um.min() + d.origin_um[0]), _g(d.x_um.max() + d.origin_um[0])],
                    "y_range_um": [_g(d.y_um.min() + d.origin_um[1]), _g(d.y_um.max() + d.origin_um[1])],
                    "shift_applied_um": f"({_g(d.origin_um[0])}, {_g(d.origin_um[1])})"})
    return out


def load_data(manifest: Manifest) -> tuple:
    """Read every measurement's file; returns SurfaceData / ProfileData / PsfImageData in manifest order."""
    return tuple(_READERS[m.kind](m) for m in manifest.measurements)
