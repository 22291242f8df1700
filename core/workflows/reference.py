"""The reference-date self-check: how far model-form error alone moves w_opt (beyond the paper).

At the reference date the truth is known: the train ran at w0. The noise model
B is identified there (eq. 3) and then taken to another date, where it is
supposed to hold for every w. The self-check makes that step on data whose
answer is known:

1. the v0 reference segments are split at random into two halves, A and B
   (``n_splits`` repetitions, seeded by the run's seed);
2. a noise model is fitted on half A (eq. 3, the run's ``noise:`` options);
3. w is identified on half B with the run's objective, weights and the
   noise paths of that model, by a bounded Nelder-Mead search started at w0
   (the simulator is cheap next to a whole EGO run, and the search stays
   near w0, where the answer should be);
4. per component, the shift u_opt − u0 (in [0, 1], i.e. in fractions of the
   admissible interval) is averaged over the splits: its mean is the
   **self-check bias**, its scatter over the splits the sampling part.

Why random halves rather than k-fold: the check imitates the two-date
protocol, which fits B on one set of segments and identifies on another of
comparable size; a k-fold split with k > 2 would identify on v0/k segments,
too few for the kernel densities of the objective, and halves repeated with
new draws average the sampling scatter out of the bias.

With the same model on both sides the shift is sampling scatter only; with a
model that differs from the vehicle (another damper law, another creep model,
a flexible carbody) the discrepancy depends on the track of each segment, B
cannot absorb it, and w_opt moves: that is the bias a measurement at w0 would
show. What the check cannot see is a model whose *sensitivity* to a parameter
is wrong (the response of the real vehicle changes less, or otherwise, with
that parameter): at w0 nothing changes. That is what the adequacy test at
w_opt looks for (:mod:`suspid.method.adequacy`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy.optimize import minimize

from suspid.errors import ClusterError, SuspidError
from suspid.infra.ledger import Ledger, stable_hash
from suspid.infra.seeds import rng as named_rng
from suspid.interfaces import Executor
from suspid.method.identifiability import SelfCheckOptions
from suspid.method.noise import fit_noise_model
from suspid.method.objective import ObjectiveFunction
from suspid.workflows.problem import Problem, segments_digest
from suspid.workflows.tasks import SpectraTask, run_one


def local_search(neg_j: Callable[[np.ndarray], float], u0: np.ndarray, initial_step: float,
                 max_evaluations: int) -> np.ndarray:
    """A bounded Nelder-Mead search of min ``neg_j`` over [0, 1]^q from ``u0 (q,)``; returns the minimiser.

    The initial simplex steps ``initial_step`` along each axis, towards the box's
    middle, so that every vertex is inside the box.
    """
    simplex = np.vstack([u0] + [np.clip(u0 + initial_step * e * (1 if u0[i] < 0.5 else -1), 0, 1)
                                for i, e in enumerate(np.eye(u0.size))])
    res = minimize(neg_j, u0, method="Nelder-Mead",
                   options={"initial_simplex": simplex, "maxfev": max_evaluations, "xatol": 2e-3, "fatol": 1e-6})
    return np.clip(res.x, 0, 1)


class SearchObjective:
    """−J at u ∈ [0, 1]^q for a local search: ``task`` simulated at u on ``executor``, J by ``fn``.

    Values are cached by u (rounded to 1e-6); a point whose simulation fails
    (an unstable vehicle) is +inf, simply a bad one for the search.

    :param extra: SI values of not-identified model parameters added to every w.
    :ivar n_simulations: simulations made so far.
    """

    def __init__(self, problem: Problem, task: SpectraTask, fn: ObjectiveFunction, executor: Executor | None,
                 extra: dict[str, float] | None = None) -> None:
        self.problem, self.task, self.fn, self.executor = problem, task, fn, executor
        self.extra = dict(extra or {})
        self.cache: dict[bytes, float] = {}
        self.n_simulations = 0

    def __call__(self, u: np.ndarray) -> float:
        u = np.clip(u, 0.0, 1.0)
        k = np.round(u, 6).tobytes()
        if k not in self.cache:
            w = self.problem.w_of(self.problem.from_unit(u)) | self.extra
            try:
                self.cache[k] = -float(self.fn.evaluate(run_one(self.executor, self.task, w))[0])
            except ClusterError:
                raise
            except SuspidError:
                self.cache[k] = np.inf
            self.n_simulations += 1
        return self.cache[k]


@dataclass
class SelfCheck:
    """Result of the self-check; arrays ``(q,)`` in fractions of the admissible interval.

    :ivar bias: mean over the splits of u_opt − u0.
    :ivar scatter: standard deviation over the splits (0 with one split).
    :ivar shifts: ``(n_splits, q)`` every split's u_opt − u0.
    :ivar n_evaluations: simulations made (all splits).
    """

    bias: np.ndarray
    scatter: np.ndarray
    shifts: np.ndarray
    n_fit: int
    n_identify: int
    n_evaluations: int

    def to_dict(self, names: list[str]) -> dict:
        return {"bias_percent": {n: float(100 * b) for n, b in zip(names, self.bias)},
                "scatter_percent": {n: float(100 * s) for n, s in zip(names, self.scatter)},
                "shifts_percent": [{n: float(100 * s) for n, s in zip(names, row)} for row in self.shifts],
                "n_splits": int(self.shifts.shape[0]), "segments_fit": self.n_fit,
                "segments_identify": self.n_identify, "n_simulations": self.n_evaluations}


SELF_CHECK_MIN_SEGMENTS = 8
"""Reference-date segments the self-check needs: it fits B on half of them and identifies on the other half."""


def self_check_missing(problem: Problem) -> str | None:
    """Why the self-check cannot run on this problem's data, with what to do (None: it can)."""
    if not problem.reference or not problem.reference_segments:
        if problem.config.noise.path is not None:
            return ("the reference date's data are not part of this run: the noise model is read from noise.path "
                    f"(give noise.reference, the reference date's measured data, with at least "
                    f"{SELF_CHECK_MIN_SEGMENTS} segments)")
        return (f"the reference date's data are not part of this run (give noise.reference with at least "
                f"{SELF_CHECK_MIN_SEGMENTS} segments)")
    n = len(problem.reference_segments)
    if n < SELF_CHECK_MIN_SEGMENTS:
        return (f"the reference date has {n} segments, the self-check needs {SELF_CHECK_MIN_SEGMENTS} (record "
                f"more kilometres at constant speed on the reference date, or cut shorter segments)")
    return None


def self_check(problem: Problem, ledger: Ledger, options: SelfCheckOptions,
               log: Callable[[str], None] = lambda s: None, executor: Executor | None = None,
               extra: dict[str, float] | None = None) -> SelfCheck | None:
    """The self-check of the module docstring, or None without reference-date data (or fewer than 8 segments).

    Each simulation of the searches runs on ``executor`` (entered; in this process without one).

    :param extra: SI values of not-identified model parameters (the ones calibrated at the reference date): the
        model checked is then that one, its reference-date spectra simulated once more at w0 with them.

    The result is cached in the run ledger (keyed by the reference data, the
    simulator, the objective and the options), so a resumed run does not redo it.
    """
    ref = problem.reference
    segments = problem.reference_segments
    if not ref or not segments or len(segments) < SELF_CHECK_MIN_SEGMENTS:
        return None
    config = problem.config
    y_mes0 = ref["y_mes0"]
    v0, q = y_mes0.shape[0], problem.q
    u0 = problem.to_unit(np.array([problem.w0[n] for n in problem.names]))
    max_eval = options.max_evaluations or 30 * q
    common = (problem.simulator_identity, segments_digest(segments), problem.names, problem.bounds.tolist(),
              options.model_dump())
    extras = [dict(extra)] if extra else []
    key = stable_hash("self-check", *common, problem.reference_identity, problem.noise_identity,
                      problem.weights_identity, config.objective.plugin, config.objective.options,
                      config.spectra.model_dump(), config.seed, *extras)
    legacy = stable_hash("self-check", *common, config.noise.model_dump(mode="json"), config.objective.plugin,
                         config.objective.options, problem.weights.tolist(), config.spectra.model_dump(), config.seed,
                         *extras)   # ledgers written before the input identities
    cached = ledger.get_array_migrating(key, [legacy])
    n_fit = v0 // 2
    if cached is not None:
        shifts = cached[:, :q]
        return SelfCheck(shifts.mean(axis=0), shifts.std(axis=0, ddof=1) if len(shifts) > 1 else 0 * u0,
                         shifts, n_fit, v0 - n_fit, int(cached[0, q]))
    rng = named_rng(config.seed, "self-check")
    noise_options = config.noise.model_dump(exclude={"path", "reference"})
    n_sims = 0
    y_sim0 = ref["y_sim0"]
    if extra:
        y_sim0 = run_one(executor, SpectraTask.of(problem.simulator, segments, config.spectra), problem.w0 | extra)
        n_sims += 1
    shifts = np.empty((options.n_splits, q))
    for s in range(options.n_splits):
        perm = rng.permutation(v0)
        a, b = np.sort(perm[:n_fit]), np.sort(perm[n_fit:])
        model = fit_noise_model(y_mes0[a], y_sim0[a], noise_options, freqs=problem.freqs,
                                channels=problem.channels, speeds=[segments[i].mean_speed for i in a])
        fn = ObjectiveFunction.from_noise_model(problem.objective, y_mes0[b], problem.freqs, model, rng,
                                                weights=problem.weights, channels=problem.channels,
                                                speeds=[segments[i].mean_speed for i in b])
        task = SpectraTask.of(problem.simulator, [segments[i] for i in b], config.spectra)
        neg_j = SearchObjective(problem, task, fn, executor, extra)
        shifts[s] = local_search(neg_j, u0, options.initial_step, max_eval) - u0
        n_sims += neg_j.n_simulations
        log(f"self-check split {s + 1}/{options.n_splits}: shift "
            + ", ".join(f"{n} {100 * d:+.1f} %" for n, d in zip(problem.names, shifts[s])))
    ledger.put_array(key, np.column_stack([shifts, np.full(options.n_splits, n_sims)]))
    return SelfCheck(shifts.mean(axis=0), shifts.std(axis=0, ddof=1) if options.n_splits > 1 else 0 * u0,
                     shifts, n_fit, v0 - n_fit, n_sims)
