"""Worker environment of sweep jobs: CPUs, XLA threads, JAX host devices and GPU memory, set before JAX starts.

:class:`WorkerEnv` is a Hydra callback (``configs/config.yaml``, ``hydra.callbacks.worker_env``) that sizes
each job's process from its scheduler's allocation (:func:`resolve_worker_cpus`) and applies it
(:func:`apply_worker_env`): one XLA thread pool per job sized to the job's CPUs (``PJRT_NPROC``), one JAX host
device unless more are asked for (``jax_num_cpu_devices``, over which ``workspace_grid``'s JAX backend can shard),
no GPU memory preallocation (``XLA_PYTHON_CLIENT_PREALLOCATE=false``) when several jobs share a GPU, and the
CPU's full vector width for XLA:CPU and Numba where it has AVX-512 (:func:`wide_vectors`).

One host device by default, whatever the CPUs: XLA's persistent compilation cache keys every executable by the
number of devices, so a process with another count (a SLURM task with other ``cpus_per_task``, a joblib worker,
an in-process run of the library) would compile every program of the job again; the XLA thread pool already uses
all the job's CPUs, and sharding a grid chunk over host devices measured no faster (docs/BENCHMARKS.md).
"""

from __future__ import annotations

import json
import os
from typing import Any, Mapping, Optional
import sys

import jax
from jax._src import xla_bridge

from ..tracing import cpu_flags
from .layout import Callback

__all__ = ["WorkerEnv", "resolve_worker_cpus", "apply_worker_env", "keep_freed_memory", "MALLOC_REUSE",
           "wide_vectors", "host_has_avx512", "WIDE_VECTOR_BITS"]


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


def apply_worker_env(cpus: int, host_devices: Optional[int] = 1, gpu_preallocate: bool = False,
                     environ: Optional[dict] = None, malloc_reuse: bool = True,
                     wide: bool = True) -> dict[str, Any]:
    """Set the environment of this process for ``cpus`` CPUs, before JAX creates its backend.

    * ``PJRT_NPROC=cpus``: XLA's CPU client sizes its thread pool from it (default: all cores of the node,
      which oversubscribes a node shared by several jobs);
    * ``OMP/MKL/OPENBLAS/NUMBA_NUM_THREADS=cpus`` for libraries loaded later;
    * ``jax_num_cpu_devices=host_devices`` (only while no backend exists; ``None``: one per CPU): that many JAX
      host devices, over which ``workspace_grid``'s JAX backend shards its chunks (default one: see the module);
    * ``XLA_PYTHON_CLIENT_PREALLOCATE=false`` unless ``gpu_preallocate``: several jobs can share one GPU;
    * with ``malloc_reuse``, glibc's allocator told to keep freed memory for reuse (:func:`keep_freed_memory`,
      before XLA's threads start): a batch program's outputs then land in memory already mapped instead of fresh
      pages the kernel must fault in on every call (docs/BENCHMARKS.md: the JAX kernel 1.4-1.7x per CPU-second);
    * with ``wide``, 512-bit vectors for XLA:CPU and Numba where the CPU has AVX-512 (:func:`wide_vectors`).

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

    if "numba" in sys.modules and environ is None:  # a reused worker: NUMBA_NUM_THREADS was read at its import
        import numba

        numba.set_num_threads(min(cpus, numba.config.NUMBA_NUM_THREADS))
    applied: dict[str, Any] = {"cpus": cpus, "PJRT_NPROC": env["PJRT_NPROC"],
                               "XLA_PYTHON_CLIENT_PREALLOCATE": env.get("XLA_PYTHON_CLIENT_PREALLOCATE", "")}
    if environ is None:
        applied["malloc"] = keep_freed_memory() if malloc_reuse else "glibc defaults (malloc_reuse=false)"
    if environ is None:  # this process: the Numba thread pool size in effect (numba reads NUMBA_NUM_THREADS once)
        import numba

        applied["numba_threads"] = int(numba.get_num_threads())
    applied["vectors"] = wide_vectors(environ) if wide else "the compilers' defaults (wide_vectors=false)"

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


#: glibc ``mallopt`` parameters (M_MMAP_THRESHOLD, M_TRIM_THRESHOLD, M_TOP_PAD) of :func:`keep_freed_memory`
MALLOC_REUSE = {-3: 1 << 30, -1: 1 << 30, -2: 64 << 20}


def keep_freed_memory() -> str:
    """Tell glibc's allocator to serve buffers below 1 GiB from its heap and keep up to 1 GiB of freed memory
    instead of handing it back at once (its defaults map each large buffer afresh and unmap it when freed, so every
    call of a batch program pays the page faults of its outputs again). Only before JAX's backend starts (its
    thread arenas are made then); what the stage engine frees between stages still goes back
    (:func:`deltajax.jobs.stages.release_memory`). Returns what was done, for the log."""
    import ctypes

    if xla_bridge.backends_are_initialized():
        return "unchanged (backend already initialised)"
    try:
        libc = ctypes.CDLL("libc.so.6")
        ok = all(libc.mallopt(k, v) == 1 for k, v in MALLOC_REUSE.items())
    except (OSError, AttributeError):
        return "unchanged (not glibc)"
    return "freed memory kept for reuse" if ok else "unchanged (mallopt refused)"


#: the vector width (bits) :func:`wide_vectors` asks XLA:CPU and Numba's LLVM to prefer
WIDE_VECTOR_BITS = 512


def host_has_avx512() -> bool:
    """Whether this machine's CPU has AVX-512 (``avx512f`` among its flags, :func:`deltajax.tracing.cpu_flags`)."""
    return "avx512f" in cpu_flags().split()


def wide_vectors(environ: Optional[dict] = None) -> str:
    """Let XLA:CPU and Numba use the CPU's 512-bit vectors where it has AVX-512.

    Both compilers prefer 256-bit vectors by default on such CPUs (XLA's ``xla_cpu_prefer_vector_width`` is 256;
    LLVM's tuning for Intel's AVX-512 cores is ``prefer-256-bit``). The kernels of deltajax are straight-line
    arithmetic over points or samples, where 512 bits measured faster on a 2-core Intel Xeon (docs/BENCHMARKS.md:
    the JAX kernel 1.4-1.7x per CPU-second, the Table-6 job's Numba R screen 1.2x) and gave the same answers
    (the kernel's outputs, the main job's and the Table-6 job's results files bit for bit).

    * XLA: ``--xla_cpu_prefer_vector_width=512`` added to ``XLA_FLAGS`` of ``environ`` (default: this process's
      environment), only while no JAX backend exists (the flags are read when it starts) and unless the flag is
      already there (an explicit setting wins). The flags are part of every compiled program's cache key (JAX's
      and :mod:`deltajax.tracing`'s), so the programs compiled either way never mix.
    * Numba (this process only, when ``environ`` is None): the host's CPU features with ``-prefer-256-bit``
      (``numba.config.CPU_FEATURES``), unless ``NUMBA_CPU_NAME`` or ``NUMBA_CPU_FEATURES`` is set, and only before
      Numba has built its code generator (importing deltajax's Numba backend builds it); not through the
      environment, which child processes on other machines would inherit (their CPUs may lack a feature); its code
      generator is built at once, with them (a few milliseconds).

    Returns what was done, for the log and the results' attributes.
    """
    env = os.environ if environ is None else environ
    if not host_has_avx512():
        return "the compilers' defaults (no AVX-512)"
    flags = env.get("XLA_FLAGS", "")
    if "xla_cpu_prefer_vector_width" in flags:
        xla = "XLA as XLA_FLAGS says"
    elif xla_bridge.backends_are_initialized():
        xla = "XLA unchanged (backend already initialised)"
    else:
        env["XLA_FLAGS"] = f"{flags} --xla_cpu_prefer_vector_width={WIDE_VECTOR_BITS}".strip()
        xla = f"XLA {WIDE_VECTOR_BITS}-bit"
    if environ is not None:
        return xla
    import llvmlite.binding as llvm
    from numba.core import config as numba_config, registry

    if "NUMBA_CPU_NAME" in env or "NUMBA_CPU_FEATURES" in env:
        nb = "Numba as NUMBA_CPU_NAME / NUMBA_CPU_FEATURES say"
    elif "_toplevel_target_context" in vars(registry.cpu_target):   # its code generator fixed its features
        nb = "Numba unchanged (already compiling)"
    else:   # the code generator built now keeps them (numba re-reads its config on a change of NUMBA_* variables)
        numba_config.CPU_FEATURES = f"{llvm.get_host_cpu_features().flatten()},-prefer-256-bit"
        registry.cpu_target.target_context
        nb = f"Numba {WIDE_VECTOR_BITS}-bit"
    return f"{xla}, {nb}"


class WorkerEnv(Callback):
    """Hydra callback: prepare each job's process (threads, host devices, GPU memory) before it runs.

    Registered in ``configs/config.yaml`` under ``hydra.callbacks.worker_env``; its arguments are overrides:
    ``hydra.callbacks.worker_env.cpus=8`` (default: see :func:`resolve_worker_cpus`),
    ``hydra.callbacks.worker_env.host_devices=4`` (default 1; ``null``: one JAX host device per CPU),
    ``hydra.callbacks.worker_env.gpu_preallocate=true``, ``hydra.callbacks.worker_env.malloc_reuse=false``
    (glibc's defaults: freed buffers unmapped at once), ``hydra.callbacks.worker_env.wide_vectors=false`` (the
    compilers' default vector width: :func:`wide_vectors`).
    """

    def __init__(self, cpus: Optional[int] = None, host_devices: Optional[int] = 1,
                 gpu_preallocate: bool = False, malloc_reuse: bool = True, wide_vectors: bool = True) -> None:
        self.cpus = cpus
        self.host_devices = host_devices
        self.gpu_preallocate = bool(gpu_preallocate)
        self.malloc_reuse = bool(malloc_reuse)
        self.wide_vectors = bool(wide_vectors)

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
        applied = apply_worker_env(cpus, self.host_devices, self.gpu_preallocate, malloc_reuse=self.malloc_reuse,
                                   wide=self.wide_vectors)
        os.environ["DELTAJAX_WORKER_ENV"] = json.dumps({**applied, "cpus_from": why})
        print(f"[deltajax] worker: {cpus} CPUs ({why}); XLA threads PJRT_NPROC={applied['PJRT_NPROC']}, "
              f"host devices {applied['host_devices']}; malloc: {applied['malloc']}; vectors: {applied['vectors']}",
              flush=True)
