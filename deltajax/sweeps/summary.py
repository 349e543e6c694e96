"""Sweep summaries: each job's outcome, and ``summary.csv`` / ``summary.json`` indexing a sweep's runs.

:class:`SweepSummary` is a Hydra callback (``configs/config.yaml``, ``hydra.callbacks.sweep_summary``): in every
sweep job it records the job's status; when the multirun ends it merges sharded jobs
(:func:`deltajax.sweeps.merge_sweep`) and writes the summary (:func:`summarize_sweep`).
"""

from __future__ import annotations

import csv
import json
import math
import os
import re
from pathlib import Path
from typing import Any, Mapping, Optional

import numpy as np

from ..io import read, to_python
from .layout import (JOB_STATUS, Callback, find_runs, job_status, now, override_dict, run_overrides,
                     write_json)
from .merge import merge_sweep

__all__ = ["SweepSummary", "summarize_sweep", "SMALL_VECTOR"]

#: 1-D datasets up to this length (per-chain figures) enter sweep summaries as ``group/name[max]``
SMALL_VECTOR = 8


def _job_status_path(config) -> Path:
    # <run>/.hydra even though hydra.output_subdir is null (deltajax.run writes .hydra/ itself once the run
    # directory is claimed): the status exists from the job's start, also for a job rejected before its claim
    sub = config.hydra.get("output_subdir", None) or ".hydra"
    return Path(str(config.hydra.runtime.output_dir)) / str(sub) / JOB_STATUS


def _scheduler_ids() -> dict[str, Any]:
    """The scheduler's identity of this job (SLURM job/array ids, submitit's log files), if any."""
    ids: dict[str, Any] = {k: os.environ[k] for k in ("SLURM_JOB_ID", "SLURM_ARRAY_JOB_ID", "SLURM_ARRAY_TASK_ID",
                                                      "SLURM_CPUS_PER_TASK", "SLURM_RESTART_COUNT")
                           if k in os.environ}
    if os.environ.get("SUBMITIT_EXECUTOR"):
        try:
            import submitit

            paths = submitit.JobEnvironment().paths
            ids.update(stdout=str(paths.stdout), stderr=str(paths.stderr))
            # logs are appended across requeues: what SLURM says about *this* run comes after this offset
            ids["stderr_offset"] = paths.stderr.stat().st_size if paths.stderr.exists() else 0
        except Exception as e:  # not inside a submitit job after all: say so in the status file
            ids["submitit_paths"] = f"unavailable: {e}"
    return ids


class SweepSummary(Callback):
    """Hydra callback: at the end of a multirun, merge sharded runs and write the sweep's summary files.

    In every sweep job it also records the job's outcome in ``<run>/.hydra/job_status.json``
    (``running`` with the scheduler's job id and log files when the job starts; ``ok`` or ``failed`` with the
    error when it ends), which :func:`summarize_sweep` reports. The summary is written when the multirun ends,
    and also when it ends with an error (a failed job makes Hydra raise before its end-of-sweep callbacks):
    then from an ``atexit`` hook of the submitting process.

    Arguments (overrides under ``hydra.callbacks.sweep_summary``): ``merge`` (default true).
    """

    def __init__(self, merge: bool = True) -> None:
        self.merge = bool(merge)
        self._pending: Optional[Path] = None

    @staticmethod
    def _in_multirun(config) -> bool:
        return "MULTIRUN" in str(config.hydra.get("mode", ""))

    def on_job_start(self, config, **kwargs: Any) -> None:
        if self._in_multirun(config):
            write_json(_job_status_path(config), {"status": "running", "start_time": now(),
                                                   "overrides": [str(o) for o in config.hydra.overrides.task],
                                                   **_scheduler_ids()})

    def on_job_end(self, config, job_return, **kwargs: Any) -> None:
        if not self._in_multirun(config):
            return
        path = _job_status_path(config)
        try:
            data = json.loads(path.read_text())
        except (OSError, ValueError):
            data = _scheduler_ids()
        data["end_time"] = now()
        status = getattr(getattr(job_return, "status", None), "name", "")
        if status == "COMPLETED":
            data["status"] = "ok"
        else:
            err = getattr(job_return, "_return_value", None)
            first = str(err).strip().splitlines()[0] if str(err).strip() else ""
            data["status"] = "failed"
            data["error"] = f"{type(err).__name__}: {first}"[:500]
        write_json(path, data)

    def on_multirun_start(self, config, **kwargs: Any) -> None:
        import atexit

        self._pending = Path(str(config.hydra.sweep.dir))
        atexit.register(self._after_failed_sweep)

    def on_multirun_end(self, config, **kwargs: Any) -> None:
        self._pending = None
        self._finish(Path(str(config.hydra.sweep.dir)))

    def _after_failed_sweep(self) -> None:
        if self._pending is not None:  # the sweep raised (a job failed, or the submitter was interrupted)
            sweep_dir, self._pending = self._pending, None
            print("[deltajax] the sweep did not finish cleanly: summarising what is there", flush=True)
            self._finish(sweep_dir)

    def _finish(self, sweep_dir: Path) -> None:
        if not sweep_dir.is_dir():
            return
        if self.merge:
            for out in merge_sweep(sweep_dir):
                print(f"[deltajax] merged shards -> {out}", flush=True)
        paths = summarize_sweep(sweep_dir)
        rows = json.loads(paths["json"].read_text())["runs"]
        bad = [f"{r['run']}: {r['status']}" for r in rows if r["status"] != "ok"]
        print(f"[deltajax] sweep summary -> {paths['csv']}"
              + (f" ({len(bad)} not ok: " + "; ".join(bad) + ")" if bad else ""), flush=True)


def _scalars(path: Path) -> tuple[dict[str, float], dict[str, str], dict[str, Any]]:
    """Every 0-d numeric dataset of a results file as ``group/name`` -> value, its units, and root attrs."""
    contents = read(path, max_elements=SMALL_VECTOR)  # the scalars and short vectors, not the grids
    vals: dict[str, float] = {}
    units: dict[str, str] = {}
    for g, variables in contents.variables.items():
        for n, v in variables.items():
            name = f"{g}/{n}" if g else n
            data = np.asarray(v.data)
            if data.dtype.kind not in "biuf":
                continue
            if data.shape == ():
                vals[name] = to_python(v.data)
                units[name] = str(v.units or "")
            elif data.ndim == 1 and 1 <= data.shape[0] <= SMALL_VECTOR and not v.is_axis:
                # a per-chain figure (peak torque of each actuator ...): its largest entry
                f = data.astype(float)
                vals[f"{name}[max]"] = float(np.nanmax(f)) if np.isfinite(f).any() else float("nan")
                units[f"{name}[max]"] = str(v.units or "")
    root = {k: v for k, v in contents.attrs.items() if k != "config"}
    return vals, units, root


#: what SLURM writes into a job's error stream when it ends the job (cancel, time limit, memory limit)
_KILL_LINE = re.compile(r"(slurmstepd\S*: error: .*)|(.*\bCANCELLED AT .*)|(.*DUE TO (TIME LIMIT|PREEMPTION).*)")


def _killed_by_scheduler(job: Mapping[str, Any]) -> str:
    """The scheduler's last word on a job that started and never ended (from its error log), or ``""``."""
    try:
        with open(str(job["stderr"]), "rb") as fh:
            fh.seek(int(job.get("stderr_offset", 0)))
            text = fh.read().decode(errors="replace")
    except (KeyError, OSError, ValueError):
        return ""
    hits = [m.group(0).strip() for m in _KILL_LINE.finditer(text)]
    memory = [h for h in hits if "exceeded memory limit" in h]  # the line with the figures
    ended = [h for h in hits if "CANCELLED AT" in h or "DUE TO" in h]
    best = memory[0] if memory else ended[-1] if ended else hits[-1] if hits else ""
    return best[:300]


def summarize_sweep(sweep_dir: os.PathLike) -> dict[str, Path]:
    """Write ``summary.json`` and ``summary.csv`` indexing a sweep's runs and their key figures.

    One row per run directory (job order) and per merged sharded job (``kind = merged``): the run's overrides
    (one column per swept key), its status (``ok``: results.h5 complete; ``failed: <error>``: the job raised;
    ``killed: <the scheduler's message>``: SLURM ended it (cancel, time or memory limit); ``incomplete``:
    checkpoint only; ``running``: started, no end recorded; ``missing``: never started; the job's own record,
    ``.hydra/job_status.json``, is in summary.json as ``job``), experiment, wall time, and every scalar
    dataset of its results.h5 as ``group/name``
    (units in ``summary.json`` and in the CSV header as ``group/name [units]``); numeric 1-D datasets of at
    most :data:`SMALL_VECTOR` entries that are not axes (per-chain figures such as peak torques) enter as
    ``group/name[max]``, their largest entry.

    Returns:
        ``{"json": path, "csv": path}``.
    """
    sweep_dir = Path(sweep_dir)
    entries: list[tuple[str, Path, dict[str, str]]] = [
        ("run", r, override_dict(run_overrides(r))) for r in find_runs(sweep_dir)]
    merged_root = sweep_dir / "merged"
    if merged_root.is_dir():
        for m in sorted(merged_root.iterdir()):
            if (m / "results.h5").exists():
                entries.append(("merged", m, {}))
    rows, all_units = [], {}
    for kind, run, ov in entries:
        f = run / "results.h5"
        row: dict[str, Any] = {"run": str(run.relative_to(sweep_dir)), "kind": kind, "overrides": ov,
                               "status": "missing", "metrics": {}}
        job = job_status(run) if kind == "run" else {}
        if job:
            row["job"] = job
        if f.exists():
            try:
                vals, units, root = _scalars(f)
            except OSError as e:  # a file being replaced right now
                row["status"] = f"unreadable: {e}"
            else:
                row["status"] = "ok" if root.get("end_time") else "incomplete"
                row["experiment"] = root.get("experiment", "")
                row["wall_time_s"] = root.get("wall_time_s")
                if kind == "merged":
                    sources = [Path(q) for q in str(root.get("merged_from", "")).splitlines() if q]
                    row["merged_from"] = [q.parent.name for q in sources]
                    row["overrides"] = override_dict(run_overrides(sources[0].parent)) if sources else {}
                    row["overrides"].pop("shard", None)
                row["metrics"] = vals
                all_units.update(units)
        if job.get("status") == "failed":
            row["status"] = f"failed: {job.get('error', '')}"
        elif job.get("status") == "running" and row["status"] != "ok":
            killed = _killed_by_scheduler(job)
            if killed:
                row["status"] = f"killed: {killed}"
            elif row["status"] == "missing":
                row["status"] = "running"  # started, no end recorded: still running, or killed without a trace
        rows.append(row)
    summary = {"sweep_dir": str(sweep_dir.resolve()), "n_runs": sum(r["kind"] == "run" for r in rows),
               "units": all_units, "runs": rows}
    jpath = sweep_dir / "summary.json"
    tmp = jpath.with_name(jpath.name + ".tmp")
    tmp.write_text(json.dumps(summary, indent=1, default=_json_default))
    os.replace(tmp, jpath)
    keys = sorted({k for r in rows for k in r["overrides"]})
    metrics = sorted({k for r in rows for k in r["metrics"]})
    cpath = sweep_dir / "summary.csv"
    tmp = cpath.with_name(cpath.name + ".tmp")
    with open(tmp, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["run", "kind", "status", "experiment_name", "wall_time_s", *keys,
                    *(f"{m} [{all_units.get(m, '')}]" for m in metrics)])
        for r in rows:
            w.writerow([r["run"], r["kind"], r["status"], r.get("experiment", ""), _fmt(r.get("wall_time_s")),
                        *(r["overrides"].get(k, "") for k in keys),
                        *(_fmt(r["metrics"].get(m)) for m in metrics)])
    os.replace(tmp, cpath)
    return {"json": jpath, "csv": cpath}


def _fmt(v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, float):
        return repr(v) if math.isfinite(v) else str(v)
    return str(v)


def _json_default(v: Any) -> Any:
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, np.ndarray):
        return v.tolist()
    return str(v)
