"""deltajax: kinematics, workspace, dynamics and design optimisation of Delta robots in JAX.

Public surface only; see README for a tour. Float64 is not switched on at import (that is the caller's
choice: ``jax.config.update("jax_enable_x64", True)``; the CLI does it from ``precision=float64``).
"""

from . import papers, presets
from ._precision import Float32Warning
from .geometry import CHAIN_ANGLES, Delta, GeometryError, ReconfigurableDelta, from_z_up, to_z_up
from .indices import (INDEX_NAMES, Indices, PointKernel, Singularity, classify_singularity, indices,
                      indices_from_singular_values, indices_from_sv, k_tilde, point_indices, point_kernel,
                      sigma_tilde, singular_values, sym3_top2)
from .jacobian import Jacobians, homogenise, jacobian, jacobians, jq_theta, jx_det, jx_row
from .kinematics import (FKResult, IKCosSin, IKResult, LimitTerms, LoopClosure, chain_local, design_ok, elbows,
                         fk, forearm_units, ik, ik_cos_sin, limit_terms, loop_closure, loop_vectors,
                         passive_angles, safe_point)
from . import reference

from . import cycle, dynamics, trajectory
from .cycle import CycleMetrics, Limits, cycle_metrics, cycle_profile
from .dynamics import Torques, inverse_dynamics
from .mass import MassModel
from .trajectory import Cycle, adept_cycle, ga_paper_motion
from . import constraints
from .constraints import (GoodSpec, JointModel, LinkModel, Motor, drive_loads, good_point, interference,
                          joint_angles, picks_per_minute, regular_workspace)
from . import optimize
from . import workspace
from .optimize import DesignSpace, GAConfig, Problem, nsga2, refine, run_ga
from . import mechanism, motion, motion_refine
from .mechanism import DirectRadial, ScrewLinkage, drive_profile, example_screw_linkage, reconfiguration_drive
from .motion import PathResult, RDriveLimits, fixed_path, path_tables, pointwise_path, resolve_path, task_path
from .motion_refine import refine_path
from .runreport import ReportError, write_report  # the main job's HTML run report (plotly imported on use)
from .datasheet import Datasheet, DatasheetError
from .datasheet import datasheet as datasheet  # the function; the module stays importable as deltajax.datasheet
from . import export
from . import tolerance  # Monte Carlo over manufacturing and model tolerances (deltajax.tolerance.analyse)

__version__ = "0.1.0"
