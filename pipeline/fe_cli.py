"""``cryograting import-fe``: an FE result from any solver -> sag map + rigid-body report."""

from __future__ import annotations

from pathlib import Path

__all__ = ["register", "format_report"]


def format_report(res) -> str:
    """The rigid-body motion and face statistics as text (µm, µrad and arcsec)."""
    rb, st = res.rigid_body, res.stats
    lines = [f"face: {res.n_face_nodes} nodes; {res.sag_map.meta.get('interpolation', '')}",
             "rigid-body motion removed (optical frame: x dispersion, y rulings, z outward normal; "
             "about the face centre):"]
    lines += [f"  d{a} = {getattr(rb, f'd{a}_um'):+.4f} µm" for a in "xyz"]
    lines += [f"  r{a} = {getattr(rb, f'r{a}_urad'):+.4f} µrad = {getattr(rb, f'r{a}_arcsec'):+.4f} arcsec"
              + ("  (groove clocking)" if a == "z" else "") for a in "xyz"]
    lines += ["over the whole face, at its nodes (RMS area-weighted; the map's regions: cryograting fit):",
              f"  P/V, RMS (piston, tilt removed):        {st['pv_ptt_um']:.4f}, {st['rms_ptt_um']:.4f} µm",
              f"  P/V, RMS (piston, tilt, power removed): {st['pv_pttp_um']:.4f}, {st['rms_pttp_um']:.4f} µm"]
    if "result_set" in res.sag_map.meta:
        lines.insert(1, f"result set: {res.sag_map.meta['result_set']}")
    lines += [f"note: {n}" for n in res.sag_map.meta.get("notes", ())]
    return "\n".join(lines)


def _origin(text):
    if text is None:
        return None
    try:
        v = [float(t) for t in text.split(",")]
    except ValueError:
        v = []
    if len(v) != 3:
        raise ValueError(f"--origin {text!r}: expected X,Y,Z in the solver's length unit")
    return v


def _cmd_import_fe(a) -> int:
    from pipeline.io.registry import write_sag_map
    from pipeline.io.fe import import_fe

    res = import_fe(a.result, a.surface, displacement_csv=a.displacement_csv, nodes=a.nodes, load_step=a.load_step,
                    substep=a.substep, field=a.field, length_unit=a.unit, tol=a.tol, angle_tol_deg=a.angle_tol_deg,
                    sag_along=a.sag_along, axes=a.axes, origin=_origin(a.origin), spacing_mm=a.spacing_mm)
    write_sag_map(res.sag_map, a.out)
    print(format_report(res))
    print(f"written: {Path(a.out)}")
    return 0


def register(sub) -> None:
    """Add the ``import-fe`` subcommand to the ``cryograting`` sub-parsers."""
    q = sub.add_parser("import-fe", help="sag map and rigid-body motion of the optical face of an FE result "
                       "from any solver (VTU, XDMF, Exodus, gmsh; Abaqus .inp / Nastran .bdf + displacement CSV; "
                       "a table of nodes x,y,z,ux,uy,uz; ANSYS PRNSOL,U + NLIST listings)")
    q.add_argument("result", metavar="RESULT", help="mesh with nodal displacements (or a mesh with --displacement-csv), "
                   "a .csv/.txt/.tsv table of nodes with coordinates and displacements, or an ANSYS PRNSOL,U "
                   "listing with --nodes (for both, the face is a plane or an axis, --surface z=10 or +z)")
    q.add_argument("--surface", required=True, help="optical face: a node set / cell set / physical group name, "
                   "a plane such as z=10 (solver unit), or an outward normal such as +z or normal:0,0,1")
    q.add_argument("--out", required=True, help="output sag map; format by suffix (.int CODE V, .dat Zemax, "
                   ".csv, .nc, .npz)")
    q.add_argument("--displacement-csv", default=None, help="node_id,ux,uy,uz (solver unit) for a mesh "
                   "without results (Abaqus .inp, Nastran .bdf)")
    q.add_argument("--nodes", default=None, metavar="NLIST", help="ANSYS NLIST listing of the model's nodes "
                   "(coordinates) when RESULT is a PRNSOL,U listing; paired by node number")
    q.add_argument("--load-step", type=int, default=None, metavar="N", help="result set of an ANSYS listing that holds several: "
                   "its LOAD STEP number")
    q.add_argument("--substep", type=int, default=None, metavar="M", help="with --load-step: its SUBSTEP, where the load step "
                   "has several")
    q.add_argument("--field", default=None, help="point-data name of the displacement (default: found by name)")
    q.add_argument("--unit", default="mm", help="solver length unit: mm, m or in (default mm)")
    q.add_argument("--tol", type=float, default=None, help="plane tolerance, solver unit (default 1e-6 of the "
                   "model size)")
    q.add_argument("--angle-tol-deg", type=float, default=1.0, help="tolerance of a normal selection, degrees")
    q.add_argument("--sag-along", default="z", help="z (optical +z) or normal (local outward normal)")
    q.add_argument("--axes", default="x,y,z", help="optical x (dispersion), y (rulings), z (outward normal) "
                   "as signed solver axes, e.g. y,x,-z (default x,y,z)")
    q.add_argument("--origin", default=None, metavar="X,Y,Z", help="optical origin in solver coordinates "
                   "(default: the face centre)")
    q.add_argument("--spacing-mm", type=float, default=0.5, help="grid spacing of the map, mm (default 0.5)")
    q.set_defaults(func=_cmd_import_fe)
