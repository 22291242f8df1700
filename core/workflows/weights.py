"""``objective.weights: efficient``: the channel weights α of eq. 5 estimated at the reference date, at w0.

At the reference date the truth w0 is known, so the channels' estimating functions can be judged there
before anything is identified: the simulator runs at w0 ± h e_k on the reference track (2q simulations,
h = ``identifiability.step`` in normalised units), and the replicates of the sampling interval
(:func:`suspid.workflows.analysis.bootstrap_objectives`: reference segments resampled, B fitted again,
new noise paths) give per channel the gradient g_ch ``(q,)`` of Ψ_ch and its curvature along each
component. :func:`suspid.method.weights.efficient_weights` then picks α ≥ 0, Σ α = 1, minimising the
components' sandwich variances. α is fixed before the identification: J does not see the measurement
date's data when it is chosen.
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING, Any, Callable

import numpy as np

from suspid.errors import SimulatorError
from suspid.infra.ledger import Ledger
from suspid.interfaces import Executor
from suspid.method.weights import efficient_weights

if TYPE_CHECKING:   # the problem module imports this one inside build_problem
    from suspid.workflows.problem import Problem

#: the criterion, shrinkage toward equal weights and kept share of each component's curvature used by
#: ``objective.weights: efficient`` (chosen on three runs of the independent trains: benchmarks/RESULTS.md)
CRITERION = "trace"
SHRINK = 0.0
KEEP_SHARE = 0.75


def channel_replicates(problem: "Problem", y0: np.ndarray, y_plus: list[np.ndarray], y_minus: list[np.ndarray],
                       h_plus: np.ndarray, h_minus: np.ndarray, n_redraws: int, paired: bool = True,
                       reference: bool = True, progress: Callable[[int], None] | None = None
                       ) -> tuple[np.ndarray, np.ndarray]:
    """Per bootstrap replicate (:func:`suspid.workflows.analysis.bootstrap_objectives`), component and channel,
    the gradient and curvature of Ψ_ch (unweighted) from the spectra at u and u ± h_k e_k.

    :param y0: ``(v, n_channels, n_freqs)`` dB at u; :param y_plus, y_minus: q such arrays at u ± h_k e_k.
    :param h_plus, h_minus: ``(q,)`` the steps actually taken (clipped by the box).
    :param progress: called with the number of replicates done.
    :returns: ``(g, c)``, both ``(R, q, n_channels)`` in normalised u.
    """
    from suspid.workflows.analysis import bootstrap_objectives, second_difference

    G, C = [], []
    for r, (fn, i) in enumerate(bootstrap_objectives(problem, n_redraws, paired, reference)):
        p0 = fn.evaluate(y0[i])[1]
        pp = np.array([fn.evaluate(y[i])[1] for y in y_plus])
        pm = np.array([fn.evaluate(y[i])[1] for y in y_minus])
        G.append((pp - pm) / (h_plus + h_minus)[:, None])
        C.append(second_difference(p0[None, :], pp, pm, h_plus, h_minus))
        if progress is not None:
            progress(r + 1)
    return np.array(G), np.array(C)


def reference_channel_replicates(problem: "Problem", ledger: Ledger, h: float, n_redraws: int, paired: bool = True,
                                 executor: Executor | None = None) -> tuple[np.ndarray, np.ndarray, int]:
    """Per replicate, component and channel, the gradient and curvature of Ψ_ch at w0 on the reference date.

    :param problem: a :class:`~suspid.workflows.problem.Problem` with the reference date's data
        (``problem.reference`` and ``problem.reference_segments``).
    :returns: ``(g, c, n_simulations)``, g and c ``(R, q, n_channels)`` in normalised u (c NaN along a
        component whose ±h point failed or sits on a bound), and the plain simulations w0 ± h took.
    """
    from suspid.workflows.analysis import cached_y_sim, simulate_missing

    names, q, n = problem.names, problem.q, len(problem.channels)
    ref = replace(problem, segments=list(problem.reference_segments), y_mes=problem.reference["y_mes0"],
                  b=problem.b[:0], b_more=None, weights=np.full(n, 1.0 / n))
    u0 = problem.to_unit(np.array([problem.w0[k] for k in names], float))
    plus = np.clip(u0 + h * np.eye(q), 0.0, 1.0)
    minus = np.clip(u0 - h * np.eye(q), 0.0, 1.0)
    points = [u for u in (*plus, *minus) if not np.allclose(u, u0)]
    simulate_missing(ref, ledger, points, executor)
    y0 = problem.reference["y_sim0"]

    def at(u: np.ndarray) -> np.ndarray | None:
        if np.allclose(u, u0):
            return y0
        try:
            return cached_y_sim(ref, ledger, u)
        except SimulatorError:
            return None

    yp, ym = [at(u) for u in plus], [at(u) for u in minus]
    hp, hm = np.diag(plus) - u0, u0 - np.diag(minus)
    ok = np.array([a is not None and b is not None for a, b in zip(yp, ym)]) & (hp > 0) & (hm > 0)
    yp = [y if good else y0 for y, good in zip(yp, ok)]
    ym = [y if good else y0 for y, good in zip(ym, ok)]
    hp_, hm_ = np.where(ok, hp, 1.0), np.where(ok, hm, 1.0)
    G, C = channel_replicates(ref, y0, yp, ym, hp_, hm_, n_redraws, paired, reference=True)
    return G, np.where(ok[None, :, None], C, np.nan), len(points)


def reference_efficient_weights(problem: "Problem", ledger: Ledger, executor: Executor | None = None,
                                criterion: str = CRITERION, shrink: float = SHRINK, keep_share: float = KEEP_SHARE
                                ) -> tuple[np.ndarray, dict[str, Any]]:
    """α of eq. 5 for ``objective.weights: efficient`` and its record for ``result.json``.

    :returns: ``(alpha (n_channels,), record)``; the record names the channels' weights, the components
        the criterion used, each component's diagonal sandwich half-width (2σ, % of its interval) at the
        reference date with equal and with these weights, and the simulations it took.
    """
    opts = problem.config.identifiability
    g, c, n_sims = reference_channel_replicates(problem, ledger, opts.step, opts.n_redraws,
                                                opts.bootstrap == "paired", executor)
    keep = ~np.isnan(c).any(axis=(0, 2))       # components whose three points all simulated
    g_use, c_use = g[:, keep], c[:, keep]
    est = efficient_weights(g_use, c_use, criterion, shrink, keep_share)
    names = [n for n, k in zip(problem.names, keep) if k]
    used = [names[k] for k in est.components]

    def half(v: np.ndarray) -> dict[str, float | None]:
        return {nm: (float(200 * np.sqrt(x)) if np.isfinite(x) else None) for nm, x in zip(names, v)}

    record = {
        "method": "efficient",
        "alpha": {ch: float(a) for ch, a in zip(problem.channels, est.alpha)},
        "how": (f"estimating-equation weights at the reference date at w0: {g.shape[0]} bootstrap replicates of "
                f"its {len(problem.reference_segments)} segments, gradient and diagonal curvature of each "
                f"channel's Ψ from w0 ± {opts.step:g} (normalised), α ≥ 0 minimising the {criterion} of the "
                f"components' sandwich variances, each component keeping {keep_share:g} of its equal-weight share of the "
                f"curvatures" + (f", shrunk {shrink:g} toward equal" if shrink else "")),
        "components": used,
        "half_width_equal_percent": half(est.variance_equal),
        "half_width_percent": half(est.variance),
        "n_simulations": int(n_sims),
    }
    return est.alpha, record
