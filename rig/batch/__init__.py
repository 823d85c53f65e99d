"""Archive reprocessing: every capture under one or more archive directories through the same
pipeline as ``rig process``, as Dask tasks (an embedded local cluster, or an existing one).

- :mod:`rig.batch.discovery` finds the captures (and the incomplete ones, skipped with a reason);
- :mod:`rig.batch.resume` fingerprints a capture's inputs so that a rerun skips finished work, and
  clears what a killed run left;
- :mod:`rig.batch.tasks` is the task a Dask worker runs for one capture (paths in, a row out);
- :mod:`rig.batch.index` writes ``index.csv`` and ``compare.csv``;
- :mod:`rig.batch.runner` drives it all on a Dask cluster and reports progress events.
"""

from rig.batch.runner import BatchPlan, BatchResult, run_batch

__all__ = ["BatchPlan", "BatchResult", "run_batch"]
