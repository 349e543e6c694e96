"""Franco-López 2026 §5: indices at the paper's example configurations (Tables 2-5) and index-vs-R curves
at its two example points (Figs 3-6), with the R that maximises every index.

Writes group ``examples`` (per table: R, p, theta, every index, the paper's printed values) and group
``curves`` (R axis x point: every index, feasibility; argmax R per index and point), plus ``index_curves.png``.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from ..indices import INDEX_NAMES, indices
from ..kinematics import ik
from ..papers import FRANCO2026_EXAMPLE_INDICES, FRANCO2026_EXAMPLES, FRANCO2026_MISPRINTS
from ..plots import plot_index_curves

__all__ = ["run", "SCALAR_INDICES", "UNITS"]

SCALAR_INDICES = tuple(n for n in INDEX_NAMES)
UNITS = {"manipulability": "m^3/rad^3", "imi": "rad^3/m^3"}


def run(ctx) -> None:
    spec = ctx.settings                                # checked before the run (config.indices_examples_settings)
    recon = ctx.recon
    dtype = ctx.dtype
    kw = dict(b_v=spec.b_v, b_f=spec.b_f, beta=spec.beta, matrix=spec.matrix)

    def at(R, p):
        rb = recon.at(R)
        sol = ik(rb, p)
        return sol, indices(rb, p, sol.theta, **kw)

    at_jit = jax.jit(at)
    res = ctx.results
    rows = []
    # one bar: each paper example (the first compiles), then the index-vs-R curves (one compiled vmap), the plot
    bar = ctx.progress(total=len(FRANCO2026_EXAMPLES) + 2, desc="indices_examples")
    for name, tab in FRANCO2026_EXAMPLES.items():
        bar.set_postfix_str(name)
        p = jnp.asarray(tab["p"], dtype)
        sol, ind = at_jit(jnp.asarray(tab["R"], dtype), p)
        g = f"examples/{name}"
        res.put(g, "R", tab["R"], units="m")
        res.put(g, "p", np.asarray(p), units="m", dims=("xyz",))
        res.put(g, "theta", np.degrees(np.asarray(sol.theta)), units="deg", dims=("chain",))
        for k in SCALAR_INDICES:
            res.put(g, k, float(getattr(ind, k)), units=UNITS.get(k, "1"))
        for k in FRANCO2026_EXAMPLE_INDICES:
            ours, paper = float(getattr(ind, k)), tab["indices"][k]
            res.put(g, f"paper_{k}", paper, units="1")
            rows.append((name, k, paper, ours, abs(ours - paper) / abs(paper)))
            res.put(g, f"match_{k}", rows[-1][-1] <= 2e-4, units="1",
                    attrs={"misprint": int((name, k) in FRANCO2026_MISPRINTS)})
        bar.update(1)
    for name, k, paper, ours, rel in rows:
        flag = "ok" if rel <= 2e-4 else ("paper misprint" if (name, k) in FRANCO2026_MISPRINTS else "MISMATCH")
        ctx.log(f"{name:7s} {k:12s} paper {paper:.5g}  ours {ours:.6g}  rel {rel:.1e}  {flag}")

    # Index-vs-R curves at the example points: R = R_min + k * R_step (integer k)
    step = spec.R_step
    n = int(round((float(recon.R_max) - float(recon.R_min)) / step)) + 1
    R = float(recon.R_min) + step * np.arange(n)
    pts = np.asarray(spec.points)
    curve = jax.jit(jax.vmap(jax.vmap(at, in_axes=(0, None)), in_axes=(None, 0)))
    bar.set_postfix_str(f"curves ({len(pts)} points x {n} R)")
    sol, ind = jax.block_until_ready(curve(jnp.asarray(R, dtype), jnp.asarray(pts, dtype)))
    bar.update(1)
    ok = np.asarray(sol.ok)
    res.put_axis("curves", "R", R, units="m")
    res.put_axis("curves", "point", np.arange(len(pts)), units="1")
    res.put("curves", "p", pts, units="m", dims=("point", "xyz"))
    res.put("curves", "feasible", ok, units="1", dims=("point", "R"))
    argmax = {}
    for k in SCALAR_INDICES:
        v = np.asarray(getattr(ind, k))
        res.put("curves", k, v, units=UNITS.get(k, "1"), dims=("point", "R"))
        finite = np.where(ok & np.isfinite(v), v, -np.inf)
        best = np.argmax(finite, axis=1)  # ties to the smallest R
        argmax[k] = np.where(np.isfinite(finite.max(axis=1)), R[best], np.nan)
        res.put("curves", f"argmax_R_{k}", argmax[k], units="m", dims=("point",))
    for i, pt in enumerate(pts):
        feas = R[ok[i]]
        where = ", ".join(f"{float(c):g}" for c in pt)
        ctx.log(f"point ({where}) m: feasible R in [{feas.min():.5f}, {feas.max():.5f}] m; argmax R: "
                + ", ".join(f"{k}={argmax[k][i]:.5f}" for k in ("k_tilde", "omega_v", "omega_f", "sigma_min_v",
                                                                  "sigma_min_f", "inv_cond")))
    res.set_attrs("curves", note="argmax over finite values with ties to the smallest R; omega_v is "
                  "unbounded at Jx-singular R (e.g. R = 0.465 at z = 0.2, singularity type 1)")
    if ctx.plots:
        bar.set_postfix_str("plot")
        ctx.savefig(plot_index_curves(R, pts, {k: np.asarray(getattr(ind, k)) for k in SCALAR_INDICES}, ok,
                                      argmax), "index_curves")
    bar.update(1)
    bar.close()
