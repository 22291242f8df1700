"""``sklearn-gp``: a Gaussian process surrogate built on scikit-learn's ``GaussianProcessRegressor``.

A second metamodel J~ (paper §3.2) from another well-kept library, so that
the surrogate is a study variable (``--set surrogate.plugin=sklearn-gp``).

Model. Inputs scaled to ``[0, 1]^q`` (by ``bounds`` when given, else by the
data's min and max per column), outputs standardised; kernel
``C · Matérn_{5/2}(ARD) + White``: an amplitude C, one length-scale per input
and a white-noise level fitted with them (a small nugget that keeps the fit
well conditioned; the predictions leave it out). Hyperparameters maximise
the log marginal likelihood by scikit-learn's L-BFGS-B from the default start
and ``n_restarts`` random ones, drawn from a generator seeded by
``(seed, n_points)``, so a fit depends only on the data and the options; the
run's seed reaches ``seed`` like the other plugins' (``suspid.config``).

Predictions are noise-free (the latent f, as EI needs): mean and variance in
the units of y, the white-noise level taken out of the variance. No
gradients: EGO then searches EI without them. Fitted attributes:
``lengthscales_ (q,)`` in the units of X, ``hyperparameters_`` (for the run
ledger), ``model_`` (the fitted regressor, on scaled data).
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator
from sklearn.exceptions import ConvergenceWarning
from sklearn.gaussian_process import GaussianProcessRegressor
from sklearn.gaussian_process.kernels import ConstantKernel, Matern, WhiteKernel

from suspid import hookimpl
from suspid.infra.threads import single_blas_thread
from suspid.interfaces import Surrogate
from suspid.options import parse_options
from suspid.plugins.surrogates._common import check_data, scaling


class SklearnGPOptions(BaseModel):
    """Options of ``sklearn-gp`` (``surrogate.options``); variances relative to var(y), length-scales
    in units of the scaled inputs (the box is 1)."""

    model_config = ConfigDict(extra="forbid")

    n_restarts: int = Field(default=5, ge=0, description="random starts of the optimiser besides the default")
    seed: int = Field(default=0, ge=0, description="seeds the random starts (derived from the run seed)")
    lengthscale_bounds: tuple[float, float] = (1e-3, 2.0)
    variance_bounds: tuple[float, float] = (1e-3, 1e3)
    noise_bounds: tuple[float, float] = (1e-10, 1e-2)
    bounds: list[tuple[float, float]] | None = None

    @model_validator(mode="after")
    def _check_intervals(self) -> "SklearnGPOptions":
        for key in ("noise_bounds", "lengthscale_bounds", "variance_bounds"):
            lo, hi = getattr(self, key)
            if not (0 < lo < hi):
                raise ValueError(f"{key} must satisfy 0 < lower < upper, got ({lo}, {hi})")
        return self


class SklearnGP(Surrogate):
    """Gaussian process regression (scikit-learn): Matérn 5/2 ARD + white noise, noise-free predictions."""

    name = "sklearn-gp"
    Options = SklearnGPOptions

    def fit(self, X: np.ndarray, y: np.ndarray) -> "SklearnGP":
        """Fit to ``X (n_points, q)`` and ``y (n_points,)``; returns ``self``.

        :raises ValueError: wrong shapes, fewer than 2 points, or non-finite values.
        :raises ConfigError: invalid options.
        """
        opts = parse_options(SklearnGPOptions, self.options, "surrogate.options")
        X, y = check_data(self.name, X, y)
        self.x_lower_, self.x_range_, self.y_mean_, self.y_std_ = scaling(self.name, X, y, opts.bounds)
        n, q = X.shape
        kernel = (ConstantKernel(1.0, opts.variance_bounds)
                  * Matern(np.full(q, 0.5), opts.lengthscale_bounds, nu=2.5)
                  + WhiteKernel(max(1e-6, opts.noise_bounds[0]), opts.noise_bounds))
        seed = int(np.random.default_rng([opts.seed, n]).integers(2 ** 31))
        self.model_ = GaussianProcessRegressor(kernel, normalize_y=False, n_restarts_optimizer=opts.n_restarts,
                                               random_state=np.random.RandomState(seed))
        with single_blas_thread(), warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)  # a bound reached is a fit, not a failure
            self.model_.fit((X - self.x_lower_) / self.x_range_, (y - self.y_mean_) / self.y_std_)
        self._record()
        return self

    def _record(self) -> None:
        k = self.model_.kernel_
        variance, noise = float(k.k1.k1.constant_value), float(k.k2.noise_level)
        ls = np.atleast_1d(k.k1.k2.length_scale)
        self.noise_level_ = noise
        self.lengthscales_ = ls * self.x_range_
        self.hyperparameters_: dict[str, Any] = {
            "kernel": "matern52", "lengthscales": [float(v) for v in self.lengthscales_],
            "lengthscales_scaled": [float(v) for v in ls], "variance": variance * self.y_std_ ** 2,
            "noise_variance": noise * self.y_std_ ** 2, "y_mean": self.y_mean_, "y_std": self.y_std_,
            "log_likelihood": float(self.model_.log_marginal_likelihood_value_)}

    def predict(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Noise-free mean ``(n_points,)`` in units of y and variance ``(n_points,)`` in y², clipped at 0.

        :raises RuntimeError: before :meth:`fit`; ``ValueError``: ``X`` is not ``(n_points, q)``.
        """
        if not hasattr(self, "model_"):
            raise RuntimeError("sklearn-gp: call fit() before predict()")
        X = np.asarray(X, dtype=float)
        if X.ndim != 2 or X.shape[1] != self.x_range_.shape[0]:
            raise ValueError(f"sklearn-gp: X must have shape (n_points, {self.x_range_.shape[0]}), got {X.shape}")
        with single_blas_thread():
            mean, std = self.model_.predict((X - self.x_lower_) / self.x_range_, return_std=True)
        var = np.maximum(std ** 2 - self.noise_level_, 0.0)  # the latent f: without the white noise
        return mean * self.y_std_ + self.y_mean_, var * self.y_std_ ** 2


@hookimpl
def suspid_register_surrogates(register) -> None:
    """Register :class:`SklearnGP` as ``sklearn-gp``."""
    register(SklearnGP)
