"""The dry run: every check of a run that needs no simulation (``suspid validate``, and ``run`` before it starts).

Loading the config already checked every section and every plugin's options
(:func:`suspid.config.load_config`). This adds what needs the simulator's
channels and rate, the files a run reads, and the folder it writes:

- the output directory can be created (it is not a file, its parent is writable);
- a noise model named by ``noise.path`` opens, and belongs to this frequency grid and these channels;
- the frequency grid fits the records: below the Nyquist frequency of the simulator's
  output, and every grid cell holds a DFT line of a record as long as the segments;
- measured data files read, pair with their track and give spectra on the grid;
- the executor could run tasks (:meth:`~suspid.interfaces.Executor.validate`: for a
  dask cluster, its scheduler answers and every worker runs suspid in the driver's versions).
"""

from __future__ import annotations

import os
from pathlib import Path

import warnings

import numpy as np

from suspid import registry
from suspid.config import Config, build_simulator
from suspid.data.files import read_track
from suspid.data.track import band_note
from suspid.errors import DataError
from suspid.method.noise import NoiseModel
from suspid.method.spectra import frequency_grid, grid_lines
from suspid.workflows.problem import synthetic_track, validate_data
from suspid.workflows.reference import SELF_CHECK_MIN_SEGMENTS
from suspid.workflows.verdict import limits_for


def check_output_dir(config: Config) -> Path:
    """The run directory can be created and written: no file in the way, a writable parent.

    :raises ConfigError: naming ``output.dir`` (or the config's name when the directory is the default).
    """
    run_dir = config.run_dir()
    key = "output.dir" if config.output.dir is not None else "name"
    for p in (run_dir, *run_dir.parents):
        if p.exists():
            if not p.is_dir():
                raise config.error(f"{p} exists and is not a directory; choose another output.dir", key)
            if not os.access(p, os.W_OK | os.X_OK):
                raise config.error(f"cannot write in {p} (permission denied); choose another output.dir", key)
            break
    return run_dir


def check_noise_model(config: Config, channels: list[str]) -> None:
    """``noise.path``, when given: a readable noise model on this grid and these channels (the file named)."""
    path = config.noise.path
    if path is None:
        return
    if path.is_dir():
        raise config.error(f"{path} is a directory; expected a noise_model.npz written by a run", "noise.path")
    try:
        model = NoiseModel.load(path)     # the message names the file; the prefix, the config's key
    except DataError as exc:
        raise config.error(str(exc), "noise.path") from None
    freqs = frequency_grid(config.spectra)[0]
    try:
        model.check_grid(freqs, channels)
    except DataError as exc:
        raise config.error(f"noise model {path}: {exc}", "noise.path") from None


NO_PARAMETERS = "no parameters to identify; name them under parameters: (bounds default to the simulator's; " \
                "`suspid parameters{file}` lists them)"


def reference_segment_count(config: Config) -> int | None:
    """The segments of the reference date's measured data (``noise.reference``), None without them."""
    ref = config.noise.reference
    if ref is None or ref.track_file is None:
        return None
    with warnings.catch_warnings():     # validate_data reads them again and says what it finds
        warnings.simplefilter("ignore")
        return len(read_track(ref.track_file, accept=config.data.accept))


def data_shortfalls(config: Config, n_reference: int | None = None) -> list[str]:
    """What a run of ``config`` will not assess for want of data, one line each, naming the number needed:

    - the reference-date self-check (needed for a component to be called trustworthy) needs the reference
      date's data with :data:`~suspid.workflows.reference.SELF_CHECK_MIN_SEGMENTS` segments: measured data with
      fewer (``noise.reference``), or with a noise model read from a file (``noise.path``), leave trust *not
      assessed*;
    - on measured data, an identified parameter without ``limits:`` gets no maintenance verdict.

    :param n_reference: the reference date's segments when the caller knows them (default: read
        ``noise.reference.track_file``).
    """
    out = []
    me = config.identifiability.model_error
    measured = config.data.source == "measured"
    if measured and me.run != "never" and me.self_check.enabled:
        need = SELF_CHECK_MIN_SEGMENTS
        if config.noise.reference is not None:
            n = reference_segment_count(config) if n_reference is None else n_reference
            if n is not None and n < need:
                out.append(f"{config.file}: the reference date has {n} segments ({config.noise.reference.measurements});"
                           f" the reference-date self-check needs {need}, so trust will be 'not assessed' (record "
                           f"more kilometres at constant speed on the reference date, or cut shorter segments)")
        elif config.noise.path is not None:
            out.append(f"{config.file}: the noise model is read from noise.path: the reference-date self-check needs "
                       f"the reference date's data (noise.reference, at least {need} segments), so trust will be "
                       f"'not assessed'")
    if measured:
        missing = [n for n in config.parameters if limits_for(n, config.limits) is None]
        if missing:
            out.append(f"{config.file}: no limits: for {', '.join(missing)}: their maintenance verdict will be "
                       f"'not assessable' (give warning and alarm levels in % of nominal under limits:, e.g. "
                       f"{missing[0]}: {{warning: -25, alarm: -40}})")
    return out


def check_identified(config: Config) -> None:
    """A run identifies parameters the config names: a config without ``parameters:`` is refused rather than run
    on the simulator's default set, which the user did not choose (``suspid parameters`` lists them)."""
    if not config.parameters:
        where = f" {config.source_file}" if config.source_file is not None else ""
        raise config.error(NO_PARAMETERS.format(file=where), "parameters")


def track_speeds(config: Config) -> np.ndarray:
    """``(n_segments,)`` m/s: the mean speed of every segment a run compares (both dates of measured data)."""
    if config.data.source == "experiment":
        return np.array([config.data.track.speed])
    files = [config.data.track_file] + ([config.noise.reference.track_file] if config.noise.reference else [])
    speeds = []
    with warnings.catch_warnings():     # validate_data reads them again and says what it finds
        warnings.simplefilter("ignore")
        for f in files:
            if f is not None:
                speeds += [s.mean_speed for s in read_track(f, accept=config.data.accept)]
    return np.array(speeds)


def apply_track_band(config: Config) -> None:
    """Restrict ``config.spectra`` to the band the track record (``data.track_band``) supports on every segment.

    At speed v a wavelength L of the track excites the frequency v / L; where the record's transfer function
    is far from 1 the model's input lacks (or distorts) what the vehicle ran on, and the spectra there would
    bias the identification. The change is said in ``config._notes`` (``validate`` prints it, report.md
    carries it). Idempotent: a second call finds the spectra within the band.

    :raises ConfigError: naming ``data.track_band`` when nothing of the spectra's band is supported.
    """
    band = config.data.track_band
    if band is None or band.filter == "full":
        return
    spectra = config.spectra
    try:
        lo, hi, note = band_note(band, track_speeds(config), spectra.f_min_hz, spectra.f_max_hz)
    except ValueError as exc:
        raise config.error(str(exc), "data.track_band") from None
    if (lo, hi) != (spectra.f_min_hz, spectra.f_max_hz):
        # the points of the configured grid within the band: the same spacing (and cells), fewer points
        freqs = frequency_grid(spectra)[0]
        inside = freqs[(freqs >= lo * (1 - 1e-9)) & (freqs <= hi * (1 + 1e-9))]
        if inside.size < 2:
            raise config.error(f"{note}: fewer than 2 frequencies of the spectra's grid lie in it", "data.track_band")
        update = {"f_min_hz": float(inside[0]), "f_max_hz": float(inside[-1])}
        if spectra.df_hz is None:
            update["n_freqs"] = int(inside.size)
        config.spectra = spectra.model_copy(update=update)
        note = note.rsplit(" to ", 1)[0] + f" to the {inside.size} grid frequencies {inside[0]:.4g}-{inside[-1]:.4g} Hz"
    if note and spectra.window == "boxcar":
        note += ("; spectra.window: boxcar leaks the power of the unsupported band into the cells next to it "
                 "(a Hann window keeps it out)")
    if note and note not in config._notes:
        config._notes.append(note)


def check_records(config: Config, fs: float | None) -> None:
    """The grid against the simulator's rate and the length of the numerical experiment's segments."""
    if fs is None:
        return
    if config.data.source == "experiment":
        segments = synthetic_track(config, "measurement")
        shortest = min(segments, key=lambda s: s.duration())
        n_t = int(round(shortest.duration() * fs))
        what = f"segment '{shortest.name}' ({shortest.duration():.3g} s at {fs:g} Hz)"
    else:
        n_t, what = int(round(fs)) * 3600, "the records"  # measured records are checked file by file
    try:
        grid_lines(n_t, fs, config.spectra, what)
    except DataError as exc:
        raise config.error(str(exc), "spectra") from None


def dry_run(config: Config) -> int:
    """Every check of a run that needs no simulation, in the order a run would meet them.

    :returns: the number of measured segments read (0 for a numerical experiment).
    :raises SuspidError: the first problem, in one line.
    """
    check_identified(config)
    check_output_dir(config)
    apply_track_band(config)
    simulator = build_simulator(config)
    check_noise_model(config, simulator.channels())
    check_records(config, simulator.sampling_rate_hz())
    n_measured = validate_data(config)
    registry.get("executor", config.executor.plugin)(**config.executor.options).validate()
    return n_measured
