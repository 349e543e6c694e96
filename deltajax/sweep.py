"""The names of :mod:`deltajax.sweeps` under their old module path (``deltajax.sweep.WorkerEnv`` in Hydra
configs written before the package, ``from deltajax.sweep import merge_shards`` in scripts)."""

from .sweeps import (JOB_STATUS, SHARD_ATTRS, SMALL_VECTOR, ShardError, SweepSummary, WorkerEnv, apply_worker_env,
                     find_runs, merge_shards, merge_sweep, resolve_worker_cpus, summarize_sweep)

__all__ = ["WorkerEnv", "SweepSummary", "resolve_worker_cpus", "apply_worker_env", "merge_shards", "merge_sweep",
           "summarize_sweep", "find_runs", "ShardError", "SHARD_ATTRS", "SMALL_VECTOR", "JOB_STATUS"]
