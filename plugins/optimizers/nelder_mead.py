"""The ``nelder-mead`` optimiser: scipy's Nelder-Mead simplex, restarted from the best design points.

The config's design (``design:``, m0 points) is asked first, as one batch.
Then ``scipy.optimize.minimize(method="Nelder-Mead")`` maximises J in the unit
cube (its bounds clip the simplex to ``[0, 1]^q``), starting from the best
design point with a simplex of edge ``simplex`` (fraction of each interval);
when it converges (``xatol``, ``fatol``) it restarts from the next best design
point, until the budget is spent or every design point has served
(``stop_reason = "converged"``).

scipy's loop calls J itself, so it runs in a helper thread that hands each
point over to :meth:`ask` and waits for :meth:`tell`: one point at a time, the
two threads never run together, and the run is deterministic (nothing here is
random besides the seeded design). A point already evaluated is answered from
memory without asking it again. A failed point is taken as the worst J so far.
"""

from __future__ import annotations

import queue
import threading

import numpy as np
from pydantic import Field
from scipy.optimize import minimize

from suspid.optimize.budgeted import BudgetedOptimizer
from suspid.options import Section


class NelderMeadOptions(Section):
    """``optimizer.options`` of ``nelder-mead``."""

    simplex: float = Field(default=0.1, gt=0, le=0.5, description="edge of the initial simplex, fraction of each interval")
    xatol: float = Field(default=1e-3, gt=0, description="convergence: simplex size in [0, 1] units")
    fatol: float = Field(default=1e-6, ge=0, description="convergence: spread of J over the simplex")
    adaptive: bool = Field(default=True, description="dimension-adapted coefficients (Gao and Han, 2012)")


class _Stopped(Exception):
    """Raised inside the helper thread when the budget is spent."""


_FINISHED = object()


class NelderMead(BudgetedOptimizer):
    """Nelder-Mead with restarts from the best design points (see the module docstring)."""

    name = "nelder-mead"
    Options = NelderMeadOptions

    def _setup(self) -> None:
        self.opts_ = NelderMeadOptions(**self.options)
        self._design = self.initial_design(self.budget)
        self.n_initial = len(self._design)
        self._thread: threading.Thread | None = None
        self._points: queue.Queue = queue.Queue(maxsize=1)
        self._values: queue.Queue = queue.Queue(maxsize=1)
        self._known: dict[bytes, float] = {}

    def _propose(self, n: int) -> np.ndarray:
        if not self.U_:
            return self._design
        if self._thread is None:
            self._thread = threading.Thread(target=self._restarts, name="suspid-nelder-mead", daemon=True)
            self._thread.start()
        item = self._points.get()
        if item is _FINISHED:
            self.stop_reason_ = "converged"
            return np.empty((0, self.q_))
        return item[None, :]

    def _learn(self, U: np.ndarray, J: np.ndarray) -> None:
        for u, v in zip(U, J):
            self._known[u.tobytes()] = float(v)
        if self._thread is not None:
            self._values.put(float(J[0]))

    # -- the helper thread -----------------------------------------------------------
    def _restarts(self) -> None:
        o, q = self.opts_, self.q_
        y0 = np.array(self.y_[: self.n_initial])
        order = np.argsort(-np.nan_to_num(y0, nan=-np.inf), kind="stable")
        try:
            for i in order:
                x0 = self._design[i]
                step = np.where(x0 + o.simplex <= 1.0, o.simplex, -o.simplex)
                simplex = np.vstack([x0, x0 + np.diag(step)])
                minimize(self._negative_J, x0, method="Nelder-Mead", bounds=[(0.0, 1.0)] * q,
                         options={"initial_simplex": simplex, "xatol": o.xatol, "fatol": o.fatol,
                                  "adaptive": o.adaptive, "maxfev": 10**9})
        except _Stopped:
            return
        self._points.put(_FINISHED)

    def _negative_J(self, u: np.ndarray) -> float:
        u = np.clip(np.asarray(u, dtype=float), 0.0, 1.0)
        known = self._known.get(u.tobytes())
        if known is not None:
            return -known
        if self.remaining <= 0:
            raise _Stopped
        self._points.put(u.copy())
        return -self._values.get()
