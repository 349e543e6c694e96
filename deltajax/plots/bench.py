"""Benchmark figures: kernel throughputs."""

from __future__ import annotations

import numpy as np

from .core import pyplot

__all__ = ["bench_rates", "bench_rates_from_results"]


def bench_rates(rates: dict, baseline: str, title: str = "kernel throughput"):
    """Horizontal bars of throughputs (evaluations/s, log scale), each labelled with its ratio to ``baseline``.

    Args:
        rates: label -> evaluations per second.
        baseline: the label the ratios are taken against (e.g. the NumPy reference).
        title: figure title (say what was measured and where).
    """
    plt = pyplot()
    names = list(rates)
    v = np.asarray([rates[n] for n in names], float)
    fig, ax = plt.subplots(figsize=(7.5, 0.55 * len(names) + 1.4), layout="constrained")
    colors = ["0.55" if n == baseline else "tab:blue" for n in names]
    ax.barh(range(len(names)), v, color=colors)
    ax.set_yticks(range(len(names)), names)
    ax.invert_yaxis()
    ax.set_xscale("log")
    ax.set_xlabel(f"evaluations per second (warm; higher is better); x = ratio to {baseline}")
    ax.set_xlim(v[v > 0].min() / 3 if np.any(v > 0) else 1, v.max() * 12 if v.size else 10)
    base = rates[baseline]
    for i, val in enumerate(v):
        ax.text(val * 1.08, i, f"{val / 1e6:.3g} M/s, x{val / base:.2g}", va="center", fontsize=8)
    ax.set_title(title, fontsize=10)
    ax.grid(axis="x", alpha=0.3, which="both")
    return fig



def bench_rates_from_results(results, title: str = "kernel throughput"):
    """:func:`bench_rates` of every scalar rate (units ``1/s``) staged under the ``bench`` group of a
    :class:`deltajax.io.ResultsFile`, labelled ``<subgroup> <name>``; the baseline is the NumPy rate."""
    rates = {}
    for g, name, data, units in results.staged("bench"):
        if units == "1/s" and np.ndim(data) == 0:
            words = " ".join([*g.split("/")[1:], name]).replace("_", " ").split()
            words = [{"cpu": "(CPU time)", "wall": "(wall)"}.get(w, w) for w in words if w != "rate"]
            if words in (["float32"], ["float64"]):
                words.append("jax fast")
            rates[" ".join(words)] = float(data)
    if not rates:
        raise ValueError("no rates (datasets in 1/s) staged under 'bench'")
    baseline = next((k for k in rates if "numpy" in k), next(iter(rates)))
    return bench_rates(rates, baseline, title)

