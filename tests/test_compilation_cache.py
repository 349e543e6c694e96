"""The tests' CLI subprocesses share the session's persistent XLA cache (tests/conftest.py exports it):
configs/config.yaml's ``compilation_cache`` reads ``DELTAJAX_JAX_CACHE``."""

import os

from omegaconf import OmegaConf

from toy_jobs import JAX_CACHE, JAX_CACHE_MIN_S


def _compose(*overrides):
    from hydra import compose, initialize_config_dir

    from deltajax.run import CONFIG_DIR

    with initialize_config_dir(config_dir=CONFIG_DIR, version_base="1.3"):
        return compose(config_name="config", overrides=["experiment=workspace_grid", *overrides])


def test_compilation_cache_follows_the_environment(monkeypatch, tmp_path):
    assert os.environ["DELTAJAX_JAX_CACHE"] == JAX_CACHE  # what every CLI subprocess of the session inherits
    monkeypatch.setenv("DELTAJAX_JAX_CACHE", str(tmp_path / "xla"))
    assert OmegaConf.to_container(_compose(), resolve=True)["compilation_cache"] == str(tmp_path / "xla")
    assert _compose("compilation_cache=null").compilation_cache is None  # an explicit value still wins
    monkeypatch.delenv("DELTAJAX_JAX_CACHE")
    assert _compose().compilation_cache == "~/.cache/deltajax/jax"  # the documented default


def test_run_uses_the_cache_the_environment_names(monkeypatch, tmp_path):
    import jax
    import pytest

    from deltajax.config import ConfigError
    from deltajax.run import execute

    monkeypatch.setenv("DELTAJAX_JAX_CACHE", str(tmp_path / "xla"))
    cfg = _compose("experiment.grid.h=0")  # refused, after the cache is set and before anything compiles
    before = (jax.config.jax_compilation_cache_dir, jax.config.jax_persistent_cache_min_compile_time_secs)
    try:
        with pytest.raises(ConfigError, match="experiment.grid.h must be > 0"):
            execute(cfg, tmp_path / "run")
        assert jax.config.jax_compilation_cache_dir == str(tmp_path / "xla")
    finally:
        jax.config.update("jax_compilation_cache_dir", before[0])
        jax.config.update("jax_persistent_cache_min_compile_time_secs", before[1])


def test_run_keeps_jaxs_own_cache_threshold_when_set(monkeypatch, tmp_path):
    """The CLI's persistent-cache threshold (``deltajax.run.CACHE_MIN_COMPILE_S``) applies unless
    JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS is set (JAX reads it at import; the tests set it for their CLI
    subprocesses: tests/conftest.py)."""
    import jax
    import pytest

    from deltajax.config import ConfigError
    from deltajax.run import CACHE_MIN_COMPILE_S, execute

    # what the CLI subprocesses inherit
    assert os.environ["JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"] == str(JAX_CACHE_MIN_S)
    cfg = _compose("experiment.grid.h=0", f"compilation_cache={tmp_path / 'xla'}")
    before = (jax.config.jax_compilation_cache_dir, jax.config.jax_persistent_cache_min_compile_time_secs)
    try:
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.25)
        with pytest.raises(ConfigError, match="experiment.grid.h must be > 0"):
            execute(cfg, tmp_path / "run")
        assert jax.config.jax_persistent_cache_min_compile_time_secs == 0.25  # left as JAX has it
        monkeypatch.delenv("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS")
        with pytest.raises(ConfigError, match="experiment.grid.h must be > 0"):
            execute(cfg, tmp_path / "run")
        assert jax.config.jax_persistent_cache_min_compile_time_secs == CACHE_MIN_COMPILE_S  # the CLI's default
    finally:
        jax.config.update("jax_compilation_cache_dir", before[0])
        jax.config.update("jax_persistent_cache_min_compile_time_secs", before[1])
