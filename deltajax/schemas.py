"""Hydra structured-config schemas: the keys and types of the robot block and of every experiment block.

Registered in the ConfigStore by :func:`register_schemas` (``deltajax.run`` calls it at import). A mistyped key,
a wrong type or an unknown ``+key`` is rejected at composition (``configs/config.yaml`` puts
``schema/robot`` before the robot group and ``schema/experiment/<name>`` before the experiment group;
``optional``: an experiment without a schema is validated by its job only). Values and defaults live in the
YAML files; ranges and cross-field rules are checked by :func:`deltajax.config.validate_config`. Pure data:
imports nothing from deltajax.
"""

from __future__ import annotations

import dataclasses
from typing import Any, Dict, List, Optional

__all__ = ["RobotSchema", "EXPERIMENT_SCHEMAS", "register_schemas", "unknown_key", "schema_keys"]

_REQ = "???"  # omegaconf.MISSING: the YAML must give a value


def _list(*items):
    return dataclasses.field(default_factory=lambda: list(items))


@dataclasses.dataclass
class RRangeSchema:
    min: Optional[float] = None
    max: Optional[float] = None
    step: Optional[float] = None


@dataclasses.dataclass
class MassSchema:
    upper_arm_mass: Optional[float] = None
    upper_arm_com_fraction: Optional[float] = None
    upper_arm_inertia_factor: Optional[float] = None
    upper_arm_inertia: Optional[float] = None
    rotor_inertia: Optional[float] = None
    gear_ratio: Optional[float] = None
    elbow_mass: Optional[float] = None
    forearm_mass: Optional[float] = None
    forearm_elbow_fraction: Optional[float] = None
    forearm_model: Optional[str] = None  # rigid_rod | point_split (deltajax/mass.py validates the value)
    forearm_inertia_factor: Optional[float] = None
    platform_mass: Optional[float] = None
    payload_mass: Optional[float] = None
    carriage_mass: Optional[float] = None
    gravity: Optional[float] = None


@dataclasses.dataclass
class RobotSchema:
    name: str = "custom"
    base_radius: Optional[float] = None
    platform_radius: Optional[float] = None
    upper_arm: Optional[float] = None
    forearm: Optional[float] = None
    theta_min_deg: Optional[float] = None
    theta_max_deg: Optional[float] = None
    R_range: Optional[RRangeSchema] = None
    mass: Optional[MassSchema] = None


@dataclasses.dataclass
class GridSchema:
    x: Optional[List[float]] = None
    y: Optional[List[float]] = None
    z: Optional[List[float]] = None
    h: float = _REQ
    bounds: Optional[List[List[float]]] = None


@dataclasses.dataclass
class WorkspaceGridSchema:
    name: str = "workspace_grid"
    grid: GridSchema = dataclasses.field(default_factory=GridSchema)
    b_v: float = _REQ
    b_f: float = _REQ
    beta: float = _REQ
    store: List[str] = _list()
    chunk_points: int = _REQ
    backend: str = "auto"
    devices: Any = "all"  # 'all' or a count
    checkpoint_s: float = 60.0
    resume: bool = True
    stop_after: Optional[int] = None


@dataclasses.dataclass
class ReconfigWorkspaceSchema:
    name: str = "reconfig_workspace"
    h: float = _REQ
    chunk_points: int = _REQ
    checkpoint: bool = True


@dataclasses.dataclass
class ReconfigIndicesSchema:
    name: str = "reconfig_indices"
    h: float = _REQ
    criterion: str = "k_tilde"
    mode: str = "fast"
    b_v: float = _REQ
    b_f: float = _REQ
    slices_z: List[float] = _list()
    slice_index: str = "omega_v"
    chunk_points: int = _REQ
    checkpoint: bool = True
    store_fields: List[str] = _list()


@dataclasses.dataclass
class IndicesExamplesSchema:
    name: str = "indices_examples"
    R_step: float = _REQ
    points: List[List[float]] = _list()
    b_v: float = _REQ
    b_f: float = _REQ
    beta: float = _REQ
    matrix: str = "theta3x3"


@dataclasses.dataclass
class BenchKernelSchema:
    name: str = "bench_kernel"
    n_points: int = _REQ
    n_baseline: int = _REQ
    block: int = 4096
    repeats: int = _REQ
    R: float = _REQ
    dtypes: List[str] = _list()


@dataclasses.dataclass
class CycleSetupSchema:
    centre: List[float] = _list()
    heading_deg: float = 0.0
    duration: float = _REQ
    torque_limit: float = _REQ
    speed_limit: float = _REQ


@dataclasses.dataclass
class GAMotionSchema:
    amplitude: float = _REQ
    duration: float = _REQ


@dataclasses.dataclass
class DynamicsCycleSchema:
    name: str = "dynamics_cycle"
    robots: List[str] = _list()
    method: str = "virtual_work"
    n_samples: int = _REQ
    law: str = "poly5"
    blend: float = _REQ
    setups: Dict[str, CycleSetupSchema] = dataclasses.field(default_factory=dict)
    ga_motion: GAMotionSchema = dataclasses.field(default_factory=GAMotionSchema)
    recon_R_amplitude: float = _REQ


@dataclasses.dataclass
class BoundarySearchSchema:
    name: str = "boundary_search"
    centre: List[float] = _list()
    eps: float = _REQ
    steps_deg: List[float] = _list()
    rho_max: float = _REQ
    predictor: str = "tangent"
    half_space: bool = True
    volume_rule: str = "pyramid"
    profile_samples: int = _REQ
    grid_h: float = _REQ
    grid_box: List[List[float]] = _list()
    centre_sweep_z: List[float] = _list()
    sweep_step_deg: float = _REQ
    timing_repeats: int = _REQ


@dataclasses.dataclass
class MotorSchema:
    peak_torque: float = _REQ
    rated_torque: float = _REQ
    max_speed: float = _REQ
    corner_speed: float = _REQ
    rotor_inertia: float = 0.0
    efficiency: float = 1.0


@dataclasses.dataclass
class DatasheetSchema:
    name: str = "datasheet"
    payloads: List[float] = _list()
    vendor_dwell: float = _REQ
    hd_ratio: float = _REQ
    volume_h: float = _REQ
    n_samples: int = _REQ
    cylinder_grid: List[int] = _list()
    centre: Optional[List[float]] = None
    R: Optional[float] = None
    motor: MotorSchema = dataclasses.field(default_factory=MotorSchema)
    gear_ratio: float = _REQ


# ga_reconfig's schema is generated from its settings (deltajax.config: readers.schema_of(GaReconfigSettings)).


#: experiment name -> schema, registered as ``schema/experiment/<name>``.
EXPERIMENT_SCHEMAS = {
    "workspace_grid": WorkspaceGridSchema,
    "reconfig_workspace": ReconfigWorkspaceSchema,
    "reconfig_indices": ReconfigIndicesSchema,
    "indices_examples": IndicesExamplesSchema,
    "bench_kernel": BenchKernelSchema,
    "dynamics_cycle": DynamicsCycleSchema,
    "boundary_search": BoundarySearchSchema,
    "datasheet": DatasheetSchema,
}


def register_schemas(experiments: Optional[Dict[str, Any]] = None) -> None:
    """Register the schemas in Hydra's ConfigStore (idempotent; run.py calls it at import, through
    :func:`deltajax.config.register_schemas`, with the generated ones added): ``experiments`` name -> schema,
    default :data:`EXPERIMENT_SCHEMAS`."""
    from hydra.core.config_store import ConfigStore

    cs = ConfigStore.instance()
    cs.store(group="schema/robot", name="delta", node=RobotSchema)
    for name, node in (EXPERIMENT_SCHEMAS if experiments is None else experiments).items():
        cs.store(group="schema/experiment", name=name, node=node)


# ---- walking the schemas (deltajax.config turns the answers into ConfigError lines) ----
def _schema_fields(schema) -> dict:
    import typing

    hints = typing.get_type_hints(schema)
    return {f.name: hints[f.name] for f in dataclasses.fields(schema)}


def _unwrap(tp):
    """The dataclass inside Optional[...] / Dict[str, ...] annotations: (dataclass or None, is_dict)."""
    import typing

    args = typing.get_args(tp)
    origin = typing.get_origin(tp)
    if origin is typing.Union:
        inner = [a for a in args if a is not type(None)]
        return _unwrap(inner[0]) if len(inner) == 1 else (None, False)
    if origin in (dict, Dict) and len(args) == 2 and dataclasses.is_dataclass(args[1]):
        return args[1], True
    if dataclasses.is_dataclass(tp):
        return tp, False
    return None, False


def unknown_key(node: Any, schema, path: str) -> Optional[str]:
    """The first key of ``node`` (a mapping at dotted ``path``) that ``schema`` does not know, as a message that
    lists the valid keys of that block; ``None`` when every key is known (nested blocks included)."""
    if not hasattr(node, "keys"):
        return None
    fields = _schema_fields(schema)
    for k in node.keys():
        if k not in fields:
            return f"{path}.{k} is not a setting of {path}; valid keys: {', '.join(sorted(fields))}"
        sub, is_dict = _unwrap(fields[k])
        v = node.get(k)
        if sub is None or v is None:
            continue
        for sub_path, sub_node in ([(f"{path}.{k}.{n}", v.get(n)) for n in v.keys()] if is_dict
                                   else [(f"{path}.{k}", v)]):
            msg = unknown_key(sub_node, sub, sub_path)
            if msg is not None:
                return msg
    return None


def schema_keys(schema, inner: List[str]) -> Optional[list]:
    """The sorted keys of the block reached from ``schema`` through the field names ``inner``; ``None`` when
    that is not a (non-dict) schema block."""
    for name in inner:
        fields = _schema_fields(schema)
        if name not in fields:
            return None
        sub, is_dict = _unwrap(fields[name])
        if sub is None or is_dict:
            return None
        schema = sub
    return sorted(_schema_fields(schema))
