"""Functions over grids of cases: the cached, resumable sweep and the FEA cases run on it.

* :mod:`pipeline.sweeps.sweep` — :func:`~pipeline.sweeps.sweep.run_sweep`: any case
  function over a grid, each case cached in the keyed store, resumable, in processes
  or on Dask (:mod:`pipeline.sweeps.executors`; case files: :mod:`pipeline.sweeps.cache`);
* :mod:`pipeline.sweeps.fea_cases` — FEA cases (:class:`fea.case.FEACase`) as sweep
  cases, their displacement fields and the paper's tables;
* :mod:`pipeline.sweeps.surrogate` — large FEA sweeps through :mod:`fea.surrogate`.
"""
