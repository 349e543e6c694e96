"""The layout of a Hydra sweep directory: its runs, each job's overrides and status record (host side).

``<sweep>/<job number>/`` holds a run (``results.h5``, ``.hydra/overrides.yaml``, ``.hydra/job_status.json``
written by :class:`deltajax.sweeps.SweepSummary`); ``<sweep>/merged/<label>/results.h5`` holds merged shards.
"""

from __future__ import annotations

import datetime
import json
import os
import re
from pathlib import Path
from typing import Any, Mapping, Sequence

try:  # Hydra is a hard dependency of the CLI; keep this package importable without it for analysis
    from hydra.experimental.callback import Callback
except ImportError:  # pragma: no cover
    Callback = object  # type: ignore[misc,assignment]

__all__ = ["find_runs", "run_overrides", "override_dict", "label", "job_status", "write_json", "now", "JOB_STATUS",
           "Callback"]

#: per-job status file (in the job's ``.hydra/`` folder) written by :class:`SweepSummary` in each sweep job
JOB_STATUS = "job_status.json"


def write_json(path: Path, data: Mapping[str, Any]) -> None:
    """Write ``data`` as JSON to ``path`` atomically (temporary file + rename)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(json.dumps(data, indent=1, default=str))
    os.replace(tmp, path)


def now() -> str:
    """The current UTC time, ISO 8601 to the second."""
    return datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")


def _run_sort_key(p: Path):
    return (0, int(p.name), "") if p.name.isdigit() else (1, 0, p.name)


def find_runs(sweep_dir: os.PathLike) -> list[Path]:
    """The run directories of a Hydra sweep (``<sweep>/<job num>/``), in job order (merged runs excluded)."""
    sweep_dir = Path(sweep_dir)
    runs = [p for p in sweep_dir.iterdir()
            if p.is_dir() and p.name != "merged" and not p.name.startswith(".")
            and ((p / ".hydra").is_dir() or (p / "results.h5").exists())]
    return sorted(runs, key=_run_sort_key)


def run_overrides(run_dir: Path) -> list[str]:
    """The job's overrides: .hydra/overrides.yaml (written once the run directory is claimed), else the job's
    status record (written at job start, so a job rejected before its claim still names its overrides)."""
    f = run_dir / ".hydra" / "overrides.yaml"
    if not f.exists():
        return [str(o) for o in job_status(run_dir).get("overrides", [])]
    from omegaconf import OmegaConf

    return [str(o) for o in OmegaConf.load(f)]


def override_dict(overrides: Sequence[str]) -> dict[str, str]:
    """``["+a.b=1", "c=x"]`` -> ``{"a.b": "1", "c": "x"}``."""
    out = {}
    for o in overrides:
        key, sep, val = o.partition("=")
        if sep:
            out[key.lstrip("+~")] = val
    return out


def label(overrides: Mapping[str, str]) -> str:
    """A directory name for a set of overrides (``all`` for none)."""
    text = ",".join(f"{k}={v}" for k, v in overrides.items()) or "all"
    return re.sub(r"[^A-Za-z0-9._=,+-]", "_", text)[:200]


def job_status(run_dir: Path) -> dict[str, Any]:
    """A run's status record (``.hydra/job_status.json``), ``{}`` when it has none."""
    for f in (run_dir / ".hydra" / JOB_STATUS, run_dir / JOB_STATUS):
        try:
            return dict(json.loads(f.read_text()))
        except FileNotFoundError:
            continue
        except (OSError, ValueError) as e:
            return {"status": "unknown", "error": f"unreadable {f}: {e}"}
    return {}
