"""Toy sizes of every CLI job (seconds each, not minutes), shared by the whole suite.

``tests/conftest.py``'s session fixture ``toy_run(name, *extra)`` runs ``name`` once per session with
``COMMON + TOY[name] + extra`` and hands every test the same results file, so no job runs twice for the same
settings (tests/test_jobs.py runs each end to end; other files check their own numbers on the same file).
Change a size here, not in a test file, so the shared runs stay shared.
"""

import os

#: the persistent XLA cache of the test session (tests/conftest.py) and of the toy runs; DELTAJAX_TEST_JAX_CACHE
#: picks another folder (an empty one measures a cold start)
JAX_CACHE = os.path.expanduser(os.environ.get("DELTAJAX_TEST_JAX_CACHE", "~/.cache/deltajax/jax"))
#: the tests' persistent-cache threshold (the CLI's too, ``deltajax.run.CACHE_MIN_COMPILE_S``): every program,
#: the smallest eager operation included. Most of the fast tier's compilations are programs of a few operations
#: (~30 ms each, ~580 per session) that a warm session reads back in a few ms instead (docs/BENCHMARKS.md, Test
#: suite)
JAX_CACHE_MIN_S = 0.0
#: plots on (a job's figures are part of its end-to-end run)
COMMON = ["progress=false", f"compilation_cache={JAX_CACHE}"]
#: jobs the fixture runs through the real CLI (``python -m deltajax.run``, a subprocess) rather than in-process
CLI = {"indices_examples"}
TOY = {
    # on the 1e-4 R grid the k~ argmax is checked to one step against the paper (tests/test_io_cli.py)
    "indices_examples": ["experiment.R_step=1e-4"],
    "reconfig_workspace": ["experiment.h=0.04"],
    "reconfig_indices": ["experiment.h=0.04", "beta=0.75", "experiment.slices_z=[0.4]"],
    "boundary_search": ["experiment.steps_deg=[15.0]", "experiment.grid_h=0.2", "experiment.profile_samples=64",
                        "experiment.centre_sweep_z=[1.62]", "experiment.sweep_step_deg=15.0",
                        "experiment.timing_repeats=1"],
    # 9 x 9 x 7 points, one x-plane per chunk, a checkpoint after every chunk (tests/test_faults.py tampers with it)
    "workspace_grid": ["experiment.grid.h=0.1", "experiment.grid.z=[0.0,0.6]", "experiment.chunk_points=63",
                       "experiment.checkpoint_s=0"],
    # franco2026 is always evaluated; industrial adds the second preset (tests/test_dynamics.py)
    "dynamics_cycle": ["experiment.n_samples=41", "experiment.robots=[industrial]"],
    # industrial, coarse volume / working-range grids, 41 cycle samples, three payloads (tests/test_datasheet_job.py)
    "datasheet": ["source=industrial", "experiment.volume_h=0.05", "experiment.cylinder_grid=[9,3,9]",
                  "experiment.n_samples=41", "experiment.payloads=[0.0,0.1,1.0]"],
    "bench_kernel": ["experiment.n_points=4000", "experiment.n_baseline=1000", "experiment.block=1000",
                     "experiment.repeats=1"],
    "reconfig_motion": ["experiment.R_step=0.007", "experiment.cases.adept.n_samples=11",
                        "experiment.cases.task.samples_per_segment=5", "experiment.refine.enabled=false",
                        "experiment.cases.task.points=[[0.0,0.0,0.30],[0.15,0.08,0.42],[-0.12,0.12,0.45]]"],
    # the main job (tests/test_ga_reconfig.py resumes it from generation 2 of 4)
    "ga_reconfig": [
        "experiment.design.n_R=3", "experiment.task.n_r=1", "experiment.task.n_phi=3", "experiment.task.n_z=2",
        "experiment.cycle.n_samples=11", "experiment.cycle.n_R_operating=2", "experiment.regular_workspace.n_r=6",
        "experiment.regular_workspace.n_phi=2", "experiment.regular_workspace.n_z=6",
        "experiment.ga.population_size=8", "experiment.ga.generations=4", "experiment.ga.checkpoint_every=2",
        "experiment.pareto.population_size=8", "experiment.pareto.generations=3", "experiment.verify.n_R=3",
        "experiment.verify.n_R_operating=2", "experiment.verify.task_n_r=1", "experiment.verify.task_n_phi=3",
        "experiment.verify.task_n_z=2", "experiment.verify.cycle_samples=13", "experiment.verify.rw_n_r=7",
        "experiment.verify.rw_n_phi=3", "experiment.verify.rw_n_z=7", "experiment.screen.log2_size=6",
        "experiment.refine.steps=3", "experiment.tolerance.samples=200",
        # certify: the first doubling only (a toy grid does not settle; each further doubling is ~5x the rays' work)
        "experiment.verify.certify_doublings=0"],
}


def overrides(name, *extra):
    """The full override list of a toy run."""
    return [*COMMON, *TOY[name], *extra]


def _optional_stages() -> set:
    """The ``experiment.<stage>`` blocks with an ``enabled`` switch in this checkout's ga_reconfig config (the
    optax refine stage and the floor step; tests switch them off where they cost)."""
    from pathlib import Path

    import yaml

    cfg = yaml.safe_load((Path(__file__).resolve().parent.parent / "configs" / "experiment" / "ga_reconfig.yaml")
                         .read_text())
    exp = cfg.get("experiment", cfg)
    return {k for k, v in exp.items() if isinstance(v, dict) and "enabled" in v}


_OPTIONAL = _optional_stages()
HAS_REFINE = "refine" in _OPTIONAL
HAS_FLOOR_STEP = "floor_solve" in _OPTIONAL
if HAS_REFINE:  # the toy run has every optional stage on
    TOY["ga_reconfig"].append("experiment.refine.enabled=true")
#: ga_reconfig with its optional stages off: one extra run, shared by every test that needs it
GA_STAGES_OFF = (("experiment.pareto.enabled=false",) + (("experiment.refine.enabled=false",) if HAS_REFINE else ())
                 + (("experiment.floor_solve.enabled=false",) if HAS_FLOOR_STEP else ()))
