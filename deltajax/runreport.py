"""The main job's run report: ``report.html``, one self-contained page per ``experiment=ga_reconfig`` run.

    python -m deltajax.report <run dir>                   # writes <run dir>/report.html
    deltajax.write_report("<run dir>/results.h5", "report.html")

Drawn from a run's ``results.h5`` (read through :func:`deltajax.io.load`) and the configuration stored in it,
from which the design space and the fine verification problem are rebuilt (:mod:`deltajax.optimize.workflow`):

* the designs verified on the fine grids (hover: parameters, objectives, picks/min, the stored constraint values);
* the good workspace of the recommendation (:func:`deltajax.constraints.good_point`, any of the design's
  verification R samples, as ``evaluate_designer`` judges the regular workspace) on a modest grid
  (:func:`deltajax.workspace.make_grid` over the regular-workspace search box), with the task cylinder and the
  regular cylinder the verification found;
* the motor torque and speed along the verification cycle at each design's operating R and verified motion time
  (:func:`deltajax.cycle_profile` through :func:`deltajax.constraints.motor_side`) over
  :meth:`deltajax.Motor.envelope`, for the recommendation and the baseline;
* the stored baseline-vs-recommended summary.

The views are computed in the JAX precision in effect (``python -m deltajax.report`` switches float64 on for a
float64 run, as the CLI does); the page says which. Figures: :mod:`deltajax.plots.report`.
"""

from __future__ import annotations

import dataclasses
import datetime
import html
import math
from pathlib import Path
from typing import Any, Mapping

import numpy as np
import jax.numpy as jnp
import jax

from .tracing import shared_program
from .optimize.good import design_good_test, DesignGoodTest
from .workspace import make_grid
from .optimize.rays import any_good_where_possible
from . import constraints as C
from .cycle import cycle_profile
from .io import load, write_atomic
from .optimize.designer import DESIGN_UNITS
from .optimize.certify import MARGIN_UNITS, overlay

__all__ = ["ReportError", "write_report", "report_path", "WORKSPACE_POINTS", "JOB"]

#: grid points per horizontal axis of the good-workspace view (the vertical axis gets the same spacing)
WORKSPACE_POINTS = 29
#: the job whose runs this module reports
JOB = "ga_reconfig"


class ReportError(ValueError):
    """The file is not a ga_reconfig run whose report can be drawn (the message names the file and why)."""


def report_path(run_dir) -> Path:
    """Where the main job writes its report: ``<run dir>/report.html``."""
    return Path(run_dir) / "report.html"


def _run_problem(data: Mapping[str, Any], path: Path):
    """(settings, design space at the verification's n_R, fine verification problem) from the stored config."""
    import yaml

    from .config import ConfigError, ga_reconfig_build, robot_from_config
    from .optimize.workflow import SetupError, designer_problem

    try:
        cfg = yaml.safe_load(data["attrs"]["config"])
    except (KeyError, yaml.YAMLError) as err:
        raise ReportError(f"{path}: no readable stored configuration ({type(err).__name__}: {err})") from None
    name = cfg.get("experiment", {}).get("name") if isinstance(cfg, Mapping) else None
    if name != JOB:
        raise ReportError(f"{path} holds a run of experiment {name!r}, not {JOB}")
    try:
        robot, recon = robot_from_config(cfg["robot"])
        s, space, _pb, _ga = ga_reconfig_build(cfg["experiment"], robot, recon)
        pb = designer_problem(s, fine=True)
    except (ConfigError, SetupError) as err:
        raise ReportError(f"{path}: its stored configuration does not build here ({err})") from None
    space_v = dataclasses.replace(space, n_R=s.verify.n_R) if space.reconfigurable else space
    return s, space_v, pb


def _good_workspace(design, reconfigurable: bool, pb, n_xy: int):
    """(good grid points (n, 3) m, spacing h m, grid size): the design's good workspace, R chosen per point."""
    reg = pb.settings["regular"]
    half, z0 = float(reg["r_max"]), float(reg["z_min"])
    h = 2.0 * half / (n_xy - 1)
    nz = max(int(math.ceil((float(reg["z_max"]) - z0) / h - 1e-9)), 1)
    grid = make_grid((-half, half), (-half, half), (z0, z0 + nz * h), h)
    pts = np.stack(np.meshgrid(grid.x, grid.y, grid.z, indexing="ij"), axis=-1).reshape(-1, 3)
    gt = design_good_test(design, pb.good, pb.links.plate_overhang)    # the designer's good test, R samples, plate
    Rs = gt.R_samples()
    dt = jnp.asarray(Rs).dtype
    good = np.asarray(_good_any(design, reconfigurable, jnp.asarray(Rs, dt), jnp.asarray(pts, dt), gt.plate,
                                pb.good))
    return pts[good], h, len(pts)


def _good_any(design, reconfigurable: bool, Rs, P, plate, good):
    """Is each point of ``P`` good at any R of ``Rs``? (P,) bool. One program per process for every design of every
    report, kept across processes (:func:`deltajax.tracing.shared_program`): a new process reads it back instead
    of tracing the good test again."""
    prog = shared_program("report_good_any", None, None, (bool(reconfigurable),),
                          lambda: jax.jit(_good_any_traced), persist=True)
    return prog(design, Rs, P, plate, good)


#: the full good tests of the report's workspace figure run in rounds of 1/GOOD_ANY_ROUNDS of its (R, point) pairs
GOOD_ANY_ROUNDS = 16


def _good_any_traced(design, Rs, P, plate, good):
    """The good test at any R, as the designer's searches run it (:func:`deltajax.optimize.rays.
    any_good_where_possible`): the full test only where its cheap necessary condition holds and the point has no
    good R yet, mostly settled by the cheaper :func:`deltajax.constraints.good_point_decided`; the answer is the
    full test's at every pair."""
    gt = DesignGoodTest(design, good, plate)
    nR, nP = Rs.shape[0], P.shape[0]
    return any_good_where_possible(gt.good, gt.possible, jnp.repeat(Rs, nP), jnp.tile(P, (nR, 1)), ((nP, nR),),
                                   -(-nR * nP // GOOD_ANY_ROUNDS), decided_R=gt.decided_settle)


def _motor_points(design, reconfigurable: bool, R_op: float, T: float, pb):
    """(motor torque (K, 3) N m, motor speed (K, 3) rad/s, every sample reachable) along the verification cycle
    at the operating R ``R_op`` (m) and motion time ``T`` (s), with the job's payload and motor (one jitted
    program: run op by op, the inverse dynamics dispatched hundreds of small operations)."""
    robot = design.at(R_op) if reconfigurable else design
    n = float(robot.mass.gear_ratio)
    dt = robot.upper_arm.dtype
    tau, om, ok = _along(C.with_drive(robot, pb.motor, n, pb.payload), pb.cycle, pb.motor, jnp.asarray(n, dt),
                         jnp.asarray(T, dt))
    return np.asarray(tau), np.asarray(om), bool(ok)


def _along(driven, cycle, motor, n, T):
    """(motor torque, motor speed, every sample reachable) along ``cycle``: one program for the baseline's and the
    recommendation's cycles, kept across processes like :func:`_good_any`'s."""
    return shared_program("report_cycle", None, None, (), lambda: jax.jit(_along_traced), persist=True)(
        driven, cycle, motor, n, T)


def _along_traced(driven, cycle, motor, n, T):
    prof = cycle_profile(driven, cycle, T)
    tau, om = C.motor_side(prof.tau, prof.theta_dot, motor, n)
    return tau, om, jnp.all(prof.ok)


def write_report(results_path, out_path=None, *, workspace_points: int = WORKSPACE_POINTS) -> Path:
    """Write the self-contained HTML report of a ``ga_reconfig`` run that has finished its verification
    (atomically: a temporary file, then a rename).

    Args:
        results_path: the run's ``results.h5``, or its run directory.
        out_path: where to write (default: ``report.html`` beside the results file).
        workspace_points: grid points per horizontal axis of the good-workspace view (>= 5).

    Returns:
        The path written.

    Raises:
        ReportError: bad ``workspace_points``, no results file there, not a ga_reconfig run, or its verification
            not finished (checked before anything compiles).
    """
    from . import plots as P

    if isinstance(workspace_points, bool) or not isinstance(workspace_points, int) or workspace_points < 5:
        raise ReportError(f"workspace_points must be an integer >= 5, got {workspace_points!r}")
    path = Path(results_path)
    path = path / "results.h5" if path.is_dir() else path
    if not path.is_file():
        raise ReportError(f"{results_path}: no results file there")
    out = Path(out_path) if out_path is not None else report_path(path.parent)
    try:
        data = load(path)
    except (OSError, KeyError, ValueError) as err:
        raise ReportError(f"{path} cannot be read as a results file ({type(err).__name__}: {err})") from None
    V = data.get("verify")
    if V is None or "design_name" not in V:
        stages = data.get("attrs", {}).get("ga_reconfig_stages", "")
        raise ReportError(f"{path}: the run has not finished its verification (stages done: {stages or 'none'}); "
                          "resume it first")

    V = overlay(data)          # the certified figures and recommendation where the certify stage ran
    s, space, pb = _run_problem(data, path)
    units = {**DESIGN_UNITS, **{f"margin_{k}": u for k, u in MARGIN_UNITS.items()},
             **{k: u for k, u in V.get("units", {}).items() if isinstance(u, str) and u != "1"}}
    names = [str(n) for n in np.asarray(V["design_name"]).reshape(-1)]
    rec = int(V["attrs"]["recommended"])
    sections = [("front", "Designs verified on the fine grids",
                 P.report.front_figure(V, list(s.objectives.names), units, space.names,
                                       [space.units(n) for n in space.names],
                                       margins={k: v for k, v in (data.get("certify") or {}).items()
                                                if k.startswith("margin_")}))]
    notes = []
    if rec >= 0:
        genes = np.asarray(V["genes"], float).reshape(len(names), -1)
        dt = jnp.zeros(()).dtype                               # the precision in effect
        design = space.decode(jnp.asarray(genes[rec], dt))
        recon = space.reconfigurable
        good, h, n_pts = _good_workspace(design, recon, pb, workspace_points)
        t = s.task
        cyl = [("task cylinder", t.diameter, t.height, t.z_top, "#d62728")]
        d, hh, zt = (float(np.asarray(V[k], float)[rec]) for k in ("regular_diameter", "regular_height",
                                                                     "regular_z_top"))
        if np.isfinite([d, hh, zt]).all() and d > 0:
            cyl.append((f"regular workspace (D {d * 1e3:.4g} mm, H {hh * 1e3:.4g} mm)", d, hh, zt, "#1f77b4"))
        sections.append(("workspace", "Good workspace of the recommended design", P.report.workspace_figure(
            good, h, n_pts, cyl)))
        rows = []
        tkey = "cycle_time_fixed" if "cycle_time_fixed" in V else "cycle_time"    # the cycle at the operating R
        for i, label, colour, symbol in ((rec, f"recommended {names[rec]}", "#d62728", "circle"),
                                          (0, "baseline", "#555555", "x")):
            T, R_op = float(np.asarray(V[tkey], float)[i]), float(np.asarray(V["R_operating"], float)[i])
            if not (np.isfinite(T) and np.isfinite(R_op)):
                notes.append(f"{label}: no finite motion time ({tkey} {T!r} s): its cycle is not drawn")
                continue
            d_i = design if i == rec else space.decode(jnp.asarray(genes[i], dt))
            tau, om, ok = _motor_points(d_i, recon, R_op, T, pb)
            if not ok:
                notes.append(f"{label}: a cycle sample is unreachable at R = {R_op:.4g} m: its cycle is not drawn")
                continue
            rows.append((f"{label} (R {R_op * 1e3:.4g} mm, T {T:.3g} s)", tau, om, colour, symbol))
        m = pb.motor
        w = np.linspace(-float(m.max_speed), float(m.max_speed), 401)
        sections.append(("torque", "Motor torque against motor speed along the cycle",
                         P.report.torque_speed_figure(w, np.asarray(m.envelope(jnp.asarray(w, dt))),
                                                      float(m.rated_torque), rows)))
    else:
        notes.append("no feasible design was verified: no recommendation, so no workspace or torque-speed view")
    a = data["attrs"]
    esc = lambda x: html.escape(str(x))  # noqa: E731
    prec = "float64" if jax.config.jax_enable_x64 else "float32"
    intro = (f"<p>Run {esc(path.parent)}: deltajax {esc(a.get('deltajax_version', ''))} "
             f"{esc(a.get('git_commit', '') or '')}, seed {esc(a.get('seed', ''))}, run precision "
             f"{esc(a.get('precision', ''))} (views computed in {prec}); report made "
             f"{datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC.</p>"
             f"<p>Recommended: <b>{esc(names[rec]) if rec >= 0 else 'none'}</b> (rule: "
             f"{esc(V['attrs'].get('recommend_rule_text', ''))}). Verification grids: "
             f"{esc(V['attrs'].get('grids', ''))}.</p>"
             + "".join(f'<p class="note">{esc(n)}</p>' for n in notes)
             + "<h2>Baseline and recommended design (fine verification grids)</h2>"
             + P.report.summary_table(data.get("summary")))
    write_atomic(out, P.report.report_page(f"deltajax {JOB} run report", intro, sections).encode("utf-8"))
    return out
