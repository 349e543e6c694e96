"""Build library objects from (Hydra/OmegaConf or plain dict) configuration, validating first: the only code
that knows config paths. One module per settings family; this package ties them together:

- ``readers.py``: the field readers and :class:`ConfigError`;
- ``robot.py``: the robot and its mass model (``robot.*``, :class:`RobotSettings`);
- ``workspace.py``: the grid jobs and the kernel benchmark (workspace_grid, reconfig_workspace, reconfig_indices,
  bench_kernel, indices_examples);
- ``dynamics.py``: dynamics_cycle and datasheet;
- ``boundary.py``: boundary_search;
- ``motion.py``: reconfig_motion;
- ``ga_reconfig.py``: the main job's settings; ``ga_reconfig_run.py``: its run built from them (identity, a
  continued run's earlier run, the setup handed to the job);
- here: the top-level keys and checks, :data:`EXPERIMENT_SETTINGS` (experiment -> settings builder),
  :data:`RUN_DIR_CHECKS`, :data:`ROBOT_SCHEMA`, :data:`EXPERIMENT_SCHEMAS`, :func:`validate_config`,
  :func:`check_keys`, :func:`valid_keys`, and every public name
  of the modules above (``from deltajax.config import X``).

Every error raised here names the config field and the value, before anything is compiled.
"""

from __future__ import annotations

from typing import Any, Mapping, Optional

__all__ = ["ConfigError", "robot_from_config", "mass_from_config", "validate_config", "check_keys", "valid_keys",
           "register_schemas", "TOP_LEVEL_KEYS", "RobotSettings", "ROBOT_SCHEMA",
           "EXPERIMENT_SETTINGS", "EXPERIMENT_SCHEMAS", "SETTINGS_CLASSES", "BenchKernelSettings",
           "PaperGridSettings", "IndicesExamplesSettings", "DatasheetSettings", "GaReconfigSettings", "source_run",
           "WorkspaceGridSettings", "ReconfigIndicesSettings", "grid_plan", "DynamicsCycleSettings",
           "BoundarySearchSettings", "ReconfigMotionSettings",
           "GaReconfigSetup",
           # also re-exported from the modules above (importable from deltajax.config as before the split)
           "check_fits", "read_choice", "read_field", "read_names", "read_vector", "validate_ga_reconfig",
           "validate_ga_reconfig_run_dir", "ga_reconfig_build", "ga_reconfig_settings", "check_reach_over_range",
           "workspace_grid_from_config", "paper_grid_from_config", "workspace_grid_settings", "paper_grid_settings",
           "reconfig_indices_settings", "bench_kernel_settings", "indices_examples_settings", "dynamics_cycle_spec",
           "datasheet_settings", "boundary_search_spec", "MECHANISM_FIELDS", "reconfig_motion_spec",
           "SOURCE_EXPERIMENTS", "R_RANGE_EXPERIMENTS", "RUN_DIR_CHECKS"]


from .readers import (ConfigError, check_fits, read_choice, read_field, read_names,  # noqa: E402,F401
                      read_vector)  # the one set of readers
from .ga_reconfig import GaReconfigSettings, ga_reconfig_settings  # noqa: E402,F401
from .ga_reconfig_run import (GaReconfigSetup, ga_reconfig_build, validate_ga_reconfig,  # noqa: E402,F401
                              validate_ga_reconfig_run_dir)
from .robot import RobotSettings, check_reach_over_range, mass_from_config, robot_from_config  # noqa: E402
from .workspace import (BenchKernelSettings, IndicesExamplesSettings, PaperGridSettings,  # noqa: E402
                        ReconfigIndicesSettings, WorkspaceGridSettings, bench_kernel_settings, grid_plan,
                        indices_examples_settings, paper_grid_from_config, paper_grid_settings,
                        reconfig_indices_settings, workspace_grid_from_config, workspace_grid_settings)
from .dynamics import (DatasheetSettings, DynamicsCycleSettings, datasheet_settings, dynamics_cycle_spec,  # noqa: E402
                       source_run)
from .boundary import BoundarySearchSettings, boundary_search_spec  # noqa: E402
from .motion import MECHANISM_FIELDS, ReconfigMotionSettings, reconfig_motion_spec  # noqa: E402


# =============================================================================================================
# Validation of every experiment field, before anything is computed (called by run.execute after the robot)
# =============================================================================================================
#: Top-level keys of the composed config (configs/config.yaml and the `# @package _global_` experiment files).
TOP_LEVEL_KEYS = ("robot", "experiment", "seed", "precision", "plots", "progress", "compilation_cache", "fresh",
                  "shard", "n_shards", "beta", "source")
#: experiments that read the top-level ``source`` (what they describe); any other experiment refuses it
SOURCE_EXPERIMENTS = ("datasheet",)

def _validate_top(cfg: Mapping[str, Any]) -> None:
    read_field("seed", cfg.get("seed"), kind="int", lo=0, hi=2 ** 32 - 1)  # NumPy's and JAX's seed range
    read_choice("precision", cfg.get("precision"), ("float64", "float32"))
    for k in ("plots", "progress", "fresh"):
        if k in cfg:
            read_field(k, cfg.get(k), kind="bool")
    n_shards = read_field("n_shards", cfg.get("n_shards", 1), kind="int", lo=1)
    read_field("shard", cfg.get("shard", 0), kind="int", lo=0, hi=n_shards - 1)


#: Experiments that use the robot's R range (the others only use the fixed robot, R = base_radius).
R_RANGE_EXPERIMENTS = ("reconfig_workspace", "reconfig_indices", "indices_examples", "ga_reconfig", "dynamics_cycle")

#: experiment name -> builder(experiment cfg, whole cfg, robot, recon) of the job's settings: every field checked
#: (one ConfigError line naming it), returned as the object the run hands to the job (``RunContext.settings``).
EXPERIMENT_SETTINGS = {
    "workspace_grid": workspace_grid_settings,
    "reconfig_workspace": paper_grid_settings,
    "reconfig_indices": reconfig_indices_settings,
    "indices_examples": indices_examples_settings,
    "bench_kernel": bench_kernel_settings,
    "dynamics_cycle": dynamics_cycle_spec,
    "boundary_search": boundary_search_spec,
    "reconfig_motion": reconfig_motion_spec,
    "ga_reconfig": validate_ga_reconfig,
    "datasheet": datasheet_settings,
}


#: experiment name -> a check of its settings against the run directory (``run_dir``), where a setting can name it
RUN_DIR_CHECKS = {"ga_reconfig": validate_ga_reconfig_run_dir}


def validate_config(cfg: Mapping[str, Any], robot=None, recon=None, *, run_dir=None) -> Any:
    """Check every field of the composed config before anything is computed, and build the job's settings.

    Top-level keys (unknown ones rejected, types and ranges), then the experiment block with its builder in
    :data:`EXPERIMENT_SETTINGS` (types, ranges, NaN, cross-field rules). The robot block is checked by
    :func:`robot_from_config`.

    Returns:
        the job's settings (what the run hands to the job as ``RunContext.settings``; the job reads no config).

    Raises:
        ConfigError: one line naming the field (dotted path) and the value.
    """
    check_keys(cfg)
    _validate_top(cfg)
    e = cfg.get("experiment") or {}
    if cfg.get("source") is not None and e.get("name") not in SOURCE_EXPERIMENTS:
        raise ConfigError(f"source={cfg.get('source')!r} is read only by experiment="
                          f"{'|'.join(SOURCE_EXPERIMENTS)}, not by experiment={e.get('name')}")
    if recon is not None and e.get("name") in R_RANGE_EXPERIMENTS:
        check_reach_over_range(cfg.get("robot"), recon)
    if run_dir is not None and e.get("name") in RUN_DIR_CHECKS:
        RUN_DIR_CHECKS[e.get("name")](e, run_dir)
    build = EXPERIMENT_SETTINGS.get(e.get("name"))
    return None if build is None else build(e, cfg, robot, recon)


from ..schemas import schema_keys, unknown_key  # noqa: E402
from ..schemas import register_schemas as _register  # noqa: E402
from .readers import schema_of  # noqa: E402

#: experiment name -> the job's settings dataclass, every config field declared with
#: :func:`deltajax.config.readers.setting` (key, type, default, range, unit, choices)
SETTINGS_CLASSES = {
    "workspace_grid": WorkspaceGridSettings,
    "reconfig_workspace": PaperGridSettings,
    "reconfig_indices": ReconfigIndicesSettings,
    "indices_examples": IndicesExamplesSettings,
    "bench_kernel": BenchKernelSettings,
    "dynamics_cycle": DynamicsCycleSettings,
    "boundary_search": BoundarySearchSettings,
    "reconfig_motion": ReconfigMotionSettings,
    "ga_reconfig": GaReconfigSettings,
    "datasheet": DatasheetSettings,
}
#: experiment name -> its structured-config schema (``schema/experiment/<name>``), generated from its settings
#: (:func:`deltajax.config.readers.schema_of`): the keys and types Hydra composes against are declared where the
#: ranges :func:`deltajax.config.readers.read_settings` checks are
EXPERIMENT_SCHEMAS = {name: schema_of(cls, f"{cls.__name__}Schema") for name, cls in SETTINGS_CLASSES.items()}
#: the robot block's structured-config schema (``schema/robot``, name ``delta``), generated from
#: :class:`RobotSettings` as the experiments' are from theirs
ROBOT_SCHEMA = schema_of(RobotSettings, "RobotSchema")


def register_schemas() -> None:
    """Register every schema in Hydra's ConfigStore (idempotent; run.py calls it at import)."""
    _register(ROBOT_SCHEMA, EXPERIMENT_SCHEMAS)


def check_keys(cfg: Mapping[str, Any]) -> None:
    """Reject keys that no schema knows, including those added with ``+key=value`` (Hydra adds them even to a
    structured config), listing the valid keys of that block.

    Raises:
        ConfigError: one line naming the unknown key and the valid ones.
    """
    extra = [k for k in cfg.keys() if k not in TOP_LEVEL_KEYS]
    if extra:
        raise ConfigError(f"unknown top-level key(s) {', '.join(map(str, extra))}; "
                          f"valid keys: {', '.join(TOP_LEVEL_KEYS)}")
    e = cfg.get("experiment")
    blocks = (("robot", cfg.get("robot"), ROBOT_SCHEMA),
              ("experiment", e, EXPERIMENT_SCHEMAS.get(e.get("name")) if e is not None else None))
    for path, node, schema in blocks:
        msg = None if node is None or schema is None else unknown_key(node, schema, path)
        if msg is not None:
            raise ConfigError(msg)


def valid_keys(full_key: str, experiment: Optional[str] = None) -> Optional[list]:
    """The valid keys of the block holding ``full_key`` (e.g. ``"robot.forarm"`` -> the robot's keys), from the
    schemas; ``None`` when no schema covers it. For error messages of Hydra's composition, which name the
    unknown key but not the valid ones (``Key 'forarm' not in 'RobotSchema'``)."""
    parts = full_key.split(".")
    if len(parts) == 1:
        return list(TOP_LEVEL_KEYS)
    schema = ROBOT_SCHEMA if parts[0] == "robot" else EXPERIMENT_SCHEMAS.get(experiment or "")
    if parts[0] not in ("robot", "experiment") or schema is None:
        return None
    return schema_keys(schema, parts[1:-1])
