"""Trials: the points an optimiser hands out, each with an identity, and the conditions that stop a loop.

A :class:`Trial` is one evaluation of J asked by an optimiser: its id (0, 1, 2, ...
in the order the loop handed it out), the point in ``[0, 1]^q`` and in SI units,
the phase that proposed it and what the proposal knew (EI, J_max, eps,
hyperparameters, fit and search times). The driver evaluates it and tells the
optimiser its value *by id*: no point is ever matched back by its coordinates.

:class:`TrialLoop` is the one ask/tell state machine: it hands out trials within the
budget, takes their values by id and commits them to the optimiser in id order, whatever
the order of ``tell``, so that an asynchronous driver gives the same run as a serial one.
What to propose and what to learn are the optimiser's hooks: the paper's EGO loop
(:class:`suspid.optimize.ego.EGO`, whose pieces are the proposer, the stopping rules and
the surrogate's updates of :mod:`suspid.optimize.loop`), the optimisers on
:class:`suspid.optimize.budgeted.BudgetedOptimizer` and a plugin that speaks only the
array contract (:class:`suspid.interfaces.Optimizer`'s default) all run on it.
:class:`TrialBook` is its bookkeeping: the trials handed out and not told, in id order,
the trials told, the budget.

Stopping conditions share one signature, ``condition(state) -> bool`` on a
:class:`StopState`, and combine with ``|``::

    stop = EIBelowTolerance(1e-4) | MaxIterations(40) | Budget(300)
    if stop(state): reason = stop.reason_for(state)

Public API: :class:`Trial`, :class:`TrialBook`, :class:`TrialLoop`, :class:`StopState`, :class:`StoppingCondition`,
:class:`MaxIterations`, :class:`EIBelowTolerance`, :class:`Budget`.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any, Iterable, Sequence

import numpy as np

from suspid.errors import SuspidError

__all__ = ["Trial", "TrialBook", "TrialLoop", "StopState", "StoppingCondition", "MaxIterations", "EIBelowTolerance", "Budget",
           "as_value"]

PENDING, OK, FAILED = "pending", "ok", "failed"


@dataclass
class Trial:
    """One evaluation of J asked by an optimiser.

    :ivar id: its identity in the run, 0, 1, 2, ... in the order the loop handed trials out.
    :ivar u: ``(q,)`` the point in ``[0, 1]^q``; :ivar x: ``(q,)`` the same in SI units.
    :ivar phase: what proposed it (``"initial"``, ``"ego"``, ``"refine"``, an optimiser's name).
    :ivar status: ``"pending"`` until told, then ``"ok"`` or ``"failed"`` (no finite value).
    :ivar J: the objective there (None while pending or when failed).
    :ivar w: ``name -> SI value``, set by the driver that knows the names (None otherwise).
    :ivar psi: the per-channel terms Ψ_k of J (eq. 5), set by the driver when it has them.
    :ivar details: what the proposal knew: ``iteration``, ``log_ei``, ``j_max``, ``epsilon``,
        ``hyperparameters``, ``fit_seconds``, ``search_seconds`` (EGO), an optimiser's own fields.
    :ivar asked_at, told_at: ``time.time()`` when it was handed out and when its value came.
    :ivar eval_seconds: the evaluation's wall time in s, when the driver measured it.
    :ivar counted: a call of J made by this run (False for a value given up front, ``y_init``).
    """

    id: int
    u: np.ndarray
    x: np.ndarray
    phase: str
    status: str = PENDING
    J: float | None = None
    w: dict[str, float] | None = None
    psi: list[float] | None = None
    details: dict[str, Any] = field(default_factory=dict)
    asked_at: float = 0.0
    told_at: float | None = None
    eval_seconds: float | None = None
    counted: bool = True

    @property
    def told(self) -> bool:
        """True once its value (or its failure) is known."""
        return self.status != PENDING

    def summary(self) -> dict[str, Any]:
        """A JSON-able row of the trial (without the point's coordinates and J, which the evaluation holds)."""
        out = {"id": self.id, "phase": self.phase, "status": self.status, "eval_s": self.eval_seconds}
        for k, v in self.details.items():
            if k != "step":   # the refinement's own step object (its fields are in the other details)
                out[k] = _plain(v)
        return out


def _plain(v: Any) -> Any:
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, (np.floating, np.integer)):
        return v.item()
    if isinstance(v, float) and not math.isfinite(v):
        return None
    if isinstance(v, dict):
        return {k: _plain(x) for k, x in v.items()}
    return v


def as_value(v: Any, x: np.ndarray | None = None) -> float | None:
    """J as a float, None for a failed evaluation (None, NaN, ±inf).

    :raises SuspidError: a value that is not a number.
    """
    if v is None:
        return None
    try:
        J = float(v)
    except (TypeError, ValueError):
        where = f" at w={np.asarray(x).tolist()}" if x is not None else ""
        raise SuspidError(f"the objective returned {v!r}{where}; expected a number") from None
    return J if math.isfinite(J) else None


class TrialBook:
    """The trials of one loop: handed out, waiting, told; ids and the budget (see the module docstring).

    :param bounds: ``(q, 2)`` SI box (the unit cube's transform: ``x = lo + u (hi - lo)``).
    :param budget: the largest number of counted trials, None for no limit.
    """

    def __init__(self, bounds: np.ndarray, budget: int | None = None) -> None:
        self.bounds = np.asarray(bounds, dtype=float)
        self.budget = budget
        self.trials: list[Trial] = []
        self.queue: list[Trial] = []   # handed out and not committed, in id order

    # -- handing out ---------------------------------------------------------------
    def new(self, u: np.ndarray, phase: str, x: np.ndarray | None = None, **details: Any) -> Trial:
        """A new trial at ``u (q,)`` (``x``: its SI point when the caller already has it), queued."""
        from suspid.optimize.design import from_unit
        trial = Trial(id=len(self.trials), u=u, x=from_unit(u, self.bounds) if x is None else x, phase=phase,
                      details=details, asked_at=time.time())
        self.trials.append(trial)
        self.queue.append(trial)
        return trial

    @property
    def waiting(self) -> list[Trial]:
        """Trials handed out whose value has not been told, in id order."""
        return [t for t in self.queue if not t.told]

    # -- telling -------------------------------------------------------------------
    def get(self, trial_id: int) -> Trial:
        """The waiting trial of that id.

        :raises SuspidError: no trial of that id waits for a value.
        """
        i = int(trial_id)
        if not 0 <= i < len(self.trials) or self.trials[i].told or self.trials[i] not in self.queue:
            raise SuspidError(f"tell: trial {trial_id} is not one that ask() handed out and that still waits "
                              f"for a value")
        return self.trials[i]

    def record(self, ids: Iterable[int], values: Sequence[Any], eval_seconds: Sequence[float | None] | None = None
               ) -> None:
        """Set the values of the trials ``ids`` (None, NaN or ±inf: failed)."""
        ids = list(ids)
        values = list(values)
        if len(ids) != len(values):
            raise SuspidError(f"tell: {len(ids)} trials for {len(values)} values")
        times = list(eval_seconds) if eval_seconds is not None else [None] * len(ids)
        trials = [self.get(i) for i in ids]
        now = time.time()
        for t, v, dt in zip(trials, values, times):
            J = as_value(v, t.x)
            t.J, t.status, t.told_at = J, OK if J is not None else FAILED, now
            if dt is not None:
                t.eval_seconds = dt

    def pop_told(self) -> Trial | None:
        """The trial at the head of the queue when it is told (committed in id order), else None."""
        if self.queue and self.queue[0].told:
            return self.queue.pop(0)
        return None

    def drop_waiting(self) -> None:
        """Forget the trials still waiting (the loop stopped)."""
        self.queue = []

    def ids_of(self, X: np.ndarray) -> list[int]:
        """The ids of the waiting trials handed out at the SI points ``X (k, q)``: each row must be
        exactly (bit for bit) the ``x`` of a waiting trial, as ``ask`` returned it. No tolerance, no
        search near a point: the array form of ``tell`` (deprecated: tell trials by id) only names
        the trials by the points it was given.

        :raises SuspidError: a point that is not one a waiting trial was handed out at.
        """
        ids: list[int] = []
        for x in np.atleast_2d(np.asarray(X, dtype=float)):
            hit = next((t for t in self.queue if not t.told and t.id not in ids and np.array_equal(t.x, x)), None)
            if hit is None:
                raise SuspidError(f"tell: the point {x.tolist()} is not one that ask() returned and that still "
                                  f"waits for a value")
            ids.append(hit.id)
        return ids


class TrialLoop:
    """The ask/tell state machine every optimiser of suspid runs on (see the module docstring).

    It hands out trials within the budget, takes their values by id, commits them in id
    order and stops; what to propose and what to learn are hooks of the optimiser:

    - :meth:`_loop_start`: set ``self.book_`` (a :class:`TrialBook`) at the first call;
    - :meth:`_propose_trials` ``(n)``: hand out new trials (``self.book_.new(u, phase, ...)``) or
      stop; called only while nothing waits for a value and the loop has not stopped;
    - :meth:`_commit_trials` ``(trials)``: learn the values of trials, in id order (with
      :attr:`whole_batches`, every trial of one ask at once);
    - :meth:`_finished`: whether the loop has stopped;
    - :meth:`_beside`: one more trial beside those waiting, for an asynchronous driver.
    """

    #: Trials of one ask are told together (the array contract of most optimisers): ``tell_trials``
    #: then takes exactly the trials waiting, and they are committed together.
    whole_batches: bool = False
    book_: TrialBook

    def _loop_start(self) -> None:
        raise NotImplementedError

    def _propose_trials(self, n: int) -> None:
        raise NotImplementedError

    def _commit_trials(self, trials: list[Trial]) -> None:
        raise NotImplementedError

    def _finished(self) -> bool:
        raise NotImplementedError

    def _beside(self) -> list[Trial]:
        """One more trial beside those waiting (an asynchronous driver), or none (default: none)."""
        return []

    def _advance(self, n: int = 1) -> None:
        """With nothing waiting, propose the next trials until some wait or the loop stops."""
        while not self.book_.queue and not self._finished():
            self._propose_trials(n)

    def _told_count(self) -> int:
        """Counted trials told (failed ones included): what the budget is spent on."""
        return sum(t.counted for t in self.book_.trials if t.told)

    def ask_trials(self, n: int = 1, beside: bool = False) -> list[Trial]:
        """The trials to evaluate next, within the budget (none when the loop has stopped); asked again
        before they are told, the same trials. ``beside``: one more trial beside those waiting
        (:meth:`_beside`), none when nothing waits."""
        self._loop_start()
        if beside:
            return self._beside() if self.book_.waiting else []
        self._advance(n)
        waiting = self.book_.waiting
        if self.book_.budget is not None:   # trials beyond the budget are never handed out
            waiting = waiting[: max(self.book_.budget - self._told_count(), 0)]
        return waiting

    def tell_trials(self, ids: Sequence[int], values: Sequence[Any],
                    eval_seconds: Sequence[float | None] | None = None) -> None:
        """J of trials handed out, by id (None, NaN or ±inf where the evaluation failed); they are
        committed in id order, a trial waiting for those handed out before it."""
        self._loop_start()
        if self.whole_batches:
            waiting = [t.id for t in self.book_.waiting]
            if sorted(int(i) for i in ids) != waiting:
                raise SuspidError(f"{getattr(self, 'name', 'optimizer')}: tell expects the {len(waiting)} trials "
                                  f"ask handed out ({waiting}), and one value each; got trials {list(ids)}")
        self.book_.record(ids, values, eval_seconds)
        self._commit_told()

    def _commit_told(self) -> None:
        """Commit the told trials at the head of the queue, in id order."""
        trials = []
        while (t := self.book_.pop_told()) is not None:
            trials.append(t)
        if trials:
            self._commit_trials(trials)


# -- stopping conditions -----------------------------------------------------------------------

@dataclass
class StopState:
    """What a stopping condition reads.

    :ivar n_told: counted trials told (failed ones included).
    :ivar n_new: trials told after the initial design (failed ones included).
    :ivar log_ei: log EI of the point the last proposal found (None before one).
    :ivar epsilon: eps of that proposal, in units of J.
    """

    n_told: int = 0
    n_new: int = 0
    log_ei: float | None = None
    epsilon: float = 0.0


class StoppingCondition:
    """``condition(state) -> bool``; ``a | b`` stops when either does (the first that fires names the reason)."""

    reason = "stopped"

    def __call__(self, state: StopState) -> bool:
        raise NotImplementedError

    def reason_for(self, state: StopState) -> str | None:
        """The reason of the condition that fires on ``state``, None if none does."""
        return self.reason if self(state) else None

    def __or__(self, other: "StoppingCondition") -> "StoppingCondition":
        return AnyOf([*_parts(self), *_parts(other)])


def _parts(c: StoppingCondition) -> list[StoppingCondition]:
    return list(c.conditions) if isinstance(c, AnyOf) else [c]


class AnyOf(StoppingCondition):
    """Stops when any of its conditions does; the reason is the first one's that fires."""

    def __init__(self, conditions: list[StoppingCondition]) -> None:
        self.conditions = conditions

    def __call__(self, state: StopState) -> bool:
        return any(c(state) for c in self.conditions)

    def reason_for(self, state: StopState) -> str | None:
        return next((c.reason for c in self.conditions if c(state)), None)


class MaxIterations(StoppingCondition):
    """At most m1 = ``max_iter`` points after the initial design (failed ones included)."""

    reason = "max_iter"

    def __init__(self, max_iter: int) -> None:
        self.max_iter = max_iter

    def __call__(self, state: StopState) -> bool:
        return state.n_new >= self.max_iter

    def should_stop(self, n_new_points: int) -> bool:
        """True once ``n_new_points`` reach m1 (the same rule, on a count)."""
        return self(StopState(n_new=n_new_points))


class EIBelowTolerance(StoppingCondition):
    """The paper's stopping rule: EI(w_l) < eps, eps = tol * (max J - min J) over the current data.

    With tol = 0, or all J equal, eps = 0 and the rule never fires.
    """

    reason = "ei_below_tol"

    def __init__(self, tol: float) -> None:
        self.tol = tol

    def epsilon(self, y: np.ndarray) -> float:
        """eps for the values ``y (n_points,)``, in units of J."""
        return self.tol * float(y.max() - y.min())

    def below(self, log_ei: float, epsilon: float) -> bool:
        """True when EI < eps (compared in log space, so an EI that underflows still counts)."""
        return epsilon > 0 and log_ei < math.log(epsilon)

    def should_stop(self, log_ei: float, epsilon: float) -> bool:
        """:meth:`below` (the same rule, on a value)."""
        return self.below(log_ei, epsilon)

    def __call__(self, state: StopState) -> bool:
        return state.log_ei is not None and self.below(state.log_ei, state.epsilon)


class Budget(StoppingCondition):
    """At most ``budget`` evaluations of J in all (initial design and failed points included)."""

    reason = "budget"

    def __init__(self, budget: int) -> None:
        self.budget = budget

    def __call__(self, state: StopState) -> bool:
        return state.n_told >= self.budget
