"""The main job's state in ``results.h5``: the GA checkpoint (:func:`load_checkpoint`, :func:`put_checkpoint`) and a
continued run's earlier front joined to the verified candidates (:func:`carry_earlier`; the earlier run itself is read with
the settings, :func:`deltajax.config.ga_reconfig_run.earlier_run`). The finished stages and restaging before a resume
are :mod:`deltajax.rundir`'s (``recorded``, ``restage``).

Application wing: it reads the results file; the engines (:mod:`deltajax.optimize`) never do.
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from ..optimize.workflow import STORED_METRIC, SetupError

__all__ = ["load_checkpoint", "put_checkpoint", "carry_earlier"]


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
