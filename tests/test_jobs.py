"""The job table: every CLI job is listed once, has its config and a ``run(ctx)``."""

from pathlib import Path

from deltajax.jobs import JOBS, load
from deltajax.run import CONFIG_DIR, list_experiments


def test_jobs_table_matches_configs_and_modules():
    configs = sorted(p.stem for p in (Path(CONFIG_DIR) / "experiment").glob("*.yaml"))
    assert sorted(JOBS) == configs
    assert list(list_experiments())[0] == "ga_reconfig"  # the main job first in --help
    for name in JOBS:
        assert callable(load(name).run), name
