"""``cryograting convert``: a sag map from one format into another (an interferometer's
export into a CODE V INT or a Zemax Grid Sag, a CODE V grid into NetCDF, ...)."""

from __future__ import annotations

from pathlib import Path

__all__ = ["register", "describe"]


def describe(sagmap) -> str:
    """One line: grid, spacing, valid samples, P/V and RMS (piston removed) of the valid samples."""
    v = sagmap.sag_um[sagmap.mask]
    return (f"{sagmap.sag_um.shape[1]} x {sagmap.sag_um.shape[0]} samples at {sagmap.dx_mm:g} x {sagmap.dy_mm:g} mm, "
            f"x {sagmap.x_mm[0]:.2f}..{sagmap.x_mm[-1]:.2f} mm, y {sagmap.y_mm[0]:.2f}..{sagmap.y_mm[-1]:.2f} mm; "
            f"{v.size} valid ({v.size / sagmap.sag_um.size:.0%}); P/V {v.max() - v.min():.4f} µm, "
            f"RMS {v.std():.4f} µm")


def _cmd_convert(a) -> int:
    from pipeline.io.registry import read_sag_map, write_sag_map

    options = {k: v for k, v in (("spacing_mm", a.spacing_mm), ("wavelength_um", a.wavelength_um)) if v is not None}
    sagmap = read_sag_map(a.input, **options)
    write_sag_map(sagmap, a.output)
    print(f"read:    {Path(a.input)} ({sagmap.meta.get('format', Path(a.input).suffix)})")
    print(f"map:     {describe(sagmap)}")
    print(f"written: {Path(a.output)}")
    return 0


def register(sub) -> None:
    """Add the ``convert`` subcommand to the ``cryograting`` sub-parsers."""
    q = sub.add_parser("convert", help="a sag map from one format into another (formats by suffix: "
                       "python -m pipeline.io.registry lists them)")
    q.add_argument("input", metavar="IN", help="sag map: .int .dat .csv .nc .npz, or a Zygo .asc/.dat/.datx")
    q.add_argument("output", metavar="OUT", help="sag map written: .int (CODE V) .dat (Zemax) .csv .nc .npz")
    q.add_argument("--spacing-mm", type=float, default=None,
                   help="sample pitch (mm) of an input without one (a foreign CODE V grid, a Zygo file "
                   "without lateral calibration, scattered CSV points)")
    q.add_argument("--wavelength-um", type=float, default=None, help="wavelength of a NetCDF map in waves (µm)")
    q.set_defaults(func=_cmd_convert)
