"""The typed sections of a config file.

Each section is a pydantic model that rejects unknown keys; the sections of
the numerical chain are the options models of the modules that use them
(:class:`~suspid.method.spectra.SpectraOptions`, :class:`~suspid.method.noise.NoiseOptions`,
:class:`~suspid.optimize.design.DesignOptions`, :class:`~suspid.optimize.ego.EGOOptions`,
:class:`~suspid.method.identifiability.IdentifiabilityOptions`, :class:`~suspid.data.track.TrackOptions`,
:class:`~suspid.data.experiment.ReferenceOptions`, :class:`~suspid.data.experiment.MeasurementOptions`);
this module adds the plugin selections, the data and output sections and the
sections of the workflows (``study``, ``monitor``, ``diagnose``).
:class:`suspid.config.Config` puts them together, so that a config is resolved
once, when it is loaded, into typed objects.
"""

from __future__ import annotations

import datetime as dt
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import Field, ValidationInfo, field_validator, model_validator

from suspid.data.experiment import MeasurementOptions, ReferenceOptions
from suspid.data.plausibility import Check
from suspid.data.track import TrackBand, TrackOptions
from suspid.method.noise import NoiseOptions
from suspid.options import ConfigPath, Section


# -- plugin selections ---------------------------------------------------------------------
class PluginSection(Section):
    """A section that selects a plugin by registered name; ``options`` are validated by the plugin's
    ``Options`` model when the config is loaded (:func:`suspid.config.check_config_plugins`)."""

    plugin: str
    options: dict[str, Any] = Field(default_factory=dict)


class SimulatorSection(PluginSection):
    plugin: str = "exudyn-train"


class ObjectiveSection(PluginSection):
    plugin: str = "overlap"
    weights: list[float] | dict[str, float] | Literal["reference", "efficient"] | None = Field(
        default=None, description="α_k of eq. 5: a list in channel order or channel -> weight; 'reference': "
        "from the noise model B, down-weighting the channels the model misses most at the reference date; "
        "'efficient': estimating-equation weights chosen at the reference date at w0 (2q simulations there) "
        "to narrow the components' sampling intervals, down-weighting channels whose gradient is noisy or "
        "whose curvature is small or unstable; default 1/n")
    noise_draws: int = Field(
        default=1, ge=1, le=64, description="J averaged over this many independent draws of the noise paths b_i "
        "(each J of eq. 5 with its own draw, the same draws at every w: common random numbers); the draw of the "
        "paths moves J's maximiser, and the average takes that share out at no simulation's cost (K times J's "
        "own cost). 1: the paper's J, one draw")


class SurrogateSection(PluginSection):
    plugin: str = "gpy-kriging"


class OptimizerSection(PluginSection):
    """``optimizer:``: who chooses the points where J is evaluated (:class:`suspid.interfaces.Optimizer`).

    The default ``ego`` is the paper's loop; its options are the ``ego:`` section
    unless ``optimizer.options`` gives them.
    """

    plugin: str = "ego"
    budget: int | None = Field(default=None, ge=1, description="evaluations of J (simulator calls), initial "
                               "design included; default: design.n_initial + ego.max_iter (+ ego.refine.max_iter)")


class ExecutorSection(PluginSection):
    plugin: str = "serial"


# -- parameters, data, noise, output ----------------------------------------------------------
class ParameterBounds(Section):
    """Bounds of one identified parameter (SI units); missing bounds keep the simulator's."""

    lower: float | None = None
    upper: float | None = None


Levels = tuple[float | None, float | None]
"""A pair of levels in % of nominal: (lower, upper); None leaves a side open."""


def _levels(value: Any) -> Any:
    """``-25`` -> ``(-25, None)``, ``30`` -> ``(None, 30)``, ``[-25, 30]`` as it is: a lone number is one side."""
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return (value, None) if value < 0 else (None, value)
    return value


class Limits(Section):
    """``limits.<parameter or group>``: the acceptable domain of one identified parameter for the verdict.

    Levels are changes from the nominal value in % of it: ``warning: -25`` warns at 25 % below nominal,
    ``alarm: [-40, 30]`` alarms at 40 % below or 30 % above (either side may be null, a lone number is the
    side of its sign). A change at or beyond a level has that level's state; the alarm lies beyond the warning
    on each side. ``nominal`` (SI) replaces the simulator's nominal value as the verdict's reference;
    ``label`` the plain-language name of the element in the summary. ``decision`` says how an interval
    reaching across one level is decided: ``precautionary`` (the more severe state, marked borderline) or
    ``strict`` (not assessable).
    """

    warning: Levels | None = Field(default=None, description="warning levels, % of nominal: a number or [lower, upper]")
    alarm: Levels | None = Field(default=None, description="alarm levels, % of nominal: a number or [lower, upper]")
    nominal: float | None = Field(default=None, description="the nominal value the change is measured from, SI "
                                  "units (default: the simulator's nominal value)")
    label: str | None = Field(default=None, min_length=1, description="plain-language name of the element(s)")
    decision: Literal["precautionary", "strict"] = Field(
        default="precautionary", description="an interval reaching across one level: precautionary gives the "
        "more severe state (borderline), strict gives not assessable")

    @field_validator("warning", "alarm", mode="before")
    @classmethod
    def _one_side(cls, value: Any) -> Any:
        return _levels(value)

    @field_validator("warning", "alarm")
    @classmethod
    def _sides(cls, value: Levels | None, info: ValidationInfo) -> Levels | None:
        if value is None:
            return value
        lower, upper = value
        if lower is None and upper is None:
            raise ValueError("give at least one level, e.g. -25 or [-25, 25] (% of nominal)")
        if lower is not None and not -100.0 < lower < 0.0:
            raise ValueError(f"the lower {info.field_name} level must lie between -100 and 0 % of nominal")
        if upper is not None and not 0.0 < upper < 1e6:
            raise ValueError(f"the upper {info.field_name} level must be above 0 % of nominal")
        return value

    @field_validator("nominal")
    @classmethod
    def _nonzero(cls, value: float | None) -> float | None:
        if value is not None and not (value != 0.0 and abs(value) < float("inf")):
            raise ValueError("the nominal value must be a finite number other than 0")
        return value

    @model_validator(mode="after")
    def _alarm_beyond_warning(self) -> "Limits":
        if self.warning is None and self.alarm is None:
            raise ValueError("give warning and/or alarm levels (% of nominal), e.g. {warning: -25, alarm: -40}")
        if self.warning is not None and self.alarm is not None:
            (wl, wu), (al, au) = self.warning, self.alarm
            if wl is not None and al is not None and not al < wl:
                raise ValueError(f"the lower alarm level ({al:g} %) must lie below the lower warning level ({wl:g} %)")
            if wu is not None and au is not None and not au > wu:
                raise ValueError(f"the upper alarm level ({au:g} %) must lie above the upper warning level ({wu:g} %)")
        return self


class SensorCorrection(Section):
    """One item of ``data.corrections``: a tilted lateral accelerometer rotated back (:mod:`suspid.data.corrections`)."""

    channel: str = Field(description="the lateral channel whose sensor is tilted")
    tilt_deg: float = Field(ge=-45.0, le=45.0, description="its tilt about the longitudinal axis, degrees "
                            "(x = cos α a_lat + sin α a_vert; suspid diagnose reports it from the coupling)")
    vertical: str | None = Field(default=None, description="the vertical channel at the same point (default: the "
                                 "channel's name with 'vertical' for 'lateral')")


class DataSection(Section):
    """Where the measurements come from.

    ``source: experiment`` builds the numerical experiment of the paper (§3.3) on a
    synthetic track; ``source: measured`` reads measured accelerations and the
    matching track geometry from files.
    """

    source: Literal["experiment", "measured"] = "experiment"
    track: TrackOptions = Field(default_factory=TrackOptions, description="synthetic track options (experiment)")
    w_ref: dict[str, float] = Field(default_factory=dict, description="known 'damaged' parameters (experiment)")
    reference: ReferenceOptions = Field(default_factory=ReferenceOptions,
                                        description="the measurement process of both dates (experiment): fixed and "
                                        "per-segment gains, sensor noise; the reference date's size and model")
    measurement: MeasurementOptions = Field(
        default_factory=MeasurementOptions, description="how the measurement-date 'measurements' are simulated "
        "(experiment), e.g. simulator_options with a hidden effect")
    measurements: ConfigPath | None = Field(default=None, description="measured data file or folder")
    track_file: ConfigPath | None = Field(default=None, description="measured track geometry file or folder")
    strict: bool = Field(default=False, description="unusual measured data (a vibration or a speed higher than "
                         "usual) are errors, not warnings (``--strict``)")
    accept: list[Check] = Field(default_factory=list, description="checks of physically impossible data to let pass "
                                "with a warning: implausible_amplitude (values 1000 times too large: mm/s^2 or mm "
                                "for SI units), dead_channel (a constant or silent channel), implausible_speed "
                                "(km/h for m/s); see suspid.data.plausibility")
    track_band: TrackBand | None = Field(
        default=None, description="how the track record was measured (full, en13848 bands, chord, transfer; "
        "suspid.data.track.TrackBand): the spectra are restricted to the band it supports at every segment's "
        "speed; in a numerical experiment the model's track input is filtered as the record would be")
    corrections: list[SensorCorrection] = Field(
        default_factory=list, description="sensor faults corrected in the measured records before their spectra "
        "(measured data; the reference date's records are taken as they are)")

    @field_validator("measurements", "track_file")
    @classmethod
    def _exists(cls, value: Path | None) -> Path | None:
        if value is not None and not value.exists():
            raise ValueError(f"file not found: {value}")
        return value

    @field_validator("corrections")
    @classmethod
    def _one_per_channel(cls, value: list[SensorCorrection]) -> list[SensorCorrection]:
        channels = [c.channel for c in value]
        twice = sorted({c for c in channels if channels.count(c) > 1})
        if twice:
            raise ValueError(f"channel {twice[0]} is corrected twice (one tilt per channel)")
        same = [c.channel for c in value if c.vertical == c.channel]
        if same:
            raise ValueError(f"channel {same[0]} cannot be its own vertical channel")
        return value

    @model_validator(mode="after")
    def _corrections_need_records(self) -> "DataSection":
        if self.corrections and self.source != "measured":
            raise ValueError("corrections apply to measured records (data.source: measured); a numerical "
                             "experiment has none")
        return self


W_REF_MEASURED = "w_ref belongs to numerical experiments, not to measured data"
"""The one message for ``data.w_ref`` given with measured data (``run``, ``validate`` and ``monitor`` alike)."""


class MeasuredReference(Section):
    """``noise.reference``: the reference date's measured data (two-date protocol on measured data).

    The train ran at the nominal parameters w0 on that date; ``suspid run`` reads
    these files, simulates w0 on their track and identifies B from eq. 3
    (cached in the run ledger), then identifies w on ``data.measurements``.
    The files have the layout of ``data.measurements`` and ``data.track_file``.
    """

    measurements: ConfigPath = Field(description="reference-date acceleration file or folder")
    track_file: ConfigPath = Field(description="track geometry measured on the reference date, file or folder")

    @field_validator("measurements", "track_file")
    @classmethod
    def _exists(cls, value: Path) -> Path:
        if not value.exists():
            raise ValueError(f"file not found: {value}")
        return value


class NoiseSection(NoiseOptions):
    """``noise:``: how B is identified at the reference date (eq. 3), or the file of a B identified before."""

    path: ConfigPath | None = Field(default=None, description="noise model written by a reference-date run")
    reference: MeasuredReference | None = Field(
        default=None, description="reference-date measured data (data.source: measured): B is identified "
        "from them at w0, unless noise.path gives a B identified before; they also serve the "
        "reference-date self-check")


class OutputSection(Section):
    dir: ConfigPath | None = Field(default=None, description="run directory; default runs/<name>/")
    figure_channel: str | None = Field(default=None, description="channel of Figure 1; default: first carbody vertical")


# -- study -------------------------------------------------------------------------------------
class Variant(Section):
    name: str = Field(pattern=r"^[A-Za-z0-9_.\-]+$")
    set: dict[str, Any] = Field(default_factory=dict, description="key.path -> value overrides")


class StudyOptions(Section):
    """``study:``: variants of the config, each run in its own directory (:mod:`suspid.workflows.study`)."""

    variants: list[Variant] = Field(min_length=1)
    seeds: list[Annotated[int, Field(ge=0, lt=2**32)]] | None = Field(
        default=None, min_length=1, description="every variant once per seed (each as the top-level seed: "
        "0 <= seed < 2**32); leave it out to run each variant once with the config's seed")
    compare: list[str] | None = Field(default=None, description="two variant names: a paired test over the seeds")
    checkpoints: list[int] = Field(default=[100, 300], min_length=1, description="simulator calls N at which the worst "
                                   "identifiable error is reported")
    target_error: float = Field(default=2.0, gt=0, description="worst identifiable error (% of the interval) "
                                "whose first reach, in simulator calls, study.md reports per variant")

    @field_validator("variants")
    @classmethod
    def _unique(cls, variants: list[Variant]) -> list[Variant]:
        names = [v.name for v in variants]
        if len(set(names)) != len(names):
            raise ValueError(f"variant names must be unique, got {names}")
        return variants

    @field_validator("seeds")
    @classmethod
    def _unique_seeds(cls, seeds: list[int] | None) -> list[int] | None:
        if seeds is not None and len(set(seeds)) != len(seeds):
            raise ValueError(f"seeds must be unique, got {seeds}")
        return seeds

    @field_validator("checkpoints")
    @classmethod
    def _positive(cls, checkpoints: list[int]) -> list[int]:
        if any(n < 1 for n in checkpoints):
            raise ValueError(f"checkpoints must be numbers of simulator calls >= 1, got {checkpoints}")
        return sorted(set(checkpoints))

    @field_validator("compare")
    @classmethod
    def _compare_known_variants(cls, compare: list[str] | None, info: ValidationInfo) -> list[str] | None:
        if compare is None:
            return compare
        if len(compare) != 2 or compare[0] == compare[1]:
            raise ValueError(f"compare needs two different variant names, got {compare}")
        names = [v.name for v in info.data.get("variants", [])]
        unknown = [c for c in compare if c not in names]
        if unknown:
            raise ValueError(f"compare names unknown variant(s) {', '.join(unknown)}; variants are: {', '.join(names)}")
        return compare


# -- monitor -----------------------------------------------------------------------------------
class ReferenceSection(Section):
    noise_model: ConfigPath | None = Field(
        default=None, description="noise model of the reference date (a noise_model.npz written by a run)")


class Campaign(Section):
    date: dt.date
    mileage_km: float | None = Field(default=None, ge=0.0, description="the vehicle's mileage at this date "
                                     "(recorded with the date in the monitoring database)")
    data: dict[str, Any] = Field(default_factory=dict, description="overrides of the data section at this date")


class Scenario(Section):
    parameter: str
    loss: float = Field(default=0.4, gt=0.0, lt=1.0, description="fraction of the nominal value lost at the last date")
    dates: list[dt.date] | None = None
    n_dates: int | None = Field(default=None, ge=2)
    start: dt.date | None = None
    interval_days: int = Field(default=30, ge=1)


class MonitorOptions(Section):
    """The validated ``monitor:`` section (see the module docstring)."""

    reference: ReferenceSection = Field(default_factory=ReferenceSection)
    acceptable: dict[str, tuple[float | None, float | None]] = Field(default_factory=dict)
    campaigns: list[Campaign] = Field(default_factory=list)
    scenario: Scenario | None = None


# -- diagnose ----------------------------------------------------------------------------------
class DiagnoseOptions(Section):
    """The ``diagnose:`` section of a config."""

    at: Literal["identified", "nominal"] = Field(
        default="identified", description="base model: identified parameters (a run first) or nominal ones")
    bands_per_octave: float = Field(default=3.0, gt=0.0, le=24.0, description="band width: 1/bands_per_octave octave")
    min_bins_per_band: int = Field(default=3, ge=1, description="least grid frequencies per band (merged upwards)")
    alpha: float = Field(default=0.05, gt=0.0, lt=1.0, description="false discovery rate (Benjamini-Yekutieli)")
    min_db: float = Field(default=0.5, ge=0.0, le=10.0, description="relevance margin, dB: a cell is flagged when its "
                          "discrepancy exceeds this beyond the noise (0: any significant discrepancy)")
    n_bootstrap: int = Field(default=200, ge=0, description="parametric bootstrap replicates of the null (0: analytic)")
    effects: list[str] | None = Field(default=None, description="candidate effects (default: every registered "
                                      "effect the simulator supports)")
    margin: float = Field(default=10.0, ge=0.0, description="score margin over the runner-up and the bump to name")
    min_explained: float = Field(default=0.5, ge=0.0, le=1.0,
                                 description="share of the flagged cells' discrepancy the named effect must explain")
    n_starts: int = Field(default=2, ge=1, description="starting points refined per effect")
    max_evaluations: int = Field(default=30, ge=3, description="simulator calls per refinement")
    reidentify: bool = Field(default=True, description="fit the suspension again jointly with the named effects, "
                             "and run the identification of the augmented model (after/)")
    max_new_flagged: float = Field(default=0.1, ge=0.0, description="new flagged cells a named effect may create "
                                   "elsewhere, as a share of the cells flagged before it")
    max_effects: int = Field(default=3, ge=1, le=10, description="effects named one after the other, at most")
    fit_suspension: bool = Field(default=True, description="fit the identified suspension by least squares on the "
                                 "diagnosis's criterion D, from the identification's w_opt (at: identified)")
    joint_max_evaluations: int = Field(default=150, ge=5, description="simulator calls of one least-squares fit of "
                                       "the suspension and the effects' parameters (Jacobians included)")
    coupling_reference: ConfigPath | None = Field(
        default=None, description="reference-date measured accelerations (file or folder): their "
        "vertical-into-lateral coupling is subtracted in the coupling test (the train's own coupling)")
    coupling_reference_track: ConfigPath | None = Field(
        default=None, description="the track measured with coupling_reference")
