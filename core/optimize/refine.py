"""The local trust-region refinement after the paper's loop (``ego.refine``, beyond the paper).

See :class:`suspid.optimize.options.RefineOptions` for why and what. Here
the refinement is a proposer with its own stopping rule, driven by
:class:`suspid.optimize.ego.EGO` through the same ask/tell cycle as the
paper's loop: :meth:`TrustRegionRefiner.propose` returns the next point (or
None once the radius rule or the budget has stopped it) and
:meth:`TrustRegionRefiner.update` takes its value.

Determinism: the candidates of the step that follows the n-th evaluation are
drawn from ``default_rng([seed, 2, n])``.

Public API: :class:`TrustRegionRefiner`, :class:`RefineStep`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from suspid.interfaces import Surrogate
from suspid.optimize.acquisition import log_expected_improvement, maximize_ei, maximize_mean
from suspid.optimize.loop import EIBelowTolerance, LoopState
from suspid.optimize.options import EGOOptions

__all__ = ["TrustRegionRefiner", "RefineStep"]


@dataclass
class RefineStep:
    """A point proposed by the refinement: ``u (q,)`` in [0, 1]^q and what the record needs."""

    u: np.ndarray
    log_ei: float
    j_max: float
    epsilon: float
    iteration: int
    hyperparameters: dict[str, Any]
    fit_seconds: float
    search_seconds: float


class TrustRegionRefiner:
    """Proposer and stopping rule of the refinement (:class:`~suspid.optimize.options.RefineOptions`).

    The local fits use a new instance of the surrogate's class with the same
    options, so the global model (its fit and its warm starts) is left as the
    paper's loop made it.

    :param surrogate: the run's surrogate (its class and options are reused).
    :param opts: the ``ego:`` options (``refine``, ``tol``, ``seed``, search fields).
    :param first_iteration: the ``iteration`` number of the first refinement record.
    :ivar reason: why it stopped (``"radius_below_min"``, ``"max_iter"``), None while running.
    :ivar n: points evaluated so far; :ivar radius: the current half-width in [0, 1] units.
    """

    def __init__(self, surrogate: Surrogate, opts: EGOOptions, first_iteration: int) -> None:
        self.opts = opts
        self.local = type(surrogate)(**surrogate.options)
        self.radius = opts.refine.radius
        self.iteration = first_iteration
        self.n = 0
        self.failures = 0
        self.reason: str | None = None
        self._stop = EIBelowTolerance(opts.tol)

    def _failed_step(self, count: int) -> None:
        """Count failures; after ``patience`` of them halve the radius (and stop below ``min_radius``)."""
        ro = self.opts.refine
        self.failures += count
        if self.failures >= ro.patience:
            self.radius, self.failures = self.radius / 2, 0
            if self.radius < ro.min_radius:
                self.reason = "radius_below_min"

    def propose(self, state: LoopState) -> RefineStep | None:
        """The next point to evaluate, or None when the refinement has stopped (see :attr:`reason`)."""
        ro, opts = self.opts.refine, self.opts
        q = state.q
        k = ro.n_points or 10 * q
        while self.reason is None:
            if self.n >= ro.max_iter:
                self.reason = "max_iter"
                break
            Ua, ya = state.U_array, state.y_array
            best = int(np.argmax(ya))
            centre, j_max = Ua[best], float(ya[best])
            near = np.argsort(np.linalg.norm(Ua - centre, axis=1), kind="stable")[:k]
            eps = self._stop.epsilon(ya)
            lo, hi = np.clip(centre - self.radius, 0.0, 1.0), np.clip(centre + self.radius, 0.0, 1.0)
            t0 = time.perf_counter()
            self.local.fit(Ua[near], ya[near])
            t_fit = time.perf_counter() - t0
            rng = np.random.default_rng([opts.seed, 2, state.n_points])
            t0 = time.perf_counter()
            u_new = maximize_mean(self.local, centre, lo, hi, opts, rng)
            if _is_evaluated(u_new, Ua[near], self.radius):
                # the local mean peaks at a point already known: explore the box by EI instead
                u_new, _ = maximize_ei(self.local, Ua[near], ya[near], j_max, opts, rng, lo, hi)
            log_ei = float(log_expected_improvement(*self.local.predict(u_new[None, :]), j_max)[0])
            t_search = time.perf_counter() - t0
            if _is_evaluated(u_new, Ua[near], self.radius):  # nothing new to learn at this scale
                self._failed_step(ro.patience)
                continue
            return RefineStep(u=u_new, log_ei=log_ei, j_max=j_max, epsilon=eps, iteration=self.iteration,
                              hyperparameters=dict(self.local.hyperparameters_ or {}), fit_seconds=t_fit,
                              search_seconds=t_search)
        return None

    def update(self, step: RefineStep, J: float | None) -> None:
        """Take the value J at ``step.u`` (None: the evaluation failed, a step without improvement)."""
        self.n += 1
        if J is None:
            self._failed_step(1)
            return
        self.iteration += 1
        if J > step.j_max + step.epsilon:
            self.failures = 0
        else:
            self._failed_step(1)


def _is_evaluated(u: np.ndarray, U: np.ndarray, radius: float) -> bool:
    """Whether ``u (q,)`` is one of the points ``U (n_points, q)``, to 1e-3 of the trust-region radius."""
    return bool(np.min(np.max(np.abs(U - u), axis=1)) <= 1e-3 * radius)
