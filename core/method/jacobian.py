"""Derivatives of the simulated spectra y_sim(w) with respect to named parameters: the mathematics.

The objective J (eq. 5-8) reads the model only through the spectra y_sim_i(w)
``(v, n_channels, n_freqs)`` dB of eq. 1-2; their Jacobian
``(v, n_channels, n_freqs, n_p)`` dB per SI unit of each parameter is what a
gradient-based search, a Fisher information or a linearised model-error check
needs. This module holds what does not run a simulation:

- :func:`spectra_derivatives`: the derivatives dA of a simulator's records
  (:class:`~suspid.interfaces.DifferentiableSimulator`) carried through eq. 1-2
  exactly. With Â the record's Fourier amplitude (detrend and window are
  linear, so dÂ is the amplitude of dA) and P_j the mean of |Â|² over the
  lines of cell j, y_j = 5 log10 P_j and ∂y_j = (5 / ln 10) ∂P_j / P_j, ∂P_j
  the cell mean of 2 Re(conj(Â) dÂ) (0 where P_j sits at the amplitude floor);
- :class:`SpectraJacobian`: y_sim, its Jacobian and how each column was obtained;
- helpers for the checks that work from Jacobians: the Fisher information
  (:func:`gauss_newton_information`), the identifiability it implies
  (:func:`fisher_identifiability`) and the first-order shift of the estimate
  with a model parameter held at a wrong value (:func:`linearised_shift`).

Running the simulations (analytic where offered, finite differences through
the run's executor otherwise) is a workflow: :func:`suspid.workflows.jacobian.spectra_jacobian`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np

from suspid.interfaces import Response
from suspid.method.spectra import SpectraOptions, frequency_grid, record_spectrum_derivatives
from suspid.options import parse_options

__all__ = ["SpectraJacobian", "spectra_derivatives", "gauss_newton_information", "linearised_shift",
           "fisher_information", "fisher_identifiability", "FisherVerdict", "DEFAULT_REL_STEP"]

DEFAULT_REL_STEP = 1e-4
"""Relative step of the finite differences: below it the simulators' own rounding (an exudyn linearisation is
itself differenced) dominates the error of a central difference, above it the curvature does."""


def spectra_derivatives(responses: Sequence[Response], d_accelerations: Sequence[np.ndarray],
                        options: SpectraOptions | Mapping[str, Any] | None = None
                        ) -> tuple[np.ndarray, np.ndarray]:
    """y (eq. 1-2) of each record and its derivatives from those of the accelerations
    (:func:`~suspid.method.spectra.record_spectrum_derivatives`).

    :param responses: one per segment, as :func:`~suspid.method.spectra.compute_spectra` takes them.
    :param d_accelerations: per segment ``(n_p, n_channels, n_t)``, (m/s²) per SI unit of each parameter.
    :returns: ``y (v, n_channels, n_freqs)`` dB and ``dy (v, n_channels, n_freqs, n_p)`` dB per SI unit.
    """
    opt = parse_options(SpectraOptions, options, "spectra")
    ys, dys = [], None
    for i, (r, da) in enumerate(zip(responses, d_accelerations)):
        n_p, n_ch = np.shape(da)[0], np.shape(r.accelerations)[0]
        if dys is None:     # written in place, each segment's (n_p, n_channels, n_freqs) a view of its slot
            dys = np.empty((len(responses), n_ch, frequency_grid(opt)[0].size, n_p))
        y, _ = record_spectrum_derivatives(r.accelerations, da, r.fs, opt, name=r.segment or str(i),
                                           out=np.moveaxis(dys[i], -1, 0))
        ys.append(y)
    return np.stack(ys), dys


@dataclass
class SpectraJacobian:
    """The spectra y_sim(w) and their Jacobian.

    :ivar names: ``(n_p,)`` the parameters, in the order of the last axis of ``jacobian``.
    :ivar w: the point, every parameter of ``names`` in SI units.
    :ivar y: ``(v, n_channels, n_freqs)`` dB; :ivar freqs: ``(n_freqs,)`` Hz.
    :ivar jacobian: ``(v, n_channels, n_freqs, n_p)`` dB per SI unit.
    :ivar methods: name -> ``"analytic"``, ``"central"`` or ``"forward"``.
    :ivar n_simulations: plain simulations (all segments at one w) the finite differences took.
    :ivar n_analytic_calls: calls of the simulator's ``simulate_jacobian`` (0 or 1).
    :ivar wall_time_s: wall time of the whole evaluation, s.
    """

    names: list[str]
    w: dict[str, float]
    y: np.ndarray
    freqs: np.ndarray
    jacobian: np.ndarray
    methods: dict[str, str]
    n_simulations: int
    n_analytic_calls: int
    wall_time_s: float
    details: dict[str, Any] = field(default_factory=dict)

    def scaled(self, scales: Sequence[float]) -> np.ndarray:
        """The Jacobian per unit of ``scales`` ``(n_p,)`` (e.g. the widths of the admissible intervals:
        derivatives with respect to the normalised parameters in [0, 1]^q): ``(v, n_channels, n_freqs, n_p)``."""
        return self.jacobian * np.asarray(scales, dtype=float)


def gauss_newton_information(jacobian: np.ndarray, variance: np.ndarray) -> np.ndarray:
    """The Gauss-Newton (Fisher) information of the parameters in the mean spectra, ``(n_p, n_p)``.

    With y_mod_i = y_sim_i(w) + b_i and b_i of variance σ² ``(n_channels, n_freqs)`` dB² (the noise
    model's), independent over segments, channels and frequencies, the information of v segments is
    F = Σ_i Σ_k,j ∂y_ikj/∂w ∂y_ikj/∂w^T / σ²_kj; F^-1 is the linearised covariance of a least-squares
    estimate. A helper for the trust checks (identifiability from the Jacobian, a sandwich bread); the
    independence it assumes is the caller's to judge.

    :param jacobian: ``(v, n_channels, n_freqs, n_p)`` (:attr:`SpectraJacobian.jacobian`, or scaled).
    :param variance: ``(n_channels, n_freqs)`` dB².
    """
    Jm = np.asarray(jacobian, dtype=float)
    inv = 1.0 / np.maximum(np.asarray(variance, dtype=float), 1e-300)
    flat = Jm.reshape(-1, Jm.shape[-1])
    weights = np.broadcast_to(inv[None], Jm.shape[:-1]).reshape(-1)
    return flat.T @ (flat * weights[:, None])


def linearised_shift(jacobian_w: np.ndarray, jacobian_theta: np.ndarray, variance: np.ndarray) -> np.ndarray:
    """How the estimate of w moves with model parameters θ held at wrong values, to first order: ``(q, n_θ)``.

    Implicit-function theorem on the weighted least-squares fit of the mean spectra: at the optimum
    J_wᵀ W r = 0 with r = y_data - y_sim(w, θ) and W = 1/σ²; moving θ by Δθ moves the optimum by
    Δw = -(J_wᵀ W J_w)^-1 J_wᵀ W J_θ Δθ. A helper for the linearised model-error checks (a nuisance
    parameter's shift without a re-identification); it is exact for a model linear in (w, θ).

    :param jacobian_w: ``(v, n_channels, n_freqs, q)`` ∂y_sim/∂w (SI or scaled units, see :meth:`SpectraJacobian.scaled`).
    :param jacobian_theta: ``(v, n_channels, n_freqs, n_θ)`` ∂y_sim/∂θ at the same point.
    :param variance: ``(n_channels, n_freqs)`` dB², the weights' inverse.
    :returns: dw/dθ in the units of the two Jacobians.
    """
    Jw = np.asarray(jacobian_w, dtype=float)
    Jt = np.asarray(jacobian_theta, dtype=float)
    inv = np.broadcast_to(1.0 / np.maximum(np.asarray(variance, dtype=float), 1e-300)[None], Jw.shape[:-1])
    A = Jw.reshape(-1, Jw.shape[-1]) * np.sqrt(inv.reshape(-1))[:, None]
    B = Jt.reshape(-1, Jt.shape[-1]) * np.sqrt(inv.reshape(-1))[:, None]
    return -np.linalg.lstsq(A, B, rcond=None)[0]


def fisher_information(y_sim: np.ndarray, jacobian: np.ndarray, noise_model, rel_floor: float = 1.0) -> np.ndarray:
    """The Fisher information ``(n_p, n_p)`` of the parameters in the modelled spectra, with B's own covariance.

    With y_mod_i = f(y_sim_i(w)) + b_i (eq. 4; f the sensor-noise floor's
    5 log10(10^{(y + m)/5} + N) - m, the identity without a floor) and the noise
    paths b_i independent over segments, each Gaussian with the noise model's
    covariance C (low rank plus diagonal, :class:`~suspid.method.noise.NoiseModel`),
    F = Σ_i G_iᵀ C⁻¹ G_i, G_i = f'(y_sim_i) ∂y_sim_i/∂w ``(D, n_p)``. C⁻¹ is applied
    by the Woodbury identity (never formed); unlike
    :func:`gauss_newton_information` the correlations of B over channels and
    frequencies are kept, so that 200 frequencies that a smooth gain moves
    together do not count as 200 independent readings. The diagonal part is
    kept at ``rel_floor`` of B's marginal variance at least. The default, 1,
    is conservative: B's v0 paths span at most v0 - 1 of the D directions, and
    in the others the fitted remainder (1 % of the variance with
    ``variance_fraction`` 0.99) would count a reading as nearly noise-free
    (on the quickstart it put the Cramér-Rao spread near 0.01 % of the
    interval); with the whole marginal variance on the diagonal as well, the
    information is no larger than that of independent readings of B's full
    variance. Where the floor N dominates, f' = P / (P + N) → 0: a
    parameter that moves the spectra only below the sensors' floor carries no
    information.

    :param y_sim: ``(v, n_channels, n_freqs)`` dB at the point.
    :param jacobian: ``(v, n_channels, n_freqs, n_p)`` dB per unit of each parameter (SI, or scaled).
    :param noise_model: a fitted :class:`~suspid.method.noise.NoiseModel`.
    :returns: F in the inverse square units of the Jacobian's parameters.
    """
    y = np.asarray(y_sim, dtype=float)
    Jm = np.asarray(jacobian, dtype=float)
    floor = getattr(noise_model, "floor_", None)
    if floor is not None:
        power = 10.0 ** ((y + floor.gain_db) / 5.0)
        Jm = Jm * (power / (power + floor.power))[..., None]
    v, n_p = Jm.shape[0], Jm.shape[-1]
    G = Jm.reshape(v, -1, n_p)                                                          # (v, D, n_p)
    d = np.maximum(np.asarray(noise_model.residual_variance_, dtype=float).ravel(),
                   rel_floor * np.asarray(noise_model.variance_, dtype=float).ravel())
    d = np.maximum(d, 1e-300)
    U = np.asarray(noise_model.components_, dtype=float).T                              # (D, r)
    s = (1.0 - float(noise_model.shrinkage_)) * np.asarray(noise_model.eigenvalues_, dtype=float)
    GD = G / d[None, :, None]                                                           # D⁻¹ G_i
    F = np.einsum("vdp,vdq->pq", G, GD)
    keep = s > 0
    if np.any(keep):
        U, s = U[:, keep], s[keep]
        inner = np.diag(1.0 / s) + (U / d[:, None]).T @ U                              # S⁻¹ + Uᵀ D⁻¹ U
        W = np.einsum("dr,vdp->vrp", U, GD)                                             # Uᵀ D⁻¹ G_i
        r = W.shape[1]
        X = np.linalg.solve(inner, np.moveaxis(W, 0, 1).reshape(r, -1)).reshape(r, v, n_p)
        F -= np.einsum("vrp,rvq->pq", W, X)
    return 0.5 * (F + F.T)


@dataclass
class FisherVerdict:
    """Identifiability from the Fisher information, per component (arrays ``(q,)``, units of the information's
    parameters, e.g. [0, 1]^q).

    :ivar sd_alone: the Cramér-Rao standard deviation with every other component known, 1/√F_kk.
    :ivar sd: the Cramér-Rao standard deviation with the others estimated too, √(F⁻¹)_kk (inf on a null direction).
    :ivar partner: per component, the component it is most correlated with under F⁻¹ and that correlation.
    """

    identifiable: np.ndarray
    reasons: list[list[str]]
    sd_alone: np.ndarray
    sd: np.ndarray
    partner: list[tuple[str, float] | None]


def fisher_identifiability(information: np.ndarray, names: Sequence[str], n_sigmas: float,
                           max_width: float) -> FisherVerdict:
    """Which components the data pin down, from the Fisher information ``(q, q)`` in [0, 1]^q units.

    A component is **not identifiable** when its ± ``n_sigmas`` Cramér-Rao interval spans more than
    ``max_width`` of the admissible interval: *no influence on the spectra* when it does so even with
    every other component known (2 n / √F_kk > max_width: the spectra hardly move with it, against
    the noise B), a *flat direction* when only together with the others (a combination of components
    moves the spectra as little). The bound is the best any unbiased estimator from these spectra can
    do without model error; the run's objective may do worse and model error adds a bias, which its
    sandwich intervals and the model-error checks say (on the quickstart the bound is a fraction of a per
    cent of the interval where the errors are a few per cent): the verdict says whether the spectra move
    with a component at all, not how precisely it is known.
    """
    F = 0.5 * (np.asarray(information, dtype=float) + np.asarray(information, dtype=float).T)
    q = F.shape[0]
    diag = np.diag(F)
    with np.errstate(divide="ignore"):
        sd_alone = np.where(diag > 0, 1.0 / np.sqrt(np.maximum(diag, 1e-300)), np.inf)
    lam, V = np.linalg.eigh(F)
    scale = max(float(np.max(np.abs(lam))) if lam.size else 0.0, 1e-300)
    live = lam > 1e-12 * scale
    cov = (V[:, live] / lam[live]) @ V[:, live].T
    null = np.sum(V[:, ~live] ** 2, axis=1) > 1e-6          # the component has a share of a null direction
    sd = np.where(null, np.inf, np.sqrt(np.clip(np.diag(cov), 0, None)))
    identifiable = np.ones(q, dtype=bool)
    reasons: list[list[str]] = [[] for _ in range(q)]
    partner: list[tuple[str, float] | None] = [None] * q
    def spread(s: float) -> str:
        return f"± {100 * n_sigmas * s:.0f} %" if n_sigmas * s < 1 else "more than the whole"

    null_vectors = V[:, ~live]
    for k in range(q):
        if null[k]:     # on a null direction n the errors move together as n does: r = sign(n_k n_j)
            share = np.abs(null_vectors[k][None, :] * null_vectors).sum(axis=1)
            share[k] = 0.0
            j = int(np.argmax(share))
            if j != k and share[j] > 1e-6:
                partner[k] = (names[j], float(np.sign(null_vectors[k] @ null_vectors[j])))
        else:
            others = [j for j in range(q) if j != k and np.isfinite(sd[j]) and sd[j] > 0]
            if sd[k] > 0 and others:
                r = [cov[k, j] / (sd[k] * sd[j]) for j in others]
                best = int(np.argmax(np.abs(r)))
                partner[k] = (names[others[best]], float(r[best]))
        if 2 * n_sigmas * sd_alone[k] > max_width:
            reasons[k].append(f"no influence on the spectra (Fisher information: ± {n_sigmas:g} σ = "
                              f"{spread(sd_alone[k])} of the interval even with the others known)")
        elif 2 * n_sigmas * sd[k] > max_width:
            what = f", mostly with {partner[k][0]} (r = {partner[k][1]:+.2f})" if partner[k] else ""
            reasons[k].append(f"flat direction (Fisher information: ± {n_sigmas:g} σ = {spread(sd[k])} of the "
                              f"interval with the others estimated{what})")
        identifiable[k] = not reasons[k]
    return FisherVerdict(identifiable, reasons, sd_alone, sd, partner)
