"""Does each part of the data tell the same w? Re-identification on data groups (beyond the paper).

If the model's physics is right, every part of the data that carries
information about a parameter points to the same value (up to sampling). A
model whose sensitivity to a parameter differs from the vehicle's, in shape
over frequency or between directions, makes the parts disagree: the lateral
channels ask for one yaw-damper rate and the vertical ones, where the model
feels the damper but the vehicle does not, for another. w_opt is then a
compromise set by where the model is wrong, not a measurement.

:func:`group_estimates` re-identifies w on data groups, starting from w_opt,
with the run's objective, noise paths and weights restricted to the group:

- *directions*: channels grouped by the last word of their name
  (``carbody_front_vertical`` -> ``vertical``);
- *frequency halves*: the grid below and above its geometric middle.

In each group only the parameters with at least ``min_group_share`` of their
information there (S_k² / Var B, :mod:`suspid.method.adequacy`) are free; the
others stay at w_opt. A bounded Nelder-Mead search (cheap next to the EGO
run: simulations at nearby points) gives each group's estimate.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy.optimize import minimize

from suspid.errors import ClusterError, SuspidError
from suspid.infra.ledger import Ledger, stable_hash
from suspid.interfaces import Executor
from suspid.method.objective import ObjectiveFunction
from suspid.workflows.problem import Problem
from suspid.workflows.tasks import SpectraTask, run_one


@dataclass
class Group:
    """One data group: a name, a channel mask ``(n_channels,)`` and a frequency mask ``(n_freqs,)``."""

    name: str
    channels: np.ndarray
    freqs: np.ndarray


def data_groups(channels: list[str], freqs: np.ndarray) -> list[Group]:
    """Direction groups (by the last word of the channel names) and the two frequency halves."""
    words = [c.rsplit("_", 1)[-1] for c in channels]
    groups = []
    if len(set(words)) > 1:
        for word in dict.fromkeys(words):
            groups.append(Group(f"{word} channels", np.array([w == word for w in words]),
                                np.ones(len(freqs), bool)))
    middle = float(np.sqrt(freqs[0] * freqs[-1]))
    all_ch = np.ones(len(channels), bool)
    groups.append(Group(f"below {middle:.2g} Hz", all_ch, freqs < middle))
    groups.append(Group(f"above {middle:.2g} Hz", all_ch, freqs >= middle))
    return groups


def group_information(S: np.ndarray, variance: np.ndarray, weights: np.ndarray,
                      groups: list[Group]) -> np.ndarray:
    """``(n_groups, q)``: each parameter's share of its information (S² / Var B · α) in each group."""
    cell = S ** 2 / np.maximum(variance, 1e-12)[None] * np.asarray(weights, float)[None, :, None]
    total = np.maximum(cell.sum(axis=(1, 2)), 1e-300)
    return np.array([cell[:, g.channels][:, :, g.freqs].sum(axis=(1, 2)) / total for g in groups])


@dataclass
class GroupEstimates:
    """Per group, the re-identified w (``(n_groups, q)`` in [0, 1], NaN where the parameter is not free)."""

    groups: list[Group]
    share: np.ndarray
    u: np.ndarray
    n_simulations: int


def group_estimates(problem: Problem, u_opt: np.ndarray, S: np.ndarray, min_group_share: float,
                    max_evaluations: int, initial_step: float, ledger: Ledger | None = None,
                    executor: Executor | None = None,
                    spectra_at: Callable[[np.ndarray], np.ndarray] | None = None) -> GroupEstimates:
    """Re-identify the free parameters of every group from ``u_opt`` (see the module docstring).

    Each simulation runs on ``executor`` (entered; in this process without one).

    With a ``ledger`` the estimates are cached there (keyed by the run's data, w_opt and the
    options), so that a resumed run does not simulate them again.

    :param spectra_at: the measurement date's spectra ``(v, n_channels, n_freqs)`` dB at a point of [0, 1]^q
        instead of simulations (the spectra linearised at w_opt, :mod:`suspid.workflows.linearised`).
    """
    groups = data_groups(problem.channels, problem.freqs)
    share = group_information(S, problem.noise_model.variance_, problem.weights, groups)
    key, legacy = (stable_hash("data-groups", problem.simulator_identity, data, np.asarray(u_opt).tolist(),
                               min_group_share, max_evaluations, initial_step)
                   for data in (problem.data_identity, problem.legacy_identity))
    cached = ledger.get_array_migrating(key, [legacy]) if ledger is not None else None
    if cached is not None:
        return GroupEstimates(groups, share, cached[:, :-1], int(cached[0, -1]))
    u_hat = np.full((len(groups), problem.q), np.nan)
    spectra: dict[bytes, np.ndarray | None] = {}
    task = SpectraTask.of(problem.simulator, problem.segments, problem.config.spectra)
    n_sims = 0

    def y_at(u: np.ndarray) -> np.ndarray | None:
        nonlocal n_sims
        if spectra_at is not None:
            return spectra_at(u)
        k = np.round(u, 6).tobytes()
        if k not in spectra:
            try:
                spectra[k] = run_one(executor, task, problem.w_of(problem.from_unit(u)))
            except ClusterError:
                raise
            except SuspidError:
                spectra[k] = None
            n_sims += 1
        return spectra[k]

    for gi, g in enumerate(groups):
        free = np.flatnonzero(share[gi] >= min_group_share)
        if free.size == 0:
            continue
        ch, fr = g.channels, g.freqs
        w = problem.weights * ch
        fn = ObjectiveFunction(problem.objective, problem.y_mes[:, :, fr], problem.freqs[fr],
                               problem.b[:, :, fr], weights=w / w.sum(), channels=problem.channels,
                               floor=None if problem.noise_model.floor_ is None else problem.noise_model.floor_.at(fr))

        def neg_j(x: np.ndarray) -> float:
            u = u_opt.copy()
            u[free] = np.clip(x, 0.0, 1.0)
            y = y_at(u)
            return np.inf if y is None else -float(fn.evaluate(y[:, :, fr])[0])

        x0 = u_opt[free]
        simplex = np.vstack([x0] + [np.clip(x0 + initial_step * e * np.where(x0 < 0.5, 1, -1), 0, 1)
                                    for e in np.eye(free.size)])
        res = minimize(neg_j, x0, method="Nelder-Mead",
                       options={"initial_simplex": simplex, "maxfev": max_evaluations * free.size,
                                "xatol": 2e-3, "fatol": 1e-7})
        u_hat[gi, free] = np.clip(res.x, 0, 1)
    if ledger is not None:
        ledger.put_array(key, np.column_stack([u_hat, np.full(len(groups), n_sims)]))
    return GroupEstimates(groups, share, u_hat, n_sims)
