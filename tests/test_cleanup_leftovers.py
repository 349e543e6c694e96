"""Leftovers of the layout/sweeps/usability branches (cleanup): one grid reader, units in config errors, progress
bars with the right totals, dynamics_cycle's plots in plots.py, rundir reading HDF5 through io.read."""

import pytest

from deltajax import config as C
from deltajax.config import ConfigError


def test_one_grid_reader_in_config():
    from deltajax.jobs import workspace_grid as job

    assert not hasattr(job, "_grid_from_config")
    assert job.workspace_grid_from_config is C.workspace_grid_from_config
