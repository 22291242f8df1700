"""The recordings a config stands for, and their indicators (``suspid indicators``, ingest, fleet records).

Measured data: the config's ``data.measurements`` on ``data.track_file``. A
numerical experiment: the simulator's accelerations at the date's true
parameters ``w_ref`` on the date's synthetic track, the records the
experiment's measured spectra are made from (without the measurement noise,
which the experiment adds to spectra, not to time histories).
"""

from __future__ import annotations

import csv
import datetime as dt
import io
from pathlib import Path
from typing import Sequence

from suspid.config import Config, build_simulator, identified_bounds
from suspid.indicators.standard import IndicatorValue, compute_indicators
from suspid.infra.files import write_json, write_text
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


CSV_COLUMNS = ("date", "indicator", "segment", "channel", "value", "unit", "verdict", "warning_level",
               "alarm_level", "bogie_mass_kg", "f0_hz", "hunting_hz_source")
"""The columns of ``indicators.csv`` (:func:`write_indicator_files`): the date, the value and its verdict, the
levels it was judged against and the inputs of the EN 14363 limit (the bogie mass, the hunting frequency f0)."""


def indicator_date(config: Config) -> tuple[dt.date, str]:
    """The date of a config's recordings and where it comes from: ``fleet.date``, else today (said so)."""
    if config.fleet is not None and config.fleet.date is not None:
        return config.fleet.date, "fleet.date"
    return dt.date.today(), "the day the indicators were computed (no fleet.date in the config)"


def write_indicator_files(out_dir: str | Path, config: Config, values: Sequence[IndicatorValue]) -> tuple[Path, Path]:
    """``indicators.json`` and ``indicators.csv`` in ``out_dir`` (atomically): every value with its verdict, the
    levels it was judged against (EN 14363: 80 % of the limit and the limit, from the bogie mass; EN 12299: N_MV 2
    and 4), the hunting frequency f0 of its band and where it came from, and the recordings' date.

    :returns: the two paths.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    date, source = indicator_date(config)
    simulator = build_simulator(config)
    rows = [{"date": date.isoformat(), "indicator": v.name, "segment": v.segment or "run", "channel": v.channel,
             "value": v.value, "unit": v.unit, "verdict": v.verdict, "warning_level": v.detail.get("warning_level"),
             "alarm_level": v.detail.get("alarm_level"), "bogie_mass_kg": v.detail.get("bogie_mass_kg"),
             "f0_hz": v.detail.get("f0_hz"), "hunting_hz_source": v.detail.get("hunting_hz_source")}
            for v in values]
    head = {"date": date.isoformat(), "date_source": source,
            "config": str(config.source_file) if config.source_file else None,
            "bogie_mass_kg": bogie_mass_kg(simulator), "bogie_mass_source": f"{BOGIE_MASS} of simulator "
            f"'{config.simulator.plugin}' (nominal)",
            "hunting_hz": config.fleet.hunting_hz if config.fleet is not None else None}
    json_path = write_json(out / "indicators.json", head | {"indicators": [v.to_dict() for v in values]})
    text = io.StringIO()
    writer = csv.DictWriter(text, fieldnames=CSV_COLUMNS, lineterminator="\n")
    writer.writeheader()
    writer.writerows({k: "" if r[k] is None else r[k] for k in CSV_COLUMNS} for r in rows)
    return json_path, write_text(out / "indicators.csv", text.getvalue())


def write_indicators(out_dir: Path, simulator: Simulator, segments: Sequence[TrackSegment],
                     responses: Sequence[Response]) -> list[IndicatorValue]:
    """The indicators of ingested segments, written to ``indicators.json`` in ``out_dir``."""
    values = compute_indicators(segments, responses, bogie_mass_kg=bogie_mass_kg(simulator))
    write_json(Path(out_dir) / "indicators.json", {"indicators": [v.to_dict() for v in values]})
    return values
