"""The paper (George et al., SPIFFI gratings) claim by claim on the model: ``scorecard(out_dir)``.

Modules: :mod:`~pipeline.paper.claim` (the Claim record and grading),
:mod:`~pipeline.paper.fea_claims` (Tables 1-2, edge P/V, directions),
:mod:`~pipeline.paper.optics_claims` (satellites, line profiles, pupil shift, collimator),
:mod:`~pipeline.paper.design_claims` (AlSi40/solid blank, doubled period),
:mod:`~pipeline.paper.scorecard` (assembly and writing).
"""

from pipeline.paper.claim import STATUSES, Claim
from pipeline.paper.scorecard import format_scorecard, scorecard

__all__ = ["Claim", "STATUSES", "scorecard", "format_scorecard"]
