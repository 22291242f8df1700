"""The ``gauss-newton`` optimiser: a trust-region search on the linearised spectra, after a small design.

Beyond the paper, for simulators whose spectra can be differentiated
(:class:`suspid.interfaces.DifferentiableSimulator`; finite differences
otherwise, at q or 2q simulations per Jacobian). A generalised Gauss-Newton
step: the *model* is linearised, the objective is kept exact. At the centre
w_c, with y_c = y_sim(w_c) and its Jacobian, the spectra are predicted as

    y_lin(w) = y_c + ∂y/∂(log w) (log w - log w_c)          (``linearise: log``)

(resonances move with the square root of a stiffness: the spectra are closer to
linear in log w than in w), and the step maximises the run's own
J(y_lin(w)) (eq. 5-8 with the run's noise paths: no simulation, a few ms per
evaluation) inside a box of half-width ``radius`` around w_c in [0, 1]^q.
One simulation at the proposed point gives the true J; with
ρ = (J - J_c) / (J_lin - J_c) the step is accepted when J rose, the radius
doubles when ρ > 0.75 on the region's edge and shrinks to half the step when
ρ < 0.25. Each accepted centre takes one Jacobian (``result.json``'s
``jacobian``: counted apart from the simulations, with its cost).

Start: the best point of a maximin design of ``n_initial`` points (2 q + 2 by default) (the
config's ``design`` method and seed). Stop: the radius below ``min_radius``,
a predicted gain below ``tol`` × (max J − min J) of the points told, or the
budget. Deterministic: the subproblem's starts are drawn from ``(seed, 5, n)``.
"""

from __future__ import annotations

import math

import numpy as np
from pydantic import Field, model_validator
from scipy.optimize import minimize

from suspid.errors import ConfigError, SuspidError
from suspid.optimize.budgeted import BudgetedOptimizer
from suspid.optimize.design import DesignOptions, from_unit, make_design
from suspid.options import Section
from typing import Literal


class GaussNewtonOptions(Section):
    """``optimizer.options`` of ``gauss-newton``."""

    n_initial: int | None = Field(default=None, ge=1, le=1000,
                                  description="points of the initial maximin design (default 2 q + 2: the best one "
                                  "starts the search, all of them give the surrogate the analysis reads a global view)")
    radius: float = Field(default=0.25, gt=0, le=1, description="initial half-width of the trust region, [0, 1] units")
    max_radius: float = Field(default=0.5, gt=0, le=1, description="largest half-width, [0, 1] units")
    min_radius: float = Field(default=2e-3, gt=0, description="stop when the half-width falls below it")
    tol: float = Field(default=1e-4, ge=0, description="stop when the predicted gain < tol x (max J - min J)")
    linearise: Literal["log", "linear"] = Field(default="log", description="linearise the spectra in log w or in w")
    starts: int = Field(default=1, ge=1, le=64, description="starts of the subproblem's search (the centre and "
                        "random points of the region)")
    max_iter: int = Field(default=20, ge=1, description="iterations of the subproblem's L-BFGS-B search per start")

    @model_validator(mode="after")
    def _radii(self) -> "GaussNewtonOptions":
        if self.radius > self.max_radius:
            raise ValueError(f"radius ({self.radius:g}) must not exceed max_radius ({self.max_radius:g})")
        return self


class GaussNewton(BudgetedOptimizer):
    """Trust region on the linearised spectra (see the module docstring)."""

    name = "gauss-newton"
    Options = GaussNewtonOptions
    uses_jacobian = True

    def _setup(self) -> None:
        self.opts_ = GaussNewtonOptions(**self.options)
        design = self.design if isinstance(self.design, DesignOptions) else DesignOptions()
        k = min(self.opts_.n_initial or 2 * self.q_ + 2, self.budget)
        self._design = make_design(design.model_copy(update={"n_initial": max(k, 2)}), self.q_)[:k]
        self.n_initial = len(self._design)
        self.radius_ = self.opts_.radius
        if self.opts_.linearise == "log" and np.any(self.bounds_[:, 0] <= 0):
            bad = int(np.flatnonzero(self.bounds_[:, 0] <= 0)[0])
            raise ConfigError(f"optimizer.options.linearise: 'log' needs positive lower bounds, parameter {bad} "
                              f"has {self.bounds_[bad, 0]:g}: use linearise: linear")
        self.centre_: np.ndarray | None = None     # u of the centre
        self.J_c = -math.inf
        self._model: tuple[np.ndarray, np.ndarray] | None = None   # (y_c, dy/dz) at the centre
        self._trial: tuple[np.ndarray, float] | None = None         # (u, predicted J) awaiting its value
        self.n_steps_ = 0
        self.n_accepted_ = 0

    # ---------------------------------------------------------------------------------------------
    def _z(self, U: np.ndarray) -> np.ndarray:
        """The coordinates the spectra are linear in: log w or w (SI), ``(..., q)``."""
        X = from_unit(np.atleast_2d(U), self.bounds_)
        return np.log(X) if self.opts_.linearise == "log" else X

    def _linearise(self) -> None:
        if self.spectra_model is None:
            raise SuspidError("gauss-newton needs the run's spectra and their Jacobian (suspid's driver sets "
                              "spectra_model); it cannot run on a bare objective")
        x_c = from_unit(self.centre_, self.bounds_)
        y, jac = self.spectra_model.jacobian(x_c)
        if self.opts_.linearise == "log":
            jac = jac * x_c            # dy/dlog w = w dy/dw
        self._model = (np.asarray(y), np.asarray(jac))

    def _predict(self, u: np.ndarray) -> float:
        y_c, jac = self._model
        dz = self._z(u)[0] - self._z(self.centre_)[0]
        return self.spectra_model.objective(y_c + jac @ dz)

    def _subproblem(self) -> tuple[np.ndarray, float]:
        """Maximise J(y_lin) in the region: L-BFGS-B from the centre and random starts (seeded)."""
        c, r = self.centre_, self.radius_
        lo, hi = np.clip(c - r, 0, 1), np.clip(c + r, 0, 1)
        rng = self.rng(5, len(self.y_))
        starts = [c] + [lo + (hi - lo) * rng.random(self.q_) for _ in range(self.opts_.starts - 1)]
        best_u, best = c, self.J_c
        for s in starts:
            res = minimize(lambda u: -self._predict(np.clip(u, lo, hi)), s, method="L-BFGS-B",
                           bounds=list(zip(lo, hi)), options={"maxiter": self.opts_.max_iter, "eps": 1e-5})
            u = np.clip(res.x, lo, hi)
            val = -float(res.fun)
            if val > best:
                best_u, best = u, val
        return best_u, best

    def _record(self, row: dict) -> None:
        """The step's own figures join its trial's details (the driver writes the trial once, after it is told)."""
        self.last_told_[-1].details.update(row, step=self.n_steps_)

    def _propose(self, n: int) -> np.ndarray:
        if not self.U_:
            return self._design
        if self.centre_ is None:
            y = np.nan_to_num(np.array(self.y_, dtype=float), nan=-np.inf)
            i = int(np.argmax(y))
            self.centre_, self.J_c = np.array(self.U_[i]), float(y[i])
        if self._model is None:
            self._linearise()
        if self.radius_ < self.opts_.min_radius:
            self.stop_reason_ = "radius_below_min"
            return np.empty((0, self.q_))
        u, predicted = self._subproblem()
        told = np.array(self.y_, dtype=float)
        spread = float(np.nanmax(told) - np.nanmin(told)) if np.isfinite(told).sum() > 1 else abs(self.J_c)
        if predicted - self.J_c <= self.opts_.tol * max(spread, 1e-300):
            self.stop_reason_ = "predicted_gain_below_tol"
            return np.empty((0, self.q_))
        self._trial = (u, predicted)
        return u[None, :]

    def _learn(self, U: np.ndarray, J: np.ndarray) -> None:
        if self._trial is None:
            return
        u, predicted = self._trial
        self._trial = None
        value = float(J[0])
        gain = predicted - self.J_c
        rho = (value - self.J_c) / gain if gain > 0 else -math.inf
        step = float(np.max(np.abs(u - self.centre_)))
        accepted = value > self.J_c
        self.n_steps_ += 1
        self._record({"J_predicted": predicted, "J_centre": self.J_c, "rho": rho if math.isfinite(rho) else None, "radius": self.radius_,
                      "accepted": accepted})
        if rho > 0.75 and step >= 0.99 * self.radius_:
            self.radius_ = min(2 * self.radius_, self.opts_.max_radius)
        elif rho < 0.25:
            self.radius_ = max(step, 1e-12) / 2
        if accepted:
            self.centre_, self.J_c = np.array(u), value
            self._model = None
            self.n_accepted_ += 1
