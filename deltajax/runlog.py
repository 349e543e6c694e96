"""Logging of a run: ``<run_dir>/run.log`` written only while the run owns its directory, console lines routed
through the progress bars, and the same routing for a run started from Python.

Under the CLI the handlers come from ``configs/hydra/job_logging/deltajax.yaml`` (:class:`BelowWarning`,
:class:`RunLogHandler`); :func:`deltajax.run.run_experiment` adds the equivalent ones itself (:func:`api_logging`).
:func:`deltajax.run.execute` opens the run log (:func:`run_log_open`) once it has claimed the run directory and
runs the job inside :func:`console_through_tqdm`.
"""

from __future__ import annotations

import contextlib
import logging
import sys
from pathlib import Path

__all__ = ["BelowWarning", "RunLogHandler", "TqdmHandler", "api_logging", "console_through_tqdm", "run_log_open"]

log = logging.getLogger("deltajax")


class TqdmHandler(logging.StreamHandler):
    """A console handler that writes through ``tqdm.write`` so a log line never breaks a progress bar."""

    def emit(self, record):
        from tqdm import tqdm

        try:
            tqdm.write(self.format(record), file=self.stream)
            self.flush()
        except Exception:  # noqa: BLE001 - logging must not raise
            self.handleError(record)


@contextlib.contextmanager
def console_through_tqdm():
    """Route every console logging handler of the root logger through ``tqdm.write`` (keeping its stream,
    level, formatter and filters; ``tqdm.contrib.logging.logging_redirect_tqdm`` keeps only the first one)."""
    root = logging.getLogger()
    saved = list(root.handlers)
    new = []
    for h in saved:
        if type(h) is logging.StreamHandler and h.stream in (sys.stdout, sys.stderr):
            t = TqdmHandler(h.stream)
            t.setLevel(h.level)
            t.setFormatter(h.formatter)
            for f in h.filters:
                t.addFilter(f)
            new.append(t)
        else:
            new.append(h)
    root.handlers = new
    try:
        yield
    finally:
        root.handlers = saved


class RunLogHandler(logging.FileHandler):
    """``<run_dir>/run.log``: written only while this process owns the run directory (between the claim in
    :func:`deltajax.run.execute` and the end of the run), so a refused rerun or a rejected config leaves another
    run's log, and a directory it never claimed, untouched. Lines before the claim still reach the console."""

    _active = False  # class-wide: one run at a time per process

    def __init__(self, filename, mode: str = "a", encoding=None, delay: bool = True, errors=None):
        super().__init__(filename, mode, encoding, delay=True, errors=errors)

    def emit(self, record: logging.LogRecord) -> None:
        if RunLogHandler._active:
            super().emit(record)


@contextlib.contextmanager
def run_log_open():
    """While the run owns its directory: :class:`RunLogHandler` writes, and its file is closed afterwards."""
    RunLogHandler._active = True
    try:
        yield
    finally:
        RunLogHandler._active = False
        for h in logging.getLogger().handlers:
            if isinstance(h, RunLogHandler):
                h.close()  # reopened (delay) by the next run's first line


class BelowWarning(logging.Filter):
    """Logging filter (used by ``configs/hydra/job_logging/deltajax.yaml``): records below WARNING only, so
    the run's lines go to stdout and warnings/errors to stderr."""

    def filter(self, record: logging.LogRecord) -> bool:
        return record.levelno < logging.WARNING


@contextlib.contextmanager
def api_logging(run_dir: Path):
    """Logging for :func:`deltajax.run.run_experiment`: the run's lines always go to ``<run_dir>/run.log`` (as
    under the CLI) and, when the caller has configured no logging, to stdout (warnings and errors to stderr)."""
    root = logging.getLogger()
    # opened only once the run directory is claimed: a config rejected before that leaves no directory behind
    file = RunLogHandler(run_dir / "run.log")
    file.setFormatter(logging.Formatter("[%(asctime)s][%(name)s][%(levelname)s] - %(message)s"))
    file.setLevel(logging.INFO)
    added = [file]
    if not root.handlers:
        out = logging.StreamHandler(sys.stdout)
        out.setFormatter(logging.Formatter("%(message)s"))
        out.addFilter(BelowWarning())
        err = logging.StreamHandler(sys.stderr)
        err.setLevel(logging.WARNING)
        err.setFormatter(logging.Formatter("%(levelname)s: %(message)s"))
        added += [out, err]
    level = log.level
    if log.getEffectiveLevel() > logging.INFO:
        log.setLevel(logging.INFO)  # the run's INFO lines reach run.log whatever the root level is
    for h in added:
        root.addHandler(h)
    try:
        yield
    finally:
        for h in added:
            root.removeHandler(h)
        log.setLevel(level)
        file.close()
