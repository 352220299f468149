"""One claim of the paper as the scorecard reports it, and the grading helper.

A claim's status is decided by an acceptance rule written beside the code that
measures it (module constants of :mod:`pipeline.paper.fea_claims`,
:mod:`pipeline.paper.optics_claims` and :mod:`pipeline.paper.design_claims`); the
rules were fixed before the model numbers were looked at and are never tuned to them.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

__all__ = ["Claim", "STATUSES", "SOURCES", "grade"]

#: Allowed statuses, best first.
STATUSES = ("reproduced", "partial", "contradicted", "not testable")

#: What a model value was computed from: the FEA maps of named cases, or an analytic
#: quilt (clearly labelled side rows only).
SOURCES = ("fea", "analytic")


@dataclass(frozen=True)
class Claim:
    """A paper claim, the model's value and the verdict.

    Parameters
    ----------
    id : str
        Stable identifier (``table1``, ``j_double_peak``, ...).
    claim : str
        The claim in one sentence, as the paper makes it.
    section : str
        Where the paper makes it (section or table label).
    paper : str
        The paper's value or statement.
    model : str
        The model's value, with units.
    status : str
        One of :data:`STATUSES`.
    reason : str
        One line: the rule applied and why the status follows.
    source : str
        One of :data:`SOURCES`.
    """

    id: str
    claim: str
    section: str
    paper: str
    model: str
    status: str
    reason: str
    source: str

    def __post_init__(self) -> None:
        if self.status not in STATUSES:
            raise ValueError(f"Claim {self.id!r}: status={self.status!r} is not one of {STATUSES}")
        if self.source not in SOURCES:
            raise ValueError(f"Claim {self.id!r}: source={self.source!r} is not one of {SOURCES}")

    def as_dict(self) -> dict:
        return asdict(self)


def grade(value: float, reproduced: tuple[float, float], partial: tuple[float, float]) -> str:
    """``"reproduced"`` if ``value`` lies in the closed interval ``reproduced``,
    ``"partial"`` if in ``partial``, ``"contradicted"`` otherwise (NaN: contradicted)."""
    if reproduced[0] <= value <= reproduced[1]:
        return "reproduced"
    if partial[0] <= value <= partial[1]:
        return "partial"
    return "contradicted"
