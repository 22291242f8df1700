"""The ingest config: one validated model (unknown keys are errors), units declared, never guessed.

An ingest file names the suspid config whose simulator defines the channels,
the recording with its channel mapping, the speed (or distance) channel, the
track record, and how to align, cut and check::

    config: ../configs/quickstart.yaml          # its simulator's channels() are the targets
    recording:
      path: run-2026-11-03.mf4                  # format by extension, or format: mdf4
      channels:                                 # simulator channel -> recorded channel
        carbody_front_vertical: {name: ACC_Z_K1, unit: mm/s^2, sign: 1}
        bogie_front_vertical: {name: ACC_Z_B1, unit: g}
      speed: {name: V_GPS, unit: km/h}          # or distance: {name: ODO, unit: m}
    track:
      path: track-car-2026-10.csv
      options: {step: 0.25}                     # the reader's options
      channels: {vertical: {name: LL_mean, unit: mm}, lateral: {name: AL_mean, unit: mm}}
    alignment: {channel: bogie_front_vertical, lever_m: 9.5}
    segments: {length_m: 1000, speed_tolerance: 0.02, min_speed_kmh: 100}
    output: {dir: ingested, format: csv}

Every unit is one of :data:`ACCELERATION_UNITS`, :data:`SPEED_UNITS`,
:data:`LENGTH_UNITS`; a unit the file states that disagrees with the declared
one is a warning in the quality report, and the declared one is used.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Literal

from pydantic import Field, NonNegativeFloat, PositiveFloat, PositiveInt, field_validator, model_validator

import numpy as np

from suspid.data.plausibility import ACCELERATION_LIMITS, Check, kind_of  # noqa: F401 - kind_of for the ingest modules
from suspid.data.track import TrackBand
from suspid.interfaces import IRREGULARITY_CHANNELS
from suspid.options import ConfigPath, Section

G = 9.80665
"""Standard gravity, m/s^2 per g."""
STATIC_G_TOLERANCE = 0.15
"""A vertical channel whose mean lies within this fraction of +-1 g carries the static gravity."""

ACCELERATION_UNITS = {"m/s^2": 1.0, "mm/s^2": 1e-3, "g": G}
"""Declared acceleration unit -> factor to m/s^2."""
SPEED_UNITS = {"m/s": 1.0, "km/h": 1 / 3.6}
"""Declared speed unit -> factor to m/s."""
LENGTH_UNITS = {"m": 1.0, "mm": 1e-3, "km": 1e3}
"""Declared length unit -> factor to m."""

_ALIASES = {"m/s²": "m/s^2", "m/s2": "m/s^2", "m s^-2": "m/s^2", "mm/s²": "mm/s^2", "mm/s2": "mm/s^2",
            "kph": "km/h", "kmh": "km/h", "km/hr": "km/h", "mps": "m/s"}


def canonical_unit(unit: str) -> str:
    """A unit's spelling as in the tables (``m/s²`` -> ``m/s^2``), for comparisons with the file's."""
    u = unit.strip()
    return _ALIASES.get(u, _ALIASES.get(u.lower(), u))


def _unit_field(table: dict[str, float]):
    def check(value: str) -> str:
        u = canonical_unit(value)
        if u not in table:
            raise ValueError(f"unknown unit '{value}'; expected one of: {', '.join(table)}")
        return u
    return check


class ChannelMap(Section):
    """One recorded acceleration channel feeding one simulator channel."""

    name: str = Field(min_length=1, description="channel name in the recording")
    unit: str = Field(description=f"declared unit: {', '.join(ACCELERATION_UNITS)}")
    sign: Literal[1, -1] = Field(default=1, description="-1 when the sensor axis points the other way")
    full_scale: PositiveFloat | None = Field(default=None, description="sensor range in the declared unit: "
                                             "|value| >= 0.999 full_scale counts as clipped")

    _unit = field_validator("unit")(classmethod(lambda cls, v: _unit_field(ACCELERATION_UNITS)(v)))

    @property
    def factor(self) -> float:
        """Multiplier from the recorded values to m/s^2 (sign included)."""
        return self.sign * ACCELERATION_UNITS[self.unit]


class SpeedChannel(Section):
    name: str = Field(min_length=1, description="speed channel in the recording")
    unit: str = Field(description=f"declared unit: {', '.join(SPEED_UNITS)}")

    _unit = field_validator("unit")(classmethod(lambda cls, v: _unit_field(SPEED_UNITS)(v)))


class LengthChannel(Section):
    name: str = Field(min_length=1, description="channel name in the file")
    unit: str = Field(description=f"declared unit: {', '.join(LENGTH_UNITS)}")

    _unit = field_validator("unit")(classmethod(lambda cls, v: _unit_field(LENGTH_UNITS)(v)))


class RecordingSection(Section):
    """The long recording of the data-acquisition system."""

    path: ConfigPath = Field(description="the recording file")
    format: str | None = Field(default=None, description="reader name (default: by the file's extension)")
    options: dict[str, Any] = Field(default_factory=dict, description="the reader's options")
    channels: dict[str, ChannelMap] = Field(description="simulator channel -> recorded channel")
    speed: SpeedChannel | None = Field(default=None, description="speed channel (give speed or distance)")
    distance: LengthChannel | None = Field(default=None, description="odometry distance channel")
    fs_hz: PositiveFloat | None = Field(default=None, description="output sampling rate (default: the "
                                        "recording's, from the first mapped channel)")

    @model_validator(mode="after")
    def _speed_or_distance(self) -> "RecordingSection":
        if (self.speed is None) == (self.distance is None):
            raise ValueError("give the train's motion once: recording.speed or recording.distance")
        if not self.channels:
            raise ValueError("recording.channels maps no channel")
        return self


CURVATURE_UNITS = {"1/m": 1.0, "1/km": 1e-3}
"""Declared curvature unit -> factor to 1/m."""


class CurveChannel(Section):
    """The design curvature of the track record: a curvature or a radius channel.

    A radius channel gives the curvature 1 / R; ``|R| >= straight_radius_m`` (and R = 0, how many
    recording cars write straight track) is straight.
    """

    name: str = Field(min_length=1, description="channel name in the track record")
    quantity: Literal["curvature", "radius"] = Field(default="curvature", description="what the channel holds")
    unit: str = Field(description="declared unit: 1/m, 1/km (curvature); m, km (radius)")
    sign: Literal[1, -1] = Field(default=1, description="-1 when the record's positive curves are to the right "
                                 "(suspid: positive = left-hand curve in the direction of travel)")
    straight_radius_m: PositiveFloat = Field(default=1.0e5, description="radius from which the track is "
                                             "straight (radius channels), m")

    @model_validator(mode="after")
    def _unit(self) -> "CurveChannel":
        table = CURVATURE_UNITS if self.quantity == "curvature" else LENGTH_UNITS
        u = canonical_unit(self.unit)
        if u not in table:
            raise ValueError(f"unknown unit '{self.unit}' of a {self.quantity} channel; expected one of: "
                             f"{', '.join(table)}")
        self.unit = u
        return self

    def to_curvature(self, values: np.ndarray) -> np.ndarray:
        """The channel's values (in their declared unit) as curvature, 1/m, ``values.shape``."""
        if self.quantity == "curvature":
            return self.sign * values * CURVATURE_UNITS[self.unit]
        r = values * LENGTH_UNITS[self.unit]
        with np.errstate(divide="ignore", invalid="ignore"):
            k = np.where((np.abs(r) >= self.straight_radius_m) | (r == 0), 0.0, 1.0 / r)
        return self.sign * np.where(np.isfinite(r), k, np.nan)


class CantChannel(LengthChannel):
    sign: Literal[1, -1] = Field(default=1, description="-1 when the record gives the left rail above the right "
                                 "(suspid: right rail above the left is positive)")


class TrackRecordSection(Section):
    """The track geometry record of a track recording car, indexed by distance."""

    path: ConfigPath = Field(description="the track record file")
    format: str | None = Field(default=None, description="reader name (default: by the file's extension)")
    options: dict[str, Any] = Field(default_factory=dict, description="the reader's options (e.g. step: 0.25 "
                                    "in the record's length unit, or index: <distance channel>)")
    channels: dict[str, LengthChannel] = Field(description=f"track quantity ({', '.join(IRREGULARITY_CHANNELS)})"
                                               " -> recorded channel; vertical is required")
    distance_unit: str = Field(default="m", description="unit of the record's abscissa (index or step)")
    step_m: PositiveFloat | None = Field(default=None, le=5.0, description="distance step of the written track "
                                         "segments, m (default: the record's)")
    curvature: CurveChannel | None = Field(default=None, description="design curvature (or radius) channel: "
                                           "written as the segments' curvature_per_m")
    cant: CantChannel | None = Field(default=None, description="design cant channel: written as cant_m")
    band: TrackBand = Field(default_factory=TrackBand, description="how the record was measured (full, en13848 "
                            "bands, chord, transfer): reported, and data.track_band of the config ingest writes")

    _du = field_validator("distance_unit")(classmethod(lambda cls, v: _unit_field(LENGTH_UNITS)(v)))

    @field_validator("channels")
    @classmethod
    def _quantities(cls, value: dict[str, LengthChannel]) -> dict[str, LengthChannel]:
        unknown = [k for k in value if k not in IRREGULARITY_CHANNELS]
        if unknown:
            raise ValueError(f"unknown track quantity '{unknown[0]}'; expected: {', '.join(IRREGULARITY_CHANNELS)}")
        if "vertical" not in value:
            raise ValueError("the vertical profile (longitudinal level) is required: it aligns the record")
        return value


class AlignmentSection(Section):
    """Alignment of the track record to the vehicle's distance (the odometry offset).

    The vertical acceleration of ``channel`` (a bogie or axlebox, which follow
    the track at long wavelengths), double-integrated over distance in the band
    ``wavelength_m``, is cross-correlated with the band-limited vertical profile.
    """

    channel: str | None = Field(default=None, description="simulator channel to correlate (default: the first "
                                "mapped *axlebox*/*bogie* vertical channel)")
    lever_m: float | Literal["model"] = Field(
        default="model", description="where the channel's response meets the track, m ahead of the odometry "
        "reference point (the point segment distances refer to; exudyn-train: the car centre); 'model': "
        "found by running the same correlation on the configured simulator at the recording's speed, which "
        "also takes in the response's own delay (the geometric lever of exudyn-train's front bogie is 9.5 m, "
        "its effective one about 7.7 m at 300 km/h)")
    wavelength_m: tuple[PositiveFloat, PositiveFloat] = Field(default=(8.0, 70.0), description="band of "
                                                              "wavelengths compared, m (short, long)")
    search_m: PositiveFloat = Field(default=500.0, description="offsets searched: guess_m +- search_m")
    guess_m: float = Field(default=0.0, description="centre of the offsets searched, m")
    min_peak_ratio: float = Field(default=1.5, ge=1.0, description="ratio of the correlation peak to the "
                                  "highest other peak below which the alignment is an error")
    offset_m: float | None = Field(default=None, description="known offset: skip the correlation")

    @field_validator("wavelength_m")
    @classmethod
    def _band(cls, value):
        if value[0] >= value[1]:
            raise ValueError("wavelength_m must be (short, long) with short < long")
        return value


class SegmentsSection(Section):
    """How the recording is cut into segments at quasi-constant speed."""

    length_m: PositiveFloat = Field(default=1000.0, description="segment length, m")
    speed_tolerance: PositiveFloat = Field(default=0.02, le=0.5, description="largest |v - mean v| / mean v "
                                           "inside a segment")
    min_speed_kmh: NonNegativeFloat = Field(default=100.0, description="slower stretches (stations, "
                                            "manoeuvres) are skipped")
    step_m: PositiveFloat | None = Field(default=None, description="how far a rejected window start moves on, m "
                                         "(default length_m / 20)")
    margin_s: NonNegativeFloat = Field(default=0.5, description="time excluded around a dropout, clipped "
                                       "stretch, flat line or spike, s")
    max_segments: PositiveInt | None = Field(default=None, description="keep at most this many (the first)")
    prefix: str = Field(default="seg", pattern=r"^[A-Za-z0-9_.\-]+$", description="segment names <prefix>-001")
    max_curvature_per_m: NonNegativeFloat | None = Field(default=None, description="keep only stretches whose "
                                                         "|curvature| stays at or below this, 1/m (e.g. 1e-5: "
                                                         "straight track, radius 100 km or more)")
    min_curvature_per_m: NonNegativeFloat | None = Field(default=None, description="keep only stretches whose "
                                                         "|curvature| stays at or above this, 1/m (curves)")
    max_cant_m: NonNegativeFloat | None = Field(default=None, description="keep only stretches whose |cant| "
                                                "stays at or below this, m")
    min_cant_m: NonNegativeFloat | None = Field(default=None, description="keep only stretches whose |cant| "
                                                "stays at or above this, m")

    @model_validator(mode="after")
    def _limits(self) -> "SegmentsSection":
        for what in ("curvature_per_m", "cant_m"):
            lo, hi = getattr(self, f"min_{what}"), getattr(self, f"max_{what}")
            if lo is not None and hi is not None and lo > hi:
                raise ValueError(f"min_{what} ({lo:g}) is above max_{what} ({hi:g})")
        return self


class QualitySection(Section):
    """Thresholds of the quality checks."""

    spike_sigma: PositiveFloat = Field(default=12.0, description="a sample further than this many robust "
                                       "standard deviations (1.4826 MAD) from the median is a spike")
    flat_s: PositiveFloat = Field(default=0.5, description="a stretch this long of identical values while "
                                  "moving is a flat line (dead sensor)")
    clip_min_run: PositiveInt = Field(default=3, description="consecutive samples at the channel's extreme "
                                      "value that count as clipping")
    gap_factor: PositiveFloat = Field(default=1.5, description="a time step longer than this many nominal "
                                      "steps is a dropout")
    rms_range: dict[str, tuple[NonNegativeFloat, PositiveFloat]] = Field(
        default_factory=lambda: {k: lim[:2] for k, lim in ACCELERATION_LIMITS.items() if k is not None},
        description="usual RMS in m/s^2 while moving, by channel kind (a word of the channel name): outside "
        "it is a warning (beyond the physical limits of suspid.data.plausibility, an error)")
    accept: list[Check] = Field(default_factory=list, description="checks of physically impossible data to let "
                                "pass with a warning: implausible_amplitude, dead_channel, implausible_speed "
                                "(as data.accept of a config; suspid.data.plausibility)")
    exclude: list[Literal["dropouts", "clipping", "flat", "spikes"]] = Field(
        default_factory=lambda: ["dropouts", "clipping", "flat", "spikes"],
        description="what excludes a stretch from the segments (the rest is only reported)")
    figures: bool = Field(default=True, description="write the PNG figures")
    strict: bool = Field(default=False, description="refuse what would otherwise be corrected with a warning: a "
                         "static 1 g on a vertical channel (``suspid ingest --strict``)")


class OutputSection(Section):
    dir: ConfigPath | None = Field(default=None, description="output folder (default: ingested/<recording "
                                   "stem>/ beside the ingest file)")
    format: Literal["csv", "hdf5"] = Field(default="csv", description="csv: track/ and accelerations/ "
                                           "folders; hdf5: track.h5 and accelerations.h5")


class ReferenceDate(Section):
    """``reference:`` the reference-date recording (the train at its nominal parameters w0), ingested as the
    measurement date's is, with these sections in place of the file's own (alignment: the file's when left out)."""

    recording: RecordingSection
    track: TrackRecordSection
    alignment: AlignmentSection | None = None


class IngestOptions(Section):
    """A whole ingest file (``suspid ingest INGEST.yaml``).

    With ``reference:`` it ingests two recordings, the reference date's and the measurement date's, into
    ``<output>/reference/`` and ``<output>/measurement/``, and writes ``<output>/two-dates.yaml``: the config
    of ``config`` with ``data`` (measurement date, ``track_band``) and ``noise.reference`` (reference date)
    pointing at them, ready for ``suspid validate`` and ``suspid run``.
    """

    config: ConfigPath | None = Field(default=None, description="the suspid config whose simulator defines "
                                      "the channels (default: the built-in exudyn-train with its defaults)")
    recording: RecordingSection
    track: TrackRecordSection
    alignment: AlignmentSection = Field(default_factory=AlignmentSection)
    segments: SegmentsSection = Field(default_factory=SegmentsSection)
    quality: QualitySection = Field(default_factory=QualitySection)
    output: OutputSection = Field(default_factory=OutputSection)
    reference: ReferenceDate | None = Field(default=None, description="the reference-date recording: both dates "
                                            "are ingested and a two-date config is written")

    def for_reference(self) -> "IngestOptions":
        """These options with the reference date's recording, track record and alignment."""
        ref = self.reference
        return self.model_copy(update={"recording": ref.recording, "track": ref.track, "reference": None,
                                       "alignment": ref.alignment or self.alignment})

    @model_validator(mode="after")
    def _design_limits_need_channels(self) -> "IngestOptions":
        seg = self.segments
        tracks = [("track", self.track)] + ([("reference.track", self.reference.track)] if self.reference else [])
        for what, key, limits in (("curvature", "curvature_per_m", (seg.min_curvature_per_m, seg.max_curvature_per_m)),
                                  ("cant", "cant_m", (seg.min_cant_m, seg.max_cant_m))):
            for where, track in tracks:
                if any(v is not None for v in limits) and getattr(track, what) is None:
                    raise ValueError(f"segments.min_{key} / max_{key} need the track record's {what} channel "
                                     f"({where}.{what})")
        return self

    def output_dir(self, base: Path) -> Path:
        """The output folder: ``output.dir`` or ``ingested/<recording stem>/`` beside the ingest file."""
        return self.output.dir if self.output.dir is not None else base / "ingested" / self.recording.path.stem



