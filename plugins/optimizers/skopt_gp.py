"""The ``skopt-gp`` optimiser: scikit-optimize's Bayesian optimisation (``skopt.Optimizer``), a library's EGO.

A peer of the paper's EGO from a well-kept library: its own Gaussian process
(scikit-learn, Matérn 5/2, hyperparameters by maximum likelihood) and its own
acquisition search (``acq_func``, default EI; ``acq_optimizer``, default L-BFGS
from random starts). It starts from the config's design (``design:``, asked as
one batch, the same m0 points as EGO's) and then asks one point at a time,
``skopt`` minimising -J. A failed point is taken as the worst J so far. Seeded
by the optimiser's seed (``random_state``).

Needs the optional extra ``methods`` (``pip install 'suspid[methods]'``);
without scikit-optimize the config is refused with one line.
"""

from __future__ import annotations

import warnings
from typing import Literal

import numpy as np
from pydantic import Field, model_validator

from suspid.infra.threads import single_blas_thread
from suspid.optimize.budgeted import BudgetedOptimizer
from suspid.options import Section

try:
    import skopt
except ImportError:  # the optional extra `methods`; refused when the config names this optimiser
    skopt = None


class SkoptOptions(Section):
    """``optimizer.options`` of ``skopt-gp``."""

    acq_func: Literal["EI", "PI", "LCB", "gp_hedge"] = Field(default="EI", description="acquisition function")
    acq_optimizer: Literal["lbfgs", "sampling"] = Field(default="lbfgs", description="how it is maximised")

    @model_validator(mode="after")
    def _installed(self) -> "SkoptOptions":
        if skopt is None:
            raise ValueError("the optimizer 'skopt-gp' needs scikit-optimize: pip install 'suspid[methods]'")
        return self


class SkoptGP(BudgetedOptimizer):
    """scikit-optimize's ``Optimizer`` with a GP (see the module docstring)."""

    name = "skopt-gp"
    Options = SkoptOptions

    def _setup(self) -> None:
        o = SkoptOptions(**self.options)
        self._design = self.initial_design(self.budget)
        self.n_initial = len(self._design)
        self.opt_ = skopt.Optimizer([(0.0, 1.0)] * self.q_, base_estimator="GP", acq_func=o.acq_func,
                                    acq_optimizer=o.acq_optimizer, n_initial_points=0,
                                    random_state=int(self.seed) % 2**32)

    def _propose(self, n: int) -> np.ndarray:
        if not self.U_:
            return self._design
        with warnings.catch_warnings(), single_blas_thread():
            warnings.simplefilter("ignore")  # skopt warns when it proposes a point twice
            return np.array(self.opt_.ask(), dtype=float)[None, :]

    def _learn(self, U: np.ndarray, J: np.ndarray) -> None:
        with warnings.catch_warnings(), single_blas_thread():  # small matrices: BLAS threads only contend
            warnings.simplefilter("ignore")
            self.opt_.tell([list(map(float, u)) for u in U], [float(-v) for v in J], fit=True)
