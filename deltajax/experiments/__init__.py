"""Experiments runnable with ``python -m deltajax.run experiment=<module name>``.

Each experiment is ``deltajax/experiments/<name>.py`` (``run(ctx)``) with its settings in
``configs/experiment/<name>.yaml``. :data:`SUMMARIES` is the one-line description ``--help`` shows; an
experiment missing from it is listed with the first sentence of its module docstring.
"""

#: experiment name -> one line for ``python -m deltajax.run --help`` (the main job first).
SUMMARIES = {
    "ga_reconfig": "MAIN JOB (default): GA + Pareto front + refinement of the reconfigurable Delta",
    "indices_examples": "Franco-Lopez 2026 Tables 2-5 and index-vs-R curves at its two example points (Figs 3-6)",
    "reconfig_workspace": "fixed vs reconfigurable workspace volume and the increase (Fig 7)",
    "reconfig_indices": "index min/max/mean over the fixed-R workspace, R* by k~ (Tables 6-8, Fig 8); heavy at 2 mm",
    "boundary_search": "workspace boundary by bisection and continuation over all rays, Test-Pose counts, volumes",
    "workspace_grid": "reachable mask, volume, index fields and statistics on a grid (shardable; used by sweeps)",
    "dynamics_cycle": "actuator torque/speed/acceleration on the pick-and-place cycle and the GA paper's motion",
    "bench_kernel": "IK + Jacobian + indices throughput, float32/float64, vs NumPy and the naive JAX kernel",
}
