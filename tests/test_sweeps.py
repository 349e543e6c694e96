"""Sweeps through the real CLI: joblib and submitit_local multiruns, sharded jobs merged exactly, resume,
the analysis script; plus the pure bookkeeping (CPU sizing, shard plans) as properties.

The CLI runs use experiment.backend=auto (the Numba kernel on CPU; its compilation is cached on disk by the
first run) and share a JAX persistent compilation cache; the two sweeps and the resume run go concurrently.
The JAX backend's sharding is tested in-process.
"""

import importlib.util
import json
import os
from pathlib import Path

import h5py
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from _sweep_helpers import assert_identical, cli, finish
from deltajax.config import ConfigError
from deltajax.config import grid_plan
from deltajax.sweeps import ShardError, merge_shards, resolve_worker_cpus

REPO = Path(__file__).resolve().parent.parent
TINY = ["experiment=workspace_grid", "plots=false", "progress=false", "experiment.grid.h=0.1",
        "experiment.grid.z=[0.0,0.6]", "experiment.chunk_points=100", "hydra.callbacks.worker_env.cpus=1"]
TIMEOUT = 240


def _cli(args, tmp, env):
    return cli(args, tmp, env)


def _finish(proc, what):
    return finish(proc, what, TIMEOUT)


@pytest.fixture(scope="module")
def sweeps(tmp_path_factory):
    """Run everything once: single reference run, then joblib sweep, submitit_local sharded sweep and a
    resumed run concurrently."""
    tmp = tmp_path_factory.mktemp("sweeps")
    env = dict(os.environ, JAX_COMPILATION_CACHE_DIR=str(tmp / "jax_cache"), HYDRA_FULL_ERROR="1",
               PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    env.pop("XLA_FLAGS", None)
    single = tmp / "single"
    # a run of the same job stopped after 4 x-planes (as if killed): the resumed run must finish it identically
    resume = tmp / "resume"
    first = {"single": _cli([*TINY, f"hydra.run.dir={single}"], tmp, env),
             "partial": _cli([*TINY, "experiment.stop_after=4", f"hydra.run.dir={resume}"], tmp, env)}
    for k, p in first.items():
        _finish(p, k)
    procs = {
        "joblib": _cli(["-m", *TINY, "robot.forearm=0.35,0.4", "hydra/launcher=joblib", "hydra.launcher.n_jobs=2",
                        f"hydra.sweep.dir={tmp / 'joblib'}"], tmp, env),
        "submitit": _cli(["-m", *TINY, "n_shards=2", "shard=0,1", "hydra/launcher=slurm_local",
                          f"hydra.sweep.dir={tmp / 'submitit'}"], tmp, env),
        "resume": _cli([*TINY, "experiment.checkpoint_s=0", f"hydra.run.dir={resume}"], tmp, env),
    }
    logs = {k: _finish(p, k) for k, p in procs.items()}
    return {"tmp": tmp, "single": single / "results.h5", "resume": resume / "results.h5", "logs": logs}


def _assert_identical(a_path, b_path, same_config=True):
    """Same groups, datasets (bit for bit, NaN = NaN), units, dimensions, group attributes and config."""
    assert_identical(a_path, b_path, same_config=same_config)


@pytest.mark.slow
def test_joblib_multirun(sweeps):
    sweep = sweeps["tmp"] / "joblib"
    runs = {}
    for d in (sweep / "0", sweep / "1"):
        with h5py.File(d / "results.h5", "r") as f:
            assert f.attrs["end_time"]
            env = json.loads(f.attrs["worker_env"])
            assert env["cpus"] == 1 and env["PJRT_NPROC"] == "1" and env["host_devices"] == 1
            assert f.attrs["device"].endswith("x1")
            runs[d.name] = int(f["workspace/count"][()])
    # forearm 0.4 is the preset: that job is the single reference run; a shorter forearm reaches less
    _assert_identical(sweep / "1" / "results.h5", sweeps["single"])
    assert 0 < runs["0"] < runs["1"] == 79  # 79: also what the JAX backend finds (test below)
    rows = json.loads((sweep / "summary.json").read_text())["runs"]
    assert [(r["run"], r["status"], r["overrides"]["robot.forearm"]) for r in rows] == [("0", "ok", "0.35"),
                                                                                        ("1", "ok", "0.4")]
    assert [r["metrics"]["workspace/count"] for r in rows] == [runs["0"], runs["1"]]
    header = (sweep / "summary.csv").read_text().splitlines()[0]
    assert "robot.forearm" in header and "workspace/volume [m^3]" in header
    assert not (sweep / "merged").exists()  # nothing sharded


@pytest.mark.slow
def test_submitit_local_shards_merge_to_single_run(sweeps):
    sweep = sweeps["tmp"] / "submitit"
    assert any((sweep / ".submitit").glob("*/*_result.pkl"))  # the submitit path really ran
    counts, ranges = [], []
    for s in ("0", "1"):
        with h5py.File(sweep / s / "results.h5", "r") as f:
            g = f["workspace"]
            counts.append(int(g["count"][()]))
            ranges.append((int(g.attrs["shard_start"]), int(g.attrs["shard_stop"])))
            assert g["reachable"].shape[0] == ranges[-1][1] - ranges[-1][0]
    assert ranges == [(0, ranges[0][1]), (ranges[0][1], 9)] and 0 < ranges[0][1] < 9
    merged = sweep / "merged" / "workspace_grid" / "results.h5"  # written by the SweepSummary callback
    _assert_identical(merged, sweeps["single"])
    with h5py.File(merged, "r") as f:
        assert int(f["workspace/count"][()]) == sum(counts)
        assert f.attrs["merged_n_shards"] == 2
    import xarray as xr

    from deltajax.io import open_xarray

    a, b = open_xarray(merged, "workspace"), open_xarray(sweeps["single"], "workspace")
    xr.testing.assert_identical(a, b)
    assert a["reachable"].dims == ("x", "y", "z") and a["volume"].attrs["units"] == "m^3"
    rows = json.loads((sweep / "summary.json").read_text())["runs"]
    assert [(r["kind"], r["status"]) for r in rows] == [("run", "ok"), ("run", "ok"), ("merged", "ok")]
    assert rows[2]["metrics"]["workspace/count"] == sum(counts)


@pytest.mark.slow
def test_merge_refuses_incomplete_or_foreign_shards(sweeps, tmp_path):
    sweep = sweeps["tmp"] / "submitit"
    with pytest.raises(ShardError, match="missing \\[1\\]"):
        merge_shards([sweep / "0" / "results.h5"], tmp_path / "m.h5")
    with pytest.raises(ShardError, match="not a shard of the same job"):
        merge_shards([sweep / "0" / "results.h5", sweeps["tmp"] / "joblib" / "0" / "results.h5"], tmp_path / "m.h5")
    out = merge_shards([sweep / "1" / "results.h5", sweep / "0" / "results.h5"], tmp_path / "m.h5")  # any order
    _assert_identical(out, sweeps["single"])


@pytest.mark.slow
def test_resume_from_checkpoint_matches_single_run(sweeps):
    assert "resuming: 4 x-planes already done" in sweeps["logs"]["resume"]
    with h5py.File(sweeps["resume"], "r") as f:
        assert f.attrs["points_evaluated"] == 9 * 9 * 7  # the whole run's work, as uninterrupted
        assert f.attrs["points_evaluated_this_process"] == 5 * 9 * 7  # only the 5 missing x-planes
    _assert_identical(sweeps["resume"], sweeps["single"], same_config=False)  # config: checkpoint_s differs


@pytest.mark.slow
def test_analysis_script_on_sweep(sweeps, tmp_path):
    spec = importlib.util.spec_from_file_location("analyze_sweep", REPO / "experiments" / "analyze_sweep.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    written = mod.analyze(sweeps["tmp"] / "joblib", out=tmp_path)
    for k in ("table_md", "table_csv", "metrics_png", "area_png"):
        assert written[k].stat().st_size > 0, k
    lines = written["table_csv"].read_text().splitlines()
    assert lines[0].startswith("run,robot.forearm,workspace/volume [m^3]")
    vols = [float(line.split(",")[2]) for line in lines[1:]]
    with h5py.File(sweeps["single"], "r") as f:
        ref = float(f["workspace/volume"][()])
    assert len(vols) == 2 and vols[1] == ref and vols[0] < vols[1]
    written = mod.analyze(sweeps["tmp"] / "submitit", out=tmp_path / "sub")  # sharded: merged row only
    rows = written["table_csv"].read_text().splitlines()[1:]
    assert len(rows) == 1 and rows[0].startswith("merged/workspace_grid,")


# -- pure bookkeeping --------------------------------------------------------------------------------------
@given(avail=st.integers(1, 256), n_jobs=st.integers(-4, 64).filter(lambda n: n != 0))
def test_joblib_cpus_never_oversubscribe(avail, n_jobs):
    cpus, _ = resolve_worker_cpus({"_target_": "hydra_plugins.hydra_joblib_launcher.JoblibLauncher",
                                   "n_jobs": n_jobs}, environ={}, available=avail)
    workers = n_jobs if n_jobs > 0 else max(1, avail + 1 + n_jobs)
    assert cpus >= 1
    assert cpus * workers <= avail or cpus == 1


def test_worker_cpus_sources():
    slurm = {"_target_": "hydra_plugins.hydra_submitit_launcher.submitit_launcher.SlurmLauncher", "cpus_per_task": 8}
    assert resolve_worker_cpus(slurm, environ={"SLURM_CPUS_PER_TASK": "12"}, available=64)[0] == 12
    assert resolve_worker_cpus(slurm, environ={}, available=64)[0] == 8
    assert resolve_worker_cpus(slurm, environ={}, available=4)[0] == 4  # never more than the process may use
    assert resolve_worker_cpus(None, environ={}, available=6) == (6, "all CPUs of the process")


@pytest.mark.slow
def test_worker_keeps_freed_memory_only_before_jax_starts():
    """The worker tells glibc to keep freed memory for reuse before XLA's threads exist (a fresh process: mallopt
    accepts every parameter, and JAX runs after it); in a process whose backend already runs (this one) it changes
    nothing and says so."""
    import subprocess
    import sys

    from deltajax.sweeps.worker import keep_freed_memory

    import jax

    jax.numpy.zeros(1).block_until_ready()                       # this process: the backend is up
    assert keep_freed_memory() == "unchanged (backend already initialised)"
    code = ("from deltajax.sweeps.worker import apply_worker_env; a = apply_worker_env(1); print(a['malloc']); "
            "import jax; print(jax.numpy.ones(3).sum())")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.split("\n")[:2] == ["freed memory kept for reuse", "3.0"], out.stdout


_WIDE_PROBE = """
import os, sys
from deltajax.sweeps.worker import apply_worker_env, host_has_avx512
a = apply_worker_env(1, wide=sys.argv[1] == "wide")
import numba, numpy as np

@numba.njit
def axpy(a, x, y):
    for i in range(x.shape[0]):
        y[i] += a * x[i]

x = np.ones(64)
axpy(2.0, x, x)
asm = next(iter(axpy.inspect_asm().values()))
from numba.core import config
print(host_has_avx512(), "|", a["vectors"], "|", os.environ.get("XLA_FLAGS", ""), "|", "zmm" in asm, "|",
      (config.CPU_FEATURES or "").endswith(",-prefer-256-bit"))
"""


@pytest.mark.slow
def test_worker_asks_for_wide_vectors_where_the_cpu_has_them():
    """A fresh worker process on a CPU with AVX-512 asks XLA:CPU for 512-bit vectors (XLA_FLAGS, before its backend
    starts) and Numba's LLVM too (the host's features with ``-prefer-256-bit``): a loop then runs on 512-bit (zmm)
    registers. ``wide_vectors=false`` leaves both compilers' defaults: no XLA flag, Numba's features untouched; its
    loop then runs at LLVM's own width for the CPU (256 bits on Intel's AVX-512 cores, 512 on AMD's Zen 5, so that
    field is not compared). On a CPU without AVX-512 nothing changes."""
    import subprocess
    import sys

    from deltajax.sweeps.worker import host_has_avx512

    env = {k: v for k, v in os.environ.items() if k not in ("XLA_FLAGS", "NUMBA_CPU_NAME", "NUMBA_CPU_FEATURES")}
    lines = {}
    for mode in ("wide", "default"):
        out = subprocess.run([sys.executable, "-c", _WIDE_PROBE, mode], capture_output=True, text=True, timeout=120,
                             env=env)
        assert out.returncode == 0, out.stderr[-2000:]
        lines[mode] = [f.strip() for f in out.stdout.strip().split("\n")[-1].split("|")]
    if host_has_avx512():
        assert lines["wide"] == ["True", "XLA 512-bit, Numba 512-bit", "--xla_cpu_prefer_vector_width=512", "True",
                                 "True"]
        d = lines["default"]
        assert d[:3] + d[4:] == ["True", "the compilers' defaults (wide_vectors=false)", "", "False"]
    else:
        assert lines["wide"] == ["False", "the compilers' defaults (no AVX-512)", "", "False", "False"]


def test_wide_vectors_keep_an_explicit_setting_and_a_running_backend():
    """An XLA_FLAGS that already names the vector width wins; with no AVX-512 or a backend already running (this
    process), the flags are left as they are; the answer says which."""
    from deltajax.sweeps.worker import host_has_avx512, wide_vectors

    import jax

    jax.numpy.zeros(1).block_until_ready()                       # this process: the backend is up
    mine = {"XLA_FLAGS": "--xla_cpu_prefer_vector_width=256"}
    said = wide_vectors(mine)
    assert mine == {"XLA_FLAGS": "--xla_cpu_prefer_vector_width=256"}
    bare = {"XLA_FLAGS": "--xla_force_host_platform_device_count=1"}
    said_bare = wide_vectors(bare)
    assert bare == {"XLA_FLAGS": "--xla_force_host_platform_device_count=1"}
    if host_has_avx512():
        assert said == "XLA as XLA_FLAGS says"
        assert said_bare == "XLA unchanged (backend already initialised)"
    else:
        assert said == said_bare == "the compilers' defaults (no AVX-512)"


@pytest.mark.slow
def test_worker_gives_one_host_device_whatever_its_cpus():
    """A job's process has one JAX host device by default however many CPUs it gets (XLA's cache keys every
    executable by the device count: jobs, in-process runs and the tests then share their compiled programs); more
    on request: the SLURM test's sharded sweep asks for two (tests/test_slurm.py)."""
    import subprocess
    import sys

    from omegaconf import OmegaConf

    cfg = OmegaConf.load(Path(__file__).resolve().parents[1] / "configs" / "config.yaml")
    assert cfg.hydra.callbacks.worker_env.host_devices == 1
    code = ("from deltajax.sweeps.worker import WorkerEnv, apply_worker_env; a = apply_worker_env(2); import jax; "
            "print(a['host_devices'], a['PJRT_NPROC'], jax.local_device_count(), WorkerEnv().host_devices)")
    env = {k: v for k, v in os.environ.items()
           if k not in ("XLA_FLAGS", "JAX_NUM_CPU_DEVICES", "PJRT_NPROC", "JAX_PLATFORMS")}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                         env={**env, "JAX_PLATFORMS": "cpu"})
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip() == "1 2 1 1", out.stdout


@given(nx=st.integers(1, 60), ny=st.integers(1, 9), nz=st.integers(1, 9), chunk=st.integers(1, 400),
       n_dev=st.integers(1, 4), data=st.data())
def test_shards_partition_the_grid_on_chunk_boundaries(nx, ny, nz, chunk, n_dev, data):
    n_chunks = grid_plan((nx, ny, nz), chunk, n_dev, 0, 1).n_chunks
    n_shards = data.draw(st.integers(1, n_chunks))
    plans = [grid_plan((nx, ny, nz), chunk, n_dev, s, n_shards) for s in range(n_shards)]
    assert plans[0].x_start == 0 and plans[-1].x_stop == nx
    for p, q in zip(plans, plans[1:]):
        assert p.x_stop == q.x_start and p.x_start < p.x_stop
    for p in plans:
        assert p.x_start % p.planes_per_chunk == 0  # same chunk positions as a single run
        assert p.chunk_len % n_dev == 0 and p.chunk_len >= p.planes_per_chunk * ny * nz


def test_bad_shard_settings_name_the_field():
    with pytest.raises(ConfigError, match="^shard must be in 0..1"):
        grid_plan((9, 9, 7), 100, 1, 2, 2)
    with pytest.raises(ConfigError, match="^n_shards must be in 1..9"):
        grid_plan((9, 9, 7), 100, 1, 0, 10)


@pytest.mark.slow
def test_jax_backend_shards_merge_to_single_run(sweeps, tmp_path):
    """backend=jax through the Python API: 3 shards merged equal one run bit for bit; the JAX kernel agrees
    with the Numba one the CLI runs used (backend=auto on CPU) to rounding, with the same reachable set."""
    from deltajax.run import run_experiment

    over = ["plots=false", "progress=false", "experiment.grid.h=0.1", "experiment.grid.z=[0.0,0.6]",
            "experiment.chunk_points=100", "experiment.backend=jax"]
    single = run_experiment("workspace_grid", over, run_dir=tmp_path / "single")
    shards = [run_experiment("workspace_grid", [*over, "n_shards=3", f"shard={i}"], run_dir=tmp_path / str(i))
              for i in (2, 0, 1)]
    merged = merge_shards(shards, tmp_path / "merged.h5")
    _assert_identical(merged, single)
    with h5py.File(single, "r") as f, h5py.File(sweeps["single"], "r") as g:
        assert f.attrs["backend"] == "jax" and g.attrs["backend"] == "numba"
        assert np.array_equal(f["workspace/reachable"][()], g["workspace/reachable"][()])
        assert int(f["workspace/count"][()]) == 79
        np.testing.assert_allclose(f["workspace/k_tilde"][()], g["workspace/k_tilde"][()], rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(f["workspace/inv_cond_mean"][()], g["workspace/inv_cond_mean"][()], rtol=1e-9)


def test_summary_indexes_runs_scalars_and_per_chain_maxima(tmp_path):
    """summarize_sweep on a hand-made sweep: overrides as columns, 0-d scalars, [max] of per-chain vectors,
    missing runs marked, axes not summarised."""
    from deltajax.io import ResultsFile
    from deltajax.sweeps import summarize_sweep

    for i, forearm in enumerate(("0.3", "0.5")):
        run = tmp_path / str(i)
        (run / ".hydra").mkdir(parents=True)
        (run / ".hydra" / "overrides.yaml").write_text(f"- experiment=demo\n- robot.forearm={forearm}\n")
        if i == 1:
            continue  # a job that never wrote results
        res = ResultsFile(run / "results.h5", attrs={"experiment": "demo"})
        res.put("dynamics/case", "peak_torque", np.array([1.5, 7.25, np.nan]), units="N m", dims=("chain",))
        res.put("workspace", "volume", 0.125, units="m^3")
        res.put_axis("workspace", "z", np.linspace(0, 1, 3), units="m")
        res.flush(final=True)
    paths = summarize_sweep(tmp_path)
    rows = json.loads(paths["json"].read_text())["runs"]
    assert [(r["run"], r["status"], r["overrides"]["robot.forearm"]) for r in rows] == [("0", "ok", "0.3"),
                                                                                        ("1", "missing", "0.5")]
    assert rows[0]["metrics"] == {"workspace/volume": 0.125, "dynamics/case/peak_torque[max]": 7.25}
    lines = paths["csv"].read_text().splitlines()
    assert lines[0].split(",") == ["run", "kind", "status", "experiment_name", "wall_time_s", "experiment",
                                   "robot.forearm", "dynamics/case/peak_torque[max] [N m]", "workspace/volume [m^3]"]
    assert lines[1].split(",") == ["0", "run", "ok", "demo", "", "demo", "0.3", "7.25", "0.125"]
    assert lines[2].split(",")[:3] == ["1", "run", "missing"]
