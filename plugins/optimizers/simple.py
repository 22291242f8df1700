"""The floors of a methods comparison: ``random`` (uniform random search) and ``lhs-only`` (the design alone).

Neither learns from J: each asks its whole budget at once (one batch, so that
every worker of the executor is busy), and w_opt is the best point evaluated.
"""

from __future__ import annotations

import numpy as np

from suspid.optimize.budgeted import BudgetedOptimizer
from suspid.optimize.design import DesignOptions, make_design
from suspid.options import Section


class NoOptions(Section):
    """This optimiser takes no options (any key is a mistake)."""


class RandomSearch(BudgetedOptimizer):
    """Uniform random search over the box: ``budget`` independent uniform points (stream ``(seed, 0)``)."""

    name = "random"
    Options = NoOptions

    def _propose(self, n: int) -> np.ndarray:
        return self.rng(0).random((self.remaining, self.q_))


class DesignOnly(BudgetedOptimizer):
    """The config's space-filling design (``design.method``, maximin LHS by default) with ``budget`` points."""

    name = "lhs-only"
    Options = NoOptions

    def _propose(self, n: int) -> np.ndarray:
        base = self.design if isinstance(self.design, DesignOptions) else DesignOptions(seed=int(self.seed) % 2**63)
        U = make_design(base.model_copy(update={"n_initial": self.budget}), self.q_)
        self.n_initial = len(U)
        return U
