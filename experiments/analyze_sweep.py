"""Compare the runs of a Hydra sweep: a table and plots of their key figures against the swept parameter.

    python experiments/analyze_sweep.py outputs/multirun/workspace_grid/<date>_<time>
    python experiments/analyze_sweep.py <sweep dir> --x robot.forearm --metrics workspace/volume,dynamics/tau_peak

Steps: refresh the sweep's ``summary.csv``/``summary.json`` (:func:`deltajax.sweeps.summarize_sweep`; sharded
jobs count once, through their merged file), pick the swept parameter (``--x``, default the first override
that takes several numeric values), then write into ``--out`` (default the sweep directory):

* ``sweep_table.md`` / ``sweep_table.csv``: one row per run, the swept parameters and the metrics;
* ``sweep_metrics.png``: each metric against the swept parameter (workspace volume, mean k~, peak torque ...);
* ``sweep_area_vs_z.png``: for runs with a gridded ``workspace/reachable`` field, the reachable area per z
  level, read through xarray (:func:`deltajax.io.open_xarray`).

Metrics default to those present among :data:`DEFAULT_METRICS` plus the largest per-chain peak torque of
every case of ``experiment=dynamics_cycle`` (``.../peak_torque[max]``).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any, Optional, Sequence

DEFAULT_METRICS = ("workspace/volume", "workspace/volume_box", "workspace/k_tilde_mean", "workspace/inv_cond_mean",
                   "workspace/k_tilde_min")


def _num(v: Any) -> Optional[float]:
    try:
        f = float(v)
    except (TypeError, ValueError):
        return None
    return f


def select_runs(summary: dict) -> list[dict]:
    """Completed runs, with the shards of a merged job replaced by its merged row."""
    rows = [r for r in summary["runs"] if r["status"] == "ok"]
    merged_sources = {name for r in rows if r["kind"] == "merged" for name in r.get("merged_from", [])}
    out = []
    for r in rows:
        if r["kind"] == "run" and r["run"] in merged_sources:
            continue
        if r["kind"] == "run" and _num(r["overrides"].get("n_shards", 1)) not in (None, 1.0):
            print(f"warning: run {r['run']} is one shard of an unmerged job; skipped", file=sys.stderr)
            continue
        out.append(r)
    return out


def pick_x(rows: Sequence[dict], x: Optional[str]) -> tuple[Optional[str], list[str]]:
    """(the x parameter, the other varying parameters)."""
    keys = sorted({k for r in rows for k in r["overrides"]} - {"shard"})
    varying = [k for k in keys if len({r["overrides"].get(k) for r in rows}) > 1]
    if x is not None:
        if x not in keys:
            raise SystemExit(f"--x {x!r} is not an override of this sweep; overrides: {keys}")
        return x, [k for k in varying if k != x]
    numeric = [k for k in varying if all(_num(r["overrides"].get(k)) is not None for r in rows)]
    if numeric:
        return numeric[0], [k for k in varying if k != numeric[0]]
    return (varying[0] if varying else None), varying[1:]


def join_experiments(rows: Sequence[dict], keys: Sequence[str]) -> list[dict]:
    """Combine the runs of different experiments with the same values of ``keys`` into one row each."""
    joined: dict[tuple, dict] = {}
    for r in rows:
        k = tuple(str(r["overrides"].get(p)) for p in keys)
        if k not in joined:
            joined[k] = {"run": r["run"], "kind": r["kind"], "overrides": {p: r["overrides"].get(p) for p in keys},
                         "metrics": {}, "runs": []}
        j = joined[k]
        j["runs"].append(r["run"])
        j["run"] = "+".join(j["runs"])
        j["metrics"].update(r["metrics"])
    return list(joined.values())


def pick_metrics(rows: Sequence[dict], metrics: Optional[str]) -> list[str]:
    present = sorted({m for r in rows for m in r["metrics"]})
    if metrics:
        chosen = [m.strip() for m in metrics.split(",") if m.strip()]
        unknown = [m for m in chosen if m not in present]
        if unknown:
            raise SystemExit(f"--metrics: {unknown} not found; available: {present}")
        return chosen
    chosen = [m for m in DEFAULT_METRICS if m in present]
    chosen += [m for m in present if m not in chosen and m.endswith("peak_torque[max]")]
    return chosen or present[:6]


def _fmt(v: Any) -> str:
    if v is None:
        return ""
    f = _num(v)
    if f is None:
        return str(v)
    if math.isnan(f):
        return "nan"
    return f"{f:.6g}"


def analyze(sweep_dir: Path, x: Optional[str] = None, metrics: Optional[str] = None,
            out: Optional[Path] = None) -> dict[str, Path]:
    """Write the table and plots of a sweep; returns the written paths by kind."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from deltajax.io import open_xarray
    from deltajax.sweeps import summarize_sweep

    sweep_dir = Path(sweep_dir)
    if not sweep_dir.is_dir():
        raise SystemExit(f"not a directory: {sweep_dir}")
    out = Path(out) if out is not None else sweep_dir
    out.mkdir(parents=True, exist_ok=True)
    paths = summarize_sweep(sweep_dir)
    summary = json.loads(Path(paths["json"]).read_text())
    rows = select_runs(summary)
    if not rows:
        raise SystemExit(f"no completed runs in {sweep_dir} (see {paths['csv']})")
    xkey, series = pick_x(rows, x)
    if "experiment" in series:  # several experiments per design: one row per design, metrics side by side
        series = [k for k in series if k != "experiment"]
        rows = join_experiments(rows, [k for k in [xkey, *series] if k])
    mets = pick_metrics(rows, metrics)
    units = summary.get("units", {})
    if xkey is not None:
        rows = sorted(rows, key=lambda r: (tuple(str(r["overrides"].get(s)) for s in series),
                                           _num(r["overrides"].get(xkey)) if _num(r["overrides"].get(xkey))
                                           is not None else str(r["overrides"].get(xkey))))
    # -- table ------------------------------------------------------------------------------------------
    params = ([xkey] if xkey else []) + series
    head = ["run", *params, *(f"{m} [{units.get(m, '')}]" for m in mets)]
    table = [[r["run"], *(str(r["overrides"].get(p, "")) for p in params), *(r["metrics"].get(m) for m in mets)]
             for r in rows]
    md = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    md += ["| " + " | ".join(_fmt(v) for v in row) + " |" for row in table]
    written = {"summary_csv": Path(paths["csv"]), "summary_json": Path(paths["json"])}
    written["table_md"] = out / "sweep_table.md"
    written["table_md"].write_text("\n".join(md) + "\n")
    import csv

    written["table_csv"] = out / "sweep_table.csv"
    with open(written["table_csv"], "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(head)
        w.writerows([["" if v is None else v for v in row] for row in table])  # full precision
    print("\n".join(md))
    # -- metrics against the swept parameter -----------------------------------------------------------
    if xkey is not None and mets:
        n = len(mets)
        ncol = min(3, n)
        fig, axes = plt.subplots(math.ceil(n / ncol), ncol, figsize=(4.2 * ncol, 3.3 * math.ceil(n / ncol)),
                                 squeeze=False)
        groups: dict[tuple, list[dict]] = {}
        for r in rows:
            groups.setdefault(tuple(str(r["overrides"].get(s)) for s in series), []).append(r)
        numeric_x = all(_num(r["overrides"].get(xkey)) is not None for r in rows)
        for ax, m in zip(axes.flat, mets):
            for gkey, members in groups.items():
                xs = [(_num(r["overrides"].get(xkey)) if numeric_x else str(r["overrides"].get(xkey)))
                      for r in members]
                ys = [_num(r["metrics"].get(m)) for r in members]
                ys = [np.nan if y is None else y for y in ys]
                if all(np.isnan(y) for y in ys):  # e.g. a series of another experiment without this metric
                    continue
                label = ", ".join(f"{s}={v}" for s, v in zip(series, gkey)) or None
                ax.plot(xs, ys, "o-", label=label)
            ax.set_xlabel(xkey)
            ax.set_title(m if len(m) <= 48 else "..." + m[-45:], fontsize=8)
            ax.set_ylabel(units.get(m, "") or "1")
            if series:
                ax.legend(fontsize=7)
        for ax in list(axes.flat)[n:]:
            ax.set_visible(False)
        fig.suptitle(f"sweep {sweep_dir.name}")
        fig.tight_layout()
        written["metrics_png"] = out / "sweep_metrics.png"
        fig.savefig(written["metrics_png"], dpi=110)
        plt.close(fig)
    # -- gridded results through xarray -------------------------------------------------------------------
    fig, ax = plt.subplots(figsize=(5.5, 3.6))
    any_grid = False
    for r in rows:
        for run in r.get("runs", [r["run"]]):
            try:
                ws = open_xarray(sweep_dir / run / "results.h5", "workspace")
            except (OSError, ValueError, KeyError):
                continue
            break
        else:
            continue
        if "reachable" not in ws or set(ws["reachable"].dims) != {"x", "y", "z"}:
            continue
        h = float(ws.attrs.get("h", abs(float(ws.x[1] - ws.x[0])) if ws.sizes["x"] > 1 else 1.0))
        area = ws["reachable"].astype("int64").sum(("x", "y")) * h * h
        label = ", ".join(f"{p}={r['overrides'].get(p)}" for p in params) or r["run"]
        ax.plot(ws["z"].values, area.values, label=label)
        any_grid = True
    if any_grid:
        ax.set_xlabel("z (m, down)")
        ax.set_ylabel("reachable area (m$^2$)")
        ax.legend(fontsize=7)
        fig.tight_layout()
        written["area_png"] = out / "sweep_area_vs_z.png"
        fig.savefig(written["area_png"], dpi=110)
    plt.close(fig)
    for k, p in written.items():
        print(f"{k}: {p}")
    return written


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("sweep_dir", type=Path)
    ap.add_argument("--x", help="swept parameter for the x axis (an override key, e.g. robot.forearm)")
    ap.add_argument("--metrics", help="comma-separated group/name scalars (default: volume, k~ ..., torques)")
    ap.add_argument("--out", type=Path, help="output directory (default: the sweep directory)")
    args = ap.parse_args(argv)
    analyze(args.sweep_dir, args.x, args.metrics, args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
