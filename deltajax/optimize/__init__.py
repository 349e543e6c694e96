"""Design optimisation: design space, the designer's problem, evosax GA, NSGA-II Pareto fronts, optax refinement,
worst cases found and certified (:mod:`deltajax.optimize.certify`).

::

    space = DesignSpace.from_bounds(recon, {"upper_arm": [0.14, 0.3], ...}, n_R=16)   # genes in [0,1]^d
    pb = DesignerProblem.build(task=..., cycle=..., motor=..., ...)   # the designer's problem (one)
    m = evaluate_designer(pb, space.decode(genes))    # every metric, constraint values, feasibility; vmappable
    fit = workflow.ga_fitness(pb, space, objectives, weights)   # genes (P, d) -> (fitness (P,), metrics)
    res = run_ga(fit, space.dim, GAConfig(...), save_checkpoint=..., checkpoint=...)   # resumable
    front = nsga2(eval_fn, space.dim, n_obj, n_constr=5, ...)                           # pymoo NSGA-II
    out = workflow.refine_designs(pb, space, winners, ...)   # optax descent on the primary objective

The main job (``experiment=ga_reconfig``) runs these stage by stage (:mod:`deltajax.optimize.workflow`); its
``objectives.mode: weighted`` is the weighted-sum problem.
"""

from .design import PARAMETERS, DesignSpace, DesignSpaceError, reflect_unit
from .ga import ALGORITHMS, GAConfig, GAError, GAResult, make_strategy, run_ga
from .designer import (CONSTRAINT_NAMES, DESIGN_METRICS, DESIGN_SENSE, DESIGN_UNITS, OBJECTIVES, DesignerProblem,
                       cylinder_points, evaluate_designer, knee_point)
from .pareto import ParetoResult, hypervolume, non_dominated, nsga2, zdt, zdt_front
from .certify import TOLERANCES, certify_design, design_margins, ray_cylinder, ray_cylinders, worst_in_cylinder

__all__ = [
    "PARAMETERS", "DesignSpace", "DesignSpaceError", "reflect_unit",
    "ALGORITHMS", "GAConfig", "GAError", "GAResult", "make_strategy", "run_ga",
    "ParetoResult", "hypervolume", "non_dominated", "nsga2", "zdt", "zdt_front",
    "CONSTRAINT_NAMES", "DESIGN_METRICS", "DESIGN_SENSE", "DESIGN_UNITS", "OBJECTIVES", "DesignerProblem",
    "evaluate_designer", "knee_point", "cylinder_points",
    "TOLERANCES", "certify_design", "design_margins", "ray_cylinder", "ray_cylinders", "worst_in_cylinder",
]
