"""The problem of one identification: data, noise model and objective (paper §2.3, §3.1, §3.3).

:func:`build_problem` gathers everything J(w) needs, once per run:

1. the measured spectra y_mes of the measurement date: read from files
   (``data.source: measured``), or the numerical experiment of §3.3 on a
   synthetic track: y_sim(w_ref) through the experiment's measurement process
   (:mod:`suspid.data.experiment`), or y_mes_i = y_sim_i(w_ref) + b_i (eq. 10);
2. the noise model B, identified at the reference date from
   b_i = y_mes_i − y_sim_i(w0) (eq. 3), or loaded from ``noise.path``;
3. the noise paths b_i of Y_mod = Y_sim(w) + b_i, drawn once from the run's
   seed (common random numbers), the objective plugin and the weights α_k.

Expensive spectra (the reference date, the measurement date) are cached in the
run ledger, so that a resumed run does not simulate them again.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import cached_property, partial
from pathlib import Path
from typing import Any, Callable, Collection, Sequence

import numpy as np

from suspid import registry
from suspid.config import Config, build_simulator, channel_weights, identified_bounds, validate_options
from suspid.data.corrections import resolve as resolve_corrections
from suspid.data.corrections import untilt
from suspid.data.experiment import measurement_process
from suspid.data.files import read_accelerations_records, read_track
from suspid.data.track import filter_track, synthetic_segments
from suspid.errors import DataError
from suspid.infra.ledger import Ledger, stable_hash
from suspid.infra.seeds import rng as named_rng
from suspid.infra.seeds import seed_for
from suspid.interfaces import Executor, Objective, Response, Simulator, TrackSegment
from suspid.method.noise import NoiseModel, fit_noise_model, modelled_spectra
from suspid.method.objective import ObjectiveFunction, reference_weights
from suspid.method.weights import EFFICIENT_NEEDS_REFERENCE
from suspid.method.spectra import SpectraOptions, compute_spectra, grid_lines
from suspid.optimize.design import from_unit, to_unit
from suspid.workflows.tasks import SpectraTask, run_tasks
from suspid.elements import declared_parameters
from suspid.workflows.identity import array_digest, data_identities, legacy_data_identity


def segments_digest(segments: Sequence[TrackSegment]) -> str:
    """A content hash of track segments (geometry, distance and speed; the design curvature and cant when a
    segment has them, so that straight track keeps its digest)."""
    parts = []
    for s in segments:
        design = [part for k, a in enumerate((s.curvature, s.cant)) if a is not None
                  for part in (np.array([k], float), np.asarray(a, float))]      # tagged: which record it is
        parts.append(array_digest(np.asarray(s.distance, float), np.asarray(s.irregularities, float),
                                  np.atleast_1d(np.asarray(s.speed, float)), *design))
    return stable_hash(parts)



def segment_speeds(segments: Sequence[TrackSegment]) -> list[float]:
    """``(n_segments,)`` m/s: each segment's mean speed."""
    return [s.mean_speed for s in segments]

@dataclass
class Problem:
    """Everything J(w) needs, built once per run.

    :ivar names: identified parameter names, ``(q,)``.
    :ivar bounds: ``(q, 2)`` SI lower and upper bounds.
    :ivar segments: measurement-date track segments (v of them).
    :ivar y_mes: ``(v, n_channels, n_freqs)`` dB measured spectra.
    :ivar b: ``(v, n_channels, n_freqs)`` dB noise paths for Y_mod.
    :ivar b_more: ``(K - 1, v, n_channels, n_freqs)`` dB, the further draws of the paths J is averaged
        over (``objective.noise_draws`` K > 1), or None (the paper's J, one draw: ``b``).
    :ivar freqs: ``(n_freqs,)`` Hz.
    :ivar reference: ``y_mes0``, ``y_sim0`` ``(v0, n_channels, n_freqs)`` dB at the reference date, when
        its data are part of the run (numerical experiment, or ``noise.reference``); empty otherwise.
    :ivar reference_segments: the reference date's track segments, in the order of ``reference``.
    :ivar data_identity: what J depends on beyond the simulator and w, from the run's inputs (files' bytes,
        the experiment's config and seed, the options; :mod:`suspid.workflows.identity`): the evaluation keys'
        data part, the same on any machine.
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
    objective: Objective
    weights: np.ndarray
    data_identity: str
    w_ref: dict[str, float] | None = None
    reference: dict[str, np.ndarray] = field(default_factory=dict)  # y_mes0, y_sim0 at the reference date
    noise_model: NoiseModel | None = None
    reference_segments: list[TrackSegment] = field(default_factory=list)  # the reference date's track
    w0: dict[str, float] = field(default_factory=dict)  # nominal values of the identified parameters (SI)
    b_more: np.ndarray | None = None
    weights_record: dict[str, Any] | None = None   # how α was chosen (``objective.weights: efficient``)
    reference_identity: str = ""  # what the reference date's spectra are made of (suspid.workflows.identity)
    noise_identity: str = ""     # what B is
    weights_identity: str = ""   # what α is chosen from
    legacy_identity: str | None = None   # the array-digest data identity of ledgers written before, to find them

    @property
    def noise_paths(self) -> np.ndarray:
        """The paths the run's J uses: ``b`` ``(v, n_channels, n_freqs)``, or with further draws
        ``(K, v, n_channels, n_freqs)``, ``b`` first (:class:`~suspid.method.objective.ObjectiveFunction`)."""
        return self.b if self.b_more is None else np.concatenate([self.b[None], self.b_more])

    @property
    def q(self) -> int:
        return len(self.names)

    @property
    def speeds(self) -> list[float]:
        """``(v,)`` m/s: each measured segment's mean speed (B's mean is taken per speed)."""
        return segment_speeds(self.segments)

    def w_of(self, x_si: np.ndarray) -> dict[str, float]:
        return {n: float(v) for n, v in zip(self.names, np.asarray(x_si, float))}

    def to_unit(self, x_si: np.ndarray) -> np.ndarray:
        """SI ``(..., q)`` to ``[0, 1]^q`` (:func:`suspid.optimize.design.to_unit`)."""
        return to_unit(x_si, self.bounds)

    def from_unit(self, u: np.ndarray) -> np.ndarray:
        """``[0, 1]^q`` ``(..., q)`` to SI (:func:`suspid.optimize.design.from_unit`)."""
        return from_unit(u, self.bounds)

    @cached_property
    def simulator_identity(self) -> str:
        """The simulator's identity (plugin, version, options), computed once per run."""
        return self.simulator.identity()

    @cached_property
    def segments_digest(self) -> str:
        """Content hash of the measurement-date segments, computed once per run."""
        return segments_digest(self.segments)

    @cached_property
    def objective_function(self) -> ObjectiveFunction:
        """The run's J (eq. 5): the measured spectra, the fixed noise paths b_i, the objective plugin, the
        weights α_k and the noise model's floor, built once per problem (a problem made by
        :func:`dataclasses.replace`, e.g. with corrected y_mes, builds its own)."""
        return ObjectiveFunction(self.objective, self.y_mes, self.freqs, self.noise_paths, weights=self.weights,
                                 channels=self.channels, floor=self.noise_model.floor_)


def _cached_spectra(ledger: Ledger, key: str, make: Callable[[], tuple[np.ndarray, np.ndarray]]
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Spectra ``(y, freqs)`` from the ledger's artifacts, or computed and stored there."""
    y, f = ledger.get_array(key + ":y"), ledger.get_array(key + ":freqs")
    if y is None or f is None:
        y, f = make()
        ledger.put_array(key + ":y", y)
        ledger.put_array(key + ":freqs", f)
    return y, f


def model_track(config: Config, segments: Sequence[TrackSegment]) -> list[TrackSegment]:
    """The model's track input in a numerical experiment: ``segments`` (the track the vehicle ran on) as the
    recording car of ``data.track_band`` records them, so that the model sees the record, as with measured data."""
    band = config.data.track_band
    if band is None or band.filter == "full":
        return list(segments)
    return [filter_track(s, band) for s in segments]


def synthetic_track(config: Config, date: str, n_segments: int | None = None) -> list[TrackSegment]:
    """The synthetic track of one date of a numerical experiment (seeded by the config's seed)."""
    options = config.data.track
    update = {} if "seed" in options.model_fields_set else {"seed": seed_for(config.seed, f"track-{date}")}
    if n_segments is not None:
        update["n_segments"] = n_segments
    return synthetic_segments(options.model_copy(update=update))


DURATION_TOLERANCE = 0.01
"""A record may differ from its track segment's duration by this fraction (1 %: a sampling rate 1.5 % off is refused)."""


def read_measurements(measurements: Path, track_file: Path | None, channels: Sequence[str], *,
                      strict: bool = False, accept: Collection[str] = (), spectra: SpectraOptions | None = None,
                      date: str = "measurement") -> tuple[list[TrackSegment], list[Response]]:
    """Measured accelerations and the track geometry measured with them, paired by segment name.

    :param strict: unusual values are errors, not warnings.
    :param accept: checks of impossible values to let pass (``data.accept``, :mod:`suspid.data.plausibility`).
    :param spectra: the frequency grid every record must fit (below its Nyquist frequency, long enough
        for a DFT line in every cell): checked here, where the file and the date are known.
    :param date: ``measurement`` or ``reference``, for the messages.
    :raises DataError: naming the file, when a segment has no track or is given twice, the
        channels differ, a record's duration does not match its segment or it does not fit the grid.
    """
    if track_file is None:
        raise DataError(f"{measurements}: measured accelerations need the track measured with them "
                        f"(data.track_file)")
    records = read_accelerations_records(measurements, channels, strict=strict, accept=accept)  # errors name files
    if not records:
        raise DataError(f"{measurements}: no acceleration records found")
    by_name = {s.name: s for s in read_track(track_file, strict=strict, accept=accept)}
    segments = []
    for f, r in records:
        seg = by_name.get(r.segment)
        if seg is None:
            raise DataError(f"{f}: record '{r.segment}' has no track segment of that name in "
                            f"{track_file} (segments: {', '.join(sorted(by_name)) or 'none'})")
        expected = seg.duration()
        if abs(r.duration - expected) > max(DURATION_TOLERANCE * expected, 2.0 / r.fs):
            raise DataError(f"{f}: record '{r.segment}' lasts {r.duration:.2f} s but its track "
                            f"segment takes {expected:.2f} s at the recorded speed")
        if spectra is not None:
            grid_lines(r.accelerations.shape[1], r.fs, spectra, f"{f}: the {date} date's record '{r.segment}'")
        segments.append(seg)
    return segments, [r for _, r in records]


NO_NOISE_MODEL = ("measured data need the noise model of the reference date: noise.reference (the reference "
                  "date's measured data) or noise.path (a noise model file)")


def measured_data(config: Config, channels: Sequence[str], date: str = "measurement"
                  ) -> tuple[list[TrackSegment], list[Response]]:
    """:func:`read_measurements` of a date of a measured-data config, checked as the config says
    (``data.strict``, ``data.accept``, the ``spectra`` grid): ``data.measurements`` or ``noise.reference``."""
    source = config.data if date == "measurement" else config.noise.reference
    return read_measurements(source.measurements, source.track_file, channels, strict=config.data.strict,
                             accept=config.data.accept, spectra=config.spectra, date=date)


def check_noise_source(config: Config) -> None:
    """The run has a noise model B: a file (``noise.path``), or reference-date data to identify it from.

    Measured data need ``noise.path`` or ``noise.reference``; a numerical experiment identifies B on its own
    reference date, whose segments (``data.reference.n_segments``, default ``data.track.n_segments``) must be
    at least 2: B's covariance is taken over segments (eq. 3). A ``monitor:`` config gets ``noise.path`` from
    its own reference date (:mod:`suspid.workflows.monitor` checks that).

    :raises ConfigError: naming the key to set.
    """
    if config.noise.path is not None:
        return
    if config.data.source == "measured":
        if config.noise.reference is None and config.monitor is None:
            raise config.error(NO_NOISE_MODEL, "noise")
        return
    n_ref = config.data.reference.n_segments or config.data.track.n_segments
    if n_ref < 2:
        key = "data.reference.n_segments" if config.data.reference.n_segments else "data.track.n_segments"
        raise config.error(f"the noise model of the reference date needs at least 2 segments (its covariance "
                           f"is taken over segments, eq. 3), got {n_ref}; or give noise.path", key)


def validate_data(config: Config) -> int:
    """Read and check measured data as a run would (files, channels, durations, spectra grid).

    :returns: the number of measured segments (0 for a numerical experiment).
    :raises DataError: one line naming the file and what is wrong.
    """
    check_noise_source(config)
    if config.data.source != "measured":
        return 0
    simulator = build_simulator(config)
    if config.data.measurements is None:
        raise config.error("measured data need data.measurements", "data.measurements")
    segments, responses = measured_data(config, simulator.channels())
    resolve_corrections(config.data.corrections, simulator.channels(), error=config.error)
    _, freqs = compute_spectra(responses, config.spectra)
    if config.noise.reference is not None:
        ref = config.noise.reference
        ref_segments, ref_responses = measured_data(config, simulator.channels(), "reference")
        _, ref_freqs = compute_spectra(ref_responses, config.spectra)
        if len(ref_segments) < 2:
            raise config.error(f"{ref.measurements}: the noise model needs at least 2 reference-date segments, "
                               f"found {len(ref_segments)}", "noise.reference.measurements")
        if ref_freqs.shape != freqs.shape or not np.allclose(ref_freqs, freqs):
            raise config.error(f"{ref.measurements}: the reference-date records give another frequency grid "
                               f"than data.measurements (sampling rate or duration differ)",
                               "noise.reference.measurements")
    if config.noise.path is not None:
        NoiseModel.load(config.noise.path).check_grid(freqs, simulator.channels())
    return len(segments)


def measured_reference(config: Config, simulator: Simulator, ledger: Ledger, log: Callable[[str], None],
                       executor: Executor | None = None
                       ) -> tuple[list[TrackSegment], np.ndarray, np.ndarray, np.ndarray]:
    """The reference date's measured spectra and the simulator's at w0 on its measured track (eq. 3).

    The simulation at w0 runs on ``executor`` (in this process without one) and
    is cached in the run ledger (keyed by the simulator, the reference track
    and the spectra options).

    :returns: ``(segments, y_mes0, y_sim0, freqs)``, spectra ``(v0, n_channels, n_freqs)`` dB.
    """
    ref = config.noise.reference
    segments, responses = measured_data(config, simulator.channels(), "reference")
    y_mes0, freqs = compute_spectra(responses, config.spectra)
    key = stable_hash("measured-reference", simulator.identity(), segments_digest(segments),
                      config.spectra.model_dump())
    if ledger.get_array(key + ":y") is None:
        log(f"reference date: simulating w0 on the {len(segments)} measured segments of {ref.measurements}")
    (y_sim0, _), = cached_spectra(ledger, executor, [(key, _task(simulator, segments, config.spectra), {})])
    return segments, y_mes0, y_sim0, freqs


def _task(simulator: Simulator, segments: Sequence[TrackSegment], spectra: Any,
          transform: Callable[[list[Response]], list[Response]] | None = None):
    """The executor task simulating ``simulator`` on ``segments``, returning ``(y, freqs)``."""
    return SpectraTask.of(simulator, segments, spectra, transform=transform, with_freqs=True)


def cached_spectra(ledger: Ledger, executor: Executor | None, jobs: Sequence[tuple[str, Callable, dict]]
                   ) -> list[tuple[np.ndarray, np.ndarray]]:
    """Spectra ``(y, freqs)`` of ``(key, task, w)`` jobs: from the ledger's artifacts, or simulated together by
    ``executor`` (in this process without one) and stored there.

    :raises SimulatorError: (or any task's error) the first failed job's.
    """
    found = {key: (ledger.get_array(key + ":y"), ledger.get_array(key + ":freqs")) for key, _, _ in jobs}
    todo = [(key, task, w) for key, task, w in jobs if found[key][0] is None or found[key][1] is None]
    for (key, _, _), outcome in zip(todo, run_tasks(executor, [(task, w) for _, task, w in todo])):
        if isinstance(outcome, BaseException):
            raise outcome
        found[key] = outcome
        ledger.put_array(key + ":y", outcome[0])
        ledger.put_array(key + ":freqs", outcome[1])
    return [found[key] for key, _, _ in jobs]


def build_problem(config: Config, ledger: Ledger, log: Callable[[str], None] = lambda s: None,
                  executor: Executor | None = None) -> Problem:
    """Data, noise model and objective of a run (paper §2.3, §3.1, §3.3).

    The simulations of the reference and measurement dates run on ``executor``
    (entered; in this process without one), all at once.
    """
    simulator = build_simulator(config)
    bounds_map = identified_bounds(config, simulator)
    names = list(bounds_map)
    bounds = np.array([bounds_map[n] for n in names], dtype=float)
    spectra_options = config.spectra
    sim_id = simulator.identity()
    channels = simulator.channels()
    noise_options = config.noise.model_dump(exclude={"path", "reference"})
    noise_path = config.noise.path
    reference: dict[str, np.ndarray] = {}
    reference_segments: list[TrackSegment] = []
    w0 = {p.name: float(p.nominal) for p in declared_parameters(simulator) if p.name in names}

    if config.data.source == "experiment":
        w_ref = {p.name: p.nominal for p in declared_parameters(simulator) if p.name in names} | config.data.w_ref
        true_segments = synthetic_track(config, "measurement")   # what the vehicle runs on
        segments = model_track(config, true_segments)              # what the model gets: the record
        ref_opt = config.data.reference
        fixed_seed = seed_for(config.seed, "measurement-process-fixed")  # one vehicle, one set of sensors: every date
        jobs = []
        if noise_path:
            noise_model = NoiseModel.load(noise_path)
        else:
            log("reference date: simulating w0 and identifying the noise model B (eq. 3)")
            ref_segments = synthetic_track(config, "reference", ref_opt.n_segments or len(segments))
            ref_sim = simulator
            if ref_opt.simulator_options:
                ref_sim = type(simulator)(**(dict(config.simulator.options) | ref_opt.simulator_options))
            key = stable_hash("reference", sim_id, ref_sim.identity(), segments_digest(ref_segments),
                              ref_opt.model_dump(), spectra_options.model_dump(), config.seed)
            err_rng = named_rng(config.seed, "reference-model-error")
            ref_model = model_track(config, ref_segments)
            if config.data.track_band is not None and config.data.track_band.filter != "full":
                key = stable_hash(key, "track-band", config.data.track_band.model_dump())
            jobs += [(key + ":mes", _task(ref_sim, ref_segments, spectra_options,
                                          partial(measurement_process, options=ref_opt, rng=err_rng,
                                                  fixed_seed=fixed_seed)), {}),
                     (key + ":sim", _task(simulator, ref_model, spectra_options), {})]
        log("measurement date: simulating w_ref (eq. 10)")
        speeds = segment_speeds(segments)
        meas_opt = config.data.measurement
        meas_sim, meas_id = simulator, sim_id
        if meas_opt.simulator_options:   # the "real" vehicle: e.g. with an effect the model lacks
            merged = validate_options(type(simulator), dict(config.simulator.options) | meas_opt.simulator_options,
                                      file=config.file, key="data.measurement.simulator_options")
            meas_sim = type(simulator)(**merged)
            meas_id = meas_sim.identity()
        # identified effect parameters (<effect>/<parameter>) keep the measurement simulator's own values
        w_meas = {k: v for k, v in w_ref.items() if meas_sim is simulator or "/" not in k or k in config.data.w_ref}
        through_process = meas_opt.errors == "process"
        transform = None
        if through_process:   # the same fixed gains as the reference date, this date's own segment gains and noise
            transform = partial(measurement_process, options=ref_opt, fixed_seed=fixed_seed,
                                rng=named_rng(config.seed, "measurement-process-" + segments_digest(true_segments)[:16]))
        key = stable_hash("measurement", meas_id, w_meas, segments_digest(true_segments), spectra_options.model_dump(),
                          *([ref_opt.model_dump(exclude={"n_segments", "simulator_options"}), config.seed]
                            if through_process else []))
        jobs.append((key, _task(meas_sim, true_segments, spectra_options, transform), w_meas))
        *reference_spectra, (y_sim_ref, freqs) = cached_spectra(ledger, executor, jobs)
        if not noise_path:
            (y_mes0, freqs0), (y_sim0, _) = reference_spectra
            noise_model = fit_noise_model(y_mes0, y_sim0, noise_options, freqs=freqs0, channels=channels,
                                          speeds=segment_speeds(ref_segments))
            reference = {"y_mes0": y_mes0, "y_sim0": y_sim0}
            reference_segments = ref_model
        if through_process:
            y_mes = y_sim_ref
        else:
            # the measurement noise of a date belongs to that date's track (monitoring runs many dates)
            b_ref = noise_model.sample(len(segments), named_rng(config.seed, "noise-measurement-"
                                                                + segments_digest(segments)[:16]), speeds)
            y_mes = modelled_spectra(y_sim_ref, b_ref, noise_model.floor_)
    else:
        w_ref = None
        segments, responses = measured_data(config, channels)
        responses = untilt(responses, config.data.corrections, channels, error=config.error)
        y_mes, freqs = compute_spectra(responses, spectra_options)
        if config.noise.reference is not None:
            reference_segments, y_mes0, y_sim0, freqs0 = measured_reference(config, simulator, ledger, log, executor)
            if freqs0.shape != freqs.shape or not np.allclose(freqs0, freqs):
                raise config.error("the reference-date records give another frequency grid than "
                                   "data.measurements (sampling rate or duration differ)",
                                   "noise.reference.measurements")
            reference = {"y_mes0": y_mes0, "y_sim0": y_sim0}
        if noise_path:
            noise_model = NoiseModel.load(noise_path)
        elif reference:
            log("reference date: identifying the noise model B (eq. 3) from the measured reference date")
            noise_model = fit_noise_model(reference["y_mes0"], reference["y_sim0"], noise_options,
                                          freqs=freqs, channels=channels,
                                          speeds=segment_speeds(reference_segments))
        else:
            raise config.error(NO_NOISE_MODEL, "noise")
    noise_model.check_grid(freqs, channels)
    path_speeds = segment_speeds(segments)

    def draw(stream: str) -> np.ndarray:
        return noise_model.sample(len(segments), named_rng(config.seed, stream), path_speeds)

    b = draw("noise-model")
    b_more = None
    if config.objective.noise_draws > 1:   # further draws, each from a stream of its own: b is the same for any K
        b_more = np.stack([draw(f"noise-model-draw-{k}") for k in range(1, config.objective.noise_draws)])

    objective_cls = registry.get("objective", config.objective.plugin)
    objective = objective_cls(**config.objective.options)
    weights = reference_weights(noise_model) if config.objective.weights == "reference" \
        else channel_weights(config, channels)

    ids = data_identities(config, sim_id, names, bounds)

    def legacy(alpha: np.ndarray) -> str:
        return legacy_data_identity(y_mes, b, b_more, segments_digest(segments), config, alpha)

    problem = Problem(config=config, simulator=simulator, names=names, bounds=bounds, segments=segments,
                      channels=channels, freqs=freqs, y_mes=y_mes, b=b, objective=objective, weights=weights,
                      data_identity=ids.data, reference_identity=ids.reference, noise_identity=ids.noise,
                      weights_identity=ids.weights, legacy_identity=legacy(weights), w_ref=w_ref, reference=reference, noise_model=noise_model,
                      reference_segments=reference_segments, w0=w0, b_more=b_more)
    if config.objective.weights == "efficient":   # α from the reference date at w0, before identifying
        from suspid.workflows.weights import reference_efficient_weights
        if not reference:
            raise config.error(EFFICIENT_NEEDS_REFERENCE, "objective.weights")
        log(f"reference date: channel weights α at w0 (objective.weights: efficient, {2 * len(names)} simulations)")
        alpha, record = reference_efficient_weights(problem, ledger, executor)
        problem = replace(problem, weights=alpha, legacy_identity=legacy(alpha), weights_record=record)
    return problem
