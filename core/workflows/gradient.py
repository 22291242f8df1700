"""The run's spectra and their Jacobian for gradient-based optimisers (:class:`suspid.interfaces.SpectraModel`).

:class:`ProblemSpectraModel` gives an optimiser that asks for it
(:attr:`suspid.interfaces.Optimizer.uses_jacobian`) the spectra y_sim(w) of the
measurement date's segments with their Jacobian
(:func:`suspid.workflows.jacobian.spectra_jacobian`: analytic where the simulator
offers it, finite differences through the run's executor otherwise), and J of
given spectra. Every Jacobian is kept in the run ledger (a resumed run reads
it) and counted apart from the evaluations of J: how many, how many plain
simulations their finite differences took, their wall time, and that time in
plain-solve equivalents (against the median wall time of the run's own
evaluations, a figure of the same machine and load).
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from suspid.infra.ledger import Ledger, stable_hash
from suspid.interfaces import Executor, SpectraModel
from suspid.workflows.jacobian import spectra_jacobian
from suspid.workflows.evaluation import j_of_spectra
from suspid.workflows.problem import Problem


class ProblemSpectraModel(SpectraModel):
    """y_sim, ∂y_sim/∂w and J of a run (see the module docstring).

    :ivar n_jacobians: Jacobians computed (or read from the ledger) so far.
    :ivar n_fd_simulations: plain simulations their finite differences took.
    :ivar wall_time_s: time spent computing them in this session, s.
    :ivar methods: parameter -> ``"analytic"``, ``"central"`` or ``"forward"`` (of the last Jacobian).
    """

    def __init__(self, problem: Problem, ledger: Ledger, executor: Executor | None = None) -> None:
        self.problem = problem
        self.ledger = ledger
        self.executor = executor
        self.n_jacobians = 0
        self.n_fd_simulations = 0
        self.n_computed = 0
        self.wall_time_s = 0.0
        self.methods: dict[str, str] = {}

    def _key(self, w: dict[str, float]) -> str:
        p = self.problem
        return stable_hash("spectra-jacobian", p.simulator_identity, w, p.segments_digest, p.names,
                           p.config.spectra.model_dump())

    def jacobian(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        p = self.problem
        w = p.w_of(np.asarray(x, dtype=float))
        key = self._key(w)
        y, jac = self.ledger.get_array(key + ":y"), self.ledger.get_array(key + ":jacobian")
        self.n_jacobians += 1
        if y is None or jac is None:
            t0 = time.perf_counter()
            res = spectra_jacobian(p.simulator, w, p.names, p.segments, p.config.spectra, executor=self.executor)
            self.wall_time_s += time.perf_counter() - t0
            self.n_computed += 1
            self.n_fd_simulations += res.n_simulations
            self.methods = dict(res.methods)
            y, jac = res.y, res.jacobian
            self.ledger.put_array(key + ":y", y)
            self.ledger.put_array(key + ":jacobian", jac)
        return y, jac

    def objective(self, y_sim: np.ndarray) -> float:
        return float(j_of_spectra(self.problem, y_sim)[0])

    def summary(self, plain_wall_s: float | None) -> dict[str, Any]:
        """The Jacobians' count and cost for ``result.json`` (``plain_wall_s``: a plain simulation's wall time, s)."""
        per = self.wall_time_s / self.n_computed if self.n_computed else None
        return {"n_jacobians": self.n_jacobians, "n_computed_this_session": self.n_computed,
                "n_fd_simulations": self.n_fd_simulations, "methods": self.methods,
                "wall_time_s": round(self.wall_time_s, 3),
                "plain_solve_equivalents_each": (round(per / plain_wall_s, 2)
                                                 if per is not None and plain_wall_s else None)}
