"""The ``ego`` optimiser: the paper's EGO loop (:class:`suspid.optimize.ego.EGO`) as an optimiser plugin.

Its options are the ``ego:`` config section (:class:`suspid.optimize.options.EGOOptions`,
with the local refinement ``refine``). It is :class:`~suspid.optimize.ego.EGO` itself,
with the run's budget and its design: the config's design (``design:``) is handed out
first, as one batch of trials; the points whose simulation failed are left out of the
loop; then the EGO trials (a batch of ``ego.batch``) and the refinement's. The budget
(default: m0 + m1 + the refinement's points) stops it when reached first.

``ask_trials(n, beside=True)``: for an asynchronous driver that asks one trial while
others run (``ego.asynchronous``). The kriging believer treats the trials waiting for
a value as known (the surrogate's mean as their J), so the new point goes elsewhere
(:meth:`suspid.optimize.ego.EGO.ask_beside`). It hands out no trial during the
design, in the refinement, once the budget or m1 is asked, or when the point's EI
is below the paper's eps: the driver then waits for a waiting trial, and with none
waiting asks without ``beside``. Trials may be told one at a time, in any order.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from suspid.infra.threads import single_blas_thread
from suspid.interfaces import Optimizer, OptimizerResult
from suspid.optimize.design import check_bounds, from_unit, make_design
from suspid.optimize.ego import EGO, EGOResult
from suspid.optimize.options import EGOOptions, make_surrogate
from suspid.optimize.trials import Trial


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
        surrogate = self.surrogate if self.surrogate is not None else make_surrogate(
            "gpy-kriging", seed=self.options_.seed)
        self.ego_ = EGO(self.bounds_, ego=self.options_, surrogate=surrogate, X_init=X0[: self.budget],
                        budget=self.budget, drop_failed_initial=True)
        self._started = True

    # -- the trial interface -----------------------------------------------------
    def ask_trials(self, n: int = 1, beside: bool = False) -> list[Trial]:
        """The design first (all of it), then the EGO trials; ``beside``: one more trial beside the
        waiting ones, or none (module docstring)."""
        self._start()
        with single_blas_thread():  # the fits and the EI search work on small matrices
            return self.ego_.ask_trials(n, beside=beside)

    def tell_trials(self, ids: Sequence[int], values: Sequence[float | None],
                    eval_seconds: Sequence[float | None] | None = None) -> None:
        self._start()
        with single_blas_thread():
            self.ego_.tell_trials(ids, values, eval_seconds)

    # -- the array contract --------------------------------------------------------
    @property
    def done(self) -> bool:
        self._start()
        with single_blas_thread():  # EGO proposes its next point to know whether it stops
            return self.ego_.done

    def ask(self, n: int = 1, pending: np.ndarray | None = None) -> np.ndarray:
        """The SI points of :meth:`ask_trials` (``pending``: points being evaluated, for one more beside them)."""
        self._start()
        with single_blas_thread():
            if pending is not None and len(pending):
                trials = self.ego_.ask_beside(pending)[:1]
            else:
                trials = self.ego_.ask_trials()
        return np.array([t.x for t in trials]).reshape(-1, self.bounds_.shape[0])

    def tell(self, X: np.ndarray, values: Sequence[float | None]) -> None:
        self._start()
        with single_blas_thread():
            self.ego_.tell(X, values)

    def result(self) -> OptimizerResult:
        res = self.loop_state()
        told = [t for t in self.ego_.book_.trials if t.told]
        return OptimizerResult(x_opt=res.x_opt, y_opt=res.y_opt, X=np.array([t.x for t in told]).reshape(
            -1, self.bounds_.shape[0]), y=np.array([np.nan if t.J is None else t.J for t in told], dtype=float),
            stop_reason=res.stop_reason, n_initial=res.n_initial, details=res)

    def loop_state(self) -> EGOResult:
        """The EGO loop's own state at its end (:class:`~suspid.optimize.loop.EGOResult`), with its surrogate."""
        self._start()
        with single_blas_thread():  # the final refit
            return self.ego_.result()

    def asynchronous(self, n_workers: int) -> bool:
        """``ego.asynchronous``: ``auto`` or ``true``, ``ego.batch`` 1 and more than one worker."""
        self._start()
        return self.options_.asynchronous is not False and self.options_.batch == 1 and n_workers > 1
