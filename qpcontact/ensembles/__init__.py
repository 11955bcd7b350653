"""Ensembles of runs and of cases on Dask (the extra ``qpcontact[sweep]``).

- :mod:`.sweep`: the command ``qpcontact sweep`` (replicates and parameter sweeps of colony
  runs) and the sweep's folder (:class:`~.sweep.Sweep`: ``sweep.json``, the summary, the
  ensemble picture);
- :mod:`.grid`: the grid of a sweep, seeds × the settings that vary, each run's settings;
- :mod:`.tasks`: one run as a Dask task in its own folder, idempotent, locked, stoppable;
- :mod:`.submit`: the runs submitted to Dask, recorded as they finish, stopped cleanly;
- :mod:`.cluster`: a Dask client on a local cluster or an existing one, and tasks that may
  start child processes (``qpcontact sweep``, and ``compare``/``stability`` with
  ``--scheduler``/``--workers``).

Nothing here is imported by ``import qpcontact``. The top of the house: only the studies sit
above it (docs/architecture.md).
"""
