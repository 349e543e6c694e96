"""The designer's search evaluator (regular workspace on) against an earlier version of it, in one process.

    python experiments/bench_evaluator.py                       # vs f021be3, 16 Sobol designs, median of 5
    python experiments/bench_evaluator.py --old-ref f021be3 --designs 32 --reps 7
    python experiments/bench_evaluator.py --fine --designs 8    # the verification's evaluator (rays) vs 9518003

The earlier version is ``deltajax/optimize/designer.py`` and ``deltajax/regular.py`` as ``git show <old-ref>``
prints them, loaded as modules beside the current package (the rest of the package is today's: the good test
itself is the same in both). Both evaluators run jitted and vmapped over the same scrambled Sobol designs of the
default main-job problem (``experiment=ga_reconfig``, the coarse search problem of the NSGA-II stage and the
screen; ``--fine``: the verification's problem, its regular workspace found by rays), as
:func:`deltajax.optimize.programs.batch_evaluator` builds them, compiled before timing.

Printed: CPU-ms (``resource.getrusage``, both cores) and wall ms per design, median over ``--reps`` interleaved
rounds, what building each program cost (tracing and lowering, compiling: CPU-s) and its size (while loops in the
lowered program, lines of the optimised HLO), the ratio old / new (on a shared machine absolute times drift with
the load; ratios measured in one process, interleaved, do not), and for every output the largest absolute
difference between the two (0 and "identical" when they agree bit for bit, NaN in the same places).
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import resource
import subprocess
import sys
import time
import types

import numpy as np

__all__ = ["main", "load_old"]

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _cpu():
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def _timed(fn, *args):
    import jax

    c0, t0 = _cpu(), time.perf_counter()
    jax.block_until_ready(fn(*args))
    return _cpu() - c0, time.perf_counter() - t0


def _module_from_source(name: str, package: str, source: str):
    spec = importlib.util.spec_from_loader(name, loader=None)
    mod = importlib.util.module_from_spec(spec)
    mod.__package__ = package
    sys.modules[name] = mod
    exec(compile(source, f"<{name}>", "exec"), mod.__dict__)
    return mod


def load_old(ref: str):
    """``evaluate_designer`` as of git ``ref``: its designer module, with its ``C`` (the constraints) seeing the
    regular-workspace functions of ``ref``'s ``deltajax/regular.py`` and ``ref``'s cheap necessary condition
    ``good_point_possible``."""
    import deltajax.constraints as C

    show = lambda path: subprocess.run(["git", "show", f"{ref}:{path}"], cwd=ROOT, check=True,  # noqa: E731
                                       capture_output=True, text=True).stdout
    old_regular = _module_from_source("deltajax._bench_old_regular", "deltajax", show("deltajax/regular.py"))
    shim = types.ModuleType("deltajax._bench_old_constraints")
    shim.__dict__.update({k: v for k, v in vars(C).items() if not k.startswith("__")})
    for n in old_regular.__all__:
        setattr(shim, n, getattr(old_regular, n))
    # the cheap necessary condition of the good test as of ``ref`` (the full test itself is today's in both)
    old_constraints = _module_from_source("deltajax._bench_old_constraints_src", "deltajax",
                                          show("deltajax/constraints.py"))
    if hasattr(old_constraints, "good_point_possible"):     # (older refs do not call it)
        shim.good_point_possible = old_constraints.good_point_possible
    old = _module_from_source("deltajax.optimize._bench_old_designer", "deltajax.optimize",
                              show("deltajax/optimize/designer.py"))
    old.C = shim
    return old.evaluate_designer


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--old-ref", default=None,
                    help="git ref of the earlier evaluator (default: f021be3 for the search evaluator, main before "
                         "its work; 9518003 with --fine, main before the ray searches skipped impossible pairs)")
    ap.add_argument("--fine", action="store_true",
                    help="the verification's evaluator (fine grids, regular workspace by rays) instead of the search's")
    ap.add_argument("--designs", type=int, default=16, help="Sobol designs per call (the vmapped batch)")
    ap.add_argument("--reps", type=int, default=5, help="interleaved rounds (median reported)")
    ap.add_argument("--seed", type=int, default=7, help="Sobol scramble seed")
    args = ap.parse_args(argv)

    import jax

    jax.config.update("jax_enable_x64", True)
    from scipy.stats import qmc

    from deltajax.config import ga_reconfig_build, robot_from_config
    from deltajax.optimize.designer import evaluate_designer
    from deltajax.overrides import compose_config
    from deltajax.run import CONFIG_DIR

    cfg = compose_config(["experiment=ga_reconfig"], CONFIG_DIR)
    robot, recon = robot_from_config(cfg.robot)
    s, space, pb, _ = ga_reconfig_build(cfg.experiment, robot, recon)
    if args.old_ref is None:
        args.old_ref = "9518003" if args.fine else "f021be3"
    if args.fine:   # as the job's verify stage builds it
        from dataclasses import replace

        from deltajax.optimize.workflow import designer_problem

        pb = designer_problem(s, fine=True)
        space = replace(space, n_R=s.verify.n_R) if space.reconfigurable else space
    X = np.asarray(qmc.Sobol(d=space.dim, scramble=True, seed=args.seed).random(args.designs))
    old_eval = load_old(args.old_ref)
    progs = {name: jax.jit(jax.vmap(lambda g, f=f: f(pb, space.decode(g), regular=True)))
             for name, f in (("old", old_eval), ("new", evaluate_designer))}
    outs, built = {}, {}
    for name, f in progs.items():   # each program's size and what building it costs (tracing + lowering, compiling)
        c0 = _cpu()
        lowered = f.lower(X)
        c1 = _cpu()
        compiled = lowered.compile()
        c2 = _cpu()
        built[name] = (c1 - c0, c2 - c1, lowered.as_text().count("stablehlo.while"),
                       len(compiled.as_text().splitlines()))
        progs[name] = compiled
        outs[name] = {k: np.asarray(v) for k, v in compiled(X).items()}
    rows = {k: [] for k in progs}
    for _ in range(args.reps):
        for name, f in progs.items():
            rows[name].append(_timed(f, X))
    med = {k: np.median(np.asarray(v), axis=0) for k, v in rows.items()}
    n = args.designs
    print(f"deltajax {__import__('deltajax').__file__}; {'verification' if args.fine else 'search'} evaluator; "
          f"old = {args.old_ref}; load {os.getloadavg()[0]:.1f}; "
          f"{n} Sobol designs (seed {args.seed}) per call; median of {args.reps} interleaved rounds")
    for name in progs:
        c, w = med[name]
        lo, co, loops, lines = built[name]
        print(f"{name:4s} {c / n * 1e3:8.2f} CPU-ms/design {w / n * 1e3:8.2f} wall-ms/design  (building: tracing and "
              f"lowering {lo:.1f} CPU-s, {loops} while loops; compiling {co:.1f} CPU-s, {lines} lines of "
              "optimised HLO)")
    print(f"ratio old/new: CPU {med['old'][0] / med['new'][0]:.2f}x, wall {med['old'][1] / med['new'][1]:.2f}x")
    same = True
    print(f"{'output':26s} {'max |old - new|':>16s}")
    for k in outs["old"]:
        a, b = outs["old"][k], outs["new"].get(k)
        if b is None:
            print(f"{k:26s} {'missing in new':>16s}")
            same = False
            continue
        a, b = np.asarray(a, float), np.asarray(b, float)
        ident = np.array_equal(a, b, equal_nan=True)
        both = np.isfinite(a) & np.isfinite(b)
        d = float(np.max(np.abs(a[both] - b[both]))) if both.any() else 0.0
        nan_moved = not np.array_equal(np.isnan(a), np.isnan(b))
        same &= ident
        print(f"{k:26s} {d:16.3e}  {'identical' if ident else 'DIFFERS'}{'  (NaN moved)' if nan_moved else ''}")
    print("all outputs bit-identical" if same else "SOME OUTPUTS DIFFER")


if __name__ == "__main__":
    main()
