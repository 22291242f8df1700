"""Derivatives of the simulated spectra y_sim(w) with respect to named parameters.

The objective J (eq. 5-8) reads the model only through the spectra y_sim_i(w)
``(v, n_channels, n_freqs)`` dB of eq. 1-2; their Jacobian
``(v, n_channels, n_freqs, n_p)`` dB per SI unit of each parameter is what a
gradient-based search, a Fisher information or a linearised model-error check
needs. :func:`spectra_jacobian` gives it for any simulator:

- **analytic** where the simulator offers it (:class:`~suspid.interfaces.DifferentiableSimulator`):
  the derivatives dA of its records are carried through eq. 1-2 exactly. With
  Â the record's Fourier amplitude (detrend and window are linear, so dÂ is
  the amplitude of dA) and P_j the mean of |Â|² over the lines of cell j,
  y_j = 5 log10 P_j and ∂y_j = (5 / ln 10) ∂P_j / P_j, ∂P_j the cell mean of
  2 Re(conj(Â) dÂ) (0 where P_j sits at the amplitude floor);
- **finite differences** otherwise, and for the names the simulator leaves out:
  central (2 simulations per parameter, error O(h²)) or forward (1 per
  parameter and one at w, error O(h)) with steps h = ``rel_step`` |w_p|, every
  simulation a task of the caller's executor, so that they run in parallel.

The result says which parameter took which method and how many plain
simulations the finite differences cost, so that callers count simulations
honestly. Helpers for the trust checks work from the same Jacobians: the
Fisher information (:func:`gauss_newton_information`) and the first-order shift of
the estimate with a model parameter held at a wrong value (:func:`linearised_shift`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any, Literal, Mapping, Sequence

import numpy as np

from suspid import registry
from suspid.errors import PluginBugError, SimulatorError, SuspidError
from suspid.interfaces import DifferentiableSimulator, Executor, Response, Simulator, TrackSegment
from suspid.method.spectra import SpectraOptions, record_spectrum_derivatives
from suspid.options import parse_options
from suspid.elements import declared_parameters

__all__ = ["SpectraJacobian", "JacobianTask", "spectra_jacobian", "spectra_derivatives",
           "gauss_newton_information", "linearised_shift", "DEFAULT_REL_STEP"]

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


@dataclass(frozen=True)
class JacobianTask:
    """Worker side of an analytic Jacobian: ``task(w) -> (y, dy, freqs)`` on fixed segments and names.

    Picklable like :class:`suspid.workflows.tasks.SpectraTask` (the simulator is built once per process).
    """

    simulator_cls: type
    options: dict
    segments: list
    spectra: Any
    names: tuple[str, ...]

    def __call__(self, w: dict[str, float]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        from suspid.method.spectra import frequency_grid
        from suspid.workflows.tasks import _simulator

        sim = _simulator(self.simulator_cls, self.options)
        try:
            pairs = sim.simulate_jacobian(w, self.segments, list(self.names))
        except SuspidError:
            raise
        except Exception as exc:  # noqa: BLE001 - not one of suspid's errors: a bug of the plugin
            raise PluginBugError(f"{registry.describe('simulator', sim.name)} failed to differentiate at "
                                 f"w = {dict(w)}: {type(exc).__name__}: {exc}") from exc
        responses = [r for r, _ in pairs]
        grads = [np.asarray(g, dtype=float) for _, g in pairs]
        for r, g in zip(responses, grads):
            if g.shape != (len(self.names),) + np.shape(r.accelerations):
                raise PluginBugError(f"{registry.describe('simulator', sim.name)}: simulate_jacobian returned "
                                     f"derivatives of shape {g.shape} for segment '{r.segment}', expected "
                                     f"{(len(self.names),) + np.shape(r.accelerations)}")
            if not (np.all(np.isfinite(g)) and np.all(np.isfinite(r.accelerations))):
                raise SimulatorError(f"simulator '{sim.name}' returned non-finite derivatives for segment "
                                     f"'{r.segment}' at w = {dict(w)}")
        y, dy = spectra_derivatives(responses, grads, self.spectra)
        return y, dy, frequency_grid(self.spectra)[0]


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


def _steps(w: Mapping[str, float], names: Sequence[str], rel_step: float) -> np.ndarray:
    return np.array([rel_step * abs(w[n]) if w[n] != 0 else rel_step for n in names], dtype=float)


def spectra_jacobian(simulator: Simulator, w: Mapping[str, float], names: Sequence[str],
                     segments: Sequence[TrackSegment], spectra: SpectraOptions | Mapping[str, Any] | None = None,
                     *, executor: Executor | None = None,
                     method: Literal["auto", "central", "forward"] = "auto",
                     fallback: Literal["central", "forward"] = "central",
                     rel_step: float = DEFAULT_REL_STEP) -> SpectraJacobian:
    """y_sim(w) and ∂y_sim/∂w for ``names`` on ``segments`` (see the module docstring).

    :param simulator: any simulator; analytic derivatives are used where it is a
        :class:`~suspid.interfaces.DifferentiableSimulator` and ``method`` is ``"auto"``.
    :param w: parameter name -> SI value; parameters not named keep their nominal values.
    :param names: the parameters to differentiate (identified ones or model parameters).
    :param executor: where the simulations run (entered; in this process without one).
    :param method: ``"auto"``: analytic where offered, ``fallback`` for the rest; ``"central"`` or
        ``"forward"``: finite differences for every parameter.
    :param rel_step: relative step of the finite differences.
    :raises SimulatorError: a simulation failed (the first failure's error).
    :raises SuspidError: an unknown method or a parameter the simulator does not declare (one line).
    """
    from suspid.workflows.tasks import SpectraTask, run_one, run_tasks

    if method not in ("auto", "central", "forward") or fallback not in ("central", "forward"):
        raise SuspidError(f"unknown differentiation method {method!r} / {fallback!r}: expected method auto, central "
                          f"or forward and fallback central or forward")
    t0 = time.perf_counter()
    names = list(names)
    declared = {p.name: p.nominal for p in declared_parameters(simulator)}
    unknown = [n for n in names if n not in declared]
    if unknown:
        raise SuspidError(f"parameter(s) {', '.join(unknown)} not declared by simulator '{simulator.name}' "
                          f"(declared: {', '.join(declared)})")
    point = {n: float(w[n]) if n in w else float(declared[n]) for n in names}
    full = {**{k: float(v) for k, v in w.items()}, **point}
    opt = parse_options(SpectraOptions, spectra, "spectra")
    analytic: list[str] = []
    if method == "auto" and isinstance(simulator, DifferentiableSimulator):
        analytic = [n for n in simulator.differentiable(names) if n in names]
    scheme = fallback if method == "auto" else method
    y = None
    jac: dict[str, np.ndarray] = {}
    freqs = None
    n_analytic = 0
    if analytic:
        task = JacobianTask(type(simulator), dict(simulator.options), list(segments), opt, tuple(analytic))
        try:
            y, dy, freqs = run_one(executor, task, full)
        except SimulatorError:
            # the analytic route can fail where a plain solve does not (e.g. ill-conditioned modes, which the
            # plain solve bridges by a direct solve): every name is then differenced instead of ending the run
            analytic = []
        else:
            n_analytic = 1
            for k, n in enumerate(analytic):
                jac[n] = dy[..., k]
    rest = [n for n in names if n not in analytic]
    methods = {n: ("analytic" if n in analytic else scheme) for n in names}
    jobs: list[dict[str, float]] = []
    h = _steps(point, rest, rel_step)
    for n, step in zip(rest, h):
        jobs.append({**full, n: point[n] + step})
        if scheme == "central":
            jobs.append({**full, n: point[n] - step})
    need_base = y is None
    if need_base:
        jobs.append(dict(full))
    task = SpectraTask.of(simulator, segments, opt, with_freqs=True)
    outcomes = run_tasks(executor, [(task, job) for job in jobs])
    for outcome in outcomes:
        if isinstance(outcome, BaseException):
            raise outcome
    if need_base:
        y, freqs = outcomes[-1]
    for k, (n, step) in enumerate(zip(rest, h)):
        if scheme == "central":
            jac[n] = (outcomes[2 * k][0] - outcomes[2 * k + 1][0]) / (2 * step)
        else:
            jac[n] = (outcomes[k][0] - y) / step
    J = np.stack([jac[n] for n in names], axis=-1) if names else np.zeros(np.shape(y) + (0,))
    return SpectraJacobian(names=names, w=point, y=np.asarray(y), freqs=np.asarray(freqs), jacobian=J,
                           methods=methods, n_simulations=len(jobs), n_analytic_calls=n_analytic,
                           wall_time_s=time.perf_counter() - t0)


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
