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
from suspid.method.spectra import SpectraOptions, record_spectrum_derivatives
from suspid.options import parse_options

__all__ = ["SpectraJacobian", "spectra_derivatives", "gauss_newton_information", "linearised_shift",
           "DEFAULT_REL_STEP"]

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
    ys, dys = [], []
    for i, (r, da) in enumerate(zip(responses, d_accelerations)):
        y, dy = record_spectrum_derivatives(r.accelerations, da, r.fs, opt, name=r.segment or str(i))
        ys.append(y)
        dys.append(np.moveaxis(dy, 0, -1))
    return np.stack(ys), np.stack(dys)


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
