"""The ``exudyn-train`` simulator: options, parameters, channels, simulate, modes."""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Literal, Mapping, Sequence

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, PositiveFloat, ValidationError, field_validator, model_validator
from pydantic_core import InitErrorDetails

from suspid.options import parse_options
from suspid.errors import SimulatorError
from suspid.elements import declared_groups, resolve_group
from suspid.interfaces import (DifferentiableSimulator, Element, ElementSimulator, Parameter, Response, Simulator,
                               TrackSegment)

from . import effects as E
from . import parameters as P
from .layout import layout_of
from .model import FLOOR_HEIGHT, TABLE_PAD, Sensor, TimeFeatures, TrainModel, default_sensors
from .modes import critical_speed, modes_summary, stability_sweep
from .sensitivity import analytic_parameters, matrix_derivatives, record_derivatives
from .solvers import (FrequencyResponse, InputSpectra, TimeSettings, check_segment, is_constant_speed, output_samples,
                      simulate_frequency, simulate_time)
from .variable_speed import SpeedFamily, car_distance, quantised_speed, simulate_variable_speed
from .curving import (CURVE_DT, CurveModel, CurveTables, DesignTrack, check_curve, curve_forces, curve_response,
                      forced_rows, frame_outputs, has_curve, static_coordinates)


MODEL_VERSION = 2
"""Version of the model's physics, part of :meth:`ExudynTrain.identity`: cached evaluations of an
earlier model are not reused. 2: Maxwell yaw dampers, free longitudinal carbody and bogie motion with
traction rods, Kalker creep coefficients, track support, g × roll in lateral sensors, vehicle presets."""


LATER_OPTIONS: dict[tuple[str, str], Any] = {("contact", "creep_at_contact_point"): False}
"""Options added after :data:`MODEL_VERSION` was last raised, with the value at which the model is the earlier
one exactly: at that value :meth:`ExudynTrain.identity` leaves them out (cached evaluations stay valid)."""


class SensorOptions(BaseModel):
    """One accelerometer channel."""

    model_config = ConfigDict(extra="forbid")

    name: str = Field(min_length=1, description="channel name")
    body: str = Field(description="body the sensor is fixed to: carbody, bogie_front, bogie_rear, wheelset_1-4 "
                      "(articulated presets: carbody_<c>, bogie_<b>, wheelset_<j>)")
    direction: Literal["vertical", "lateral", "longitudinal"] = "vertical"
    position: tuple[float, float, float] = Field(
        default=(0.0, 0.0, 0.0), description="m, relative to the body's centre of mass (x forward, y left, z up)")


class ContactOptions(BaseModel):
    """Wheel-rail contact options."""

    model_config = ConfigDict(extra="forbid")

    conicity: PositiveFloat | None = Field(default=None, le=1.0,
                                           description="equivalent conicity (default: the parameter table's)")
    creep_saturation: bool = Field(default=False, description="nonlinear creep saturation (time solver only)")
    friction: PositiveFloat = Field(default=0.3, le=1.0, description="wheel-rail friction coefficient for saturation")
    bump_stops: bool = Field(default=False, description="lateral bump stops carbody-bogie (time solver only)")
    bump_gap_m: PositiveFloat = Field(default=0.025, description="free lateral play before the bump stop, m "
                                      "(Manchester Benchmark Vehicle 1, Iwnicki 1998)")
    bump_stiffness: PositiveFloat = Field(default=2.0e6, description="bump stop stiffness, N/m (assumption)")
    wheelset_rolling: bool = Field(
        default=True, description="the wheelsets move longitudinally and spin, held by the longitudinal creep "
        "forces (false: their longitudinal motion and spin are held to ground, as in models that neglect them)")
    creep_at_contact_point: bool = Field(
        default=False, description="the lateral creep force acts at the contact points, r0 below the axle: the "
        "lateral creepage is (y' + r0 roll') / v - yaw (the wheelset's roll rate moves the contact points "
        "sideways) and the force has the moment r0 F_y on the wheelset's roll (Garg and Dukkipati, Dynamics of "
        "Railway Vehicle Systems, 1984, ch. 4); false: at the axle, as the model had it before, the results of "
        "earlier runs unchanged")


class YawDamperOptions(BaseModel):
    """Yaw damper options (the dampers are Maxwell elements: ``c_yaw`` in series with ``k_yaw_s``)."""

    model_config = ConfigDict(extra="forbid")

    blow_off: bool = Field(default=False, description="blow-off (time solver only): the damper force is "
                           "c_yaw v up to the blow-off velocity, then grows at rate_after_blow_off")
    blow_off_velocity_mps: PositiveFloat = Field(
        default=0.01, description="damper stroke velocity at blow-off, m/s (Mathematical Problems in "
        "Engineering 2019, article 7163732: 3 kN at 0.01 m/s)")
    rate_after_blow_off: PositiveFloat = Field(
        default=20e3, description="damping rate above the blow-off velocity, N s/m (same source: 20 kN s/m)")


DIFFERENCE_STEP = 1e-4
"""Relative step of the central differences :meth:`ExudynTrain.simulate_jacobian` takes on segments with a speed
record or a curve (their derivatives are not analytic)."""


class Options(BaseModel):
    """The ``simulator.options`` of ``exudyn-train``."""

    model_config = ConfigDict(extra="forbid")

    solver: Literal["time", "frequency"] = Field(
        default="frequency", description="'frequency': linearised model, fast (a speed record: "
        "short-time constant speed with overlap-add); 'time': exudyn generalised-alpha, nonlinear options")
    fs_hz: PositiveFloat = Field(default=100.0, description="output sampling rate, Hz")
    step_s: PositiveFloat = Field(default=0.002, le=0.01,
                                  description="largest time step of the time solver, s (used: 1/(k fs))")
    spectral_radius: float = Field(default=0.8, ge=0.0, le=1.0,
                                   description="generalised-alpha spectral radius at infinite frequency")
    speed_kmh: PositiveFloat = Field(default=320.0, description="speed for `modes` (segments carry their own), km/h")
    sensors: list[SensorOptions] | None = Field(default=None, description="channels (default: 10, see docs)")
    contact: ContactOptions = Field(default_factory=ContactOptions)
    yaw_damper: YawDamperOptions = Field(default_factory=YawDamperOptions)
    vehicle: dict[str, float | str] = Field(
        default_factory=dict, description="vehicle preset and nominal values of model parameters: a preset name "
        f"({', '.join(P.PRESETS)}; default {P.DEFAULT_PRESET}), or a mapping {{preset: <name>, <parameter>: "
        "<SI value>, ...}}")
    gravity_roll: bool = Field(default=True, description="lateral accelerometers are fixed to their body and also "
                               "measure g times its roll angle (false: kinematic lateral acceleration only)")
    taper_m: float = Field(default=20.0, ge=0.0, description="fade-in/out length of each segment's track, m")
    settle_s: PositiveFloat = Field(default=8.0, description="frequency solver: least zero padding for the decay "
                                    "of the impulse response, s")
    effects: list[dict[str, Any]] = Field(
        default_factory=list, description="model extensions, each {name: <registered effect>, <parameter>: value}; "
        f"supported here: {', '.join(E.supported())}")

    @field_validator("effects")
    @classmethod
    def _effects(cls, value: list[dict[str, Any]]) -> list[dict[str, Any]]:
        return validate_effects(value)

    @field_validator("vehicle", mode="before")
    @classmethod
    def _preset_name(cls, value: Any) -> Any:
        return {"preset": value} if isinstance(value, str) else value

    @field_validator("vehicle")
    @classmethod
    def _known(cls, value: dict[str, float | str]) -> dict[str, float | str]:
        preset = value.get("preset", P.DEFAULT_PRESET)
        if preset not in P.PRESETS:
            raise ValueError(f"unknown vehicle preset {preset!r} (known: {', '.join(P.PRESETS)})")
        numbers = {k: v for k, v in value.items() if k != "preset"}
        known = P.by_name(preset)
        problems = P.check_values(numbers, known)
        if problems:
            raise ValueError(problems[0] + f" (known: preset, {', '.join(sorted(known))})")
        return value

    @property
    def preset(self) -> str:
        """The selected vehicle preset."""
        return str(self.vehicle.get("preset", P.DEFAULT_PRESET))

    @property
    def layout(self):
        """The bodies of the selected preset (:class:`.layout.Layout`)."""
        return layout_of(self.preset)

    def vehicle_values(self) -> dict[str, float]:
        """The nominal parameter values: the preset's, then the ``vehicle`` overrides and ``contact.conicity``."""
        values = P.nominal_values(self.preset)
        values.update({k: float(v) for k, v in self.vehicle.items() if k != "preset"})
        if self.contact.conicity is not None:
            values["conicity"] = float(self.contact.conicity)
        return values

    @field_validator("sensors")
    @classmethod
    def _unique(cls, value):
        if value is not None:
            names = [s.name for s in value]
            if not names:
                raise ValueError("at least one sensor is needed")
            dup = sorted({n for n in names if names.count(n) > 1})
            if dup:
                raise ValueError(f"sensor names must be unique, repeated: {', '.join(dup)}")
        return value

    @model_validator(mode="after")
    def _consistent(self) -> "Options":
        if self.contact.conicity is not None and "conicity" in self.vehicle:
            raise ValueError("conicity is given twice (contact.conicity and vehicle.conicity); keep one")
        if self.solver == "frequency" and (self.contact.creep_saturation or self.contact.bump_stops):
            raise ValueError("creep_saturation and bump_stops are nonlinear: they need solver: time")
        if self.solver == "frequency" and self.yaw_damper.blow_off:
            raise ValueError("yaw_damper.blow_off is nonlinear: it needs solver: time")
        if self.yaw_damper.blow_off and any(e["name"] == "yaw-damper-series-stiffness" for e in self.effects):
            raise ValueError("yaw_damper.blow_off acts on the model's own yaw dampers; the effect "
                             "'yaw-damper-series-stiffness' replaces them: use one or the other")
        layout = self.layout
        sensors = (default_sensors(self.vehicle_values(), layout) if self.sensors is None else
                   [Sensor(s.name, s.body, s.direction, tuple(s.position)) for s in self.sensors])
        for i, s in enumerate(sensors):
            if s.body not in layout.bodies:
                raise ValueError(f"sensors.{i}.body: unknown body {s.body!r} for vehicle {self.preset!r} "
                                 f"(bodies: {', '.join(layout.bodies)})")
        for i, spec in enumerate(self.effects):
            try:
                E.make(spec).check(sensors, layout.n_wheelsets)
            except ValueError as exc:
                raise ValueError(f"effect {i}: {exc}") from None
        return self


def validate_effects(value: list[Any]) -> list[dict[str, Any]]:
    """Each entry against its registered effect's ``Options`` (errors located as ``effects.<i>.<field>``).

    :returns: ``[{name, **every parameter}]`` with defaults filled in.
    """
    from suspid import registry
    from suspid.errors import UnknownPluginError

    out, names = [], []
    for i, item in enumerate(value):
        if not isinstance(item, dict) or not isinstance(item.get("name"), str):
            raise ValueError(f"effect {i}: expected a mapping with a 'name' (one of: {', '.join(E.supported())})")
        params = dict(item)
        name = params.pop("name")
        try:
            effect_cls = registry.get("effect", name)
        except UnknownPluginError as exc:
            raise ValueError(f"effect {i}: {exc}") from None
        if name not in E.IMPLEMENTATIONS:
            raise ValueError(f"effect {i}: '{name}' is not supported by exudyn-train (supported: "
                             f"{', '.join(E.supported())})")
        if name in names:
            raise ValueError(f"effect {i}: '{name}' is enabled twice; enable each effect once")
        names.append(name)
        try:
            validated = effect_cls.Options.model_validate(params).model_dump()
        except ValidationError as exc:
            allowed = ", ".join(["name", *effect_cls.Options.model_fields])
            raise ValidationError.from_exception_data("effects", [
                InitErrorDetails(type="value_error", loc=(i, *e["loc"]), input=e["input"],
                                 ctx={"error": ValueError(f"unknown parameter of effect '{name}'; expected one of: "
                                                          f"{allowed}")})
                if e["type"] == "extra_forbidden" else
                InitErrorDetails(type=e["type"], loc=(i, *e["loc"]), input=e["input"], ctx=e.get("ctx", {}))
                for e in exc.errors()]) from None
        out.append({"name": name, **validated})
    return out


def _canonical(name: str, groups: dict) -> str | None:
    """The canonical name of the element group ``name`` (tags in any order, :func:`suspid.elements.resolve_group`),
    ``None`` when it selects no declared elements."""
    if name in groups:
        return name
    elements = [Element(g.kind, m) for g in groups.values() if not g.tags for m in g.members]
    g = resolve_group(elements, name)
    return None if g is None else g.name


def _unit(parameter: str) -> str:
    """Unit of an effect parameter from its name's suffix."""
    for suffix, unit in (("_n_per_m", "N/m"), ("_hz", "Hz"), ("_kg", "kg"), ("_deg", "deg"), ("_rad", "rad"),
                         ("_m", "m")):
        if parameter.endswith(suffix):
            return unit
    return "1"


class ExudynTrain(Simulator, DifferentiableSimulator, ElementSimulator):
    """High-speed car built with exudyn: 7 rigid bodies, suspension, linearised wheel-rail contact.

    See :mod:`suspid.plugins.simulators.exudyn_train` for the model and
    :mod:`.parameters` for every parameter's value and source. The
    constructor only stores its options; models are built on first use and
    kept (one per solver configuration), and are not pickled.
    """

    name = "exudyn-train"
    Options = Options

    def __init__(self, **options: Any) -> None:
        super().__init__(**options)
        self._opts: Options | None = None
        self._effects: list[E.ExudynEffect] | None = None
        self._models: dict = {}
        self._spectra = InputSpectra()
        self._frf: dict = {}
        self._blocks: dict = {}
        self._checked: dict = {}

    # ------------------------------------------------------------------ options and parameters
    @property
    def opts(self) -> Options:
        """The validated options (validated on first use)."""
        if self._opts is None:
            self._opts = parse_options(Options, self.options, "simulator.options")
        return self._opts

    def sampling_rate_hz(self) -> float:
        """The output sampling rate ``fs_hz``, Hz."""
        return float(self.opts.fs_hz)

    def _nominal(self) -> dict[str, float]:
        return self.opts.vehicle_values()

    def effects(self) -> list[E.ExudynEffect]:
        """The implementations of the enabled effects (``options.effects``), in order."""
        if self._effects is None:
            self._effects = [E.make(spec) for spec in self.opts.effects]
        return self._effects

    def supported_effects(self) -> list[str]:
        """Names of the registered effects this model implements (``options.effects``)."""
        return E.supported()

    def _effect_parameters(self) -> list[Parameter]:
        """The fitted parameters of the enabled effects, named ``<effect>/<parameter>``."""
        from suspid import registry

        out = []
        for spec, effect in zip(self.opts.effects, self.effects()):
            cls = registry.get("effect", spec["name"])
            for name in effect.fitted:
                lo, hi = cls.bounds(name)
                v = float(spec[name])
                field = cls.Options.model_fields[name]
                out.append(Parameter(effect.key(name), _unit(name), v, min(lo, v), max(hi, v),
                                     f"effect {spec['name']}: {field.description or name}"))
        return out

    def parameters(self) -> list[Parameter]:
        nominal = self._nominal()
        out = []
        for p in P.parameter_table(self.opts.preset):
            v = nominal[p.name]
            out.append(Parameter(p.name, p.unit, v, min(p.lower, v), max(p.upper, v),
                                 f"{p.description}; source: {p.source}", domain=(0.0, math.inf)))
        return out + self._effect_parameters()

    def default_parameters(self) -> list[str]:
        return list(P.DEFAULT_IDENTIFIED)

    def elements(self) -> list[Element]:
        """Every suspension element (:data:`.parameters.ELEMENT_KINDS`, tags of
        :meth:`.layout.Layout.element_tags`): per axlebox the primary rates, per carbody end and side the
        secondary springs and dampers, per bogie and side the yaw dampers, per bogie the traction rod and
        anti-roll bar. The yaw dampers are left out when an effect replaces them or they blow off (one
        damper law for all of them)."""
        layout = self.opts.layout
        replaced = set().union(*(e.replaces for e in self.effects()))
        out = []
        for placement, kinds in P.ELEMENT_KINDS.items():
            if placement == "yaw" and ("yaw_damper" in replaced or self.opts.yaw_damper.blow_off):
                continue
            tags = layout.element_tags(placement)
            out += [Element(kind, t) for kind in kinds for t in tags]
        return out

    def candidate_sensors(self) -> list[Sensor]:
        """Accelerometers a sensor-placement advice may add (:meth:`candidate_channels`): on each carbody above
        each of its pivots, left and right (floor level, y = ±b_sec), vertical and longitudinal; on each bogie
        frame left and right (±b_yaw) vertical and longitudinal, and lateral over its leading and trailing
        wheelset; on each wheelset's axleboxes (±b_prim) vertical."""
        v = self._nominal()
        layout = self.opts.layout
        z = FLOOR_HEIGHT - v["h_car"]
        out = []
        for car in layout.carbodies:
            for where, x in (("front", v["a_bogie"]), ("rear", -v["a_bogie"])):
                for side, y in (("left", v["b_sec"]), ("right", -v["b_sec"])):
                    for d in ("vertical", "longitudinal"):
                        out.append(Sensor(f"{car}_{where}_{side}_{d}", car, d, (x, y, z)))
        for bogie in layout.bogies:
            for side, y in (("left", v["b_yaw"]), ("right", -v["b_yaw"])):
                for d in ("vertical", "longitudinal"):
                    out.append(Sensor(f"{bogie}_{side}_{d}", bogie, d, (0.0, y, 0.0)))
            for where, x in (("leading", v["a_ws"]), ("trailing", -v["a_ws"])):
                out.append(Sensor(f"{bogie}_{where}_lateral", bogie, "lateral", (x, 0.0, 0.0)))
        for ws in layout.wheelsets:
            for side, y in (("left", v["b_prim"]), ("right", -v["b_prim"])):
                out.append(Sensor(f"{ws}_{side}_vertical", ws, "vertical", (0.0, y, 0.0)))
        have = set(self.channels())
        return [s for s in out if s.name not in have]

    def candidate_channels(self) -> list[str]:
        return [s.name for s in self.candidate_sensors()]

    def with_channels(self, channels: Sequence[str]) -> "ExudynTrain":
        """This simulator with the candidate ``channels`` added after its own (:meth:`candidate_sensors`).

        :raises SimulatorError: a name that is not a candidate channel.
        """
        by_name = {s.name: s for s in self.candidate_sensors()}
        unknown = [c for c in channels if c not in by_name]
        if unknown:
            raise SimulatorError(f"exudyn-train: unknown candidate channel(s) {', '.join(unknown)} "
                                 f"(candidates: {', '.join(by_name)})")
        current = [{"name": s.name, "body": s.body, "direction": s.direction, "position": list(s.position)}
                   for s in self.sensors()]
        extra = [{"name": c, "body": by_name[c].body, "direction": by_name[c].direction,
                  "position": list(by_name[c].position)} for c in channels]
        return type(self)(**{**self.options, "sensors": current + extra})

    def _groups(self) -> dict:
        if getattr(self, "_group_cache", None) is None:
            self._group_cache = declared_groups(self.elements())
        return self._group_cache

    def calibratable(self) -> list[str]:
        """The model parameters the vehicle tables give as assumptions or ranges (:data:`.parameters.CALIBRATABLE`):
        the dampers' series stiffnesses, the creep-coefficient scale and the equivalent conicity; then the fitted
        parameters of the enabled effects (``<effect>/<parameter>``, e.g. ``carbody-bending/frequency_hz``): a
        configured effect's frequency and damping are an assumption or a diagnosis's estimate as well, and where
        the model's added resonance sits elsewhere than the vehicle's, an element's sensitivity near it has the
        wrong shape."""
        names = {p.name for p in self.parameters()}
        return [n for n in P.CALIBRATABLE if n in names] + [p.name for p in self._effect_parameters()]

    def sensors(self, values: Mapping[str, float] | None = None) -> list[Sensor]:
        """The sensors of the configured channels (defaults depend on the geometry ``values``)."""
        if self.opts.sensors is None:
            return default_sensors(dict(values or self._nominal()), self.opts.layout)
        return [Sensor(s.name, s.body, s.direction, tuple(float(c) for c in s.position)) for s in self.opts.sensors]

    def channels(self) -> list[str]:
        return [s.name for s in self.sensors()]

    def values(self, w: Mapping[str, float]) -> dict[str, float]:
        """All parameter values for ``w`` (parameters not named keep their nominal values).

        :raises SimulatorError: unknown names or non-positive values.
        """
        values = self._nominal()
        effect_values = {p.name: p.nominal for p in self._effect_parameters()}
        groups = self._groups() if any("[" in k for k in w) else {}
        canonical = {k: _canonical(k, groups) for k in w if "[" in k}
        unknown = [k for k in w if k not in values and k not in effect_values and canonical.get(k) is None]
        if unknown:
            raise SimulatorError(f"unknown parameter(s) {', '.join(map(repr, unknown))} for exudyn-train; "
                                 f"known: {', '.join(sorted(values) + sorted(effect_values))}")
        values.update({k: float(v) for k, v in w.items() if k in values})
        values.update({canonical[k]: float(v) for k, v in w.items() if canonical.get(k) is not None})
        problems = P.check_values(values, P.by_name(self.opts.preset))
        effect_values.update({k: float(v) for k, v in w.items() if k in effect_values})
        problems += [f"effect parameter '{k}' = {v!r} must be finite" for k, v in effect_values.items()
                     if not math.isfinite(v)]
        if problems:
            raise SimulatorError(problems[0])
        values.update(effect_values)
        for effect in self.effects():
            effect.adjust_values(values)
        return values

    # ------------------------------------------------------------------ models
    def _model(self, values: dict[str, float], speed: float, features: TimeFeatures) -> TrainModel:
        sensors = self.sensors(values)
        key = features.key()
        model = self._models.get(key)
        if model is None or model.needs_rebuild(values, sensors, features):
            try:
                model = TrainModel(values, sensors, speed, features, self.effects(), self.opts.gravity_roll,
                                   self.opts.layout, rolling=self.opts.contact.wheelset_rolling,
                                   contact_point=self.opts.contact.creep_at_contact_point)
            except ValueError as exc:
                raise SimulatorError(f"exudyn-train: cannot build the model: {exc}") from exc
            self._models[key] = model
            if key == TimeFeatures().key():
                self._frf.clear()
        else:
            model.update(values, speed)
        return model

    def _features(self, segments: Sequence[TrackSegment]) -> TimeFeatures:
        c = self.opts.contact
        o = self.opts
        n = max(len(s.distance) for s in segments) + 2 * TABLE_PAD
        cap = 1 << max(4, int(math.ceil(math.log2(n))))
        variable = not all(is_constant_speed(s) for s in segments)
        # the speed table spans the run-in (leading wheelset up to 15 m ahead of the car centre, more for an
        # articulated rake), the record and the run-out, at 0.02 s
        ahead = max(15.0, float(np.max(self.opts.layout.wheelset_x(self._nominal()))) + 2.0)
        longest = max(s.duration() + ahead / float(np.atleast_1d(s.speed)[0]) + 1.0 for s in segments)
        speed_cap = (1 << max(6, int(math.ceil(math.log2(longest / 0.02 + 60))))) if variable else 0
        return TimeFeatures(track_capacity=cap, variable_speed=variable, speed_capacity=speed_cap,
                            saturation=c.creep_saturation, friction=c.friction, bump_stops=c.bump_stops,
                            bump_gap=c.bump_gap_m, bump_stiffness=c.bump_stiffness,
                            yaw_blow_off=o.yaw_damper.blow_off, blow_off_velocity=o.yaw_damper.blow_off_velocity_mps,
                            blow_off_rate=o.yaw_damper.rate_after_blow_off)

    # ------------------------------------------------------------------ simulate
    def _check_segments(self, segments: Sequence[TrackSegment]) -> None:
        for s in segments:
            key = InputSpectra._fingerprint(s)
            if key not in self._checked:
                check_segment(s)
                check_curve(s)
                self._checked[key] = (s.irregularities, s.distance)   # keep the arrays: ids stay unique
                if len(self._checked) > 1024:
                    self._checked.pop(next(iter(self._checked)))

    def simulate(self, w: Mapping[str, float], segments: Sequence[TrackSegment]) -> list[Response]:
        segments = list(segments)
        if not segments:
            return []
        self._check_segments(segments)
        values = self.values(w)
        if self.opts.solver == "time":
            return self._simulate_time(values, segments)
        return self._simulate_frequency(values, segments)

    # ------------------------------------------------------------------ derivatives
    def differentiable(self, names: Sequence[str]) -> list[str]:
        """The parameters :meth:`simulate_jacobian` differentiates (:mod:`.sensitivity`): with the frequency
        solver and no effect enabled, every parameter of the vehicle table but the geometry
        (:data:`.model.GEOMETRY`); none with the time solver (its nonlinear laws) or with effects
        (their periodic inputs and parameters): the caller takes finite differences for those."""
        if self.opts.solver != "frequency" or self.opts.effects:
            return []
        table = {p.name for p in P.parameter_table(self.opts.preset)}
        groups = self._groups() if any("[" in n for n in names) else {}
        return analytic_parameters(names, table | {n for n in names if _canonical(n, groups) is not None})

    def simulate_jacobian(self, w: Mapping[str, float], segments: Sequence[TrackSegment],
                          names: Sequence[str]) -> list[tuple[Response, np.ndarray]]:
        """The records at ``w`` and their derivatives ``(n_p, n_channels, n_t)`` (m/s² per SI unit) with
        respect to ``names``: dH/dp = O (dF/dp - dZ/dp Q) on the eigen-decomposition of the plain solve
        (:mod:`.sensitivity`).

        :raises SimulatorError: a name :meth:`differentiable` does not list, or a failed run.
        """
        names = list(names)
        bad = [n for n in names if n not in self.differentiable([n])]
        if bad:
            raise SimulatorError(f"exudyn-train cannot differentiate {', '.join(map(repr, bad))} (solver "
                                 f"{self.opts.solver!r}; see differentiable()): use finite differences")
        segments = list(segments)
        if not segments:
            return []
        self._check_segments(segments)
        values = self.values(w)
        special = [i for i, s in enumerate(segments) if not is_constant_speed(s) or has_curve(s)]
        if special:
            return self._jacobian_by_differences(w, segments, names, special)
        shared, alone = self._derivative_points(values, names)
        o = self.opts
        channels = tuple(s.name for s in self.sensors(values))
        out: list[tuple[Response, np.ndarray] | None] = [None] * len(segments)
        groups: dict[float, list[int]] = {}
        for i, s in enumerate(segments):
            groups.setdefault(float(s.mean_speed), []).append(i)
        for speed, idx in groups.items():
            model = self._model(values, speed, TimeFeatures())
            base = model.linear_system()
            response = FrequencyResponse(base)
            if not response.modal:
                raise SimulatorError("exudyn-train: the eigenvectors of the linear model are ill-conditioned "
                                     f"at {speed * 3.6:.1f} km/h; its derivatives need finite differences")
            try:
                common = [n for n in names if n not in alone]
                found = dict(zip(common, matrix_derivatives(model, shared, speed, common, base)))
                for n, at in alone.items():
                    found[n], = matrix_derivatives(model, at, speed, [n], base)
                derivatives = [found[n] for n in names]
            except ValueError as exc:
                raise SimulatorError(f"exudyn-train: {exc}") from exc
            group = [segments[i] for i in idx]
            records = simulate_frequency(response, group, o.fs_hz, o.taper_m, o.settle_s, self._spectra, channels, {})
            grads = record_derivatives(response, derivatives, group, o.fs_hz, o.taper_m, o.settle_s, self._spectra)
            for i, r, g in zip(idx, records, grads):
                out[i] = (r, g)
        return out  # type: ignore[return-value]

    def _derivative_points(self, values: dict[str, float], names: list[str]
                           ) -> tuple[dict[str, float], dict[str, dict[str, float]]]:
        """Where each of ``names`` is differentiated: ``(shared, alone)``. A group not in ``values`` is added at
        its elements' value (its kind's, or a wider group's); in ``shared`` (one call, linearisations shared) when
        no other name acts on its elements, else ``alone[name]``: the values with that group only, so that a
        kind asked with it keeps acting on its other elements."""
        missing = [n for n in names if "[" in n and n not in values]
        if not missing:
            return values, {}
        groups = self._groups()
        resolved = {n: groups[_canonical(n, groups)] for n in names if "[" in n}
        at = {n: self._element_value(values, resolved[n]) for n in missing}

        def crowded(n: str) -> bool:
            g = resolved[n]
            return g.kind in names or any(o != n and resolved[o].overlaps(g) for o in resolved)

        alone = {n: {**values, n: at[n]} for n in missing if crowded(n)}
        shared = {**values, **{n: at[n] for n in missing if n not in alone}}
        return shared, alone

    @staticmethod
    def _element_value(values: dict[str, float], group) -> float:
        """The value the first element of ``group`` has in ``values``."""
        placement = next(pl for pl, kinds in P.ELEMENT_KINDS.items() if group.kind in kinds)
        return float(P.element_view(values, P.ELEMENT_KINDS[placement], group.members[0])[group.kind])

    def _jacobian_by_differences(self, w: Mapping[str, float], segments: list[TrackSegment], names: list[str],
                                 special: list[int]) -> list[tuple[Response, np.ndarray]]:
        """:meth:`simulate_jacobian` when some segments have a speed record or a curve: the others
        analytically, these by central differences of :meth:`simulate` (relative step
        :data:`DIFFERENCE_STEP`; the records are smooth in the parameters)."""
        plain = [i for i in range(len(segments)) if i not in special]
        out: list[tuple[Response, np.ndarray] | None] = [None] * len(segments)
        if plain:
            for i, pair in zip(plain, self.simulate_jacobian(w, [segments[i] for i in plain], names)):
                out[i] = pair
        group = [segments[i] for i in special]
        base = self.simulate(w, group)
        values = self.values(w)
        grads = [np.zeros((len(names),) + r.accelerations.shape) for r in base]
        groups = self._groups() if any("[" in n for n in names) else {}
        for k, name in enumerate(names):
            x = values[name] if name in values else self._element_value(values, groups[_canonical(name, groups)])
            h = DIFFERENCE_STEP * max(abs(x), 1e-12)
            up = self.simulate({**w, name: x + h}, group)
            down = self.simulate({**w, name: x - h}, group)
            for g, a, b in zip(grads, up, down):
                g[k] = (a.accelerations - b.accelerations) / (2 * h)
        for i, r, g in zip(special, base, grads):
            out[i] = (r, g)
        return out  # type: ignore[return-value]

    def _simulate_time(self, values: dict[str, float], segments: list[TrackSegment]) -> list[Response]:
        o = self.opts
        features = self._features(segments)
        if any(has_curve(s) for s in segments):
            ahead = max(15.0, float(np.max(o.layout.wheelset_x(self._nominal()))) + 2.0)
            longest = max(s.duration() + ahead / float(np.min(s.speed)) + 1.0 for s in segments)
            features = dataclasses.replace(
                features, curve_capacity=1 << max(6, int(math.ceil(math.log2(longest / CURVE_DT + 60)))))
        settings = TimeSettings(fs=o.fs_hz, step=o.step_s, spectral_radius=o.spectral_radius, taper_m=o.taper_m,
                                # a speed record puts the creep forces (f/v, v the odometer's velocity) into a
                                # symbolic function: a single linear solve would keep the step matrix of the
                                # starting speed, so it needs Newton iterations like the other nonlinear laws
                                newton=features.saturation or features.bump_stops or features.yaw_blow_off
                                or features.variable_speed)
        out = []
        for seg in segments:
            speed = float(seg.mean_speed)
            frame = self._time_curve(values, seg, features, settings) if features.curve_capacity else None
            model = self._model(values, speed, features)
            record = simulate_time(model, seg, settings)
            if frame is not None and has_curve(seg):
                record = Response(record.channels, record.fs, record.accelerations + frame, record.segment)
            out.append(record)
        return out

    def _time_curve(self, values: dict[str, float], segment: TrackSegment, features: TimeFeatures,
                    settings: TimeSettings) -> np.ndarray:
        """Fill the time model's curve force tables for ``segment`` (zero for straight track) and its initial
        state (the static equilibrium of the curve at the start); returns the sensors' frame terms
        ``(n_sensors, n_t)`` (:mod:`.curving`)."""
        fs = settings.fs
        speed = float(segment.mean_speed)
        lin = self._model(values, speed, TimeFeatures()).linear_system()      # M, G, labels: the same coordinates
        model = self._model(values, speed, features)
        if getattr(model, "curve_tables", None) is None:
            cm0 = CurveModel.of(values, self.opts.layout, self.sensors(values), self.opts.gravity_roll)
            model.curve_tables = CurveTables(model, forced_rows(cm0, lin), features.curve_capacity)
        cm = CurveModel.of(values, self.opts.layout, self.sensors(values), self.opts.gravity_roll)
        # the time solver's run-in: the car starts n_pre samples before the record (see simulate_time)
        v_start = float(np.atleast_1d(segment.speed)[0])
        t_pre = (int(math.ceil(float(np.max(lin.wheelset_x)) / v_start * fs)) + 1) / fs
        n_t = output_samples(segment, fs)
        tau = np.arange(features.curve_capacity) * CURVE_DT
        tau = tau[: int(math.ceil((t_pre + n_t / fs + 0.1 + 12.0 / fs) / CURVE_DT)) + 2]
        if has_curve(segment):
            design = DesignTrack(segment)
            s, v = car_distance(segment, tau - t_pre)
            F = curve_forces(cm, lin, design, s, v)
            static = static_coordinates(lin, F[:, :1])
            q0 = {lin.labels.index(k): float(val[0]) for k, val in static.items()}
            t = np.arange(n_t) / fs
            s_r, v_r = car_distance(segment, t)
            frame = frame_outputs(cm, design, s_r, v_r)
        else:
            F, q0, frame = np.zeros((lin.M.shape[0], tau.size)), {}, np.zeros((len(cm.sensors), n_t))
        model.curve_tables.set(F, q0)
        return frame

    def _simulate_frequency(self, values: dict[str, float], segments: list[TrackSegment]) -> list[Response]:
        o = self.opts
        groups: dict[float, list[int]] = {}
        varying: list[int] = []
        for i, s in enumerate(segments):
            if is_constant_speed(s):
                groups.setdefault(float(s.mean_speed), []).append(i)
            else:
                varying.append(i)
        out: list[Response | None] = [None] * len(segments)
        channels = tuple(s.name for s in self.sensors(values))
        for i in varying:      # short-time constant speed with overlap-add (:mod:`.variable_speed`)
            out[i] = simulate_variable_speed(lambda v0, n_fft: self._speed_family(values, v0, n_fft), segments[i],
                                             o.fs_hz, o.taper_m, o.settle_s, channels)
        for speed, idx in groups.items():
            response, frf_cache = self._frequency_response(values, speed)
            results = simulate_frequency(response, [segments[i] for i in idx], o.fs_hz, o.taper_m, o.settle_s,
                                         self._spectra, channels, frf_cache)
            for i, r in zip(idx, results):
                out[i] = r
        for i, seg in enumerate(segments):     # curves and cant: superposed on the track's response
            if has_curve(seg):
                out[i] = self._add_curve(values, seg, out[i])
        return out  # type: ignore[return-value]

    def _add_curve(self, values: dict[str, float], segment: TrackSegment, record: Response) -> Response:
        """``record`` plus the response to the segment's curvature and cant (:mod:`.curving`), with the
        linear model at the segment's (mean) speed."""
        o = self.opts
        if is_constant_speed(segment):
            v = float(segment.mean_speed)
            response = self._frequency_response(values, v)[0]
            x0 = float(segment.distance[0])

            def s_of_t(t):
                return x0 + v * t

            def v_of_t(t):
                return np.full_like(t, v)
        else:
            v0 = quantised_speed(segment.length / segment.duration())
            self._speed_family(values, v0, 0)             # the model about v0 (cached with the blocks)
            response = self._frf_blocks(values)[("response", v0)]

            def s_of_t(t):
                return car_distance(segment, t)[0]

            def v_of_t(t):
                return car_distance(segment, t)[1]
        cm = CurveModel.of(values, o.layout, self.sensors(values), o.gravity_roll)
        y = curve_response(response, cm, segment, o.fs_hz, record.accelerations.shape[1], o.settle_s,
                           s_of_t, v_of_t)
        return Response(record.channels, record.fs, record.accelerations + y, record.segment)

    def _frequency_response(self, values: dict[str, float], speed: float) -> tuple[FrequencyResponse, dict]:
        """The linear model's frequency response at ``speed`` and its FRF cache, once per parameter vector
        and speed, reused for every segment."""
        key = tuple(sorted(values.items()))
        cached = self._frf.get(speed)
        if cached is not None and cached[0] == key:
            return cached[1], cached[2]
        model = self._model(values, speed, TimeFeatures())
        response = FrequencyResponse(model.linear_system())
        self._frf[speed] = (key, response, {})
        return response, self._frf[speed][2]

    def _speed_family(self, values: dict[str, float], v0: float, n_fft: int) -> SpeedFamily:
        """The per-wheelset responses about ``v0`` (m/s) on the lines k fs / n_fft, for any speed
        (:class:`.variable_speed.SpeedFamily`): only the creep damping depends on the speed
        (D = D_inf + D_creep / v, as in :class:`.modes.SpeedDependentSystem`), separated from two
        linearisations; one eigen-decomposition per parameter vector and ``v0``."""
        blocks = self._frf_blocks(values)
        hit = blocks.get((v0, n_fft))
        if hit is not None:
            return hit
        if "d_creep" not in blocks:
            a = self._model(values, 50.0, TimeFeatures()).linear_system()
            b = self._model(values, 100.0, TimeFeatures()).linear_system()
            d_creep = (a.D - b.D) * 100.0        # D(50) - D(100) = D_creep (1/50 - 1/100)
            blocks["d_creep"] = (b, b.D - d_creep / 100.0, d_creep)
        base, d_inf, d_creep = blocks["d_creep"]
        if ("response", v0) not in blocks:
            blocks[("response", v0)] = FrequencyResponse(dataclasses.replace(base, D=d_inf + d_creep / v0,
                                                                              speed=float(v0)))
        freqs = np.arange(n_fft // 2 + 1) * self.opts.fs_hz / n_fft if n_fft else np.zeros(0)
        family = blocks[(v0, n_fft)] = SpeedFamily(blocks[("response", v0)], d_creep, freqs)
        return family

    def _frf_blocks(self, values: dict[str, float]) -> dict:
        """Per-wheelset responses of the variable-speed blocks for ``values``, keyed by (speed, FFT length)."""
        key = tuple(sorted(values.items()))
        if self._blocks.get("values") != key:
            self._blocks.clear()
            self._blocks["values"] = key
        return self._blocks

    # ------------------------------------------------------------------ modes
    def linear_system(self, w: Mapping[str, float] | None = None, speed: float | None = None):
        """exudyn's linearisation at ``speed`` (m/s; default the ``speed_kmh`` option)."""
        v = float(speed) if speed is not None else self.opts.speed_kmh / 3.6
        if not v > 0:
            raise SimulatorError(f"speed must be positive, got {v}")
        return self._model(self.values(w or {}), v, TimeFeatures()).linear_system()

    def modes(self, speed: float | None = None, w: Mapping[str, float] | None = None) -> dict:
        """Modes at ``speed`` (m/s; default the ``speed_kmh`` option): frequency (Hz), damping ratio,
        dominant body and motion, and whether every mode is damped.

        :returns: ``{"speed_mps", "speed_kmh", "stable", "least_damped", "modes": [...]}``.
        """
        return modes_summary(self.linear_system(w, speed))

    def critical_speed(self, w: Mapping[str, float] | None = None) -> float:
        """Linear critical speed in m/s at parameters ``w`` (``inf``: stable up to 1500 km/h); see
        :func:`.modes.critical_speed`."""
        return critical_speed(self, dict(w or {}))

    def stability(self, parameters: Sequence[str] | None = None,
                  conicities: Sequence[float] = (0.05, 0.1, 0.15, 0.2, 0.25, 0.3, 0.4), n_points: int = 3) -> dict:
        """Linear critical speed (km/h) at the nominal parameters, against the equivalent conicity and
        against each of ``parameters`` (default: the default identified ones) over its bounds.

        :returns: ``{"nominal_kmh", "conicity": [(lambda, km/h)], "parameters": {name: [(value, km/h)]}}``
            (see :func:`.modes.stability_sweep`).
        """
        return stability_sweep(self, parameters, conicities, n_points)

    # ------------------------------------------------------------------ identity, pickling
    def identity(self) -> dict[str, Any]:
        """Plugin, :data:`MODEL_VERSION` and options: what a cached evaluation was made with. An option of
        :data:`LATER_OPTIONS` at the value that reproduces the earlier model is left out, so that a run
        written before the option existed resumes from its ledger instead of simulating again."""
        options = self.opts.model_dump(mode="json")
        for (section, key), earlier in LATER_OPTIONS.items():
            if options.get(section, {}).get(key) == earlier:
                del options[section][key]
        return {"plugin": self.name, "model": MODEL_VERSION, "options": options}

    def __getstate__(self) -> dict:
        state = self.__dict__.copy()
        state["_models"] = {}
        state["_effects"] = None
        state["_spectra"] = InputSpectra()
        state["_frf"] = {}
        state["_blocks"] = {}
        state["_checked"] = {}
        return state
