"""deltajax: kinematics, workspace, dynamics and design optimisation of Delta robots in JAX.

The names a user needs (:data:`__all__`); everything else lives in its module (``deltajax.kinematics``,
``deltajax.indices``, ``deltajax.motion``, ``deltajax.optimize``, ...). See the README for a tour. Float64 is not
switched on at import (that is the caller's choice: ``jax.config.update("jax_enable_x64", True)``; the CLI does it
from ``precision=float64``).
"""

from . import papers, presets
from ._precision import Float32Warning
from .geometry import Delta, GeometryError, ReconfigurableDelta, from_z_up, to_z_up
from .kinematics import elbows, fk, ik, ik_cos_sin, passive_angles
from .jacobian import jacobian, jacobians
from .indices import INDEX_NAMES, classify_singularity, indices, point_indices
from .mass import MassModel
from .dynamics import inverse_dynamics
from .trajectory import Cycle, adept_cycle, ga_paper_motion
from .cycle import Limits, cycle_metrics, cycle_profile
from .constraints import (GoodSpec, JointModel, LinkModel, good_point, interference, joint_angles,
                          regular_workspace)
from .drive import Motor, drive_loads, picks_per_minute
from .motion import RDriveLimits, resolve_path
from .motion_refine import refine_path
from .datasheet import Datasheet, DatasheetError
from .datasheet import datasheet as datasheet  # the function; the module stays importable as deltajax.datasheet
from .runreport import ReportError, write_report  # the main job's HTML run report (plotly imported on use)
from .optimize.certify import certify_design as certify  # worst cases found, the density doubled, margins
from . import (constraints, cycle, drive, dynamics, export, io, kinematics, mechanism, motion, optimize, reference,
               tolerance, trajectory, workspace)

__version__ = "0.1.0"

__all__ = [
    # robots and conventions
    "Delta", "ReconfigurableDelta", "GeometryError", "Float32Warning", "to_z_up", "from_z_up", "presets", "papers",
    # kinematics, Jacobians, indices
    "ik", "fk", "ik_cos_sin", "passive_angles", "elbows", "jacobian", "jacobians", "indices", "point_indices",
    "INDEX_NAMES", "classify_singularity",
    # dynamics and cycles
    "MassModel", "inverse_dynamics", "Cycle", "adept_cycle", "ga_paper_motion", "cycle_profile", "cycle_metrics",
    "Limits",
    # the designer's constraints
    "GoodSpec", "JointModel", "LinkModel", "Motor", "good_point", "interference", "joint_angles", "drive_loads",
    "picks_per_minute", "regular_workspace",
    # reconfiguration in motion
    "RDriveLimits", "resolve_path", "refine_path",
    # trusting a design: worst cases found and doubling checked (deltajax.optimize.certify), tolerances
    # (deltajax.tolerance.analyse)
    "certify", "tolerance",
    # taking a design out
    "datasheet", "Datasheet", "DatasheetError", "write_report", "ReportError",
    # modules
    "workspace", "optimize", "constraints", "drive", "kinematics", "cycle", "dynamics", "trajectory", "motion",
    "mechanism", "export", "io", "reference",
]
