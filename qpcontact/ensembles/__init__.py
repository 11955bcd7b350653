"""Ensembles of runs and of cases on Dask (the extra ``qpcontact[sweep]``).

- :mod:`.sweep`: ``qpcontact sweep``, replicates and parameter sweeps of colony runs as tasks
  (imported by the command only);
- :mod:`.cluster`: a Dask client on a local cluster or an existing one, and tasks that may
  start child processes (``qpcontact sweep``, and ``compare``/``stability`` with
  ``--scheduler``/``--workers``).

Nothing here is imported by ``import qpcontact``. The top of the house: only the studies sit
above it (docs/architecture.md).
"""
