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

from suspid import registry
from suspid.config import Config, build_simulator
from suspid.errors import DataError
from suspid.method.noise import NoiseModel
from suspid.method.spectra import frequency_grid, grid_lines
from suspid.workflows.problem import synthetic_track, validate_data


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
    model = NoiseModel.load(path)
    freqs = frequency_grid(config.spectra)[0]
    try:
        model.check_grid(freqs, channels)
    except DataError as exc:
        raise DataError(f"noise model {path}: {exc}") from None


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
    check_output_dir(config)
    simulator = build_simulator(config)
    check_noise_model(config, simulator.channels())
    check_records(config, simulator.sampling_rate_hz())
    n_measured = validate_data(config)
    registry.get("executor", config.executor.plugin)(**config.executor.options).validate()
    return n_measured
