"""Command-line entry point (Hydra): ``python -m deltajax.run experiment=NAME key=value ...``.

This is the only module that reads configuration, switches precision and picks the output directory.
Jobs are listed in :data:`deltajax.jobs.JOBS` (``deltajax/jobs/<name>.py``, ``run(ctx: RunContext) -> None``);
their settings live in ``configs/experiment/<name>.yaml`` (``# @package _global_``, with ``experiment.name``).
"""

from __future__ import annotations

import contextlib
import dataclasses
import datetime
import logging
import os
import shutil
import sys
import time
from pathlib import Path
from typing import Any, Iterable, Optional
import io

import hydra
from omegaconf import DictConfig, OmegaConf
import jax
import jax.numpy as jnp

from .io import git_commit, ResultsFile, ResultsWriteError, write_atomic
# BelowWarning and RunLogHandler: also named as deltajax.run.* by logging configs written before deltajax.runlog
from .runlog import BelowWarning, RunLogHandler, api_logging, console_through_tqdm, run_log_open  # noqa: F401
from .config import check_keys, ConfigError, register_schemas, robot_from_config, validate_config
from .jobs import JOBS, load
from ._precision import float32_requested
from . import __version__
from .rundir import claim, RunDirError
from .geometry import GeometryError
from .overrides import check_overrides as check, compose_config, composition_error_line as line, sweep_jobs
from .jobs.stages import collecting_by_stage

log = logging.getLogger("deltajax")

#: Exit status of a run stopped by a user error (bad config value, unknown experiment): one line on stderr.
EXIT_USER_ERROR = 2

#: JAX's persistent-cache threshold for the CLI's runs (seconds of compilation; unless
#: ``JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS`` is set): every program is kept, the ~150 single operations a job
#: dispatches eagerly while it builds its problem, cycles and exports included (~30 ms each to compile, ~2 ms to
#: read back: ~4 CPU-s of a warm run of the main job; docs/BENCHMARKS.md)
CACHE_MIN_COMPILE_S = 0.0


def _config_dir() -> str:
    """Where the Hydra configs are: ``DELTAJAX_CONFIG_DIR``, else the repository's top-level ``configs/`` (a
    source checkout or an editable install), else the copy shipped inside the package (``deltajax/configs``,
    a wheel or a non-editable ``pip install .``)."""
    env = os.environ.get("DELTAJAX_CONFIG_DIR")
    if env:
        return env
    here = Path(__file__).resolve().parent
    repo = here.parent
    if (repo / "configs" / "config.yaml").is_file() and (repo / "pyproject.toml").is_file():
        return str(repo / "configs")
    return str(here / "configs")


CONFIG_DIR = _config_dir()


def _register_schemas() -> None:
    register_schemas()


_register_schemas()  # before Hydra composes (configs/config.yaml names schema/robot and schema/experiment)

__all__ = ["RunContext", "main", "cli", "run_experiment", "execute", "list_experiments", "CONFIG_DIR",
           "check_overrides", "check_sweep", "composition_error_line",
           "EXIT_USER_ERROR", "CACHE_MIN_COMPILE_S"]


@dataclasses.dataclass
class RunContext:
    """What an experiment gets: config, output directory, results file, robots and helpers.

    Attributes:
        cfg: the resolved config (OmegaConf).
        run_dir: the run's output directory (Hydra's), where results.h5 and plots go.
        results: the run's :class:`deltajax.io.ResultsFile` (flushed at the end; flush it yourself to checkpoint).
        robot: the fixed robot built from ``cfg.robot`` (validated).
        recon: the reconfigurable robot, or ``None`` if ``cfg.robot.R_range`` is null.
        settings: the job's settings, built and checked once before the run (:func:`deltajax.config.validate_config`;
            the job reads these, not ``cfg``).
        complete: set it to False when the run stops before its end (to be resumed): ``<run_dir>/checkpoint``
            is then kept; a complete run's checkpoint directory is removed after the final flush.
    """

    cfg: DictConfig
    run_dir: Path
    results: Any
    robot: Any
    recon: Any
    settings: Any = None
    complete: bool = True  # a job that stops early (resumable) sets False: the run dir then stays resumable
    figures: list = dataclasses.field(default_factory=list)  # (path, PNG bytes), written after results.h5

    @property
    def seed(self) -> int:
        """The run's seed (``seed``)."""
        return int(self.cfg.seed)

    @property
    def plots(self) -> bool:
        """Whether the run draws its figures (``plots``)."""
        return bool(self.cfg.get("plots", True))

    @property
    def dtype(self):
        return jnp.float64 if self.cfg.precision == "float64" else jnp.float32

    def progress(self, iterable: Optional[Iterable] = None, *, total: Optional[int] = None, desc: str = ""):
        """A tqdm progress bar (to stderr), disabled with ``progress=false``."""
        from tqdm.auto import tqdm

        return tqdm(iterable, total=total, desc=desc, disable=not self.cfg.get("progress", True),
                    file=sys.stderr, mininterval=1.0)

    def savefig(self, fig, name: str, *, crop: bool = True) -> Optional[Path]:
        """Render a matplotlib figure for ``<run_dir>/<name>.png`` (if ``plots=true``) and close it.

        The PNG is rendered now and written after the final results.h5 (:meth:`write_figures`), so a failure
        while writing figures (a full disk) never costs results. Returns the path the figure will have.
        ``crop``: cropped to what is drawn (``bbox_inches="tight"``, which lays the figure out twice); False for
        a page of fixed size (a datasheet's A4), saved as laid out.
        """
        import matplotlib.pyplot as plt

        path = None
        if self.cfg.get("plots", True):
            path = self.run_dir / f"{name}.png"
            buf = io.BytesIO()
            fig.savefig(buf, format="png", dpi=120, bbox_inches="tight" if crop else None)
            self.figures.append((path, buf.getvalue()))
        plt.close(fig)
        return path

    def write_figures(self) -> None:
        """Write the rendered figures (atomically, like results.h5)."""
        while self.figures:
            path, png = self.figures.pop(0)
            write_atomic(path, png)

    def log(self, msg: str) -> None:
        """Log a line of the run (console and ``<run_dir>/run.log``; through the progress bars, not across)."""
        log.info(msg)


def _validate_top(cfg: DictConfig) -> None:
    if cfg.get("precision") not in ("float64", "float32"):
        raise ConfigError(f"precision must be 'float64' or 'float32', got {cfg.get('precision')!r}")
    seed = cfg.get("seed")
    if not isinstance(seed, int) or isinstance(seed, bool):
        raise ConfigError(f"seed must be an integer, got {seed!r}")
    if "experiment" not in cfg or "name" not in cfg.experiment:
        raise ConfigError("experiment.name is missing: pick one with experiment=NAME")


def list_experiments() -> dict[str, str]:
    """Experiments selectable with ``experiment=NAME`` (:data:`deltajax.jobs.JOBS`) -> one-line description."""
    return {name: job.summary for name, job in JOBS.items()}


def _validated(cfg: DictConfig, run_dir: Optional[Path] = None):
    """Every check of ``cfg`` that needs no run directory (and those of ``run_dir`` where given): (experiment name,
    job module, robot, reconfigurable robot or None). Sets the precision (the robot is built in it).

    Raises:
        ConfigError: one line naming the field and the value; nothing has been compiled or written.
    """
    _validate_top(cfg)
    name = cfg.experiment.name

    if name not in JOBS:
        raise ConfigError(f"experiment.name={name!r} is not a job; choose one of {', '.join(JOBS)}")
    module = load(name)

    # Precision first: the robot's array leaves take the default float dtype when they are built.
    jax.config.update("jax_enable_x64", cfg.precision == "float64")

    float32_requested(cfg.precision == "float32")  # asked for: no float32 warning
    check_keys(cfg)  # unknown keys (also +key=value ones), before anything else reads the config
    robot, recon = robot_from_config(cfg.robot)  # validated before anything compiles
    settings = validate_config(cfg, robot, recon, run_dir=run_dir)  # every experiment field, the job's settings
    return name, module, robot, recon, settings


def execute(cfg: DictConfig, run_dir: Path, on_claimed=None) -> Path:
    """Run the experiment described by ``cfg`` into ``run_dir``; returns the results path.

    The run directory is claimed first (:mod:`deltajax.rundir`: lock, manifest, refusal of another job or
    config); ``on_claimed()`` runs right after the claim (the CLI writes ``.hydra/`` there).

    Raises:
        ConfigError: a user error (bad value, unknown experiment), raised before anything compiles where the
            value is known up front; the CLI prints it as one line and exits with status 2.
    """
    cache = cfg.get("compilation_cache")
    if cache:  # persistent XLA cache: reruns, resumes and sweep jobs skip most compilation (set before the checks,
        # some of which compile: a boundary search's centre is checked by inverse kinematics)
        jax.config.update("jax_compilation_cache_dir", os.path.expanduser(str(cache)))
        if "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS" not in os.environ:  # JAX's own setting wins if given
            jax.config.update("jax_persistent_cache_min_compile_time_secs", CACHE_MIN_COMPILE_S)
    name, module, robot, recon, settings = _validated(cfg, run_dir)  # every field, before the run dir is touched

    with contextlib.ExitStack() as stack:
        owner = stack.enter_context(claim(run_dir, name, OmegaConf.to_container(cfg, resolve=True),
                                          fresh=bool(cfg.get("fresh", False))))
        if on_claimed is not None and owner.state != "complete":  # a finished run's .hydra/ stays as it is
            on_claimed()
        if owner.state == "complete":  # a no-op: not even a line in that run's run.log
            log.info(f"{run_dir} already holds the complete results of this {name} run; nothing to do "
                     f"(fresh=true recomputes them)")
            return run_dir / "results.h5"
        stack.enter_context(run_log_open())
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
        ctx = RunContext(cfg=cfg, run_dir=run_dir, results=results, robot=robot, recon=recon, settings=settings)
        t0 = time.perf_counter()

        with console_through_tqdm(), collecting_by_stage():   # one scope for all of the job's stage runners
            module.run(ctx)
            results.set_attrs(wall_time_s=time.perf_counter() - t0)
            path = results.flush(final=True)
            ctx.write_figures()  # after the results: a failure here costs no result (the run stays resumable)
            if ctx.complete and cfg.experiment.get("stop_after") is None:
                owner.mark_complete()
                _drop_checkpoints(ctx)
            ctx.log(f"wrote {path} ({path.stat().st_size / 1e6:.3g} MB)")
    return path


def _drop_checkpoints(ctx: RunContext) -> None:
    """Remove ``<run_dir>/checkpoint`` once the complete results are safely in results.h5 (after the final
    flush): a finished run keeps its results, not gigabytes of resume state. Partial runs keep it."""
    ck = ctx.run_dir / "checkpoint"
    if not ck.is_dir() or not ctx.complete:
        return
    size = sum(p.stat().st_size for p in ck.rglob("*") if p.is_file())
    shutil.rmtree(ck)
    ctx.log(f"run complete: removed its checkpoint directory ({size / 1e6:.3g} MB)")


def _user_errors() -> tuple:
    return (ConfigError, GeometryError, RunDirError)  # RunDirError: busy, foreign or damaged run directory


def _use_agg_backend() -> None:
    """Select matplotlib's non-interactive Agg backend: the one place in deltajax that selects a backend, once, in
    the CLI before any job runs (the jobs render PNGs through :meth:`RunContext.savefig`; no window, no display).
    The library (:mod:`deltajax.plots`, :func:`run_experiment`) never selects one: a notebook keeps its own."""
    import matplotlib

    matplotlib.use("Agg")


try:
    from hydra.experimental.callback import Callback as _Callback
except ImportError:  # pragma: no cover
    _Callback = object  # type: ignore[misc,assignment]


class RunDirWatch(_Callback):
    """Hydra callback (``configs/config.yaml``, ``hydra.callbacks.run_dir_watch``): notes, before Hydra creates a
    single run's directory, which of it and its parents do not exist yet, so that a refused run removes exactly
    those again (:func:`_remove_created`) and leaves nothing behind."""

    created: list = []  # the missing directories of this process's run, deepest first

    def on_run_start(self, config, **kwargs: Any) -> None:
        d = Path(os.path.abspath(str(config.hydra.run.dir)))
        missing = []
        while not d.exists() and d != d.parent:
            missing.append(d)
            d = d.parent
        RunDirWatch.created = missing


def _remove_created(run_dir: Path) -> None:
    """Remove the directories Hydra created for a refused run (:class:`RunDirWatch`), deepest first, while they are
    empty; a directory that existed before, or that holds anything, is kept."""
    created = RunDirWatch.created
    if not created or created[0] != Path(os.path.abspath(run_dir)):
        return
    for d in created:
        if not d.is_dir() or any(d.iterdir()):
            break
        d.rmdir()


@hydra.main(config_path=CONFIG_DIR, config_name="config", version_base="1.3")
def main(cfg: DictConfig) -> None:
    """Hydra entry point. A user error is one line on stderr (and in run.log) and exit status 2; set
    ``HYDRA_FULL_ERROR=1`` for the traceback."""
    _use_agg_backend()
    from hydra.core.hydra_config import HydraConfig
    from hydra.types import RunMode

    hc = HydraConfig.get()
    logging.captureWarnings(True)  # Python warnings as log lines: in run.log, and not across progress bars
    run_dir = Path(hc.runtime.output_dir)

    def write_hydra_files() -> None:  # what Hydra's output_subdir would have written, once the dir is ours
        out = run_dir / ".hydra"
        out.mkdir(parents=True, exist_ok=True)
        OmegaConf.save(cfg, out / "config.yaml")
        OmegaConf.save(OmegaConf.create({"hydra": OmegaConf.to_container(hc, resolve=False)}), out / "hydra.yaml")
        OmegaConf.save(OmegaConf.create(list(hc.overrides.task)), out / "overrides.yaml")

    try:
        execute(cfg, run_dir, on_claimed=write_hydra_files)
    except _user_errors() as e:
        if os.environ.get("HYDRA_FULL_ERROR") == "1" or hc.mode == RunMode.MULTIRUN:
            raise  # a sweep records the failed job; the launcher reports it
        _remove_created(run_dir)
        log.error("%s", e)
        sys.exit(EXIT_USER_ERROR)
    except ResultsWriteError as e:  # disk full / I/O error: one line (the previous results are intact), status 1
        if os.environ.get("HYDRA_FULL_ERROR") == "1" or hc.mode == RunMode.MULTIRUN:
            raise
        log.error("%s", e)
        sys.exit(1)


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

    from hydra.errors import HydraException

    overrides = [f"experiment={name}", *overrides]
    try:
        with initialize_config_dir(config_dir=CONFIG_DIR, version_base="1.3"):
            cfg = compose(config_name="config", overrides=overrides)
    except HydraException as e:  # a mistyped key, a wrong type, a missing preset: the CLI's one line
        raise ConfigError(composition_error_line(e, overrides)) from e
    if run_dir is None:
        # microseconds: two calls in one second must not share (and be refused by) one run directory
        run_dir = Path("outputs") / name / datetime.datetime.now().strftime("%Y-%m-%d_%H-%M-%S_%f")
    with api_logging(Path(run_dir)):
        return execute(cfg, Path(run_dir))


def help_text() -> str:
    """What ``python -m deltajax.run --help`` prints: usage, the experiments (one line each), common keys."""
    exps = list_experiments()
    w = max(map(len, exps)) + 2
    robots = sorted(p.stem for p in (Path(CONFIG_DIR) / "robot").glob("*.yaml"))
    lines = [
        "usage: python -m deltajax.run [experiment=NAME] [KEY=VALUE ...]     (one run)",
        "       python -m deltajax.run -m experiment=NAME KEY=A,B ...         (a sweep: Hydra multirun)",
        "",
        "Runs one experiment (default: ga_reconfig, the main job) and writes results.h5 (HDF5, SI units),",
        "PNG plots and run.log into outputs/<experiment>/<date>_<time>/ (set it with hydra.run.dir=DIR;",
        "rerun into a killed run's directory to resume).",
        "",
        "experiments (experiment=NAME; settings in configs/experiment/NAME.yaml):",
        *[f"  {n:<{w}}{d}" for n, d in exps.items()],
        "",
        "common keys:",
        f"  robot=NAME           robot preset: {', '.join(robots)}; then e.g. robot.forearm=0.45 (m),",
        "                       robot.theta_min_deg=-40 (deg)",
        "  experiment.KEY=V     an experiment setting (see its yaml), e.g. experiment.h=0.004",
        "  precision=float64    float64 (analysis default) | float32 (throughput)",
        "  seed=0  plots=true  progress=true  compilation_cache=null",
        "  hydra/launcher=joblib | slurm | slurm_local   (with -m; see docs/CLUSTER.md)",
        "",
        "other flags: --cfg job (print the composed config and exit), --hydra-help (Hydra's own options).",
        "A bad value stops the run with one line naming the field (exit status 2); HYDRA_FULL_ERROR=1 shows",
        "the traceback.",
        f"configs: {CONFIG_DIR}",
    ]
    return "\n".join(lines)


def check_overrides(args: Iterable[str]) -> Optional[str]:
    """:func:`deltajax.overrides.check_overrides` against this CLI's configs (:data:`CONFIG_DIR`)."""
    return check(args, CONFIG_DIR)


def composition_error_line(exc: Exception, overrides: Iterable[str]) -> str:
    """:func:`deltajax.overrides.composition_error_line` against this CLI's configs (:data:`CONFIG_DIR`)."""
    return line(exc, overrides, CONFIG_DIR)


def check_sweep(args: Iterable[str]) -> Optional[str]:
    """The one-line refusal of a multirun command line (``-m``) with a bad value in any of its jobs, or None.

    Every job's config (:func:`deltajax.overrides.sweep_jobs`) gets the checks a single run gets before its claim
    (:func:`_validated`), in a child process: this one stays without a JAX backend, which the sweep's
    worker callback configures per job. Sweeps only Hydra's sweeper can expand are left to the jobs."""
    import subprocess

    if sweep_jobs(args) is None:
        return None
    code = "import sys; from deltajax.run import _check_sweep_main; sys.exit(_check_sweep_main(sys.argv[1:]))"
    proc = subprocess.run([sys.executable, "-c", code, *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                          text=True)
    if proc.returncode == 0:
        return None
    lines = [ln for ln in proc.stderr.splitlines() if ln.startswith("ERROR: ")]
    if proc.returncode == EXIT_USER_ERROR and lines:
        return lines[-1][len("ERROR: "):]
    raise RuntimeError(f"the check of the sweep's jobs failed (exit status {proc.returncode}):\n{proc.stderr}")


def _check_sweep_main(args: list) -> int:
    """The child process of :func:`check_sweep`: each job's config composed and validated in turn."""
    from hydra.errors import HydraException

    logging.getLogger().setLevel(logging.ERROR)  # the child's only output is the refusal
    for i, overrides in enumerate(sweep_jobs(args)):
        try:
            _validated(compose_config(overrides, CONFIG_DIR))
        except HydraException as e:
            problem = composition_error_line(e, overrides)
        except _user_errors() as e:
            problem = str(e)
        else:
            continue
        print(f"ERROR: sweep job {i} ({' '.join(overrides)}): {problem}", file=sys.stderr)
        return EXIT_USER_ERROR
    return 0


def cli(argv: Optional[list] = None) -> int:
    """Console entry point (``python -m deltajax.run`` / ``deltajax``): our ``--help``, an early check of
    ``experiment=NAME``, then Hydra."""
    args = sys.argv[1:] if argv is None else list(argv)
    if "--help" in args or "-h" in args:
        print(help_text())
        return 0
    known = None
    for a in args:
        if a.startswith("experiment="):
            known = known or list_experiments()
            bad = [n for n in a.split("=", 1)[1].split(",") if n not in known]
            if bad:
                print(f"ERROR: experiment={bad[0]} is not an experiment; choose one of: {', '.join(known)} "
                      "(python -m deltajax.run --help describes them)", file=sys.stderr)
                return EXIT_USER_ERROR
    # HYDRA_FULL_ERROR=1: the user wants Hydra's own error with its traceback
    problem = None if os.environ.get("HYDRA_FULL_ERROR") == "1" else check_overrides(args)
    if problem is None and os.environ.get("HYDRA_FULL_ERROR") != "1":
        problem = check_sweep(args)  # every job of a multirun, before Hydra creates the sweep directory
    if problem is not None:  # Hydra would print several lines (and suggest +key=value for a typo), exit 1
        print(f"ERROR: {problem}", file=sys.stderr)
        return EXIT_USER_ERROR
    if argv is not None:
        sys.argv = [sys.argv[0], *args]
    main()
    return 0


if __name__ == "__main__":
    # run the imported module's cli, not this __main__ copy: Hydra instantiates deltajax.run.RunDirWatch, whose
    # class-wide record of created directories _remove_created must read (else a refused run leaves them behind)
    from deltajax.run import cli as _package_cli

    sys.exit(_package_cli())
