"""The stage engine (deltajax.jobs.stages): done/skip, and the checkpoints of stages that commit part of their work
(identity: the run's fingerprint and the stage; verified; refused when another run's or damaged), on made-up
toy jobs (the real ones: test_faults.py, test_ga_reconfig.py, test_results_integrity.py)."""

from __future__ import annotations

import types

import h5py
import numpy as np
import pytest

from deltajax import io as dio
from deltajax.jobs import stages
from deltajax.jobs.stages import Runner, Stage, State, Stop, resize_bar
from deltajax.rundir import CheckpointError, RunDirError
from deltajax.workspace.chunks import run_chunks, seal

N_STEPS = 6


def _ctx(path):
    return types.SimpleNamespace(results=dio.ResultsFile(path), log=[].append, complete=True)


def _walk(st: State) -> None:
    """A stage that commits its partial work after every step: a running sum of deterministic numbers."""
    ck = st.runner.checkpoints["walk"]
    part = ck.load()
    step, acc = (0, np.zeros(4)) if part is None else part
    while step < N_STEPS:
        if st.stop_at is not None and step == st.stop_at:
            raise Stop(f"stopped at step {step}")
        acc = acc + np.sqrt(np.arange(4.0) + step)
        step += 1
        ck.commit(step, acc)
    st.acc = acc
    st.ctx.results.put("walk", "acc", acc, units="1")


def _double(st: State) -> None:
    st.ctx.results.put("double", "acc2", 2 * st.acc, units="1")


def _save(res, step, acc):
    res.put("walk/checkpoint", "acc", acc, units="1")
    res.set_attrs("walk/checkpoint", step=step)


def _read(g):
    return int(g["attrs"]["step"]), np.asarray(g["acc"])


STAGES = (Stage("walk", _walk, load=lambda st: setattr(st, "acc", np.asarray(dio.load(st.path, "walk")["acc"]))),
          Stage("double", _double))


def _job(path, fp="run-a", stop_at=None, resume="auto"):
    """One process of the made-up two-stage job: returns (finished, runner)."""
    ctx = _ctx(path)
    runner = Runner(ctx, "toy")
    runner.checkpoint("walk", "walk/checkpoint", save=_save, read=_read, what="walk checkpoint",
                      note=lambda step, acc: f"step {step}")
    runner.open(fp, resume=resume)
    ok = runner.run(STAGES, State(ctx=ctx, path=path, stop_at=stop_at))
    ctx.results.flush()
    return ok, runner


@pytest.mark.slow
def test_a_resume_reads_the_checkpoint_once(tmp_path, monkeypatch):
    # resume=must asks the checkpoint whether there is something to resume (Runner.open), then the stage loads it:
    # the verified read of the group (the GA's: its whole population and history) happens once
    part = tmp_path / "part.h5"
    assert not _job(part, stop_at=4)[0]
    reads = []
    real = dio.load          # the runner's reader (deltajax.io.load, as the stage engine names it)
    monkeypatch.setattr(stages, "load",
                        lambda path, group=None, **kw: (reads.append(group), real(path, group, **kw))[1])
    ok, runner = _job(part, resume="must")
    assert ok and reads.count("walk/checkpoint") == 1


@pytest.mark.slow
def test_stage_stopped_mid_way_resumes_from_its_checkpoint_bit_identically(tmp_path):
    ref = tmp_path / "ref.h5"
    assert _job(ref)[0]
    part = tmp_path / "part.h5"
    ok, runner = _job(part, stop_at=4)          # stopped mid-stage, after 4 committed steps
    assert not ok and runner.done == [] and not runner.ctx.complete
    assert dio.load(part, "walk/checkpoint")["attrs"]["step"] == 4
    assert dio.load(part, "walk/checkpoint")["attrs"]["fingerprint"] == "run-a"   # stamped by the runner
    ok, runner = _job(part, resume="must")      # a new process: the partial stage counts as something to resume
    assert ok and runner.done == ["walk", "double"]
    a, b = dio.load(ref), dio.load(part)
    np.testing.assert_array_equal(a["walk"]["acc"], b["walk"]["acc"])
    np.testing.assert_array_equal(a["double"]["acc2"], b["double"]["acc2"])
    with pytest.raises(RunDirError, match=r"^experiment\.resume=must but .*empty\.h5 holds no walk checkpoint$"):
        _job(tmp_path / "empty.h5", resume="must")


def test_checkpoint_of_another_run_is_refused_in_one_line(tmp_path):
    path = tmp_path / "results.h5"
    _job(path, stop_at=2)
    with pytest.raises(RunDirError, match="holds a toy run with different settings"):
        _job(path, fp="run-b")                  # the run's own fingerprint, checked when the runner opens
    # a job that records no stages: its checkpoint alone carries the run's identity
    runner = Runner(_ctx(path), "toy", resumable=False, fingerprint="run-b")
    ck = runner.checkpoint("walk", "walk/checkpoint", save=_save, read=_read, what="walk checkpoint")
    with pytest.raises(CheckpointError, match=r"^cannot resume the walk checkpoint in .*results\.h5: its "
                                              r"walk/checkpoint is not this run's walk stage \(fingerprint run-a, "
                                              r"this run's run-b.*fresh=true[^\n]*$"):
        ck.load()
    assert Runner(_ctx(path), "toy", resumable=False, fingerprint="run-a").checkpoint(
        "walk", "walk/checkpoint", save=_save, read=_read).load()[0] == 2


def test_damaged_or_malformed_checkpoint_is_refused(tmp_path):
    path = tmp_path / "results.h5"
    _job(path, stop_at=3)
    runner = Runner(_ctx(path), "toy", resumable=False, fingerprint="run-a")
    ck = runner.checkpoint("walk", "walk/checkpoint", save=_save, read=lambda g: g["attrs"]["nope"])
    with pytest.raises(CheckpointError, match=r"its walk/checkpoint is malformed \(KeyError: 'nope'\)"):
        ck.load()
    with h5py.File(path, "r+") as f:
        f["walk/checkpoint/acc"][0] += 1.0
    with pytest.raises(CheckpointError, match=r"walk/checkpoint/acc does not match its checksum.*fresh=true"):
        _job(path)


def test_chunk_checkpoint_resumes_bit_identically_and_refuses_tampering_or_another_run(tmp_path):
    """The runner's results-file store for the chunk engine (workspace_grid's), at toy size."""
    n, chunk = 10, 3

    def job(path, max_chunks=None, fp="grid-a", span=(0, n)):
        ctx = _ctx(path)
        runner = Runner(ctx, "toy", resumable=False, fingerprint=fp)
        arrays = {"a": np.full(n, np.nan), "b": np.zeros((n, 2), np.int64)}
        done = {"n": 0}

        def stage(d):
            ctx.results.put("g", "a", arrays["a"], units="1")
            ctx.results.put("g", "b", arrays["b"], units="1")
            ctx.results.set_attrs("g", done=d, resume_key=fp, shard_start=span[0], shard_stop=span[1],
                                  resume_seal=seal(fp, d, *span))

        ck = runner.chunk_checkpoint("g", "g", arrays, span=span, save=lambda res, arr, d: stage(d),
                                     check=lambda data, d: "" if np.all(data["b"][:d, 0] == np.arange(d)) else
                                     "b is not the item numbers")
        out, complete = run_chunks(n, chunk, lambda a, b: {"a": np.sqrt(np.arange(a, b)),
                                                          "b": np.stack([np.arange(a, b)] * 2, -1)},
                                   {"a": (float, None), "b": (int, None)}, checkpoint=ck, max_chunks=max_chunks,
                                   progress=lambda k: done.update(n=done["n"] + k))
        stage(done["n"])
        ctx.results.flush()
        return out, complete, done["n"]

    ref, ok, _ = job(tmp_path / "ref.h5")
    assert ok
    part = tmp_path / "part.h5"
    assert job(part, max_chunks=2)[1:] == (False, 6)
    out, ok, done = job(part)  # resumes at item 6
    assert ok and done == n and np.array_equal(out["a"], ref["a"]) and np.array_equal(out["b"], ref["b"])
    job(tmp_path / "p1.h5", max_chunks=1)
    with pytest.raises(CheckpointError, match=r"its g is not this run's g stage \(resume_key grid-a, this run's "
                                              r"grid-b"):
        job(tmp_path / "p1.h5", fp="grid-b")
    with pytest.raises(CheckpointError, match=r"written by another shard \(items 0:10, this run's 0:5\)"):
        job(tmp_path / "p1.h5", span=(0, 5))
    job(tmp_path / "p2.h5", max_chunks=1)
    with h5py.File(tmp_path / "p2.h5", "r+") as f:
        f["g"].attrs["done"] = 6  # edited
    with pytest.raises(CheckpointError, match="attribute 'done' does not match its checksum.*fresh=true"):
        job(tmp_path / "p2.h5")
    job(tmp_path / "p3.h5", max_chunks=1)
    with h5py.File(tmp_path / "p3.h5", "r+") as f:
        f["g/b"][0, 0] = 5
    with pytest.raises(CheckpointError, match="g/b does not match its checksum"):
        job(tmp_path / "p3.h5")


def test_resize_bar_ends_a_bar_full_when_a_stage_needs_more_or_less_than_planned():
    import io

    from tqdm import tqdm

    log = io.StringIO()
    with tqdm(total=2, file=log, mininterval=0) as bar:      # planned: two designs; the stage finds a third
        bar.update(2)
        resize_bar(bar, 3)
        bar.update(1)
        assert (bar.n, bar.total) == (3, 3)
    assert "3/2" not in log.getvalue() and "3/3" in log.getvalue()
    with tqdm(total=2, file=io.StringIO(), mininterval=0) as bar:  # planned two, one was enough
        bar.update(1)
        resize_bar(bar, 1)
        assert (bar.n, bar.total) == (1, 1)


def test_stage_ends_collect_only_what_the_stage_made_and_the_run_leaves_nothing_frozen(tmp_path):
    """Within a run each stage end collects the cycles made since the last one (what was alive before the run and
    what survived a stage end is frozen, not walked again); a cycle dropped in a stage is collected at its end;
    after the run (finished or raising) nothing stays frozen."""
    import gc
    import weakref

    class Node:
        pass

    seen = {}

    def make(st: State) -> None:            # a cycle that dies inside the stage: collected at its end
        seen["frozen_at_start"] = gc.get_freeze_count()   # what was alive before the run is not walked again
        a, b = Node(), Node()
        a.other, b.other = b, a
        seen["ref"] = weakref.ref(a)

    def check(st: State) -> None:
        seen["collected"] = seen["ref"]() is None
        seen["frozen"] = gc.get_freeze_count()

    def fail(st: State) -> None:
        raise RuntimeError("a stage fails")

    assert gc.get_freeze_count() == 0
    ctx = _ctx(tmp_path / "r.h5")
    assert Runner(ctx, "toy").run((Stage("make", make), Stage("check", check)), State(ctx=ctx))
    assert seen["frozen_at_start"] > 0 and seen["collected"] and seen["frozen"] > 0 and gc.get_freeze_count() == 0
    with pytest.raises(RuntimeError, match="a stage fails"):
        Runner(ctx, "toy").run((Stage("make", make), Stage("fail", fail)), State(ctx=ctx))
    assert gc.get_freeze_count() == 0
