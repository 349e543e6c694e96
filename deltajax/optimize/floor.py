"""The floor rule's question asked directly: the best primary objective subject to every other objective at least
``floor`` x the verified baseline's (an epsilon-constraint step after the verification).

The verified front is a sample of the true one. Where it is steep (the main job: 0.3 % of picks/min buys 8 % of
regular workspace near the floor), reading the answer off the first sampled point above the floor makes the
recommendation's other objectives depend on where that run's front happens to have gaps (docs/REPRODUCTION.md
§5.2). :func:`solve_floor` therefore solves for it: from every verified front point that meets the floor it runs
the refinement's descent on the primary objective (projected Adam with the constraint penalty, on the search
grids, the same compiled program as :func:`deltajax.optimize.descent.refine_designs`); along each path the
primary improves and the other objectives fall toward the floor. Each iterate's fine-grid objectives are
predicted from its search-grid ones times its start's fine/search ratio; the feasible iterates predicted to meet
the floor, best predicted primary first (each path's best, then each path's last-but-one as a margin, then the
rest), are verified on the fine grids in one batch. The caller adds them to the verified candidates and applies
the rule again, so the recommendation can only get better on the rule's own terms (a verified design that meets
the floor with a better primary, or the same one as before).
"""

from __future__ import annotations

import dataclasses
from typing import Any, Callable, Optional, Sequence

import numpy as np

from .descent import DESCENT_ROWS, descent_paths
from .programs import objective_matrix

__all__ = ["FloorOutcome", "solve_floor"]


@dataclasses.dataclass
class FloorOutcome:
    """What :func:`solve_floor` verified: ``genes`` (m, d), ``metrics`` (fine grids, like
    :func:`deltajax.optimize.workflow.verify`), ``start`` (m,) row of the caller's candidates each descent began
    at, ``step`` (m,) its iterate (1 = the first step), ``predicted`` (m, k) the predicted normalised fine-grid
    objectives, ``starts`` the rows descended from, ``n_predicted`` how many iterates were predicted to meet the
    floor."""

    genes: np.ndarray
    metrics: dict
    start: np.ndarray
    step: np.ndarray
    predicted: np.ndarray
    starts: np.ndarray
    n_predicted: int


def solve_floor(pb, space, cand: np.ndarray, Fv: np.ndarray, front: np.ndarray, objs: Sequence[str],
                scale: np.ndarray, primary: str, lim: np.ndarray, *, evaluate: Callable, evaluate_cheap: Callable,
                evaluate_fine: Callable, steps: int = 16, learning_rate: float = 0.01, penalty: float = 10.0,
                rounds: int = 4, n_fine: int = 8, max_starts: int = DESCENT_ROWS,
                progress: Optional[Callable[[int], Any]] = None) -> FloorOutcome:
    """Descend on ``primary`` from the verified front points (rows ``front`` of ``cand`` / ``Fv``) that meet the
    floor ``lim`` (:func:`deltajax.optimize.workflow.floor_limits`) and verify the ``n_fine`` most promising
    iterates on the fine grids.

    A path whose last iterate is still predicted to meet the floor (feasible, primary better than at its start)
    is continued from there (Adam restarted), up to ``rounds`` descents of ``steps`` steps, so a path far above
    the floor reaches it. ``progress`` gets 1 after each round and after the fine verification.
    ``Fv``: normalised minimised objectives on the fine grids (by the verified baseline); ``scale``: the search
    grids' normalisation (sense / |search baseline|); ``evaluate`` / ``evaluate_cheap``: search-grid batch
    evaluators with / without the regular workspace; ``evaluate_fine``: the verification's evaluator. Returns an
    empty outcome when no front point meets the floor (the rule's fallback then decides).
    """
    objs = list(objs)
    jp = objs.index(primary)
    d, k_obj = space.dim, len(objs)
    front = np.asarray(front, int).reshape(-1)
    lim = np.asarray(lim, float)
    meets = np.all(Fv[front] <= lim[None, :], axis=1) if len(front) else np.zeros(0, bool)
    starts = front[meets]
    starts = starts[np.argsort(Fv[starts, jp], kind="stable")][:max_starts]
    n = len(starts)
    empty = FloorOutcome(np.zeros((0, d)), {}, np.zeros(0, int), np.zeros(0, int), np.zeros((0, k_obj)), starts, 0)
    if not n:
        if progress is not None:
            progress(int(rounds) + 1)
        return empty
    # calibration: each start's fine / search ratio per objective (the start evaluated on the search grids)
    s0 = evaluate(cand[starts])
    F0 = objective_matrix(s0, objs, scale)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = Fv[starts] / F0
    ratio = np.where(np.isfinite(ratio) & (ratio > 0), ratio, np.nan)
    genes = [[] for _ in range(n)]      # per start: iterates of every round, in order
    pred = [[] for _ in range(n)]
    ok = [[] for _ in range(n)]
    cur, active = cand[starts].copy(), np.isfinite(ratio).all(axis=1)
    done = 0
    for _ in range(int(rounds)):
        live = np.flatnonzero(active)
        if not len(live):
            break
        done += 1
        _, path = descent_paths(pb, space, cur[live], objs, scale, primary, steps=steps,
                                learning_rate=learning_rate, penalty=penalty)
        X = path[:, 1:].reshape(-1, d)
        m_live, K = len(live), path.shape[1] - 1
        cheap = evaluate_cheap(X)
        P = np.asarray(cheap[primary], float) * scale[jp]
        better = cheap["feasible"].astype(bool) & np.isfinite(P) & (P < np.repeat(F0[live, jp], K))
        Fs = np.full((len(X), k_obj), np.nan)
        feas = np.zeros(len(X), bool)
        if better.any():
            full = evaluate(X[better])
            Fs[better] = objective_matrix(full, objs, scale)
            feas[better] = full["feasible"].astype(bool)
        Fp = (Fs.reshape(m_live, K, k_obj) * ratio[live][:, None, :])
        good = (better & feas).reshape(m_live, K) & np.all(np.isfinite(Fp), axis=2) & np.all(Fp <= lim, axis=2)
        for r, a in enumerate(live):
            genes[a].append(path[r, 1:])
            pred[a].append(Fp[r])
            ok[a].append(good[r])
            # continue while the path's last iterate still meets the floor (and beats the start)
            active[a] = bool(good[r, -1])
            cur[a] = path[r, -1]
        if progress is not None:
            progress(1)
    if progress is not None and done < int(rounds):
        progress(int(rounds) - done)                        # the rounds no path needed
    tiers = []
    for a in range(n):
        if not genes[a]:
            continue
        g_a, p_a, ok_a = np.concatenate(genes[a]), np.concatenate(pred[a]), np.concatenate(ok[a])
        genes[a], pred[a] = g_a, p_a
        ks = np.flatnonzero(ok_a)
        if not len(ks):
            continue
        # each path's best predicted primary, then its last ok iterate before that one (a margin against the
        # prediction's error), then every other ok iterate; best predicted primary first within each tier
        kb = ks[np.argmin(p_a[ks, jp])]
        before = ks[ks < kb]
        margin = before[-1] if len(before) else -1
        tiers.append((0, p_a[kb, jp], a, kb))
        if margin >= 0:
            tiers.append((1, p_a[margin, jp], a, margin))
        tiers += [(2, p_a[k, jp], a, k) for k in ks if k not in (kb, margin)]
    n_pred = len(tiers)
    if not tiers:
        if progress is not None:
            progress(1)
        return empty
    tiers.sort(key=lambda t: (t[0], t[1]))
    pick = [(a, k) for _, _, a, k in tiers[:n_fine]]
    G = np.stack([genes[a][k] for a, k in pick])
    mv = evaluate_fine(G)
    if progress is not None:
        progress(1)
    return FloorOutcome(genes=G, metrics=mv, start=np.asarray([starts[a] for a, _ in pick], int),
                        step=np.asarray([k + 1 for _, k in pick], int),
                        predicted=np.stack([pred[a][k] for a, k in pick]), starts=starts, n_predicted=n_pred)
