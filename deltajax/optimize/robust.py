"""The robust recommendation (``experiment.robust``) of the main job's ``tolerance`` stage.

The stage runs after ``verify`` on the verification problem and reads only what ``verify`` stored (so a resumed run
computes the same): the Monte Carlo of :func:`deltajax.tolerance.analyse` for the baseline and the recommendation,
stored in the results group ``tolerance`` by the application (:mod:`deltajax.jobs.designer_store`); this module
only chooses.

**Robust recommendation** (``experiment.robust.enabled``): the recommendation rule
(:func:`deltajax.optimize.workflow.recommend`) is applied among the verified candidates that hold every constraint
in at least ``robust.probability`` of the Monte Carlo samples. It is found lazily: the rule picks from the verified
front of the feasible candidates not yet found wanting; that design gets the Monte Carlo (``tolerance.seed``); below
the probability it is set aside and the rule picks again. Whatever it picks then holds at the probability and is
the rule's answer among the candidates that do (for ``floor`` and ``primary`` exactly: a candidate never checked is
dominated by, or ranks after, the one chosen). The chosen design is then confirmed by a *fresh* Monte Carlo with
``robust.confirm_seed`` (independent of the samples that selected it); if that falls below the probability it is
set aside too. At most ``robust.max_candidates`` designs are checked. The nominal recommendation stays stored next
to the robust one (``verify`` attribute ``recommended_nominal``, group ``tolerance/robust``): what robustness costs.
"""

from __future__ import annotations

import dataclasses
from typing import Any, Callable, Optional, Sequence

import numpy as np

from .pareto import non_dominated

__all__ = ["robust_choice", "RobustChoice"]


@dataclasses.dataclass(frozen=True)
class RobustChoice:
    """What the robust selection checked and chose.

    Attributes:
        chosen: verify row of the robust recommendation (-1: none found within the cap).
        checked: verify rows checked, in order.
        p_selection: their Monte Carlo probability that every constraint holds (``tolerance.seed``).
        p_confirm: the fresh Monte Carlo's probability (``robust.confirm_seed``) for the designs that passed the
            selection (NaN for the others).
        results: the :func:`deltajax.tolerance.analyse` results, per checked row (selection) and the confirmation.
        exhausted: True when every feasible candidate was checked (no robust design exists among them).
    """

    chosen: int
    checked: tuple
    p_selection: tuple
    p_confirm: tuple
    results: dict
    confirm: Optional[dict]
    exhausted: bool


def robust_choice(analyse_rows: Callable[[Sequence[int], int], dict], F: np.ndarray, feasible: np.ndarray,
                  rule: Callable[[np.ndarray], int], probability: float, seed: int, confirm_seed: int,
                  max_candidates: int, known: Optional[dict] = None,
                  log: Callable[[str], Any] = lambda _m: None) -> RobustChoice:
    """The robust recommendation (module docstring).

    Args:
        analyse_rows: ``(rows, seed) -> analyse result`` of the verified designs ``rows``.
        F: (n, k) verified minimised objectives; feasible: (n,) nominal feasibility on the fine grids.
        rule: ``front rows -> chosen row`` (the job's recommendation rule; -1 for an empty front).
        probability: required probability that every constraint holds.
        known: ``{row: result of analyse_rows([row], seed)}`` already computed (reused, same seed).
    """
    ok = np.asarray(feasible, bool) & np.all(np.isfinite(F), axis=1)
    out_rows, p_sel, p_conf, results = [], [], [], dict(known or {})
    wanting: set = set()
    confirm = None
    while True:
        rest = np.asarray([i for i in np.flatnonzero(ok) if i not in wanting], int)
        if len(rest) == 0:
            return RobustChoice(-1, tuple(out_rows), tuple(p_sel), tuple(p_conf), results, None, True)
        nd = rest[non_dominated(F[rest])]
        nd = nd[np.lexsort(F[nd].T[::-1])]
        r = int(rule(nd))
        if len(out_rows) >= max_candidates:
            log(f"robust: {max_candidates} candidates checked (experiment.robust.max_candidates), none holds every "
                f"constraint in >= {probability:g} of the samples")
            return RobustChoice(-1, tuple(out_rows), tuple(p_sel), tuple(p_conf), results, None, False)
        if r not in results:
            results[r] = analyse_rows([r], seed)
        p = float(results[r]["p_all"][0])
        out_rows.append(r)
        p_sel.append(p)
        if p < probability:
            p_conf.append(float("nan"))
            wanting.add(r)
            continue
        confirm = analyse_rows([r], confirm_seed)
        pc = float(confirm["p_all"][0])
        p_conf.append(pc)
        if pc < probability:
            log(f"robust: row {r} held in {p:.4f} of the selection samples but {pc:.4f} of the fresh ones; set aside")
            wanting.add(r)
            continue
        return RobustChoice(r, tuple(out_rows), tuple(p_sel), tuple(p_conf), results, confirm, False)
