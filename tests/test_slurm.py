"""Sweeps through a real SLURM scheduler (slurmctld + slurmd on this machine, `.ci/slurm-up`), with the real CLI
(``python -m deltajax.run -m ... hydra/launcher=slurm``): array jobs, sharded grids merged exactly, a GA job
cancelled and resubmitted into its run directory, failed and memory-killed jobs in the sweep summary, and the
resources (CPUs, memory, log files) as SLURM itself records and enforces them.

Needs a cluster: ``SLURM_CONF`` (or ``/tmp/deltajax-slurm/slurm.conf`` from ``.ci/slurm-up``) with its node
idle. Without one these tests skip, saying so; with ``DELTAJAX_REQUIRE_SLURM=1`` (set by ``.ci/run``) they
fail instead, so CI can never skip them silently.
"""

import json
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

from _sweep_helpers import assert_identical, cli, finish, job, rows
from toy_jobs import GA_STAGES_OFF, TOY
from deltajax.io import read

REPO = Path(__file__).resolve().parent.parent
DEFAULT_CONF = Path(os.environ.get("DELTAJAX_SLURM_DIR", "/tmp/deltajax-slurm")) / "slurm.conf"
TINY = ["experiment=workspace_grid", "plots=false", "progress=false", "experiment.grid.h=0.1",
        "experiment.grid.z=[0.0,0.6]", "experiment.chunk_points=100"]
# a job's limit and a CLI call's wait: generous for a machine whose XLA cache is empty (every job compiles its
# programs on one CPU beside the rest of the suite: the uninterrupted GA job outran a 15-min limit, 2026-12-05)
SLURM = ["hydra/launcher=slurm", "hydra.launcher.timeout_min=45"]
TIMEOUT = 1800  # s per CLI call (jobs share the machine's 2 cores with the rest of CI)

def _cluster_problem(env) -> str:
    """'' if the cluster answers with an idle (or busy) node, else why not."""
    conf = env.get("SLURM_CONF")
    if not conf:
        return f"SLURM_CONF unset and {DEFAULT_CONF} absent: start a test cluster with .ci/slurm-up"
    if not Path(conf).is_file():
        return f"SLURM_CONF={conf} does not exist"
    if shutil.which("sbatch", path=env["PATH"]) is None:
        return "sbatch not found (slurm-client not installed): run .ci/slurm-up"
    try:
        out = subprocess.run(["sinfo", "-h", "-o", "%t"], env=env, capture_output=True, text=True, timeout=20)
    except (OSError, subprocess.TimeoutExpired) as e:
        return f"sinfo failed: {e}"
    states = out.stdout.split()
    if out.returncode != 0 or not any(s in ("idle", "mix", "alloc", "comp") for s in states):
        return f"no usable node (sinfo rc {out.returncode}: {(out.stdout + out.stderr).strip()[:300]})"
    return ""


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    """The environment for CLI calls that submit to the test cluster (skip or, in CI, fail without one)."""
    env = dict(os.environ, HYDRA_FULL_ERROR="1",
               PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    env.pop("XLA_FLAGS", None)
    if "SLURM_CONF" not in env and DEFAULT_CONF.is_file():
        env["SLURM_CONF"] = str(DEFAULT_CONF)
    if env.get("SLURM_CONF"):  # .ci/slurm-up's sacct stand-in (see there) comes first on PATH
        env["PATH"] = str(Path(env["SLURM_CONF"]).parent / "bin") + os.pathsep + env["PATH"]
    problem = _cluster_problem(env)
    if problem:
        if os.environ.get("DELTAJAX_REQUIRE_SLURM") == "1":
            pytest.fail(f"DELTAJAX_REQUIRE_SLURM=1 but no SLURM test cluster: {problem}")
        pytest.skip(f"no SLURM test cluster: {problem}")
    tmp = tmp_path_factory.mktemp("slurm")
    return {"env": env, "tmp": tmp, "jobcomp": Path(env["SLURM_CONF"]).parent / "log" / "jobcomp.log"}


def _cli(cluster, args, **kw):
    return cli(args, cluster["tmp"], cluster["env"], **kw)


def _finish(proc, what, ok=True):
    return finish(proc, what, TIMEOUT, ok=ok)


_job = job


def _slurm_record(cluster, job_id, wait_s=60.0):
    """SLURM's completion record of a job (jobcomp/filetxt, written by slurmctld) as a dict. The job's result
    file, which the submitter waits for, is written before the job ends in SLURM: wait for the record."""
    deadline = time.monotonic() + wait_s
    while True:
        text = cluster["jobcomp"].read_text() if cluster["jobcomp"].exists() else ""
        for line in reversed(text.splitlines()):
            rec = dict(re.findall(r"(\w+)=(\S*)", line))
            if rec.get("JobId") == str(job_id):
                return rec
        if time.monotonic() > deadline:
            raise AssertionError(f"SLURM has no completion record of job {job_id} in {cluster['jobcomp']}")
        time.sleep(0.5)


_rows = rows


def _assert_identical(a_path, b_path, skip_attrs=()):
    """Same groups and datasets (bit for bit, NaN = NaN), units, dimensions and group attributes."""
    assert_identical(a_path, b_path, skip_attrs=skip_attrs)


def _sweeps(tmp) -> dict:
    """The CLI calls of the tests that submit a sweep and wait for it, by name (the memory sweep's field names
    come from the package)."""
    from deltajax.workspace import FIELD_NAMES

    one = [*SLURM, "hydra.launcher.cpus_per_task=1", "hydra.launcher.mem_gb=1"]
    return {
        # first, so that SLURM starts its job first: the GA job that test (a) cancels and resubmits
        "cut": ["-m", *_ga_overrides(), *GA_SLURM, f"hydra.sweep.dir={tmp / 'ga_cut'}"],
        "array": ["-m", *TINY, "robot.forearm=0.35,0.4", *one, f"hydra.sweep.dir={tmp / 'array'}"],
        "single": [*TINY, f"hydra.run.dir={tmp / 'single'}"],       # one local process, all CPUs
        "shards": ["-m", *TINY, "n_shards=3", "shard=0,1,2", *SLURM, "hydra.launcher.cpus_per_task=2",
                   "hydra.launcher.mem_gb=2", "hydra.callbacks.worker_env.host_devices=2",
                   f"hydra.sweep.dir={tmp / 'shards'}"],
        "failing": ["-m", *TINY, "robot.forearm=0.4,-1", "n_shards=2", "shard=0,1", *one,
                    f"hydra.sweep.dir={tmp / 'failing'}"],
        "memory": ["-m", *TINY, "experiment.grid.h=0.1,0.0025", "experiment.store=[" + ",".join(FIELD_NAMES[:5]) + "]",
                   *one, f"hydra.sweep.dir={tmp / 'memory'}"],
    }


#: which of :func:`_sweeps` each test reads (test (a), the first to run, starts them all)
SWEEPS_OF = {"test_cancelled_ga_job_resubmitted_finishes_bit_identical": ("cut",),
             "test_two_point_sweep_is_one_array_job": ("array",),
             "test_sharded_grid_merges_to_single_run_and_cpus_reach_the_worker": ("single", "shards"),
             "test_failed_point_is_reported_others_merge_and_merge_cli_recovers": ("failing",),
             "test_mem_gb_is_enforced_and_reported": ("memory",)}


@pytest.fixture(scope="module")
def started(cluster, request):
    """{name: the running CLI} of every sweep a selected test of this file reads, all started by the first of
    them to run (the GA job that test (a) cancels first, so that SLURM starts it first): their jobs share the
    node and their submitters wait together (sacct's polling, SLURM's ~5 s kill delay, submitit's 15 s wait for
    the result of a job SLURM killed), instead of one after the other with a core left idle (the file took
    ~120 s of one worker, ~60 s of it waiting). A submitter still running at the end of the module (its test
    failed first) is killed."""
    selected = {item.originalname for item in request.session.items if item.module is request.module}
    calls = _sweeps(cluster["tmp"])
    procs = {name: _cli(cluster, calls[name]) for test, names in SWEEPS_OF.items() if test in selected
             for name in names}
    yield procs
    for proc in procs.values():
        if proc.poll() is None:
            proc.kill()
            proc.communicate()


# -- (a) a GA job cancelled mid-way, resubmitted into its run directory (first: it starts the sweeps) ------
def _ga_overrides():
    """A toy GA: population, generations, seed; a checkpoint every 10 generations (a checkpoint rewrites
    results.h5 atomically, tens of CPU-ms and an fsync: one after each of the 3000 generations cost minutes
    under load; one every 100 made the GA so quick on an idle machine with a warm cache that it finished before
    scancel landed, CI 2026-12-01); the screen, Pareto, refine and floor stages off (what is checked is the GA's
    cancel, resubmit and bit-identical finish; with the screen and refine on, each of the three SLURM processes
    compiled them: ~33 s of each job on its one CPU), and the tolerance stage (a Monte Carlo of the finished
    recommendation: ~3.5 s of each finished job); every other size is the suite's toy main job
    (tests/toy_jobs.py: one source, so this job costs what the toy run costs -- its own copy of the sizes missed
    ``certify_doublings=0`` and the job outgrew its 3 GB, CI 2026-12-04)."""
    ga = ("experiment.ga.population_size=", "experiment.ga.generations=", "experiment.ga.checkpoint_every=")
    toy = [o for o in TOY["ga_reconfig"] if not o.startswith(ga) and not o.endswith(".enabled=true")]
    return ["experiment=ga_reconfig", "plots=false", "progress=false", "seed=0", *toy,
            "experiment.ga.population_size=8", "experiment.ga.generations=3000",  # ~5 ms each: time to cancel
            "experiment.ga.checkpoint_every=10", "experiment.screen.enabled=false",
            "experiment.tolerance.enabled=false", *GA_STAGES_OFF]


#: the GA job's resources: the toy main job peaks at 2.1-2.2 GiB (docs/BENCHMARKS.md): 2 GB killed the resumed
#: job at 2.18 GB
GA_SLURM = [*SLURM, "hydra.launcher.cpus_per_task=1", "hydra.launcher.mem_gb=3"]


def _generations_done(path):
    try:
        with h5py.File(path, "r") as f:
            return int(f["ga/checkpoint"].attrs["generations_done"])
    except (OSError, KeyError):
        return 0


@pytest.mark.slow
def test_cancelled_ga_job_resubmitted_finishes_bit_identical(cluster, started):
    over = [*_ga_overrides(), *GA_SLURM]
    generations = int(next(o for o in over if o.startswith("experiment.ga.generations=")).split("=")[1])
    tmp = cluster["tmp"]
    ref_sweep, sweep = tmp / "ga_ref", tmp / "ga_cut"
    cut = started["cut"]
    results = sweep / "0" / "results.h5"
    deadline = time.monotonic() + TIMEOUT
    while _generations_done(results) < 1:  # the first checkpoint
        assert cut.poll() is None, f"GA job ended before its first checkpoint:\n{cut.communicate()[0][-3000:]}"
        assert time.monotonic() < deadline, "no GA checkpoint in time"
        time.sleep(0.2)
    job = _job(sweep / "0")
    subprocess.run(["scancel", job["SLURM_JOB_ID"]], env=cluster["env"], check=True, timeout=30)
    # the uninterrupted reference runs while the cancelled sweep's submitter waits (SLURM kills the step ~5 s after
    # scancel; submitit then notices the job's end and waits 15 s for a result it will not get): on a core that
    # would otherwise be idle, rather than beside the cut job and the rest of the suite
    ref = _cli(cluster, ["-m", *over, f"hydra.sweep.dir={ref_sweep}"])
    out = _finish(cut, "cancelled sweep", ok=False)
    assert cut.returncode != 0 and "has not produced any output (state: CANCELLED" in out
    done_at_cancel = _generations_done(results)
    assert 1 <= done_at_cancel < generations, f"GA finished ({done_at_cancel} generations) before scancel landed"
    status = {r["run"]: r["status"] for r in _rows(sweep)}
    assert status["0"].startswith("killed: ") and "CANCELLED" in status["0"], status
    assert _slurm_record(cluster, job["SLURM_JOB_ID"])["JobState"] == "CANCELLED"
    # resubmit the same sweep into the same directory: the job resumes from its checkpoint
    out = _finish(_cli(cluster, ["-m", *over, f"hydra.sweep.dir={sweep}"]), "resubmitted sweep")
    log = Path(_job(sweep / "0")["stdout"]).read_text()
    assert f"resuming the GA from generation {done_at_cancel}" in log
    _finish(ref, "uninterrupted GA sweep")
    with h5py.File(results, "r") as f:
        assert int(f["ga"].attrs["resumed_from"]) == done_at_cancel
    # every dataset bit-identical to the uninterrupted run; attributes too, but timings and the resume point
    _assert_identical(results, ref_sweep / "0" / "results.h5", skip_attrs=(r"time_.*", "resumed_from"))
    assert [r["status"] for r in _rows(sweep)] == ["ok"]


# -- (b) an array job -----------------------------------------------------------------------------------
@pytest.mark.slow
def test_two_point_sweep_is_one_array_job(cluster, started):
    sweep = cluster["tmp"] / "array"
    out = _finish(started["array"], "array sweep")
    jobs = [_job(sweep / r) for r in ("0", "1")]
    # one array job, one task per sweep point
    assert jobs[0]["SLURM_ARRAY_JOB_ID"] == jobs[1]["SLURM_ARRAY_JOB_ID"]
    assert [j["SLURM_ARRAY_TASK_ID"] for j in jobs] == ["0", "1"]
    array = jobs[0]["SLURM_ARRAY_JOB_ID"]
    script = (sweep / ".submitit" / array / f"{array}_submission.sh").read_text()
    assert "#SBATCH --array=0-1%" in script
    for j, task in zip(jobs, "01"):
        rec = _slurm_record(cluster, j["SLURM_JOB_ID"])  # what SLURM itself recorded
        assert (rec["ArrayJobId"], rec["ArrayTaskId"], rec["JobState"]) == (array, task, "COMPLETED")
        assert "cpu=1," in rec["Tres"] and "mem=1G" in rec["Tres"]
        # logs where docs/CLUSTER.md says: <sweep>/.submitit/<array id>_<task>/<array id>_<task>_0_log.{out,err}
        log_dir = sweep / ".submitit" / f"{array}_{task}"
        assert j["stdout"] == str(log_dir / f"{array}_{task}_0_log.out")
        assert j["stderr"] == str(log_dir / f"{array}_{task}_0_log.err")
        log = Path(j["stdout"]).read_text()
        assert "[deltajax] worker: 1 CPUs (SLURM_CPUS_PER_TASK)" in log and "wrote " in log
        assert j["status"] == "ok"
    rows = _rows(sweep)
    assert [(r["run"], r["status"], r["overrides"]["robot.forearm"]) for r in rows] == [("0", "ok", "0.35"),
                                                                                        ("1", "ok", "0.4")]
    csv = (sweep / "summary.csv").read_text().splitlines()
    assert len(csv) == 3 and csv[1].startswith("0,run,ok,") and csv[2].startswith("1,run,ok,")
    assert rows[0]["metrics"]["workspace/count"] < rows[1]["metrics"]["workspace/count"] == 79
    assert "sweep summary" in out


# -- (c) shards merged exactly, and the CPUs of the job reach JAX, XLA and Numba ---------------------------
@pytest.mark.slow
def test_sharded_grid_merges_to_single_run_and_cpus_reach_the_worker(cluster, started):
    tmp = cluster["tmp"]
    single, sweep = tmp / "single", tmp / "shards"
    _finish(started["shards"], "sharded sweep")
    _finish(started["single"], "single run")
    merged = sweep / "merged" / "workspace_grid" / "results.h5"
    _assert_identical(merged, single / "results.h5")
    with h5py.File(merged, "r") as f:
        assert f.attrs["merged_n_shards"] == 3
    for s in ("0", "1", "2"):
        job = _job(sweep / s)
        assert job["SLURM_CPUS_PER_TASK"] == "2"
        rec = _slurm_record(cluster, job["SLURM_JOB_ID"])
        assert rec["JobState"] == "COMPLETED" and "cpu=2," in rec["Tres"] and "mem=2G" in rec["Tres"]
        with h5py.File(sweep / s / "results.h5", "r") as f:
            env = json.loads(f.attrs["worker_env"])
            device = str(f.attrs["device"])
        # SLURM_CPUS_PER_TASK=2 -> 2 XLA threads and 2 Numba threads in the job's process; 2 JAX host devices as
        # asked (the default is one: tests/test_sweeps.py), the merge bit-identical to the single run's one device
        assert env["cpus_from"] == "SLURM_CPUS_PER_TASK" and env["cpus"] == 2
        assert env["PJRT_NPROC"] == "2" and env["host_devices"] == 2 and env["numba_threads"] == 2
        assert device.endswith(" x2"), device
    rows = _rows(sweep)
    assert [(r["kind"], r["status"]) for r in rows] == [("run", "ok")] * 3 + [("merged", "ok")]


# -- (d) a failing sweep point --------------------------------------------------------------------------
@pytest.mark.slow
def test_failed_point_is_reported_others_merge_and_merge_cli_recovers(cluster, started):
    sweep = cluster["tmp"] / "failing"
    out = _finish(started["failing"], "failing sweep", ok=False)
    assert "forearm must be > 0 m, got -1.0" in out
    rows = _rows(sweep)  # written although Hydra raised (SweepSummary's exit hook)
    status = {r["run"]: r["status"] for r in rows}
    assert status["0"] == status["1"] == "ok"
    for r in ("2", "3"):
        assert status[r].startswith("failed: ConfigError: robot.forearm must be > 0 m, got -1.0 m"), status[r]
    merged = sweep / "merged" / "robot.forearm=0.4" / "results.h5"
    assert status["merged/robot.forearm=0.4"] == "ok" and len(rows) == 5
    before = {k: v.data for k, v in read(merged).variables["workspace"].items()}
    csv_before = (sweep / "summary.csv").read_text()
    assert "failed: ConfigError" in csv_before
    # as if the submitting process had died before its summary: the merge command rebuilds both
    shutil.rmtree(sweep / "merged")
    for f in ("summary.csv", "summary.json"):
        (sweep / f).unlink()
    res = subprocess.run([sys.executable, "-m", "deltajax.merge", str(sweep)], cwd=cluster["tmp"], env=cluster["env"],
                         capture_output=True, text=True, timeout=TIMEOUT)
    assert res.returncode == 0, res.stderr
    assert f"merged -> {merged}" in res.stdout
    after = {k: v.data for k, v in read(merged).variables["workspace"].items()}
    assert before.keys() == after.keys()
    assert all(np.array_equal(before[k], after[k], equal_nan=before[k].dtype.kind == "f") for k in before)
    assert (sweep / "summary.csv").read_text() == csv_before


# -- (e) mem_gb is enforced by SLURM --------------------------------------------------------------------
@pytest.mark.slow
def test_mem_gb_is_enforced_and_reported(cluster, started):
    """A point that needs more than mem_gb (a 2.5 mm grid, 24.8e6 points, storing 5 index fields: ~1.0 GB of
    arrays allocated up front, ~1.4 GB with the interpreter) is killed by SLURM (OverMemoryKill: the step's RSS
    is polled every second); the other point completes."""
    sweep = cluster["tmp"] / "memory"
    out = _finish(started["memory"], "memory sweep", ok=False)
    status = {r["run"]: r["status"] for r in _rows(sweep)}
    assert status["0"] == "ok"
    # OverMemoryKill (.ci/slurm-up's default) or the cgroup OOM killer (DELTAJAX_SLURM_CGROUP=1)
    assert re.match(r"killed: slurmstepd\S*: error: (StepId=\S+ exceeded memory limit \(\d+ > 1073741824\), being "
                    r"killed|Detected \d+ oom-kill event)", status["1"]), status["1"]
    job = _job(sweep / "1")
    rec = _slurm_record(cluster, job["SLURM_JOB_ID"])
    assert "mem=1G" in rec["Tres"] and rec["JobState"] in ("FAILED", "OUT_OF_MEMORY", "CANCELLED"), rec
    assert "has not produced any output" in out  # submitit saw the job end without a result


# -- the summary's statuses from the jobs' own records (no cluster needed) ------------------------------------
def test_summary_status_from_job_records(tmp_path):
    """failed (the job raised), killed (SLURM's message in the job's stderr), running (no end and no trace),
    ok; the job records go to summary.json."""
    from deltajax.io import ResultsFile
    from deltajax.sweeps import summarize_sweep

    records = {
        "0": {"status": "ok"},
        "1": {"status": "failed", "error": "ConfigError: robot.forearm must be > 0 m, got -1.0 m"},
        "2": {"status": "running", "err": "slurmstepd-n1: error: *** JOB 6 ON n1 CANCELLED AT 2026-12-01T11:00:00 "
                                          "DUE TO JOB REQUEUE ***\n(an earlier run of the same job, before the offset)\n"
                                          "submitit WARNING - Bypassing signal SIGTERM\n"
                                          "slurmstepd-n1: error: *** STEP 7.0 ON n1 CANCELLED AT 2026-12-01T12:00:00 ***\n"},
        "3": {"status": "running", "err": "still computing\n"},
        "4": None,
    }
    for run, rec in records.items():
        d = tmp_path / run
        (d / ".hydra").mkdir(parents=True)
        (d / ".hydra" / "overrides.yaml").write_text(f"- seed={run}\n")
        if run == "0":
            res = ResultsFile(d / "results.h5", attrs={"experiment": "demo"})
            res.put("g", "x", 1.5, units="m")
            res.flush(final=True)
        if rec is None:
            continue
        rec = dict(rec)
        if "err" in rec:
            text = rec.pop("err")
            (d / "err.log").write_text(text)
            rec["stderr"] = str(d / "err.log")
            rec["stderr_offset"] = text.index("\n(") + 1 if "\n(" in text else 0
        (d / ".hydra" / "job_status.json").write_text(json.dumps(rec))
    rows = _rows(Path(summarize_sweep(tmp_path)["json"]).parent)
    status = {r["run"]: r["status"] for r in rows}
    assert status == {"0": "ok", "1": "failed: ConfigError: robot.forearm must be > 0 m, got -1.0 m",
                      "2": "killed: slurmstepd-n1: error: *** STEP 7.0 ON n1 CANCELLED AT 2026-12-01T12:00:00 ***",
                      "3": "running", "4": "missing"}
    assert rows[1]["job"]["status"] == "failed" and "job" not in rows[4]
    csv = (tmp_path / "summary.csv").read_text().splitlines()
    assert csv[2].startswith('1,run,"failed: ConfigError: robot.forearm must be > 0 m, got -1.0 m"')
