"""Shared by the configuration tests: compose a job's config as the CLI does, and run every check of it."""

import copy
import functools
from pathlib import Path

from deltajax import config as C
from deltajax.run import CONFIG_DIR


def _hydra_compose(overrides):
    from hydra import compose as hydra_compose, initialize_config_dir

    C.register_schemas()
    with initialize_config_dir(config_dir=CONFIG_DIR, version_base="1.3"):
        return hydra_compose(config_name="config", overrides=list(overrides))


@functools.lru_cache(maxsize=None)
def _experiment(experiment):
    return _hydra_compose([f"experiment={experiment}"])


def _changes_the_defaults(override) -> bool:
    """Does ``override`` pick a config group option (``robot=...``, ``hydra/launcher=...``) rather than set a
    value? Those change what Hydra composes, so they go through a full composition."""
    key = override.key_or_group
    return override.is_hydra_override() or (Path(CONFIG_DIR) / key).is_dir()


def compose(experiment, *overrides):
    """The composed config of ``experiment=<experiment>`` plus ``overrides`` (Hydra, the schemas registered as
    deltajax.run registers them at import).

    Each experiment's defaults are composed once per process (a composition reads and merges ~15 YAML files and
    schemas, ~0.1 s, ~200 times in the suite); value overrides are then applied to a copy by the same Hydra
    function that applies them at the end of a composition, after the same parser, so the result and every
    error are the composition's. An override that picks a group option is composed in full."""
    from hydra._internal.config_loader_impl import ConfigLoaderImpl
    from hydra.core.override_parser.overrides_parser import OverridesParser

    parsed = OverridesParser.create().parse_overrides(list(overrides))
    if any(_changes_the_defaults(o) for o in parsed):
        return _hydra_compose([f"experiment={experiment}", *overrides])
    cfg = copy.deepcopy(_experiment(experiment))
    ConfigLoaderImpl._apply_overrides_to_config(parsed, cfg)
    return cfg


def validate(cfg):
    """Every check the run makes before anything compiles; returns (robot, reconfigurable robot or None)."""
    C.check_keys(cfg)
    robot, recon = C.robot_from_config(cfg.robot)
    C.validate_config(cfg, robot, recon)
    return robot, recon
