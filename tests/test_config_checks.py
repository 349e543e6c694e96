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
           ({"n": 3, "flag": True, "speed": 1}, r"^e: unknown keys speed; valid keys: flag, inner, limit, n$"),
           ({"n": 3, "flag": True, "n_squared": 4}, r"^e: unknown keys n_squared; "),                # derived
           ([1, 2], r"^e must be a mapping, got \[1, 2\]$")]
    for block, match in bad:
        with pytest.raises(ConfigError, match=match):
            read_settings(Outer, block, "e")


def test_every_main_job_setting_declares_how_it_is_checked():
    """Every field of the main job's settings tree carries metadata (deltajax.config.readers.setting); every
    number either a range or its own reader; the default YAML reads without a refusal."""
    import dataclasses
    import typing

    from deltajax.config import ga_reconfig as G

    def walk(cls, path):
        for f in dataclasses.fields(cls):
            spec = f.metadata.get("deltajax")
            assert spec is not None, f"{path}.{f.name} has no setting() metadata"
            tp = typing.get_type_hints(cls)[f.name]
            tp = next((a for a in typing.get_args(tp) if a is not type(None)), tp)   # Optional[X] -> X
            if dataclasses.is_dataclass(tp):
                yield from walk(tp, f"{path}.{f.name}")
            elif tp in (int, float) and spec.read is None and f.name != "threshold":   # threshold: by the index
                assert spec.lo is not None or spec.hi is not None, f"{path}.{f.name}: no range"
            yield f"{path}.{f.name}"

    names = list(walk(G.GaReconfigSettings, "experiment"))
    assert len(names) > 80 and "experiment.robust.margins.joint_deg" in names
    s = G.ga_reconfig_settings(compose("ga_reconfig").experiment)
    assert s.robust.margins.clearance_mm == 0.0 and s.verify.certify_doublings == 2 and s.ga.population_size > 0


# -- the grid jobs and the kernel benchmark: settings declared once too (deltajax.config.workspace) --------------
from deltajax import config as C  # noqa: E402

def _workspace_job_settings():
    from deltajax.config import workspace as W

    return {"workspace_grid": W.WorkspaceGridSettings, "reconfig_workspace": W.PaperGridSettings,
            "reconfig_indices": W.ReconfigIndicesSettings, "bench_kernel": W.BenchKernelSettings,
            "indices_examples": W.IndicesExamplesSettings}


WORKSPACE_JOBS = ["workspace_grid", "reconfig_workspace", "reconfig_indices", "bench_kernel", "indices_examples"]


def _yaml_keys(node, path):
    """The dotted keys of a YAML block, nested blocks walked, in the file's order."""
    for k, v in node.items():
        if isinstance(v, dict):
            yield from _yaml_keys(v, f"{path}.{k}")
        yield f"{path}.{k}"


@pytest.mark.parametrize("job", WORKSPACE_JOBS)
def test_every_workspace_job_setting_declares_how_it_is_checked(job):
    """Every key of configs/experiment/<job>.yaml (name included, nested blocks walked) is a field of the job's
    settings declared with setting() metadata, in the YAML's order; every number has a range or its own reader;
    the fields without metadata (derived by the builder) are no config keys; the default YAML reads."""
    import dataclasses
    import typing

    from omegaconf import OmegaConf

    from deltajax.run import CONFIG_DIR

    def walk(cls, path):
        for f in dataclasses.fields(cls):
            spec = f.metadata.get("deltajax")
            if spec is None:                      # derived: no config key
                continue
            tp = typing.get_type_hints(cls)[f.name]
            tp = next((a for a in typing.get_args(tp) if a is not type(None)), tp)   # Optional[X] -> X
            if dataclasses.is_dataclass(tp):
                yield from walk(tp, f"{path}.{f.name}")
            elif tp in (int, float) and spec.read is None:
                assert spec.lo is not None or spec.hi is not None, f"{path}.{f.name}: no range"
            yield f"{path}.{f.name}"

    cls = _workspace_job_settings()[job]
    yaml = OmegaConf.to_container(OmegaConf.load(f"{CONFIG_DIR}/experiment/{job}.yaml"))["experiment"]
    assert list(walk(cls, "experiment")) == list(_yaml_keys(yaml, "experiment"))
    derived = [f.name for f in dataclasses.fields(cls) if "deltajax" not in f.metadata]
    assert not set(derived) & set(yaml)
    cfg = compose(job)
    s = C.validate_config(cfg, *C.robot_from_config(cfg.robot))
    assert isinstance(s, cls) and s.name == job


@pytest.mark.parametrize("job", WORKSPACE_JOBS)
def test_workspace_job_schema_generated_from_its_settings_composes_the_same_config(job):
    """readers.schema_of(<the job's settings>) registered as the job's structured config (as main does for
    ga_reconfig) composes the default YAML to the same experiment block as the hand-written schema: the same
    values, the same keys in the same order (the stored config does not change when the schema is switched)."""
    from hydra import compose as hydra_compose, initialize_config_dir
    from hydra.core.config_store import ConfigStore
    from omegaconf import OmegaConf

    from deltajax.config.readers import schema_of
    from deltajax.run import CONFIG_DIR

    def keys(node):
        return [(k, keys(v) if isinstance(v, dict) else None) for k, v in node.items()]

    today = OmegaConf.to_container(compose(job).experiment)
    try:
        ConfigStore.instance().store(group="schema/experiment", name=job, node=schema_of(_workspace_job_settings()[job]))
        with initialize_config_dir(config_dir=CONFIG_DIR, version_base="1.3"):
            generated = OmegaConf.to_container(hydra_compose(config_name="config",
                                                             overrides=[f"experiment={job}"]).experiment)
    finally:
        C.register_schemas()    # the registered schemas as before
    assert generated == today and keys(generated) == keys(today)


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


# -- the other jobs' settings declared the same way (dynamics_cycle, datasheet, boundary_search, reconfig_motion) --
def _declared_jobs():
    from deltajax.config import boundary as B, dynamics as D, motion as M

    # (experiment, settings class, the blocks its fields' own readers read: one block, or one per entry of a
    # mapping (a setup per robot, a case per name, its class by its kind))
    return [("dynamics_cycle", D.DynamicsCycleSettings, {"setups": ("each", [D.CycleSetupBlock])}),
            ("datasheet", D.DatasheetSettings, {}),
            ("boundary_search", B.BoundarySearchSettings, {}),
            ("reconfig_motion", M.ReconfigMotionSettings, {"mechanism": ("one", [M.MechanismBlock]),
                                                           "cases": ("each", [M.AdeptCaseBlock, M.TaskCaseBlock])})]


#: numbers whose every finite value is meaningful (no range): a heading, an offset
_ANY_NUMBER = {"heading_deg", "d3"}


def _config_fields(cls):
    import dataclasses

    return [f for f in dataclasses.fields(cls) if "deltajax" in f.metadata]


def _check_block(cls, block, path):
    """Every config field of ``cls`` declares how it is checked; ``block`` (the default YAML's) has exactly its
    config fields (the required ones at least), in the order declared."""
    import dataclasses
    import typing

    fields = _config_fields(cls)
    names = [f.name for f in fields]
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
        if tp is str and spec.read is None and f.name != "name":
            assert spec.choices is not None, f"{path}.{f.name}: a string without choices"
        if dataclasses.is_dataclass(tp) and spec.read is None:
            _check_block(tp, block.get(f.name) or {}, f"{path}.{f.name}")


@pytest.mark.parametrize("job", ["dynamics_cycle", "datasheet", "boundary_search", "reconfig_motion"])
def test_every_declared_job_setting_declares_how_it_is_checked(job):
    """Each job's settings mirror its YAML key for key (name included, nested blocks as blocks, in the YAML's
    order); every config field carries setting() metadata (a field without is derived: no YAML key), every
    number a range or its own reader, every string its choices; the default config reads without a refusal."""
    from omegaconf import OmegaConf

    _, cls, inner = next(j for j in _declared_jobs() if j[0] == job)
    cfg = compose(job)
    e = OmegaConf.to_container(cfg.experiment, resolve=True)
    _check_block(cls, e, "experiment")
    for key, (how, classes) in inner.items():    # blocks read by a field's own reader
        items = {"": e[key]} if how == "one" else {f".{k}": v for k, v in e[key].items()}
        assert items
        for name, block in items.items():
            kind = classes[0] if len(classes) == 1 else next(c for c in classes
                                                             if c.__name__.lower().startswith(block["kind"]))
            _check_block(kind, block, f"experiment.{key}{name}")
    s = validate_settings(cfg)
    assert isinstance(s, cls) and s.name == job


def validate_settings(cfg):
    import jax

    from deltajax import config as C

    jax.config.update("jax_enable_x64", True)   # as the CLI at its default precision (the mechanism's range check)
    robot, recon = C.robot_from_config(cfg.robot)
    return C.validate_config(cfg, robot, recon)


@pytest.mark.parametrize("job", ["dynamics_cycle", "datasheet", "boundary_search", "reconfig_motion"])
def test_declared_settings_compose_the_default_config_unchanged(job):
    """readers.schema_of(the job's settings), registered as the job's structured config, composes the default
    YAML to the same config as today, key for key and in the same order (ready to replace the hand-written
    schema of deltajax.schemas, or to add one where there is none)."""
    import json

    from hydra import compose as hydra_compose, initialize_config_dir
    from hydra.core.config_store import ConfigStore
    from omegaconf import OmegaConf

    from deltajax import config as C
    from deltajax.config.readers import schema_of
    from deltajax.run import CONFIG_DIR

    _, cls, _ = next(j for j in _declared_jobs() if j[0] == job)
    today = OmegaConf.to_container(compose(job), resolve=True)
    repo = ConfigStore.instance().repo["schema"]["experiment"]
    before = repo.get(f"{job}.yaml")
    try:
        ConfigStore.instance().store(group="schema/experiment", name=job, node=schema_of(cls))
        with initialize_config_dir(config_dir=CONFIG_DIR, version_base="1.3"):
            generated = OmegaConf.to_container(hydra_compose(config_name="config", overrides=[f"experiment={job}"]),
                                               resolve=True)
    finally:
        if before is None:
            repo.pop(f"{job}.yaml", None)
        else:
            repo[f"{job}.yaml"] = before
        C.register_schemas()
    assert generated == today
    assert json.dumps(generated) == json.dumps(today)      # the same keys in the same order
