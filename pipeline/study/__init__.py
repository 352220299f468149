"""The paper study: a config in, FEA cases, sag maps, line profiles, tables, figures and a report out.

* :mod:`pipeline.study.config` — study configs read from TOML (and ``--set`` overrides)
  into frozen dataclasses checked before any work: :mod:`~pipeline.study.cases` (FEA case
  groups, selectors), :mod:`~pipeline.study.profile_specs` (line profiles),
  :mod:`~pipeline.study.figure_specs` (figures, output switches) and
  :mod:`~pipeline.study.study_config` (the whole study, cross-checked); every key's type,
  unit and range in :mod:`pipeline.study.schema`; the shipped presets in
  ``pipeline/study/configs/``;
* :mod:`pipeline.study.run` — :func:`~pipeline.study.run.run_study`, end to end;
* :mod:`pipeline.study.dataset` — the fits, ``study.nc`` and the exports for design codes;
* :mod:`pipeline.study.plots`, :mod:`pipeline.study.render3d` — PNG figures and the
  off-screen 3-D render of the deformed blank.
"""
