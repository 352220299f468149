"""Thermo-elastic FEA of the NiP-plated, lightweighted grating blank.

``MODEL_VERSION`` changes whenever a code change alters the sag computed for unchanged
inputs; result caches (sweeps, diagnosis) include it in their keys.
"""

MODEL_VERSION = 4
