"""Fault injection: kills, a full disk, concurrent starts, garbage and tampered files, bad configs,
fuzzed batches. Nothing finished may be lost, nothing may come back silently wrong, and every refusal is one
line that names the path or the field and says what to do.

Fast tests run in-process (``run_experiment`` at toy sizes, library calls); the CLI kill/resume tests, the
concurrent start and the real-tmpfs ENOSPC are marked slow.
"""

import errno
import json
import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import deltajax as dj
import deltajax.io as dio
from _config_helpers import compose, validate
from deltajax.config import ConfigError
from deltajax.rundir import CheckpointError, RunDirError, claim
from deltajax.run import run_experiment

REPO = Path(__file__).resolve().parent.parent
# workspace_grid at toy size: 9 x 9 x 7 points, one x-plane per chunk, a checkpoint after every chunk
WG = ["plots=false", "progress=false", "experiment.grid.h=0.1", "experiment.grid.z=[0.0,0.6]",
      "experiment.chunk_points=63", "experiment.checkpoint_s=0", "compilation_cache=null"]


def _datasets(path):
    """{group/name: (array, attrs)} of every dataset of a results file."""
    out = {}
    with h5py.File(path, "r") as f:
        def visit(name, obj):
            if isinstance(obj, h5py.Dataset):
                data = obj.asstr()[()] if h5py.check_string_dtype(obj.dtype) is not None else obj[()]
                out[name] = (data, {k: str(v) for k, v in obj.attrs.items() if k not in ("DIMENSION_LIST",
                                                                                      "REFERENCE_LIST")})
        f.visititems(visit)
    return out


def _assert_same_results(a, b, skip=()):
    da, db = _datasets(a), _datasets(b)
    assert da.keys() == db.keys()
    for k in da:
        if k in skip:
            continue
        x, y = da[k][0], db[k][0]
        assert np.asarray(x).dtype == np.asarray(y).dtype and np.shape(x) == np.shape(y), k
        if np.asarray(x).dtype.kind == "f":
            assert np.array_equal(x, y, equal_nan=True), k
        else:
            assert np.array_equal(x, y), k
        assert da[k][1] == db[k][1], k


@pytest.fixture(scope="module")
def reference_grid(toy_run):
    """One uninterrupted toy workspace_grid run (the session's shared one: tests/toy_jobs.py, the same grid as WG)."""
    from toy_jobs import overrides

    same = {o for o in overrides("workspace_grid") if not o.startswith("compilation_cache=")}  # cache: neutral
    assert same == set(WG) - {"plots=false", "compilation_cache=null"}
    return toy_run("workspace_grid")


@pytest.fixture(scope="module")
def partial_grid(tmp_path_factory):
    """A workspace_grid run stopped after 3 x-planes (as if killed), once per module: read-only, see _partial."""
    d = tmp_path_factory.mktemp("partial_grid") / "run"
    run_experiment("workspace_grid", [*WG, "experiment.stop_after=3"], run_dir=d)
    return d


def _partial(tmp_path, partial_grid):
    """A copy of ``partial_grid`` in ``tmp_path``: a checkpoint to tamper with (one run serves the five tests)."""
    import shutil

    return Path(shutil.copytree(partial_grid, tmp_path / "run"))


# -- 1. run directories are owned ---------------------------------------------------------------------------
@pytest.mark.slow
def test_rerun_with_other_settings_is_refused_naming_them_and_touches_nothing(tmp_path, reference_grid):
    d = reference_grid.parent
    before = {p.name: p.read_bytes() for p in d.iterdir() if p.is_file() and p.name != ".deltajax.lock"}
    with pytest.raises(RunDirError, match=r"experiment\.grid\.h=0\.1 there, 0\.05 now.*fresh=true"):
        run_experiment("workspace_grid", [*WG, "experiment.grid.h=0.05"], run_dir=d)
    with pytest.raises(RunDirError, match=r"holds a 'workspace_grid' run, not 'reconfig_workspace'"):
        run_experiment("reconfig_workspace", ["experiment.h=0.1", "plots=false", "progress=false"], run_dir=d)
    with pytest.raises(RunDirError, match=r"robot\.forearm=0\.4 there, 0\.45 now"):
        run_experiment("workspace_grid", [*WG, "robot.forearm=0.45"], run_dir=d)
    after = {p.name: p.read_bytes() for p in d.iterdir() if p.is_file() and p.name != ".deltajax.lock"}
    assert after == before
    # the same job and config: complete, nothing to do (settings that do not change the numbers may differ)
    run_experiment("workspace_grid", [*WG, "plots=true", "experiment.checkpoint_s=5"], run_dir=d)
    assert {p.name: p.read_bytes() for p in d.iterdir() if p.is_file() and p.name != ".deltajax.lock"} == before


@pytest.mark.slow
def test_fresh_true_is_the_explicit_way_to_start_over(tmp_path):
    d = tmp_path / "run"
    run_experiment("workspace_grid", WG, run_dir=d)
    path = run_experiment("workspace_grid", [*WG, "experiment.grid.h=0.05", "fresh=true"], run_dir=d)
    assert json.loads((d / "deltajax_run.json").read_text())["config"]["experiment"]["grid"]["h"] == 0.05
    assert dio.load(path)["workspace"]["reachable"].shape == (17, 17, 13)


@pytest.mark.slow
def test_results_without_a_manifest_are_not_overwritten(tmp_path, reference_grid):
    d = tmp_path / "run"
    d.mkdir()
    foreign = d / "results.h5"
    foreign.write_bytes(reference_grid.read_bytes())
    with pytest.raises(RunDirError, match="results.h5 but no deltajax_run.json"):
        run_experiment("workspace_grid", WG, run_dir=d)
    assert foreign.read_bytes() == reference_grid.read_bytes()
    (d / "deltajax_run.json").write_text("{not json")
    with pytest.raises(RunDirError, match="unreadable"):
        run_experiment("workspace_grid", WG, run_dir=d)


def test_second_process_in_a_run_directory_is_refused(tmp_path):
    with claim(tmp_path, "workspace_grid", {"a": 1}):
        with pytest.raises(RunDirError, match=f"in use by another deltajax run \\(pid {os.getpid()}\\)"):
            claim(tmp_path, "workspace_grid", {"a": 1})
    with claim(tmp_path, "workspace_grid", {"a": 1}) as again:  # released: claimable again, same job resumes
        assert again.state == "resume"


@pytest.mark.slow
def test_refused_cli_rerun_keeps_hydra_files(tmp_path):
    """Through the CLI: a rerun with another config is refused before .hydra/ is written."""
    d = tmp_path / "run"
    ok = _cli("experiment=workspace_grid", *WG, f"hydra.run.dir={d}")
    assert ok.returncode == 0, ok.stderr[-2000:]
    hydra_cfg = (d / ".hydra" / "config.yaml").read_bytes()
    bad = _cli("experiment=workspace_grid", *WG, "experiment.grid.h=0.05", f"hydra.run.dir={d}")
    assert bad.returncode != 0 and "experiment.grid.h=0.1 there, 0.05 now" in bad.stderr
    assert (d / ".hydra" / "config.yaml").read_bytes() == hydra_cfg
    again = _cli("experiment=workspace_grid", *WG, f"hydra.run.dir={d}")
    assert again.returncode == 0 and "nothing to do" in again.stdout


# -- 2. checkpoints: damaged or tampered files are refused -------------------------------------------------------
@pytest.mark.slow
def test_unreadable_results_file_is_refused_on_resume(tmp_path, partial_grid):
    d = _partial(tmp_path, partial_grid)
    (d / "results.h5").write_bytes(b"garbage" * 100)
    with pytest.raises(RunDirError, match=r"cannot resume: .*results\.h5 is not a readable HDF5 file.*fresh=true"):
        run_experiment("workspace_grid", WG, run_dir=d)
    assert (d / "results.h5").read_bytes() == b"garbage" * 100


@pytest.mark.parametrize("tamper, message", [
    ("planes_done", "attribute 'planes_done' does not match its checksum"),
    ("flip_plane", "workspace/reachable does not match its checksum"),
    ("flip_value", "workspace/k_tilde does not match its checksum"),
    ("count", "workspace/plane_count does not match its checksum"),
])
def test_tampered_checkpoint_is_refused(tmp_path, partial_grid, tamper, message):
    d = _partial(tmp_path, partial_grid)
    with h5py.File(d / "results.h5", "r+") as f:
        g = f["workspace"]
        if tamper == "planes_done":
            g.attrs["planes_done"] = 1_000_000
        elif tamper == "flip_plane":
            g["reachable"][1] = 1 - g["reachable"][1]
        elif tamper == "flip_value":
            v = g["k_tilde"][()]
            i = np.flatnonzero(np.isfinite(v))[0]
            v.flat[i] *= 1.5
            g["k_tilde"][()] = v
        else:
            g["plane_count"][0] += 1
    with pytest.raises(CheckpointError, match=message + ".*fresh=true"):
        run_experiment("workspace_grid", WG, run_dir=d)


def test_driver_checkpoint_damage_is_refused(tmp_path):
    """The memory-mapped chunk checkpoints of reconfig_workspace / reconfig_indices (workspace/driver.py)."""
    from deltajax.workspace.driver import CheckpointMismatch, run_chunks

    def compute(a, b):
        return {"v": np.arange(a, b, dtype=np.float64) ** 0.5}

    ck = tmp_path / "ck"
    _, complete = run_chunks(100, 10, compute, {"v": (np.float64, np.nan)}, checkpoint_dir=ck, max_chunks=4)
    assert not complete
    v = np.load(ck / "v.npy", mmap_mode="r+")
    v[15] += 1e-12  # one flipped value in a finished chunk
    v.flush()
    del v
    with pytest.raises(CheckpointMismatch, match=r"chunk 1 \(items 10:20\) does not match its checksum"):
        run_chunks(100, 10, compute, {"v": (np.float64, np.nan)}, checkpoint_dir=ck)
    (ck / "state.json").write_text("{garbage")
    with pytest.raises(CheckpointMismatch, match="state.json unreadable.*delete that directory"):
        run_chunks(100, 10, compute, {"v": (np.float64, np.nan)}, checkpoint_dir=ck)
    state = {"fingerprint": "x", "done_chunks": 10 ** 6, "n_chunks": 10, "chunk_sha256": []}
    (ck / "state.json").write_text(json.dumps(state))
    with pytest.raises(CheckpointMismatch):
        run_chunks(100, 10, compute, {"v": (np.float64, np.nan)}, checkpoint_dir=ck)
    # an intact checkpoint resumes bit-identically
    ck2 = tmp_path / "ck2"
    run_chunks(100, 10, compute, {"v": (np.float64, np.nan)}, checkpoint_dir=ck2, max_chunks=4)
    out, complete = run_chunks(100, 10, compute, {"v": (np.float64, np.nan)}, checkpoint_dir=ck2)
    assert complete and np.array_equal(out["v"], np.arange(100.0) ** 0.5)


# -- 3. a full disk ends the run cleanly --------------------------------------------------------------------------
@pytest.mark.slow
def test_enospc_at_a_checkpoint_keeps_the_last_one_and_resume_finishes(tmp_path, monkeypatch, reference_grid):
    real = dio._write_all
    calls = {"n": 0}

    def full_disk(fd, data):
        calls["n"] += 1
        if calls["n"] == 4:  # the 3rd checkpoint (the manifest is the 1st write): half written, then no space
            os.write(fd, bytes(data)[: len(data) // 2])
            raise OSError(errno.ENOSPC, "No space left on device")
        real(fd, data)

    d = tmp_path / "run"
    monkeypatch.setattr(dio, "_write_all", full_disk)
    with pytest.raises(dio.ResultsWriteError) as err:
        run_experiment("workspace_grid", WG, run_dir=d)
    msg = str(err.value)
    assert "no space left on device" in msg and "previous results.h5 there is intact" in msg
    assert "rerun the same command to resume" in msg and "\n" not in msg
    assert not list(d.glob(".results.h5.*.tmp")) and not list(d.glob("*.tmp"))
    assert dio.load(d / "results.h5")["workspace"]["attrs"]["planes_done"] == 2  # the last good checkpoint
    monkeypatch.setattr(dio, "_write_all", real)
    _assert_same_results(run_experiment("workspace_grid", WG, run_dir=d), reference_grid)


@pytest.mark.slow
def test_results_are_written_before_plots(tmp_path, monkeypatch, reference_grid):
    """The disk fills while the figures are written: results.h5 is already final; a rerun writes the plots."""
    real = dio._write_all

    def full_at_png(fd, data):
        if bytes(data[:4]) == b"\x89PNG":
            raise OSError(errno.ENOSPC, "No space left on device")
        real(fd, data)

    d = tmp_path / "run"
    monkeypatch.setattr(dio, "_write_all", full_at_png)
    with pytest.raises(dio.ResultsWriteError, match="workspace_grid.png.*no space left on device"):
        run_experiment("workspace_grid", [*WG, "plots=true"], run_dir=d)
    assert "end_time" in dio.load(d / "results.h5")["attrs"]
    _assert_same_results(d / "results.h5", reference_grid)
    assert not (d / "workspace_grid.png").exists()
    monkeypatch.setattr(dio, "_write_all", real)
    run_experiment("workspace_grid", [*WG, "plots=true"], run_dir=d)  # not complete yet: resumes, plots
    assert (d / "workspace_grid.png").stat().st_size > 1000
    assert json.loads((d / "deltajax_run.json").read_text())["status"] == "complete"


def test_enospc_on_the_first_write_says_nothing_was_written(tmp_path, monkeypatch):
    def full_disk(fd, data):
        raise OSError(errno.ENOSPC, "No space left on device")

    res = dio.ResultsFile(tmp_path / "results.h5")
    res.put("ga", "x", np.arange(3.0), units="1")
    monkeypatch.setattr(dio, "_write_all", full_disk)
    with pytest.raises(dio.ResultsWriteError, match="no space left on device; nothing was written"):
        res.flush()
    assert list(tmp_path.iterdir()) == []


def test_checksums_round_trip_and_catch_a_flip(tmp_path):
    res = dio.ResultsFile(tmp_path / "r.h5")
    res.put("g", "a", np.linspace(0, 1, 7), units="1")
    res.put("g", "s", np.array(["x", "yz"], dtype=object), units="1")
    res.flush()
    with h5py.File(tmp_path / "r.h5", "r+") as f:
        np.testing.assert_array_equal(dio.read_checked(f["g/a"]), np.linspace(0, 1, 7))
        dio.read_checked(f["g/s"])
        f["g/a"][3] = 0.25
        with pytest.raises(dio.ChecksumError, match="g/a does not match its checksum"):
            dio.read_checked(f["g/a"])


@pytest.mark.slow
def test_real_full_disk_exits_cleanly_without_segfault(tmp_path):
    """A 256 KiB tmpfs (needs root; the compressed results are ~0.4 MB): the run fails with the one-line message,
    exit 1, no exit 139, no temp file."""
    mnt = tmp_path / "tiny"
    mnt.mkdir()
    if os.geteuid() != 0 or subprocess.run(["mount", "-t", "tmpfs", "-o", "size=256k", "tmpfs", str(mnt)],
                                           capture_output=True).returncode != 0:
        pytest.skip("cannot mount a tmpfs here")
    try:
        out = _cli("experiment=workspace_grid", "plots=false", "progress=false", "compilation_cache=null",
                   "experiment.grid.h=0.01", "experiment.grid.z=[0.0,0.59]", "experiment.chunk_points=60000",
                   "experiment.checkpoint_s=0", f"hydra.run.dir={mnt / 'run'}")
        assert out.returncode == 1, (out.returncode, out.stderr[-2000:])
        assert "no space left on device" in out.stderr and "rerun the same command to resume" in out.stderr
        assert not [p for p in (mnt / "run").iterdir() if p.name.endswith(".tmp")]
    finally:
        subprocess.run(["umount", str(mnt)], capture_output=True)


# -- 4. SIGKILL at random moments: resume is bit-identical -------------------------------------------------------
def _cli(*args, timeout=300):
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    return subprocess.run([sys.executable, "-m", "deltajax.run", *args], cwd=REPO, env=env, capture_output=True,
                          text=True, timeout=timeout)


def _progress(run_dir):
    """What a killed run had finished: x-planes of workspace_grid, or chunks of reconfig_indices' checkpoints."""
    run_dir = Path(run_dir)
    states = sorted(run_dir.glob("checkpoint/*/state.json"))
    if states:
        return tuple(json.loads(p.read_text())["done_chunks"] for p in states)
    if (run_dir / "results.h5").exists():
        with h5py.File(run_dir / "results.h5", "r") as f:
            done = f["workspace"].attrs.get("planes_done") if "workspace" in f else None
        # a finished reconfig_indices run has no checkpoint left (removed once complete) and no planes_done
        return () if done is None else (int(done),)
    return ()


#: per CLI run of the kill/resume tests: seconds on a quiet machine, but the first run in a fresh checkout compiles
#: the Numba kernels (~140 CPU-s), which under load took over the 300 s that _cli allows by default
KILL_WAIT_S = 900


def _kill_then_finish(args, run_dir, seed, targets):
    """Start the CLI and SIGKILL it at a seeded random moment once its checkpoint has reached each of
    ``targets`` (finished x-planes or chunks; plus a random 0-0.2 s so the kill lands anywhere inside the next
    chunk or flush), then run it to completion. Returns the progress seen after each kill."""
    rng = random.Random(seed)
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    seen = []
    for target in targets:
        p = subprocess.Popen([sys.executable, "-m", "deltajax.run", *args, f"hydra.run.dir={run_dir}"], cwd=REPO,
                             env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        # wait for the target, or fail saying so: a 240 s cap used to SIGKILL a slow run (heavy load, cold
        # caches) wherever it was, e.g. before the RDR stage, and the test then failed on its kill count
        t0 = time.monotonic()
        while p.poll() is None:
            try:
                if sum(_progress(run_dir)) >= target:
                    break
            except (OSError, KeyError, ValueError):  # a file being replaced right now: look again
                pass
            if time.monotonic() - t0 > KILL_WAIT_S:
                p.kill()
                p.wait()
                pytest.fail(f"{args[0]} did not reach {target} chunks/planes in {KILL_WAIT_S} s (progress "
                            f"{_progress(run_dir)}, load {os.getloadavg()}); kills so far {seen}")
            time.sleep(0.01)
        time.sleep(rng.uniform(0.0, 0.2))
        if p.poll() is None:
            p.send_signal(signal.SIGKILL)
        p.wait()
        assert p.returncode in (0, -signal.SIGKILL), p.returncode
        seen.append(_progress(run_dir))
        if p.returncode == 0:
            break
    out = _cli(*args, f"hydra.run.dir={run_dir}", timeout=KILL_WAIT_S)
    assert out.returncode == 0, out.stderr[-3000:]
    assert not list(Path(run_dir).glob("*.tmp")) and not list(Path(run_dir).glob(".*.tmp"))
    return seen


WG_KILL = ["experiment=workspace_grid", "plots=false", "progress=false", "experiment.grid.h=0.02",
           "experiment.grid.z=[0.0,0.6]", "experiment.chunk_points=1271", "experiment.checkpoint_s=0"]


@pytest.mark.slow
def test_workspace_grid_killed_at_random_moments_resumes_bit_identically(tmp_path):
    ref = _cli(*WG_KILL, f"hydra.run.dir={tmp_path / 'ref'}", timeout=KILL_WAIT_S)
    assert ref.returncode == 0, ref.stderr[-3000:]
    rng = random.Random(11)
    seen = _kill_then_finish(WG_KILL, tmp_path / "killed", seed=11, targets=sorted(rng.sample(range(1, 30), 3)))
    assert sum(0 < s[0] < 41 for s in seen if s) >= 2, seen  # kills inside the grid (41 x-planes)
    _assert_same_results(tmp_path / "killed" / "results.h5", tmp_path / "ref" / "results.h5")


RI_KILL = ["experiment=reconfig_indices", "plots=false", "progress=false", "experiment.h=0.025",
           "experiment.chunk_points=16", "experiment.slices_z=[0.4]"]


@pytest.mark.slow
def test_reconfig_indices_killed_at_random_moments_resumes_bit_identically(tmp_path):
    ref = _cli(*RI_KILL, f"hydra.run.dir={tmp_path / 'ref'}", timeout=KILL_WAIT_S)
    assert ref.returncode == 0, ref.stderr[-3000:]
    rng = random.Random(5)  # progress = ODR chunks + RDR chunks (~500 of 16 points): small chunks, so that the
    # kills land inside the RDR stage even on a quiet machine (its checkpoint exists only until the run completes)
    seen = _kill_then_finish(RI_KILL, tmp_path / "killed", seed=5, targets=sorted(rng.sample(range(20, 300), 3)))
    assert sum(len(s) == 2 and 0 < s[1] for s in seen) >= 2, seen  # kills inside the RDR stage
    _assert_same_results(tmp_path / "killed" / "results.h5", tmp_path / "ref" / "results.h5")


@pytest.mark.slow
def test_concurrent_starts_one_runs_the_other_is_refused(tmp_path):
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    cmd = [sys.executable, "-m", "deltajax.run", "experiment=workspace_grid", *WG, f"hydra.run.dir={tmp_path}"]
    procs = [subprocess.Popen(cmd, cwd=REPO, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for _ in range(2)]
    outs = [p.communicate(timeout=300) for p in procs]
    codes = sorted(p.returncode for p in procs)
    texts = [o[0] + o[1] for o in outs]
    # either one held the lock while the other tried (refused), or they ran one after the other (no-op)
    assert codes[0] == 0, texts
    assert (codes[1] != 0 and any("in use by another deltajax run" in t for t in texts)) or \
        any("nothing to do" in t for t in texts), texts
    dio.load(tmp_path / "results.h5")


# -- 5. bad configuration values: rejected up front, naming the field -------------------------------------------


BAD = [
    ("ga_reconfig", "experiment.regular_workspace.z_max=-1",
     "experiment.regular_workspace.z_max must be > 0 m, got -1.0 m"),
    ("ga_reconfig", "experiment.pareto.ref_min_factor=nan", "experiment.pareto.ref_min_factor must be a finite number"),
    ("ga_reconfig", "experiment.motor.rated_torque=nan", "experiment.motor.rated_torque must be a finite number"),
    ("ga_reconfig", "experiment.pareto.population_size=0", "experiment.pareto.population_size must be >= 4, got 0"),
    ("ga_reconfig", "experiment.verify.task_n_r=0", "experiment.verify.task_n_r must be >= 1, got 0"),
    ("ga_reconfig", "experiment.task.n_phi=1", "experiment.task.n_phi must be >= 2, got 1"),   # both wedge ends
    ("ga_reconfig", "experiment.verify.task_n_phi=1", "experiment.verify.task_n_phi must be >= 2, got 1"),
    ("ga_reconfig", "experiment.ga.sigma=inf", r"experiment.ga.sigma \(gene units, genes in \[0,1\]\) must be in"),
    ("ga_reconfig", "+experiment.foo=1", r"experiment.foo is not a setting of experiment; valid keys: constraints, "),
    ("reconfig_indices", "robot.R_range.max=10", r"robot.R_range.max=10.0 m: at R = 10 m the geometry can reach nothing"),
    ("ga_reconfig", "robot.forearm=0.35", r"robot.R_range.max=0.495 m: at R = 0.495 m the geometry can reach nothing"),
    ("workspace_grid", "experiment.checkpoint_s=-1", "experiment.checkpoint_s must be >= 0 s, got -1.0 s"),
    ("workspace_grid", "experiment.grid.h=0", "experiment.grid.h must be > 0 m, got 0.0 m"),
    ("workspace_grid", "experiment.beta=1.5", r"experiment.beta must be in \(0, 1\), got 1.5"),
    ("workspace_grid", "experiment.store=[k_tild]", "experiment.store entry must be one of"),
    ("workspace_grid", "n_shards=0", "n_shards must be >= 1, got 0"),
    ("workspace_grid", "+robot.forarm=0.4", r"robot.forarm is not a setting of robot; valid keys: R_range, base_radius,"),
    ("workspace_grid", "+experiment.grid.hh=1", r"experiment.grid.hh is not a setting of experiment.grid; valid"),
    ("workspace_grid", "+foo=1", r"unknown top-level key\(s\) foo; valid keys: robot, experiment,"),
    ("reconfig_indices", "beta=nan", "beta must be a finite number, got nan"),
    ("reconfig_indices", "experiment.mode=slow", "experiment.mode must be one of"),
    ("dynamics_cycle", "experiment.n_samples=1", "experiment.n_samples must be >= 11, got 1"),
    ("boundary_search", "experiment.eps=nan", "experiment.eps must be a finite number"),
]


@pytest.mark.parametrize("experiment, override, message", BAD, ids=[b[1] for b in BAD])
def test_bad_config_is_rejected_before_anything_runs(experiment, override, message):
    with pytest.raises(ConfigError, match=message):
        validate(compose(experiment, override))


@pytest.mark.parametrize("override, key", [("experiment.checkpoint_s=abc", "experiment.checkpoint_s"),
                                           ("robot.forarm=0.4", "robot.forarm"),
                                           ("experiment.grid.hh=1", "experiment.grid.hh"),
                                           ("experiment.chunk_points=1.5", "experiment.chunk_points")])
def test_schema_rejects_wrong_types_and_mistyped_keys_at_composition(override, key):
    from hydra.errors import ConfigCompositionException

    with pytest.raises(ConfigCompositionException) as err:
        compose("workspace_grid", override)
    assert key in str(err.value) + str(err.value.__cause__)


def test_valid_keys_for_composition_errors():
    from deltajax.config import valid_keys

    assert "forearm" in valid_keys("robot.forarm") and "step" in valid_keys("robot.R_range.stp")
    assert "h" in valid_keys("experiment.grid.hh", "workspace_grid")
    assert "ref_min_factor" in valid_keys("experiment.pareto.ref_max", "ga_reconfig")   # its generated schema's
    assert "seed" in valid_keys("sed") and valid_keys("experiment.x", "no_such_job") is None


@pytest.mark.slow
def test_every_experiment_composes_and_validates_at_its_defaults():
    for name in ("workspace_grid", "reconfig_workspace", "reconfig_indices", "indices_examples", "bench_kernel",
                 "dynamics_cycle", "boundary_search", "ga_reconfig"):
        validate(compose(name))
    validate(compose("workspace_grid", "robot=industrial"))
    validate(compose("workspace_grid", "robot.forearm=0.35"))  # the R range is not used by this job


def test_rejected_config_leaves_the_run_directory_untouched(tmp_path):
    with pytest.raises(ConfigError):
        run_experiment("workspace_grid", [*WG, "experiment.checkpoint_s=-1"], run_dir=tmp_path / "run")
    assert not (tmp_path / "run").exists()


def test_reconfigurable_at_rejects_invalid_concrete_R():
    rec = dj.presets.franco2026()
    for R in (-0.2, 0.0, float("nan"), float("inf")):
        with pytest.raises(dj.GeometryError, match="R must be"):
            rec.at(R)
    assert float(rec.at(0.3).base_radius) == 0.3
    # traced R is not checked (failure is data inside batches)
    jax.vmap(lambda R: rec.at(R).base_radius)(jnp.array([-0.2, 0.3]))


# -- 6. truncated results ------------------------------------------------------------------------------------
@pytest.mark.slow
def test_grid_touching_the_box_is_flagged_and_the_reach_box_holds_everything(tmp_path):
    cut = run_experiment("workspace_grid", [*WG, "robot.forearm=0.5", "experiment.grid.h=0.05"],
                         run_dir=tmp_path / "cut")
    full = run_experiment("workspace_grid", [*WG, "robot.forearm=0.5", "experiment.grid.h=0.05",
                                             "experiment.grid.x=null", "experiment.grid.y=null",
                                             "experiment.grid.z=null", "experiment.grid.bounds=null"],
                          run_dir=tmp_path / "full")
    c, f = dio.load(cut)["workspace"], dio.load(full)["workspace"]
    assert c["truncated"] == 1 and c["face_count"] > 0
    assert f["truncated"] == 0 and f["face_count"] == 0 and f["count"] > c["count"]
    from deltajax.workspace.driver import face_count

    assert face_count(c["reachable"]) == c["face_count"]
    with pytest.raises(ConfigError, match="bounds must be null when the grid is sized from the reach bound"):
        run_experiment("workspace_grid", [*WG, "experiment.grid.x=null"], run_dir=tmp_path / "bad")


@pytest.mark.slow
def test_reach_box_contains_every_reachable_point():
    from deltajax.workspace import make_grid, reachable_mask
    from deltajax.workspace.driver import reach_box

    for robot in (dj.presets.franco2026().robot, dj.Delta.from_degrees(base_radius=0.2, platform_radius=0.05,
                                                                        upper_arm=0.3, forearm=0.5)):
        box = reach_box(robot)
        big = make_grid((-1.0, 1.0), (-1.0, 1.0), (-1.0, 1.0), 0.04)
        ok = np.asarray(reachable_mask(robot, jnp.asarray(big.points()))).reshape(big.shape)
        pts = big.points()[ok.reshape(-1)]
        assert len(pts) > 0
        for i in range(3):
            assert box[i][0] <= pts[:, i].min() and pts[:, i].max() <= box[i][1], (i, box[i])


# -- 7. fuzzed batches with invalid designs through the public API ----------------------------------------------
_ik_batch = jax.jit(jax.vmap(dj.ik, in_axes=(None, 0)))


@settings(max_examples=10, deadline=None)
@given(st.lists(st.tuples(*[st.one_of(st.floats(-2, 2), st.sampled_from([np.nan, np.inf, -np.inf, 1e300]))] * 3),
                min_size=1, max_size=16))
@pytest.mark.slow
def test_fuzzed_points_never_raise_and_non_finite_points_are_not_ok(points):
    robot = dj.presets.franco2026().robot
    p = jnp.asarray(np.array(points, dtype=np.float64))
    sol = _ik_batch(robot, p)
    ok = np.asarray(sol.ok)
    assert ok.shape[0] == len(points)
    finite = np.all(np.isfinite(np.asarray(p)), axis=1)
    assert not ok[~finite].any()
    theta = np.asarray(sol.theta)
    assert np.all(np.isfinite(theta[ok]))


@settings(max_examples=8, deadline=None)
@given(st.lists(st.tuples(st.floats(-1, 1), st.floats(-0.5, 1), st.floats(-1, 1), st.floats(-1, 1)),
                min_size=1, max_size=8))
@pytest.mark.slow
def test_fuzzed_designs_in_a_batch_never_raise(designs):
    """Designs with negative or zero lengths inside a vmapped batch: no exception, shapes kept (whether such
    designs come back ok=False is the core's item 7, asserted there)."""
    d = np.array(designs, dtype=np.float64)

    def one(R, r, L1, L2):  # traced values: the constructor's concrete checks do not apply inside the batch
        robot = dj.Delta(base_radius=R, platform_radius=r, upper_arm=L1, forearm=L2)
        return dj.ik(robot, jnp.array([0.0, 0.0, 0.4])).ok

    ok = jax.jit(jax.vmap(one))(*(jnp.asarray(d[:, i]) for i in range(4)))
    assert ok.shape[0] == len(designs) and ok.dtype == jnp.bool_
