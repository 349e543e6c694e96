"""The one stage engine of the CLI jobs: a job is a list of :class:`Stage` run by :class:`Runner`.

A stage computes one step of a job and writes what it found into the run's results file; the runner owns
everything around that, identically for every job:

* **done and skip**: with ``resumable=True`` the finished stages are recorded in the results file (attribute
  ``<job>_stages``, with the run's fingerprint in ``<job>_fingerprint``); a rerun into the same run directory
  skips them (:meth:`Runner.open` checks the fingerprint and stages the existing file first) and a finished run
  does nothing.
* **what a skipped stage hands on**: a finished stage's ``load`` (or, for a stage that is not recorded, its
  ``compute``) runs only when a later stage has to be computed, and in order: a run stopped after its last
  in-memory stage never rebuilds the state it would not use.
* **checkpoints** of a stage that commits part of its work (the GA's generations, a grid's chunks): the stage asks
  the runner for its :class:`Checkpoint` (:meth:`Runner.checkpoint`, :meth:`Runner.chunk_checkpoint`); the
  runner reads it back verified (checksums, integrity record), refuses one of another run or a damaged one
  (:class:`deltajax.rundir.CheckpointError`, one line), and commits (the stage's data staged, the run's identity
  stamped, the file flushed, a log line). A checkpoint's identity is one: the run's fingerprint (the one
  :meth:`Runner.open` checks, stamped in the checkpoint's group) and the stage's name (whose group it is).
* **stops**: a stage that raises :class:`Stop` (``experiment.stop_after``) ends the run resumable, with the
  message logged.
* **timing and log lines**: each computed stage logs ``[name: wall s, CPU-s, peak GiB, GiB in use]``
  (CPU-seconds of the process: on a shared machine the figure to compare; the process's peak resident memory so
  far, so the stage that raises it shows -- what a scheduler's memory request must cover; what it still holds once
  the memory the stage freed went back to the system, :func:`release_memory`) and its wall time is kept in
  :attr:`Runner.timings`.

Stages share one mutable :class:`State` (the job's settings, problem and what earlier stages handed on), so a
job's ``run()`` is the list of its stages. Application wing: it reads and writes the results file through the
run context only.
"""

from __future__ import annotations

import contextlib
import dataclasses
import resource
import sys
import time
import types
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping, Optional
import gc

import numpy as np

from ..io import ChecksumError, load, ResultsGroupError
from ..rundir import CheckpointError, recorded, restage, RunDirError
from ..workspace.chunks import seal

__all__ = ["Stage", "State", "Stop", "Runner", "Checkpoint", "ChunkCheckpoint", "release_memory", "collecting_by_stage",
           "resize_bar"]


def resize_bar(bar, total: int) -> None:
    """Set a progress bar's total to the work a stage turned out to need (more steps found along the way, or fewer
    than planned), so that the bar ends at n == total rather than at 3/2 or 1/2."""
    if bar.total != total:
        bar.total = total
        bar.refresh()


#: open :func:`collecting_by_stage` scopes of this process
_SCOPES = [0]


@contextlib.contextmanager
def collecting_by_stage():
    """Within it, each :func:`release_memory` freezes what its collection found alive (``gc.freeze``), so the next
    one only walks the objects made since: a stage's tracing leaves millions of live objects (JAX's caches; a toy
    main-job run that traces its programs held 2.5 M) and a full collection walked them all at every stage end,
    ~1.4 s each. What is alive on entering the outermost scope (the imports, an earlier run's caches in the same
    process) is frozen too. On leaving it everything is unfrozen (the next collection sees it all again)."""
    if not _SCOPES[0]:
        gc.freeze()
    _SCOPES[0] += 1
    try:
        yield
    finally:
        _SCOPES[0] -= 1
        if not _SCOPES[0]:
            gc.unfreeze()


def release_memory() -> None:
    """Hand the memory a finished computation freed back to the operating system: Python's cycles collected, then
    glibc's ``malloc_trim`` (its per-thread arenas keep freed memory, which XLA's worker threads then do not
    reuse: a certify program at its densest left 1.9 GiB resident of which the trim returned 1.1 GiB, and each
    later stage's peak stacked on the last). Nothing where the C library is not glibc. Inside
    :func:`collecting_by_stage`, the survivors are frozen for the collections after this one."""
    import ctypes

    gc.collect()
    if _SCOPES[0]:
        gc.freeze()
    try:
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):
        pass


def _in_use() -> str:
    """``, x.xx GiB in use``: the process's resident memory now (Linux), else nothing."""
    try:
        with open("/proc/self/statm") as f:
            pages = int(f.read().split()[1])
    except (OSError, ValueError, IndexError):
        return ""
    return f", {pages * resource.getpagesize() / 2 ** 30:.2f} GiB in use"


class Stop(Exception):
    """Raised by a stage that stops the run early on purpose (resumable); the message is logged."""


class State(types.SimpleNamespace):
    """What a job's stages share: settings, problem, and what each stage hands on (attributes)."""


def _always(state: State) -> bool:
    return True


@dataclasses.dataclass(frozen=True)
class Stage:
    """One step of a job.

    Attributes:
        name: the stage's name (recorded in the results file when the job is resumable).
        compute: ``compute(state)``: computes the stage, writes its results (``state.ctx.results``) and sets on
            ``state`` what later stages read.
        load: ``load(state)``: for a stage already finished in the run directory, sets on ``state`` what
            ``compute`` would have (read back from the results, or rebuilt from a checkpoint); None when later
            stages read nothing of it from memory.
        when: ``when(state) -> bool``; a stage that does not apply is neither computed nor recorded.
        record: False for a preparation step that is never recorded as done (computed lazily, like a finished
            stage's ``load``, whenever a later stage is computed).
    """

    name: str
    compute: Callable[[State], None]
    load: Optional[Callable[[State], None]] = None
    when: Callable[[State], bool] = _always
    record: bool = True


class Runner:
    """Runs a job's stages (:meth:`run`) with done/skip, stops, timings and log lines.

    Args:
        ctx: the run context (:class:`deltajax.run.RunContext`).
        job: the job's name (the prefix of its results-file attributes).
        resumable: record finished stages in the results file, skip them on a rerun.
        fingerprint: the run's identity, for a job that checkpoints without recording its stages (a resumable
            job's is given to :meth:`open`).

    Attributes:
        checkpoints: stage name -> its :class:`Checkpoint` (:meth:`checkpoint`, :meth:`chunk_checkpoint`).
    """

    def __init__(self, ctx: Any, job: str, *, resumable: bool = True, fingerprint: Optional[str] = None):
        self.ctx, self.job, self.resumable, self.fingerprint = ctx, job, resumable, fingerprint
        self.checkpoints: dict[str, Checkpoint] = {}
        self.done: list[str] = []
        self.timings: dict[str, float] = {}
        self._t = (time.perf_counter(), time.process_time())

    @property
    def attr_stages(self) -> str:
        return f"{self.job}_stages"

    @property
    def attr_fingerprint(self) -> str:
        return f"{self.job}_fingerprint"

    def open(self, fingerprint: str, *, resume: str = "auto") -> list[str]:
        """Claim the run's results file for this job: the stages it already finished (``resume="auto"`` or
        ``"must"``), or none (``"never"``). An existing file is verified and staged into the results first, so
        the next flush keeps everything on disk. A partial stage's checkpoint (:meth:`checkpoint`, asked for
        before) counts as something to resume.

        Args:
            fingerprint: the hash of everything that determines the results (a file holding another is refused).
            resume: ``"auto"``, ``"must"`` (refuse when the file holds nothing to resume) or ``"never"``.

        Raises:
            deltajax.rundir.RunDirError: the file holds another job or other settings, cannot be read, or
                ``resume="must"`` finds nothing to resume (one line, nothing changed).
            deltajax.rundir.CheckpointError: the file fails its checksums (``fresh=true`` starts over).
        """
        self.fingerprint = fingerprint
        path = Path(self.ctx.results.path)
        try:
            old_fp, done = recorded(path, self.job)
        except ChecksumError as err:
            raise CheckpointError(f"cannot resume: {err}; add fresh=true to start over") from None
        except OSError as err:
            raise RunDirError(f"{path} exists but cannot be read ({err}); move it away or choose another "
                              "hydra.run.dir") from None
        if old_fp is not None and old_fp != fingerprint:
            raise RunDirError(f"{path} holds a {self.job} run with different settings (fingerprint {old_fp} vs "
                              f"{fingerprint}); choose another hydra.run.dir (nothing was changed)")
        if path.exists() and old_fp is None and resume != "never" and not self._partial():
            raise RunDirError(f"{path} exists but holds no {self.job} run; choose another hydra.run.dir "
                              "(nothing was changed)")
        self.ctx.results.set_attrs(**{self.attr_fingerprint: fingerprint})
        if resume == "never":
            return self.done
        if path.exists():
            try:
                restage(self.ctx.results, path)     # verified, and nothing already on disk is ever dropped
            except ChecksumError as err:
                raise CheckpointError(f"cannot resume: {err}; add fresh=true to start over") from None
        if resume == "must" and not done and not self._partial():
            what = " or ".join(c.what for c in self.checkpoints.values()) or "finished stage"
            raise RunDirError(f"experiment.resume=must but {path} holds no {what}")
        self.done = done
        return self.done

    def _partial(self) -> bool:
        return any(c.load() is not None for c in self.checkpoints.values())

    def checkpoint(self, stage: str, group: str, *, save: Callable[..., None],
                   read: Optional[Callable[[dict], Any]] = None, what: str = "checkpoint",
                   note: Optional[Callable[..., str]] = None, attr: str = "fingerprint",
                   remedy: str = "add fresh=true to start over (the checkpoint is part of results.h5)") -> "Checkpoint":
        """The checkpoint of stage ``stage`` in group ``group`` of the results file (see :class:`Checkpoint` for
        the arguments); asked for before :meth:`open`, a checkpoint found there counts as something to resume."""
        self.checkpoints[stage] = Checkpoint(self, stage, group, save=save, read=read, what=what, note=note,
                                             attr=attr, remedy=remedy)
        return self.checkpoints[stage]

    def chunk_checkpoint(self, stage: str, group: str, arrays: Mapping[str, np.ndarray], *, span: tuple[int, int],
                         save: Callable[..., None], check: Optional[Callable[[dict, int], str]] = None,
                         done_attr: str = "done", what: str = "checkpoint", note: Optional[Callable[..., str]] = None,
                         remedy: str = "move it away to keep it, or add fresh=true to start over"
                         ) -> "ChunkCheckpoint":
        """The checkpoint of a stage run on the chunk engine (:func:`deltajax.workspace.chunks.run_chunks`), in
        group ``group`` of the results file: a :class:`ChunkCheckpoint` (the engine's store contract)."""
        self.checkpoints[stage] = ChunkCheckpoint(self, stage, group, arrays, span=span, save=save, check=check,
                                                  done_attr=done_attr, what=what, note=note, remedy=remedy)
        return self.checkpoints[stage]

    def mark(self, name: str) -> None:
        """Record stage ``name`` as finished (results flushed), log its wall time and CPU-seconds."""
        now = (time.perf_counter(), time.process_time())
        self.timings[name] = now[0] - self._t[0]
        cpu = now[1] - self._t[1]
        if self.resumable:
            self.done.append(name)
            self.ctx.results.set_attrs(**{self.attr_stages: ",".join(self.done)})
            self.ctx.results.flush()
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2 ** (30 if sys.platform == "darwin" else 20)
        release_memory()          # the next stage's peak starts from what is still in use, not from this one's
        self.ctx.log(f"[{name}: {self.timings[name]:.1f} s, {cpu:.1f} CPU-s, peak {peak:.2f} GiB{_in_use()}]")
        self._t = (time.perf_counter(), time.process_time())

    def run(self, stages: Iterable[Stage], state: State) -> bool:
        """Run ``stages`` in order on ``state``: finished ones skipped (their ``load`` run lazily, when a later
        stage is computed), the others computed and marked. Returns False when a stage stopped the run
        (:class:`Stop`), True otherwise."""
        state.runner = self
        with collecting_by_stage():
            return self._run(stages, state)

    def _run(self, stages: Iterable[Stage], state: State) -> bool:
        pending: list[Callable[[State], None]] = []
        for stage in stages:
            if not stage.when(state):
                continue
            if not stage.record or stage.name in self.done:
                fn = stage.compute if not stage.record else stage.load
                if fn is not None:
                    pending.append(fn)
                continue
            for fn in pending:
                fn(state)
            pending.clear()
            try:
                stage.compute(state)
            except Stop as stop:
                self.ctx.complete = False
                self.ctx.log(str(stop))
                return False
            self.mark(stage.name)
        return True


class Checkpoint:
    """A stage's partial work in the run's results file, owned by the :class:`Runner` (ask it for one:
    :meth:`Runner.checkpoint`).

    The checkpoint of stage ``stage`` lives in group ``group`` and carries the run's fingerprint in the group's
    attribute ``attr``: :meth:`load` refuses a checkpoint of another run (or a damaged one), :meth:`commit`
    stamps it.

    Args:
        runner: the runner (its ``fingerprint`` is the run's identity; ``ctx.results`` the results file).
        stage: the stage's name.
        group: the results-file group of the checkpoint.
        save: ``save(results, *state)``: stages the partial state into the results (the runner stamps, flushes).
        read: ``read(group_dict) -> partial state``, the group as :func:`deltajax.io.load` gives it (verified,
            of this run); a KeyError, TypeError or ValueError there is a malformed checkpoint. None: the dict.
        what: what the checkpoint is called in messages (``"GA checkpoint"``).
        note: ``note(*state) -> str``: what a commit holds, for its log line.
        attr: the group attribute holding the run's fingerprint.
        remedy: what a refusal tells the user to do.
    """

    def __init__(self, runner: Runner, stage: str, group: str, *, save: Callable[..., None],
                 read: Optional[Callable[[dict], Any]] = None, what: str = "checkpoint",
                 note: Optional[Callable[..., str]] = None, attr: str = "fingerprint",
                 remedy: str = "add fresh=true to start over"):
        self.runner, self.stage, self.group, self.save, self.read = runner, stage, group, save, read
        self.what, self.note, self.attr, self.remedy = what, note, attr, remedy
        self._loaded: Optional[tuple] = None   # (file identity, state) of the last load() since the last commit

    @property
    def path(self) -> Path:
        return Path(self.runner.ctx.results.path)

    def __str__(self) -> str:
        return str(self.path)

    def refuse(self, problem: str) -> Exception:
        """The one-line refusal (:class:`deltajax.rundir.CheckpointError`) of this checkpoint."""
        return CheckpointError(f"cannot resume the {self.what} in {self.path}: {problem}; {self.remedy}")

    def _group(self) -> Optional[dict]:
        """The checkpoint's group read back verified, or None when the file or the group is not there."""
        path = self.path
        if not path.exists():
            return None
        try:
            data = load(path, self.group, verify=True)
        except ResultsGroupError:
            return None
        except ChecksumError as e:
            raise self.refuse(str(e).replace(f"{path}:", "").replace(f"{path} ", "").strip()) from None
        except (OSError, KeyError, RuntimeError) as e:
            raise self.refuse(f"it is unreadable or incomplete ({type(e).__name__}: "
                              f"{str(e).split('(')[0].strip()})") from None
        mine = self._fingerprint()
        theirs = data["attrs"].get(self.attr)
        if theirs is None or str(theirs) != mine:
            raise self.refuse(f"its {self.group} is not this run's {self.stage} stage ({self.attr} "
                              f"{_short(theirs)}, this run's {_short(mine)}: written with other settings or by an "
                              "older deltajax)")
        return data

    def _fingerprint(self) -> str:
        if self.runner.fingerprint is None:
            raise RuntimeError(f"the {self.stage} stage's checkpoint needs the run's fingerprint: Runner.open(fp) or "
                               "Runner(..., fingerprint=fp)")
        return str(self.runner.fingerprint)

    def load(self) -> Any:
        """The stage's partial state, verified and of this run; None when the results file holds none.

        Raises:
            deltajax.rundir.CheckpointError: the checkpoint is another run's, damaged, edited or malformed
                (one line: the path, what is wrong, what to do).

        A second call before a :meth:`commit` (the runner's resume check in :meth:`Runner.open`, then the stage)
        returns the state already read when the file is unchanged since (same inode, size and modification time,
        in ns); a file changed in between is read and verified again.
        """
        ident = self._identity()
        if self._loaded is None or self._loaded[0] != ident or ident is None:
            self._loaded = (ident, self._read())
        return self._loaded[1]

    def _identity(self) -> Optional[tuple]:
        try:
            st = self.path.stat()
        except OSError:
            return None
        return st.st_ino, st.st_size, st.st_mtime_ns

    def _read(self) -> Any:
        data = self._group()
        if data is None or self.read is None:
            return data
        try:
            return self.read(data)
        except (KeyError, TypeError, ValueError) as e:
            raise self.refuse(f"its {self.group} is malformed ({type(e).__name__}: {e})") from None

    def commit(self, *state: Any) -> None:
        """Make ``state`` the stage's checkpoint: staged (``save``), stamped with the run's fingerprint, flushed
        (durable once this returns) and logged."""
        res = self.runner.ctx.results
        self._loaded = None
        self.save(res, *state)
        res.set_attrs(self.group, **{self.attr: self._fingerprint()})
        res.flush()
        self.runner.ctx.log(f"[{self.stage}: checkpoint{': ' + self.note(*state) if self.note else ''}]")


def _short(v: Any) -> str:
    s = repr(v) if not isinstance(v, str) else v
    return s if len(s) <= 24 else s[:21] + "..."


class ChunkCheckpoint(Checkpoint):
    """The checkpoint of a stage run on the chunk engine, in the results file (:meth:`Runner.chunk_checkpoint`):
    the engine's store contract (``open`` -> the arrays and the items already done, ``commit`` -> durable), so
    that the partial file is a readable result and a mergeable shard.

    The group holds the arrays (leading axis: this stage's items), ``<done_attr>`` (items finished),
    ``resume_key`` (the run's fingerprint), ``shard_start``/``shard_stop`` (``span``) and ``resume_seal``
    (:func:`deltajax.workspace.chunks.seal` of those), all written by ``save(results, arrays, done_items)``;
    :meth:`open` refuses a file whose fingerprint, seal, range, shape or any dataset's checksum does not
    match, and copies the finished items of every array from it.

    Args:
        arrays: name in the group -> preallocated array (leading axis: this stage's items).
        span: (shard_start, shard_stop) of this run along the item axis.
        check: ``check(data, done) -> problem or ""``: consistency of the stored arrays beyond their checksums.
        done_attr: the group attribute counting finished items.
        (the others: :class:`Checkpoint`)
    """

    commit_last = False  # the stage writes its final results itself

    def __init__(self, runner: Runner, stage: str, group: str, arrays: Mapping[str, np.ndarray], *,
                 span: tuple[int, int], save: Callable[..., None], check: Optional[Callable[[dict, int], str]] = None,
                 done_attr: str = "done", what: str = "checkpoint", note: Optional[Callable[..., str]] = None,
                 remedy: str = "move it away to keep it, or add fresh=true to start over"):
        super().__init__(runner, stage, group, save=save, what=what, note=note, attr="resume_key", remedy=remedy)
        self.arrays, self.span, self.check, self.done_attr = dict(arrays), span, check, done_attr

    def open(self, n_items: int, chunk_size: int, outputs: dict) -> tuple[dict, int]:
        missing = [n for n in outputs if n not in self.arrays]
        if missing:
            raise ValueError(f"ChunkCheckpoint has no arrays for outputs {missing}")
        data = self._group()
        if data is None:
            if self.path.exists():
                raise self.refuse(f"it has no group {self.group!r}")
            return self.arrays, 0
        a = data["attrs"]
        try:
            done = int(a[self.done_attr])
            span = [int(a["shard_start"]), int(a["shard_stop"])]
            ok_seal = a.get("resume_seal") == seal(a[self.attr], done, *span)
            stored = {n: np.asarray(data[n]) for n in self.arrays}
        except (KeyError, TypeError, ValueError):
            raise self.refuse("its checkpoint attributes or arrays are missing or malformed") from None
        if not ok_seal:
            raise self.refuse(f"its checkpoint attributes ({self.done_attr}, {self.attr}, shard range) do not match "
                              "their checksum (the file is damaged or was edited)")
        if span != list(self.span):
            raise self.refuse(f"it was written by another shard (items {span[0]}:{span[1]}, this run's "
                              f"{self.span[0]}:{self.span[1]})")
        if not 0 <= done <= n_items:
            raise self.refuse(f"{self.done_attr}={done} is outside 0..{n_items}")
        for name, arr in stored.items():
            if arr.shape != self.arrays[name].shape:
                raise self.refuse(f"{self.group}/{name} has shape {arr.shape}, this run expects "
                                  f"{self.arrays[name].shape}")
        problem = self.check(stored, done) if self.check is not None else ""
        if problem:
            raise self.refuse(problem)
        for name, arr in self.arrays.items():
            arr[:done] = stored[name][:done]
        return self.arrays, done
