"""y_sim(w) with its Jacobian for any simulator: analytic where offered, finite differences otherwise.

:func:`spectra_jacobian` runs the simulations a Jacobian of the spectra needs
(the mathematics is :mod:`suspid.method.jacobian`):

- **analytic** where the simulator offers it (:class:`~suspid.interfaces.DifferentiableSimulator`):
  one :class:`JacobianTask` gives the records with their derivatives, carried
  through eq. 1-2 exactly (:func:`~suspid.method.jacobian.spectra_derivatives`);
- **finite differences** otherwise, and for the names the simulator leaves out:
  central (2 simulations per parameter, error O(h²)) or forward (1 per
  parameter and one at w, error O(h)) with steps h = ``rel_step`` |w_p|, every
  simulation a task of the caller's executor (:mod:`suspid.workflows.tasks`),
  so that they run in parallel.

The result says which parameter took which method and how many plain
simulations the finite differences cost, so that callers count simulations honestly.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any, Literal, Mapping, Sequence

import numpy as np

from suspid import registry
from suspid.elements import declared_parameters
from suspid.errors import PluginBugError, SimulatorError, SuspidError
from suspid.interfaces import DifferentiableSimulator, Executor, Simulator, TrackSegment
from suspid.method.jacobian import DEFAULT_REL_STEP, SpectraJacobian, spectra_derivatives
from suspid.method.spectra import SpectraOptions, frequency_grid
from suspid.options import parse_options
from suspid.workflows.tasks import SpectraTask, run_one, run_tasks, simulator_instance

__all__ = ["JacobianTask", "spectra_jacobian"]


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
        sim = simulator_instance(self.simulator_cls, self.options)
        try:
            pairs = sim.simulate_jacobian(w, self.segments, list(self.names))
        except SuspidError:
            raise
        except Exception as exc:  # noqa: BLE001 - not one of suspid's errors: a bug of the plugin
            raise PluginBugError(f"{registry.describe('simulator', sim.name)} failed to differentiate at "
                                 f"w = {dict(w)}: {type(exc).__name__}: {exc}") from exc
        responses = [r for r, _ in pairs]
        # single-precision derivatives stay single (the spectra's derivatives read them as they are)
        grads = [g if isinstance(g, np.ndarray) and g.dtype in (np.float32, np.float64) else np.asarray(g, dtype=float)
                 for _, g in pairs]
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


def _steps(w: Mapping[str, float], names: Sequence[str], rel_step: float) -> np.ndarray:
    return np.array([rel_step * abs(w[n]) if w[n] != 0 else rel_step for n in names], dtype=float)


def spectra_jacobian(simulator: Simulator, w: Mapping[str, float], names: Sequence[str],
                     segments: Sequence[TrackSegment], spectra: SpectraOptions | Mapping[str, Any] | None = None,
                     *, executor: Executor | None = None,
                     method: Literal["auto", "central", "forward"] = "auto",
                     fallback: Literal["central", "forward"] = "central",
                     rel_step: float = DEFAULT_REL_STEP) -> SpectraJacobian:
    """y_sim(w) and ∂y_sim/∂w for ``names`` on ``segments`` (see the module docstring; the math: :mod:`suspid.method.jacobian`).

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
    if method not in ("auto", "central", "forward") or fallback not in ("central", "forward"):
        raise SuspidError(f"unknown differentiation method {method!r} / {fallback!r}: expected method auto, central "
                          f"or forward and fallback central or forward")
    t0 = time.perf_counter()
    names = list(names)
    declared = {p.name: p.nominal for p in declared_parameters(simulator)}   # element groups too
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
