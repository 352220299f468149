"""Verification of the FEA model against references it does not share code with.

* :mod:`fea.verification.analytic` — closed-form bilayer plate curvature (Timoshenko, Stoney);
* :mod:`fea.verification.cell` — the mesh of a slice through one lightweighting cell;
* :mod:`fea.verification.layer` — the thin-film model against an explicitly meshed NiP layer
  on that slice.

Used by tests and benchmarks only; production code (``fea``, ``optics``, ``pipeline``) never
imports this package.
"""
