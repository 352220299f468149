"""The study's 3-D renders of the deformed blank, drawn in a guarded child process.

VTK can crash the interpreter (not raise) on a machine where no OpenGL back-end loads
(VTK 9.7 left to its default tries X11 first and segfaults when no X11 library is
installed), so :func:`start_study_render` solves and renders the study's figures
(:data:`STUDY_RENDERS`) in a child process (``python -m pipeline.study.render3d``): a
machine without OpenGL gets a warning and a notice figure, never a crashed run.
Finished renders are entries of the keyed store (:mod:`fea.store`) and are reused
on re-run. The scene itself: :mod:`pipeline.study.render_scene`; the surface:
:mod:`pipeline.study.render_geometry`.

Functions
---------
start_study_render    the study's figures, solved and rendered in a guarded child process
render_study_figures  the same, waited for
"""

from __future__ import annotations

import argparse
import atexit
import json
import logging
import os
import re
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path
from types import SimpleNamespace

from fea import store
from fea.case import FEACase, model_namespace
from fea.mesh import blank_mesh
from fea.model import PreparedBlank
from pipeline.study.plots import plt, save
from pipeline.study.render_scene import configure_offscreen_env, probe, render_comparison, render_deformed_blank
from pipeline.sweeps.fea_cases import field_path, load_field

__all__ = ["STUDY_RENDERS", "StudyRender", "study_renders", "start_study_render", "render_study_figures"]

log = logging.getLogger(__name__)

#: all its cases (their full parameters, mesh included, are used)
STUDY_RENDERS = {
    "blank_3d.png": ("3-D render of the deformed blank", [("all", 200.0, 0.75)], None),
    "blank_3d_holes_vs_surfaces.png": (
        "3-D render of the deformed blank",
        [("holes", 200.0, 1.0), ("surfaces", 200.0, 1.0)],
        ["NiP 200 µm only in the holes", "NiP 200 µm only on the outer surfaces"]),
}
#: payload format of a render entry (:mod:`fea.store`); bump when a render changes look
_RENDER_VERSION = 1
#: key of the child's answer that lists renders redone because their files did not verify
_REBUILT = "rebuilt"
_HEADING = "3-D render of the deformed blank"


def study_renders(cases) -> dict:
    """The :data:`STUDY_RENDERS` a study can draw: ``{file: (heading, [params], labels)}``.

    ``cases`` are the study's FEA cases (``.full`` and ``.params`` dicts, ``.is_paper_setup``).
    """
    found = {}
    for c in cases:
        full = getattr(c, "full", None) or {}
        if not getattr(c, "is_paper_setup", False):
            continue
        try:
            key = (str(full["coverage"]), float(full["t0_um"]), float(full["polish"]))
        except (KeyError, TypeError, ValueError):
            continue
        found.setdefault(key, dict(c.params))
    return {f: (h, [found[k] for k in keys], labels) for f, (h, keys, labels) in STUDY_RENDERS.items()
            if all(k in found for k in keys)}


def _entry(out: Path, file: str, params: list):
    """The render's store entry: the PNG in ``out``, its sidecar in ``out/fea/render3d``."""
    cases = [{k: (v if isinstance(v, (str, int, float, bool)) or v is None else str(v)) for k, v in p.items()}
             for p in params]
    return store.Entry(f"render3d-{model_namespace()}", {"file": file, "cases": cases}, out / file,
                       out / "fea" / "render3d" / (Path(file).stem + ".json"), format_version=_RENDER_VERSION)


def _is_current(entry, rebuilt: dict) -> bool:
    """True when the PNG of ``entry`` is the verified render of its cases; a PNG that is
    not (edited, truncated, another case's, a failure notice) is noted in ``rebuilt``."""
    try:
        store.verify(entry)
        return True
    except FileNotFoundError:
        return False
    except store.CacheMiss as exc:
        rebuilt[entry.payload.name] = str(exc)
        return False


def _render_child(out: Path, renders: dict) -> dict:
    """Solve and render (runs inside the child process); returns {file: path}."""
    done, models, rebuilt = {}, {}, {}
    for file, (_, params, labels) in renders.items():
        png, entry = out / file, _entry(out, file, params)
        if _is_current(entry, rebuilt):
            done[file] = str(png)
            continue
        t0 = time.perf_counter()
        results = []
        for c in params:
            case = FEACase.from_params(c)
            o = case.to_objects()
            blank, spec, substrate, coating, film, load, scale = (o.blank, o.mesh, case.substrate, o.coating,
                                                                  case.film, o.load, o.stress_scale)
            saved = load_field(field_path(out / "fea" / "fields", c))  # kept by the study's FEA run
            if saved is not None:
                results.append((SimpleNamespace(mesh=blank_mesh(blank, spec)), saved))
                continue
            mk = (blank, spec, substrate)
            if mk not in models:
                models = {mk: PreparedBlank(blank_mesh(blank, spec), substrate)}  # keep one: memory
            results.append((models[mk], models[mk].solve(coating, film, load, stress_scale=scale)))
        t_solve = time.perf_counter() - t0
        if len(results) == 1:
            info = render_deformed_blank(results[0][0].mesh, results[0][1], png)
        else:
            info = render_comparison(results[0][0].mesh, [r for _, r in results], labels, png)
        store.commit(entry, {"exaggeration": info["exaggeration"], "clim_um": list(info["clim_um"]),
                             "solve_s": round(t_solve, 1), "render_s": round(info["seconds"], 1)})
        done[file] = str(png)
    if rebuilt:
        done[_REBUILT] = rebuilt
    return done


def start_study_render(cases, out_dir, *, timeout_s: float = 1800.0, progress: bool = True):
    """Start the study's 3-D renders (:func:`study_renders`) in a child process.

    Returns a :class:`StudyRender` (``.figures()`` waits and returns ``{file: (heading,
    path)}``, a notice figure in place of the renders when they failed) or None when the
    study has none of the cases. The child solves its cases again (the sweep cache keeps
    sag maps, not displacement fields) with the study's parameters and mesh; finished
    renders are reused on re-run (key in ``fea/render3d/*.json``). A machine without
    OpenGL, where VTK can crash, loses only these figures, with a warning.
    """
    renders = study_renders(cases)
    if not renders:
        return None
    return StudyRender(Path(out_dir), renders, timeout_s, progress)


def render_study_figures(out_dir, cases=None, *, mesh_size_mm: float | None = None,
                         mesh_bulk_mm: float | None = None, timeout_s: float = 1800.0) -> dict:
    """:func:`start_study_render` and wait: ``{file: Path or None, ..., "error": str or None}``.

    ``cases`` default to the paper's (coverage, t0, polish) of :data:`STUDY_RENDERS` with
    the given element sizes.
    """
    if cases is None:
        extra = {k: float(v) for k, v in (("mesh_size_mm", mesh_size_mm), ("mesh_bulk_mm", mesh_bulk_mm))
                 if v is not None}
        keys = dict.fromkeys(k for _, ks, _ in STUDY_RENDERS.values() for k in ks)
        cases = [SimpleNamespace(full={"coverage": c, "t0_um": t, "polish": p}, is_paper_setup=True,
                                 params={"coverage": c, "t0_um": t, "polish": p, **extra}) for c, t, p in keys]
    h = start_study_render(cases, out_dir, timeout_s=timeout_s, progress=False)
    return h.result() if h is not None else {"error": "no cases to render"}


class StudyRender:
    """A child process rendering the study's figures (see :func:`start_study_render`)."""

    def __init__(self, out: Path, renders: dict, timeout_s: float, progress: bool = True):
        self.out, self.renders, self.timeout_s, self.progress = out, renders, timeout_s, progress
        self.t0 = time.perf_counter()
        self._result = None
        out.mkdir(parents=True, exist_ok=True)
        env = dict(os.environ)
        configure_offscreen_env(env)
        root = str(Path(__file__).resolve().parents[2])  # the directory holding the pipeline package
        env["PYTHONPATH"] = root + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
        self._err = tempfile.TemporaryFile()
        spec = {f: [h, params, labels] for f, (h, params, labels) in renders.items()}
        self._spec = tempfile.NamedTemporaryFile("w", suffix=".json", delete=False)
        json.dump(spec, self._spec, default=str)
        self._spec.close()
        try:
            # The child works in the caller's directory, so a relative --out or cache path
            # means there what it means here; the output goes as an absolute path anyway.
            # -P keeps a 'pipeline' package in that directory from shadowing this one.
            self.proc = subprocess.Popen(
                [sys.executable, "-P", "-m", "pipeline.study.render3d", "--study", str(out.resolve()),
                 "--spec", self._spec.name],
                stdout=subprocess.PIPE, stderr=self._err, env=env, cwd=os.getcwd())
        except OSError as exc:
            self.proc = None
            self._result = self._fail(f"the render process could not start: {exc}")
        else:
            atexit.register(self._kill)  # a run that dies early does not leave the child behind

    def _kill(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.kill()

    def result(self) -> dict:
        """Wait; ``{file: Path or None, ..., "error": message or None}``."""
        if self._result is None:
            self._result = self._wait()
            try:
                os.unlink(self._spec.name)
            except OSError:
                pass
            if self.progress and self._result["error"] is None:
                print(f"3-D renders: {len(self.renders)} in {time.perf_counter() - self.t0:.0f} s", flush=True)
        return self._result

    def figures(self) -> dict:
        """Wait; ``{file: (heading, path)}`` for the study's report (a notice when rendering failed)."""
        res = self.result()
        if res["error"] is None:
            return {f: (h, res[f]) for f, (h, _, _) in self.renders.items()}
        path = _notice_png(self.out / next(iter(self.renders)), res["error"])
        return {path.name: (_HEADING, path)} if path is not None else {}

    def _wait(self) -> dict:
        try:
            stdout, _ = self.proc.communicate(timeout=self.timeout_s)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.communicate()
            return self._fail(f"timed out after {self.timeout_s:g} s")
        self._err.seek(0)
        err = self._err.read().decode(errors="replace")
        self._err.close()
        if self.proc.returncode != 0:
            rc = self.proc.returncode
            why = (f"signal {-rc} (VTK found no usable OpenGL back-end?)" if rc < 0 else f"exit code {rc}")
            msgs = _last_messages(err)
            gl = rc < 0 or any(k in msgs for k in ("OpenGL", "EGL", "OSMesa", "X11", "RenderUnavailable"))
            return self._fail(f"the render process failed with {why}: {msgs.rstrip('.')}", gl)
        try:
            done = json.loads(stdout.decode().strip().splitlines()[-1])
        except (ValueError, IndexError):
            return self._fail(f"the render process gave no result: {err[-300:]}")
        for file, why in done.get(_REBUILT, {}).items():  # the child's stderr is not shown: warn here
            store.warn_rebuild(self.out / file, why, "3-D render", stacklevel=2)
        res = {f: (Path(done[f]) if f in done else None) for f in self.renders}
        res["error"] = None
        return res

    def _fail(self, why: str, opengl: bool = True) -> dict:
        msg = f"3-D render of the deformed blank unavailable: {why}. The rest of the run is unaffected."
        if opengl:
            msg += (" Off-screen rendering needs Mesa's EGL or OSMesa (Debian: apt-get install "
                    "libegl1 libgl1-mesa-dri; scripts/offscreen-gl), see pipeline/study/render3d.py.")
        if log.hasHandlers():
            log.warning(msg)
        else:
            print(f"warning: {msg}", file=sys.stderr, flush=True)
        res = {f: None for f in self.renders}
        res["error"] = msg
        return res


def _last_messages(err: str, n: int = 2) -> str:
    """The last distinct messages of a child's stderr, without VTK's log prefixes and colours."""
    out = []
    for line in err.splitlines():
        line = re.sub(r"\x1b\[[0-9;]*m", "", line).strip()
        if "WARN|" in line or "ERR|" in line:
            line = line.split("|", 1)[1].strip()
        if line and line not in out:
            out.append(line[:200])
    return " | ".join(out[-n:]) or "no message"


def _notice_png(path: Path, message: str):
    """A figure that says the render is unavailable (matplotlib, no OpenGL needed)."""
    try:
        fig, ax = plt.subplots(figsize=(9.0, 1.8))
        ax.axis("off")
        ax.text(0.0, 0.5, "\n".join(textwrap.wrap(message, 110)), va="center", ha="left", fontsize=9,
                color="#8a1c1c", transform=ax.transAxes)
        return save(fig, path)
    except Exception as exc:  # the notice is a courtesy; never fail the run over it
        log.warning("could not write the render notice %s: %s", path, exc)
        return None


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m pipeline.study.render3d",
                                 description="off-screen renders of the deformed blank")
    ap.add_argument("--probe", action="store_true", help="render a test cube; exit 0 when it works")
    ap.add_argument("--study", metavar="DIR", help="render figures into DIR (with --spec)")
    ap.add_argument("--spec", help="JSON file {png file: [heading, [case params], labels or null]}")
    a = ap.parse_args(argv)
    if a.probe:
        ok = probe()
        print("off-screen rendering works" if ok else "off-screen rendering gave a blank image")
        return 0 if ok else 1
    if a.study and a.spec:
        spec = json.loads(Path(a.spec).read_text())
        done = _render_child(Path(a.study), {f: tuple(v) for f, v in spec.items()})
        print(json.dumps(done), flush=True)
        return 0
    ap.print_help()
    return 2


if __name__ == "__main__":
    sys.exit(main())
