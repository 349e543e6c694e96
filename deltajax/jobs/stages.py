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

import dataclasses
import resource
import sys
import time
import types
from pathlib import Path
from typing import Any, Callable, Iterable, Optional

__all__ = ["Stage", "State", "Stop", "Runner", "release_memory"]


def release_memory() -> None:
    """Hand the memory a finished computation freed back to the operating system: Python's cycles collected, then
    glibc's ``malloc_trim`` (its per-thread arenas keep freed memory, which XLA's worker threads then do not
    reuse: a certify program at its densest left 1.9 GiB resident of which the trim returned 1.1 GiB, and each
    later stage's peak stacked on the last). Nothing where the C library is not glibc."""
    import ctypes
    import gc

    gc.collect()
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
    """

    def __init__(self, ctx: Any, job: str, *, resumable: bool = True):
        self.ctx, self.job, self.resumable = ctx, job, resumable
        self.done: list[str] = []
        self.timings: dict[str, float] = {}
        self._t = (time.perf_counter(), time.process_time())

    @property
    def attr_stages(self) -> str:
        return f"{self.job}_stages"

    @property
    def attr_fingerprint(self) -> str:
        return f"{self.job}_fingerprint"

    def open(self, fingerprint: str, *, resume: str = "auto", has_partial: Callable[[Path], bool] = lambda p: False,
             partial_what: str = "checkpoint") -> list[str]:
        """Claim the run's results file for this job: the stages it already finished (``resume="auto"`` or
        ``"must"``), or none (``"never"``). An existing file is verified and staged into the results first, so
        the next flush keeps everything on disk.

        Args:
            fingerprint: the hash of everything that determines the results (a file holding another is refused).
            resume: ``"auto"``, ``"must"`` (refuse when the file holds nothing to resume) or ``"never"``.
            has_partial: ``has_partial(path)``: the file holds a partial stage's checkpoint (e.g. the GA's).
            partial_what: what that checkpoint is called in the refusal of ``resume="must"``.

        Raises:
            deltajax.rundir.RunDirError: the file holds another job or other settings, cannot be read, or
                ``resume="must"`` finds nothing to resume (one line, nothing changed).
            deltajax.rundir.CheckpointError: the file fails its checksums (``fresh=true`` starts over).
        """
        from ..io import ChecksumError
        from ..rundir import CheckpointError, RunDirError, recorded, restage

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
        if path.exists() and old_fp is None and resume != "never" and not has_partial(path):
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
        if resume == "must" and not done and not has_partial(path):
            raise RunDirError(f"experiment.resume=must but {path} holds no {partial_what}")
        self.done = done
        return self.done

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
