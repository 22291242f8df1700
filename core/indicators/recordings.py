"""The recordings a config stands for, and their indicators (``suspid indicators``, ingest, fleet records).

Measured data: the config's ``data.measurements`` on ``data.track_file``. A
numerical experiment: the simulator's accelerations at the date's true
parameters ``w_ref`` on the date's synthetic track, the records the
experiment's measured spectra are made from (without the measurement noise,
which the experiment adds to spectra, not to time histories).
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

from suspid.config import Config, build_simulator, identified_bounds
from suspid.indicators.standard import IndicatorValue, compute_indicators
from suspid.infra.files import write_json
from suspid.interfaces import Response, Simulator, TrackSegment
from suspid.workflows.problem import measured_data, synthetic_track

BOGIE_MASS = "m_bogie"
"""The simulator parameter whose nominal value is the bogie mass (kg) of the EN 14363 limit."""


def bogie_mass_kg(simulator: Simulator) -> float | None:
    """The nominal ``m_bogie`` of ``simulator``, kg; None when the model has no such parameter."""
    return next((float(p.nominal) for p in simulator.parameters() if p.name == BOGIE_MASS), None)


def recordings(config: Config) -> tuple[list[TrackSegment], list[Response]]:
    """The segments and accelerations of the config's measurement date (module docstring)."""
    simulator = build_simulator(config)
    if config.data.source == "experiment":
        names = identified_bounds(config, simulator)
        w_ref = {p.name: p.nominal for p in simulator.parameters() if p.name in names} | dict(config.data.w_ref)
        segments = synthetic_track(config, "measurement")
        return segments, simulator.simulate(w_ref, segments)
    return measured_data(config, simulator.channels())


def config_indicators(config: Config, *, hunting_hz: float | None = None) -> list[IndicatorValue]:
    """EN 14363 instability and EN 12299 comfort of the config's recordings, per segment and per run."""
    segments, responses = recordings(config)
    return compute_indicators(segments, responses, bogie_mass_kg=bogie_mass_kg(build_simulator(config)),
                              hunting_hz=hunting_hz)


def write_indicators(out_dir: Path, simulator: Simulator, segments: Sequence[TrackSegment],
                     responses: Sequence[Response]) -> list[IndicatorValue]:
    """The indicators of ingested segments, written to ``indicators.json`` in ``out_dir``."""
    values = compute_indicators(segments, responses, bogie_mass_kg=bogie_mass_kg(simulator))
    write_json(Path(out_dir) / "indicators.json", {"indicators": [v.to_dict() for v in values]})
    return values
