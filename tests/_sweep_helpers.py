"""Helpers shared by the sweep tests (test_sweeps.py: joblib / submitit_local; test_slurm.py: a real SLURM): the
CLI as a subprocess, and results files compared dataset by dataset through deltajax.io.read."""

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from deltajax.io import read


def cli(args, cwd, env, **kw):
    """``python -m deltajax.run ARGS`` started in ``cwd`` (stdout and stderr together)."""
    return subprocess.Popen([sys.executable, "-m", "deltajax.run", *args], cwd=cwd, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, **kw)


def finish(proc, what, timeout, ok=True):
    """Its output once it ends; fails the test when it takes longer than ``timeout`` s or (``ok``) fails."""
    try:
        out, _ = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, _ = proc.communicate()
        pytest.fail(f"{what}: no answer in {timeout} s:\n{out[-4000:]}")
    if ok:
        assert proc.returncode == 0, f"{what} failed (rc {proc.returncode}):\n{out[-4000:]}"
    return out


def job(run_dir):
    """A sweep job's status record (``<run>/.hydra/job_status.json``)."""
    return json.loads((Path(run_dir) / ".hydra" / "job_status.json").read_text())


def rows(sweep):
    """The rows of a sweep's ``summary.json``."""
    return json.loads((Path(sweep) / "summary.json").read_text())["runs"]


def assert_identical(a_path, b_path, skip_attrs=(), same_config=None):
    """Same groups, datasets (bit for bit, NaN = NaN), units, dimensions, dataset and group attributes (but those
    matching a pattern of ``skip_attrs``); with ``same_config`` True/False, whether the configs are equal."""
    a, b = read(a_path), read(b_path)
    assert a.variables.keys() == b.variables.keys()
    for g in b.variables:
        assert a.variables[g].keys() == b.variables[g].keys(), g
        for n, d in b.variables[g].items():
            e = a.variables[g][n]
            assert e.data.dtype == d.data.dtype and e.data.shape == d.data.shape, (g, n)
            assert np.array_equal(e.data, d.data, equal_nan=d.data.dtype.kind in "fc"), (g, n)
            assert (e.units, e.dims, e.attrs) == (d.units, d.dims, d.attrs), (g, n)
        if not g:
            continue  # the root's attributes: start/end times, config (below)
        ka = {k for k in a.group_attrs[g] if not any(re.fullmatch(p, k) for p in skip_attrs)}
        kb = {k for k in b.group_attrs[g] if not any(re.fullmatch(p, k) for p in skip_attrs)}
        assert ka == kb, g
        for k in kb:
            assert np.array_equal(np.asarray(a.group_attrs[g][k]), np.asarray(b.group_attrs[g][k])), (g, k)
    if same_config is not None:
        assert (a.attrs["config"] == b.attrs["config"]) == same_config
