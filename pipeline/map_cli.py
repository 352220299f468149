"""Commands on one sag map of any readable format: ``cryograting convert`` (into another
format: an interferometer's export into a CODE V INT or a Zemax Grid Sag, ...) and
``cryograting fit`` (Zernike or quilt-Fourier coefficients of the map over a region)."""

from __future__ import annotations

from pathlib import Path

__all__ = ["register", "describe", "parse_basis", "fit_table", "reader_options", "READER_OPTIONS"]

#: ``--basis`` families: Zernike in a single-index convention (count of terms), or the quilt's Fourier series.
BASES = ("zernike-noll", "zernike-fringe", "fourier")


def describe(sagmap) -> str:
    """One line: grid, spacing, valid samples, P/V and RMS (piston removed) of the valid samples."""
    v = sagmap.sag_um[sagmap.mask]
    return (f"{sagmap.sag_um.shape[1]} x {sagmap.sag_um.shape[0]} samples at {sagmap.dx_mm:g} x {sagmap.dy_mm:g} mm, "
            f"x {sagmap.x_mm[0]:.2f}..{sagmap.x_mm[-1]:.2f} mm, y {sagmap.y_mm[0]:.2f}..{sagmap.y_mm[-1]:.2f} mm; "
            f"{v.size} valid ({v.size / sagmap.sag_um.size:.0%}); P/V {v.max() - v.min():.4f} µm, "
            f"RMS {v.std():.4f} µm")


#: argparse destinations of the options a sag-map reader takes (:func:`pipeline.io.registry.read_sag_map`).
READER_OPTIONS = ("spacing_mm", "extent_mm", "wavelength_um", "quantity", "wfr_to_sag_factor")


def reader_options(a) -> dict:
    """The reader options the user gave on the command line (a format that does not use one
    refuses it, naming those it does)."""
    out = {k: getattr(a, k) for k in READER_OPTIONS if getattr(a, k, None) is not None}
    if "extent_mm" in out:
        out["extent_mm"] = tuple(out["extent_mm"])
    return out


def _cmd_convert(a) -> int:
    from pipeline.io.registry import read_sag_map, write_sag_map

    sagmap = read_sag_map(a.input, **reader_options(a))
    write_sag_map(sagmap, a.output)
    print(f"read:    {Path(a.input)} ({sagmap.meta.get('format', Path(a.input).suffix)})")
    print(f"map:     {describe(sagmap)}")
    print(f"written: {Path(a.output)}")
    return 0


def parse_basis(text: str) -> tuple[str, int]:
    """``"zernike-noll:37"`` -> ``("zernike-noll", 37)``; ``"fourier"`` -> ``("fourier", 3)``
    (harmonics); the count defaults to 37 Zernike terms or 3 harmonics."""
    name, _, count = str(text).strip().lower().partition(":")
    if name not in BASES:
        raise ValueError(f"--basis {text!r}: unknown basis {name!r}; valid: {', '.join(BASES)} "
                         "(with :N, e.g. zernike-fringe:37, fourier:3)")
    default, lo, hi = (3, 1, 10) if name == "fourier" else (37, 1, 231)
    try:
        n = int(count) if count else default
    except ValueError:
        n = -1
    if not lo <= n <= hi:
        raise ValueError(f"--basis {text!r}: the count must be an integer in [{lo}, {hi}]")
    return name, n


def fit_table(sagmap, basis: str, region: str):
    """The fit of ``sagmap`` over ``region`` in ``basis`` (:func:`parse_basis`): the fit
    and its rows ``(term, coefficient_um, phase_deg or None)``: Zernike coefficients
    RMS-normalised for Noll and unnormalised (CODE V / Zemax Fringe) for Fringe; Fourier
    terms ``i=I j=J`` of frequency ``(I / 21 mm, J / 18 mm)`` with amplitude and phase
    (:class:`optics.fitting.FourierFit`), after piston and tilts."""
    import numpy as np

    from optics.fitting import fit_fourier, fit_zernike_map
    from optics.zernike import nm_to_fringe, nm_to_noll

    name, n = parse_basis(basis)
    if name == "fourier":
        fit = fit_fourier(sagmap, harmonics=n, aperture=region)
        rows = [("piston", fit.piston_um, None), ("tilt x (um/mm)", fit.slope_um_per_mm[0], None),
                ("tilt y (um/mm)", fit.slope_um_per_mm[1], None)]
        rows += [(f"i={i} j={j}", fit.amplitude_um[(i, j)], float(np.degrees(fit.phase_rad[(i, j)])))
                 for (i, j) in fit.components]
        return fit, rows
    index = name.split("-")[1]
    to_index = nm_to_noll if index == "noll" else nm_to_fringe
    fit = fit_zernike_map(sagmap, terms=n, aperture=region, norm=index == "noll", index=index)
    rows = [(f"Z{j} (n={nm[0]} m={nm[1]})", c, None)
            for j, nm, c in sorted((to_index(*nm), nm, c) for nm, c in fit.coefficients.items())]
    return fit, rows


def _cmd_fit(a) -> int:
    from pipeline.io.common import atomic_write
    from pipeline.io.registry import read_sag_map

    sagmap = read_sag_map(a.map, **reader_options(a))
    fit, rows = fit_table(sagmap, a.basis, a.region)
    print(f"map:      {describe(sagmap)}")
    extra = (f", disc r = {fit.radius_mm:g} mm about ({fit.center_mm[0]:g}, {fit.center_mm[1]:g}) mm"
             if hasattr(fit, "radius_mm") else f", periods {fit.period_x_mm:g} x {fit.period_y_mm:g} mm")
    print(f"fit:      {a.basis} over {fit.aperture!r} ({fit.n_points} samples{extra})")
    print(f"residual: RMS {fit.residual_rms_um:.5f} µm, P/V {fit.residual_pv_um:.5f} µm; "
          f"captured {fit.captured_fraction:.2%} of the variance")
    for term, c, ph in rows:
        print(f"  {term:22s} {c:+.6f}" + ("" if ph is None else f"   phase {ph:+8.2f} deg"))
    if a.out:
        with atomic_write(Path(a.out)) as fh:
            fh.write("term,coefficient_um,phase_deg\n")
            fh.writelines(f"{t},{c!r},{'' if ph is None else repr(ph)}\n" for t, c, ph in rows)
        print(f"written:  {Path(a.out)}")
    return 0


def _suffixes(written: bool) -> str:
    """The sag-map suffixes read (or written), from the format registry."""
    from pipeline.io.registry import formats

    return " ".join(sorted({s for f in formats("sag map") if f.writer or not written for s in f.suffixes}))


def _add_reader_options(q) -> None:
    """What a map's file may not say about itself, for every command that reads one."""
    g = q.add_argument_group("what the input file may not say")
    g.add_argument("--spacing-mm", type=float, default=None,
                   help="sample pitch (mm) of an input without one (a foreign CODE V grid, a Zygo file "
                   "without lateral calibration, scattered points)")
    g.add_argument("--extent-mm", type=float, nargs=4, default=None, metavar=("XMIN", "XMAX", "YMIN", "YMAX"),
                   help="the grid's extent (mm, first to last sample) of a CODE V INT without one")
    g.add_argument("--wavelength-um", type=float, default=None,
                   help="wavelength (µm) of one wave, for a map whose heights are in waves")
    g.add_argument("--quantity", choices=("sag", "wavefront"), default=None,
                   help="what a CODE V WFR grid holds is taken as: 'wavefront' keeps it an OPD map")
    g.add_argument("--wfr-to-sag-factor", type=float, default=None,
                   help="sag = factor x OPD for a CODE V WFR grid (-0.5 for a mirror in reflection at normal "
                   "incidence)")


def register(sub) -> None:
    """Add the ``convert`` and ``fit`` subcommands to the ``cryograting`` sub-parsers."""
    q = sub.add_parser("convert", help="a sag map from one format into another (formats by suffix: "
                       "python -m pipeline.io.registry lists them)")
    q.add_argument("input", metavar="IN", help=f"sag map read: {_suffixes(False)}")
    q.add_argument("output", metavar="OUT", help=f"sag map written: {_suffixes(True)}")
    _add_reader_options(q)
    q.set_defaults(func=_cmd_convert)

    q = sub.add_parser("fit", help="Zernike or quilt-Fourier coefficients of a sag map (any readable format)")
    q.add_argument("map", metavar="MAP", help=f"sag map read: {_suffixes(False)}")
    q.add_argument("--basis", default="zernike-fringe:37",
                   help="zernike-noll:N (RMS-normalised), zernike-fringe:N (unnormalised, as CODE V ZFR) or "
                   "fourier:H (the quilt's harmonics up to H at 21 x 18 mm); default zernike-fringe:37")
    q.add_argument("--region", default="full", help="center (82 x 72 mm), interferometer (137 mm disc), pupil "
                   "(110 mm disc) or full; default full")
    _add_reader_options(q)
    q.add_argument("--out", default=None, help="CSV of the coefficients (term,coefficient_um,phase_deg)")
    q.set_defaults(func=_cmd_fit)
