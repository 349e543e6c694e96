"""The main job's state in ``results.h5``: the GA checkpoint (:func:`load_checkpoint`, :func:`put_checkpoint`), the
finished stages (:func:`stages_done`; restaging, :func:`restage`, is the stage engine's), the job's
fingerprint (:func:`job_fingerprint`) and continuing a finished run with more budget (:func:`earlier_run`,
:func:`carry_earlier`: only :data:`BUDGET_SETTINGS` may differ; its verified front seeds the searches and joins
the verified candidates with the metrics it verified).

Application wing: it reads the config and the results file; the engines (:mod:`deltajax.optimize`) never do.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import re
from pathlib import Path
from typing import Any, Mapping, Optional, Sequence

import numpy as np

from ..optimize.workflow import STORED_METRIC, SetupError
from .stages import recorded, restage

__all__ = ["load_checkpoint", "put_checkpoint", "restage", "stages_done", "job_fingerprint", "BUDGET_SETTINGS",
           "EarlierRun", "continued_file", "earlier_run", "carry_earlier"]


# -- results-file bookkeeping (checkpoint, restaging, stages) -------------------------------------------------------

def _history_name(k: str) -> str:
    return k.replace("/", "__")


def load_checkpoint(path) -> Any:
    """The GA checkpoint stored in a results.h5, or None; verified (checksums, integrity record) before use.

    Raises:
        deltajax.rundir.CheckpointError: the checkpoint is damaged, edited or malformed (one line: the path, what
            is wrong, ``fresh=true``).
    """
    from ..io import ChecksumError, ResultsGroupError, load
    from ..rundir import CheckpointError

    if not Path(path).exists():
        return None
    todo = "add fresh=true to start over (the checkpoint is part of results.h5)"
    try:
        ck = load(path, "ga/checkpoint", verify=True)
    except ResultsGroupError:
        return None
    except ChecksumError as e:
        raise CheckpointError(f"cannot resume the GA from {path}: {str(e).replace(f'{path}:', '')}; {todo}") from None
    try:
        attrs = ck["attrs"]
        state = {k: v for k, v in ck["state"].items() if re.fullmatch(r"leaf_\d{3}", k)}
        hist = {k.replace("__", "/"): v for k, v in ck["history"].items()
                if k not in ("attrs", "units", "generation", "gene")}
        out = {"fingerprint": str(attrs["fingerprint"]), "generations_done": int(attrs["generations_done"]),
               "state": state, "key": ck["key"], "history": hist, "population": ck["population"],
               "fitness": ck["fitness"]}
    except (KeyError, TypeError, ValueError) as e:
        raise CheckpointError(f"cannot resume the GA from {path}: its ga/checkpoint is malformed ({type(e).__name__}: "
                              f"{e}); {todo}") from None
    if out["generations_done"] != len(np.asarray(ck["history"].get("generation", []))):
        raise CheckpointError(f"cannot resume the GA from {path}: ga/checkpoint generations_done="
                              f"{out['generations_done']} does not match its history; {todo}")
    return out


def put_checkpoint(res, ck: Mapping[str, Any]) -> None:
    g = "ga/checkpoint"
    for k, v in ck["state"].items():
        res.put(f"{g}/state", k, v, units="1")
    res.put(g, "key", ck["key"], units="1")
    n = int(ck["generations_done"])
    res.put_axis(f"{g}/history", "generation", np.arange(1, n + 1), units="1")
    for k, v in ck["history"].items():
        v = np.asarray(v)
        dims = ("generation",) + (("gene",) if v.ndim == 2 else ())
        res.put(f"{g}/history", _history_name(k), v, units="1", dims=dims)
    res.put(g, "population", ck["population"], units="1", dims=("member", "gene"))
    res.put(g, "fitness", ck["fitness"], units="1", dims=("member",))
    res.set_attrs(g, fingerprint=ck["fingerprint"], generations_done=int(ck["generations_done"]))


def job_fingerprint(cfg) -> str:
    """Hash of everything that determines a run's results (not resume/stop_after/progress/plots)."""
    from omegaconf import OmegaConf

    c = OmegaConf.to_container(cfg, resolve=True)
    e = dict(c.get("experiment", {}))
    e.pop("resume", None)
    e.pop("stop_after", None)
    blob = json.dumps({"experiment": e, "robot": c.get("robot"), "seed": c.get("seed"),
                       "precision": c.get("precision")}, sort_keys=True, default=str)
    return hashlib.sha256(blob.encode()).hexdigest()[:16]


def stages_done(path: Path) -> tuple[Optional[str], list]:
    """(fingerprint, finished stages) of the ``ga_reconfig`` run recorded in ``path``
    (:func:`deltajax.jobs.stages.recorded`)."""
    return recorded(path, "ga_reconfig")


# -- continuing a finished run with more budget (experiment.continue_from) --------------------------------------------

#: Settings a continued run may change: the search's budget (besides :data:`deltajax.rundir.NEUTRAL`, which never
#: change the numbers). Everything else (robot, precision, the problem, the verification grids, the recommendation
#: rule) must equal the earlier run's, so that its verified metrics hold here.
BUDGET_SETTINGS = ("seed", "experiment.continue_from", "experiment.screen", "experiment.ga",
                   "experiment.pareto.enabled", "experiment.pareto.population_size", "experiment.pareto.generations",
                   "experiment.refine", "experiment.floor_solve",
                   # the tolerance analysis reads the verified designs and changes none of their numbers
                   "experiment.tolerance", "experiment.robust")


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
    more budget. Raises :class:`SetupError` (one line naming ``experiment.continue_from``) when it is missing,
    unfinished, or a run of another problem: only :data:`BUDGET_SETTINGS` may differ. Reads the file only
    (nothing compiles)."""
    import yaml
    from omegaconf import OmegaConf

    from ..io import load
    from ..rundir import config_differences, describe_differences

    key = "experiment.continue_from"
    p = continued_file(where)
    if not p.is_file():
        raise SetupError(f"{key}: {where} is neither a run directory holding a results.h5 nor a results file")
    try:
        fp, done = stages_done(p)
        data = load(p)
        old = yaml.safe_load(data["attrs"]["config"])
    except (OSError, KeyError, ValueError, yaml.YAMLError) as err:
        raise SetupError(f"{key}: {p} cannot be read as a ga_reconfig run ({type(err).__name__}: {err})") from None
    if not fp or not isinstance(old, Mapping) or old.get("experiment", {}).get("name") != "ga_reconfig":
        raise SetupError(f"{key}: {p} holds no ga_reconfig run")
    if "verify" not in done:
        raise SetupError(f"{key}: the run in {p} has not finished its verification (stages done: "
                         f"{','.join(done) or 'none'}); resume it first (rerun with hydra.run.dir={p.parent})")
    new = OmegaConf.to_container(cfg, resolve=True)
    diffs = config_differences(old, new, ignore=BUDGET_SETTINGS)
    if diffs:
        raise SetupError(f"{key}: {p} is a run of another problem ({describe_differences(diffs)}); a continued run "
                         "may change only the search budget (seed, experiment.screen, .ga, .pareto population_size "
                         "and generations, .refine, .floor_solve, .tolerance, .robust)")
    V = data["verify"]
    rows = np.asarray(V["front"], int).reshape(-1)
    genes = np.asarray(V["genes"], float)
    names = [str(n) for n in np.asarray(V["design_name"]).reshape(-1)[rows]]
    rec = int(V["attrs"]["recommended"])
    # "earlier_" on every carried name (a chain of continuations gives earlier_earlier_..., names stay unique)
    return EarlierRun(path=p.resolve(), fingerprint=fp, names=tuple(f"earlier_{n}" for n in names),
                      genes=genes.reshape(-1, genes.shape[-1])[rows], rows=rows, verify=V,
                      recommended=int(np.flatnonzero(rows == rec)[0]) if rec in rows else -1)


def carry_earlier(mv: Mapping[str, np.ndarray], earlier: EarlierRun, objs: Sequence[str]) -> dict:
    """This run's fine-grid metrics ``mv`` (row 0: the baseline) followed by the earlier run's front points with
    the metrics *it* verified (stored, not recomputed: its recommendation keeps its exact numbers). Raises
    :class:`SetupError` when the earlier run's verified baseline differs from this run's (another deltajax
    computed it) or its file lacks a metric this run has."""
    V = earlier.verify
    missing = [k for k in mv if STORED_METRIC.get(k, k) not in V]
    if missing:
        raise SetupError(f"experiment.continue_from: {earlier.path} lacks the metrics {', '.join(sorted(missing))} "
                         "(written by an older deltajax); start a new run")
    for o in objs:
        a, b = float(np.asarray(V[o])[0]), float(mv[o][0])
        if not math.isclose(a, b, rel_tol=1e-9, abs_tol=1e-12):
            raise SetupError(f"experiment.continue_from: the baseline's {o} verifies to {b!r} here but {a!r} in "
                             f"{earlier.path} (computed by another deltajax); start a new run")
    out = {}
    for k, v in mv.items():
        old = np.asarray(V[STORED_METRIC.get(k, k)])[earlier.rows]
        out[k] = np.concatenate([np.asarray(v), old.astype(np.asarray(v).dtype)])
    return out
