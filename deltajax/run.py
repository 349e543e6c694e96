"""Command-line entry point (Hydra): ``python -m deltajax.run experiment=NAME key=value ...``.

This is the only module that reads configuration, switches precision and picks the output directory.
Experiments live in ``deltajax/experiments/<name>.py`` and expose ``run(ctx: RunContext) -> None``; their
settings live in ``configs/experiment/<name>.yaml`` (``# @package _global_``, with ``experiment.name``).
"""

from __future__ import annotations

import dataclasses
import datetime
import importlib
import os
import sys
import time
from pathlib import Path
from typing import Any, Iterable, Optional

import hydra
from omegaconf import DictConfig, OmegaConf

CONFIG_DIR = os.environ.get("DELTAJAX_CONFIG_DIR", str(Path(__file__).resolve().parent.parent / "configs"))


def _register_schemas() -> None:
    from .config import register_schemas

    register_schemas()


_register_schemas()  # before Hydra composes (configs/config.yaml names schema/robot and schema/experiment)

__all__ = ["RunContext", "main", "run_experiment", "CONFIG_DIR"]


@dataclasses.dataclass
class RunContext:
    """What an experiment gets: config, output directory, results file, robots and helpers.

    Attributes:
        cfg: the resolved config (OmegaConf).
        run_dir: the run's output directory (Hydra's), where results.h5 and plots go.
        results: the run's :class:`deltajax.io.ResultsFile` (flushed at the end; flush it yourself to checkpoint).
        robot: the fixed robot built from ``cfg.robot`` (validated).
        recon: the reconfigurable robot, or ``None`` if ``cfg.robot.R_range`` is null.
    """

    cfg: DictConfig
    run_dir: Path
    results: Any
    robot: Any
    recon: Any
    complete: bool = True  # a job that stops early (resumable) sets False: the run dir then stays resumable
    figures: list = dataclasses.field(default_factory=list)  # (path, PNG bytes), written after results.h5

    @property
    def dtype(self):
        import jax.numpy as jnp

        return jnp.float64 if self.cfg.precision == "float64" else jnp.float32

    def progress(self, iterable: Optional[Iterable] = None, *, total: Optional[int] = None, desc: str = ""):
        """A tqdm progress bar (to stderr), disabled with ``progress=false``."""
        from tqdm.auto import tqdm

        return tqdm(iterable, total=total, desc=desc, disable=not self.cfg.get("progress", True),
                    file=sys.stderr, mininterval=1.0)

    def savefig(self, fig, name: str) -> Optional[Path]:
        """Render a matplotlib figure for ``<run_dir>/<name>.png`` (if ``plots=true``) and close it.

        The PNG is rendered now and written after the final results.h5 (:meth:`write_figures`), so a failure
        while writing figures (a full disk) never costs results. Returns the path the figure will have.
        """
        import io

        import matplotlib.pyplot as plt

        path = None
        if self.cfg.get("plots", True):
            path = self.run_dir / f"{name}.png"
            buf = io.BytesIO()
            fig.savefig(buf, format="png", dpi=120, bbox_inches="tight")
            self.figures.append((path, buf.getvalue()))
        plt.close(fig)
        return path

    def write_figures(self) -> None:
        """Write the rendered figures (atomically, like results.h5)."""
        from .io import write_atomic

        while self.figures:
            path, png = self.figures.pop(0)
            write_atomic(path, png)

    def log(self, msg: str) -> None:
        print(f"[deltajax] {msg}", flush=True)


def _validate_top(cfg: DictConfig) -> None:
    from .config import ConfigError

    if cfg.get("precision") not in ("float64", "float32"):
        raise ConfigError(f"precision must be 'float64' or 'float32', got {cfg.get('precision')!r}")
    seed = cfg.get("seed")
    if not isinstance(seed, int) or isinstance(seed, bool):
        raise ConfigError(f"seed must be an integer, got {seed!r}")
    if "experiment" not in cfg or "name" not in cfg.experiment:
        raise ConfigError("experiment.name is missing: pick one with experiment=NAME")


def execute(cfg: DictConfig, run_dir: Path, on_claimed=None) -> Path:
    """Run the experiment described by ``cfg`` into ``run_dir``; returns the results path.

    The run directory is claimed first (:mod:`deltajax.rundir`: lock, manifest, refusal of another job or
    config); ``on_claimed()`` runs right after the claim (the CLI writes ``.hydra/`` there).
    """
    from .config import check_keys, robot_from_config, validate_config

    _validate_top(cfg)
    name = cfg.experiment.name
    try:
        module = importlib.import_module(f"deltajax.experiments.{name}")
    except ModuleNotFoundError as e:
        if e.name == f"deltajax.experiments.{name}":
            raise SystemExit(f"unknown experiment {name!r} (no deltajax/experiments/{name}.py)") from None
        raise
    import jax

    # Precision first: the robot's array leaves take the default float dtype when they are built.
    jax.config.update("jax_enable_x64", cfg.precision == "float64")
    cache = cfg.get("compilation_cache")
    if cache:  # persistent XLA cache: reruns, resumes and sweep jobs skip most compilation
        jax.config.update("jax_compilation_cache_dir", os.path.expanduser(str(cache)))
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)
    check_keys(cfg)  # unknown keys (also +key=value ones), before anything else reads the config
    robot, recon = robot_from_config(cfg.robot)  # validated before anything compiles
    validate_config(cfg, robot, recon)  # every experiment field, before the run directory is touched
    from . import __version__
    from .io import ResultsFile, git_commit
    from .rundir import claim

    with claim(run_dir, name, OmegaConf.to_container(cfg, resolve=True), fresh=bool(cfg.get("fresh", False))) as owner:
        if on_claimed is not None:
            on_claimed()
        if owner.state == "complete":
            print(f"[deltajax] {run_dir} already holds the complete results of this {name} run; nothing to do "
                  f"(fresh=true recomputes them)", flush=True)
            return run_dir / "results.h5"
        dev = jax.devices()[0]
        attrs = {
            "deltajax_version": __version__,
            "git_commit": git_commit(),
            "config": OmegaConf.to_yaml(cfg, resolve=True),
            "experiment": name,
            "seed": int(cfg.seed),
            "precision": str(cfg.precision),
            "backend": jax.default_backend(),
            "device": f"{dev.platform}:{getattr(dev, 'device_kind', '')} x{jax.device_count()}",
            "jax_version": jax.__version__,
        }
        results = ResultsFile(run_dir / "results.h5", attrs=attrs)
        ctx = RunContext(cfg=cfg, run_dir=run_dir, results=results, robot=robot, recon=recon)
        t0 = time.perf_counter()
        module.run(ctx)
        results.set_attrs(wall_time_s=time.perf_counter() - t0)
        path = results.flush(final=True)
        ctx.write_figures()  # after the results: a failure here costs no result (the run stays resumable)
        if ctx.complete and cfg.experiment.get("stop_after") is None:
            owner.mark_complete()
    ctx.log(f"wrote {path}")
    return path


@hydra.main(config_path=CONFIG_DIR, config_name="config", version_base="1.3")
def main(cfg: DictConfig) -> None:
    """Hydra entry point."""
    from hydra.core.hydra_config import HydraConfig

    hc = HydraConfig.get()
    run_dir = Path(hc.runtime.output_dir)

    def write_hydra_files() -> None:  # what Hydra's output_subdir would have written, once the dir is ours
        out = run_dir / ".hydra"
        out.mkdir(parents=True, exist_ok=True)
        OmegaConf.save(cfg, out / "config.yaml")
        OmegaConf.save(OmegaConf.create({"hydra": OmegaConf.to_container(hc, resolve=False)}), out / "hydra.yaml")
        OmegaConf.save(OmegaConf.create(list(hc.overrides.task)), out / "overrides.yaml")

    execute(cfg, run_dir, on_claimed=write_hydra_files)


def run_experiment(name: str, overrides: Iterable[str] = (), run_dir: Optional[os.PathLike] = None) -> Path:
    """Run an experiment from Python with the same configs as the CLI (Hydra compose API).

    Args:
        name: experiment name (``configs/experiment/<name>.yaml``).
        overrides: Hydra overrides, e.g. ``["robot.forearm=0.45", "plots=false"]``.
        run_dir: output directory (default: a fresh directory under ``outputs/<name>/``).

    Returns:
        Path of the written results.h5.
    """
    from hydra import compose, initialize_config_dir

    with initialize_config_dir(config_dir=CONFIG_DIR, version_base="1.3"):
        cfg = compose(config_name="config", overrides=[f"experiment={name}", *overrides])
    if run_dir is None:
        # microseconds: two calls in one second must not share (and be refused by) one run directory
        run_dir = Path("outputs") / name / datetime.datetime.now().strftime("%Y-%m-%d_%H-%M-%S_%f")
    return execute(cfg, Path(run_dir))


if __name__ == "__main__":
    main()
