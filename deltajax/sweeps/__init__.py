"""Sweeps beyond one process: worker environment, merging sharded results, sweep summaries.

Scheduling is Hydra's (``-m`` multirun with the joblib or submitit launchers); this package only supplies

* :mod:`.worker`: :class:`WorkerEnv`, a Hydra callback that prepares each job's process before JAX creates
  its backend (threads, JAX host devices, GPU memory);
* :mod:`.merge`: :func:`merge_shards`, which combines the ``results.h5`` of the N shards of one job into a
  file whose datasets are identical to those of a single-process run, and :func:`merge_sweep`;
* :mod:`.reducers`: the registry of shard reducers, looked up by the name a sharded group stores;
* :mod:`.summary`: :class:`SweepSummary`, a Hydra callback that records each job's outcome and, when a
  multirun ends, merges sharded runs and writes ``summary.csv`` / ``summary.json`` (:func:`summarize_sweep`);
* :mod:`.layout`: the sweep directory's runs, overrides and status records;
* ``python -m deltajax.sweeps <sweep dir>`` (also ``python -m deltajax.merge``): merge and summarise afterwards.

Results files are read with :func:`deltajax.io.read`, the one HDF5 reader.
"""

from .layout import JOB_STATUS, find_runs
from .merge import SHARD_ATTRS, merge_shards, merge_sweep
from .reducers import LEGACY, REDUCERS, ShardError, get_reducer, register_reducer
from .summary import SMALL_VECTOR, SweepSummary, summarize_sweep
from .worker import WorkerEnv, apply_worker_env, resolve_worker_cpus

__all__ = ["WorkerEnv", "SweepSummary", "resolve_worker_cpus", "apply_worker_env", "merge_shards", "merge_sweep",
           "summarize_sweep", "find_runs", "ShardError", "SHARD_ATTRS", "SMALL_VECTOR", "JOB_STATUS", "REDUCERS",
           "LEGACY", "register_reducer", "get_reducer"]
