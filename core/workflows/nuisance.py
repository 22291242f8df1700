"""How much of w_opt rests on assumed model parameters: re-identification with nuisance values (beyond the paper).

The reference-date self-check (:mod:`suspid.workflows.reference`) and the data
groups (:mod:`suspid.workflows.adequacy`) see model-form error where it shows
in the data. A model whose sensitivity to an identified parameter is wrong in
the same way in every part of the data shows nothing: a damper modelled
without the series stiffness of its bushes feels a change of its rate more
than the vehicle does, on every channel and in every band; every group then
agrees on the same wrong value, and the residuals at w_opt are small.

What is known is which of the model's *other* parameters are uncertain and
over which range (the yaw damper's series stiffness, the creep coefficients'
fraction of Kalker's theory, the equivalent conicity, ...): the config lists
them as nuisance parameters, each with a plausible range. For each nuisance
parameter θ at each end of its range:

1. the reference date is simulated at w0 with θ and the noise model B fitted
   again (eq. 3): that model explains the reference date as well as the
   nominal one, since B absorbs the difference there;
2. w is identified again on the measurement date with that model and its B,
   by a bounded Nelder-Mead search started at w_opt;
3. the **shift** is that estimate minus the same search with the nominal
   model (same noise draws, so that the Monte Carlo of Y_mod cancels).

A component that some θ within its plausible range moves by more than
``max_shift`` of its admissible interval is *not trustworthy under model
error*: the data do not decide it, the assumed θ does. Every nuisance
parameter may be off at once: the sum over θ of each one's larger |shift|
bounds the bias they cause together, and the intervals are widened by it
(:func:`suspid.method.identifiability.bias_aware_half_width`). The searches cost about ``(2 n_θ + 1) · 20 q``
simulations of the measurement date and one of the reference date per end.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from suspid.infra.ledger import Ledger, stable_hash
from suspid.infra.seeds import rng as named_rng
from suspid.interfaces import Executor
from suspid.method.identifiability import NuisanceOptions
from suspid.method.noise import fit_noise_model
from suspid.method.objective import ObjectiveFunction
from suspid.workflows.problem import Problem, segment_speeds, segments_digest
from suspid.workflows.reference import SearchObjective, local_search
from suspid.workflows.tasks import SpectraTask, run_one
from suspid.elements import declared_parameters


@dataclass
class NuisanceCheck:
    """Shifts of w_opt per nuisance value: ``shifts (n_values, q)`` in fractions of the admissible interval.

    :ivar values: ``(name, SI value)`` of each row of ``shifts``.
    :ivar n_simulations: simulations made by all the searches.
    """

    values: list[tuple[str, float]]
    shifts: np.ndarray
    n_simulations: int

    def largest(self) -> tuple[np.ndarray, list[int]]:
        """``(q,)`` largest |shift| per component and the row that gives it."""
        rows = np.argmax(np.abs(self.shifts), axis=0)
        return np.abs(self.shifts[rows, np.arange(self.shifts.shape[1])]), [int(r) for r in rows]

    def per_parameter(self) -> np.ndarray:
        """``(q,)`` the sum over nuisance parameters of each one's larger |shift| (of the ends of its range):
        a bound on the shift when every parameter is off at once, each within its range (linear response)."""
        names = list(dict.fromkeys(name for name, _ in self.values))
        return sum(np.abs(self.shifts[[i for i, (n, _) in enumerate(self.values) if n == name]]).max(axis=0)
                   for name in names)

    def to_dict(self, names: list[str]) -> dict:
        return {"status": "done", "n_simulations": self.n_simulations,
                "shifts_percent": [{"parameter": p, "value": v, **{n: float(100 * s) for n, s in zip(names, row)}}
                                   for (p, v), row in zip(self.values, self.shifts)]}


def nuisance_shifts(problem: Problem, ledger: Ledger, u_opt: np.ndarray, options: NuisanceOptions,
                    initial_step: float, log: Callable[[str], None] = lambda s: None,
                    executor: Executor | None = None) -> NuisanceCheck | None:
    """The check of the module docstring, or None without nuisance parameters or reference-date data.

    Cached in the run ledger (keyed by the data, w_opt and the options), so that a
    resumed run does not simulate it again. Simulations run on ``executor``.
    """
    ref, ref_segments = problem.reference, problem.reference_segments
    if not options.parameters or not ref or not ref_segments:
        return None
    config, q = problem.config, problem.q
    values = [(name, float(v)) for name, ends in options.parameters.items() for v in ends]
    key = stable_hash("nuisance", problem.simulator_identity, problem.data_identity, segments_digest(ref_segments),
                      np.asarray(u_opt).tolist(), options.model_dump(), config.noise.model_dump(mode="json"),
                      config.objective.plugin, config.objective.options, problem.weights.tolist(),
                      config.spectra.model_dump(), config.seed, initial_step)
    cached = ledger.get_array(key)
    if cached is not None:
        return NuisanceCheck(values, cached[:, :q], int(cached[0, q]))
    noise_options = config.noise.model_dump(exclude={"path", "reference"})
    max_eval = options.max_evaluations or 20 * q
    ref_task = SpectraTask.of(problem.simulator, ref_segments, config.spectra)
    task = SpectraTask.of(problem.simulator, problem.segments, config.spectra)
    n_sims = 0

    def identify(extra: dict[str, float], y_sim0: np.ndarray) -> np.ndarray:
        """w re-identified from u_opt with the model at ``extra`` and its own B."""
        nonlocal n_sims
        model = fit_noise_model(ref["y_mes0"], y_sim0, noise_options, freqs=problem.freqs, channels=problem.channels,
                                speeds=segment_speeds(ref_segments))
        fn = ObjectiveFunction.from_noise_model(problem.objective, problem.y_mes, problem.freqs, model,
                                                named_rng(config.seed, "nuisance"),  # the same draws each time
                                                weights=problem.weights, channels=problem.channels,
                                                speeds=problem.speeds)
        neg_j = SearchObjective(problem, task, fn, executor, extra)
        found = local_search(neg_j, np.asarray(u_opt, float), initial_step, max_eval)
        n_sims += neg_j.n_simulations
        return found

    nominal = {p.name: p.nominal for p in declared_parameters(problem.simulator)}
    base = identify({}, ref["y_sim0"])
    shifts = np.zeros((len(values), q))
    for i, (name, value) in enumerate(values):
        if value == nominal.get(name):  # the nominal model again: the same search, no shift
            continue
        extra = {name: value}
        y_sim0 = run_one(executor, ref_task, problem.w0 | extra)
        n_sims += 1
        shifts[i] = identify(extra, y_sim0) - base
        log(f"nuisance {name} = {value:g}: w_opt moves by "
            + ", ".join(f"{n} {100 * d:+.1f} %" for n, d in zip(problem.names, shifts[i])))
    ledger.put_array(key, np.column_stack([shifts, np.full(len(values), n_sims)]))
    return NuisanceCheck(values, shifts, n_sims)
