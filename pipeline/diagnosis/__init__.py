"""Sim-to-real diagnosis: where the gap between measurements and the nominal
simulation lies, which unmodelled effect explains it, how far it shrinks, checked on
withheld data and by an injection-recovery campaign.

>>> from pipeline.diagnosis import diagnose
>>> d = diagnose("pipeline/scenarios/cryo_astigmatism/manifest.toml")   # doctest: +SKIP
>>> d.verdict, d.best.effect                                             # doctest: +SKIP
('explained', 'astigmatism')
"""

from .effects import LIBRARY, Effect, Parameter
from .engine import Criteria, Diagnosis, Finding, diagnose
from .manifest import Manifest, Measurement, Simulation, load_manifest

__all__ = ["diagnose", "Diagnosis", "Finding", "Criteria", "LIBRARY", "Effect", "Parameter",
           "Manifest", "Measurement", "Simulation", "load_manifest"]
