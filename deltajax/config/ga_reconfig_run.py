"""The main job's run, built once from its settings (:mod:`deltajax.config.ga_reconfig`): the run's identity
(:func:`job_fingerprint`), the finished run that ``experiment.continue_from`` continues (:func:`earlier_run`: only
:data:`BUDGET_SETTINGS` may differ) and the job's :class:`GaReconfigSetup` (settings, design space, problem, GA
configuration) built by :func:`ga_reconfig_build` (the library's :class:`deltajax.optimize.workflow.SetupError`
becomes a one-line :class:`ConfigError`)."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any, Mapping, Optional

import numpy as np

from ..rundir import config_differences, describe_differences, recorded
from ..workspace.chunks import fingerprint
from .ga_reconfig import GaReconfigSettings, ga_reconfig_settings
from .readers import ConfigError
from ..io import load
from ..optimize.workflow import setup, SetupError

__all__ = ["GaReconfigSetup", "ga_reconfig_build", "validate_ga_reconfig", "validate_ga_reconfig_run_dir",
           "job_fingerprint", "BUDGET_SETTINGS", "problem_differences", "EarlierRun", "continued_file",
           "earlier_run"]


# ---- the run's identity and continuing a finished run (experiment.continue_from) ----

def job_fingerprint(cfg) -> str:
    """Hash of everything that determines a run's results (not resume/stop_after/progress/plots): the one
    identity hash (:func:`deltajax.workspace.chunks.fingerprint`) of the config's experiment, robot, seed and
    precision."""
    from omegaconf import OmegaConf

    c = OmegaConf.to_container(cfg, resolve=True) if OmegaConf.is_config(cfg) else dict(cfg)
    e = dict(c.get("experiment", {}))
    e.pop("resume", None)
    e.pop("stop_after", None)
    return fingerprint({"experiment": e, "robot": c.get("robot"), "seed": c.get("seed"),
                        "precision": c.get("precision")})



#: Settings a continued run may change: the search's budget (besides :data:`deltajax.rundir.NEUTRAL`, which never
#: change the numbers). Everything else (robot, precision, the problem, the verification grids, the recommendation
#: rule) must equal the earlier run's, so that its verified metrics hold here.
BUDGET_SETTINGS = ("seed", "experiment.continue_from", "experiment.screen", "experiment.ga",
                   "experiment.pareto.enabled", "experiment.pareto.population_size", "experiment.pareto.generations",
                   "experiment.refine", "experiment.floor_solve",
                   # the tolerance analysis reads the verified designs and changes none of their numbers
                   "experiment.tolerance", "experiment.robust.enabled", "experiment.robust.probability",
                   "experiment.robust.confirm_seed", "experiment.robust.max_candidates")
# (experiment.robust.margins is not a budget setting: it tightens the problem the earlier run verified)


def problem_differences(old: Mapping[str, Any], new: Mapping[str, Any]) -> list:
    """The settings (dotted key, there, here) in which two runs' configurations pose different problems: every
    difference but :data:`BUDGET_SETTINGS`; an unset margin and a zero one (``experiment.robust.margins``) are the
    same constraint (a run made before margins existed poses the problem a run with zero margins does)."""
    return [d for d in config_differences(old, new, ignore=BUDGET_SETTINGS)
            if not (d[0].startswith("experiment.robust.margins.") and {d[1], d[2]} <= {"<unset>", 0, 0.0})]


@dataclasses.dataclass(frozen=True)
class EarlierRun:
    """The verified front of a finished ``ga_reconfig`` run that a run continues (:func:`earlier_run`)."""

    path: Path                 # its results.h5
    fingerprint: str           # its ga_reconfig_fingerprint
    names: tuple               # its front points' names there, each prefixed "earlier_"
    genes: np.ndarray          # (k, d) their genes
    rows: np.ndarray           # (k,) their rows on its verify group's design axis
    verify: Mapping[str, Any]  # its verify group as loaded (metrics on the fine grids)
    recommended: int           # index into names/genes of its recommendation (-1: none)


def continued_file(where: str) -> Path:
    """The results file that ``experiment.continue_from`` names (a run directory or a results.h5)."""
    p = Path(str(where)).expanduser()
    return p / "results.h5" if p.is_dir() or not p.suffix else p


def earlier_run(where: str, cfg) -> EarlierRun:
    """The finished run ``where`` (its run directory or results.h5) that this run (config ``cfg``) continues with
    more budget. Raises :class:`ConfigError` (one line naming ``experiment.continue_from``) when it is missing,
    unfinished, or a run of another problem: only :data:`BUDGET_SETTINGS` may differ. Reads the file only
    (nothing compiles)."""
    import yaml
    from omegaconf import OmegaConf

    key = "experiment.continue_from"
    p = continued_file(where)
    if not p.is_file():
        raise ConfigError(f"{key}: {where} is neither a run directory holding a results.h5 nor a results file")
    try:
        fp, done = recorded(p, "ga_reconfig")
        data = load(p)
        old = yaml.safe_load(data["attrs"]["config"])
    except (OSError, KeyError, ValueError, yaml.YAMLError) as err:
        raise ConfigError(f"{key}: {p} cannot be read as a ga_reconfig run ({type(err).__name__}: {err})") from None
    if not fp or not isinstance(old, Mapping) or old.get("experiment", {}).get("name") != "ga_reconfig":
        raise ConfigError(f"{key}: {p} holds no ga_reconfig run")
    if "verify" not in done:
        raise ConfigError(f"{key}: the run in {p} has not finished its verification (stages done: "
                         f"{','.join(done) or 'none'}); resume it first (rerun with hydra.run.dir={p.parent})")
    new = OmegaConf.to_container(cfg, resolve=True)
    diffs = problem_differences(old, new)
    if diffs:
        raise ConfigError(f"{key}: {p} is a run of another problem ({describe_differences(diffs)}); a continued run "
                         "may change only the search budget (seed, experiment.screen, .ga, .pareto population_size "
                         "and generations, .refine, .floor_solve, .tolerance, .robust but its margins)")
    V = data["verify"]
    rows = np.asarray(V["front"], int).reshape(-1)
    genes = np.asarray(V["genes"], float)
    names = [str(n) for n in np.asarray(V["design_name"]).reshape(-1)[rows]]
    rec = int(V["attrs"]["recommended"])
    # "earlier_" on every carried name (a chain of continuations gives earlier_earlier_..., names stay unique)
    return EarlierRun(path=p.resolve(), fingerprint=fp, names=tuple(f"earlier_{n}" for n in names),
                      genes=genes.reshape(-1, genes.shape[-1])[rows], rows=rows, verify=V,
                      recommended=int(np.flatnonzero(rows == rec)[0]) if rec in rows else -1)



@dataclasses.dataclass(frozen=True)
class GaReconfigSetup:
    """What the main job runs on, built once per run from its settings: the settings, the design space, the
    coarse (search) problem, the GA's configuration and, for ``experiment.continue_from``, the earlier run
    (:class:`EarlierRun`; None for a new search)."""

    settings: GaReconfigSettings
    space: Any
    problem: Any
    ga: Any
    earlier: Any = None
    fingerprint: str = ""    # the run's identity (:func:`job_fingerprint`)


def validate_ga_reconfig(e, cfg, robot, recon) -> GaReconfigSetup:
    """The main job's :class:`GaReconfigSetup`: every field, the design space, the GA settings, the problem and a
    continued run's earlier run (finished, of the same problem; its file only)."""
    s, space, pb, ga = ga_reconfig_build(e, robot, recon)
    earlier = None
    if s.continue_from is not None:
        earlier = earlier_run(s.continue_from, cfg)
    return GaReconfigSetup(settings=s, space=space, problem=pb, ga=dataclasses.replace(ga, seed=int(cfg.get("seed"))),
                           earlier=earlier, fingerprint=job_fingerprint(cfg))


def validate_ga_reconfig_run_dir(e, run_dir) -> None:
    """The run directory is not the run that ``experiment.continue_from`` reads (with fresh=true its claim would
    delete what this run continues)."""
    cont = e.get("continue_from")
    if cont is not None and continued_file(cont).resolve() == (Path(run_dir) / "results.h5").resolve():
        raise ConfigError(f"experiment.continue_from={cont} is this run's own directory; continue into another "
                          "hydra.run.dir (to resume a run, rerun into its directory without continue_from)")


def ga_reconfig_build(ectx: Mapping[str, Any], robot, recon, *, n_R: Optional[int] = None):
    """(settings, design space, coarse problem, GA config) of experiment=ga_reconfig, validated (one ConfigError
    line naming the field and the value)."""
    s = ga_reconfig_settings(ectx)
    try:
        space, pb = setup(s, robot, recon, n_R=n_R)
    except SetupError as err:
        raise ConfigError(str(err)) from None
    return s, space, pb, s.ga

