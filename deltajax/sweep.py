"""Sweeps beyond one process: worker environment, sharded results, merging and sweep summaries.

Scheduling is Hydra's (``-m`` multirun with the joblib or submitit launchers); this module only supplies

* :class:`WorkerEnv`, a Hydra callback that prepares each job's process *before* JAX creates its backend:
  one XLA thread pool per job sized to the job's CPUs (``PJRT_NPROC``), the job's CPUs exposed as that many
  JAX host devices (``jax_num_cpu_devices``) so that grid experiments can shard over them, and no GPU memory
  preallocation (``XLA_PYTHON_CLIENT_PREALLOCATE=false``) when several jobs share a GPU;
* :class:`SweepSummary`, a Hydra callback that, when a multirun ends, merges sharded runs and writes
  ``summary.csv`` / ``summary.json`` into the sweep directory (:func:`summarize_sweep`);
* :func:`merge_shards`, which combines the ``results.h5`` of the N shards of one job into a file whose
  datasets are identical to those of a single-process run.

Sharded results (the contract an experiment follows to be mergeable): a group carrying the attributes
``shard_axis`` (name of the dimension split between shards), ``shard``, ``n_shards``, ``shard_start``,
``shard_stop`` (the shard's half-open index range along that axis) and optionally ``shard_reduce``
(``"module:function"``). Datasets that have the shard axis among their dimensions are concatenated; the
reducer recomputes every other dataset and attribute that depends on the whole axis; anything else must be
identical in all shards.
"""

from __future__ import annotations

import csv
import importlib
import json
import logging
import math
import os
import re
from pathlib import Path
from typing import Any, Callable, Mapping, Optional, Sequence

import numpy as np

from .io import to_python

try:  # Hydra is a hard dependency of the CLI; keep this module importable without it for analysis
    from hydra.experimental.callback import Callback
except ImportError:  # pragma: no cover
    Callback = object  # type: ignore[misc,assignment]

__all__ = [
    "WorkerEnv",
    "SweepSummary",
    "resolve_worker_cpus",
    "apply_worker_env",
    "merge_shards",
    "merge_sweep",
    "summarize_sweep",
    "find_runs",
    "ShardError",
    "SHARD_ATTRS",
]

log = logging.getLogger(__name__)

#: group attributes that describe a shard (rewritten to the single-run values by :func:`merge_shards`)
SHARD_ATTRS = ("shard", "n_shards", "shard_start", "shard_stop")
#: 1-D datasets up to this length (per-chain figures) enter sweep summaries as ``group/name[max]``
SMALL_VECTOR = 8
_SCALE_ATTRS = ("CLASS", "NAME", "REFERENCE_LIST", "DIMENSION_LIST", "DIMENSION_LABELS", "_Netcdf4Dimid",
                "_Netcdf4Coordinates", "units")


class ShardError(ValueError):
    """Shards that cannot be merged (missing, overlapping, or from different jobs); the message says which."""


# ---------------------------------------------------------------------------------------------------------
# worker environment
# ---------------------------------------------------------------------------------------------------------
def _available_cpus() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        return os.cpu_count() or 1


def resolve_worker_cpus(launcher_cfg: Optional[Mapping[str, Any]], environ: Mapping[str, str] = os.environ,
                        available: Optional[int] = None) -> tuple[int, str]:
    """How many CPUs one job may use, and why.

    Order: ``SLURM_CPUS_PER_TASK`` (inside a SLURM allocation), the submitit launcher's ``cpus_per_task``,
    the joblib launcher's ``n_jobs`` (the machine's CPUs divided among the concurrent jobs), else all CPUs
    this process may run on (its affinity mask).

    Args:
        launcher_cfg: ``hydra.launcher`` of the job's config (or ``None`` in a single run).
        environ: the environment (for ``SLURM_CPUS_PER_TASK``).
        available: CPUs of this machine usable by the process (default: the affinity mask).

    Returns:
        (cpus >= 1, a short explanation).
    """
    avail = available if available is not None else _available_cpus()
    slurm = environ.get("SLURM_CPUS_PER_TASK")
    if slurm and slurm.isdigit() and int(slurm) > 0:
        return int(slurm), "SLURM_CPUS_PER_TASK"
    cfg = dict(launcher_cfg or {})
    target = str(cfg.get("_target_", ""))
    cpt = cfg.get("cpus_per_task")
    if "submitit" in target and cpt:
        return max(1, min(int(cpt), avail)), "hydra.launcher.cpus_per_task"
    if "joblib" in target:
        n_jobs = int(cfg.get("n_jobs") or -1)
        workers = n_jobs if n_jobs > 0 else max(1, avail + 1 + n_jobs)  # joblib: -1 = all, -2 = all but one
        return max(1, avail // workers), f"{avail} CPUs / hydra.launcher.n_jobs={workers}"
    return max(1, avail), "all CPUs of the process"


def apply_worker_env(cpus: int, host_devices: Optional[int] = None, gpu_preallocate: bool = False,
                     environ: Optional[dict] = None) -> dict[str, Any]:
    """Set the environment of this process for ``cpus`` CPUs, before JAX creates its backend.

    * ``PJRT_NPROC=cpus``: XLA's CPU client sizes its thread pool from it (default: all cores of the node,
      which oversubscribes a node shared by several jobs);
    * ``OMP/MKL/OPENBLAS/NUMBA_NUM_THREADS=cpus`` for libraries loaded later;
    * ``jax_num_cpu_devices=host_devices`` (only while no backend exists): the CPUs appear as that many JAX
      devices, over which grid experiments shard their chunks;
    * ``XLA_PYTHON_CLIENT_PREALLOCATE=false`` unless ``gpu_preallocate``: several jobs can share one GPU.

    Values already present in the environment win (an explicit user setting is kept). In a reused worker
    process (joblib) whose backend already exists nothing JAX-side can change; this is reported.

    Returns:
        What was applied (for the log and the results' attributes).
    """
    env = os.environ if environ is None else environ
    cpus = max(1, int(cpus))
    for var in ("PJRT_NPROC", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS", "NUMBA_NUM_THREADS"):
        env.setdefault(var, str(cpus))
    if not gpu_preallocate:
        env.setdefault("XLA_PYTHON_CLIENT_PREALLOCATE", "false")
    import sys

    if "numba" in sys.modules and environ is None:  # a reused worker: NUMBA_NUM_THREADS was read at its import
        import numba

        numba.set_num_threads(min(cpus, numba.config.NUMBA_NUM_THREADS))
    applied: dict[str, Any] = {"cpus": cpus, "PJRT_NPROC": env["PJRT_NPROC"],
                               "XLA_PYTHON_CLIENT_PREALLOCATE": env.get("XLA_PYTHON_CLIENT_PREALLOCATE", "")}
    if environ is None:  # this process: the Numba thread pool size in effect (numba reads NUMBA_NUM_THREADS once)
        import numba

        applied["numba_threads"] = int(numba.get_num_threads())
    import jax
    from jax._src import xla_bridge

    if xla_bridge.backends_are_initialized():
        applied["host_devices"] = f"unchanged (backend already initialised: {jax.local_device_count()})"
        return applied
    n_dev = cpus if host_devices is None else max(1, int(host_devices))
    if "xla_force_host_platform_device_count" in env.get("XLA_FLAGS", "") or "JAX_NUM_CPU_DEVICES" in env:
        applied["host_devices"] = "from XLA_FLAGS/JAX_NUM_CPU_DEVICES"
    else:
        jax.config.update("jax_num_cpu_devices", n_dev)
        applied["host_devices"] = n_dev
    return applied


class WorkerEnv(Callback):
    """Hydra callback: prepare each job's process (threads, host devices, GPU memory) before it runs.

    Registered in ``configs/config.yaml`` under ``hydra.callbacks.worker_env``; its arguments are overrides:
    ``hydra.callbacks.worker_env.cpus=8`` (default: see :func:`resolve_worker_cpus`),
    ``hydra.callbacks.worker_env.host_devices=1`` (default: one JAX host device per CPU),
    ``hydra.callbacks.worker_env.gpu_preallocate=true``.
    """

    def __init__(self, cpus: Optional[int] = None, host_devices: Optional[int] = None,
                 gpu_preallocate: bool = False) -> None:
        self.cpus = cpus
        self.host_devices = host_devices
        self.gpu_preallocate = bool(gpu_preallocate)

    def on_job_start(self, config, **kwargs: Any) -> None:
        from omegaconf import OmegaConf

        launcher = OmegaConf.to_container(config.hydra.launcher, resolve=False) if "launcher" in config.hydra else {}
        mode = str(config.hydra.get("mode", ""))
        if "MULTIRUN" not in mode:
            launcher = {}  # a single run executes in this process, whatever launcher is configured
        if self.cpus is not None:
            cpus, why = int(self.cpus), "hydra.callbacks.worker_env.cpus"
        else:
            cpus, why = resolve_worker_cpus(launcher)
        applied = apply_worker_env(cpus, self.host_devices, self.gpu_preallocate)
        os.environ["DELTAJAX_WORKER_ENV"] = json.dumps({**applied, "cpus_from": why})
        print(f"[deltajax] worker: {cpus} CPUs ({why}); XLA threads PJRT_NPROC={applied['PJRT_NPROC']}, "
              f"host devices {applied['host_devices']}", flush=True)


#: per-job status file (in the job's ``.hydra/`` folder) written by :class:`SweepSummary` in each sweep job
JOB_STATUS = "job_status.json"


def _job_status_path(config) -> Path:
    # <run>/.hydra even though hydra.output_subdir is null (deltajax.run writes .hydra/ itself once the run
    # directory is claimed): the status exists from the job's start, also for a job rejected before its claim
    sub = config.hydra.get("output_subdir", None) or ".hydra"
    return Path(str(config.hydra.runtime.output_dir)) / str(sub) / JOB_STATUS


def _write_json(path: Path, data: Mapping[str, Any]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(json.dumps(data, indent=1, default=str))
    os.replace(tmp, path)


def _scheduler_ids() -> dict[str, Any]:
    """The scheduler's identity of this job (SLURM job/array ids, submitit's log files), if any."""
    ids: dict[str, Any] = {k: os.environ[k] for k in ("SLURM_JOB_ID", "SLURM_ARRAY_JOB_ID", "SLURM_ARRAY_TASK_ID",
                                                      "SLURM_CPUS_PER_TASK", "SLURM_RESTART_COUNT")
                           if k in os.environ}
    if os.environ.get("SUBMITIT_EXECUTOR"):
        try:
            import submitit

            paths = submitit.JobEnvironment().paths
            ids.update(stdout=str(paths.stdout), stderr=str(paths.stderr))
            # logs are appended across requeues: what SLURM says about *this* run comes after this offset
            ids["stderr_offset"] = paths.stderr.stat().st_size if paths.stderr.exists() else 0
        except Exception as e:  # not inside a submitit job after all: say so in the status file
            ids["submitit_paths"] = f"unavailable: {e}"
    return ids


class SweepSummary(Callback):
    """Hydra callback: at the end of a multirun, merge sharded runs and write the sweep's summary files.

    In every sweep job it also records the job's outcome in ``<run>/.hydra/job_status.json``
    (``running`` with the scheduler's job id and log files when the job starts; ``ok`` or ``failed`` with the
    error when it ends), which :func:`summarize_sweep` reports. The summary is written when the multirun ends,
    and also when it ends with an error (a failed job makes Hydra raise before its end-of-sweep callbacks):
    then from an ``atexit`` hook of the submitting process.

    Arguments (overrides under ``hydra.callbacks.sweep_summary``): ``merge`` (default true).
    """

    def __init__(self, merge: bool = True) -> None:
        self.merge = bool(merge)
        self._pending: Optional[Path] = None

    @staticmethod
    def _in_multirun(config) -> bool:
        return "MULTIRUN" in str(config.hydra.get("mode", ""))

    def on_job_start(self, config, **kwargs: Any) -> None:
        if self._in_multirun(config):
            _write_json(_job_status_path(config), {"status": "running", "start_time": _now(),
                                                   "overrides": [str(o) for o in config.hydra.overrides.task],
                                                   **_scheduler_ids()})

    def on_job_end(self, config, job_return, **kwargs: Any) -> None:
        if not self._in_multirun(config):
            return
        path = _job_status_path(config)
        try:
            data = json.loads(path.read_text())
        except (OSError, ValueError):
            data = _scheduler_ids()
        data["end_time"] = _now()
        status = getattr(getattr(job_return, "status", None), "name", "")
        if status == "COMPLETED":
            data["status"] = "ok"
        else:
            err = getattr(job_return, "_return_value", None)
            first = str(err).strip().splitlines()[0] if str(err).strip() else ""
            data["status"] = "failed"
            data["error"] = f"{type(err).__name__}: {first}"[:500]
        _write_json(path, data)

    def on_multirun_start(self, config, **kwargs: Any) -> None:
        import atexit

        self._pending = Path(str(config.hydra.sweep.dir))
        atexit.register(self._after_failed_sweep)

    def on_multirun_end(self, config, **kwargs: Any) -> None:
        self._pending = None
        self._finish(Path(str(config.hydra.sweep.dir)))

    def _after_failed_sweep(self) -> None:
        if self._pending is not None:  # the sweep raised (a job failed, or the submitter was interrupted)
            sweep_dir, self._pending = self._pending, None
            print("[deltajax] the sweep did not finish cleanly: summarising what is there", flush=True)
            self._finish(sweep_dir)

    def _finish(self, sweep_dir: Path) -> None:
        if not sweep_dir.is_dir():
            return
        if self.merge:
            for out in merge_sweep(sweep_dir):
                print(f"[deltajax] merged shards -> {out}", flush=True)
        paths = summarize_sweep(sweep_dir)
        rows = json.loads(paths["json"].read_text())["runs"]
        bad = [f"{r['run']}: {r['status']}" for r in rows if r["status"] != "ok"]
        print(f"[deltajax] sweep summary -> {paths['csv']}"
              + (f" ({len(bad)} not ok: " + "; ".join(bad) + ")" if bad else ""), flush=True)


def _now() -> str:
    import datetime

    return datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")


# ---------------------------------------------------------------------------------------------------------
# reading results files with their dimensions
# ---------------------------------------------------------------------------------------------------------
class _Dataset:
    __slots__ = ("data", "units", "dims", "attrs", "is_axis")

    def __init__(self, data, units, dims, attrs, is_axis):
        self.data, self.units, self.dims, self.attrs, self.is_axis = data, units, dims, attrs, is_axis




def _read_tree(path: os.PathLike) -> tuple[dict, dict[str, dict], dict[str, dict[str, _Dataset]]]:
    """(root attrs, {group: attrs}, {group: {name: _Dataset}}) of a results file (groups by full path)."""
    import h5py

    root_attrs: dict = {}
    gattrs: dict[str, dict] = {}
    groups: dict[str, dict[str, _Dataset]] = {}
    with h5py.File(path, "r") as f:
        root_attrs = {k: to_python(v) for k, v in f.attrs.items()}

        def visit(name: str, obj) -> None:
            if isinstance(obj, h5py.Group):
                gattrs[name] = {k: to_python(v) for k, v in obj.attrs.items()}
                groups.setdefault(name, {})
                return
            gname, _, dname = name.rpartition("/")
            data = obj.asstr()[()] if h5py.check_string_dtype(obj.dtype) is not None else obj[()]
            is_axis = obj.attrs.get("CLASS", b"") in (b"DIMENSION_SCALE", "DIMENSION_SCALE")
            if is_axis:
                dims = (dname,)
            else:
                dims = []
                for i, dim in enumerate(obj.dims):
                    scales = list(dim.keys())
                    if not scales:
                        raise ShardError(f"{path}: {name} has no dimension scale on axis {i}")
                    dims.append(scales[0])
                dims = tuple(dims)
            attrs = {k: to_python(v) for k, v in obj.attrs.items() if k not in _SCALE_ATTRS}
            groups.setdefault(gname, {})[dname] = _Dataset(data, to_python(obj.attrs.get("units", "")), dims, attrs,
                                                           is_axis)

        f.visititems(visit)
    return root_attrs, gattrs, groups


def _same(a: Any, b: Any) -> bool:
    a, b = np.asarray(a), np.asarray(b)
    if a.shape != b.shape or a.dtype != b.dtype:
        return False
    if a.dtype.kind in "fc":
        return bool(np.array_equal(a, b, equal_nan=True))
    return bool(np.array_equal(a, b))


def _resolve_function(spec: str) -> Callable:
    module, _, name = spec.partition(":")
    if not module or not name:
        raise ShardError(f"shard_reduce must be 'module:function', got {spec!r}")
    return getattr(importlib.import_module(module), name)


def _config_without_shard(config_yaml: str) -> tuple[str, Any]:
    """(config YAML of the equivalent single run, shard index) from a run's ``config`` attribute."""
    from omegaconf import OmegaConf

    cfg = OmegaConf.create(config_yaml or "{}")
    shard = cfg.get("shard", None)
    if "shard" in cfg:
        cfg.shard = 0
    if "n_shards" in cfg:
        cfg.n_shards = 1
    return OmegaConf.to_yaml(cfg), shard


# ---------------------------------------------------------------------------------------------------------
# merging shards
# ---------------------------------------------------------------------------------------------------------
def merge_shards(paths: Sequence[os.PathLike], out: Optional[os.PathLike] = None) -> Path:
    """Merge the ``results.h5`` files of the shards of one job into one file.

    The merged datasets, units, dimensions and group attributes are identical to those a single process
    (``n_shards=1``) writes: gridded datasets are concatenated along the shard axis in index order and
    everything derived from the whole axis is recomputed by the group's ``shard_reduce`` function from the
    merged arrays. Root attributes are the first shard's, with ``config`` rewritten to the single-run config
    (``shard=0``, ``n_shards=1``), ``start_time``/``end_time`` spanning all shards, ``wall_time_s`` summed,
    ``merged_from`` listing the inputs (one per line), and root attributes that differ between shards (e.g.
    throughput) stored as one value per shard.

    Args:
        paths: the shards' results files, in any order; all ``n_shards`` of them.
        out: output path (default: ``merged_results.h5`` beside the first input).

    Returns:
        The written path.

    Raises:
        ShardError: shards missing, duplicated, overlapping, from different configurations, or a dataset
            that is not along the shard axis differs between shards and no reducer recomputes it.
    """
    from .io import ResultsFile

    paths = [Path(p) for p in paths]
    if not paths:
        raise ShardError("merge_shards: no input files")
    trees = [_read_tree(p) for p in paths]
    # -- same job? --------------------------------------------------------------------------------------
    single_cfgs = [_config_without_shard(str(t[0].get("config", ""))) for t in trees]
    for (cfg, _), p in zip(single_cfgs[1:], paths[1:]):
        if cfg != single_cfgs[0][0]:
            raise ShardError(f"{p} is not a shard of the same job as {paths[0]} (configs differ beyond 'shard')")
    sharded = {g: a for g, a in trees[0][1].items() if "shard_axis" in a}
    if not sharded:
        raise ShardError(f"{paths[0]}: no group has a 'shard_axis' attribute: not a sharded result")
    # -- order and coverage -----------------------------------------------------------------------------
    gname0 = next(iter(sharded))
    infos = []
    for t, p in zip(trees, paths):
        a = t[1].get(gname0)
        if a is None:
            raise ShardError(f"{p}: group {gname0!r} missing")
        infos.append((int(a["shard_start"]), int(a["shard_stop"]), int(a["shard"]), int(a["n_shards"]), p))
    n_shards = infos[0][3]
    if any(i[3] != n_shards for i in infos):
        raise ShardError(f"shards disagree on n_shards: {[i[3] for i in infos]}")
    shards = sorted(i[2] for i in infos)
    if shards != list(range(n_shards)):
        missing = sorted(set(range(n_shards)) - set(shards))
        dup = sorted({s for s in shards if shards.count(s) > 1})
        raise ShardError(f"need shards 0..{n_shards - 1} exactly once: missing {missing}, duplicated {dup}")
    order = sorted(range(len(paths)), key=lambda i: infos[i][0])
    trees = [trees[i] for i in order]
    paths = [paths[i] for i in order]
    # -- merge group by group ---------------------------------------------------------------------------
    root0 = trees[0][0]
    res = ResultsFile(out if out is not None else paths[0].with_name("merged_results.h5"))
    res.attrs = {}
    all_groups = list(trees[0][2].keys() | trees[0][1].keys())
    for g in sorted(all_groups):
        if g == "":
            continue
        per_shard = [t[2].get(g, {}) for t in trees]
        attrs = [t[1].get(g, {}) for t in trees]
        if g in sharded:
            datasets, gattrs = _merge_group(g, per_shard, attrs, paths)
        else:
            datasets, gattrs = _check_identical_group(g, per_shard, attrs, paths)
        _stage(res, g, datasets)
        if gattrs:
            res.set_attrs(g, **gattrs)
    # -- root attributes --------------------------------------------------------------------------------
    root = dict(root0)
    root["config"] = single_cfgs[0][0] if "config" in root0 else ""
    starts = [str(t[0].get("start_time", "")) for t in trees if t[0].get("start_time")]
    ends = [str(t[0].get("end_time", "")) for t in trees if t[0].get("end_time")]
    if starts:
        root["start_time"] = min(starts)
    if ends:
        root["end_time"] = max(ends)
    walls = [t[0].get("wall_time_s") for t in trees]
    if all(isinstance(w, (int, float)) for w in walls):
        root["wall_time_s"] = float(sum(walls))
    for key in root0:  # per-shard figures (throughput, worker settings): one value per shard, in order
        if key in ("config", "start_time", "end_time", "wall_time_s"):
            continue
        values = [t[0].get(key) for t in trees]
        if not all(_same(v, values[0]) for v in values[1:]):
            if all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values):
                root[key] = np.asarray(values)
            else:
                root[key] = "\n".join(str(v) for v in values)
    root["merged_from"] = "\n".join(str(p.resolve()) for p in paths)  # one path per line
    root["merged_n_shards"] = n_shards
    res.attrs.update(root)
    return res.flush()


def _merge_group(g, per_shard, attrs, paths):
    a0 = attrs[0]
    axis = str(a0["shard_axis"])
    size = None
    merged: dict[str, _Dataset] = {}
    names = set(per_shard[0])
    for p, d in zip(paths[1:], per_shard[1:]):
        if set(d) != names:
            raise ShardError(f"{p}: group {g!r} has datasets {sorted(d)}, first shard has {sorted(names)}")
    expected = 0
    for a, p in zip(attrs, paths):
        if int(a["shard_start"]) != expected:
            raise ShardError(f"{p}: shard covers {axis}[{a['shard_start']}:{a['shard_stop']}], expected to start "
                             f"at {expected} (shards overlap or one is missing)")
        expected = int(a["shard_stop"])
    size = expected
    for name in sorted(names):
        d0 = per_shard[0][name]
        if axis in d0.dims:
            k = d0.dims.index(axis)
            data = np.concatenate([d[name].data for d in per_shard], axis=k)
            if data.shape[k] != size:
                raise ShardError(f"group {g!r}: {name} has {data.shape[k]} entries along {axis!r}, expected {size}")
            merged[name] = _Dataset(data, d0.units, d0.dims, d0.attrs, d0.is_axis)
        else:
            merged[name] = d0
    gattrs = dict(a0)
    gattrs.update(shard=0, n_shards=1, shard_start=0, shard_stop=size)
    recomputed: set[str] = set()
    recomputed_attrs: set[str] = set()
    if a0.get("shard_reduce"):
        reducer = _resolve_function(str(a0["shard_reduce"]))
        new_data, new_attrs = reducer({k: v.data for k, v in merged.items()}, [dict(a) for a in attrs])
        for k, v in new_data.items():
            if k not in merged:
                raise ShardError(f"shard_reduce of {g!r} returned {k!r}, which the shards do not have")
            old = merged[k]
            merged[k] = _Dataset(np.asarray(v), old.units, old.dims, old.attrs, old.is_axis)
            recomputed.add(k)
        gattrs.update(new_attrs)
        recomputed_attrs = set(new_attrs)
    for name in sorted(names):
        d0 = per_shard[0][name]
        if axis in d0.dims or name in recomputed:
            continue
        for d, p in zip(per_shard[1:], paths[1:]):
            if not _same(d[name].data, d0.data):
                raise ShardError(f"group {g!r}: {name} differs between shards ({p}) and is not along "
                                 f"{axis!r} nor recomputed by shard_reduce")
    skip = set(SHARD_ATTRS) | recomputed_attrs
    for key in a0:
        if key in skip:
            continue
        for a, p in zip(attrs[1:], paths[1:]):
            if not _same(a.get(key), a0[key]):
                raise ShardError(f"group {g!r}: attribute {key!r} differs between shards ({p})")
    return merged, gattrs


def _check_identical_group(g, per_shard, attrs, paths):
    d0, a0 = per_shard[0], attrs[0]
    for d, a, p in zip(per_shard[1:], attrs[1:], paths[1:]):
        if set(d) != set(d0) or any(not _same(d[k].data, d0[k].data) for k in d0):
            raise ShardError(f"group {g!r} (not sharded) differs between shards ({p})")
        if set(a) != set(a0) or any(not _same(a[k], a0[k]) for k in a0):
            raise ShardError(f"group {g!r} (not sharded): attributes differ between shards ({p})")
    return d0, a0


def _stage(res, g: str, datasets: Mapping[str, _Dataset]) -> None:
    for name, d in datasets.items():
        if d.is_axis:
            res.put_axis(g, name, d.data, units=d.units, attrs=d.attrs)
    for name, d in datasets.items():
        if not d.is_axis:
            res.put(g, name, d.data, units=d.units, dims=d.dims, attrs=d.attrs)


# ---------------------------------------------------------------------------------------------------------
# sweep directories
# ---------------------------------------------------------------------------------------------------------
def _run_sort_key(p: Path):
    return (0, int(p.name), "") if p.name.isdigit() else (1, 0, p.name)


def find_runs(sweep_dir: os.PathLike) -> list[Path]:
    """The run directories of a Hydra sweep (``<sweep>/<job num>/``), in job order (merged runs excluded)."""
    sweep_dir = Path(sweep_dir)
    runs = [p for p in sweep_dir.iterdir()
            if p.is_dir() and p.name != "merged" and not p.name.startswith(".")
            and ((p / ".hydra").is_dir() or (p / "results.h5").exists())]
    return sorted(runs, key=_run_sort_key)


def _overrides(run_dir: Path) -> list[str]:
    """The job's overrides: .hydra/overrides.yaml (written once the run directory is claimed), else the job's
    status record (written at job start, so a job rejected before its claim still names its overrides)."""
    f = run_dir / ".hydra" / "overrides.yaml"
    if not f.exists():
        return [str(o) for o in _job_status(run_dir).get("overrides", [])]
    from omegaconf import OmegaConf

    return [str(o) for o in OmegaConf.load(f)]


def _override_dict(overrides: Sequence[str]) -> dict[str, str]:
    out = {}
    for o in overrides:
        key, sep, val = o.partition("=")
        if sep:
            out[key.lstrip("+~")] = val
    return out


def _label(overrides: Mapping[str, str]) -> str:
    text = ",".join(f"{k}={v}" for k, v in overrides.items()) or "all"
    return re.sub(r"[^A-Za-z0-9._=,+-]", "_", text)[:200]


def merge_sweep(sweep_dir: os.PathLike) -> list[Path]:
    """Merge every sharded job of a sweep: runs with ``n_shards > 1`` whose configs differ only in ``shard``.

    Writes ``<sweep>/merged/<label>/results.h5`` for each complete set of shards, ``<label>`` being the
    overrides that vary across the sweep (without ``shard``), or the experiment name; sets with missing or
    inconsistent shards are skipped with a message. Returns the written paths.
    """
    import h5py

    sweep_dir = Path(sweep_dir)
    groups: dict[str, list[tuple[Path, dict]]] = {}
    all_overrides = []
    for run in find_runs(sweep_dir):
        ov = _override_dict(_overrides(run))
        all_overrides.append(ov)
        f = run / "results.h5"
        if not f.exists():
            continue
        with h5py.File(f, "r") as h:
            cfg_yaml = to_python(h.attrs.get("config", ""))
            name = str(to_python(h.attrs.get("experiment", "run")))
            is_sharded = any("shard_axis" in h[k].attrs and int(h[k].attrs.get("n_shards", 1)) > 1
                             for k in h if isinstance(h[k], h5py.Group))
        if not is_sharded:
            continue
        single, _ = _config_without_shard(str(cfg_yaml))
        groups.setdefault(single, []).append((f, {**ov, "__name__": name}))
    keys = sorted({k for ov in all_overrides for k in ov})
    varying = [k for k in keys if k != "shard" and len({ov.get(k) for ov in all_overrides}) > 1]
    written = []
    for members in groups.values():
        files = [m[0] for m in members]
        ov = members[0][1]
        label = _label({k: ov[k] for k in varying if k in ov}) if varying else _label({}).replace("all", ov["__name__"])
        out = sweep_dir / "merged" / label / "results.h5"
        try:
            written.append(merge_shards(files, out))
        except ShardError as e:
            log.warning("not merged (%s): %s", ", ".join(map(str, files)), e)
            print(f"[deltajax] not merged: {e}", flush=True)
    return written


def _scalars(path: Path) -> tuple[dict[str, float], dict[str, str], dict[str, Any]]:
    """Every 0-d numeric dataset of a results file as ``group/name`` -> value, its units, and root attrs."""
    import h5py

    vals: dict[str, float] = {}
    units: dict[str, str] = {}
    with h5py.File(path, "r") as f:
        root = {k: to_python(v) for k, v in f.attrs.items() if k != "config"}

        def visit(name, obj):
            if not isinstance(obj, h5py.Dataset) or obj.dtype.kind not in "biuf":
                return
            if obj.shape == ():
                vals[name] = to_python(obj[()])
                units[name] = str(to_python(obj.attrs.get("units", "")))
            elif len(obj.shape) == 1 and 1 <= obj.shape[0] <= SMALL_VECTOR and not obj.attrs.get("CLASS"):
                # a per-chain figure (peak torque of each actuator ...): its largest entry
                v = np.asarray(obj[()], dtype=float)
                vals[f"{name}[max]"] = float(np.nanmax(v)) if np.isfinite(v).any() else float("nan")
                units[f"{name}[max]"] = str(to_python(obj.attrs.get("units", "")))

        f.visititems(visit)
    return vals, units, root


def _job_status(run_dir: Path) -> dict[str, Any]:
    for f in (run_dir / ".hydra" / JOB_STATUS, run_dir / JOB_STATUS):
        try:
            return dict(json.loads(f.read_text()))
        except FileNotFoundError:
            continue
        except (OSError, ValueError) as e:
            return {"status": "unknown", "error": f"unreadable {f}: {e}"}
    return {}


#: what SLURM writes into a job's error stream when it ends the job (cancel, time limit, memory limit)
_KILL_LINE = re.compile(r"(slurmstepd\S*: error: .*)|(.*\bCANCELLED AT .*)|(.*DUE TO (TIME LIMIT|PREEMPTION).*)")


def _killed_by_scheduler(job: Mapping[str, Any]) -> str:
    """The scheduler's last word on a job that started and never ended (from its error log), or ``""``."""
    try:
        with open(str(job["stderr"]), "rb") as fh:
            fh.seek(int(job.get("stderr_offset", 0)))
            text = fh.read().decode(errors="replace")
    except (KeyError, OSError, ValueError):
        return ""
    hits = [m.group(0).strip() for m in _KILL_LINE.finditer(text)]
    memory = [h for h in hits if "exceeded memory limit" in h]  # the line with the figures
    ended = [h for h in hits if "CANCELLED AT" in h or "DUE TO" in h]
    best = memory[0] if memory else ended[-1] if ended else hits[-1] if hits else ""
    return best[:300]


def summarize_sweep(sweep_dir: os.PathLike) -> dict[str, Path]:
    """Write ``summary.json`` and ``summary.csv`` indexing a sweep's runs and their key figures.

    One row per run directory (job order) and per merged sharded job (``kind = merged``): the run's overrides
    (one column per swept key), its status (``ok``: results.h5 complete; ``failed: <error>``: the job raised;
    ``killed: <the scheduler's message>``: SLURM ended it (cancel, time or memory limit); ``incomplete``:
    checkpoint only; ``running``: started, no end recorded; ``missing``: never started; the job's own record,
    ``.hydra/job_status.json``, is in summary.json as ``job``), experiment, wall time, and every scalar
    dataset of its results.h5 as ``group/name``
    (units in ``summary.json`` and in the CSV header as ``group/name [units]``); numeric 1-D datasets of at
    most :data:`SMALL_VECTOR` entries that are not axes (per-chain figures such as peak torques) enter as
    ``group/name[max]``, their largest entry.

    Returns:
        ``{"json": path, "csv": path}``.
    """
    sweep_dir = Path(sweep_dir)
    entries: list[tuple[str, Path, dict[str, str]]] = [
        ("run", r, _override_dict(_overrides(r))) for r in find_runs(sweep_dir)]
    merged_root = sweep_dir / "merged"
    if merged_root.is_dir():
        for m in sorted(merged_root.iterdir()):
            if (m / "results.h5").exists():
                entries.append(("merged", m, {}))
    rows, all_units = [], {}
    for kind, run, ov in entries:
        f = run / "results.h5"
        row: dict[str, Any] = {"run": str(run.relative_to(sweep_dir)), "kind": kind, "overrides": ov,
                               "status": "missing", "metrics": {}}
        job = _job_status(run) if kind == "run" else {}
        if job:
            row["job"] = job
        if f.exists():
            try:
                vals, units, root = _scalars(f)
            except OSError as e:  # a file being replaced right now
                row["status"] = f"unreadable: {e}"
            else:
                row["status"] = "ok" if root.get("end_time") else "incomplete"
                row["experiment"] = root.get("experiment", "")
                row["wall_time_s"] = root.get("wall_time_s")
                if kind == "merged":
                    sources = [Path(q) for q in str(root.get("merged_from", "")).splitlines() if q]
                    row["merged_from"] = [q.parent.name for q in sources]
                    row["overrides"] = _override_dict(_overrides(sources[0].parent)) if sources else {}
                    row["overrides"].pop("shard", None)
                row["metrics"] = vals
                all_units.update(units)
        if job.get("status") == "failed":
            row["status"] = f"failed: {job.get('error', '')}"
        elif job.get("status") == "running" and row["status"] != "ok":
            killed = _killed_by_scheduler(job)
            if killed:
                row["status"] = f"killed: {killed}"
            elif row["status"] == "missing":
                row["status"] = "running"  # started, no end recorded: still running, or killed without a trace
        rows.append(row)
    summary = {"sweep_dir": str(sweep_dir.resolve()), "n_runs": sum(r["kind"] == "run" for r in rows),
               "units": all_units, "runs": rows}
    jpath = sweep_dir / "summary.json"
    tmp = jpath.with_name(jpath.name + ".tmp")
    tmp.write_text(json.dumps(summary, indent=1, default=_json_default))
    os.replace(tmp, jpath)
    keys = sorted({k for r in rows for k in r["overrides"]})
    metrics = sorted({k for r in rows for k in r["metrics"]})
    cpath = sweep_dir / "summary.csv"
    tmp = cpath.with_name(cpath.name + ".tmp")
    with open(tmp, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["run", "kind", "status", "experiment_name", "wall_time_s", *keys,
                    *(f"{m} [{all_units.get(m, '')}]" for m in metrics)])
        for r in rows:
            w.writerow([r["run"], r["kind"], r["status"], r.get("experiment", ""), _fmt(r.get("wall_time_s")),
                        *(r["overrides"].get(k, "") for k in keys),
                        *(_fmt(r["metrics"].get(m)) for m in metrics)])
    os.replace(tmp, cpath)
    return {"json": jpath, "csv": cpath}


def _fmt(v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, float):
        return repr(v) if math.isfinite(v) else str(v)
    return str(v)


def _json_default(v: Any) -> Any:
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, np.ndarray):
        return v.tolist()
    return str(v)
