"""Configuration values checked against what they mean before anything runs (deltajax.config.validate_config):
sizes against the machine's memory (estimated, never built), integers and ranges, cross-field rules (index
thresholds in the index's range, points below the base, boxes of positive width, search centres inside the
workspace), messages in the units the user wrote."""

import time

import pytest

from _config_helpers import compose, validate
from deltajax.config import ConfigError


REFUSED = [
    # sizes: estimated from the settings, refused with the estimate (the grid is never built)
    ("workspace_grid", ["experiment.grid.h=1e-5"], r"^experiment.grid.h=1e-05 m needs at least .* GiB of memory "
                                                   r"for a grid of \d+ x \d+ x \d+ = .* points, more than the "
                                                   r".* GiB this machine has$"),
    ("reconfig_indices", ["experiment.h=1e-5"], r"^experiment.h=1e-05 m needs at least .* GiB of memory"),
    ("ga_reconfig", ["experiment.ga.population_size=100000000"],
     r"^experiment.ga.population_size=100000000 needs at least .* GiB of memory for 1e\+08 designs"),
    ("ga_reconfig", ["experiment.pareto.population_size=100000000"],
     r"^experiment.pareto.population_size=100000000 needs at least .* GiB"),
    ("ga_reconfig", ["experiment.verify.task_n_r=100000000000"],
     r"^experiment.verify=\{.*'task_n_r': 100000000000.*\} needs at least .* GiB of memory for .* evaluated points"),
    ("bench_kernel", ["experiment.n_points=100000000000000"], r"^experiment.n_points=100000000000000 needs at least"),
    ("reconfig_indices", ["robot.R_range.step=1e-13"],
     r"^robot.R_range.step=1e-13 m needs at least .* GiB of memory for the R samples"),
    ("indices_examples", ["experiment.R_step=1e-13"], r"^experiment.R_step=1e-13 m needs at least .* GiB"),
    ("reconfig_motion", ["experiment.R_step=1e-13"], r"^experiment.R_step=1e-13 m needs at least .* GiB"),
    ("reconfig_motion", ["experiment.cases.adept.n_samples=100000000001"],
     r"^experiment.cases.adept.n_samples=100000000001 needs at least .* GiB"),
    ("dynamics_cycle", ["experiment.n_samples=100000000001"],
     r"^experiment.n_samples=100000000001 needs at least .* GiB of memory for 2 cycles"),
    # integers in their range
    ("workspace_grid", ["seed=-1"], r"^seed must be in \[0, 4294967295\], got -1$"),
    ("workspace_grid", ["seed=4294967296"], r"^seed must be in \[0, 4294967295\], got 4294967296$"),
    # cross-field rules
    ("ga_reconfig", ["experiment.good_workspace.threshold=1.5"],
     r"^experiment.good_workspace.threshold must be in \[0, 1\], got 1.5$"),
    ("workspace_grid", ["experiment.grid.x=[0.0,0.0]"],
     r"^experiment.grid.x must be \[lo, hi\] with lo < hi \(m\), got \[0.0, 0.0\]$"),
    ("boundary_search", ["experiment.centre=[0,0,-5]"],
     r"^experiment.centre=\[0.0, 0.0, -5.0\] m puts the search centre \[0.0, 0.0, -5.0\] m outside the robot's "
     r"workspace"),
    ("boundary_search", ["experiment.centre_sweep_z=[1.5,9.0]"],
     r"^experiment.centre_sweep_z\[1\]=9.0 m puts the search centre \[0.0, 0.0, 9.0\] m outside"),
    ("reconfig_indices", ["experiment.slices_z=[-1.0]"], r"^experiment.slices_z\[0\] must be in \(0, 0.598\] m, "
                                                         r"got -1.0 m$"),
    ("reconfig_indices", ["experiment.slices_z=[0.9]"], r"^experiment.slices_z\[0\] must be in \(0, 0.598\] m"),
    ("indices_examples", ["experiment.points=[[0.0,0.0,-0.3]]"],
     r"^experiment.points\[0\]=\[0.0, 0.0, -0.3\] m lies above the base plane: .*got z = -0.3 m$"),
    # the units the user wrote (lead in m per screw turn, not the linkage's pitch in m/rad)
    ("reconfig_motion", ["experiment.mechanism.lead=-0.01"], r"^experiment.mechanism.lead must be > 0 m, got -0.01 m$"),
    ("reconfig_motion", ["experiment.mechanism.efficiency=1.5"],
     r"^experiment.mechanism.efficiency must be in \(0, 1\], got 1.5$"),
]


@pytest.mark.parametrize("experiment, overrides, message", REFUSED, ids=[" ".join(r[1]) for r in REFUSED])
def test_refused_in_one_line_naming_the_field_within_seconds(experiment, overrides, message):
    cfg = compose(experiment, *overrides)
    t0 = time.perf_counter()
    with pytest.raises(ConfigError, match=message) as err:
        validate(cfg)
    assert "\n" not in str(err.value)
    assert time.perf_counter() - t0 < 10


def test_reachable_centre_and_points_below_the_base_are_accepted():
    validate(compose("boundary_search"))
    validate(compose("indices_examples", "experiment.points=[[0.0,0.0,0.3]]"))
    validate(compose("reconfig_indices", "experiment.slices_z=[0.4]"))
    validate(compose("ga_reconfig", "experiment.good_workspace.threshold=1.0"))


@pytest.mark.parametrize("override, message", [
    ("experiment.joints.limit_deg=200", r"^experiment.joints.limit_deg must be in \(0, 180\] deg, got 200.0 deg$"),
    ("experiment.motor.peak_torque=-1", r"^experiment.motor.peak_torque must be > 0 N m, got -1.0 N m$"),
    ("experiment.cycle.dwell=-0.1", r"^experiment.cycle.dwell must be >= 0 s, got -0.1 s$"),
    ("experiment.task.diameter=0", r"^experiment.task.diameter must be > 0 m, got 0.0 m$"),
])
def test_ga_reconfig_messages_carry_the_units_written(override, message):
    with pytest.raises(ConfigError, match=message):
        validate(compose("ga_reconfig", override))


# -- settings declared once: the generic reader of a settings dataclass (deltajax.config.readers) ---------------
def test_settings_are_read_from_their_declared_metadata():
    import dataclasses
    from typing import Optional

    from deltajax.config.readers import read_settings, setting

    @dataclasses.dataclass(frozen=True, kw_only=True)
    class Inner:
        speed: float = setting(lo=0, lo_open=True, unit="m/s")
        law: str = setting("poly5", choices=("poly5", "cycloidal"))

    @dataclasses.dataclass(frozen=True, kw_only=True)
    class Outer:
        n: int = setting(lo=2)
        limit: Optional[float] = setting(None, lo=0, hi=180, hi_open=True, unit="deg")
        inner: Inner = setting(Inner(speed=1.0))
        flag: bool = setting()
        n_squared: int = 0          # derived: no config key, filled in by _check

        def _check(self, path):
            if self.limit is not None and self.limit > 10 * self.n:
                raise ConfigError(f"{path}.limit={self.limit!r} deg must be <= 10 x {path}.n")
            return dataclasses.replace(self, n_squared=self.n ** 2)

    ok = read_settings(Outer, {"n": 3, "flag": True, "inner": {"speed": 2}}, "experiment")
    assert ok == Outer(n=3, flag=True, inner=Inner(speed=2.0, law="poly5"), limit=None, n_squared=9)
    assert isinstance(ok.inner.speed, float)
    assert read_settings(Outer, {"n": 3, "flag": False}, "e").inner == Inner(speed=1.0)   # a default block
    bad = [({"n": 1, "flag": True}, r"^e\.n must be >= 2, got 1$"),
           ({"n": 2.5, "flag": True}, r"^e\.n must be an integer, got 2\.5$"),
           ({"n": 3, "flag": "yes"}, r"^e\.flag must be true or false, got 'yes'$"),
           ({"n": 3, "flag": True, "limit": 180}, r"^e\.limit must be in \[0, 180\) deg, got 180\.0 deg$"),
           ({"n": 3, "flag": True, "limit": 31}, r"^e\.limit=31\.0 deg must be <= 10 x e\.n$"),      # its _check
           ({"n": 3, "flag": True, "inner": {"speed": 0}}, r"^e\.inner\.speed must be > 0 m/s, got 0\.0 m/s$"),
           ({"n": 3, "flag": True, "inner": {"speed": 1, "law": "x"}},
            r"^e\.inner\.law must be one of cycloidal, poly5, got 'x'$"),
           ({"n": 3, "flag": True, "inner": {}}, r"^e\.inner: missing keys speed$"),
           ({"n": 3}, r"^e: missing keys flag$"),
           ({"n": 3, "flag": "???"}, r"^e: missing keys flag$"),     # left MISSING by the structured config
           ({"n": 3, "flag": True, "speed": 1}, r"^e: unknown keys speed; valid keys: flag, inner, limit, n$"),
           ({"n": 3, "flag": True, "n_squared": 4}, r"^e: unknown keys n_squared; "),                # derived
           ([1, 2], r"^e must be a mapping, got \[1, 2\]$")]
    for block, match in bad:
        with pytest.raises(ConfigError, match=match):
            read_settings(Outer, block, "e")


# -- the grid jobs and the kernel benchmark: refusals by their settings' metadata, derived fields ---------------
from deltajax import config as C  # noqa: E402


@pytest.mark.parametrize("experiment, override, message", [
    ("workspace_grid", "experiment.grid.h=0", r"^experiment.grid.h must be > 0 m, got 0.0 m$"),
    ("workspace_grid", "experiment.backend=cuda", r"^experiment.backend must be one of auto, jax, numba, got 'cuda'$"),
    ("workspace_grid", "experiment.devices=0", r"^experiment.devices must be >= 1, got 0$"),
    ("workspace_grid", "experiment.checkpoint_s=-1", r"^experiment.checkpoint_s must be >= 0 s, got -1.0 s$"),
    ("workspace_grid", "experiment.store=[volume]", r"^experiment.store entry must be one of .*, got 'volume'$"),
    ("workspace_grid", "experiment.grid.x=null",
     r"^experiment.grid.bounds must be null when the grid is sized from the reach bound \(experiment.grid.x=null\)"),
    ("workspace_grid", "experiment.grid.bounds=[[0.0,1.0]]",
     r"^experiment.grid.bounds must be null or \[\[x0,x1\],\[y0,y1\],\[z0,z1\]\] \(m\), got \[\[0.0, 1.0\]\]$"),
    ("reconfig_workspace", "experiment.chunk_points=0", r"^experiment.chunk_points must be >= 1, got 0$"),
    ("reconfig_indices", "experiment.criterion=volume", r"^experiment.criterion must be one of .*, got 'volume'$"),
    ("reconfig_indices", "experiment.mode=slow", r"^experiment.mode must be one of exact, fast, got 'slow'$"),
    ("reconfig_indices", "beta=1.0", r"^beta must be in \(0, 1\), got 1.0$"),
    ("bench_kernel", "experiment.dtypes=[]", r"^experiment.dtypes must list at least 1 of float32, float64, got \[\]$"),
    ("bench_kernel", "experiment.R=0", r"^experiment.R must be > 0 m, got 0.0 m$"),
    ("bench_kernel", "precision=float32", r"^experiment.dtypes lists float64, which needs precision=float64"),
    ("indices_examples", "experiment.matrix=full", r"^experiment.matrix must be one of full3x4, theta3x3, got 'full'$"),
    ("indices_examples", "experiment.beta=0", r"^experiment.beta must be in \(0, 1\), got 0.0$"),
])
def test_workspace_job_settings_refused_by_their_metadata(experiment, override, message):
    cfg = compose(experiment, override)
    with pytest.raises(ConfigError, match=message) as err:
        validate(cfg)
    assert "\n" not in str(err.value)


def test_workspace_grid_builder_fills_in_what_the_block_lacks():
    """The builder's derived fields: the grid built from the block (a null axis sized from the robot's reach
    bound on whole steps of h), the backend resolved (auto: jax in float32), the shard of the top-level keys, the
    devices resolved and the shard plan."""
    from deltajax.workspace import Grid
    from deltajax.workspace.driver import reach_box

    cfg = compose("workspace_grid", "experiment.grid.h=0.1", "experiment.grid.z=[0.0,0.6]", "experiment.grid.x=null",
                  "experiment.grid.bounds=null", "precision=float32", "n_shards=2", "shard=1",
                  "experiment.chunk_points=63")
    robot, recon = C.robot_from_config(cfg.robot)
    s = C.validate_config(cfg, robot, recon)
    lo, hi = reach_box(robot)[0]
    g = s.built_grid
    assert isinstance(g, Grid) and g.x[0] <= lo and g.x[-1] >= hi and g.h == 0.1 and s.grid.x is None  # the block
    assert s.backend == "jax" and (s.shard, s.n_shards, s.precision) == (1, 2, "float32") and s.n_dev >= 1
    assert s.plan.x_start > 0 and s.plan.x_stop == g.shape[0]
    assert s.params == {"b_v": 2.0, "b_f": 4.2, "beta": 0.5} and s.robot_key["forearm"] == str(cfg.robot.forearm)


# -- every job's settings declared once, and its structured config generated from them ------------------------
def _inner_blocks():
    """The blocks read by a field's own reader (so not walked as nested dataclasses): dotted key -> ("one": the
    block, "each": one block per entry of a mapping, its class by its ``kind`` where there are several; classes)."""
    from deltajax.config import dynamics as D, motion as M

    return {"dynamics_cycle": {"setups": ("each", [D.CycleSetupBlock])},
            "reconfig_motion": {"mechanism": ("one", [M.MechanismBlock]),
                                "cases": ("each", [M.AdeptCaseBlock, M.TaskCaseBlock])}}


#: numbers whose every finite value is meaningful (no range of their own): a heading, an offset, the
#: good-workspace threshold (its range is the chosen index's, checked by its block) and the robot's joint limits
#: (their order and span are the geometry's rule, deltajax.Delta.from_degrees)
_ANY_NUMBER = {"heading_deg", "d3", "threshold", "theta_min_deg", "theta_max_deg"}
#: strings checked against another setting, not a fixed list: the primary objective (one of the objectives)
_FREE_STRING = {"name", "primary"}


def _config_fields(cls):
    import dataclasses

    return [f for f in dataclasses.fields(cls) if "deltajax" in f.metadata]


def _check_block(cls, block, path):
    """Every config field of ``cls`` declares how it is checked; ``block`` (the default YAML's; None: the YAML's
    block is null, so only the declaration is checked) has exactly its config fields (the required ones at least),
    in the order declared."""
    import dataclasses
    import typing

    fields = _config_fields(cls)
    names = [f.name for f in fields]
    if block is not None:
        assert set(block) <= set(names), f"{path}: YAML keys {sorted(set(block) - set(names))} are no settings"
        required = [f.name for f in fields if f.default is dataclasses.MISSING
                    and f.default_factory is dataclasses.MISSING]
        assert set(required) <= set(block), f"{path}: required settings {set(required) - set(block)} not in the YAML"
        assert [n for n in names if n in block] == list(block), f"{path}: fields not ordered as the YAML"
    hints = typing.get_type_hints(cls)
    for f in fields:
        spec = f.metadata["deltajax"]
        tp = hints[f.name]
        tp = next((a for a in typing.get_args(tp) if a is not type(None)), tp)   # Optional[X] -> X
        if tp in (int, float) and spec.read is None and f.name not in _ANY_NUMBER:
            assert spec.lo is not None or spec.hi is not None, f"{path}.{f.name}: no range"
        if tp is str and spec.read is None and f.name not in _FREE_STRING:
            assert spec.choices is not None, f"{path}.{f.name}: a string without choices"
        if dataclasses.is_dataclass(tp) and spec.read is None:
            _check_block(tp, None if block is None else block.get(f.name, {}), f"{path}.{f.name}")


@pytest.mark.parametrize("job", sorted(C.SETTINGS_CLASSES))
def test_every_job_setting_declares_how_it_is_checked(job):
    """Each job's settings mirror its YAML key for key (name included, nested blocks as blocks, in the YAML's
    order); every config field carries setting() metadata (a field without is derived: no YAML key), every
    number a range or its own reader, every string its choices; the default config reads without a refusal."""
    from omegaconf import OmegaConf

    cls = C.SETTINGS_CLASSES[job]
    cfg = compose(job)
    e = OmegaConf.to_container(cfg.experiment, resolve=True)
    _check_block(cls, e, "experiment")
    for key, (how, classes) in _inner_blocks().get(job, {}).items():    # blocks read by a field's own reader
        node = e
        for part in key.split("."):
            node = node[part]
        items = {"": node} if how == "one" else {f".{k}": v for k, v in node.items()}
        assert items
        for name, block in items.items():
            kind = classes[0] if len(classes) == 1 else next(c for c in classes
                                                             if c.__name__.lower().startswith(block["kind"]))
            _check_block(kind, block, f"experiment.{key}{name}")
    s = validate_settings(cfg)
    s = getattr(s, "settings", s)                  # the main job's setup holds its settings
    assert isinstance(s, cls) and s.name == job


def validate_settings(cfg):
    import jax

    jax.config.update("jax_enable_x64", True)   # as the CLI at its default precision (the mechanism's range check)
    robot, recon = C.robot_from_config(cfg.robot)
    return C.validate_config(cfg, robot, recon)


@pytest.mark.parametrize("job", sorted(C.SETTINGS_CLASSES))
def test_the_structured_config_is_generated_from_the_settings(job):
    """The schema Hydra composes each job against is the one generated from its settings (readers.schema_of: the
    same keys, nested the same way), and it composes the default YAML to the file's own values, key for key and
    in the file's order (what a run stores as its config)."""
    import dataclasses
    import json

    import yaml
    from hydra.core.config_store import ConfigStore
    from omegaconf import OmegaConf

    from deltajax.run import CONFIG_DIR

    def keys(schema):
        hints = {f.name: f.type for f in dataclasses.fields(schema)}
        out = []
        for name, tp in hints.items():
            inner = [a for a in getattr(tp, "__args__", ()) if dataclasses.is_dataclass(a)]
            sub = tp if dataclasses.is_dataclass(tp) else (inner[0] if inner else None)
            out.append((name, keys(sub) if sub is not None else None))
        return out

    stored = ConfigStore.instance().repo["schema"]["experiment"][f"{job}.yaml"].node
    generated = OmegaConf.structured(C.readers.schema_of(C.SETTINGS_CLASSES[job]))
    assert list(stored.keys()) == list(generated.keys())
    assert keys(C.EXPERIMENT_SCHEMAS[job]) == keys(C.readers.schema_of(C.SETTINGS_CLASSES[job]))
    with open(f"{CONFIG_DIR}/experiment/{job}.yaml") as f:
        written = yaml.safe_load(f)["experiment"]
    composed = OmegaConf.to_container(compose(job).experiment, resolve=True)
    assert composed == written
    assert json.dumps(list(_dotted(composed))) == json.dumps(list(_dotted(written)))   # the same keys, in order


def _dotted(node, path=""):
    for k, v in node.items():
        yield f"{path}{k}"
        if isinstance(v, dict):
            yield from _dotted(v, f"{path}{k}.")


# -- the robot block: declared once as well (deltajax.config.robot.RobotSettings), its schema generated -------------
def _robot_presets():
    from pathlib import Path

    from deltajax.run import CONFIG_DIR

    return sorted(p.stem for p in (Path(CONFIG_DIR) / "robot").glob("*.yaml"))


@pytest.mark.parametrize("robot", _robot_presets())
def test_every_robot_setting_declares_how_it_is_checked(robot):
    """Each configs/robot/*.yaml mirrors RobotSettings key for key (name included, R_range and mass as blocks, in
    the file's order), every number a range (the joint limits: any value), every string its choices; composed
    against the schema registered as schema/robot (generated from RobotSettings) it is the file's own values, key
    for key and in the file's order (what a run stores as its config); it reads without a refusal."""
    import json

    import yaml
    from hydra.core.config_store import ConfigStore
    from omegaconf import OmegaConf

    from deltajax.config.readers import read_settings, schema_of
    from deltajax.run import CONFIG_DIR

    with open(f"{CONFIG_DIR}/robot/{robot}.yaml") as f:
        written = yaml.safe_load(f)
    _check_block(C.RobotSettings, written, "robot")
    stored = ConfigStore.instance().repo["schema"]["robot"]["delta.yaml"].node
    assert list(stored.keys()) == list(OmegaConf.structured(schema_of(C.RobotSettings)).keys())
    composed = OmegaConf.to_container(compose("workspace_grid", f"robot={robot}").robot, resolve=True)
    assert composed == written
    assert json.dumps(list(_dotted(composed))) == json.dumps(list(_dotted(written)))   # the same keys, in order
    assert read_settings(C.RobotSettings, composed, "robot").name == robot
    C.robot_from_config(composed)


def test_the_mass_block_is_every_mass_model_field():
    """robot.mass declares a config key for every field of deltajax.mass.MassModel (generated from
    deltajax.mass.MASS_FIELDS), plus the absolute upper_arm_inertia, each with the unit MASS_FIELDS gives it."""
    import dataclasses

    from deltajax.config.robot import MassBlock
    from deltajax.mass import MASS_FIELDS, MassModel

    declared = {f.name: f.metadata["deltajax"] for f in _config_fields(MassBlock)}
    assert set(declared) == {f.name for f in dataclasses.fields(MassModel)} | {"upper_arm_inertia"}
    assert all(declared[name].unit == ("" if unit == "1" else unit) for name, unit, _kind in MASS_FIELDS)


@pytest.mark.parametrize("override, message", [
    ("robot.base_radius=0", r"^robot.base_radius must be > 0 m, got 0.0 m$"),
    ("robot.platform_radius=-0.01", r"^robot.platform_radius must be >= 0 m, got -0.01 m$"),
    ("robot.R_range.step=0", r"^robot.R_range.step must be > 0 m, got 0.0 m$"),
    ("robot.mass.gear_ratio=0", r"^robot.mass.gear_ratio must be > 0, got 0.0$"),
    ("robot.mass.upper_arm_inertia=-1e-3", r"^robot.mass.upper_arm_inertia must be >= 0 kg m\^2, got -0.001 kg m\^2$"),
    ("robot.mass.upper_arm_mass=null", r"^robot.mass.upper_arm_mass is required$"),
    ("robot.mass.upper_arm_inertia=1e-3",
     r"^robot.mass: give upper_arm_inertia or upper_arm_inertia_factor, not both$"),
    ("robot.mass.forearm_model=rods", r"^robot.mass.forearm_model must be one of point_split, rigid_rod, got 'rods'$"),
    ("robot.mass.forearm_inertia_factor=0.3",
     r"^robot.mass.forearm_inertia_factor must be <= s \(1 - s\) = 0.25 .*, got 0.3$"),
])
def test_robot_settings_refused_by_their_metadata_and_rules(override, message):
    with pytest.raises(ConfigError, match=message) as err:
        validate(compose("workspace_grid", override))
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("experiment, overrides", [
    ("ga_reconfig", ["experiment.task.diameter=0", "robot.forearm=0.35"]),
    ("ga_reconfig", ["+experiment.foo=1", "experiment.ga.sigma=inf"]),
    ("ga_reconfig", ["robot=industrial", "experiment.cycle.dwell=-0.1"]),
    ("workspace_grid", ["experiment.grid.x=null", "experiment.grid.h=0.05"]),
    ("ga_reconfig", ["experiment.nope=1"]),                # refused by Hydra: the same error
    ("ga_reconfig", ["~experiment.screen"]),               # refused by the schema: the same error
])
def test_the_tests_compose_helper_is_a_full_hydra_composition(experiment, overrides):
    # _config_helpers.compose applies value overrides to a copy of the experiment's composed defaults: the same
    # config (or the same error) as a full composition of the same command line
    from omegaconf import OmegaConf

    import _config_helpers as H

    def outcome(f):
        try:
            cfg = f()
        except Exception as e:  # noqa: BLE001 - compared below
            return type(e).__name__, str(e)
        return OmegaConf.to_container(cfg), OmegaConf.is_struct(cfg)

    full = outcome(lambda: H._hydra_compose([f"experiment={experiment}", *overrides]))
    assert outcome(lambda: H.compose(experiment, *overrides)) == full
