"""The main job's state in ``results.h5``: the GA checkpoint's contents (:data:`GA_CHECKPOINT`) and a
continued run's earlier front joined to the verified candidates (:func:`carry_earlier`; the earlier run itself is read with
the settings, :func:`deltajax.config.ga_reconfig_run.earlier_run`). The finished stages and restaging before a resume
are :mod:`deltajax.rundir`'s (``recorded``, ``restage``).

Application wing: it reads the results file; the engines (:mod:`deltajax.optimize`) never do. The checkpoint's identity,
verification and commits are the stage engine's (:class:`deltajax.jobs.stages.Checkpoint`).
"""

from __future__ import annotations

import math
import re
from typing import Any, Mapping, Sequence

import numpy as np

from ..optimize.workflow import STORED_METRIC, SetupError

__all__ = ["read_checkpoint", "put_checkpoint", "GA_CHECKPOINT", "carry_earlier"]


# -- results-file bookkeeping (checkpoint, restaging, stages) -------------------------------------------------------

def _history_name(k: str) -> str:
    return k.replace("/", "__")


def read_checkpoint(ck: Mapping[str, Any]) -> dict:
    """The GA checkpoint (the ``ga/checkpoint`` group as :func:`deltajax.io.load` gives it, verified and of this run
    by the stage engine, :class:`deltajax.jobs.stages.Checkpoint`) as :func:`deltajax.optimize.run_ga` resumes
    from it. Raises KeyError, TypeError or ValueError when it is malformed (the engine's one-line refusal)."""
    attrs = ck["attrs"]
    out = {"generations_done": int(attrs["generations_done"]),
           "state": {k: v for k, v in ck["state"].items() if re.fullmatch(r"leaf_\d{3}", k)},
           "key": ck["key"], "population": ck["population"], "fitness": ck["fitness"],
           "history": {k.replace("__", "/"): v for k, v in ck["history"].items()
                       if k not in ("attrs", "units", "generation", "gene")}}
    if out["generations_done"] != len(np.asarray(ck["history"].get("generation", []))):
        raise ValueError(f"generations_done={out['generations_done']} does not match its history")
    return out


def put_checkpoint(res, ck: Mapping[str, Any]) -> None:
    """Stage the GA checkpoint ``ck`` (as :func:`deltajax.optimize.run_ga` saves it) into group ``ga/checkpoint``
    (the stage engine stamps the run's fingerprint and flushes)."""
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
    res.set_attrs(g, generations_done=n)


#: The GA stage's checkpoint on the stage engine: ``runner.checkpoint("ga", **GA_CHECKPOINT)``.
GA_CHECKPOINT = dict(group="ga/checkpoint", save=put_checkpoint, read=read_checkpoint, what="GA checkpoint",
                     note=lambda ck: f"generation {int(ck['generations_done'])}")


# -- continuing a finished run with more budget (experiment.continue_from) --------------------------------------------

def carry_earlier(mv: Mapping[str, np.ndarray], earlier, objs: Sequence[str]) -> dict:
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
