"""Ownership of a run directory: one process at a time, a manifest of job + config, no silent overwrite.

Every CLI run (``python -m deltajax.run``, :func:`deltajax.run.run_experiment`, each job of a multirun) claims
its output directory before it writes anything there, ``.hydra/`` included:

* **Lock**: ``<dir>/.deltajax.lock`` is held with ``fcntl.flock`` for the life of the process (the kernel
  drops it when the process dies, even by SIGKILL). A second process in the same directory stops at once
  with :class:`RunDirError` naming the directory and the holder's pid.
* **Manifest**: ``<dir>/deltajax_run.json`` records the experiment, the resolved config (without ``hydra``),
  and the status (``running`` until the job returns, then ``complete``).
* **Rerun**: into a directory whose manifest holds the same experiment and the same config (up to the
  settings in :data:`NEUTRAL`, which do not change the numbers) resumes it (``running``) or reports that it is
  complete and does nothing (``complete``), after verifying its ``results.h5`` (checksums and integrity record,
  :func:`deltajax.io.verify_file`): a damaged, edited or truncated file is refused with :class:`CheckpointError`
  (one line: the path, what is wrong, ``fresh=true``). Anything else is refused with one line naming the
  settings that differ, and nothing in the directory is touched. A directory holding deltajax results but no manifest is
  refused too (it cannot be matched to a config).
* **Killed writers**: their unique temporaries (``.<name>.<pid>.<random>.tmp``) are removed by the next claim.
* **Starting over is explicit**: ``fresh=true`` deletes what earlier runs wrote there (results, checkpoints,
  manifest, ``.hydra``, figures) before the new run starts.

Hydra writes ``.hydra/`` itself before any user code runs (``hydra.output_subdir``); ``configs/config.yaml``
turns that off (``hydra.output_subdir: null``) and :func:`deltajax.run.main` writes the same three files
after the claim succeeds, so a refused run leaves the previous ``.hydra/config.yaml`` in place.
"""

from __future__ import annotations

import datetime as _dt
import errno
import fcntl
import json
import math
import os
import shutil
from pathlib import Path
from typing import Any, Mapping, Optional

from .io import ChecksumError, read, verify_file, write_atomic

__all__ = ["RunDirError", "CheckpointError", "RunDirectory", "claim", "config_differences", "describe_differences",
           "MANIFEST", "LOCK", "NEUTRAL", "recorded", "restage"]

MANIFEST = "deltajax_run.json"
LOCK = ".deltajax.lock"
#: Settings a rerun may change without changing the numbers (not compared against the manifest).
NEUTRAL = ("plots", "progress", "compilation_cache", "fresh", "experiment.resume", "experiment.checkpoint_s",
           "experiment.stop_after")
#: What earlier runs write into a run directory; ``fresh=true`` removes these (and ``*.png``).
ARTEFACTS = ("results.h5", "checkpoint", ".hydra", MANIFEST)


class RunDirError(RuntimeError):
    """The run directory is busy or holds another job's results; the message says what to do."""


class CheckpointError(RunDirError):
    """A checkpoint in the run directory is damaged or inconsistent; a run refuses to resume from it."""


def _now() -> str:
    return _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")


def _flatten(cfg: Any, prefix: str = "") -> dict[str, Any]:
    if isinstance(cfg, Mapping):
        out: dict[str, Any] = {}
        for k, v in cfg.items():
            out.update(_flatten(v, f"{prefix}{k}."))
        if not cfg and prefix:
            out[prefix[:-1]] = {}
        return out
    return {prefix[:-1]: cfg}


def _same(a: Any, b: Any) -> bool:
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    return a == b


def _neutral(key: str, ignore: tuple = ()) -> bool:
    return any(key == n or key.startswith(n + ".") for n in NEUTRAL + tuple(ignore))


def config_differences(old: Mapping[str, Any], new: Mapping[str, Any], ignore: tuple = ()
                       ) -> list[tuple[str, Any, Any]]:
    """(dotted key, old value, new value) of every setting that differs, :data:`NEUTRAL` ones and those under
    ``ignore`` (dotted keys or prefixes) left out.

    A key missing on one side has the value ``"<unset>"`` there.
    """
    a, b = _flatten(old), _flatten(new)
    out = []
    for k in sorted(a.keys() | b.keys()):
        if _neutral(k, ignore):
            continue
        va, vb = a.get(k, "<unset>"), b.get(k, "<unset>")
        if not _same(va, vb):
            out.append((k, va, vb))
    return out


def describe_differences(diffs: list[tuple[str, Any, Any]], limit: int = 4) -> str:
    parts = [f"{k}={_short(old)} there, {_short(new)} now" for k, old, new in diffs[:limit]]
    more = f" and {len(diffs) - limit} more" if len(diffs) > limit else ""
    return "; ".join(parts) + more


def _short(v: Any) -> str:
    s = json.dumps(v, default=str) if not isinstance(v, str) else v
    return s if len(s) <= 60 else s[:57] + "..."


class RunDirectory:
    """A claimed run directory (see the module docstring). Use :func:`claim`.

    Attributes:
        path: the directory.
        state: ``"new"`` (nothing there before), ``"resume"`` (an unfinished run of the same job and config)
            or ``"complete"`` (a finished run of the same job and config: nothing to do).
    """

    def __init__(self, path: Path, fd: int, manifest: dict, state: str):
        self.path, self._fd, self.manifest, self.state = path, fd, manifest, state

    def mark_complete(self) -> None:
        """Record that the job finished (a rerun with the same config is then a no-op)."""
        self.manifest.update(status="complete", finished=_now())
        _write_manifest(self.path, self.manifest)

    def release(self) -> None:
        """Drop the lock (also dropped automatically when the process exits)."""
        if self._fd is not None:
            fcntl.flock(self._fd, fcntl.LOCK_UN)
            os.close(self._fd)
            self._fd = None

    def __enter__(self) -> "RunDirectory":
        return self

    def __exit__(self, *exc) -> None:
        self.release()


def _lock(path: Path) -> int:
    lock = path / LOCK
    fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o666)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError as e:
        os.close(fd)
        if e.errno not in (errno.EAGAIN, errno.EACCES, errno.EWOULDBLOCK):
            raise
        try:
            holder = lock.read_text().strip() or "?"
        except OSError:
            holder = "?"
        raise RunDirError(f"run directory {path} is in use by another deltajax run (pid {holder}); wait for it to "
                          f"finish, or choose another hydra.run.dir") from None
    os.ftruncate(fd, 0)
    os.write(fd, f"{os.getpid()}\n".encode())
    return fd


def _write_manifest(path: Path, manifest: dict) -> None:
    write_atomic(path / MANIFEST, (json.dumps(manifest, indent=1, default=str, sort_keys=True) + "\n").encode())


def _remove_artefacts(path: Path) -> None:
    for name in ARTEFACTS:
        p = path / name
        if p.is_dir():
            shutil.rmtree(p)
        elif p.exists():
            p.unlink()
    for p in path.glob("*.png"):
        p.unlink()


def _check_results(results: Path, state: str) -> None:
    """Verify the results file a rerun trusts (state ``resume``: its checkpoint and finished stages; ``complete``:
    the finished results it reports as done): every dataset against its checksum, every attribute (stages done,
    generations done, ...) and group against the file's integrity record (:func:`deltajax.io.verify_file`).
    Raises :class:`CheckpointError` (one line: the path, what is wrong, what to do) when it is damaged,
    edited, truncated or missing."""
    if state == "resume":
        head, todo = "cannot resume", "move it away to keep it, or add fresh=true to start over"
    else:
        head, todo = "cannot trust the finished run", "move it away to keep it, or add fresh=true to recompute it"
    if not results.exists():
        if state == "resume":
            return  # killed before its first write: nothing to trust, nothing to lose
        raise CheckpointError(f"{head}: {results} is missing although {results.parent / MANIFEST} records the run "
                              f"as complete; add fresh=true to recompute it")
    try:
        verify_file(results)
    except ChecksumError as e:
        what = str(e).replace(f"{results}:", "").replace(f"{results} ", "")
        raise CheckpointError(f"{head}: {results} fails verification: {what}; {todo}") from None
    except (OSError, RuntimeError) as e:
        cause = str(e).split("(")[0].strip() or type(e).__name__
        raise CheckpointError(f"{head}: {results} is not a readable HDF5 file ({cause}); {todo}") from None


def claim(path: os.PathLike, experiment: str, config: Mapping[str, Any], *, fresh: bool = False) -> RunDirectory:
    """Lock ``path`` for this process and check it against the manifest there (module docstring).

    Args:
        path: the run directory (created if missing).
        experiment: the experiment name.
        config: the resolved config as plain containers (without ``hydra``).
        fresh: delete what earlier runs left there and start over.

    Returns:
        The claimed :class:`RunDirectory` (keep it alive while the job runs; its lock ends with the process).

    Raises:
        RunDirError: another process holds the directory, or it holds another job's or another config's
            results (the message names the settings that differ), or results without a manifest.
    """
    path = Path(path)
    path.mkdir(parents=True, exist_ok=True)
    fd = _lock(path)
    try:
        state = "new"
        # temporaries of writers killed mid-write (SIGKILL cannot clean up): with the lock held no writer is
        # alive here, and a temporary is never data (the rename that would have made it so did not happen)
        for tmp in list(path.glob(".*.tmp")) + list(path.glob("checkpoint/*/.*.tmp")):
            tmp.unlink()
        if fresh:
            _remove_artefacts(path)
        mpath = path / MANIFEST
        config = json.loads(json.dumps(config, default=str))  # plain JSON values, as stored
        if mpath.exists():
            try:
                old = json.loads(mpath.read_text())
                old_exp, old_cfg, status = old["experiment"], old["config"], old["status"]
            except (OSError, ValueError, KeyError, TypeError) as e:
                raise RunDirError(f"{mpath} is unreadable ({type(e).__name__}); this directory cannot be matched to "
                                  f"a config: choose another hydra.run.dir, or add fresh=true to replace it") from None
            if old_exp != experiment:
                raise RunDirError(f"run directory {path} holds a {old_exp!r} run, not {experiment!r}; choose another "
                                  f"hydra.run.dir, or add fresh=true to replace it")
            diffs = config_differences(old_cfg, config)
            if diffs:
                raise RunDirError(f"run directory {path} holds a {experiment} run with other settings: "
                                  f"{describe_differences(diffs)}; choose another hydra.run.dir, or add fresh=true to "
                                  "replace it")
            state = "complete" if status == "complete" else "resume"
            _check_results(path / "results.h5", state)  # what a resume or a "nothing to do" trusts
            manifest = old
            if state == "resume":
                manifest.update(resumed=_now())
                _write_manifest(path, manifest)
        else:
            found = [n for n in ("results.h5", "checkpoint") if (path / n).exists()]
            if found:
                raise RunDirError(f"run directory {path} holds {' and '.join(found)} but no {MANIFEST} (written "
                                  f"before run directories were owned, or not by deltajax); choose another "
                                  f"hydra.run.dir, or add fresh=true to replace it")
            manifest = {"experiment": experiment, "config": config, "status": "running", "started": _now(),
                        "pid": os.getpid()}
            _write_manifest(path, manifest)
        return RunDirectory(path, fd, manifest, state)
    except BaseException:
        fcntl.flock(fd, fcntl.LOCK_UN)
        os.close(fd)
        raise


# -- what a job recorded in its results file (the stage engine, deltajax.jobs.stages, writes it) ---------------

def recorded(path: Path, job: str) -> tuple[Optional[str], list]:
    """(fingerprint, finished stages) that job ``job`` recorded in the results file ``path``; (None, []) when
    there is no file. Its attributes are verified against the file's integrity record first (raises
    :class:`deltajax.io.ChecksumError`); raises OSError (with the path) when it exists but cannot be read."""
    if not Path(path).exists():
        return None, []
    attrs = read(path, max_elements=0, verify=True).attrs
    fp = str(attrs.get(f"{job}_fingerprint", "")) or None
    return fp, [x for x in str(attrs.get(f"{job}_stages", "")).split(",") if x]


def restage(res: Any, path: Path) -> None:
    """Stage everything the results file ``path`` holds into ``res`` (a :class:`deltajax.io.ResultsFile`, so
    that its next flush keeps it), verified first: data that does not match its checksums or the file's
    integrity record is never re-staged (the next flush would write fresh checksums over it). Raises
    :class:`deltajax.io.ChecksumError` (or OSError) then."""
    contents = read(path, verify=True)
    for k, v in contents.attrs.items():
        if k not in ("start_time",):
            res.attrs.setdefault(k, v)
    for group, variables in contents.variables.items():
        if group:
            res.set_attrs(group, **contents.group_attrs[group])
            res.put_variables(group, variables)
