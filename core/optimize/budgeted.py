"""A base for ask/tell optimisers with a budget: the bookkeeping every one of them needs.

:class:`BudgetedOptimizer` implements :class:`suspid.interfaces.Optimizer` once, on
trials (:class:`suspid.optimize.trials.Trial`): it checks the box, hands out the points
a subclass proposes as trials (never more than the budget left), takes their values by
trial id (all the trials of one ask, told together), keeps every point and value in
evaluation order, and builds the :class:`~suspid.interfaces.OptimizerResult`. A subclass
works in the unit cube ``[0, 1]^q`` and writes two methods::

    def _propose(self, n: int) -> np.ndarray     # (k, q) points in [0, 1]^q, k >= 1; empty: stop
    def _learn(self, U: np.ndarray, J: np.ndarray) -> None   # their J, failed ones as the worst J so far

The stopping conditions are :class:`~suspid.optimize.trials.Budget` and the subclass's
own (``stop_reason_``, e.g. ``"converged"``).

Public API: :class:`BudgetedOptimizer`.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from suspid.errors import SuspidError
from suspid.interfaces import Optimizer, OptimizerResult
from suspid.optimize.design import DesignOptions, check_bounds, from_unit, make_design, to_unit
from suspid.optimize.trials import Budget, StopState, Trial, TrialBook

__all__ = ["BudgetedOptimizer"]


class BudgetedOptimizer(Optimizer):
    """The bookkeeping of an ask/tell optimiser in ``[0, 1]^q`` (see the module docstring).

    State, set at the first call: ``bounds_ (q, 2)``, ``q_``, ``U_`` (list of ``(q,)`` unit points
    told), ``y_`` (their J, NaN where failed), ``stop_reason_`` (None while running), ``book_``
    (the :class:`~suspid.optimize.trials.TrialBook` of the trials handed out), ``last_told_`` (the
    trials of the last tell, whose ``details`` a subclass may add its own figures to in ``_learn``).
    """

    def _start(self) -> None:
        if getattr(self, "_started", False):
            return
        self.bounds_ = check_bounds(self.bounds)
        self.q_ = self.bounds_.shape[0]
        self.U_: list[np.ndarray] = []
        self.y_: list[float] = []
        self.stop_reason_: str | None = None
        self.book_ = TrialBook(self.bounds_, self.budget)
        self.stopping_ = Budget(self.budget)
        self._started = True
        self._setup()

    def _setup(self) -> None:
        """Build the optimiser's own state (called once, at the first call)."""

    # -- the loop's hooks (suspid.optimize.trials.TrialLoop) ---------------------------
    whole_batches = True

    def _loop_start(self) -> None:
        self._start()

    @property
    def remaining(self) -> int:
        """Evaluations left in the budget."""
        self._start()
        return self.budget - len(self.y_)

    def _finished(self) -> bool:
        if self.stop_reason_ is None:
            self.stop_reason_ = self.stopping_.reason_for(StopState(n_told=len(self.y_)))
        return self.stop_reason_ is not None

    @property
    def done(self) -> bool:
        self._start()
        return self._finished()

    def _propose_trials(self, n: int) -> None:
        U = np.atleast_2d(np.asarray(self._propose(max(int(n), 1)), dtype=float))
        if U.size == 0:
            self.stop_reason_ = self.stop_reason_ or "converged"
            return
        for u in np.clip(U[: self.remaining], 0.0, 1.0):
            self.book_.new(u, self.name)

    def _commit_trials(self, trials: list[Trial]) -> None:
        U = to_unit(np.array([t.x for t in trials]), self.bounds_)   # the points as the driver evaluated them
        values = [math.nan if t.J is None else t.J for t in trials]
        self.U_.extend(u.copy() for u in U)
        self.y_.extend(values)
        self.last_told_ = trials
        self._learn(U, self.filled(values))

    # -- the array contract ----------------------------------------------------------
    def ask(self, n: int = 1) -> np.ndarray:
        self._start()
        return np.array([t.x for t in self.ask_trials(n)]).reshape(-1, self.q_)

    def tell(self, X: np.ndarray, values: Sequence[float | None]) -> None:
        """J at the points the last :meth:`ask` returned, in that order (deprecated: tell trials by id)."""
        self._start()
        X = np.atleast_2d(np.asarray(X, dtype=float))
        waiting = [t.id for t in self.book_.waiting]
        if X.shape != (len(waiting), self.q_) or len(values) != len(X) or _ids_of(self.book_, X) != waiting:
            raise SuspidError(f"{self.name}: tell expects the {len(waiting)} points ask returned, "
                              f"in the same order, and one value each; got {X.shape[0]} points, {len(values)} values")
        self.tell_trials(waiting, list(values))

    def result(self) -> OptimizerResult:
        self._start()
        y = np.array(self.y_, dtype=float)
        if not np.any(np.isfinite(y)):
            raise SuspidError(f"{self.name}: no point has a value yet")
        best = int(np.nanargmax(y))
        U = np.array(self.U_).reshape(-1, self.q_)
        return OptimizerResult(x_opt=from_unit(U[best], self.bounds_), y_opt=float(y[best]),
                               X=from_unit(U, self.bounds_), y=y, stop_reason=self.stop_reason_ or "running",
                               n_initial=self.n_initial)

    # -- helpers for subclasses ----------------------------------------------------
    n_initial: int = 0
    """Points of the initial design among the first told (set by subclasses that use one)."""

    def worst(self) -> float:
        """The worst J told so far (0 before any value): what a failed point is taken to be."""
        finite = [v for v in self.y_ if math.isfinite(v)]
        return min(finite) if finite else 0.0

    def filled(self, values: Sequence[float]) -> np.ndarray:
        """``values`` with failed points (NaN) replaced by the worst J told so far."""
        return np.array([v if math.isfinite(v) else self.worst() for v in values], dtype=float)

    def initial_design(self, n_max: int | None = None) -> np.ndarray:
        """The config's design (``design:`` section) in ``[0, 1]^q``, at most ``n_max`` points
        (fewer than the budget: the rest is the optimiser's)."""
        options = self.design if isinstance(self.design, DesignOptions) else DesignOptions()
        U = make_design(options, self.q_)
        return U[: min(len(U), n_max if n_max is not None else self.budget)]

    def rng(self, *stream: int) -> np.random.Generator:
        """A generator of the stream ``(seed, *stream)``: deterministic for a given seed."""
        return np.random.default_rng([int(self.seed), *stream])

    def _propose(self, n: int) -> np.ndarray:
        raise NotImplementedError

    def _learn(self, U: np.ndarray, J: np.ndarray) -> None:
        """Take the values of the points just told (default: nothing to learn)."""


def _ids_of(book: TrialBook, X: np.ndarray) -> list[int] | None:
    """The trials of ``book`` handed out exactly at ``X (k, q)`` SI, None when a point is not one."""
    try:
        return book.ids_of(X)
    except SuspidError:
        return None
