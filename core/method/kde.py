"""Gaussian kernel density estimates per (channel, ω), shared by the objectives Ψ_k (paper §3.1, eq. 5-8).

At each channel k and frequency ω the densities p_{Y_k^mes}(·; ω) and
p_{Y_k^mod}(·; ω, w) are Gaussian kernel estimates from the v samples in dB:

    p(u) = (1/n) Σ_j φ_h(u - y_j),   φ_h(u) = exp(-u²/(2h²)) / (√(2π) h).

Bandwidth h (dB) per (channel, ω) and per sample set, as ``scipy.stats.gaussian_kde``
defines its rules: h = c · s with s the sample standard deviation (ddof = 1)
and c = (3n/4)^(-1/5) for ``"silverman"``, n^(-1/5) for ``"scott"``, or a
given float c. h is floored at ``min_bandwidth_db`` (default 1e-3 dB, far below
the ~2.8 dB scatter of a single-line spectrum, so it only acts on a constant
sample, where s = 0 would give h = 0 and NaN).

Two evaluations, vectorised over all (channel, ω) at once (no Python loop
over frequencies; loops run over blocks of 65536 kernel values):

- :func:`log_kde`, exact: log p at given points, the Gaussian mixture evaluated
  term by term, by one of two implementations that agree to ~1e-14:

  * ``method="numba"`` (the default when numba is importable): one compiled pass
    per (channel, ω) that forms each exponent -((x - y_j)/(√2 h))², its
    exponential and the running sum in registers, with no temporary array of
    kernel values; the exponential is evaluated inline (Cody-Waite reduction
    by ln 2 and a degree-11 polynomial, within 2 ulp of the correctly rounded
    value; its arguments are clamped at -708 so it never leaves the normal
    range) so that the compiler vectorises the loop over the points. Where the
    sum falls below 1e-250 (a point further than ~34 h from every centre) that
    point is redone with the largest exponent subtracted first, so log p
    stays finite and exact. Compiled on first use (about a second) and cached
    on disk (``cache=True``), so the compilation is paid once per machine.
  * ``method="numpy"``, the reference and the fallback without numba, below.

  The numpy evaluation: the exponents -(x - y_j)²/(2h²) <= 0 are formed by one batched
  matrix product (centred, scaled data, so the rounding error is ~1e-14 for
  data within 100·√2 h of the centre), their exponentials summed by a matrix-vector
  product. A sum of non-positive exponents cannot overflow; where it
  underflows (a point further than ~34 h from every centre) or data lie
  further than 100·√2 h from the centre, the entries are recomputed with
  logsumexp (max subtracted), so log p is finite and accurate everywhere.
- :func:`overlap_coefficient`, binned: OVL(p_1, p_2) = ∫ min(p_1, p_2) du
  = 1 - ½ ∫ |p_1 - p_2| du (eq. 8). Both samples are linearly binned onto a
  common grid of G points spanning their range plus ``tail`` bandwidths each
  side, smoothed by the Gaussian through the FFT (the kernel's exact Fourier
  transform exp(-2π²h²ξ²); the circular wrap-around is below φ at ``tail``·h,
  1.5e-8 of the peak for tail = 6), clipped at 0 and normalised to unit mass
  on the grid, and ∫ min is a sum over the grid. Linear binning errs by
  O(δ²/σ²) and the grid sum by O(δ²) at the crossing points (δ the grid
  step, σ the spread of the data); for v = 100 samples and G = 256 the
  largest error seen is 2e-4, falling as G^-2 (5e-5 at G = 512); the tests
  check < 5e-4 against direct quadrature (``tests/test_objectives.py``).
  A bandwidth below the grid step is raised to the step for this evaluation
  (only a degenerate sample far narrower than the other can need it).
"""

from __future__ import annotations

import math
from typing import Literal

import numpy as np
import scipy.fft
from pydantic import BaseModel, ConfigDict, Field, PositiveFloat

from suspid.errors import DataError

try:  # numba is a dependency; without it (a stripped-down install) log_kde falls back to numpy
    from llvmlite import ir as _llvm_ir
    from numba import njit, types as _nb_types
    from numba.core import cgutils as _cgutils
    from numba.extending import intrinsic as _intrinsic
except ImportError:  # pragma: no cover - exercised only without numba
    njit = None

HAVE_NUMBA = njit is not None
"""Whether the compiled kernel of :func:`log_kde` is available."""

BLOCK = 1 << 16
"""Kernel values per block (512 KiB of float64): large enough to amortise numpy calls, small enough for cache."""

_TINY_SUM = 1e-250   # below this a kernel sum is recomputed with logsumexp
_FAR = 100.0         # |data - centre| in units of √2 h beyond which rows take the logsumexp path


class KdeOptions(BaseModel):
    """Kernel density options common to the objectives (the ``objective.options`` section)."""

    model_config = ConfigDict(extra="forbid")

    bandwidth: Literal["silverman", "scott"] | PositiveFloat = Field(
        default="silverman", description="rule for h (as scipy.stats.gaussian_kde) or a factor times the sample sd")
    min_bandwidth_db: PositiveFloat = Field(default=1e-3, description="floor of h in dB (constant samples)")


def bandwidth_factor(rule: str | float, n: int) -> float:
    """The factor c of h = c · s for ``n`` samples (scipy's ``silverman_factor`` / ``scotts_factor``)."""
    if rule == "silverman":
        return (0.75 * n) ** -0.2
    if rule == "scott":
        return n ** -0.2
    return float(rule)


def bandwidths(samples: np.ndarray, rule: str | float, floor: float) -> np.ndarray:
    """Bandwidths h in dB, ``(n_rows,)``, of samples given as ``(n_rows, n)`` (one row per (channel, ω))."""
    n = samples.shape[1]
    h = bandwidth_factor(rule, n) * samples.std(axis=1, ddof=1)
    return np.maximum(h, floor)


def prepare(y_mes: np.ndarray, y_mod: np.ndarray, freqs: np.ndarray, min_mes: int = 1
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray, tuple[int, int]]:
    """Validate the arguments of :meth:`suspid.interfaces.Objective.psi` and lay them out by row.

    :param y_mes: ``(n_mes, n_channels, n_freqs)`` dB.
    :param y_mod: ``(n_mod, n_channels, n_freqs)`` dB, n_mod >= 2.
    :param freqs: ``(n_freqs,)`` Hz, strictly increasing.
    :returns: ``x`` ``(n_channels·n_freqs, n_mes)``, ``y`` ``(n_channels·n_freqs, n_mod)``
        (row = channel-major (k, ω)), ``freqs`` and ``(n_channels, n_freqs)``.
    :raises DataError: shapes that do not match, too few samples, non-finite values.
    """
    y_mes = np.asarray(y_mes, dtype=float)
    y_mod = np.asarray(y_mod, dtype=float)
    freqs = np.asarray(freqs, dtype=float)
    if y_mes.ndim != 3 or y_mod.ndim != 3 or y_mes.shape[1:] != y_mod.shape[1:]:
        raise DataError(f"y_mes {y_mes.shape} and y_mod {y_mod.shape} must be (n_samples, n_channels, n_freqs) "
                        f"with the same channels and frequencies")
    grid = y_mes.shape[1:]
    if freqs.shape != (grid[1],):
        raise DataError(f"freqs has shape {freqs.shape}, the spectra have {grid[1]} frequencies")
    if not np.all(np.isfinite(freqs)) or np.any(np.diff(freqs) <= 0):
        raise DataError("freqs must be finite and strictly increasing (Hz)")
    if y_mes.shape[0] < min_mes or y_mod.shape[0] < 2:
        raise DataError(f"need at least {min_mes} measured and 2 modelled samples, "
                        f"got {y_mes.shape[0]} and {y_mod.shape[0]}")
    for name, a in (("y_mes", y_mes), ("y_mod", y_mod)):
        if not np.all(np.isfinite(a)):
            raise DataError(f"{name} contains NaN or infinite values")
    x = np.ascontiguousarray(y_mes.reshape(y_mes.shape[0], -1).T)
    y = np.ascontiguousarray(y_mod.reshape(y_mod.shape[0], -1).T)
    return x, y, freqs, grid


def frequency_mean(values: np.ndarray, freqs: np.ndarray) -> np.ndarray:
    """(1/|Ω|) ∫_Ω values dω by the trapezoidal rule (eq. 6-7); ``values`` ``(..., n_freqs)``.

    |Ω| = freqs[-1] - freqs[0]; non-uniform (log) grids are fine. A single
    frequency returns its value.
    """
    if freqs.size == 1:
        return values[..., 0]
    return np.trapezoid(values, freqs, axis=-1) / (freqs[-1] - freqs[0])


def _logsumexp_rows(x: np.ndarray, c: np.ndarray) -> np.ndarray:
    """log Σ_j exp(-(x_e - c_ej)²) for entries e: ``x`` ``(E,)``, ``c`` ``(E, n)`` (scaled units)."""
    out = np.empty(x.shape[0])
    step = max(1, BLOCK // c.shape[1])
    for s in range(0, x.shape[0], step):
        d = x[s:s + step, None] - c[s:s + step]
        e = -(d * d)
        top = e.max(axis=1)
        out[s:s + step] = top + np.log(np.exp(e - top[:, None]).sum(axis=1))
    return out


def log_kde(points: np.ndarray, centres: np.ndarray, h: np.ndarray,
            method: Literal["auto", "numba", "numpy"] = "auto") -> np.ndarray:
    """Exact log of the Gaussian KDE of ``centres`` at ``points``, row by row.

    :param points: ``(n_rows, m)`` where to evaluate (dB).
    :param centres: ``(n_rows, n)`` the sample the density is estimated from (dB).
    :param h: ``(n_rows,)`` bandwidths (dB), > 0.
    :param method: ``"numba"`` the compiled kernel, ``"numpy"`` the vectorised reference,
        ``"auto"`` the kernel when numba is importable (see the module docstring).
    :returns: ``(n_rows, m)`` log p in log(1/dB).
    :raises ValueError: ``method="numba"`` without numba, an unknown method, or shapes that do not match.
    """
    if method == "auto":
        method = "numba" if HAVE_NUMBA else "numpy"
    if method == "numpy":
        return log_kde_numpy(points, centres, h)
    if method != "numba":
        raise ValueError(f"log_kde method must be 'auto', 'numba' or 'numpy', not {method!r}")
    if not HAVE_NUMBA:
        raise ValueError("log_kde method 'numba' needs the numba package")
    points = np.ascontiguousarray(points, dtype=float)
    centres = np.ascontiguousarray(centres, dtype=float)
    h = np.ascontiguousarray(h, dtype=float)
    # the compiled kernel does not check bounds: check the shapes here
    if points.ndim != 2 or centres.ndim != 2 or h.shape != (points.shape[0],) or centres.shape[0] != h.size \
            or centres.shape[1] < 1:
        raise ValueError(f"log_kde needs points (n_rows, m), centres (n_rows, n >= 1) and h (n_rows,), "
                         f"got {points.shape}, {centres.shape} and {h.shape}")
    out = np.empty(points.shape)
    if out.size == 0:
        return out
    _log_kernel_sums(points, centres, 1.0 / (math.sqrt(2.0) * h), out)
    return out - np.log(centres.shape[1] * math.sqrt(2.0 * math.pi) * h)[:, None]


def log_kde_numpy(points: np.ndarray, centres: np.ndarray, h: np.ndarray) -> np.ndarray:
    """:func:`log_kde` by numpy alone (batched matrix products, blocked ``np.exp``): the reference."""
    n_rows, m = points.shape
    n = centres.shape[1]
    shift = centres.mean(axis=1, keepdims=True)
    scale = 1.0 / (math.sqrt(2.0) * h[:, None])
    x = (points - shift) * scale
    c = (centres - shift) * scale
    far = (np.abs(x).max(axis=1) > _FAR) | (np.abs(c).max(axis=1) > _FAR)
    if far.any():  # keep the fast path's rounding small; these rows are redone below
        x[far], c[far] = 0.0, 0.0
    # -(x - c)² = [-x², 2x, 1] · [1, c, -c²]
    lhs = np.empty((n_rows, m, 3))
    lhs[..., 0], lhs[..., 1], lhs[..., 2] = -x * x, 2.0 * x, 1.0
    rhs = np.empty((n_rows, 3, n))
    rhs[:, 0], rhs[:, 1], rhs[:, 2] = 1.0, c, -c * c
    sums = np.empty((n_rows, m))
    ones = np.ones(n)
    pts = min(m, max(1, BLOCK // n))
    rows = max(1, BLOCK // (pts * n))
    buf = np.empty((rows, pts, n))
    with np.errstate(under="ignore"):
        for r in range(0, n_rows, rows):
            r1 = min(r + rows, n_rows)
            for p in range(0, m, pts):
                p1 = min(p + pts, m)
                e = buf[: r1 - r, : p1 - p]
                np.matmul(lhs[r:r1, p:p1], rhs[r:r1], out=e)
                np.exp(e, out=e)
                np.matmul(e, ones, out=sums[r:r1, p:p1])
        small = sums < _TINY_SUM
        small[far] = True
        log_sums = np.log(np.maximum(sums, _TINY_SUM))
        if small.any():
            rows_idx, pts_idx = np.nonzero(small)
            x_all = (points - shift) * scale
            c_all = (centres - shift) * scale
            log_sums[rows_idx, pts_idx] = _logsumexp_rows(x_all[rows_idx, pts_idx], c_all[rows_idx])
    return log_sums - np.log(n * math.sqrt(2.0 * math.pi) * h)[:, None]


# The compiled kernel of log_kde. Plain IEEE arithmetic (no fastmath): the only
# liberties are explicit fused multiply-adds, which round once instead of twice.
_LOG2E = 1.4426950408889634           # 1/ln 2
_ROUND = 6755399441055744.0           # 1.5·2^52: adding it rounds a double below 2^51 to an integer
_LN2_HI = 6.93147180369123816490e-01  # ln 2 split so that k·_LN2_HI is exact for |k| < 2^20
_LN2_LO = 1.90821492927058770002e-10
_EXP_CLAMP = 708.0                    # e^-708 = 3e-308 is still a normal double
# exp(r) on |r| <= 0.35 (⊃ [-ln2/2, ln2/2]): the degree-11 polynomial interpolating exp at the
# 12 Chebyshev nodes, solved in exact rational arithmetic from 80-digit values and rounded to
# double; its own relative error is below 5e-18, so rounding in Horner's scheme dominates.
_EXP_POLY = (1.0, 1.0, 0.500000000000002, 0.16666666666666682, 0.041666666666473465,
             0.008333333333318475, 0.0013888888956173813, 0.0001984126989301463,
             2.4801481392218248e-05, 2.755723777338061e-06, 2.763413820537965e-07,
             2.511118996532136e-08)

if HAVE_NUMBA:
    @_intrinsic
    def _fma(typingctx, a, b, c):
        """a·b + c rounded once (the ``llvm.fma`` intrinsic, which vectorises)."""
        sig = _nb_types.float64(_nb_types.float64, _nb_types.float64, _nb_types.float64)

        def codegen(context, builder, signature, args):
            d = _llvm_ir.DoubleType()
            fn = _cgutils.get_or_insert_function(builder.module, _llvm_ir.FunctionType(d, [d, d, d]),
                                                 "llvm.fma.f64")
            return builder.call(fn, args)
        return sig, codegen

    @_intrinsic
    def _bits(typingctx, x):
        """The IEEE bits of a double as int64."""
        def codegen(context, builder, signature, args):
            return builder.bitcast(args[0], _llvm_ir.IntType(64))
        return _nb_types.int64(_nb_types.float64), codegen

    @_intrinsic
    def _from_bits(typingctx, i):
        """The double with the IEEE bits of an int64."""
        def codegen(context, builder, signature, args):
            return builder.bitcast(args[0], _llvm_ir.DoubleType())
        return _nb_types.float64(_nb_types.int64), codegen

    _C2, _C3, _C4, _C5, _C6, _C7, _C8, _C9, _C10, _C11 = _EXP_POLY[2:]

    @njit(inline="always", cache=True)
    def _exp_neg(u):
        """exp(-u) for u >= 0, u clamped at 708 (so ≥ 3e-308), within 2 ulp; branch-free so loops vectorise."""
        u = min(u, _EXP_CLAMP)
        kd = _fma(u, -_LOG2E, _ROUND)             # k = round(-u / ln 2) sits in the low bits
        scale = _from_bits((_bits(kd) + 1023) << 52)  # 2^k, k in [-1022, 0]
        kd = kd - _ROUND
        r = _fma(kd, -_LN2_HI, -u)                # r = -u - k ln 2, |r| <= ln2/2
        r = _fma(kd, -_LN2_LO, r)
        p = _fma(_C11, r, _C10)
        p = _fma(p, r, _C9)
        p = _fma(p, r, _C8)
        p = _fma(p, r, _C7)
        p = _fma(p, r, _C6)
        p = _fma(p, r, _C5)
        p = _fma(p, r, _C4)
        p = _fma(p, r, _C3)
        p = _fma(p, r, _C2)
        p = _fma(p, r, 1.0)
        p = _fma(p, r, 1.0)
        return p * scale

    @njit(cache=True, nogil=True)
    def _log_kernel_sums(points, centres, scale, out):
        """out[r, i] = log Σ_j exp(-((points[r, i] - centres[r, j]) · scale[r])²), exact.

        The loop over the points is innermost, so it vectorises without
        reassociating any sum (each point keeps its own accumulator; the
        terms are added in the order j = 0, 1, ...). The point buffer is
        padded to a multiple of 8 so no scalar remainder loop runs.
        """
        n_rows, m = points.shape
        n = centres.shape[1]
        width = (m + 7) // 8 * 8
        x = np.empty(width)
        acc = np.empty(width)
        for r in range(n_rows):
            s = scale[r]
            for i in range(width):
                x[i] = points[r, min(i, m - 1)]
                acc[i] = 0.0
            for j in range(n):
                c = centres[r, j]
                for i in range(width):
                    d = (x[i] - c) * s
                    acc[i] += _exp_neg(d * d)
            for i in range(m):
                if acc[i] >= _TINY_SUM:
                    out[r, i] = math.log(acc[i])
                    continue
                # Every term below 1e-250: subtract the largest exponent first (log-sum-exp).
                low = np.inf
                for j in range(n):
                    d = (x[i] - centres[r, j]) * s
                    low = min(low, d * d)
                total = 0.0
                for j in range(n):
                    d = (x[i] - centres[r, j]) * s
                    total += _exp_neg(d * d - low)
                out[r, i] = math.log(total) - low


def _grid_masses(samples: tuple[np.ndarray, ...], hs: tuple[np.ndarray, ...], lo: np.ndarray,
                 delta: np.ndarray, size: int) -> np.ndarray:
    """KDE probability mass per grid cell of each sample, ``(n_samples, n_rows, size)``, rows summing to 1.

    Linear binning (each value splits its weight between the two nearest
    nodes), then the Gaussian of bandwidth max(h, δ) applied through the FFT
    with its exact Fourier transform; see the module docstring.
    """
    n_rows = lo.shape[0]
    index, weight = [], []
    row_base = (np.arange(n_rows) * size)[:, None]
    for s, values in enumerate(samples):
        u = (values - lo[:, None]) / delta[:, None]     # >= 0: the grid starts below the data
        i0 = u.astype(np.intp)
        np.minimum(i0, size - 2, out=i0)
        frac = u - i0
        i0 += row_base + s * n_rows * size
        index += [i0.ravel(), i0.ravel() + 1]
        weight += [(1.0 - frac).ravel(), frac.ravel()]
    counts = np.bincount(np.concatenate(index), np.concatenate(weight), minlength=len(samples) * n_rows * size)
    counts = counts.reshape(len(samples), n_rows, size)
    width = np.stack([np.maximum(h, delta) for h in hs]) / (size * delta)  # h per grid period
    k = np.arange(size // 2 + 1)
    transfer = np.exp(-2.0 * math.pi ** 2 * (width[..., None] * k) ** 2)
    mass = scipy.fft.irfft(scipy.fft.rfft(counts, axis=-1) * transfer, n=size, axis=-1)
    np.maximum(mass, 0.0, out=mass)
    mass /= mass.sum(axis=-1, keepdims=True)
    return mass


def overlap_coefficient(a: np.ndarray, b: np.ndarray, h_a: np.ndarray, h_b: np.ndarray,
                        grid_size: int = 256, tail: float = 6.0) -> np.ndarray:
    """OVL of the Gaussian KDEs of two samples, row by row (eq. 8), binned on a grid.

    :param a: ``(n_rows, n_a)`` first sample (dB); ``b``: ``(n_rows, n_b)`` second sample.
    :param h_a: ``(n_rows,)`` bandwidths of ``a`` (dB); ``h_b`` those of ``b``.
    :param grid_size: grid points G per row.
    :param tail: grid margin beyond the data, in bandwidths.
    :returns: ``(n_rows,)`` in [0, 1].
    """
    out = np.empty(a.shape[0])
    rows = max(1, (1 << 15) // grid_size)
    for r in range(0, a.shape[0], rows):
        sl = slice(r, r + rows)
        margin = tail * np.maximum(h_a[sl], h_b[sl])
        lo = np.minimum(a[sl].min(axis=1), b[sl].min(axis=1)) - margin
        hi = np.maximum(a[sl].max(axis=1), b[sl].max(axis=1)) + margin
        mass = _grid_masses((a[sl], b[sl]), (h_a[sl], h_b[sl]), lo, (hi - lo) / (grid_size - 1), grid_size)
        out[sl] = np.minimum(mass[0], mass[1]).sum(axis=1)
    return np.clip(out, 0.0, 1.0)
