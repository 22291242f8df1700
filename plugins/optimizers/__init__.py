"""Built-in optimisers (:class:`suspid.interfaces.Optimizer`), registered through the ``suspid`` entry-point group.

- ``ego``: the paper's EGO loop with its optional refinement (the default);
- ``random``: uniform random search, the floor of a comparison;
- ``lhs-only``: the space-filling design alone;
- ``nelder-mead``: scipy's Nelder-Mead, restarted from the best design points;
- ``cma-es``: the CMA evolution strategy of the ``cma`` package;
- ``skopt-gp``: scikit-optimize's Bayesian optimisation, a library's EGO (extra ``methods``);
- ``gauss-newton``: a trust region on the linearised spectra (their Jacobian), after a small design.
"""

from __future__ import annotations

from suspid import hookimpl
from suspid.plugins.optimizers.cma_es import CMAES
from suspid.plugins.optimizers.ego import EGOOptimizer
from suspid.plugins.optimizers.gauss_newton import GaussNewton
from suspid.plugins.optimizers.nelder_mead import NelderMead
from suspid.plugins.optimizers.simple import DesignOnly, RandomSearch
from suspid.plugins.optimizers.skopt_gp import SkoptGP

BUILT_INS = (EGOOptimizer, RandomSearch, DesignOnly, NelderMead, CMAES, SkoptGP, GaussNewton)


@hookimpl
def suspid_register_optimizers(register):
    for cls in BUILT_INS:
        register(cls)
