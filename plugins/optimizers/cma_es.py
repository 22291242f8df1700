"""The ``cma-es`` optimiser: the CMA evolution strategy of the ``cma`` package (Hansen), its native ask/tell.

It searches the unit cube (``cma``'s ``bounds [0, 1]``, a boundary transformation),
from the centre with step size ``sigma0``, one generation (``popsize`` points)
per :meth:`ask`. Its normal draws come from the optimiser's seeded generator
(``cma``'s option ``randn``), not from numpy's global state. A failed point is
taken as the worst J so far. When the budget leaves less than a generation, the
last points asked are its first ones and the strategy is not updated with them.
When ``cma`` meets a stopping criterion of its own, the run stops
(``stop_reason = "converged"``).
"""

from __future__ import annotations

import cma
import numpy as np
from pydantic import Field

from suspid.optimize.budgeted import BudgetedOptimizer
from suspid.options import Section


class CMAESOptions(Section):
    """``optimizer.options`` of ``cma-es``."""

    sigma0: float = Field(default=0.3, gt=0, le=1.0, description="initial step size, fraction of each interval")
    popsize: int | None = Field(default=None, ge=2, description="points per generation; default 4 + 3 ln q")


class CMAES(BudgetedOptimizer):
    """CMA-ES in the unit cube (see the module docstring)."""

    name = "cma-es"
    Options = CMAESOptions

    def _setup(self) -> None:
        o = CMAESOptions(**self.options)
        rng = self.rng(0)
        opts = {"bounds": [0.0, 1.0], "randn": lambda lam, n: rng.standard_normal((lam, n)),
                "verbose": -9, "verb_log": 0, "verb_disp": 0, "maxfevals": self.budget}
        if o.popsize is not None:
            opts["popsize"] = o.popsize
        self.es_ = cma.CMAEvolutionStrategy(np.full(self.q_, 0.5), o.sigma0, opts)
        self._solutions: list[np.ndarray] = []

    def _propose(self, n: int) -> np.ndarray:
        if self.es_.stop():
            self.stop_reason_ = "converged"
            return np.empty((0, self.q_))
        self._solutions = self.es_.ask()
        return np.array(self._solutions)

    def _learn(self, U: np.ndarray, J: np.ndarray) -> None:
        if len(J) == len(self._solutions):  # a whole generation: the strategy learns (cma minimises)
            self.es_.tell(self._solutions, list(-J))
