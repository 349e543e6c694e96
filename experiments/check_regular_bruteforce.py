"""Is the certified regular workspace right? A brute-force check on the default problem.

    python experiments/check_regular_bruteforce.py                                   # the baseline
    python experiments/check_regular_bruteforce.py --results <run>/results.h5        # its baseline + recommendation
    python experiments/check_regular_bruteforce.py --params R_min=..,R_max=..,platform_radius=..,upper_arm=..,\
        forearm=..,gear_ratio=..                                                    # another design (physical units)

For each design: the volume found by rays (:func:`deltajax.optimize.certify.ray_cylinders`, the verification's
density and twice it, R chosen per point among the verification's R samples, as in the main job), the old sampled
measure (:func:`deltajax.constraints.refine_cylinder` on the old fine grid 32 x 5 x 43, what the verification
reported before) and the brute-force bounds of :func:`deltajax.optimize.certify.grid_cylinder_bounds` on a dense
polar point grid (``--grid`` rings x angles x levels, rings up to ``--r-max``; every window of levels scanned: no
rays, no bisection, no local search), at least 10x the samples of the verification's rays, with the ratio rays /
brute-force mid estimate. CPU seconds printed.
"""

from __future__ import annotations

import argparse
import dataclasses
import resource

import numpy as np


def _cpu():
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--params", default=None, help="name=value,... physical parameters of another design")
    ap.add_argument("--results", default=None, help="a main-job results.h5: check its baseline and recommendation")
    ap.add_argument("--grid", default="201,31,421", help="brute-force rings,angles,levels")
    ap.add_argument("--r-max", type=float, default=0.26, help="brute-force rings 0..r_max (m); a radius beyond it "
                    "counts as good (the upper bound then says so)")
    ap.add_argument("--no-old", action="store_true", help="skip the old sampled measure")
    a = ap.parse_args(argv)

    import jax
    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp
    from deltajax import constraints as C
    from deltajax.config import ga_reconfig_build, robot_from_config
    from deltajax.optimize import certify as CE
    from deltajax.optimize import workflow as W
    from deltajax.overrides import compose_config
    from deltajax.run import CONFIG_DIR

    cfg = compose_config(["experiment=ga_reconfig"], CONFIG_DIR)
    robot, recon = robot_from_config(cfg.robot)
    s, space, _, _ = ga_reconfig_build(cfg.experiment, robot, recon)
    space_v = dataclasses.replace(space, n_R=s.verify.n_R)
    pbf = W.designer_problem(s, fine=True)
    designs = [("baseline", space_v.baseline_genes())]
    if a.params:
        p = dict(kv.split("=") for kv in a.params.split(","))
        designs.append(("given", np.asarray(space_v.from_params([float(p[n]) for n in space_v.names]))))
    if a.results:
        from deltajax.io import load

        V = load(a.results)["verify"]
        rec = int(V["attrs"]["recommended"])
        designs.append((str(V["design_name"][rec]), np.asarray(V["genes"][rec], float)))
    rg = s.regular_workspace
    n_r, n_phi, n_z = (int(x) for x in a.grid.split(","))
    d1 = CE.RayDensity(*pbf.rw_rays)
    n_ray = len(CE.RAY_PASSES) * d1.n_phi * d1.n_z * d1.n_along * d1.n_levels
    n_bf = n_r * n_phi * n_z
    print(f"verification ray density {tuple(d1)} ({', '.join(d1._fields)}), {len(CE.RAY_PASSES)} passes: {n_ray} "
          f"samples on rays; brute-force grid {n_r} x {n_phi} x {n_z} = {n_bf} points, rings 0..{a.r_max} m "
          f"({n_bf / n_ray:.0f}x)", flush=True)
    pts_old, r_old, z_old = C.polar_grid(rg.r_max, rg.z_min, rg.z_max, 32, 5, 43)
    pb_old = dataclasses.replace(pbf, rw_rays=None, rw_points=pts_old, rw_r=r_old, rw_z=z_old)
    pts, r, z = C.polar_grid(a.r_max, rg.z_min, rg.z_max, n_r, n_phi, n_z)
    flat = pts.reshape(-1, 3)
    chunk = 32768
    for name, g in designs:
        d = space_v.decode(jnp.asarray(g))
        plate = d.R_max + pbf.links.plate_overhang
        Rs = d.R_samples()

        def good_R(R, p, d=d, plate=plate):
            return C.good_point(d.at(R), p, pbf.good, plate_radius=plate).good

        t = _cpu()
        ray = [jax.jit(lambda dd=dd, Rs=Rs, good_R=good_R: CE.ray_cylinders(
            good_R, [Rs], rg.r_max, rg.z_min, rg.z_max, rg.hd_ratio, dd)[0])() for dd in (d1, d1.doubled())]
        v1, v2 = float(ray[0].volume), float(ray[1].volume)
        t_ray = _cpu() - t
        t = _cpu()
        old = float("nan") if a.no_old else float(W.verify(pb_old, space_v, np.asarray(g)[None])["regular_volume"][0])
        t_old = _cpu() - t
        t = _cpu()
        f = jax.jit(jax.vmap(lambda p, Rs=Rs, good_R=good_R: jnp.any(jax.vmap(lambda R: good_R(R, p))(Rs))))
        parts = []
        for i in range(0, len(flat), chunk):
            blk = flat[i:i + chunk]
            pad = chunk - len(blk)
            out = np.asarray(f(jnp.asarray(np.concatenate([blk, np.repeat(blk[:1], pad, axis=0)]))))
            parts.append(out[:len(blk)])
        good = np.concatenate(parts).reshape(pts.shape[:3])
        bf = CE.grid_cylinder_bounds(good, r, z, rg.hd_ratio)
        t_bf = _cpu() - t
        print(f"{name}: rays {1e3 * v1:.3f} L (D {1e3 * float(ray[0].diameter):.2f} mm; doubled density "
              f"{1e3 * v2:.3f} L, change {100 * abs(v2 / v1 - 1):.2f} %), old refine_cylinder {1e3 * old:.3f} L; "
              f"brute force [{1e3 * bf['lower']:.3f}, {1e3 * bf['upper']:.3f}] L, mid {1e3 * bf['mid']:.3f} L; "
              f"rays / mid = {v1 / bf['mid']:.4f}, doubled / mid = {v2 / bf['mid']:.4f}, old / mid = "
              f"{old / bf['mid']:.4f}; CPU-s rays {t_ray:.0f}, old {t_old:.0f}, brute force {t_bf:.0f}", flush=True)


if __name__ == "__main__":
    main()
