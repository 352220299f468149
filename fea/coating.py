"""NiP plating layout: which surfaces carry how much film.

Units: micrometres for thicknesses, polish as a fraction of the as-plated thickness.

The blank is plated to ``t0_um`` everywhere; the two large faces are then polished
flat, leaving ``polish_front`` and ``polish_back`` of ``t0_um``. The coverage presets
are the paper's cases:

* ``all``      — every surface (Table 1): faces p·t0, side faces and holes t0.
* ``holes``    — only the lightweighting-hole walls at t0 (Table 2, left column).
* ``surfaces`` — only the outer surfaces at t0: both faces and the four side faces
  (Table 2, right column; "on blank surfaces").
* ``faces``    — only the two large faces at t0 (an alternative reading of
  "outer surfaces", kept for the investigation of Table 2).
* ``none``     — no film: the blank contracts uniformly and the sag is zero.

The 2-3 µm gold layer on the front face is neglected: its membrane force
(E·t·Δε ≈ 79 GPa · 3 µm · 0.17 %) is ~3 % of that of the thinnest front NiP layer in
the paper's range, and it is uniform over the face, so it adds a near-uniform
curvature and almost nothing to the quilting.
"""

from __future__ import annotations

from dataclasses import dataclass
from .errors import ParameterError

__all__ = ["Coating", "COVERAGES", "SURFACE_GROUPS"]

#: Surface groups of the blank mesh that can carry film (see fea.mesh).
SURFACE_GROUPS = ("front", "back", "side_x", "side_y", "holes_x", "holes_y")

COVERAGES = ("all", "holes", "surfaces", "faces", "none")


@dataclass(frozen=True)
class Coating:
    """NiP film thickness layout.

    Parameters
    ----------
    t0_um : float
        As-plated NiP thickness (µm), in (0, 2000].
    polish_front, polish_back : float
        Fraction of ``t0_um`` left on the front/back face after polishing, in (0, 1].
        Only used by coverage ``all``.
    coverage : str
        One of :data:`COVERAGES`.
    """

    t0_um: float = 200.0
    polish_front: float = 0.75
    polish_back: float = 0.75
    coverage: str = "all"

    def __post_init__(self) -> None:
        if self.coverage not in COVERAGES:
            raise ParameterError("coverage", self.coverage, f"coverage={self.coverage!r} is unknown; valid values are {list(COVERAGES)}")
        if not (0.0 < self.t0_um <= 2000.0):
            raise ParameterError("t0_um", self.t0_um, f"t0_um={self.t0_um} is outside the valid range (0, 2000] µm")
        for name in ("polish_front", "polish_back"):
            v = getattr(self, name)
            if not (0.0 < v <= 1.0):
                raise ParameterError(name, v, f"{name}={v} is outside the valid range (0, 1]")

    @classmethod
    def symmetric(cls, t0_um: float, polish: float, coverage: str = "all") -> "Coating":
        """Same polish on both faces (the paper's cases)."""
        return cls(t0_um=t0_um, polish_front=polish, polish_back=polish, coverage=coverage)

    @property
    def is_z_symmetric(self) -> bool:
        """True when front and back carry the same film (allows the eighth model)."""
        return self.coverage != "all" or self.polish_front == self.polish_back

    def thickness_um(self) -> dict[str, float]:
        """Film thickness (µm) on each surface group; groups without film are omitted."""
        t0 = self.t0_um
        if self.coverage == "all":
            return {
                "front": self.polish_front * t0,
                "back": self.polish_back * t0,
                "side_x": t0,
                "side_y": t0,
                "holes_x": t0,
                "holes_y": t0,
            }
        if self.coverage == "holes":
            return {"holes_x": t0, "holes_y": t0}
        if self.coverage == "surfaces":
            return {g: t0 for g in ("front", "back", "side_x", "side_y")}
        if self.coverage == "faces":
            return {"front": t0, "back": t0}
        return {}
