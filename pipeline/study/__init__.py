"""The paper study: a config in, FEA cases, sag maps, line profiles, tables, figures and a report out.

* :mod:`pipeline.study.config` — study configs (TOML → frozen dataclasses), checked before
  any work; every key's type, unit and range in :mod:`pipeline.study.schema`; the shipped
  presets in ``pipeline/study/configs/``;
* :mod:`pipeline.study.run` — :func:`~pipeline.study.run.run_study`, end to end;
* :mod:`pipeline.study.dataset` — the fits, ``study.nc`` and the exports for design codes;
* :mod:`pipeline.study.plots`, :mod:`pipeline.study.render3d` — PNG figures and the
  off-screen 3-D render of the deformed blank.
"""
