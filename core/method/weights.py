"""Channel weights α of eq. 5 chosen as estimating-equation weights: the narrowest sampling interval.

J = Σ_ch α_ch Ψ_ch, so at the maximiser both the gradient's noise and the curvature that the sandwich
H⁻¹ G H⁻¹ combines split over the channels: with g_ch ``(q,)`` the gradient of Ψ_ch over replicates of the
data and H_ch its curvature, H(α) = Σ α_ch H_ch and G(α) = cov(Σ α_ch g_ch). A channel whose gradient is
noisy, or whose curvature is small or unstable (a model-form error the model lacks, e.g. a carbody bending
a rigid model does not have), widens the interval of every component; weights that minimise the sandwich
(generalised estimating equations: the optimal linear combination of unbiased estimating functions) give
it less. With a diagonal curvature the variance of component k is αᵀV_kα / (αᵀc̄_k)², V_k ``(n, n)`` the
channels' gradient covariance and c̄_k ``(n,)`` their mean curvatures along u_k; for one component the
minimiser is α ∝ V_k⁻¹c̄_k (Godambe's optimal estimating function).

Pure arithmetic on moments or replicates; :mod:`suspid.workflows.weights` estimates them at the reference
date, at w0, where the truth is known.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize

CRITERIA = ("trace", "log")
EFFICIENT_NEEDS_REFERENCE = ("'efficient' estimates α at the reference date: the run needs the reference date's data "
                             "(data.source: experiment without noise.path, or noise.reference)")


@dataclass(frozen=True)
class EfficientWeights:
    """The weights and what they were chosen on.

    :ivar alpha: ``(n,)`` α ≥ 0, Σ α = 1 (after shrinking).
    :ivar components: indices of the components the criterion used (those whose equal-weight curvature
        is negative: J has a maximum along them).
    :ivar variance_equal: ``(q,)`` each component's sandwich variance with equal weights (NaN where unused).
    :ivar variance: ``(q,)`` the same with ``alpha``.
    """

    alpha: np.ndarray
    components: list[int]
    variance_equal: np.ndarray
    variance: np.ndarray


def component_variances(alpha: np.ndarray, V: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Diagonal sandwich variance per component, αᵀV_kα / (αᵀc_k)², ``(q,)`` (inf where αᵀc_k ≥ 0).

    :param V: ``(q, n, n)`` the channels' gradient covariance along each component.
    :param c: ``(q, n)`` the channels' mean curvatures along each component.
    """
    num = np.einsum("i,kij,j->k", alpha, V, alpha)
    den = c @ alpha
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(den < 0, num / den ** 2, np.inf)


def curvature_shares(alpha: np.ndarray, c: np.ndarray) -> np.ndarray:
    """``(q,)`` each component's share of J's squared curvatures, (αᵀc_k)² / Σ_j (αᵀc_j)².

    For J quadratic in u over the box, a component's total Sobol index is its share of J's variance,
    ∝ (αᵀc_k)²: what the identifiability verdict's "no influence" rule reads. Weights that shrink a component's
    share would call a precise component "no influence".
    """
    s = (np.asarray(c, float) @ alpha) ** 2
    return s / s.sum() if s.sum() > 0 else s


def efficient_weights_from_moments(V: np.ndarray, c: np.ndarray, criterion: str = "trace",
                                   shrink: float = 0.0, keep_share: float = 0.0) -> EfficientWeights:
    """α ≥ 0, Σ α = 1, minimising the trace (or the sum of logs) of the components' diagonal sandwich variances.

    :param V: ``(q, n, n)`` gradient covariance of the n channels along each of the q components (normalised u).
    :param c: ``(q, n)`` mean curvature of each channel along each component.
    :param criterion: ``trace`` Σ_k var_k (the flattest components weigh most) or ``log`` Σ_k log var_k
        (every component alike, invariant to each component's scale).
    :param shrink: λ in [0, 1]: α = (1 − λ) α* + λ/n, toward equal weights (against fitting the replicates' noise).
    :param keep_share: ρ in [0, 1]: every component keeps at least ρ times its equal-weight share of the
        curvatures (:func:`curvature_shares`), so that the weights do not trade one component's influence
        on J for the others' precision.
    :returns: :class:`EfficientWeights`; equal weights when no component has a negative equal-weight curvature.
    """
    if criterion not in CRITERIA:
        raise ValueError(f"criterion {criterion!r}: expected one of {CRITERIA}")
    V, c = np.asarray(V, float), np.asarray(c, float)
    q, n = c.shape
    equal = np.full(n, 1.0 / n)
    var_equal = component_variances(equal, V, c)
    use = [k for k in range(q) if np.isfinite(var_equal[k]) and var_equal[k] > 0]
    if not use or n == 1:
        return EfficientWeights(equal, use, np.where(np.isfinite(var_equal), var_equal, np.nan), var_equal)
    Vu, cu = V[use], c[use]
    scale = var_equal[use]
    share_floor = keep_share * curvature_shares(equal, c)

    def loss(x: np.ndarray) -> float:
        a = x ** 2 / (x @ x)
        v = component_variances(a, Vu, cu)
        if not np.all(np.isfinite(v)) or np.any(curvature_shares(a, c) < share_floor):
            return 1e300
        return float(np.sum(v) if criterion == "trace" else np.sum(np.log(v / scale)))

    starts = [np.sqrt(equal)]
    for k in range(len(use)):   # each component's own optimum α ∝ V⁻¹c̄, clipped to α ≥ 0
        try:
            a = -np.linalg.solve(Vu[k] + 1e-12 * np.trace(Vu[k]) * np.eye(n), cu[k])
        except np.linalg.LinAlgError:
            continue
        a = np.clip(a, 0, None)
        if a.sum() > 0:
            starts.append(np.sqrt(a / a.sum()))
    best = None
    for x0 in starts:
        res = minimize(loss, x0, method="L-BFGS-B")   # then Nelder-Mead: the barrier αᵀc̄_k < 0 is not smooth
        res = minimize(loss, res.x, method="Nelder-Mead", options={"maxiter": 400 * n, "xatol": 1e-6, "fatol": 1e-12})
        if best is None or res.fun < best.fun:
            best = res
    x = best.x
    alpha = x ** 2 / (x @ x)
    if loss(x) > loss(np.sqrt(equal)):   # never worse than equal weights on its own criterion
        alpha = equal
    alpha = (1.0 - shrink) * alpha + shrink * equal
    alpha = alpha / alpha.sum()
    variance = component_variances(alpha, V, c)
    return EfficientWeights(alpha, use, np.where(np.isfinite(var_equal), var_equal, np.nan), variance)


def efficient_weights(g: np.ndarray, curvature: np.ndarray, criterion: str = "trace",
                      shrink: float = 0.0, keep_share: float = 0.0) -> EfficientWeights:
    """:func:`efficient_weights_from_moments` on replicates.

    :param g: ``(R, q, n)`` per replicate, component and channel, the gradient of Ψ_ch (normalised u).
    :param curvature: ``(R, q, n)`` the same replicates' second derivatives d²Ψ_ch/du_k².
    """
    g, curvature = np.asarray(g, float), np.asarray(curvature, float)
    if g.shape[0] < 3:
        raise ValueError(f"{g.shape[0]} replicates: the channels' gradient covariance needs at least 3")
    V = np.stack([np.atleast_2d(np.cov(g[:, k, :], rowvar=False)) for k in range(g.shape[1])])
    return efficient_weights_from_moments(V, curvature.mean(axis=0), criterion, shrink, keep_share)
