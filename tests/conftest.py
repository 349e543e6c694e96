"""Strict, fast test settings shared by every test file (STYLE §9), and the session's shared toy job runs.

Tiers: ``python -m pytest`` runs everything; ``python -m pytest -m "not slow"`` skips tests marked
``@pytest.mark.slow`` (each over ~1 s on 2 cores).
"""

import contextlib
import fcntl
import hashlib
import os
import subprocess
import sys
from pathlib import Path

os.environ.setdefault("XLA_PYTHON_CLIENT_PREALLOCATE", "false")

import jax  # noqa: E402
import pytest  # noqa: E402

jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_rank_promotion", "raise")
# Compilation dominates the suite's CPU time: the persistent XLA cache that the CLI uses by default
# (configs/config.yaml compilation_cache) also serves the tests, in-process and in CLI subprocesses, so a rerun
# compiles only what changed. Cached executables are keyed by the HLO, JAX version and flags, never stale;
# DELTAJAX_TEST_JAX_CACHE=<dir> picks another folder (an empty one measures a cold start).
from toy_jobs import JAX_CACHE, JAX_CACHE_MIN_S  # noqa: E402
jax.config.update("jax_compilation_cache_dir", JAX_CACHE)
jax.config.update("jax_persistent_cache_min_compile_time_secs", JAX_CACHE_MIN_S)
# every CLI run the tests start (toy runs, SLURM and joblib sweep jobs, kill/resume, the wheel's CLI) inherits
# it: configs/config.yaml's compilation_cache reads DELTAJAX_JAX_CACHE, so the subprocesses reuse the programs the
# session (and earlier sessions) compiled, and a cold measurement (an empty DELTAJAX_TEST_JAX_CACHE) is cold
os.environ["DELTAJAX_JAX_CACHE"] = JAX_CACHE
# ... and the tests' threshold too (JAX's own variable, which deltajax.run leaves alone when it is set; the CLI's
# default is 1 s): a toy CLI run compiles many programs under 1 s, and each CLI process compiled them again.
# A warm toy ga_reconfig CLI run (screen, Pareto, refine off: the SLURM test's job): 45.0, 39.7 -> 36.9, 38.4
# CPU-s (load 3-4, 2026-12-02)
os.environ["JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"] = str(JAX_CACHE_MIN_S)
# the CLI worker's vector width (512 bits where the CPU has AVX-512: deltajax.sweeps.worker.wide_vectors) for the
# tests' own programs and, through XLA_FLAGS, every CLI run they start: one width, one set of compiled programs
from deltajax.sweeps.worker import wide_vectors  # noqa: E402
wide_vectors()

from hypothesis import settings  # noqa: E402

settings.register_profile("deltajax", deadline=None, max_examples=25, derandomize=True)
settings.load_profile("deltajax")

REPO = Path(__file__).resolve().parent.parent


def _shared_root(tmp_path_factory) -> Path:
    """The session's folder for shared toy runs: under pytest-xdist (``-n 2``, README) the workers' common parent
    of their own base temp folders, so a job at one setting runs once per session, not once per worker."""
    base = tmp_path_factory.getbasetemp()
    root = (base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base) / "toy_runs"
    root.mkdir(parents=True, exist_ok=True)
    return root


@contextlib.contextmanager
def _locked(path: Path):
    """An exclusive lock on ``path`` (fcntl.flock) across the xdist workers of the session."""
    with open(path, "a") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


@pytest.fixture(scope="session")
def toy_run(tmp_path_factory):
    """``toy_run(name, *extra) -> Path`` of results.h5: the job ``name`` at its toy size (tests/toy_jobs.py) plus
    ``extra`` overrides, run once per session and shared (also across pytest-xdist workers: the first worker to
    ask runs it under a file lock, the others wait for it and read the same file). Treat the run directory as
    read-only (a rerun into it with the same settings is a no-op; anything that writes must use its own
    ``tmp_path``)."""
    from toy_jobs import CLI, overrides

    root = _shared_root(tmp_path_factory)
    runs = {}

    def run(name, *extra):
        key = (name, extra)
        if isinstance(runs.get(key), BaseException):  # failed once: the same error for every test that needs it
            raise runs[key]
        if key not in runs:
            from deltajax.run import list_experiments

            if name not in list_experiments():
                pytest.skip(f"experiment {name} is not in this checkout")
            tag = hashlib.sha1(repr(key).encode()).hexdigest()[:10]
            d = root / f"{name}-{tag}"
            with _locked(root / f"{name}-{tag}.lock"):
                failed = d / "FAILED.txt"
                if failed.exists():  # another worker's run of the same settings failed: the same error here
                    runs[key] = RuntimeError(f"toy run {name} {list(extra)} failed in another worker:\n"
                                             + failed.read_text())
                    raise runs[key]
                done = d / "DONE"
                if done.exists():  # another worker ran it: its file, untouched
                    runs[key] = d / "run" / "results.h5"
                    return runs[key]
                try:
                    runs[key] = _run(name, extra, d / "run")
                    done.touch()
                except Exception as e:
                    runs[key] = e
                    d.mkdir(parents=True, exist_ok=True)
                    failed.write_text(f"{type(e).__name__}: {e}"[-5000:])
                    raise
        return runs[key]

    def _run(name, extra, d):
        from deltajax.run import run_experiment

        if name in CLI:  # through the real command line: python -m deltajax.run
            env = {**os.environ, "PYTHONPATH": str(REPO)}
            out = subprocess.run([sys.executable, "-m", "deltajax.run", f"experiment={name}", *overrides(name, *extra),
                                  f"hydra.run.dir={d}"], cwd=REPO, env=env,
                                 capture_output=True, text=True, timeout=600)
            assert out.returncode == 0, out.stderr[-3000:]
            return d / "results.h5"
        try:
            return run_experiment(name, overrides(name, *extra), run_dir=d)
        finally:  # the job sets the CLI's threshold (run.CACHE_MIN_COMPILE_S) unless JAX's variable is set
            jax.config.update("jax_persistent_cache_min_compile_time_secs", JAX_CACHE_MIN_S)

    return run


# -- pytest-xdist (README: ``python -m pytest -q -n 2``, ``--dist loadgroup`` from pyproject.toml) ------------------
#: the long units of work (nodeid prefixes; a group goes where its first test goes), handed out first, longest
#: first, so that neither worker is left with one of them at the end (the rest are short and fill in around them).
#: Order from the CI durations of 2026-12-02 01:23 (warm XLA cache): the SLURM tests (one worker, ~190 s alone,
#: mostly waiting for the cluster's jobs), the main job's toy runs (GA_TOY), the R(t) job, the sweeps, the kill/resume
#: tests, the population screens, the other jobs end to end, the GPU check script, ...
LONG_FIRST = ("tests/test_slurm.py", "tests/test_ga_reconfig.py", "tests/test_operating_mode.py", "tests/test_sweeps.py",
              "tests/test_faults.py", "tests/test_ga_fitness.py", "tests/test_jobs.py", "tests/test_gpu_check.py",
              "tests/test_optimize.py", "tests/test_dynamics.py", "tests/test_kernel.py", "tests/test_packaging.py",
              "tests/test_motion.py", "tests/test_backends.py")


#: files whose tests share in-process compiles without a fixture (module-level jitted functions or lru_cache'd
#: compiled functions): one worker each, so that each is traced and compiled once per session, not once per
#: worker. test_backends' two point-kernel cases each compiled the same Numba functions (~320 s wall each, cold,
#: on both workers at once, 2026-12-01); test_ga_fitness's exact and screened population covers (per k_min)
#: serve three tests; test_kernel_blocks' two scales share one compiled singular-value tail
SAME_WORKER = ("tests/test_backends.py", "tests/test_ga_fitness.py", "tests/test_workspace_grid_jax.py",
               "tests/test_dynamics.py", "tests/test_kernel.py", "tests/test_kinematics.py",
               "tests/test_trajectory.py", "tests/test_indices.py", "tests/test_kernel_blocks.py")


#: tests that run the main job in-process on the toy size's search and verification grids (tests/toy_jobs.py), or
#: its refine descent: one worker, so that the job's compiled programs, which deltajax.optimize.workflow keeps by
#: the content of the problem, are traced and compiled once per session rather than once per worker.
#: experiments/gpu_check.py --scale 1 runs the main job at the same toy size (and its search evaluator): after the
#: toy run in the same process 27.8 CPU-s, alone 50 (2026-12-04, load 4)
GA_TOY = ("tests/test_ga_reconfig.py", "tests/test_resume_older_runs.py", "tests/test_jobs.py::test_ga_reconfig_",
          "tests/test_jobs.py::test_every_job_end_to_end_at_toy_size[ga_reconfig]",
          "tests/test_optimize.py::test_refine_designs_",
          "tests/test_results_files.py::test_xarray_opens_every_group_with_units[ga_reconfig]",
          "tests/test_gpu_check.py")


#: where the workers tell the scheduler their groups ({nodeid: group} per worker, JSON): set by the controller
_GROUPS_ENV = "DELTAJAX_TEST_XDIST_GROUPS"


def pytest_configure(config):
    """Under xdist, in the controller: a folder for the workers' groups (``_GROUPS_ENV``, inherited by the workers,
    which start after this), and the work queue in the order of the collection (``LONG_FIRST`` below), not
    xdist's default reordering of groups by their number of tests (a group of 27 quick tests is not a long one)."""
    if getattr(config.option, "numprocesses", None) and not hasattr(config, "workerinput"):
        import tempfile

        os.environ[_GROUPS_ENV] = tempfile.mkdtemp(prefix="deltajax-xdist-groups-")
        config.option.loadscopereorder = False


#: every process the session starts (xdist workers, CLI subprocesses, sweep, submitit and loky workers, SLURM jobs
#: submitted with the caller's environment) inherits this variable; a process's /proc/PID/environ is the
#: environment it was started with, so the controller itself (which sets it after its own start) does not carry it
_SESSION_ENV = "DELTAJAX_TEST_SESSION"
_SESSION_TOKEN = os.environ.setdefault(_SESSION_ENV, f"{os.getpid()}-{os.urandom(6).hex()}")
#: how long a finished session waits for the processes it started to exit before it calls them left over
LEFTOVER_GRACE_S = 15.0


def session_processes(token: str = _SESSION_TOKEN) -> dict[int, str]:
    """{pid: command line} of the running processes started by the test session ``token`` (Linux /proc)."""
    marker = f"{_SESSION_ENV}={token}".encode()
    found = {}
    for d in Path("/proc").iterdir():
        if not d.name.isdigit() or int(d.name) == os.getpid():
            continue
        try:
            if marker in (d / "environ").read_bytes().split(b"\0"):
                stat = (d / "stat").read_text()
                if stat[stat.rindex(")") + 2] == "Z":  # a zombie has ended; its parent has not reaped it yet
                    continue
                found[int(d.name)] = (d / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
        except (OSError, ValueError):  # gone meanwhile, or not ours to read
            continue
    return found


@pytest.hookimpl(hookwrapper=True, trylast=True)
def pytest_sessionfinish(session, exitstatus):
    """In the controller, after every other finish hook (pytest-xdist's shutdown of its workers included): no
    process that the session started may still be running. Leftovers are listed, killed, and fail the session."""
    yield
    if hasattr(session.config, "workerinput") or not Path("/proc/self/environ").exists():
        return
    import signal
    import time

    deadline = time.monotonic() + LEFTOVER_GRACE_S
    while (left := session_processes()) and time.monotonic() < deadline:
        time.sleep(0.5)
    if not left:
        return
    for pid in left:
        with contextlib.suppress(OSError):
            os.kill(pid, signal.SIGKILL)
    lines = "\n".join(f"  {pid}: {cmd[:200]}" for pid, cmd in sorted(left.items()))
    session.config.get_terminal_writer().line(
        f"\nthe test session left {len(left)} process(es) running {LEFTOVER_GRACE_S:.0f} s after its end (killed):\n"
        f"{lines}", red=True)
    session.exitstatus = pytest.ExitCode.TESTS_FAILED


def pytest_unconfigure(config):
    d = os.environ.get(_GROUPS_ENV)
    if d and not hasattr(config, "workerinput"):
        import shutil

        shutil.rmtree(d, ignore_errors=True)


def pytest_xdist_make_scheduler(config, log):
    """``--dist loadgroup`` with the groups this conftest assigns. pytest-xdist (3.8) groups by a ``@group``
    suffix that its worker hook writes into ``item._nodeid``; since pytest 9 ``item.nodeid`` no longer reads
    ``_nodeid``, so no group reached the scheduler and every test was its own unit (until 2026-12-02: the main
    job's toy runs, module fixtures and shared compiles ran on both workers). The workers write their groups to
    ``_GROUPS_ENV`` instead (``pytest_collection_modifyitems`` below), and this scheduler reads them."""
    if config.getvalue("dist") != "loadgroup" or not os.environ.get(_GROUPS_ENV):
        return None
    import json

    from xdist.scheduler import LoadGroupScheduling

    folder = Path(os.environ[_GROUPS_ENV])

    class Scheduling(LoadGroupScheduling):
        _groups = None

        def _split_scope(self, nodeid):
            if self._groups is None:  # read once all workers have collected (schedule() comes after that)
                self._groups = {}
                for f in sorted(folder.glob("*.json")):
                    self._groups.update(json.loads(f.read_text()))
            return self._groups.get(nodeid) or super()._split_scope(nodeid)

    return Scheduling(config, log)


@pytest.hookimpl(tryfirst=True)  # before pytest-xdist's worker hook (which reads the marks, see above)
def pytest_collection_modifyitems(config, items):
    """Under xdist: every test that uses a module- or class-scoped fixture (a shared compiled function, a
    cluster, a grid) goes to one worker with the rest of its module (``xdist_group``), so that the fixture is built
    once, not once per worker; so do the files of ``SAME_WORKER``; the main job's toy runs (``GA_TOY``) go to one
    worker together; and the long units come first (longest-first scheduling).

    Collection happens in the workers, where pytest-xdist resets ``numprocesses`` to None (and ``dist`` to "no"):
    a worker is recognised by its ``workerinput``. Until 2026-12-02 this hook asked for ``numprocesses`` and so
    did nothing in the workers. The groups go to the scheduler through a file (``pytest_xdist_make_scheduler``)."""
    if not hasattr(config, "workerinput"):
        return
    groups = {}
    for item in items:
        defs = getattr(item, "_fixtureinfo", None)
        scopes = {d.scope for fd in (defs.name2fixturedefs.values() if defs else ()) for d in fd}
        if item.nodeid.startswith(GA_TOY):
            groups[item.nodeid] = "ga_reconfig_toy"
        elif scopes & {"module", "class", "package"} or item.nodeid.startswith(SAME_WORKER):
            groups[item.nodeid] = item.nodeid.split("::")[0]
        if item.nodeid in groups:
            item.add_marker(pytest.mark.xdist_group(groups[item.nodeid]))

    def rank(item):
        slow = item.get_closest_marker("slow") is None  # within a rank, the slow tests (over ~1 s) first
        for i, prefix in enumerate(LONG_FIRST):
            if item.nodeid.startswith(prefix):
                return i, slow
        # then the other groups (a file's tests in one unit, up to ~30 s), then the single tests: the end of the
        # run is made of short units, so the two workers finish together
        return len(LONG_FIRST) + (item.nodeid not in groups), slow

    items.sort(key=rank)  # stable: otherwise the order inside each file is kept
    folder = os.environ.get(_GROUPS_ENV)
    if folder:
        import json

        name = Path(folder) / f"{config.workerinput['workerid']}.json"
        tmp = name.with_suffix(".tmp")
        tmp.write_text(json.dumps(groups))
        tmp.replace(name)
