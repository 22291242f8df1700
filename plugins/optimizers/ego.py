"""The ``ego`` optimiser: the paper's EGO loop (:class:`suspid.optimize.ego.EGO`) as an optimiser plugin.

Its options are the ``ego:`` config section (:class:`suspid.optimize.options.EGOOptions`,
with the local refinement ``refine``). The run is the one :mod:`suspid.workflows.identify`
ran before optimisers were plugins, point for point: the config's design (``design:``)
is asked first, as one batch; the points whose simulation failed are left out
of it; then the EGO points (a batch of ``ego.batch``) and the refinement's.
The budget (default: m0 + m1 + the refinement's points) stops it when reached first.

``ask(n, pending=X_p)``: for an asynchronous driver that asks one point while
others run (``ego.asynchronous``, :func:`suspid.workflows.asynchronous.drive_async`).
``X_p (p, q)`` SI are points being evaluated: the kriging believer treats them
as known (the surrogate's mean as their J), so the new point goes elsewhere
(:meth:`suspid.optimize.ego.EGO.ask_beside`). It returns no point (``(0, q)``)
during the design, in the refinement, once the budget or m1 is asked, or when
the point's EI is below the paper's eps: the driver then waits for a pending
point, and with none pending asks without ``pending``. Points may be told one
at a time, in any order.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from suspid.errors import SimulatorError, SuspidError
from suspid.infra.threads import single_blas_thread
from suspid.interfaces import Optimizer, OptimizerResult
from suspid.optimize.design import check_bounds, from_unit, make_design
from suspid.optimize.ego import EGO
from suspid.optimize.loop import IterationRecord
from suspid.optimize.options import EGOOptions, make_surrogate


class EGOOptimizer(Optimizer):
    """The paper's EGO loop (with its optional refinement) behind the :class:`~suspid.interfaces.Optimizer` contract."""

    name = "ego"
    Options = EGOOptions
    options_section = "ego"

    def _start(self) -> None:
        if getattr(self, "_started", False):
            return
        options = dict(self.options)
        options.setdefault("seed", int(self.seed))
        self.options_ = EGOOptions.model_validate(options)
        self.bounds_ = check_bounds(self.bounds)
        X0 = from_unit(make_design(self.design, self.bounds_.shape[0]), self.bounds_)
        self.X0_ = X0[: self.budget]
        self.y0_ = np.full(len(self.X0_), np.nan)
        self.X_: list[np.ndarray] = []
        self.y_: list[float] = []
        self.ego_: EGO | None = None
        self._out: list[np.ndarray] = list(self.X0_)  # asked, waiting for a value
        self._started = True

    # -- the contract ------------------------------------------------------------
    @property
    def done(self) -> bool:
        self._start()
        with single_blas_thread():  # EGO proposes its next point to know whether it stops
            return self.ego_ is not None and not self._out and self.ego_.done

    def ask(self, n: int = 1, pending: np.ndarray | None = None) -> np.ndarray:
        """The design first (all of it), then the EGO points.

        :param pending: ``(p, q)`` SI points being evaluated (asked before, not told yet):
            one more point is proposed beside them (:meth:`suspid.optimize.ego.EGO.ask_beside`),
            or none (``(0, q)``) when none can be added now (module docstring).
        """
        with single_blas_thread():  # the fits and the EI search work on small matrices
            return self._ask(pending)

    def _ask(self, pending: np.ndarray | None) -> np.ndarray:
        self._start()
        q = self.bounds_.shape[0]
        room = self.budget - len(self.y_) - len(self._out)
        if pending is not None and len(pending):
            if self.ego_ is None or room <= 0:
                return np.empty((0, q))
            X = self.ego_.ask_beside(pending)[:1]
            self._out.extend(X)
            return X
        if self.ego_ is not None and not self._out and not self.ego_.done:
            self._out = list(self.ego_.ask()[: max(room, 0)])
        return np.array(self._out).reshape(-1, q)

    def tell(self, X: np.ndarray, values: Sequence[float | None]) -> None:
        self._start()
        X = np.atleast_2d(np.asarray(X, dtype=float))
        values = [math.nan if v is None or not math.isfinite(float(v)) else float(v) for v in values]
        if len(values) != len(X):
            raise SuspidError(f"ego: tell got {len(X)} points and {len(values)} values")
        for x in X:
            i = next((i for i, o in enumerate(self._out) if np.allclose(o, x, rtol=1e-12, atol=0.0)), None)
            if i is None:
                raise SuspidError(f"ego: tell got the point {x.tolist()}, which ask did not return "
                                  f"or which has a value already")
            self._out.pop(i)
        self.X_.extend(X)
        self.y_.extend(values)
        with single_blas_thread():
            self._learn(X, values)

    def _learn(self, X: np.ndarray, values: list[float]) -> None:
        if self.ego_ is None:
            for x, v in zip(X, values):
                self.y0_[int(np.argmin(np.max(np.abs(self.X0_ - x), axis=1)))] = v
            if not self._out:
                self._begin(self.X0_, self.y0_)
            return
        self.ego_.tell(X, values)
        if len(self.y_) >= self.budget and not self.ego_.done:
            self.ego_.stop("budget")

    def result(self) -> OptimizerResult:
        self._start()
        if self.ego_ is None:
            raise SuspidError("ego: no point has a value yet")
        with single_blas_thread():  # the final refit
            res = self.ego_.result()
        return OptimizerResult(x_opt=res.x_opt, y_opt=res.y_opt, X=np.array(self.X_), y=np.array(self.y_),
                               stop_reason=res.stop_reason, n_initial=res.n_initial, details=res)

    def asynchronous(self, n_workers: int) -> bool:
        """``ego.asynchronous``: ``auto`` or ``true``, ``ego.batch`` 1 and more than one worker."""
        self._start()
        return self.options_.asynchronous is not False and self.options_.batch == 1 and n_workers > 1

    # -- internals ---------------------------------------------------------------
    def _begin(self, X0: np.ndarray, y0: np.ndarray) -> None:
        """The design's values are in: start the paper's loop on the points that have one."""
        ok = np.isfinite(y0)
        for i, (x, J) in enumerate(zip(X0, y0)):
            if ok[i]:
                self._record("design", i, {"x": x.tolist(), "J": float(J)})
        if ok.sum() < 2:
            raise SimulatorError(f"only {int(ok.sum())} of {len(y0)} design points could be simulated; "
                                 f"see the failures in the run's ledger")
        surrogate = self.surrogate if self.surrogate is not None else make_surrogate(
            "gpy-kriging", seed=self.options_.seed)
        self.ego_ = EGO(self.bounds_, ego=self.options_, surrogate=surrogate, X_init=X0[ok], y_init=y0[ok],
                        callback=self._on_iteration)

    def _on_iteration(self, record: IterationRecord) -> None:
        if record.phase == "initial":
            return
        run = "refine" if record.phase.startswith("refine") else "ego"
        self._record(run, record.index, {
            "iteration": record.iteration, "phase": record.phase, "x": np.asarray(record.x).tolist(),
            "J": record.J, "EI": record.EI, "J_max": record.J_max, "epsilon": record.epsilon,
            "hyperparameters": record.hyperparameters, "fit_s": record.fit_seconds,
            "search_s": record.search_seconds, "eval_s": record.eval_seconds})

    def _record(self, run: str, index: int, row: dict) -> None:
        if self.on_record is not None:
            self.on_record(run, index, row)
