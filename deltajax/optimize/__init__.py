"""Design optimisation: design space, objectives, evosax GA, NSGA-II Pareto fronts, optax refinement.

::

    space = DesignSpace.from_bounds(recon, {"upper_arm": [0.14, 0.3], ...}, n_R=16)   # genes in [0,1]^d
    pb = Problem.from_config(cfg, r_max=..., z_max=...).with_baseline(baseline_metrics)
    fit = make_fitness(pb, space)                     # genes (P, d) -> (fitness (P,), metrics)
    res = run_ga(fit, space.dim, GAConfig(...), save_checkpoint=..., checkpoint=...)   # resumable
    front = nsga2(eval_fn, space.dim, n_obj, n_constr=1, ...)                           # pymoo NSGA-II
    ref = refine(pb, space, genes)                    # optax on the relaxation, verified on the truth
"""

from .design import PARAMETERS, DesignSpace, DesignSpaceError, reflect_unit
from .ga import ALGORITHMS, GAConfig, GAError, GAResult, make_strategy, run_ga
from .objectives import (INFEASIBLE_OFFSET, METRIC_UNITS, METRICS, SENSE, ObjectiveError, Problem, evaluate_design,
                         evaluate_population, fitness_from_metrics, make_fitness, soft_margin, soft_membership)
from .designer import (CONSTRAINT_NAMES, DESIGN_METRICS, DESIGN_SENSE, DESIGN_UNITS, OBJECTIVES, DesignerProblem,
                       evaluate_designer, knee_point)
from .screens import reach_cover, task_cover  # population-level screens of make_fitness (issue 9)
from .pareto import ParetoResult, hypervolume, non_dominated, nsga2, zdt, zdt_front
from .refine import RefineResult, refine

__all__ = [
    "PARAMETERS", "DesignSpace", "DesignSpaceError", "reflect_unit",
    "ALGORITHMS", "GAConfig", "GAError", "GAResult", "make_strategy", "run_ga",
    "INFEASIBLE_OFFSET", "METRIC_UNITS", "METRICS", "SENSE", "ObjectiveError", "Problem", "evaluate_design",
    "evaluate_population", "fitness_from_metrics", "make_fitness", "soft_margin", "soft_membership",
    "ParetoResult", "hypervolume", "non_dominated", "nsga2", "zdt", "zdt_front",
    "RefineResult", "refine",
    "CONSTRAINT_NAMES", "DESIGN_METRICS", "DESIGN_SENSE", "DESIGN_UNITS", "OBJECTIVES", "DesignerProblem",
    "evaluate_designer", "knee_point",
    "reach_cover", "task_cover",
]
