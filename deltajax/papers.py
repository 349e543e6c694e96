"""Every number the reference papers print that deltajax is compared against, in one place.

Tests, CLI jobs (which store them beside our values as ``paper_*`` datasets/attributes), benchmarks and
docs/REPRODUCTION.md all read these; nothing else types a published number. Values are as printed, with
minus signs and exponents restored where the text extraction of the paper lost them (docs/REPRODUCTION.md). Misprints
are flagged (:data:`FRANCO2026_MISPRINTS`), never corrected here: the tests show why they are wrong.

Papers (texts in the project's shared ``papers/`` folder):

* Franco-López et al. 2026, singularity-sensitive index of the reconfigurable Delta (``FRANCO2026_*``).
* The boundary-search paper (Conti et al.'s bisection and a continuation variant; ``BOUNDARY_SEARCH``).
* Hasanlu 2025, GA design of a reconfigurable Delta (``HASANLU2025_CLAIMS``).
"""

from __future__ import annotations

__all__ = [
    "FRANCO2026_EXAMPLES",
    "FRANCO2026_MISPRINTS",
    "FRANCO2026_EXAMPLE_INDICES",
    "FRANCO2026_ARGMAX_R",
    "FRANCO2026_VOLUMES",
    "FRANCO2026_INDEX_STATS",
    "BOUNDARY_SEARCH",
    "HASANLU2025_CLAIMS",
    "example_indices",
]

#: Franco-López 2026 Tables 2-5: one configuration each, R (m), platform point p (m), the printed arm angle
#: theta_1 (deg; theta < 0 above the horizontal) and the printed indices. Table 2's R "0.4649" is a
#: truncation of 0.46499 (docs/REPRODUCTION.md).
FRANCO2026_EXAMPLES = {
    "table2": dict(R=0.46499, p=(0.0, 0.0, 0.200), theta_deg=90.000,
                   indices=dict(omega_v=6.1584e8, omega_f=1.6237e-9, sigma_min_v=8.1648e-1,
                                sigma_min_f=1.0825e-9, inv_cond=8.8388e-10)),
    "table3": dict(R=0.22842, p=(0.0, 0.0, 0.1153), theta_deg=-35.0297355,
                   indices=dict(omega_v=3.5566e-9, omega_f=2.8116e8, sigma_min_v=1.5236e-3,
                                sigma_min_f=6.5274e2, inv_cond=0.9946)),
    "table4": dict(R=0.20465, p=(0.0, 0.0, 0.200), theta_deg=-3.39378,
                   indices=dict(omega_v=1.1063e-1, omega_f=9.0389e0, sigma_min_v=4.6054e-1,
                                sigma_min_f=2.4592e0, inv_cond=0.8829)),
    "table5": dict(R=0.24901, p=(0.0, 0.0, 0.1153), theta_deg=0.92940,
                   indices=dict(omega_v=3.8553e-2, omega_f=25.9473, sigma_min_v=2.5148e-1,
                                sigma_min_f=1.6410e0, inv_cond=0.4127)),
}

#: Printed values contradicted by the paper's own other numbers (docs/REPRODUCTION.md §1):
#: Table 4 sigma_min_f = (1/k) / sigma_min_v = 0.8829 / 0.46054 = 1.917, not 2.4592;
#: Table 5 omega_v = 1 / omega_f = 1 / 25.9473 = 0.038540, not 0.038553.
FRANCO2026_MISPRINTS = frozenset({("table4", "sigma_min_f"), ("table5", "omega_v")})

#: The indices Tables 2-5 print (columns of the jobs' ``paper_*`` datasets).
FRANCO2026_EXAMPLE_INDICES = ("omega_v", "omega_f", "sigma_min_v", "sigma_min_f", "inv_cond")

#: Figs 3-6 (and Tables 2-5): the R (m) that maximises an index at the two example points, as
#: (z of the point p = (0, 0, z) in m, index, R). omega_f, sigma_min_f and 1/k peak at the lower end of the
#: feasible R range at z = 0.1153; omega_v at z = 0.2 next to the singular R = 0.465 (omega_v -> inf).
FRANCO2026_ARGMAX_R = (
    (0.200, "k_tilde", 0.20465),     # Fig 5 / Table 4
    (0.1153, "k_tilde", 0.24901),    # Fig 6 / Table 5
    (0.1153, "omega_f", 0.22842),    # Fig 4 / Table 3
    (0.1153, "sigma_min_f", 0.22842),
    (0.1153, "inv_cond", 0.22842),
    (0.200, "omega_v", 0.46499),     # Fig 3 / Table 2
)

#: Franco-López 2026 §6 (2 mm grid): workspace volume of the fixed robot (R = 0.200 m) and of the
#: reconfigurable one (some R sample reaches), m^3, and the printed increase (%).
FRANCO2026_VOLUMES = {"volume_fixed": 0.075, "volume_reconfigurable": 0.137, "increase_percent": 82.0}

# The ODR rows are the same in the three tables: the fixed robot's indices do not depend on beta (only k~ does).
_ODR = {"inv_cond": (8.93e-4, 0.9994, 0.4778), "omega_v": (5.71e-4, 1.1375, 0.7036),
        "omega_f": (0.8790, 1748.7, 1.8231), "sigma_min_v": (9.87e-4, 0.8493, 0.6008),
        "sigma_min_f": (0.4060, 9.4800, 0.7924)}

#: Franco-López 2026 Tables 6 (beta 0.5), 7 (0.75), 8 (0.25): min / max / mean of each index over the fixed
#: robot's workspace, for the fixed robot (ODR) and the reconfigurable one at its k~-optimal R* (RDR):
#: {beta: {robot: {index: (min, max, mean)}}}.
FRANCO2026_INDEX_STATS = {
    0.5: {"RDR": {"inv_cond": (0.1505, 0.9999, 0.4988), "omega_v": (0.0635, 1.1538, 0.6380),
                  "omega_f": (0.8666, 15.7337, 1.7976), "sigma_min_v": (0.2100, 0.9963, 0.5981),
                  "sigma_min_f": (0.3672, 1.9724, 0.8231)}, "ODR": _ODR},
    0.75: {"RDR": {"inv_cond": (0.1511, 0.9999, 0.4916), "omega_v": (0.0881, 1.3151, 0.7197),
                   "omega_f": (0.7603, 11.3387, 1.5480), "sigma_min_v": (0.2409, 0.9997, 0.6204),
                   "sigma_min_f": (0.3534, 1.2721, 0.7769)}, "ODR": _ODR},
    0.25: {"RDR": {"inv_cond": (0.1443, 0.9999, 0.4598), "omega_v": (0.0291, 0.9751, 0.5374),
                   "omega_f": (1.0254, 34.3475, 2.1525), "sigma_min_v": (0.1740, 0.9435, 0.5329),
                   "sigma_min_f": (0.4060, 2.8499, 0.8597)}, "ODR": _ODR},
}

#: The boundary-search paper (its Table 1 robot, eps = 0.01 m): Test-Pose calls at a 2 deg ray step
#: (Conti's bisection 148239 = 9 calls x 91 x 181 rays; the continuation variant), run times at 1 deg (s, the
#: paper's machine) and the pyramid-sector workspace volume (m^3).
BOUNDARY_SEARCH = dict(calls_conti_2deg=148239, calls_continuation_2deg=79500, time_conti_1deg_s=589.1236,
                       time_continuation_1deg_s=246.647, volume_m3=46.3936, eps=0.01)

#: Hasanlu 2025 (abstract, conclusions): improvement of the optimised design over the baseline (%); compared
#: in docs/REPRODUCTION.md only (a different problem and different metrics).
HASANLU2025_CLAIMS = {"volume": 15.0, "peak_torque": -12.0, "peak_speed": 8.0}


def example_indices(*, include_misprints: bool = False) -> dict:
    """{table: {index: printed value}} of Tables 2-5, without the known misprints unless asked for."""
    return {t: {k: v for k, v in row["indices"].items()
                if include_misprints or (t, k) not in FRANCO2026_MISPRINTS}
            for t, row in FRANCO2026_EXAMPLES.items()}
