"""The CLI jobs: ``python -m deltajax.run experiment=NAME`` runs ``JOBS[NAME]``.

Each job is ``deltajax/jobs/<name>.py`` exposing ``run(ctx: RunContext) -> None`` (spec -> compute -> write ->
plot), with its settings in ``configs/experiment/<name>.yaml``. :data:`JOBS` is the one list of them: ``run.py``
dispatches through it and ``--help`` prints it (the main job first). Top-level ``experiments/`` holds scripts
(benchmarks, checks), not jobs.
"""

from __future__ import annotations

import importlib
from types import ModuleType
from typing import NamedTuple

__all__ = ["Job", "JOBS", "load"]


class Job(NamedTuple):
    """One CLI job: the module that runs it and the line ``--help`` shows."""

    module: str
    summary: str


#: experiment name -> job (the main job first).
JOBS: dict[str, Job] = {
    "ga_reconfig": Job("deltajax.jobs.ga_reconfig",
                       "MAIN JOB (default): GA + Pareto front + refinement of the reconfigurable Delta"),
    "indices_examples": Job("deltajax.jobs.indices_examples",
                            "Franco-Lopez 2026 Tables 2-5 and index-vs-R curves at its two example points (Figs 3-6)"),
    "reconfig_workspace": Job("deltajax.jobs.reconfig_workspace",
                              "fixed vs reconfigurable workspace volume and the increase (Fig 7)"),
    "reconfig_indices": Job("deltajax.jobs.reconfig_indices",
                            "index min/max/mean over the fixed-R workspace, R* by k~ (Tables 6-8, Fig 8); heavy at 2 mm"),
    "reconfig_motion": Job("deltajax.jobs.reconfig_motion",
                           "R(t) along the cycle: fixed R vs pointwise R* vs path-optimal R(t) under R-drive limits"),
    "boundary_search": Job("deltajax.jobs.boundary_search",
                           "workspace boundary by bisection and continuation over all rays, Test-Pose counts, volumes"),
    "workspace_grid": Job("deltajax.jobs.workspace_grid",
                          "reachable mask, volume, index fields and statistics on a grid (shardable; used by sweeps)"),
    "dynamics_cycle": Job("deltajax.jobs.dynamics_cycle",
                          "actuator torque/speed/acceleration on the pick-and-place cycle and the GA paper's motion"),
    "datasheet": Job("deltajax.jobs.datasheet",
                     "vendor-style datasheet (working range, picks/min vs payload, utilisations) of a preset or of a "
                     "ga_reconfig run's baseline and recommended designs"),
    "bench_kernel": Job("deltajax.jobs.bench_kernel",
                        "IK + Jacobian + indices throughput, float32/float64, vs NumPy and the frozen old kernel"),
}


def load(name: str) -> ModuleType:
    """The module of job ``name`` (``KeyError`` when there is no such job)."""
    return importlib.import_module(JOBS[name].module)
