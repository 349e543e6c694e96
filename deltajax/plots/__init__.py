"""Every figure of deltajax, one plotting home (matplotlib, host side only).

Functions take plain NumPy arrays (as saved in results.h5) or the jobs' results and return a
``matplotlib.figure.Figure``; the jobs only hand it to ``ctx.savefig``. No module here selects a backend: the CLI
(:mod:`deltajax.run`) selects Agg once before a job runs, a library user (a notebook) keeps their own.

Modules: :mod:`.core` (shared helpers, actuator line styles), :mod:`.workspace` (workspaces, index slices and
curves, workspace_grid and boundary_search figures), :mod:`.bench` (kernel throughputs), :mod:`.dynamics` (cycle
profiles), :mod:`.datasheet` (the one-page datasheet), :mod:`.motion` (reconfig_motion), :mod:`.designer` (the main
job's GA and Pareto figures), :mod:`.report` (the figures of the main job's self-contained HTML run report, plotly,
imported on first use; written by :mod:`deltajax.runreport`).
"""

from __future__ import annotations

from .bench import bench_rates, bench_rates_from_results
from .core import ACTUATOR_STYLES, actuator_lines, robust_limits
from .datasheet import datasheet_page
from .designer import convergence_series, ga_convergence, ga_pareto
from .dynamics import adept_profiles, cycle_platform, cycle_torques
from .motion import motion_landscape, motion_profiles, motion_torques
from . import report
from .workspace import (boundary_slice, boundary_surface, index_slices, plot_index_curves, workspace_3d,
                        workspace_grid)

__all__ = ["workspace_3d", "index_slices", "robust_limits", "bench_rates", "bench_rates_from_results", "actuator_lines",
           "ACTUATOR_STYLES", "cycle_platform", "cycle_torques", "adept_profiles", "plot_index_curves",
           "workspace_grid", "boundary_slice", "boundary_surface", "motion_landscape", "motion_profiles",
           "motion_torques", "convergence_series", "ga_convergence", "ga_pareto", "report", "datasheet_page"]
