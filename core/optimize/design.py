"""Initial experimental designs for EGO (paper §3.2: m0 space-filling points).

A design is a function ``(n, q, rng, options) -> X`` returning ``(n, q)``
points of the unit cube ``[0, 1]^q``; :data:`DESIGNS` maps the names accepted
by the ``design:`` config section to them:

- ``maximin-lhs`` (default): a Latin hypercube optimised for the maximin
  distance by the Enhanced Stochastic Evolutionary algorithm (ESE) of Jin,
  Chen & Sudjianto (2005) on the Morris-Mitchell criterion φ_p. Points sit at
  the centres of the LHS cells. Yardstick, unit cube, 50 points in 5
  dimensions: best-of-1000 random LHS give a minimum pairwise distance of
  about 0.30; this implementation gives about 0.49 (≥ 0.45 is tested);
- ``sobol``: a scrambled Sobol' sequence (``scipy.stats.qmc.Sobol``);
- ``lhs-cd``: a random Latin hypercube improved on the centred discrepancy
  (``scipy.stats.qmc.LatinHypercube(optimization="random-cd")``);
- ``lhs``: a plain random Latin hypercube (a baseline, not space-filling).

Designs in SI units come from :func:`from_unit` with the parameter box
``bounds (q, 2)`` (lower, upper); :func:`to_unit` is its inverse.
:func:`min_distance` reports the smallest pairwise distance of a design.

Public API: :class:`DesignOptions`, :func:`make_design`, :func:`default_n_initial`,
:func:`maximin_lhs`, :func:`min_distance`, :func:`phi_p`, :func:`to_unit`,
:func:`from_unit`, :func:`check_bounds`, :data:`DESIGNS`.
"""

from __future__ import annotations

import warnings
from typing import Callable

import numpy as np
from pydantic import BaseModel, ConfigDict, Field
from scipy.spatial.distance import pdist
from scipy.stats import qmc

from suspid.errors import ConfigError

__all__ = ["DesignOptions", "DESIGNS", "make_design", "default_n_initial", "maximin_lhs",
           "min_distance", "phi_p", "to_unit", "from_unit", "check_bounds"]


class DesignOptions(BaseModel):
    """The ``design:`` config section: how the m0 initial points are chosen.

    :ivar method: a name in :data:`DESIGNS`.
    :ivar n_initial: m0, the number of initial points; ``None`` uses
        :func:`default_n_initial` (``min(2^q, 10 q)``, at least 4).
    :ivar seed: seed of the design's random generator.
    :ivar iterations: outer iterations of the ESE optimiser (``maximin-lhs``).
    :ivar p: exponent of the Morris-Mitchell criterion φ_p (``maximin-lhs``);
        large p approaches the maximin distance.
    """

    model_config = ConfigDict(extra="forbid")

    method: str = "maximin-lhs"
    n_initial: int | None = Field(default=None, ge=2, le=20_000,
                                  description="m0; a Kriging model of more points is beyond reach (O(m0^3))")
    seed: int = Field(default=0, ge=0, lt=2**63, description="seed of the design's random draws")
    iterations: int = Field(default=100, ge=0)
    p: float = Field(default=50.0, gt=0)


def default_n_initial(q: int) -> int:
    """Rule for m0 when the config does not give it: ``min(2^q, 10 q)``, at least 4.

    q = 1..7 gives 4, 4, 8, 16, 32, 60, 70. In low dimension the Kriging model
    learns the function quickly from EI points, and each initial point spent is
    an EI point lost: Branin (q = 2) and Hartmann 3 need the fewest evaluations
    with 4 and 8 initial points. In higher dimension a sparse design can miss
    the basin of the global optimum altogether and EGO then refines a local one
    (Hartmann 6 with m0 = 14 did so in most runs; Jones et al.'s 10 q in few). The
    paper's railway case used m0 = 500 for q = 7; set ``design.n_initial``
    when the budget allows more.
    """
    if q < 1:
        raise ConfigError(f"the design needs at least one parameter, got q={q}")
    return max(4, min(2 ** q, 10 * q))


# -- criteria -----------------------------------------------------------------

def min_distance(X: np.ndarray) -> float:
    """Smallest Euclidean distance between two rows of ``X (n, q)`` (inf for n < 2)."""
    X = np.asarray(X, dtype=float)
    if X.shape[0] < 2:
        return float("inf")
    return float(pdist(X).min())


def phi_p(X: np.ndarray, p: float = 50.0) -> float:
    """Morris-Mitchell criterion φ_p = (Σ_{i<j} d_ij^-p)^(1/p) of ``X (n, q)``; smaller is better.

    Computed with distances scaled by their minimum, so it cannot overflow.
    """
    d = pdist(np.asarray(X, dtype=float))
    dmin = d.min()
    if dmin == 0.0:
        return float("inf")
    return float(np.sum((d / dmin) ** -p) ** (1.0 / p) / dmin)


# -- maximin LHS by ESE --------------------------------------------------------

def maximin_lhs(n: int, q: int, rng: np.random.Generator, iterations: int = 100,
                p: float = 50.0) -> np.ndarray:
    """A maximin Latin hypercube of ``n`` points in ``[0, 1]^q``, optimised by ESE.

    Enhanced Stochastic Evolutionary algorithm (Jin, Chen & Sudjianto 2005):
    element exchanges inside one column keep the Latin property; each inner
    step tries ``J`` random exchanges in a column and keeps the best; it is
    accepted when it worsens φ_p by less than ``T * U(0, 1)`` (threshold
    accepting); the threshold ``T`` adapts after each outer iteration, lowered
    while the best design improves and raised to escape when it stalls.
    Changes of φ_p are computed in O(n) from the squared distance matrix.

    :param n: number of points; :param q: dimension.
    :param rng: the random generator (seeded by the caller).
    :param iterations: outer iterations (each of ``M <= 100`` inner steps).
    :param p: exponent of φ_p.
    :returns: ``(n, q)`` points at the centres of the LHS cells ``(k + 0.5) / n``.
    """
    levels = (np.arange(n) + 0.5) / n
    X = np.column_stack([rng.permutation(levels) for _ in range(q)])
    if n < 3 or iterations == 0:
        return X
    # Squared distances are kept relative to d0^2 = q / n^2, the smallest
    # possible one between two rows of a centred LHS (every coordinate differs
    # by >= 1/n). The terms of S = Σ (D2 / c)^(-p/2) use a scale c reset to the
    # current smallest D2 whenever S has shrunk a lot, so that S stays near 1:
    # no overflow, and no loss of precision in the incremental updates.
    d0sq = q / n ** 2
    half_p = p / 2.0
    D2 = np.sum((X[:, None, :] - X[None, :, :]) ** 2, axis=-1) / d0sq
    np.fill_diagonal(D2, np.inf)

    def rescale() -> tuple[float, np.ndarray, float]:
        c = float(D2.min())
        terms = (D2 / c) ** -half_p  # (n, n), zero on the diagonal
        return c, terms, terms.sum() / 2.0

    def phi_of(S: float) -> float:
        return float(max(S, 0.0) ** (1.0 / p) / np.sqrt(c * d0sq))

    c, terms, S = rescale()
    phi = phi_of(S)
    best_X, best_phi = X.copy(), phi

    n_pairs = n * (n - 1) // 2
    J = int(min(max(n_pairs // 5, 1), 50))
    M = int(min(max(2 * n_pairs * q // J, 1), 100))
    T = 0.005 * phi
    cand = np.arange(J)
    # stale entries of masked pairs may overflow; they are discarded
    with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
        for _ in range(iterations):
            old_best = best_phi
            n_accept = n_improve = 0
            for i in range(M):
                k = i % q
                a = rng.integers(0, n, size=J)
                b = (a + rng.integers(1, n, size=J)) % n  # b != a
                xa, xb, col = X[a, k], X[b, k], X[:, k]
                # new squared distances (scaled) of rows a and b to every row r
                delta = ((xb[:, None] - col) ** 2 - (xa[:, None] - col) ** 2) / d0sq  # (J, n)
                da_new, db_new = D2[a] + delta, D2[b] - delta
                ta = (da_new / c) ** -half_p - terms[a]
                tb = (db_new / c) ** -half_p - terms[b]
                # d(a, b) is unchanged by the exchange, and d(a, a) = d(b, b) = inf:
                # their (stale, possibly overflowing) entries are left out
                ta[cand, a] = ta[cand, b] = tb[cand, a] = tb[cand, b] = 0.0
                dS = ta.sum(axis=1) + tb.sum(axis=1)
                j = int(np.argmin(dS))
                new_phi = phi_of(S + dS[j])
                if new_phi - phi <= T * rng.random():
                    ia, ib = int(a[j]), int(b[j])
                    X[ia, k], X[ib, k] = X[ib, k], X[ia, k]
                    for r, dnew in ((ia, da_new[j]), (ib, db_new[j])):
                        dnew = dnew.copy()
                        dnew[r] = np.inf
                        D2[r, :], D2[:, r] = dnew, dnew
                    # D2[ia, ib] was set from the stale value of the other row; restore it
                    D2[ia, ib] = D2[ib, ia] = np.sum((X[ia] - X[ib]) ** 2) / d0sq
                    for r in (ia, ib):
                        t = (D2[r] / c) ** -half_p
                        terms[r, :], terms[:, r] = t, t
                    S = S + dS[j]
                    if S < 1e-3:  # the smallest distance grew: rescale before precision is lost
                        c, terms, S = rescale()
                    phi = phi_of(S)
                    n_accept += 1
                    if phi < best_phi:
                        best_X, best_phi = X.copy(), phi
                        n_improve += 1
            c, terms, S = rescale()  # no drift from the incremental updates
            phi = phi_of(S)
            ratio = n_accept / M
            if best_phi < old_best - 1e-12 * old_best:  # improving: tighten while many are accepted
                if ratio > 0.1 and n_improve < n_accept:
                    T *= 0.8
                elif ratio <= 0.1:
                    T /= 0.8
            else:  # exploring: raise T fast when little is accepted, lower it slowly otherwise
                if ratio < 0.1:
                    T /= 0.7
                elif ratio > 0.8:
                    T *= 0.9
    return best_X


def _sobol(n: int, q: int, rng: np.random.Generator, options: DesignOptions) -> np.ndarray:
    with warnings.catch_warnings():  # balance properties need n = 2^k; any n is still fine here
        warnings.filterwarnings("ignore", message=".*balance properties.*")
        return qmc.Sobol(q, scramble=True, rng=rng).random(n)


def _lhs_cd(n: int, q: int, rng: np.random.Generator, options: DesignOptions) -> np.ndarray:
    return qmc.LatinHypercube(q, optimization="random-cd", rng=rng).random(n)


def _lhs(n: int, q: int, rng: np.random.Generator, options: DesignOptions) -> np.ndarray:
    return qmc.LatinHypercube(q, rng=rng).random(n)


def _maximin(n: int, q: int, rng: np.random.Generator, options: DesignOptions) -> np.ndarray:
    return maximin_lhs(n, q, rng, iterations=options.iterations, p=options.p)


DESIGNS: dict[str, Callable[[int, int, np.random.Generator, DesignOptions], np.ndarray]] = {
    "maximin-lhs": _maximin,
    "sobol": _sobol,
    "lhs-cd": _lhs_cd,
    "lhs": _lhs,
}
"""Design name (``design.method``) -> ``f(n, q, rng, options) -> (n, q)`` points in [0, 1]^q."""


def make_design(options: DesignOptions | None, q: int) -> np.ndarray:
    """The initial design ``(m0, q)`` in ``[0, 1]^q`` chosen by ``options``.

    Deterministic for a given ``options.seed``.

    :raises ConfigError: unknown method (listing the known ones) or q < 1.
    """
    options = options or DesignOptions()
    if options.method not in DESIGNS:
        raise ConfigError(f"unknown design method '{options.method}'; "
                          f"available: {', '.join(sorted(DESIGNS))}", key="design.method")
    n = options.n_initial if options.n_initial is not None else default_n_initial(q)
    if q < 1:
        raise ConfigError(f"the design needs at least one parameter, got q={q}")
    rng = np.random.default_rng(options.seed)
    return np.asarray(DESIGNS[options.method](n, q, rng, options), dtype=float)


# -- scaling between the SI box and the unit cube ---------------------------------

def check_bounds(bounds) -> np.ndarray:
    """``bounds`` as a float array ``(q, 2)`` of (lower, upper) with lower < upper, both finite.

    :raises ConfigError: wrong shape, non-finite or empty intervals (naming the row).
    """
    try:
        b = np.asarray(bounds, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"bounds must be a list of (lower, upper) pairs: {exc}") from None
    if b.ndim != 2 or b.shape[1] != 2 or b.shape[0] < 1:
        raise ConfigError(f"bounds must have shape (q, 2) with q >= 1, got {b.shape}")
    bad = np.flatnonzero(~np.all(np.isfinite(b), axis=1) | (b[:, 0] >= b[:, 1]))
    if bad.size:
        i = int(bad[0])
        raise ConfigError(f"bounds row {i} = ({b[i, 0]}, {b[i, 1]}) is not a finite interval "
                          "with lower < upper")
    return b


def to_unit(X: np.ndarray, bounds: np.ndarray) -> np.ndarray:
    """Map points ``X (n, q)`` (or ``(q,)``) from the box ``bounds (q, 2)`` to ``[0, 1]^q``."""
    b = np.asarray(bounds, dtype=float)
    return (np.asarray(X, dtype=float) - b[:, 0]) / (b[:, 1] - b[:, 0])


def from_unit(U: np.ndarray, bounds: np.ndarray) -> np.ndarray:
    """Map points ``U (n, q)`` (or ``(q,)``) of ``[0, 1]^q`` to the box ``bounds (q, 2)`` (SI units)."""
    b = np.asarray(bounds, dtype=float)
    return b[:, 0] + np.asarray(U, dtype=float) * (b[:, 1] - b[:, 0])
