"""The whole identification chain of the paper, as ``suspid run`` runs it.

1. data: the measured spectra y_mes (or the numerical experiment of §3.3,
   :mod:`suspid.data.experiment`), and the noise model B identified at the
   reference date (§2.3) or loaded from a file;
2. J(w) = Σ α_k Ψ_k(w) (eq. 5) with Y_mod = Y_sim(w) + b_i, the paths b_i
   drawn once from the run's seed (common random numbers);
3. J on the maximin design of m0 points, the Kriging surrogate, EGO (eq. 9);
4. identifiability, intervals, ``result.json`` and ``report.md``.

Every evaluation of J is committed to the run ledger the moment it
finishes. The whole chain is deterministic for a given config, so a run that
was interrupted is resumed by running it again: the design and the EGO steps
are retraced and every finished evaluation is read from the ledger instead of
being simulated again.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np
import yaml

from suspid import registry
from suspid.config import Config, build_simulator, identified_bounds, raise_validation_error
from suspid.errors import ConfigError, SimulatorError
from suspid.interfaces import Response, Simulator, TrackSegment
from suspid.infra.ledger import Evaluation, Ledger, evaluation_key, stable_hash
from suspid.infra.seeds import rng as named_rng
from suspid.infra.seeds import seed_for
from suspid.infra.threads import single_blas_thread


def array_digest(*arrays: np.ndarray) -> str:
    """A content hash of arrays (shape, dtype and bytes)."""
    import hashlib

    h = hashlib.sha256()
    for a in arrays:
        a = np.ascontiguousarray(a)
        h.update(str((a.shape, a.dtype.str)).encode())
        h.update(a.tobytes())
    return h.hexdigest()


def segments_digest(segments: Sequence[TrackSegment]) -> str:
    """A content hash of track segments (geometry, distance and speed)."""
    parts = []
    for s in segments:
        parts.append(array_digest(np.asarray(s.distance, float), np.asarray(s.irregularities, float),
                                  np.atleast_1d(np.asarray(s.speed, float))))
    return stable_hash(parts)


@dataclass
class Problem:
    """Everything J(w) needs, built once per run.

    :ivar names: identified parameter names, ``(q,)``.
    :ivar bounds: ``(q, 2)`` SI lower and upper bounds.
    :ivar segments: measurement-date track segments (v of them).
    :ivar y_mes: ``(v, n_channels, n_freqs)`` dB measured spectra.
    :ivar b: ``(v, n_channels, n_freqs)`` dB noise paths for Y_mod.
    :ivar freqs: ``(n_freqs,)`` Hz.
    """

    config: Config
    simulator: Simulator
    names: list[str]
    bounds: np.ndarray
    segments: list[TrackSegment]
    channels: list[str]
    freqs: np.ndarray
    y_mes: np.ndarray
    b: np.ndarray
    objective: Any
    weights: np.ndarray
    data_identity: str
    w_ref: dict[str, float] | None = None
    reference: dict[str, np.ndarray] = field(default_factory=dict)  # y_mes0, y_sim0 at the reference date
    noise_model: Any = None

    @property
    def q(self) -> int:
        return len(self.names)

    def w_of(self, x_si: np.ndarray) -> dict[str, float]:
        return {n: float(v) for n, v in zip(self.names, np.asarray(x_si, float))}

    def to_unit(self, x_si: np.ndarray) -> np.ndarray:
        lo, hi = self.bounds[:, 0], self.bounds[:, 1]
        return (np.asarray(x_si, float) - lo) / (hi - lo)

    def from_unit(self, u: np.ndarray) -> np.ndarray:
        lo, hi = self.bounds[:, 0], self.bounds[:, 1]
        return lo + np.asarray(u, float) * (hi - lo)


# -- building the problem -------------------------------------------------------------
def _cached_spectra(ledger: Ledger, key: str, make: Callable[[], tuple[np.ndarray, np.ndarray]]
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Spectra ``(y, freqs)`` from the ledger's artifacts, or computed and stored there."""
    y, f = ledger.get_array(key + ":y"), ledger.get_array(key + ":freqs")
    if y is None or f is None:
        y, f = make()
        ledger.put_array(key + ":y", y)
        ledger.put_array(key + ":freqs", f)
    return y, f


def _simulate_spectra(simulator: Simulator, w: dict[str, float], segments: Sequence[TrackSegment],
                      spectra_options: Any, transform: Callable[[list[Response]], list[Response]] | None = None
                      ) -> tuple[np.ndarray, np.ndarray]:
    from suspid.method.spectra import compute_spectra

    responses = simulator.simulate(w, segments)
    if transform is not None:
        responses = transform(responses)
    return compute_spectra(responses, spectra_options)


def synthetic_track(config: Config, date: str, n_segments: int | None = None) -> list[TrackSegment]:
    """The synthetic track of one date of a numerical experiment (seeded by the config's seed)."""
    from suspid.data.track import synthetic_segments

    options = dict(config.data.track)
    if n_segments is not None:
        options["n_segments"] = n_segments
    options.setdefault("seed", seed_for(config.seed, f"track-{date}"))
    try:
        return synthetic_segments(options)
    except ConfigError as exc:
        raise ConfigError(exc.detail, file=str(config.source_file), key=exc.key) from None


def read_measurements(measurements: Path, track_file: Path | None, channels: Sequence[str]
                      ) -> tuple[list[TrackSegment], list[Response]]:
    """Measured accelerations and the track geometry measured with them, paired by segment name.

    :raises DataError: naming the file, when a segment has no track, the
        channels differ, or a record's duration does not match its segment.
    """
    from suspid.errors import DataError
    from suspid.data.track import read_accelerations, read_track

    if track_file is None:
        raise DataError(f"{measurements}: measured accelerations need the track measured with them "
                        f"(data.track_file)")
    files = sorted(Path(measurements).glob("*.csv")) if Path(measurements).is_dir() else [Path(measurements)]
    records = [(f, r) for f in files for r in read_accelerations(f, channels)]  # each error names its file
    if not records:
        raise DataError(f"{measurements}: no acceleration records found")
    by_name = {s.name: s for s in read_track(track_file)}
    segments = []
    for f, r in records:
        seg = by_name.get(r.segment)
        if seg is None:
            raise DataError(f"{f}: record '{r.segment}' has no track segment of that name in "
                            f"{track_file} (segments: {', '.join(sorted(by_name)) or 'none'})")
        expected = seg.duration()
        if abs(r.duration - expected) > max(0.02 * expected, 2.0 / r.fs):
            raise DataError(f"{f}: record '{r.segment}' lasts {r.duration:.2f} s but its track "
                            f"segment takes {expected:.2f} s at the recorded speed")
        segments.append(seg)
    return segments, [r for _, r in records]


def check_sections(config: Config) -> None:
    """Validate the sections that their modules read later (spectra, noise, design, ego, ...).

    Called before any simulation, so that a typo in ``ego:`` does not wait
    for the reference date to be simulated, nor one in ``identifiability:``
    for the end of the run.

    :raises ConfigError: one line naming the file and the key.
    """
    from suspid.optimize.design import DesignOptions
    from suspid.optimize.ego import EGOOptions
    from suspid.data.experiment import MeasurementOptions, ReferenceOptions
    from suspid.method.identifiability import IdentifiabilityOptions
    from suspid.method.noise import NoiseOptions
    from suspid.method.spectra import SpectraOptions
    from suspid.data.track import TrackOptions

    file = str(config.source_file)
    noise = {k: v for k, v in config.noise.items() if k != "path"}
    checks = [(SpectraOptions, config.spectra, "spectra"), (NoiseOptions, noise, "noise"),
              (DesignOptions, config.design, "design"), (EGOOptions, config.ego, "ego"),
              (IdentifiabilityOptions, config.identifiability, "identifiability")]
    if config.data.source == "experiment":
        checks += [(TrackOptions, config.data.track, "data.track"),
                   (ReferenceOptions, config.data.reference, "data.reference"),
                   (MeasurementOptions, config.data.measurement, "data.measurement")]
    for model, values, section in checks:
        _section_with_seed(model, values, 0, section, file)


def validate_data(config: Config) -> int:
    """Read and check measured data as a run would (files, channels, durations, spectra grid).

    :returns: the number of measured segments (0 for a numerical experiment).
    :raises DataError: one line naming the file and what is wrong.
    """
    if config.data.source != "measured":
        return 0
    from suspid.method.spectra import compute_spectra

    simulator = build_simulator(config)
    if config.data.measurements is None:
        raise ConfigError("measured data need data.measurements", file=str(config.source_file),
                          key="data.measurements")
    segments, responses = read_measurements(config.data.measurements, config.data.track_file,
                                            simulator.channels())
    compute_spectra(responses, config.spectra)
    return len(segments)


def build_problem(config: Config, ledger: Ledger, log: Callable[[str], None] = lambda s: None) -> Problem:
    """Data, noise model and objective of a run (paper §2.3, §3.1, §3.3)."""
    from suspid.data.experiment import MeasurementOptions, ReferenceOptions, apply_model_error
    from suspid.method.noise import NoiseModel, fit_noise_model
    from suspid.method.spectra import SpectraOptions

    file = str(config.source_file)
    simulator = build_simulator(config)
    bounds_map = identified_bounds(config, simulator)
    names = list(bounds_map)
    bounds = np.array([bounds_map[n] for n in names], dtype=float)
    spectra_options = SpectraOptions.model_validate(config.spectra)
    sim_id = simulator.identity()
    channels = simulator.channels()
    noise_section = dict(config.noise)
    noise_path = noise_section.pop("path", None)
    reference: dict[str, np.ndarray] = {}

    if config.data.source == "experiment":
        w_ref = {p.name: p.nominal for p in simulator.parameters() if p.name in names} | config.data.w_ref
        segments = synthetic_track(config, "measurement")
        ref_opt = ReferenceOptions.model_validate(config.data.reference)
        if noise_path:
            noise_model = NoiseModel.load(config.resolve(noise_path))
        else:
            log("reference date: simulating w0 and identifying the noise model B (eq. 3)")
            ref_segments = synthetic_track(config, "reference", ref_opt.n_segments or len(segments))
            ref_sim = simulator
            if ref_opt.simulator_options:
                ref_sim = type(simulator)(**(dict(config.simulator.options) | ref_opt.simulator_options))
            key = stable_hash("reference", sim_id, ref_sim.identity(), segments_digest(ref_segments),
                              ref_opt.model_dump(), spectra_options.model_dump(), config.seed)
            err_rng = named_rng(config.seed, "reference-model-error")
            y_mes0, freqs = _cached_spectra(ledger, key + ":mes", lambda: _simulate_spectra(
                ref_sim, {}, ref_segments, spectra_options, lambda rs: apply_model_error(rs, ref_opt, err_rng)))
            y_sim0, _ = _cached_spectra(ledger, key + ":sim", lambda: _simulate_spectra(
                simulator, {}, ref_segments, spectra_options))
            noise_model = fit_noise_model(y_mes0, y_sim0, noise_section,
                                          freqs=freqs, channels=channels)
            reference = {"y_mes0": y_mes0, "y_sim0": y_sim0}
        log("measurement date: simulating w_ref (eq. 10)")
        meas_opt = _section_with_seed(MeasurementOptions, config.data.measurement, 0, "data.measurement", file)
        meas_sim, meas_id = simulator, sim_id
        if meas_opt.simulator_options:   # the "real" vehicle: e.g. with an effect the model lacks
            from suspid.config import validate_options

            merged = validate_options(type(simulator), dict(config.simulator.options) | meas_opt.simulator_options,
                                      file=file, key="data.measurement.simulator_options")
            meas_sim = type(simulator)(**merged)
            meas_id = meas_sim.identity()
        # identified effect parameters (<effect>/<parameter>) keep the measurement simulator's own values
        w_meas = {k: v for k, v in w_ref.items() if meas_sim is simulator or "/" not in k or k in config.data.w_ref}
        key = stable_hash("measurement", meas_id, w_meas, segments_digest(segments), spectra_options.model_dump())
        y_sim_ref, freqs = _cached_spectra(ledger, key, lambda: _simulate_spectra(
            meas_sim, w_meas, segments, spectra_options))
        # the measurement noise of a date belongs to that date's track (monitoring runs many dates)
        b_ref = noise_model.sample(len(segments), named_rng(config.seed, "noise-measurement-"
                                                            + segments_digest(segments)[:16]))
        y_mes = y_sim_ref + b_ref
    else:
        w_ref = None
        segments, responses = read_measurements(config.data.measurements, config.data.track_file,
                                                channels=channels)
        from suspid.method.spectra import compute_spectra

        y_mes, freqs = compute_spectra(responses, spectra_options)
        if not noise_path:
            raise ConfigError("measured data need a noise model identified at the reference date "
                              "(noise.path: a file written by a reference-date run)", file=file, key="noise.path")
        noise_model = NoiseModel.load(config.resolve(noise_path))
    noise_model.check_grid(freqs, channels)
    b = noise_model.sample(len(segments), named_rng(config.seed, "noise-model"))

    objective_cls = registry.get("objective", config.objective.plugin)
    objective = objective_cls(**config.objective.options)
    weights = channel_weights(config, channels)
    data_identity = stable_hash("data", array_digest(y_mes, b), segments_digest(segments),
                                config.objective.plugin, config.objective.options, weights.tolist(),
                                spectra_options.model_dump())
    return Problem(config=config, simulator=simulator, names=names, bounds=bounds, segments=segments,
                   channels=channels, freqs=freqs, y_mes=y_mes, b=b, objective=objective, weights=weights,
                   data_identity=data_identity, w_ref=w_ref, reference=reference, noise_model=noise_model)


def channel_weights(config: Config, channels: Sequence[str]) -> np.ndarray:
    """α_k of eq. 5 from ``objective.weights``, normalised to sum 1; default 1/n."""
    from suspid.method.objective import validate_weights

    try:
        return validate_weights(config.objective.weights, channels)
    except ConfigError as exc:
        raise ConfigError(exc.detail, file=str(config.source_file), key="objective.weights") from None


# -- J(w) through the ledger -------------------------------------------------------------
def j_of_spectra(problem: Problem, y_sim: np.ndarray, b: np.ndarray | None = None,
                 y_mes: np.ndarray | None = None) -> tuple[float, np.ndarray]:
    """J = Σ α_k Ψ_k (eq. 5) with Y_mod = y_sim + b (by default the run's fixed paths and measured spectra)."""
    from suspid.method.objective import ObjectiveFunction

    fn = ObjectiveFunction(problem.objective, problem.y_mes if y_mes is None else y_mes, problem.freqs,
                           problem.b if b is None else b, weights=problem.weights, channels=problem.channels)
    J, psi = fn.evaluate(y_sim)
    return J, psi


def simulate_spectra_task(task: tuple) -> np.ndarray:
    """Worker side of one evaluation: ``(plugin, options, w, segments, spectra) -> y_sim``.

    Module-level and built from picklable parts so that process and cluster
    executors can run it; the simulator is rebuilt from the registry.
    """
    plugin, options, w, segments, spectra_options = task
    y_sim, _ = _simulate_spectra(_simulator(plugin, options), w, segments, spectra_options)
    return y_sim


_SIMULATORS: dict[str, Simulator] = {}


def _simulator(plugin: str, options: dict) -> Simulator:
    """The simulator for ``(plugin, options)``, built once per process (models keep caches per instance)."""
    key = stable_hash(plugin, options)
    if key not in _SIMULATORS:
        if len(_SIMULATORS) >= 4:
            _SIMULATORS.pop(next(iter(_SIMULATORS)))
        _SIMULATORS[key] = registry.get("simulator", plugin)(**options)
    return _SIMULATORS[key]


def evaluation_key_of(problem: Problem, x_si: np.ndarray) -> tuple[str, dict[str, float]]:
    w = problem.w_of(x_si)
    return evaluation_key(problem.simulator.identity(), w, problem.data_identity), w


def evaluate_many(problem: Problem, ledger: Ledger, X_si: np.ndarray, executor,
                  on_done: Callable[[int, Evaluation | None, bool], None] = lambda i, ev, reused: None
                  ) -> list[Evaluation | None]:
    """J at many parameter vectors: reused from the ledger, or simulated by ``executor``.

    Each result is committed to the ledger the moment it arrives. A failed
    simulation is recorded as failed and gives ``None`` in the returned list.

    :param X_si: ``(n_points, q)`` SI values.
    :param on_done: called as ``on_done(index, evaluation, reused)`` for every point.
    """
    out: list[Evaluation | None] = [None] * len(X_si)
    todo, keys = [], {}
    for i, x in enumerate(np.asarray(X_si, float)):
        key, w = evaluation_key_of(problem, x)
        found = ledger.get(key)
        if found is not None and found.ok:
            out[i] = found
            on_done(i, found, True)
        else:
            keys[len(todo)] = (i, key, w)
            todo.append((problem.config.simulator.plugin, dict(problem.config.simulator.options), w,
                         problem.segments, problem.config.spectra))
    t0 = time.perf_counter()
    for j, result in executor.map_unordered(simulate_spectra_task, todo):
        i, key, w = keys[j]
        wall = time.perf_counter() - t0
        if isinstance(result, BaseException):
            ev = Evaluation(key, w, None, None, status="failed", error=f"{type(result).__name__}: {result}",
                            wall_time_s=wall)
            ledger.put(ev)
            on_done(i, None, False)
            if not isinstance(result, SimulatorError):  # bad data, bad options or a bug: fatal
                raise result
            continue
        J, psi = j_of_spectra(problem, result)
        ev = Evaluation(key, w, J, psi.tolist(), wall_time_s=wall)
        ledger.put(ev)
        out[i] = ev
        on_done(i, ev, False)
    return out


def evaluate(problem: Problem, ledger: Ledger, x_si: np.ndarray) -> Evaluation:
    """J at one parameter vector in this process: :func:`evaluate_many` with the serial executor.

    :param x_si: ``(q,)`` SI values in the order of ``problem.names``.
    :raises SimulatorError: when the simulator fails (the failure is recorded first).
    """
    ev = evaluate_many(problem, ledger, np.asarray(x_si, float)[None, :], registry.get("executor", "serial")())[0]
    if ev is None:
        key, _ = evaluation_key_of(problem, x_si)
        raise SimulatorError(ledger.get(key).error)
    return ev


# -- the run ---------------------------------------------------------------------------
def _section_with_seed(model, values: dict, seed: int, section: str, file: str):
    """Validate ``values`` as ``model``; a missing ``seed`` field is derived from the run seed."""
    from pydantic import ValidationError

    values = dict(values)
    if "seed" in model.model_fields and "seed" not in values:
        values["seed"] = seed
    try:
        return model.model_validate(values)
    except ValidationError as exc:
        raise_validation_error(exc, model, file, {}, tuple(section.split(".")))


def make_progress(enabled: bool):
    """A rich progress display with elapsed and remaining time (disabled: a no-op display)."""
    from rich.progress import (BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn,
                               TimeRemainingColumn)

    return Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                    TextColumn("eta"), TimeRemainingColumn(), TextColumn("{task.fields[status]}"),
                    disable=not enabled, transient=False)


@dataclass
class RunResult:
    """What ``suspid run`` produced: the result dict (as in result.json) and the run directory."""

    result: dict[str, Any]
    run_dir: Path
    problem: Problem
    ego: Any


def run(config: Config, *, fresh: bool = False, progress: bool = True,
        log: Callable[[str], None] = print) -> RunResult:
    """The whole identification (see the module docstring); writes result.json and report.md.

    :param fresh: forget the ledger of a previous run in the same directory.
    :param progress: show rich progress bars.
    """
    from suspid.optimize.design import DesignOptions, from_unit, make_design
    from suspid.optimize.ego import EGOOptions, run_ego

    t_start = time.perf_counter()
    file = str(config.source_file)
    run_dir = config.run_dir()
    run_dir.mkdir(parents=True, exist_ok=True)
    (run_dir / "config.yaml").write_text(yaml.safe_dump(config.model_dump(mode="json", exclude={"source_file"}),
                                                        sort_keys=False))
    check_sections(config)
    ledger = Ledger(run_dir / "ledger.sqlite")
    if fresh:
        ledger.clear()
    n_before = ledger.count()
    problem = build_problem(config, ledger, log)
    problem.noise_model.save(run_dir / "noise_model.npz")

    design_opts = _section_with_seed(DesignOptions, config.design, seed_for(config.seed, "design"), "design", file)
    ego_opts = _section_with_seed(EGOOptions, config.ego, seed_for(config.seed, "ego"), "ego", file)
    surrogate_cls = registry.get("surrogate", config.surrogate.plugin)
    surrogate_options = dict(config.surrogate.options)
    model = getattr(surrogate_cls, "Options", None)
    if model is not None and "seed" in model.model_fields and "seed" not in (config.surrogate.options or {}):
        surrogate_options["seed"] = seed_for(config.seed, "surrogate")
    surrogate = surrogate_cls(**surrogate_options)
    executor_cls = registry.get("executor", config.executor.plugin)

    U0 = make_design(design_opts, problem.q)
    X0 = from_unit(U0, problem.bounds)
    ei_history: list[float] = []
    # The Kriging fits and the EI search work on small matrices: OpenBLAS threads only contend (suspid.infra.threads)
    with make_progress(progress) as bars, single_blas_thread():
        design_task = bars.add_task("initial design", total=len(X0), status="")
        j_max = -np.inf

        def design_done(i: int, ev: Evaluation | None, reused: bool) -> None:
            nonlocal j_max
            if ev is not None:
                j_max = max(j_max, ev.J)
            bars.update(design_task, advance=1, status=f"J_max {j_max:.4g}" if ev else "failed point")

        executor = executor_cls(**config.executor.options)
        with executor:
            evs = evaluate_many(problem, ledger, X0, executor, design_done)
            ok = np.array([e is not None for e in evs])
            if ok.sum() < 2:
                raise SimulatorError(f"only {int(ok.sum())} of {len(evs)} design points could be simulated; "
                                     f"see the failures in {ledger.path}")
            for i, e in enumerate(evs):
                if e is not None:
                    ledger.put_iteration("design", i, {"w": e.w, "J": e.J})
            y0 = np.array([e.J for e in evs if e is not None])

            ego_task = bars.add_task("EGO", total=ego_opts.max_iter + (ego_opts.refine.max_iter
                                                                       if ego_opts.refine.enabled else 0), status="")

            def func(x: np.ndarray) -> float:
                return evaluate(problem, ledger, x).J

            def func_batch(X: np.ndarray) -> list[float]:
                """A batch of EGO points simulated in parallel by the executor (``ego.batch`` > 1)."""
                out = evaluate_many(problem, ledger, X, executor)
                if any(e is None for e in out):
                    raise SimulatorError(f"a simulation of an EGO batch failed; see the failures in {ledger.path}")
                return [e.J for e in out]

            def callback(record) -> None:
                if record.phase != "initial":
                    ei_history.append(float(record.EI) if record.EI is not None else float("nan"))
                    run_key = "refine" if record.phase.startswith("refine") else "ego"
                    ledger.put_iteration(run_key, record.index, {
                        "iteration": record.iteration, "phase": record.phase, "w": problem.w_of(record.x),
                        "J": record.J, "EI": record.EI, "J_max": record.J_max, "epsilon": record.epsilon,
                        "hyperparameters": record.hyperparameters, "fit_s": record.fit_seconds,
                        "search_s": record.search_seconds, "eval_s": record.eval_seconds})
                    bars.update(ego_task, advance=1 if record.phase in ("ego", "refine") else 0,
                                status=f"J_max {record.J_max:.4g}  EI {record.EI:.2e}"
                                if record.EI is not None else "")

            ego = run_ego(func, problem.bounds, ego=ego_opts, design=design_opts, surrogate=surrogate,
                          X_init=X0[ok], y_init=y0, callback=callback,
                          func_batch=func_batch if ego_opts.batch > 1 else None)
        bars.update(ego_task, total=max(ego.n_iterations, 1), completed=max(ego.n_iterations, 1))

    with single_blas_thread():
        result = analyse(problem, ledger, ego, ei_history, config)
    result.update({
        "n_initial": int(ok.sum()), "n_iterations": int(ego.n_iterations),
        "n_simulator_calls": int(ego.n_evaluations),
        "n_simulator_calls_this_session": int(ledger.count() - n_before),
        "stop_reason": ego.stop_reason, "n_refine_iterations": int(ego.n_refine),
        "refine_stop_reason": ego.refine_stop_reason, "wall_time_s": round(time.perf_counter() - t_start, 3),
        "design_min_distance": float(ego.design_min_distance),
    })
    (run_dir / "result.json").write_text(json.dumps(result, indent=2))
    write_report(run_dir, problem, ego, result, ei_history)
    return RunResult(result, run_dir, problem, ego)


def gradient_noise(problem: Problem, ledger: Ledger, u_opt: np.ndarray, h: float, n_redraws: int,
                   paired: bool = True) -> tuple[np.ndarray, np.ndarray, float]:
    """Covariance of the noise in the gradient of J at w_opt, in [0, 1]^q coordinates.

    J is estimated from v measured spectra and v modelled ones (y_sim_i + b_i).
    Each of ``n_redraws`` replicates resamples the segments with replacement
    (a bootstrap over segments: the finite measured data; with ``paired`` a
    segment's measured and simulated spectra, which share its track, are
    drawn together, otherwise the two sets are resampled independently) and
    draws new noise paths b_i (the finite Monte Carlo sample of Y_mod, §2.3),
    then takes the central-difference gradient of J at w_opt from the 2q points
    w_opt ± h e_k (clipped to the box). The spread of these gradients over the
    replicates, Σ_g, is how far the data of the same kind could tilt J at its
    maximum. The 2q spectra are simulated once (cached in the ledger).

    The same 2q + 1 spectra with the run's own data give the curvature of J
    along each axis, d²J/du_k² (central second differences).

    :returns: ``(Σ_g (q, q), curvature (q,), σ_J)``, σ_J the scatter of J(w_opt) itself.
    """
    config = problem.config
    q = problem.q

    def y_sim_at(u: np.ndarray) -> np.ndarray:
        w = problem.w_of(problem.from_unit(u))
        key = stable_hash("y_sim", problem.simulator.identity(), w, segments_digest(problem.segments))
        return _cached_spectra(ledger, key, lambda: _simulate_spectra(problem.simulator, w, problem.segments,
                                                                       config.spectra))[0]

    plus = np.clip(u_opt + h * np.eye(q), 0.0, 1.0)
    minus = np.clip(u_opt - h * np.eye(q), 0.0, 1.0)
    step = np.diag(plus - minus)
    y_plus, y_minus, y_opt = [y_sim_at(u) for u in plus], [y_sim_at(u) for u in minus], y_sim_at(u_opt)
    rng = named_rng(config.seed, "noise-redraws")
    v = len(problem.segments)
    grads, j_opt = np.empty((n_redraws, q)), np.empty(n_redraws)
    for k in range(n_redraws):
        b = problem.noise_model.sample(v, rng)
        i_mes = rng.integers(0, v, v)
        i_mod = i_mes if paired else rng.integers(0, v, v)
        y_mes = problem.y_mes[i_mes]
        J = lambda y: j_of_spectra(problem, y[i_mod], b, y_mes)[0]  # noqa: E731
        grads[k] = [(J(yp) - J(ym)) / step[i] for i, (yp, ym) in enumerate(zip(y_plus, y_minus))]
        j_opt[k] = J(y_opt)
    J0 = j_of_spectra(problem, y_opt)[0]
    Jp = np.array([j_of_spectra(problem, y)[0] for y in y_plus])
    Jm = np.array([j_of_spectra(problem, y)[0] for y in y_minus])
    h_plus, h_minus = np.diag(plus) - u_opt, u_opt - np.diag(minus)
    with np.errstate(divide="ignore", invalid="ignore"):  # one-sided at a bound: no curvature there
        curvature = np.where((h_plus > 0) & (h_minus > 0),
                             2 * (h_minus * Jp + h_plus * Jm - (h_plus + h_minus) * J0)
                             / (h_plus * h_minus * (h_plus + h_minus)), np.nan)
    return np.atleast_2d(np.cov(grads, rowvar=False)), curvature, float(np.std(j_opt, ddof=1))


def analyse(problem: Problem, ledger: Ledger, ego, ei_history: list[float], config: Config) -> dict[str, Any]:
    """w_opt, errors against w_ref, identifiability, intervals and sensitivity, as a JSON-able dict."""
    from suspid.method.identifiability import IdentifiabilityOptions, assess

    opts = IdentifiabilityOptions.model_validate(config.identifiability)
    names, lo, hi = problem.names, problem.bounds[:, 0], problem.bounds[:, 1]
    x_opt = np.asarray(ego.x_opt, float)
    u_opt = problem.to_unit(x_opt)
    sigma_g, curvature, sigma_J = gradient_noise(problem, ledger, u_opt, opts.step, opts.n_redraws,
                                                 paired=opts.bootstrap == "paired")
    rng = named_rng(config.seed, "identifiability")
    verdict = assess(names, u_opt, sigma_g, ego.surrogate, opts, rng, curvature)
    interval_si = lo[:, None] + verdict.interval_unit * (hi - lo)[:, None]
    units = {p.name: p.unit for p in problem.simulator.parameters()}
    result: dict[str, Any] = {
        "name": config.name,
        "parameters": names,
        "units": {n: units.get(n, "") for n in names},
        "bounds": {n: [float(a), float(b)] for n, a, b in zip(names, lo, hi)},
        "w_opt": {n: float(v) for n, v in zip(names, x_opt)},
        "w_opt_normalized": {n: float(v) for n, v in zip(names, u_opt)},
        "identifiable": {n: bool(v) for n, v in zip(names, verdict.identifiable)},
        "non_identifiable_reasons": {n: r for n, r in zip(names, verdict.reasons) if r},
        "correlated_with": {n: c for n, c in zip(names, verdict.correlated_with) if c},
        "interval": {n: [float(a), float(b)] for n, (a, b) in zip(names, interval_si)},
        "interval_normalized": {n: [float(a), float(b)] for n, (a, b) in zip(names, verdict.interval_unit)},
        "interval_method": {"sigma_J": sigma_J, "n_redraws": opts.n_redraws, "step": opts.step,
                            "bootstrap": opts.bootstrap,
                            "n_sigmas": opts.n_sigmas,
                            "covariance_normalized": verdict.covariance.tolist()},
        "sensitivity": {
            "total_sobol": {n: float(v) for n, v in zip(names, verdict.total_index)},
            "first_sobol": {n: float(v) for n, v in zip(names, verdict.first_index)},
            "lengthscales": None if verdict.lengthscales is None
            else {n: float(v) for n, v in zip(names, np.ravel(verdict.lengthscales))},
        },
        "J_max": float(ego.y_opt),
        "objective": config.objective.plugin,
        "surrogate": config.surrogate.plugin,
        "simulator": config.simulator.plugin,
        "seed": config.seed,
    }
    if problem.w_ref is not None:
        w_ref = np.array([problem.w_ref[n] for n in names])
        result["w_ref"] = {n: float(v) for n, v in zip(names, w_ref)}
        result["w_ref_normalized"] = {n: float(v) for n, v in zip(names, problem.to_unit(w_ref))}
        result["errors_percent"] = _errors_percent(problem, x_opt)
    if ego.n_refine:
        result["paper_loop"] = _paper_loop(problem, ego)
    return result


def _paper_loop(problem: Problem, ego) -> dict[str, Any]:
    """Where the paper's loop stood when it stopped, before the local refinement (``ego.refine``)."""
    names = problem.names
    n_loop = ego.n_evaluations - ego.n_refine
    best = int(np.argmax(ego.y[:n_loop]))
    x = np.asarray(ego.X[best], float)
    out: dict[str, Any] = {
        "n_iterations": n_loop - ego.n_initial, "n_simulator_calls": n_loop, "J_max": float(ego.y[best]),
        "w_opt": {n: float(v) for n, v in zip(names, x)},
        "w_opt_normalized": {n: float(v) for n, v in zip(names, problem.to_unit(x))}}
    if problem.w_ref is not None:
        out["errors_percent"] = _errors_percent(problem, x)
    return out


def _errors_percent(problem: Problem, x_si: np.ndarray) -> dict[str, float]:
    """|w - w_ref| per component in % of its admissible interval; ``x_si (q,)`` SI."""
    lo, hi = problem.bounds[:, 0], problem.bounds[:, 1]
    return {n: float(100 * abs(a - problem.w_ref[n]) / (h - l)) for n, a, l, h in zip(problem.names, x_si, lo, hi)}


def _figure_channel(config: Config, channels: Sequence[str]) -> int:
    wanted = config.output.figure_channel
    if wanted is not None:
        if wanted not in channels:
            raise ConfigError(f"unknown channel '{wanted}'; channels are {', '.join(channels)}",
                              file=str(config.source_file), key="output.figure_channel")
        return list(channels).index(wanted)
    for i, c in enumerate(channels):
        if "carbody" in c and "vertical" in c:
            return i
    return 0


def write_report(run_dir: Path, problem: Problem, ego, result: dict[str, Any], ei_history: list[float]) -> Path:
    """``report.md`` with the parameter table and Figures 1-2 analogues and the convergence plot."""
    from suspid.workflows.report import figure_convergence, figure_parameters, figure_spectra, markdown_table

    config = problem.config
    names = problem.names
    k = _figure_channel(config, problem.channels)
    if problem.reference:
        y_mes0, y_sim0 = problem.reference["y_mes0"], problem.reference["y_sim0"]
        date = "reference date (where B is identified)"
    else:
        y_mes0 = problem.y_mes
        y_sim0, _ = _simulate_spectra(problem.simulator, {}, problem.segments, config.spectra)
        date = "measurement date"
    y_mod0 = y_sim0 + problem.noise_model.sample(y_sim0.shape[0], named_rng(config.seed, "figure-1"))
    figure_spectra(run_dir / "figure1_spectra.png", problem.freqs, y_mes0, y_sim0, y_mod0, k, problem.channels[k])
    w_ref_n = np.array([result["w_ref_normalized"][n] for n in names]) if "w_ref" in result else None
    figure_parameters(run_dir / "figure2_parameters.png", names,
                      {config.objective.plugin: np.array([result["w_opt_normalized"][n] for n in names])},
                      w_ref_n, {config.objective.plugin: np.array([result["interval_normalized"][n] for n in names])})
    figure_convergence(run_dir / "convergence.png", np.asarray(ego.y), ego.n_initial, ei_history, ego.n_refine)

    rows = []
    for n in names:
        u = result["units"][n]
        row = [n, u, result["w_opt"][n]]
        if "w_ref" in result:
            row += [result["w_ref"][n], f"{result['errors_percent'][n]:.2f}"]
        lo_i, hi_i = result["interval"][n]
        row += [f"[{lo_i:.4g}, {hi_i:.4g}]", "yes" if result["identifiable"][n] else
                "**no**: " + "; ".join(result["non_identifiable_reasons"].get(n, [])),
                f"{result['sensitivity']['total_sobol'][n]:.3f}"]
        rows.append(row)
    header = ["parameter", "unit", "w_opt"] + (["w_ref", "error (% of interval)"] if "w_ref" in result else []) \
        + ["interval", "identifiable", "total Sobol index"]
    refine = ""
    if result.get("refine_stop_reason"):
        refine = (f" (the last {result['n_refine_iterations']} in the local refinement, stop: "
                  f"`{result['refine_stop_reason']}`)")
    text = f"""# suspid run `{config.name}`

Objective `{config.objective.plugin}`, surrogate `{config.surrogate.plugin}`, simulator `{config.simulator.plugin}`,
seed {config.seed}. {result['n_initial']} initial points (maximin design, minimum distance
{result['design_min_distance']:.3f} in [0, 1]^q), {result['n_iterations']} iterations, stop: `{result['stop_reason']}`{refine},
J_max = {result['J_max']:.6g}, wall time {result['wall_time_s']:.1f} s.

{markdown_table(header, rows)}

Components marked **no** are not identifiable from these data: their value is not a finding.
Intervals: w_opt ± {result['interval_method']['n_sigmas']:g} standard deviations of the sandwich covariance
H⁻¹ Σ_g H⁻¹ (H the Hessian of J at w_opt: curvatures from simulations, correlations from the metamodel, Σ_g the covariance of the gradient of J at w_opt under a
bootstrap over segments, {result['interval_method']['bootstrap']}, with redrawn noise paths), clipped to the admissible box.

## Figure 1: measured, simulated and modelled spectra ({date}), channel `{problem.channels[k]}`

![figure 1](figure1_spectra.png)

## Figure 2: identified parameters, normalised

![figure 2](figure2_parameters.png)

## Convergence

![convergence](convergence.png)
"""
    if result.get("correlated_with"):
        text += "\n## Correlated components\n\n" + "\n".join(
            f"- `{n}` with {', '.join(c)}" for n, c in result["correlated_with"].items()) + "\n"
    path = run_dir / "report.md"
    path.write_text(text)
    return path
