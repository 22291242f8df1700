"""Global sensitivity of J computed on the metamodel (for the identifiability report).

Two measures, both cheap once the surrogate is fitted:

- Sobol' indices of the surrogate mean, for independent inputs uniform on the
  parameter box: first-order ``S_i`` (share of Var J explained by w_i alone)
  and total ``ST_i`` (share involving w_i, interactions included). Sampling
  scheme of Saltelli (2010): two ``(N, q)`` matrices ``A`` and ``B`` from one
  scrambled Sobol' sequence of dimension 2q, and ``A_B^(i)`` (A with column i
  from B); first order by Saltelli's estimator
  ``mean(f(B) (f(A_B^i) - f(A))) / V``, total by Jansen's
  ``mean((f(A) - f(A_B^i))^2) / (2 V)``. N (q + 2) predictions of the mean.
  Optional bootstrap percentile intervals (seeded).
- The fitted length-scales of an ARD kernel, when the surrogate exposes
  ``lengthscales_`` (relative to the box width): a short length-scale marks a
  parameter that J depends on strongly; a length-scale at its upper bound, a
  parameter J hardly sees (not identifiable from J, as component 2 of the
  paper's Table 1).

A parameter with ``ST_i`` near 0 cannot be identified from J.

Public API: :func:`sobol_indices` (any vectorised function on ``[0, 1]^q``),
:func:`surrogate_sensitivity` (a fitted surrogate), :class:`SensitivityResult`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Sequence

import numpy as np
from scipy.stats import qmc

from suspid.errors import ConfigError
from suspid.optimize.design import from_unit

__all__ = ["SensitivityResult", "sobol_indices", "surrogate_sensitivity"]


@dataclass
class SensitivityResult:
    """Sobol' indices (and length-scales) of J over the parameter box.

    :ivar first_order: ``(q,)`` S_i.
    :ivar total: ``(q,)`` ST_i.
    :ivar variance: Var J over the box (units of J²).
    :ivar first_order_ci, total_ci: ``(q, 2)`` bootstrap percentile intervals, or None.
    :ivar lengthscales: ``(q,)`` fitted ARD length-scales relative to the box
        width (1 = the whole interval), or None when the surrogate has none.
    :ivar names: parameter names, or None.
    :ivar n: base sample size N (N (q + 2) evaluations).
    """

    first_order: np.ndarray
    total: np.ndarray
    variance: float
    first_order_ci: np.ndarray | None = None
    total_ci: np.ndarray | None = None
    lengthscales: np.ndarray | None = None
    names: list[str] | None = None
    n: int = 0

    def as_dict(self) -> dict[str, Any]:
        """JSON-friendly form: one entry per parameter (keyed by name, or ``w<i>``)."""
        names = self.names or [f"w{i}" for i in range(self.first_order.shape[0])]
        rows = {}
        for i, name in enumerate(names):
            row = {"first_order": float(self.first_order[i]), "total": float(self.total[i])}
            if self.first_order_ci is not None:
                row["first_order_ci"] = [float(v) for v in self.first_order_ci[i]]
                row["total_ci"] = [float(v) for v in self.total_ci[i]]
            if self.lengthscales is not None:
                row["lengthscale"] = float(self.lengthscales[i])
            rows[name] = row
        return {"variance": float(self.variance), "n": int(self.n), "parameters": rows}


def _estimate(fA: np.ndarray, fB: np.ndarray, fAB: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """(S, ST, V) from ``fA (N,)``, ``fB (N,)``, ``fAB (q, N)``."""
    V = float(np.var(np.concatenate([fA, fB]), ddof=1))
    if not V > 0:
        q = fAB.shape[0]
        return np.zeros(q), np.zeros(q), 0.0
    S = np.mean(fB[None, :] * (fAB - fA[None, :]), axis=1) / V
    ST = 0.5 * np.mean((fA[None, :] - fAB) ** 2, axis=1) / V
    return S, ST, V


def sobol_indices(func: Callable[[np.ndarray], np.ndarray], q: int, *, n: int = 4096, seed: int = 0,
                  n_bootstrap: int = 0, confidence: float = 0.95,
                  names: Sequence[str] | None = None) -> SensitivityResult:
    """Sobol' first-order and total indices of ``func`` for inputs uniform on ``[0, 1]^q``.

    :param func: vectorised, ``func(U (m, q)) -> (m,)``.
    :param q: number of inputs.
    :param n: base sample size N (rounded up to a power of 2 for the Sobol'
        sequence); cost N (q + 2) evaluations.
    :param seed: seeds the scrambling and the bootstrap.
    :param n_bootstrap: bootstrap resamples for the intervals (0: none).
    :param confidence: level of the percentile intervals.
    :param names: parameter names, ``(q,)``.
    :raises ConfigError: q < 1, n < 2, or names of the wrong length.
    """
    if q < 1 or n < 2:
        raise ConfigError(f"sensitivity needs q >= 1 and n >= 2, got q={q}, n={n}")
    if names is not None and len(names) != q:
        raise ConfigError(f"{len(names)} names given for q={q} parameters")
    rng = np.random.default_rng(seed)
    m = int(np.ceil(np.log2(n)))
    AB = qmc.Sobol(2 * q, scramble=True, rng=rng).random_base2(m)
    A, B = AB[:, :q], AB[:, q:]
    N = A.shape[0]
    mixed = np.repeat(A[None, :, :], q, axis=0)  # (q, N, q)
    for i in range(q):
        mixed[i, :, i] = B[:, i]
    values = np.asarray(func(np.vstack([A, B, mixed.reshape(q * N, q)])), dtype=float).reshape(-1)
    if values.shape[0] != (q + 2) * N:
        raise ValueError(f"func returned {values.shape[0]} values for {(q + 2) * N} points")
    fA, fB, fAB = values[:N], values[N:2 * N], values[2 * N:].reshape(q, N)
    S, ST, V = _estimate(fA, fB, fAB)
    S_ci = ST_ci = None
    if n_bootstrap > 0:
        boot_S, boot_ST = np.empty((n_bootstrap, q)), np.empty((n_bootstrap, q))
        for b in range(n_bootstrap):
            idx = rng.integers(0, N, size=N)
            boot_S[b], boot_ST[b], _ = _estimate(fA[idx], fB[idx], fAB[:, idx])
        lo, hi = 50 * (1 - confidence), 50 * (1 + confidence)
        S_ci = np.percentile(boot_S, [lo, hi], axis=0).T
        ST_ci = np.percentile(boot_ST, [lo, hi], axis=0).T
    return SensitivityResult(first_order=S, total=ST, variance=V, first_order_ci=S_ci,
                             total_ci=ST_ci, names=list(names) if names is not None else None, n=N)


def surrogate_sensitivity(surrogate, q: int, *, bounds=None, n: int = 4096, seed: int = 0,
                          n_bootstrap: int = 0, names: Sequence[str] | None = None,
                          batch: int = 8192) -> SensitivityResult:
    """Sobol' indices of a fitted surrogate's mean, and its length-scales.

    :param surrogate: a fitted :class:`suspid.interfaces.Surrogate`; its inputs
        are in ``[0, 1]^q`` (as EGO fits it) unless ``bounds`` is given.
    :param q: number of parameters.
    :param bounds: ``(q, 2)`` the box the surrogate's inputs live in (SI), or
        None for the unit cube.
    :param n, seed, n_bootstrap, names: as in :func:`sobol_indices`.
    :param batch: predictions per call of ``surrogate.predict``.
    :returns: a :class:`SensitivityResult` with ``lengthscales`` relative to
        the box width when the surrogate has ``lengthscales_``.
    """
    b = np.array([[0.0, 1.0]] * q) if bounds is None else np.asarray(bounds, dtype=float)
    if b.shape != (q, 2):
        raise ConfigError(f"bounds must have shape ({q}, 2), got {b.shape}")

    def mean(U: np.ndarray) -> np.ndarray:
        X = from_unit(U, b)
        return np.concatenate([surrogate.predict(X[i:i + batch])[0]
                               for i in range(0, X.shape[0], batch)])

    result = sobol_indices(mean, q, n=n, seed=seed, n_bootstrap=n_bootstrap, names=names)
    ls = surrogate.lengthscales_
    if ls is not None:
        result.lengthscales = np.asarray(ls, dtype=float).reshape(-1) / (b[:, 1] - b[:, 0])
    return result
