"""Standard analytic test functions with known answers, independent of railways.

Used by the EGO tests and ``benchmarks/bench_ego.py`` (optimisation functions)
and by the sensitivity tests (Ishigami, with analytic Sobol indices). They live
in one place so that tests and benchmarks cannot drift apart.

Every optimisation function takes ``X`` of shape ``(n_points, q)`` (or a single
point ``(q,)``) in its own box and returns ``(n_points,)`` (or a float). The
:data:`FUNCTIONS` table gives, for each, the box ``bounds (q, 2)``, the global
minimum value ``f_min`` and one minimiser ``x_min``. Values and minimisers are
those of Surjanovic & Bingham's Virtual Library of Simulation Experiments and
of Dixon & Szegő (1978), the usual references for these functions.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

__all__ = ["TestFunction", "FUNCTIONS", "branin", "goldstein_price", "hartmann3", "hartmann6",
           "ishigami", "ishigami_indices"]


def _as_2d(X: np.ndarray, q: int) -> tuple[np.ndarray, bool]:
    X = np.asarray(X, dtype=float)
    single = X.ndim == 1
    X = np.atleast_2d(X)
    if X.shape[1] != q:
        raise ValueError(f"expected points with {q} coordinates, got shape {X.shape}")
    return X, single


def _out(f: np.ndarray, single: bool):
    return float(f[0]) if single else f


def branin(X: np.ndarray):
    """Branin-Hoo on [-5, 10] x [0, 15]; three global minima, f* = 0.397887."""
    X, single = _as_2d(X, 2)
    x1, x2 = X[:, 0], X[:, 1]
    b, c, t = 5.1 / (4 * np.pi ** 2), 5 / np.pi, 1 / (8 * np.pi)
    f = (x2 - b * x1 ** 2 + c * x1 - 6) ** 2 + 10 * (1 - t) * np.cos(x1) + 10
    return _out(f, single)


def goldstein_price(X: np.ndarray):
    """Goldstein-Price on [-2, 2]^2; f* = 3 at (0, -1); values span 3 to ~1e6."""
    X, single = _as_2d(X, 2)
    x1, x2 = X[:, 0], X[:, 1]
    a = 1 + (x1 + x2 + 1) ** 2 * (19 - 14 * x1 + 3 * x1 ** 2 - 14 * x2 + 6 * x1 * x2 + 3 * x2 ** 2)
    b = 30 + (2 * x1 - 3 * x2) ** 2 * (18 - 32 * x1 + 12 * x1 ** 2 + 48 * x2 - 36 * x1 * x2
                                       + 27 * x2 ** 2)
    return _out(a * b, single)


_ALPHA = np.array([1.0, 1.2, 3.0, 3.2])
_A3 = np.array([[3.0, 10, 30], [0.1, 10, 35], [3.0, 10, 30], [0.1, 10, 35]])
_P3 = 1e-4 * np.array([[3689, 1170, 2673], [4699, 4387, 7470], [1091, 8732, 5547],
                       [381, 5743, 8828]])
_A6 = np.array([[10, 3, 17, 3.5, 1.7, 8], [0.05, 10, 17, 0.1, 8, 14],
                [3, 3.5, 1.7, 10, 17, 8], [17, 8, 0.05, 10, 0.1, 14]])
_P6 = 1e-4 * np.array([[1312, 1696, 5569, 124, 8283, 5886], [2329, 4135, 8307, 3736, 1004, 9991],
                       [2348, 1451, 3522, 2883, 3047, 6650], [4047, 8828, 8732, 5743, 1091, 381]])


def _hartmann(X: np.ndarray, A: np.ndarray, P: np.ndarray):
    X, single = _as_2d(X, A.shape[1])
    inner = np.einsum("ij,nij->ni", A, (X[:, None, :] - P[None, :, :]) ** 2)  # (n, 4)
    return _out(-np.exp(-inner) @ _ALPHA, single)


def hartmann3(X: np.ndarray):
    """Hartmann 3 on [0, 1]^3; f* = -3.86278 at (0.114614, 0.555649, 0.852547)."""
    return _hartmann(X, _A3, _P3)


def hartmann6(X: np.ndarray):
    """Hartmann 6 on [0, 1]^6; f* = -3.32237; a local minimum at -3.2032 is a known trap."""
    return _hartmann(X, _A6, _P6)


@dataclass(frozen=True)
class TestFunction:
    """A minimisation benchmark: ``func`` over ``bounds (q, 2)`` with minimum ``f_min`` at ``x_min``."""

    __test__ = False  # not a pytest test class despite its name

    name: str
    func: Callable[[np.ndarray], np.ndarray]
    bounds: np.ndarray
    f_min: float
    x_min: np.ndarray

    @property
    def q(self) -> int:
        """Number of inputs."""
        return self.bounds.shape[0]


FUNCTIONS: dict[str, TestFunction] = {
    "branin": TestFunction("branin", branin, np.array([[-5.0, 10.0], [0.0, 15.0]]),
                           0.397887357729739, np.array([np.pi, 2.275])),
    "goldstein-price": TestFunction("goldstein-price", goldstein_price,
                                    np.array([[-2.0, 2.0], [-2.0, 2.0]]), 3.0, np.array([0.0, -1.0])),
    "hartmann3": TestFunction("hartmann3", hartmann3, np.array([[0.0, 1.0]] * 3), -3.86278214782076,
                              np.array([0.114614, 0.555649, 0.852547])),
    "hartmann6": TestFunction("hartmann6", hartmann6, np.array([[0.0, 1.0]] * 6), -3.32236801141551,
                              np.array([0.20168952, 0.15001069, 0.47687398, 0.27533243,
                                        0.31165162, 0.65730054])),
}
"""Name -> :class:`TestFunction`; the minimisation benchmarks of ``benchmarks/bench_ego.py``."""


def ishigami(X: np.ndarray, a: float = 7.0, b: float = 0.1):
    """Ishigami function on [-pi, pi]^3: sin x1 + a sin^2 x2 + b x3^4 sin x1."""
    X, single = _as_2d(X, 3)
    f = np.sin(X[:, 0]) + a * np.sin(X[:, 1]) ** 2 + b * X[:, 2] ** 4 * np.sin(X[:, 0])
    return _out(f, single)


def ishigami_indices(a: float = 7.0, b: float = 0.1) -> tuple[np.ndarray, np.ndarray]:
    """Analytic first-order and total Sobol indices ``(S (3,), ST (3,))`` of :func:`ishigami`
    for independent inputs uniform on [-pi, pi]."""
    pi4 = np.pi ** 4
    v1 = 0.5 * (1 + b * pi4 / 5) ** 2
    v2 = a ** 2 / 8
    v13 = 8 * b ** 2 * np.pi ** 8 / 225
    v = v1 + v2 + v13
    return np.array([v1, v2, 0.0]) / v, np.array([v1 + v13, v2, v13]) / v
