"""The screen's feasible non-dominated set seeds NSGA-II (workflow.screen_front / spread_rows)."""

import numpy as np

from deltajax.optimize import workflow as W
from deltajax.optimize.pareto import non_dominated


def test_screen_front_is_the_feasible_non_dominated_set_sorted():
    rng = np.random.default_rng(3)
    X = rng.random((200, 4))
    sc = {"X": X, "order": np.arange(0, 200, 2)}                 # the screen's feasible designs, best first
    calls = []

    def evaluate(G):                                             # independent toy objectives: maximise both
        calls.append(len(G))
        return {"a": G[:, 0], "b": 1.0 - G[:, 0] ** 2 + 0.3 * G[:, 1], "feasible": G[:, 2] < 0.7}

    scale = np.asarray([-1.0, -1.0])
    got = W.screen_front(evaluate, sc, ["a", "b"], scale, cap=60)
    assert calls == [60]                                         # only the capped feasible designs evaluated
    C = X[np.arange(0, 120, 2)]
    C = C[C[:, 2] < 0.7]
    F = np.stack([-C[:, 0], -(1.0 - C[:, 0] ** 2 + 0.3 * C[:, 1])], axis=1)
    # brute force: no other candidate is at least as good in both and better in one
    nd = [i for i in range(len(C)) if not any(np.all(F[j] <= F[i]) and np.any(F[j] < F[i]) for j in range(len(C)))]
    assert {tuple(x) for x in got} == {tuple(x) for x in C[nd]}
    assert np.all(np.diff(-got[:, 0]) >= 0)                      # sorted by the first (minimised) objective
    assert len(non_dominated(np.stack([-got[:, 0], -(1.0 - got[:, 0] ** 2 + 0.3 * got[:, 1])], 1))) == len(got)


def test_screen_front_layers_are_non_dominated_sorting():
    rng = np.random.default_rng(5)
    X = rng.random((80, 3))
    sc = {"X": X, "order": np.arange(80)}

    def evaluate(G):
        return {"a": G[:, 0], "b": G[:, 1], "feasible": G[:, 2] < 0.8}

    got = W.screen_front(evaluate, sc, ["a", "b"], np.asarray([-1.0, -1.0]), layers=True)
    C = X[X[:, 2] < 0.8]
    assert {tuple(x) for x in got} == {tuple(x) for x in C}     # every feasible design, once
    # independent rank: a design's layer is 1 + the largest layer of the designs dominating it
    F = -got[:, :2]
    dom = lambda i, k: np.all(F[k] <= F[i]) and np.any(F[k] < F[i])  # noqa: E731
    rank = np.zeros(len(F), int)
    order = sorted(range(len(F)), key=lambda i: F[i].sum())     # a dominator always has a smaller sum
    for i in order:
        rank[i] = max([rank[k] + 1 for k in range(len(F)) if dom(i, k)], default=0)
    assert np.all(np.diff(rank) >= 0)                            # returned layer by layer
    first = W.screen_front(evaluate, sc, ["a", "b"], np.asarray([-1.0, -1.0]))
    assert len(first) == int(np.sum(rank == 0))
