"""The names the readers accept for each quantity: one table for delimited text tables
(:mod:`pipeline.io.common`), NetCDF variables and ``.npz`` arrays (:mod:`pipeline.io.plain`),
measured profiles and images (:mod:`pipeline.io.measured`) and FITS binary tables
(:mod:`pipeline.io.fits`).

A name is a *stem*, then, after an underscore, a *unit*; a table header ``Height [nm]``,
``height (nm)`` or ``height nm`` reads as ``height_nm``. Names match case-insensitively.

============== =============================================== ==========================================
quantity       stems, in order of preference                   unit
============== =============================================== ==========================================
sag (height)   ``sag``, ``height``, ``z``                      required: nm, um/µm, mm, m (long forms
                                                               too) or waves (with ``wavelength_um``);
                                                               NetCDF: the ``units`` attribute
x, y (maps)    ``x``, ``y``                                    required length unit (NetCDF dims ``x``,
                                                               ``y``: ``units`` attribute, default mm)
intensity      ``intensity``, ``flux``, ``counts``,             optional, any (:data:`INTENSITY_UNITS`
               ``signal``, ``data``, ``value``                 first; flux and background are fitted)
profile axis   ``offset`` (length unit), pixels                :data:`PIXEL_OFFSET_COLUMNS`,
               (:data:`PIXEL_OFFSET_COLUMNS`), a wavelength    :data:`WAVELENGTH_COLUMNS`
               (:data:`WAVELENGTH_COLUMNS`, any length unit)
============== =============================================== ==========================================

A height or coordinate without its unit (``z``, ``height``, ``x``) is refused, the error
listing the accepted names and how to write the unit: no unit is assumed for a length. Where a
file holds several accepted names for one quantity, the first in the order above is read.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Iterable

from pipeline.io.gridding import SAG_UNITS_TO_UM, WAVE_UNITS

__all__ = ["Quantity", "SAG", "X", "Y", "INTENSITY", "INTENSITY_UNITS", "QUALIFIERS", "ANY_UNIT", "matches",
           "PIXEL_OFFSET_COLUMNS", "WAVELENGTH_COLUMNS", "TABLE_AXIS_STEMS", "split_unit", "names_table"]

#: Units an intensity column may carry; all are read alike (any normalisation is data), and so
#: is any other unit (``Flux [e-/s]``, ``flux [erg/s/cm2/A]``): these are only preferred.
INTENSITY_UNITS = ("counts", "count", "cts", "adu", "dn", "e", "e-", "electrons", "photons", "arb", "a.u.", "au",
                   "norm", "normalised", "normalized", "rel", "relative")
#: What follows a stem where a column holds something else about that quantity (its error,
#: a mask, a model, a background), not a unit: ``flux_err``, ``Flux (sigma)``, ``counts_bkg``.
QUALIFIERS = ("err", "error", "errors", "sigma", "unc", "uncert", "uncertainty", "var", "variance", "ivar", "std",
              "stddev", "rms", "mask", "quality", "qual", "dq", "flag", "flags", "snr", "noise", "model", "fit", "bg",
              "bkg", "back", "background", "sky", "weight", "weights")
#: A name ``<stem>_*`` in :meth:`Quantity.names` stands for the stem with any unit that is not
#: a qualifier (:func:`matches`).
ANY_UNIT = "*"


def matches(name: str, header_name: str) -> bool:
    """Whether ``header_name`` (canonical, lower case) is the accepted ``name``: equal, or, for
    ``<stem>_*``, the stem with any unit that does not start with a :data:`QUALIFIERS` word."""
    stem, _, unit = name.partition("_")
    if unit != ANY_UNIT:
        return header_name == name
    s, sep, u = header_name.partition("_")
    return s == stem and bool(sep) and bool(u) and re.split(r"[^a-z]", u)[0] not in QUALIFIERS


def split_unit(name: str) -> tuple[str, str]:
    """``"height_nm"`` -> ``("height", "nm")``, ``"z"`` -> ``("z", "")`` (lower case)."""
    stem, _, unit = str(name).strip().lower().partition("_")
    return stem, unit


@dataclass(frozen=True)
class Quantity:
    """One quantity's accepted names.

    Attributes
    ----------
    what : str
        The quantity in words, for errors.
    stems : tuple of str
        Stems, in order of preference.
    units : tuple of str
        Units a name may carry after its stem.
    unit_required : bool
        Whether a bare stem (no unit) is refused.
    example : str
        Names as a header may spell them, for errors.
    any_unit : bool
        Whether a stem with a unit not in ``units`` is accepted too (after every listed
        name; :data:`ANY_UNIT`).
    """

    what: str
    stems: tuple[str, ...]
    units: tuple[str, ...]
    unit_required: bool
    example: str
    any_unit: bool = False

    def names(self, length_unit: str | None = None, bare: bool = False) -> tuple[str, ...]:
        """Every accepted name, in order of preference. With ``length_unit`` the names in
        a length unit are given once, in that unit: the table reader
        (:func:`pipeline.io.common.read_csv_choices`) matches and converts the others.
        ``bare`` lists the stems too where the unit comes from elsewhere (a NetCDF
        ``units`` attribute)."""
        def units(stem):
            if length_unit is None:
                return tuple(f"{stem}_{u}" for u in self.units)
            other = tuple(f"{stem}_{u}" for u in self.units if u not in SAG_UNITS_TO_UM)
            return ((f"{stem}_{length_unit}",) if any(u in SAG_UNITS_TO_UM for u in self.units) else ()) + other

        listed = tuple(n for s in self.stems for n in ((() if self.unit_required and not bare else (s,)) + units(s)))
        return listed + (tuple(f"{s}_{ANY_UNIT}" for s in self.stems) if self.any_unit else ())

    def find(self, names: Iterable[str], bare: bool = False) -> tuple[str, str] | None:
        """(name as given, its unit, "" for none) of the first of ``names`` that is
        accepted (with ``bare``, a stem without a unit too), by order of preference; None
        if none is."""
        given = {str(n).strip().lower(): str(n) for n in names}
        for n in self.names(bare=bare):
            hit = next((g for g in given if matches(n, g)), None)
            if hit is not None:
                return given[hit], split_unit(hit)[1]
        return None

    def bare(self, names: Iterable[str]) -> list[str]:
        """The ``names`` that are a stem without the unit it needs."""
        if not self.unit_required:
            return []
        return [str(n) for n in names if str(n).strip().lower() in self.stems]

    def describe(self) -> str:
        """The accepted names in words, for an error message."""
        stems = ", ".join(repr(s) for s in self.stems)
        if self.unit_required:
            return f"{self.what}: {stems} with its unit in the name ({self.example})"
        return f"{self.what}: {stems}, with or without a unit ({self.example})"

    def refusal(self, names: Iterable[str]) -> str:
        """Why none of ``names`` is accepted and what is: a bare stem is named."""
        bare = self.bare(names)
        head = (f"{', '.join(repr(b) for b in bare)} has no unit; " if bare else "")
        return head + "accepted " + self.describe()


_LENGTH_UNITS = tuple(SAG_UNITS_TO_UM)
#: A sag map's height: in a length unit, or in waves (one wave is the reader's ``wavelength_um``).
SAG = Quantity("sag (surface height)", ("sag", "height", "z"), _LENGTH_UNITS + WAVE_UNITS, True,
               "sag_um, Height [nm], Z (mm), sag [waves] with wavelength_um")
#: A map's coordinates, in a length unit.
X = Quantity("x coordinate", ("x",), _LENGTH_UNITS, True, "x_mm, X [m]")
Y = Quantity("y coordinate", ("y",), _LENGTH_UNITS, True, "y_mm, Y [m]")
#: A profile's or an image's intensity.
INTENSITY = Quantity("intensity", ("intensity", "flux", "counts", "signal", "data", "value"), INTENSITY_UNITS, False,
                     "intensity, counts, Flux [ADU], Flux [e-/s]: any unit, all read alike", any_unit=True)

#: Table columns of a profile's offsets in detector pixels (after ``[px]`` -> ``_px``).
PIXEL_OFFSET_COLUMNS = ("offset_px", "offset_pixel", "offset_pixels", "offset_pix", "pixel", "pixels", "px")
#: Table columns of a profile's wavelength axis (any length unit: ``wavelength_nm``, ``lambda [nm]``).
WAVELENGTH_COLUMNS = ("wavelength_um", "lambda_um", "wave_um")
#: FITS table columns of a profile's axis: (stem, axis kind), the unit from ``TUNIT`` or the
#: name's suffix (``wave_nm``, ``offset_mm``).
TABLE_AXIS_STEMS = (("offset", "offset_um"), ("wave", "wavelength_um"), ("wavelength", "wavelength_um"),
                    ("lambda", "wavelength_um"), ("wavelen", "wavelength_um"), ("pixel", "pixel"), ("px", "pixel"),
                    ("x", "offset_um"))


def names_table() -> str:
    """Plain-text list of the accepted names of every quantity."""
    rows = [q.describe() for q in (SAG, X, Y, INTENSITY)]
    rows.append("profile axis: 'offset' with a length unit (offset_um, Offset [mm]); detector pixels "
                + ", ".join(repr(c) for c in PIXEL_OFFSET_COLUMNS) + "; a wavelength "
                + ", ".join(repr(c.rpartition('_')[0]) for c in WAVELENGTH_COLUMNS) + " with a length unit")
    return "\n".join(rows)
