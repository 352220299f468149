"""Caps on the work one command may start, and its run time estimated before it starts.

Every size a user can make blow up by a typo (a range with a tiny step, a list pasted
twice, a campaign of a million cases) is checked against a stated cap *before* any case
runs; a refusal is a ``ValueError`` naming the parameter, the value and the valid range.
The caps are far above any study the toolkit is meant for (the paper's is 15 FEA cases and
72 line profiles) and far below what would run for weeks or exhaust memory.

The run-time estimate multiplies the number of cases by per-case seconds measured on the
reference machine (2 cores; ``benchmarks/results_*.md``). It is an order of magnitude, not
a promise: it exists so that a run of days says so in its first line instead of after a
day. :func:`warn_if_long` prints that one line (stderr) when the estimate exceeds an hour.
"""

from __future__ import annotations

import math
import os
import sys

__all__ = [
    "MAX_CAMPAIGN_CASES",
    "MAX_FEA_CASES",
    "MAX_MEASUREMENTS",
    "MAX_PROFILE_JOBS",
    "MAX_SURROGATE_CASES",
    "LONG_RUN_S",
    "SECONDS",
    "campaign_seconds",
    "check_count",
    "fea_case_seconds",
    "GEOMETRY_KEYS",
    "max_workers",
    "format_duration",
    "product_count",
    "warn_if_long",
]

#: FEA cases in one study or sweep: at ~3.5 s each (default mesh) 10 000 cases are ~10 h.
MAX_FEA_CASES = 10_000
#: Line profiles in one study (~0.05 s each; a profile table is also a row of ``profiles.nc``).
MAX_PROFILE_JOBS = 100_000
#: Cases of a surrogate sweep (milliseconds each, but every case is a row and a map in sweep.nc).
MAX_SURROGATE_CASES = 100_000
#: Cases of an injection-recovery campaign (``diagnose --validate --cases``): 8-24 s each.
MAX_CAMPAIGN_CASES = 10_000
#: Measurements in one diagnosis manifest (each a file read and fitted; the paper's data: 4 maps
#: and a few dozen line profiles).
MAX_MEASUREMENTS = 1_000
#: A run estimated longer than this (s) says so before it starts.
LONG_RUN_S = 3600.0

#: Per-case seconds on the reference machine (2 cores), from the benchmark pages:
#: ``fea_case`` the 15-case paper table solved one case at a time at the default mesh
#: (1.4/2.8 mm), 50 s / 15 (results_tables.md); ``line_profile`` one detected profile at
#: 250 mas, the slowest pixel scale (results_lsf.md); ``campaign_*`` one campaign case on
#: one core, 2 workers x wall / cases (results_diagnosis.md: profiles 824 s / 208,
#: profiles + map 1360 s / 208, profiles + map + image 2466 s / 208); ``study_overhead``
#: what a study adds to its cases (preparing the blank, fits, exports, figures, 3-D renders,
#: report): the default study's 120 s minus 15 x 3.5 s and 72 x 0.05 s (results_run.md);
#: ``new_blank`` meshing a blank geometry or element size not in the mesh cache ("the first
#: run on a machine adds ~1 min of meshing", results_run.md).
SECONDS = {
    "study_overhead": 64.0,
    "new_blank": 60.0,
    "fea_case": 3.5,
    "line_profile": 0.05,
    "surrogate_case": 0.002,
    "campaign_profiles": 7.9,
    "campaign_profiles_map": 13.1,
    "campaign_profiles_map_image": 23.7,
}
#: FEA parameters that change the mesh: each distinct combination is meshed once.
GEOMETRY_KEYS = ("size_x_mm", "size_y_mm", "thickness_mm", "hole_diameter_mm", "pitch_x_mm", "n_holes_x",
                 "pitch_y_mm", "n_holes_y", "hole_axis_z_mm", "mesh_size_mm", "mesh_bulk_mm")
#: The element size (mm) at which ``SECONDS["fea_case"]`` was measured.
_REFERENCE_MESH_MM = 1.4


def max_workers() -> int:
    """Most local worker processes a command may start: twice this machine's cores (at least
    4). Each FEA or campaign worker holds 1-4 GB, so 64 workers on a laptop is a typo that
    ends in the out-of-memory killer, not a speed-up."""
    return max(4, 2 * (os.cpu_count() or 1))


def check_count(n: int, name: str, cap: int, hint: str = "") -> int:
    """Return ``n`` if ``1 <= n <= cap``; else a ``ValueError`` naming ``name``, ``n`` and the range."""
    if not 1 <= n <= cap:
        raise ValueError(f"{name}={n} is outside the valid range 1..{cap}" + (f"; {hint}" if hint else ""))
    return n


def product_count(lengths) -> int:
    """The number of combinations of axes of these lengths (the product; 1 for none)."""
    return math.prod(int(n) for n in lengths)


def fea_case_seconds(mesh_size_mm: float | None = None) -> float:
    """Seconds of one FEA case: the tabulated default-mesh time scaled by the element count,
    which grows as ``(1.4 mm / mesh_size_mm)**3``; at least 0.5 s (meshing, I/O)."""
    size = _REFERENCE_MESH_MM if mesh_size_mm is None else float(mesh_size_mm)
    return max(0.5, SECONDS["fea_case"] * (_REFERENCE_MESH_MM / size) ** 3)


def campaign_seconds(n_cases: int, workers: int, with_map: bool, with_image: bool) -> float:
    """Wall seconds of ``n_cases`` campaign cases on ``workers`` processes (at most 2 cores' worth)."""
    key = ("campaign_profiles_map_image" if with_image else
           "campaign_profiles_map" if with_map else "campaign_profiles")
    return n_cases * SECONDS[key] / max(1, min(int(workers), 2))


def format_duration(seconds: float) -> str:
    """``"40 s"``, ``"45 min"``, ``"3.2 h"`` or ``"2.1 days"``."""
    if seconds >= 2 * 86400:
        return f"{seconds / 86400:.1f} days"
    if seconds >= 3600:
        return f"{seconds / 3600:.1f} h"
    return f"{seconds / 60:.0f} min" if seconds >= 90 else f"{seconds:.0f} s"


def warn_if_long(seconds: float, command: str, detail: str, stream=None) -> bool:
    """Print one line to ``stream`` (stderr) if ``seconds`` exceeds :data:`LONG_RUN_S`.

    ``detail`` says what the estimate is made of (e.g. ``"3000 FEA cases x ~3.5 s"``).
    Returns whether it printed.
    """
    if seconds <= LONG_RUN_S:
        return False
    print(f"cryograting {command}: warning: estimated run time {format_duration(seconds)} ({detail}, "
          "per-case times of the 2-core reference machine; cached cases and meshes take none); interrupt now if "
          "that was not intended",
          file=stream or sys.stderr)
    return True
