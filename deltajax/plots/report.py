"""The main job's run report as one self-contained HTML page (plotly; plotly.js inline, so it opens offline).

Figures from plain arrays (as stored in results.h5 or computed by :mod:`deltajax.runreport`, which reads the run and
writes ``report.html``): :func:`front_figure` (verified designs, hover: parameters, objectives, constraint values),
:func:`workspace_figure` (3-D good workspace with cylinders), :func:`torque_speed_figure` (cycle over the motor
envelope), :func:`summary_table` and :func:`report_page`. plotly is imported on first use.
"""

from __future__ import annotations

import html

import numpy as np

__all__ = ["front_figure", "workspace_figure", "torque_speed_figure", "summary_table", "report_page"]


def _display(unit: str) -> tuple[float, str]:
    """(factor, unit shown): volumes in litres (as the PNG figures show them), the rest as stored."""
    return (1e3, "L") if unit == "m^3" else (1.0, unit)


def _suffix(unit: str) -> str:
    """`` <unit>`` after a number, nothing for a dimensionless one."""
    return "" if unit in ("1", "") else f" {unit}"


def front_figure(V, objs, units, param_names, param_units, margins=None):
    """The designs verified on the fine grids in the plane of the first two objectives: the verified Pareto front,
    the other candidates, the baseline (row 0) and the recommendation; each point's hover lists its objectives,
    picks/min, its parameters and the stored constraint values (``V``: the staged ``verify`` group;
    ``units``: each metric's unit; ``param_names``/``param_units``: the columns of ``V["params"]``; ``margins``:
    ``{"margin_<name>": (n,)}`` every constraint's margin per design, group ``certify``, listed in the hover)."""
    import plotly.graph_objects as go

    names = [str(n) for n in np.asarray(V["design_name"]).reshape(-1)]
    n = len(names)
    feas = np.asarray(V["feasible"]).astype(bool).reshape(-1)
    front = np.asarray(V["front"], int).reshape(-1)
    rec = int(V["attrs"]["recommended"])
    o0, o1 = objs[0], objs[1] if len(objs) > 1 else objs[0]
    f0, u0 = _display(units[o0])
    f1, u1 = _display(units[o1])
    x, y = np.asarray(V[o0], float) * f0, np.asarray(V[o1], float) * f1
    params = np.asarray(V["params"], float).reshape(n, -1)
    pnames, punits = list(param_names), list(param_units)
    cnames = [str(c) for c in np.asarray(V.get("constraint_names", [])).reshape(-1)]
    cvals = np.asarray(V["constraint_values"], float).reshape(n, -1) if "constraint_values" in V else None
    show = list(objs) + [m for m in ("picks_per_min", "cycle_time", "R_operating") if m not in objs and m in V]

    def hover(i):
        rows = [f"<b>{html.escape(names[i])}</b>" + (" (recommended)" if i == rec else "")
                + (" (baseline)" if i == 0 else "") + ("" if feas[i] else " infeasible")]
        for m in show:
            f, u = _display(units.get(m, "1"))
            rows.append(f"{m}: {float(np.asarray(V[m]).reshape(-1)[i]) * f:.5g}{_suffix(u)}")
        rows.append("<i>parameters</i>")
        rows += [f"{p}: {params[i, j]:.5g}{_suffix(u)}" for j, (p, u) in enumerate(zip(pnames, punits))]
        if margins:
            rows.append("<i>margins (&gt;= 0: met by that much)</i>")
            rows += [f"{k[7:]}: {float(np.asarray(v).reshape(-1)[i]):.4g}{_suffix(units.get(k, '1'))}"
                     for k, v in margins.items()]
        if cvals is not None:
            rows.append("<i>constraint values (&lt;= 0 satisfied)</i>")
            rows += [f"{c}: {cvals[i, j]:.3g}" for j, c in enumerate(cnames)]
        return "<br>".join(rows)

    text = [hover(i) for i in range(n)]
    fig = go.Figure()
    on_front = np.zeros(n, bool)
    on_front[front] = True
    others = [i for i in range(1, n) if not on_front[i] and i != rec]
    for sel, label, marker in (
            ([i for i in others if feas[i]], "verified, feasible, dominated",
             dict(symbol="circle-open", color="#888", size=7)),
            ([i for i in others if not feas[i]], "verified, infeasible on the fine grids",
             dict(symbol="x", color="#bbb", size=6))):
        if sel:
            fig.add_trace(go.Scatter(x=x[sel], y=y[sel], mode="markers", name=label, marker=marker,
                                     hovertext=[text[i] for i in sel], hoverinfo="text"))
    if len(front):
        o = front[np.argsort(x[front])]
        fig.add_trace(go.Scatter(x=x[o], y=y[o], mode="markers+lines", name="verified Pareto front",
                                 line=dict(shape="hv", width=1, color="#1f77b4"),
                                 marker=dict(size=10, color="#1f77b4"), hovertext=[text[i] for i in o],
                                 hoverinfo="text"))
    fig.add_trace(go.Scatter(x=x[:1], y=y[:1], mode="markers", name="baseline" + ("" if feas[0] else " (infeasible)"),
                             marker=dict(symbol="star", size=16, color="black"), hovertext=text[:1], hoverinfo="text"))
    if rec >= 0:
        fig.add_trace(go.Scatter(x=x[[rec]], y=y[[rec]], mode="markers", name=f"recommended ({names[rec]})",
                                 marker=dict(symbol="diamond", size=15, color="#d62728",
                                             line=dict(width=1, color="black")),
                                 hovertext=[text[rec]], hoverinfo="text"))
    hv = float(V["attrs"].get("hypervolume", float("nan")))
    fig.update_layout(title=f"Designs verified on the fine grids (front hypervolume {hv:.4g}; hover a point for its "
                            "parameters)", xaxis_title=f"{o0} [{u0}]", yaxis_title=f"{o1} [{u1}]",
                      hovermode="closest", height=560, legend=dict(orientation="h", y=-0.18))
    return fig


def _cylinder(go, diameter, height, z_top, name, color, opacity):
    phi = np.linspace(0.0, 2 * np.pi, 41)
    zz = np.array([z_top, z_top + height])
    P, Z = np.meshgrid(phi, zz)
    r = diameter / 2.0
    return go.Surface(x=r * np.cos(P), y=r * np.sin(P), z=Z, name=name, showscale=False, opacity=opacity,
                      colorscale=[[0, color], [1, color]], showlegend=True, hoverinfo="name")


def workspace_figure(good_points, h: float, n_points: int, cylinders):
    """3-D view of a good workspace: ``good_points`` (n, 3) m (base frame, z down) of a grid of ``n_points``
    points with spacing ``h`` (m); ``cylinders``: ``(name, diameter, height, z_top, colour)`` each (m), drawn as
    translucent surfaces (e.g. the task and the regular-workspace cylinders)."""
    import plotly.graph_objects as go

    g = np.asarray(good_points, float).reshape(-1, 3)
    fig = go.Figure()
    fig.add_trace(go.Scatter3d(x=g[:, 0], y=g[:, 1], z=g[:, 2], mode="markers", name=f"good workspace ({len(g)} of "
                               f"{n_points} grid points, h = {h * 1e3:.3g} mm)",
                               marker=dict(size=2.2, color=g[:, 2], colorscale="Viridis", opacity=0.55),
                               hovertemplate="x %{x:.3f} m<br>y %{y:.3f} m<br>z %{z:.3f} m<extra></extra>"))
    for name, d, hh, zt, colour in cylinders:
        fig.add_trace(_cylinder(go, d, hh, zt, name, colour, 0.4))
    fig.update_layout(title="Good workspace of the recommended design (base frame, z down; R chosen per point)",
                      height=640, legend=dict(orientation="h", y=-0.05),
                      scene=dict(xaxis_title="x [m]", yaxis_title="y [m]", zaxis_title="z [m] (down)",
                                 zaxis=dict(autorange="reversed"), aspectmode="data"))
    return fig


def torque_speed_figure(speed, envelope, rated_torque: float, rows):
    """Motor torque against motor speed along a cycle over the motor's envelope: ``speed`` (n,) rad/s from -max
    to +max and ``envelope`` (n,) N m the available torque there (drawn +-), ``rated_torque`` N m (dashed),
    ``rows``: ``(label, torque (K, 3) N m, speed (K, 3) rad/s, colour, marker symbol)`` per design (motor side)."""
    import plotly.graph_objects as go

    w, env = np.asarray(speed, float), np.asarray(envelope, float)
    fig = go.Figure()
    fig.add_trace(go.Scatter(x=np.concatenate([w, w[::-1]]), y=np.concatenate([env, -env[::-1]]), mode="lines",
                             name="motor envelope (peak torque, falling past the corner speed)", fill="toself",
                             line=dict(color="#444"), fillcolor="rgba(120,120,120,0.12)", hoverinfo="skip"))
    rt = float(rated_torque)
    for sgn in (1, -1):
        fig.add_trace(go.Scatter(x=[w[0], w[-1]], y=[sgn * rt] * 2, mode="lines", name="rated (RMS) torque",
                                 line=dict(color="#ff7f0e", dash="dash"), showlegend=sgn == 1, hoverinfo="skip"))
    for label, tau, om, colour, symbol in rows:
        for i in range(3):
            fig.add_trace(go.Scatter(x=om[:, i], y=tau[:, i], mode="markers+lines", name=f"{label}, motor {i + 1}",
                                     marker=dict(symbol=symbol, size=6, color=colour), line=dict(width=0.6,
                                                                                                   color=colour),
                                     opacity=[1.0, 0.75, 0.5][i],
                                     hovertemplate="speed %{x:.4g} rad/s<br>torque %{y:.4g} N m<extra>"
                                                   + html.escape(f"{label}, motor {i + 1}") + "</extra>"))
    fig.update_layout(title="Motor torque vs motor speed along the cycle (motor side, through the gearbox)",
                      xaxis_title="motor speed [rad/s]", yaxis_title="motor torque [N m]", height=560,
                      hovermode="closest", legend=dict(orientation="h", y=-0.2))
    return fig


def summary_table(S) -> str:
    """HTML table of the stored baseline-vs-recommended summary (``S``: the staged ``summary`` group)."""
    if not S or "metric_name" not in S:
        return "<p>No summary stored (no feasible design was verified).</p>"
    head = "<tr><th>metric</th><th>units</th><th>baseline</th><th>recommended</th><th>direction</th></tr>"
    body = "".join(f"<tr><td>{html.escape(str(n))}</td><td>{html.escape(str(u))}</td><td>{b:.5g}</td>"
                   f"<td>{r:.5g}</td><td>{html.escape(str(d))}</td></tr>"
                   for n, u, b, r, d in zip(S["metric_name"], S["metric_units"], S["baseline"], S["recommended"],
                                            S["direction"]))
    prm = "".join(f"<tr><td>{html.escape(str(n))}</td><td>{html.escape(str(u))}</td><td>{b:.5g}</td>"
                  f"<td>{r:.5g}</td><td>design parameter</td></tr>"
                  for n, u, b, r in zip(S["parameter_name"], S["parameter_units"], S["baseline_params"],
                                        S["recommended_params"]))
    return f"<table>{head}{body}{prm}</table>"


# -- the page -----------------------------------------------------------------------------------------------------

_CSS = ("body{font-family:sans-serif;margin:1.5em;max-width:1200px}table{border-collapse:collapse;font-size:90%}"
        "td,th{border:1px solid #ccc;padding:2px 8px;text-align:right}td:first-child{text-align:left}"
        ".plot{margin:1em 0 2em 0}")


def report_page(title: str, intro_html: str, sections) -> str:
    """The HTML page: ``intro_html`` (trusted HTML) then ``sections``, each ``(key, heading, plotly figure or HTML
    string)``; figures get the div id ``fig-<key>``. plotly.js is embedded once, inline (no network needed)."""
    import plotly
    import plotly.io as pio

    parts = []
    for key, heading, body in sections:
        if not isinstance(body, str):
            body = pio.to_html(body, full_html=False, include_plotlyjs=False, div_id=f"fig-{key}",
                               config={"displaylogo": False})
        parts.append(f'<h2>{html.escape(heading)}</h2><div class="plot" id="sec-{key}">{body}</div>')
    return (f'<!DOCTYPE html><html><head><meta charset="utf-8"><title>{html.escape(title)}</title>'
            f'<style>{_CSS}</style><script type="text/javascript">{plotly.offline.get_plotlyjs()}</script>'
            f"</head><body><h1>{html.escape(title)}</h1>{intro_html}{''.join(parts)}</body></html>")
