"""``gpy-kriging``: a Kriging (Gaussian process regression) surrogate built on GPy.

The metamodel J~ of paper §3.2, registered as surrogate ``gpy-kriging``.

Model. Zero-mean GP on standardised outputs ``(y - mean) / std`` with an ARD
kernel on inputs scaled to ``[0, 1]^q`` (by ``Options.bounds`` when given,
else by the data's min and max per column): Matérn 5/2 by default (``kernel:
matern52``) or squared exponential (``kernel: rbf``). Predictions are
noise-free (the latent f, not y), in the units of ``y``, as EI needs.

Noise (``noise:``):

- ``fixed`` (default): the Gaussian noise variance is fixed at
  ``noise_variance`` (1e-10 of the output variance): interpolating Kriging of a
  deterministic J;
- ``nugget``: fixed at ``nugget`` (1e-6): a regularising nugget for a J with
  small numerical noise; the surrogate then no longer interpolates exactly;
- ``estimated``: a hyperparameter fitted with the others, within
  ``noise_bounds``, for a noisy J.

Hyperparameters (kernel variance, ARD length-scales, and the noise when
estimated) maximise the log marginal likelihood by L-BFGS-B from several
starts: on a cold fit, a default start and ``n_restarts`` random ones; on a
warm fit (``warm_start``, the same instance refitted, as EGO does each
iteration), the previous optimum and ``n_restarts_warm`` random ones. Random
starts are drawn log-uniformly from a generator seeded by ``(seed, n_points)``,
so a fit depends only on the data, the options and the fits before it. A start that fails (linear algebra, overflow, anything
GPy raises) is counted in ``n_failed_restarts_`` and skipped; if all fail, the
jitter is raised and the fit tried again; the last resort keeps the default
hyperparameters. Nothing in the fit can kill an EGO run.

Global random state. The restarts are ours, not GPy's ``optimize_restarts``
(which draws from numpy's global generator). As a guard for anything inside
GPy or paramz that still draws from it, every GPy call runs inside a context
that seeds numpy's global ``RandomState`` from our seeded generator and
restores the caller's state afterwards, so a fit neither depends on nor
disturbs the caller's global random state.

Conditioning. Near-duplicate points (scaled distance < ``duplicate_tol``) are
reported with a :class:`ConditioningWarning`; if their values disagree, the
noise floor is raised to the variance of the disagreement. After the fit the
condition number of ``K + σ²I`` is checked; above ``max_condition`` the jitter
(added to σ²) is raised just enough, and raised further if the Cholesky
factorisation still fails. A jitter above ``jitter_warning`` (1e-6 of the
output variance, enough to change predictions) comes with a warning; smaller
ones, routine for smooth kernels on clustered EGO points, are only recorded
in ``hyperparameters_["jitter_standardised"]``. Duplicates never crash.

Predictions. GPy fits the hyperparameters; the posterior (Cholesky factor,
α) and the predictions with their gradients are computed here in numpy with
the same formulas, which is ~100 times faster than GPy's ``predict`` for the
single-point calls of the EI search and exact at the data points.

Fitted attributes: ``lengthscales_ (q,)`` in the units of ``X``,
``variance_`` and ``noise_variance_`` in units of ``y``², ``jitter_``
(standardised), ``log_likelihood_``, ``n_failed_restarts_``,
``hyperparameters_`` (a JSON-friendly dict for the run ledger), ``model_``
(the GPy model, on scaled data).
"""

from __future__ import annotations

import warnings
from contextlib import contextmanager
from typing import Any, Iterator, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator
from scipy.linalg import cho_solve, cholesky, solve_triangular
from scipy.spatial.distance import cdist, pdist, squareform

from suspid import hookimpl
from suspid.options import parse_options
from suspid.interfaces import Surrogate
from suspid.infra.threads import single_blas_thread
from suspid.plugins.surrogates._common import check_data, scaling

__all__ = ["GPyKriging", "GPyKrigingOptions", "ConditioningWarning", "suspid_register_surrogates"]


class ConditioningWarning(UserWarning):
    """Near-duplicate points or an ill-conditioned covariance: the jitter was raised."""


class GPyKrigingOptions(BaseModel):
    """Options of ``gpy-kriging`` (the ``surrogate.options`` config section).

    Variances (``noise_variance``, ``nugget``, ``noise_bounds``,
    ``variance_bounds``) are relative to the variance of the standardised
    outputs (i.e. in units of var(y)); length-scale bounds are in units of the
    scaled inputs (the box or data range is 1). The upper length-scale bound
    2 (twice the range, DiceKriging's default) matters for EGO: beyond it the
    kernel is nearly flat over the box anyway, and unbounded length-scales let
    a model fitted to points clustered in a flat local basin declare a
    direction irrelevant and stop exploring it (seen on Hartmann 6).
    """

    model_config = ConfigDict(extra="forbid")

    kernel: Literal["matern52", "rbf"] = "matern52"
    noise: Literal["fixed", "nugget", "estimated"] = "fixed"
    noise_variance: float = Field(default=1e-10, gt=0, le=1)
    nugget: float = Field(default=1e-6, gt=0, le=1)
    noise_bounds: tuple[float, float] = (1e-10, 1.0)
    n_restarts: int = Field(default=5, ge=0)
    n_restarts_warm: int = Field(default=1, ge=0)
    seed: int = 0
    warm_start: bool = True
    lengthscale_bounds: tuple[float, float] = (1e-3, 2.0)
    variance_bounds: tuple[float, float] = (1e-3, 1e3)
    max_iters: int = Field(default=1000, ge=1)
    max_condition: float = Field(default=1e12, gt=10)
    jitter_warning: float = Field(default=1e-6, ge=0)
    duplicate_tol: float = Field(default=1e-8, ge=0)
    bounds: list[tuple[float, float]] | None = None

    @model_validator(mode="after")
    def _check_intervals(self) -> "GPyKrigingOptions":
        for key in ("noise_bounds", "lengthscale_bounds", "variance_bounds"):
            lo, hi = getattr(self, key)
            if not (0 < lo < hi):
                raise ValueError(f"{key} must satisfy 0 < lower < upper, got ({lo}, {hi})")
        for i, (lo, hi) in enumerate(self.bounds or []):
            if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
                raise ValueError(f"bounds[{i}] = ({lo}, {hi}) is not a finite interval")
        return self


@contextmanager
def _global_numpy_seed(seed: int) -> Iterator[None]:
    """Seed numpy's legacy global generator, and restore the caller's state on exit."""
    state = np.random.get_state()
    np.random.seed(seed)
    try:
        yield
    finally:
        np.random.set_state(state)


class GPyKriging(Surrogate):
    """Kriging surrogate (GPy): ARD Matérn 5/2 or RBF kernel, noise-free predictions.

    ``GPyKriging(**options)`` stores the options (see :class:`GPyKrigingOptions`);
    they are validated at :meth:`fit`.
    """

    name = "gpy-kriging"
    Options = GPyKrigingOptions

    # -- options -----------------------------------------------------------------
    def _opts(self) -> GPyKrigingOptions:
        return parse_options(GPyKrigingOptions, self.options, "surrogate.options")

    # -- fitting -----------------------------------------------------------------
    def fit(self, X: np.ndarray, y: np.ndarray) -> "GPyKriging":
        """Fit to ``X (n_points, q)`` and ``y (n_points,)``; returns ``self``.

        :raises ValueError: wrong shapes, fewer than 2 points, or non-finite values.
        :raises ConfigError: invalid options.
        """
        import GPy  # imported here so that listing plugins does not pay for it

        opts = self._opts()
        X, y = check_data(self.name, X, y)
        self.x_lower_, self.x_range_, self.y_mean_, self.y_std_ = scaling(self.name, X, y, opts.bounds)
        Xs = (X - self.x_lower_) / self.x_range_
        ys = ((y - self.y_mean_) / self.y_std_)[:, None]
        # small matrices: OpenBLAS threads only contend (suspid.infra.threads)
        with single_blas_thread():
            self._fit(GPy, Xs, ys, opts)
        return self

    def _fit(self, GPy, Xs: np.ndarray, ys: np.ndarray, opts: GPyKrigingOptions) -> None:
        n, q = Xs.shape
        rng = np.random.default_rng([opts.seed, n])
        self.jitter_ = 0.0
        noise_floor = {"fixed": opts.noise_variance, "nugget": opts.nugget,
                       "estimated": opts.noise_bounds[0]}[opts.noise]
        noise_floor = max(noise_floor, self._duplicate_noise(Xs, ys[:, 0], opts))

        kern_cls = GPy.kern.Matern52 if opts.kernel == "matern52" else GPy.kern.RBF
        previous = getattr(self, "_start_", None) if opts.warm_start else None
        if previous is not None and previous[1].shape != (q,):
            previous = None

        self.n_failed_restarts_ = 0
        model = None
        for attempt in range(6):  # raise the noise floor until some start succeeds
            with _global_numpy_seed(int(rng.integers(2 ** 32))), np.errstate(all="ignore"), \
                    warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)
                model, failed = self._optimise(GPy, kern_cls, Xs, ys, opts, noise_floor, previous, rng)
            self.n_failed_restarts_ += failed
            if model is not None:
                break
            noise_floor = min(max(noise_floor * 100.0, 1e-8), 1.0)
            warnings.warn(f"gpy-kriging: every hyperparameter start failed ({n} points); noise "
                          f"floor raised to {noise_floor:.3g} (standardised) and trying again",
                          ConditioningWarning, stacklevel=3)
        if model is None:  # last resort: default hyperparameters, no optimisation
            warnings.warn("gpy-kriging: hyperparameter optimisation failed; keeping the default "
                          "hyperparameters", ConditioningWarning, stacklevel=3)
            model = self._build(GPy, kern_cls, Xs, ys, opts, noise_floor)
            self.log_likelihood_ = float("nan")
        self.model_ = model
        self._posterior(opts, ys[:, 0])
        self._record(opts)

    def _build(self, GPy, kern_cls, Xs, ys, opts, noise, start=None):
        q = Xs.shape[1]
        kern = kern_cls(q, ARD=True, variance=1.0, lengthscale=np.full(q, 0.5))
        kern.lengthscale.constrain_bounded(*opts.lengthscale_bounds, warning=False)
        kern.variance.constrain_bounded(*opts.variance_bounds, warning=False)
        model = GPy.models.GPRegression(Xs, ys, kern, noise_var=noise)
        if opts.noise == "estimated":
            lo, hi = max(opts.noise_bounds[0], noise), max(opts.noise_bounds[1], 10 * noise)
            model.likelihood.variance.constrain_bounded(lo, hi, warning=False)
        else:
            model.likelihood.variance.constrain_fixed(noise, warning=False)
        if start is not None:
            variance, lengthscale, noise_start = start
            kern.variance[:] = np.clip(variance, *opts.variance_bounds)
            kern.lengthscale[:] = np.clip(lengthscale, *opts.lengthscale_bounds)
            if opts.noise == "estimated":
                model.likelihood.variance[:] = np.clip(noise_start, lo, hi)
        return model

    def _starts(self, q, opts, noise_floor, previous, rng):
        """Cold fit: a default start and ``n_restarts`` random ones; warm fit: the previous
        optimum and ``n_restarts_warm`` random ones."""
        lo_l, hi_l = opts.lengthscale_bounds
        if previous is not None:
            starts, n_random = [previous], opts.n_restarts_warm
        else:
            starts = [(1.0, np.full(q, np.clip(0.5, lo_l, hi_l)), max(noise_floor, 1e-6))]
            n_random = opts.n_restarts
        for _ in range(n_random):
            ls = np.exp(rng.uniform(np.log(max(lo_l, 0.05)), np.log(min(hi_l, 5.0)), size=q))
            var = float(np.exp(rng.uniform(np.log(0.1), np.log(10.0))))
            lo_n, hi_n = opts.noise_bounds
            nz = float(np.exp(rng.uniform(np.log(max(lo_n, noise_floor)), np.log(max(hi_n, noise_floor)))))
            starts.append((var, ls, nz))
        return starts

    def _optimise(self, GPy, kern_cls, Xs, ys, opts, noise_floor, previous, rng):
        """Best model over the starts, and the number of failed starts."""
        best, best_ll, failed = None, -np.inf, 0
        for start in self._starts(Xs.shape[1], opts, noise_floor, previous, rng):
            try:
                model = self._build(GPy, kern_cls, Xs, ys, opts, noise_floor, start)
                model.optimize(optimizer="lbfgsb", max_iters=opts.max_iters, messages=False)
                ll = float(model.log_likelihood())
            except Exception:  # noqa: BLE001 -- a failed start must not end the run
                failed += 1
                continue
            if not np.isfinite(ll):
                failed += 1
                continue
            if ll > best_ll:
                best, best_ll = model, ll
        if best is not None:
            self.log_likelihood_ = best_ll
        return best, failed

    def _duplicate_noise(self, Xs: np.ndarray, ys: np.ndarray, opts: GPyKrigingOptions) -> float:
        """Warn about near-duplicate points; the noise variance their disagreement implies."""
        if Xs.shape[0] < 2:
            return 0.0
        D = squareform(pdist(Xs))
        iu = np.triu_indices_from(D, k=1)
        close = D[iu] <= opts.duplicate_tol
        if not np.any(close):
            return 0.0
        i, j = iu[0][close], iu[1][close]
        disagreement = float(np.max((ys[i] - ys[j]) ** 2) / 2.0)
        noise = min(disagreement, 1.0)
        msg = (f"gpy-kriging: {close.sum()} pair(s) of near-duplicate points (scaled distance "
               f"<= {opts.duplicate_tol:g}, first: rows {i[0]} and {j[0]})")
        if noise > 0:
            msg += f"; their values differ, noise floor raised to {noise:.3g} (standardised)"
        warnings.warn(msg, ConditioningWarning, stacklevel=4)
        return noise

    def _posterior(self, opts: GPyKrigingOptions, ys: np.ndarray) -> None:
        """Cholesky factor L of K + (σ² + jitter) I and α = (K + ...)⁻¹ y, with our kernel code.

        Predictions use the same kernel code as this factorisation, so that the
        variance vanishes at the data even when K is nearly singular (mixing
        GPy's K with ours loses ~cond(K) * 1e-16 there). The jitter is raised
        until cond(K + (σ² + jitter) I) <= ``max_condition`` and the Cholesky
        factorisation succeeds, with a :class:`ConditioningWarning`.
        """
        model = self.model_
        self._Xs = np.asarray(model.X, dtype=float)
        self._ls = np.array(model.kern.lengthscale, dtype=float).reshape(-1)
        self._kvar = float(model.kern.variance[0])
        self._matern = opts.kernel == "matern52"
        noise = float(model.likelihood.variance[0])
        K, _, _ = self._kernel(self._Xs)
        lam = np.linalg.eigvalsh(K)
        lmin, lmax = float(lam[0]) + noise, float(lam[-1]) + noise
        c = opts.max_condition
        jitter = 0.0
        if not (lmin > 0 and lmax <= c * lmin):
            jitter = 1.01 * (lmax - c * lmin) / (c - 1.0)
        if jitter > opts.jitter_warning:
            warnings.warn(f"gpy-kriging: ill-conditioned covariance ({K.shape[0]} points, "
                          f"condition {lmax / max(lmin, 1e-300):.2g}); jitter {jitter:.3g} added "
                          f"to the noise variance (standardised)", ConditioningWarning, stacklevel=4)
        n = K.shape[0]
        while True:
            try:
                L = cholesky(K + (noise + jitter) * np.eye(n), lower=True)
                break
            except np.linalg.LinAlgError:
                jitter = max(10.0 * jitter, 1e-12 * max(lmax, 1.0))
                warnings.warn(f"gpy-kriging: Cholesky factorisation failed; jitter raised to "
                              f"{jitter:.3g} (standardised)", ConditioningWarning, stacklevel=4)
        self._L = L
        self._alpha = cho_solve((L, True), ys)
        self.jitter_ = float(jitter)
        if jitter > 0:  # keep the GPy model consistent with what we predict with
            with _global_numpy_seed(0), np.errstate(all="ignore"):
                if opts.noise == "estimated":
                    model.likelihood.variance.unconstrain()
                model.likelihood.variance.constrain_fixed(noise + jitter, warning=False)
                self.log_likelihood_ = float(model.log_likelihood())

    def _record(self, opts: GPyKrigingOptions) -> None:
        model = self.model_
        ls_s, var_s = self._ls, self._kvar
        noise_s = float(model.likelihood.variance[0])
        self._start_ = (var_s, ls_s.copy(), noise_s - self.jitter_)
        self.lengthscales_ = ls_s * self.x_range_
        self.variance_ = var_s * self.y_std_ ** 2
        self.noise_variance_ = noise_s * self.y_std_ ** 2
        self.hyperparameters_: dict[str, Any] = {
            "kernel": opts.kernel,
            "noise_mode": opts.noise,
            "lengthscales": [float(v) for v in self.lengthscales_],
            "lengthscales_scaled": [float(v) for v in ls_s],
            "variance": float(self.variance_),
            "noise_variance": float(self.noise_variance_),
            "jitter_standardised": float(self.jitter_),
            "y_mean": self.y_mean_,
            "y_std": self.y_std_,
            "log_likelihood": float(self.log_likelihood_),
            "n_failed_restarts": int(self.n_failed_restarts_),
        }

    # -- prediction --------------------------------------------------------------
    def _scaled(self, X: np.ndarray) -> np.ndarray:
        if not hasattr(self, "model_"):
            raise RuntimeError("gpy-kriging: call fit() before predict()")
        X = np.asarray(X, dtype=float)
        if X.ndim != 2 or X.shape[1] != self.x_range_.shape[0]:
            raise ValueError(f"gpy-kriging: X must have shape (n_points, {self.x_range_.shape[0]}), "
                             f"got {X.shape}")
        return (X - self.x_lower_) / self.x_range_

    def _kernel(self, Xs: np.ndarray, with_grad: bool = False):
        """Cross-covariances ``k (m, n)`` between scaled points and the data; with
        ``with_grad`` also ``g = (dk/dr) / r (m, n)`` and ``diff (m, n, q)``."""
        ls, v = self._ls, self._kvar
        Z = self._Xs / ls
        if with_grad:
            diff = Xs[:, None, :] - self._Xs[None, :, :]
            r = np.sqrt(np.sum((diff / ls) ** 2, axis=-1))
        else:
            diff = None
            r = cdist(Xs / ls, Z)
        if self._matern:
            s5r = np.sqrt(5.0) * r
            e = np.exp(-s5r)
            k = v * (1.0 + s5r + s5r ** 2 / 3.0) * e
            g = -5.0 / 3.0 * v * (1.0 + s5r) * e if with_grad else None
        else:
            k = v * np.exp(-0.5 * r ** 2)
            g = -k if with_grad else None
        return k, g, diff

    def predict(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Noise-free mean and variance of the latent function at ``X (n_points, q)``.

        The GP formulas of GPy's ``predict_noiseless`` with GPy's fitted
        hyperparameters, in plain numpy from our Cholesky factor L of
        K + σ²I: mean = k_x·α, var = k(x, x) - |L⁻¹ k_x|² (fast for the many
        small calls of the EI search, and exact at the data, see ``_posterior``).

        :returns: ``mean (n_points,)`` in units of y and ``variance (n_points,)``
            in units of y², clipped at 0.
        """
        Xs = self._scaled(X)
        k, _, _ = self._kernel(Xs)
        mean = k @ self._alpha
        A = solve_triangular(self._L, k.T, lower=True)  # (n, m)
        var = self._kvar - np.einsum("ij,ij->j", A, A)
        return mean * self.y_std_ + self.y_mean_, np.maximum(var, 0.0) * self.y_std_ ** 2

    def predict_gradients(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Gradients of the noise-free mean and variance w.r.t. ``X (n_points, q)``.

        ∂k(x, x_i)/∂x_d = g(r_i) (x_d - x_id) / ℓ_d², with g = (dk/dr) / r;
        ∂mean = Σ_i α_i ∂k_i and ∂var = -2 ((K + σ²I)⁻¹ k_x)·∂k_x (k(x, x) is constant).

        :returns: ``dmean (n_points, q)`` in y/[X] and ``dvariance (n_points, q)`` in y²/[X].
        """
        Xs = self._scaled(X)
        k, g, diff = self._kernel(Xs, with_grad=True)
        dk = g[:, :, None] * diff / self._ls ** 2  # (m, n, q)
        dmean = np.einsum("mnq,n->mq", dk, self._alpha)
        Wk = cho_solve((self._L, True), k.T)  # (n, m)
        dvar = -2.0 * np.einsum("mnq,nm->mq", dk, Wk)
        return (dmean * self.y_std_ / self.x_range_,
                dvar * self.y_std_ ** 2 / self.x_range_)


@hookimpl
def suspid_register_surrogates(register) -> None:
    """Register :class:`GPyKriging` as ``gpy-kriging``."""
    register(GPyKriging)
