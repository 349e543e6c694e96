"""Shared by the configuration tests: compose a job's config as the CLI does, and run every check of it."""

from deltajax import config as C
from deltajax.run import CONFIG_DIR


def compose(experiment, *overrides):
    """The composed config of ``experiment=<experiment>`` plus ``overrides`` (Hydra, the schemas registered as
    deltajax.run registers them at import)."""
    from hydra import compose as hydra_compose, initialize_config_dir

    C.register_schemas()
    with initialize_config_dir(config_dir=CONFIG_DIR, version_base="1.3"):
        return hydra_compose(config_name="config", overrides=[f"experiment={experiment}", *overrides])


def validate(cfg):
    """Every check the run makes before anything compiles; returns (robot, reconfigurable robot or None)."""
    C.check_keys(cfg)
    robot, recon = C.robot_from_config(cfg.robot)
    C.validate_config(cfg, robot, recon)
    return robot, recon
