"""The exudyn multibody model of the car: bodies, suspension, wheel-rail contact, track support, sensors.

One :class:`TrainModel` owns one exudyn ``MainSystem``, built once and updated
in place when parameters change (``SetObjectParameter``): only a change of
geometry, of the sensors or of the time-solver features rebuilds it. Both
solvers use this one system, so they cannot drift apart: the time solver
integrates it (generalised-alpha), the frequency solver takes its
linearisation (``ComputeLinearizedSystem``: M, K, D).

What is in it (``docs/model.md`` has the vehicle, its parameters and sources):

- rigid bodies (``ObjectRigidBody``, six coordinates each, nodes at the centres
  of mass): carbody, bogie frames, wheelsets; an articulated layout
  (:class:`.layout.Layout`) puts carbodies on Jacobs bogies joined by an
  articulation and inter-car dampers;
- suspension connectors between markers at the attachment points: primary and
  secondary springs and dampers, traction rods, anti-roll bars, Maxwell yaw and
  secondary vertical dampers (a linear ``ObjectGenericODE2`` each, with one
  internal coordinate); lateral bump stops as a time-solver option;
- per wheelset, one contact element (Hertz, linear Kalker creep with an
  equivalent conicity, gravitational stiffness) and one track-support element
  (a rail mass per wheel on pad and ballast), driven by the track's vertical
  level, alignment and cross-level;
- sensors: accelerations ``C q'' + C_disp q`` of body points, the lateral ones
  fixed to their body (they read g x roll, ``gravity_roll``).

Why it is built this way:

- Spring preloads are connector offsets, so the reference configuration is the
  static equilibrium without a static solve (:meth:`TrainModel.static_residual`
  checks it with exudyn's own right-hand side).
- The wheelsets roll (their longitudinal motion and spin held by creep only),
  so the whole car has a free longitudinal rigid-body mode: a soft tie of each
  carbody to the train's mean motion (:data:`TIE_HZ`, :data:`TIE_DAMPING`, the
  rest of the train) removes it; with ``wheelset_rolling: false`` stiff springs
  to ground (:data:`RESTRAINT_HZ`) hold the wheelsets instead. A wheelset's spin
  angle acts nowhere and the linear analyses leave it out
  (:func:`.modes.acting_positions`).
- Gravity and the tie are one sparse ``ObjectGenericODE2``: exudyn's cost per
  item and time step dominates a model this small.
- In the time solver the track is read by symbolic functions evaluated in C++
  (no Python call per step): tables of named leaves read through balanced
  ``IfThenElse`` trees, because exudyn 1.13 has no symbolic table index and
  crashes on indexing symbolic vectors of 8 or more entries (hence one contact
  element of 7 coordinates per wheelset). One odometer coordinate per wheelset
  holds its position in the table; a speed record prescribes the leading one's
  velocity.
- Effects (:mod:`.effects`) extend this system with nodes, linear elements,
  changed values or outputs, labelled (effect name, coordinate).
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from . import parameters as P
from .effects import maxwell_secondary_damper, maxwell_yaw_damper, point_jacobian
from .layout import SINGLE, Layout
from suspid.infra.threads import single_blas_thread

TABLE_PAD = 2
"""Zero leaves before the first track sample (and at least as many after the last one)."""

RESTRAINT_HZ = 300.0
"""Natural frequency (Hz) of the stiff springs that hold the wheelsets' longitudinal and pitch coordinates."""

RESTRAINED = {"wheelset": (0, 4)}
"""Body kind -> coordinates held by restraint springs (not degrees of freedom) when the wheelsets do not roll
(contact option ``wheelset_rolling: false``): the wheelset's longitudinal motion and its spin perturbation."""

TIE_HZ = 0.2
"""Natural frequency (Hz) of the soft longitudinal tie of each carbody to the train's mean motion (rolling
wheelsets): the rest of the train and its traction control, not modelled, keep the car at its mean speed;
the tie removes the free rigid-body mode of the car from the linear model, well below the spectra's band."""
TIE_DAMPING = 0.7
"""Damping ratio of that tie."""


BODIES = SINGLE.bodies
"""Body names of a conventional car (:data:`.layout.SINGLE`): carbody, bogie_front, bogie_rear, wheelset_1-4;
wheelset 1 leads, wheelsets 1-2 are in the front bogie. Articulated layouts: :class:`.layout.Layout`."""

COORDINATES = ("longitudinal", "lateral", "vertical", "roll", "pitch", "yaw")
"""Motions of one rigid-body node, in the order of its exudyn (Rxyz) coordinates."""

TRACK_INPUTS = ("vertical", "lateral", "cross_level")
"""Track channels that act on the model (columns of :meth:`TrainModel.input_matrix`)."""

DIRECTIONS = {"longitudinal": 0, "lateral": 1, "vertical": 2}
"""Sensor direction -> component of the (global-axes) acceleration."""

FLOOR_HEIGHT = 1.2
"""Height above rail (m) of the default carbody sensors, floor level (assumption)."""


@dataclass(frozen=True)
class Sensor:
    """An accelerometer: body, direction and position relative to the body's centre of mass.

    Accelerations in the axes of the frame that moves with the train (x
    forward, y left, z up), m/s^2: kinematic, plus g × roll of the body for
    lateral sensors when the model's ``gravity_roll`` is on (the default);
    tilt is an effect (``sensor-tilt``).
    """

    name: str
    body: str
    direction: str
    position: tuple[float, float, float] = (0.0, 0.0, 0.0)


def default_sensors(values: dict[str, float], layout: Layout = SINGLE) -> list[Sensor]:
    """The default channels, vertical and lateral each, carbody ones at floor level.

    One car (10 channels): carbody above each bogie and mid-car, bogie frames at
    their centre. Articulated (n carbodies, 4 n + 2 channels): every carbody
    mid-car, the inner carbodies (2 .. n - 1) also above their front and rear
    pivots (``carbody_<c>_front|middle|rear_<direction>``), and the Jacobs bogie
    frames at their centre (``bogie_<b>_<direction>``, b = 2 .. n). The ends of
    the section stand for the rest of the trainset (its end bogies carry one
    carbody end, where a real rake has the next carbody): no sensor there.
    """
    z = FLOOR_HEIGHT - values["h_car"]
    a = values["a_bogie"]
    out = []
    directions = ("vertical", "lateral")
    if not layout.articulated:
        for where, x in (("front", a), ("middle", 0.0), ("rear", -a)):
            for d in directions:
                out.append(Sensor(f"carbody_{where}_{d}", "carbody", d, (x, 0.0, z)))
        for where in ("front", "rear"):
            for d in directions:
                out.append(Sensor(f"bogie_{where}_{d}", f"bogie_{where}", d, (0.0, 0.0, 0.0)))
        return out
    last = len(layout.carbodies) - 1
    for c, car in enumerate(layout.carbodies):
        inner = 0 < c < last
        places = (("front", a), ("middle", 0.0), ("rear", -a)) if inner else (("middle", 0.0),)
        for where, x in places:
            for d in directions:
                out.append(Sensor(f"{car}_{where}_{d}", car, d, (x, 0.0, z)))
    for bogie in layout.bogies[1:-1]:
        for d in directions:
            out.append(Sensor(f"{bogie}_{d}", bogie, d, (0.0, 0.0, 0.0)))
    return out


GEOMETRY = ("h_car", "h_bogie", "r0", "a_bogie", "a_ws", "b_prim", "b_sec", "h_sec", "b_yaw", "h_yaw", "h_trac",
            "h_art", "b_ic", "h_ic")
"""Parameters that move bodies or attachment points: changing one rebuilds the exudyn system."""


def wheelset_positions(values: dict[str, float], layout: Layout = SINGLE) -> np.ndarray:
    """Longitudinal positions (m) of the wheelsets relative to the middle of the vehicle, forward positive."""
    return layout.wheelset_x(values)


@dataclass
class TimeFeatures:
    """What the time solver adds to the system (changing it rebuilds the system).

    :ivar track_capacity: number of track samples the symbolic tables hold
        (a power of two; 0: no track input, e.g. for the frequency solver).
    :ivar variable_speed: the odometer's velocity is prescribed by a speed table.
    :ivar speed_capacity: number of samples of the speed table.
    :ivar saturation: nonlinear creep saturation with friction coefficient ``friction``.
    :ivar bump_stops: lateral bump stops with ``bump_gap`` (m) and ``bump_stiffness`` (N/m).
    :ivar yaw_blow_off: yaw dampers with blow-off: the damper force c_yaw v up to the stroke velocity
        ``blow_off_velocity`` (m/s), then growing at ``blow_off_rate`` (N s/m).
    :ivar curve_capacity: number of samples of the curve force tables (0: no curves;
        :class:`.curving.CurveTables`, added by the simulator).
    """

    track_capacity: int = 0
    variable_speed: bool = False
    speed_capacity: int = 0
    saturation: bool = False
    friction: float = 0.3
    bump_stops: bool = False
    bump_gap: float = 0.025
    bump_stiffness: float = 2.0e6
    yaw_blow_off: bool = False
    blow_off_velocity: float = 0.01
    blow_off_rate: float = 20e3
    curve_capacity: int = 0

    def key(self) -> tuple:
        return (self.track_capacity, self.variable_speed, self.speed_capacity, self.saturation,
                self.friction, self.bump_stops, self.bump_gap, self.bump_stiffness, self.yaw_blow_off,
                self.blow_off_velocity, self.blow_off_rate, self.curve_capacity)

    @property
    def creep_in_user_function(self) -> bool:
        """Creep forces computed by the symbolic function (not the matrices)."""
        return self.saturation or self.variable_speed


@dataclass
class LinearSystem:
    """The linearised model at one speed, on its free coordinates (SI units).

    M q'' + D q' + K q = sum_j G_j r_j(t), accelerations at the sensors = C q''.

    :ivar M, K, D: ``(n, n)`` from exudyn's ``ComputeLinearizedSystem``.
    :ivar G: ``(n_wheelsets, n, 3)`` track input matrices, columns :data:`TRACK_INPUTS`.
    :ivar C: ``(n_sensors, n)`` sensor acceleration matrix.
    :ivar labels: ``(n,)`` (body, motion) of each free coordinate.
    :ivar wheelset_x: ``(n_wheelsets,)`` wheelset positions relative to the car centre, m.
    :ivar speed: m/s.
    :ivar C_disp: ``(n_sensors, n)`` displacement part of the sensor outputs (sensor = C q'' + C_disp q),
        or ``None`` (zero); effects such as a sensor tilt set it.
    :ivar periodic: periodic wheel inputs of effects (:class:`.effects.PeriodicInput`).
    """

    M: np.ndarray
    K: np.ndarray
    D: np.ndarray
    G: np.ndarray
    C: np.ndarray
    labels: list[tuple[str, str]]
    wheelset_x: np.ndarray
    speed: float
    C_disp: np.ndarray | None = None
    periodic: tuple = ()


class TrainModel:
    """The exudyn system of the car for given parameter values, sensors and time-solver features."""

    def __init__(self, values: dict[str, float], sensors: Sequence[Sensor], speed: float,
                 features: TimeFeatures | None = None, effects: Sequence = (), gravity_roll: bool = True,
                 layout: Layout = SINGLE, rolling: bool = True, contact_point: bool = False) -> None:
        self.features = features or TimeFeatures()
        self.rolling = bool(rolling)
        self.contact_point = bool(contact_point)
        self.restrained = {} if self.rolling else dict(RESTRAINED)
        self.layout = layout
        self.bodies = layout.bodies
        self.n_wheelsets = layout.n_wheelsets
        self.gravity_roll = bool(gravity_roll)
        self.sensors = list(sensors)
        self.values = dict(values)
        self.speed = float(speed)
        self.effects = list(effects)
        self.replaced = set().union(*(e.replaces for e in self.effects))
        self._build()

    # ------------------------------------------------------------------ building
    def _build(self) -> None:
        import exudyn as exu
        from exudyn import itemInterface as ii

        self.exu = exu
        self.SC = exu.SystemContainer()
        mbs = self.mbs = self.SC.AddSystem()
        p = self.values
        self._updaters: list[tuple[Callable[[object, object], None], Callable[[dict], object]]] = []
        self._current: list[object] = []

        ground_node = mbs.AddNode(ii.NodePointGround())
        self._m_ground = mbs.AddMarker(ii.MarkerNodeCoordinate(nodeNumber=ground_node, coordinate=0))

        # --- bodies
        ref = self._body_positions(p)
        self.nodes: dict[str, object] = {}
        self.objects: dict[str, object] = {}
        for name in self.bodies:
            node = mbs.AddNode(ii.NodeRigidBodyRxyz(referenceCoordinates=list(ref[name]) + [0.0, 0.0, 0.0]))
            obj = mbs.AddObject(ii.ObjectRigidBody(nodeNumber=node, mass=1.0,
                                                   inertia=[1.0, 1.0, 1.0, 0.0, 0.0, 0.0]))
            self.nodes[name], self.objects[name] = node, obj
            kind = _kind(name)
            self._track(lambda v, o=obj: mbs.SetObjectParameter(o, "mass", v),
                        lambda q, k=kind: q[f"m_{k}"])
            self._track(lambda v, o=obj: mbs.SetObjectParameter(o, "inertia", list(v)),
                        lambda q, k=kind: (q[f"I_{k}_x"], q[f"I_{k}_y"], q[f"I_{k}_z"], 0.0, 0.0, 0.0))

        # gravity, the restraints of the coordinates that are not degrees of freedom (wheelsets that do not
        # roll: longitudinal motion and pitch held by stiff springs to ground) and the soft longitudinal tie
        # of each carbody to the train's mean motion (rolling wheelsets: TIE_HZ), gathered in one exudyn
        # GenericODE2 "ground" element: gravity -m g on each body's vertical coordinate (the nodes sit at
        # the centres of mass), a sparse diagonal stiffness and damping. One item instead of 7 loads and 11
        # connectors: exudyn's cost per item and step dominates this small model.
        n_r = 6 * len(self.bodies)
        restrained = [(6 * i + k, name, k) for i, name in enumerate(self.bodies)
                      for k in self.restrained.get(name.split("_")[0], ())]
        tied = [6 * self.bodies.index(c) for c in self.layout.carbodies] if self.rolling else []
        self.restraint = mbs.AddObject(ii.ObjectGenericODE2(
            nodeNumbers=[self.nodes[b] for b in self.bodies], massMatrix=_sparse(n_r, []),
            stiffnessMatrix=_sparse(n_r, [(i, i, 1.0) for i in [r[0] for r in restrained] + tied]),
            dampingMatrix=_sparse(n_r, [(i, i, 1.0) for i in tied]), forceVector=[0.0] * n_r))

        def tie_mass(q):
            """The vehicle's mass per carbody, kg: each carbody's tie holds its share of the whole car."""
            return sum(q[f"m_{_kind(b)}"] for b in self.bodies) / len(self.layout.carbodies)

        def restraint_stiffness(q):
            w2 = (2 * math.pi * RESTRAINT_HZ) ** 2
            out = [(i, i, w2 * (q[f"m_{_kind(b)}"] if k == 0 else q[f"I_{_kind(b)}_y"])) for i, b, k in restrained]
            return tuple(out + [(i, i, (2 * math.pi * TIE_HZ) ** 2 * tie_mass(q)) for i in tied])

        def restraint_damping(q):
            return tuple((i, i, 2.0 * TIE_DAMPING * 2 * math.pi * TIE_HZ * tie_mass(q)) for i in tied)

        self._track(lambda v, o=self.restraint: mbs.SetObjectParameter(o, "stiffnessMatrix", _sparse(n_r, v)),
                    restraint_stiffness)
        if tied:
            self._track(lambda v, o=self.restraint: mbs.SetObjectParameter(o, "dampingMatrix", _sparse(n_r, v)),
                        restraint_damping)

        def gravity(q):
            f = np.zeros(n_r)
            for i, b in enumerate(self.bodies):
                f[6 * i + 2] = -P.GRAVITY * q[f"m_{_kind(b)}"]
            for b, bogie in enumerate(self.layout.bogies):   # dead loads of carbody ends outside the section
                f[6 * self.bodies.index(bogie) + 2] -= self.layout.neighbour_load(q, b)
            return f

        self._track(lambda v, o=self.restraint: mbs.SetObjectParameter(o, "forceVector", list(v)), gravity)

        lay = self.layout
        xw = lay.wheelset_x(p)
        xbogie = lay.bogie_x(p)
        self.effect_nodes: list[tuple[object, str, tuple[str, ...]]] = []
        for b, bogie in enumerate(lay.bogies):
            ends = lay.bogie_cars(b)
            carrying = self.objects[lay.carbodies[ends[0][0]]]
            xb = ends[0][1] * p["a_bogie"]           # pivot relative to the carrying carbody's centre
            # --- primary suspension, per axlebox
            for w in range(2):
                j = 2 * b + w
                ws = self.objects[f"wheelset_{j + 1}"]
                for side, side_name in ((1.0, "left"), (-1.0, "right")):
                    tags = (f"bogie{b + 1}", f"ws{j + 1}", side_name)
                    m0 = self._marker(ws, (0.0, side * p["b_prim"], 0.0))
                    m1 = self._marker(self.objects[bogie], (xw[j] - xbogie[b], side * p["b_prim"],
                                                            p["r0"] - p["h_bogie"]))
                    self._cartesian(m0, m1,
                                    lambda q, t=tags: _primary(q, t, "k_prim_x", "k_prim_y", "k_prim_z"),
                                    lambda q, t=tags: _primary(q, t, "c_prim_x", None, "c_prim_z"),
                                    lambda q, b=b, t=tags: (0.0, 0.0, lay.axlebox_load(q, b)
                                                            / _primary(q, t, None, None, "k_prim_z")[2]))
            # --- secondary suspension, per carbody end and side (springs and lateral dampers; the vertical
            #     dampers are Maxwell elements, :meth:`_add_secondary_dampers`)
            for c, end in ends:
                for side, side_name in ((1.0, "left"), (-1.0, "right")):
                    tags = _secondary_tags(lay, b, c, side_name)
                    m0 = self._marker(self.objects[bogie], (0.0, side * p["b_sec"], p["h_sec"] - p["h_bogie"]))
                    m1 = self._marker(self.objects[lay.carbodies[c]],
                                      (end * p["a_bogie"], side * p["b_sec"], p["h_sec"] - p["h_car"]))
                    self._cartesian(m0, m1,
                                    lambda q, t=tags: _secondary(q, t, "k_sec_x", "k_sec_y", "k_sec_z"),
                                    lambda q, t=tags: _secondary(q, t, None, "c_sec_y", None),
                                    lambda q, t=tags: (0.0, 0.0, P.static_loads(q)["secondary_side"]
                                                       / _secondary(q, t, None, None, "k_sec_z")[2]))
            # --- traction rod: longitudinal link bogie frame - carrying carbody at the bogie centre
            m0 = self._marker(self.objects[bogie], (0.0, 0.0, p["h_trac"] - p["h_bogie"]))
            m1 = self._marker(carrying, (xb, 0.0, p["h_trac"] - p["h_car"]))
            bogie_tags = (f"bogie{b + 1}",)
            self._cartesian(m0, m1, lambda q, t=bogie_tags: (_element(q, "bogie", t)["k_trac"], 0.0, 0.0),
                            lambda q: (0.0, 0.0, 0.0), lambda q: (0.0, 0.0, 0.0))
            # --- anti-roll bar: relative roll of the carrying carbody and the bogie frame
            mr0 = mbs.AddMarker(ii.MarkerNodeCoordinate(nodeNumber=self.nodes[bogie], coordinate=3))
            mr1 = mbs.AddMarker(ii.MarkerNodeCoordinate(nodeNumber=self.nodes[lay.carbodies[ends[0][0]]],
                                                        coordinate=3))
            arb = mbs.AddObject(ii.CoordinateSpringDamper(markerNumbers=[mr0, mr1], stiffness=0.0))
            self._track(lambda v, o=arb: mbs.SetObjectParameter(o, "stiffness", v),
                        lambda q, t=bogie_tags: _element(q, "bogie", t)["k_arb"])
        self._add_articulations()
        self._add_neighbour_loads()

        # --- wheel-rail contact: one force element per wheelset, on the wheelset's coordinates and its
        #     odometer (its distance along the track, in track samples). One element per wheelset because
        #     exudyn.symbolic vectors of 8 or more entries cannot be indexed (crash in exudyn 1.13).
        self.odometers = []
        self.contacts = []
        mass = np.zeros((7, 7))
        mass[6, 6] = 1.0  # the odometer's (unit) mass
        zeros = np.zeros((7, 7))
        for j in range(self.n_wheelsets):
            odo = mbs.AddNode(ii.NodeGenericODE2(referenceCoordinates=[0.0], initialCoordinates=[0.0],
                                                 initialCoordinates_t=[0.0], numberOfODE2Coordinates=1))
            c = mbs.AddObject(ii.ObjectGenericODE2(nodeNumbers=[self.nodes[f"wheelset_{j + 1}"], odo],
                                                   massMatrix=mass, stiffnessMatrix=zeros, dampingMatrix=zeros,
                                                   forceVector=[0.0] * 7))
            self.odometers.append(odo)
            self.contacts.append(c)
            self._track(lambda v, o=c: mbs.SetObjectParameter(o, "stiffnessMatrix", v),
                        lambda q, j=j: self.contact_matrices(q, self.speed, j)[0])
            self._track(lambda v, o=c: mbs.SetObjectParameter(o, "dampingMatrix", v),
                        lambda q, j=j: self.contact_matrices(q, self.speed, j)[1])
            self._track(lambda v, o=c: mbs.SetObjectParameter(o, "forceVector", list(v)),
                        lambda q, j=j: (0.0, 0.0, 2.0 * lay.wheel_load(q, j), 0.0, 0.0, 0.0, 0.0))

        # --- sensors: accelerations of the nodes that carry accelerometers (C q'' gives the sensors)
        for s in self.sensors:
            if s.body not in self.objects:
                raise ValueError(f"sensor '{s.name}': unknown body '{s.body}'")
            if s.direction not in DIRECTIONS:
                raise ValueError(f"sensor '{s.name}': unknown direction '{s.direction}'")
        # --- yaw dampers (Maxwell elements) and track support, unless an effect replaces them
        self._add_secondary_dampers()
        if "yaw_damper" not in self.replaced:
            self._add_yaw_dampers()
        self.track_nodes: list[object] = []
        if "track_support" not in self.replaced:
            self._add_track_support()
        # --- effects: extra nodes and linear elements
        for e in self.effects:
            e.check(self.sensors, self.n_wheelsets)
            e.build(self)

        self.sensor_bodies = sorted({s.body for s in self.sensors}, key=self.bodies.index)
        recorded = [self.nodes[b] for b in self.sensor_bodies] + [n for n, _, _ in self.effect_nodes]
        self.sensor_items = [(node, "acceleration", mbs.AddSensor(ii.SensorNode(
            nodeNumber=node, storeInternal=True, writeToFile=False,
            outputVariableType=exu.OutputVariableType.Coordinates_tt))) for node in recorded]
        if any(e.needs_coordinates for e in self.effects) or self._gravity_roll_sensors():
            self.sensor_items += [(node, "displacement", mbs.AddSensor(ii.SensorNode(
                nodeNumber=node, storeInternal=True, writeToFile=False,
                outputVariableType=exu.OutputVariableType.Coordinates))) for node in recorded]

        self._time_extras()
        self._apply(p, force=True)
        mbs.Assemble()
        self._coordinate_map()
        self.point_jacobians_xyz = self._sensor_jacobians()
        self.point_jacobians = np.array([self.point_jacobians_xyz[i, DIRECTIONS[s.direction]]
                                         for i, s in enumerate(self.sensors)]).reshape(len(self.sensors), 6)

    def _add_secondary_dampers(self) -> None:
        """Secondary vertical dampers, one per side of each carbody end: Maxwell elements (c_sec_z in series with
        the stiffness k_sec_z_s of their rubber end mounts), :func:`.effects.maxwell_secondary_damper`.

        One internal coordinate per damper (vertical, m, labelled ("secondary_damper",
        "<bogie>_<carbody>_<side>")); ``secondary_damper_nodes[(bogie, side)]`` is the
        node of the damper under the bogie's first carried carbody.
        """
        self.secondary_damper_nodes: dict[tuple[str, float], object] = {}
        for b, bogie in enumerate(self.layout.bogies):
            for k, (c, end) in enumerate(self.layout.bogie_cars(b)):
                car = self.layout.carbodies[c]
                for side, side_name in ((1.0, "left"), (-1.0, "right")):
                    node = self.add_effect_node("secondary_damper", (f"{bogie}_{car}_{side_name}",))
                    if k == 0:
                        self.secondary_damper_nodes[(bogie, side)] = node
                    tags = _secondary_tags(self.layout, b, c, side_name)
                    self.add_linear_element([self.nodes[bogie], self.nodes[car], node], 13,
                                            lambda q, e=end, s=side, t=tags: maxwell_secondary_damper(
                                                _element(q, "secondary", t), e, s))

    def _add_yaw_dampers(self) -> None:
        """Yaw dampers, one per side of each bogie: Maxwell elements (spring k_yaw_s in series with c_yaw).

        One internal coordinate u per damper (longitudinal, m, labelled
        ("yaw_damper", "<bogie>_<side>")) with a small mass c_yaw / (2π
        :data:`.effects.MAXWELL_FAST_HZ`); a linear element on (bogie, carbody, u):
        energy ½ k_yaw_s (u - d_bogie)², dissipation ½ c_yaw (u' - d'_carbody)²,
        d the longitudinal displacement of the attachment points at
        (±a_bogie, ±b_yaw, h_yaw).
        """
        damped = not self.features.yaw_blow_off
        self.yaw_nodes: list[tuple[str, float, float, object]] = []
        for b, (bogie, car, end, side, side_name) in enumerate(self.yaw_damper_places()):
            node = self.add_effect_node("yaw_damper", (f"{bogie}_{side_name}",))
            self.yaw_nodes.append((car, end, side, node))
            tags = (f"bogie{b // 2 + 1}", side_name)
            self.add_linear_element([self.nodes[bogie], self.nodes[car], node], 13,
                                    lambda q, e=end, s=side, t=tags: _yaw_damper(_element(q, "yaw", t), e, s, damped))

    def yaw_damper_places(self) -> list[tuple[str, str, float, float, str]]:
        """``(bogie, carrying carbody, pivot side +1 front / -1 rear of that carbody, side +1 left / -1 right,
        side name)`` of every yaw damper: one per side of each bogie."""
        out = []
        for b, bogie in enumerate(self.layout.bogies):
            c, end = self.layout.bogie_cars(b)[0]
            for side, side_name in ((1.0, "left"), (-1.0, "right")):
                out.append((bogie, self.layout.carbodies[c], end, side, side_name))
        return out

    def _add_articulations(self) -> None:
        """Articulations between adjacent carbodies (articulated layouts): a spherical joint at the pivot,
        height h_art, as springs k_art and dampers c_art in x, y, z; two longitudinal inter-car dampers c_ic at
        (±b_ic, h_ic) between the same carbody ends."""
        p = self.values
        for ahead, behind in self.layout.articulations():
            car0 = self.objects[self.layout.carbodies[ahead]]
            car1 = self.objects[self.layout.carbodies[behind]]
            m0 = self._marker(car0, (-p["a_bogie"], 0.0, p["h_art"] - p["h_car"]))
            m1 = self._marker(car1, (p["a_bogie"], 0.0, p["h_art"] - p["h_car"]))
            self._cartesian(m0, m1, lambda q: (q["k_art"],) * 3, lambda q: (q["c_art"],) * 3,
                            lambda q: (0.0, 0.0, 0.0))
            for side in (1.0, -1.0):
                m0 = self._marker(car0, (-p["a_bogie"], side * p["b_ic"], p["h_ic"] - p["h_car"]))
                m1 = self._marker(car1, (p["a_bogie"], side * p["b_ic"], p["h_ic"] - p["h_car"]))
                self._cartesian(m0, m1, lambda q: (0.0, 0.0, 0.0), lambda q: (q["c_ic"], 0.0, 0.0),
                                lambda q: (0.0, 0.0, 0.0))

    def _add_neighbour_loads(self) -> None:
        """The static load W of a carbody end outside the section on an end bogie (articulated layouts with
        ``outer_neighbours``, :meth:`.layout.Layout.neighbour_load`).

        W acts downward at the bogie's secondary seats (±b_sec, height
        h_sec): the vertical force is in the ground element (``gravity``);
        here the stiffness a constant force applied e = h_sec - h_bogie above
        the frame's centre of mass adds to the frame's roll and pitch, -W e
        each (the term the preload of a secondary spring gives its seat; a
        linear element on the bogie node). The neighbouring carbody's mass
        does not enter the dynamics.
        """
        lay = self.layout
        for b, bogie in enumerate(lay.bogies):
            if lay.neighbour_ends(b):
                self.add_linear_element([self.nodes[bogie]], 6, lambda q, b=b: _dead_load_matrices(
                    lay.neighbour_load(q, b), q["h_sec"] - q["h_bogie"]))

    def _add_track_support(self) -> None:
        """A rail mass under each wheel on the track support (pad and ballast), vertical.

        Per wheelset a node with the vertical displacements (m) of the left
        and right rail under it, labelled ("track", "wheelset_<j>_left|right");
        linear element on (wheelset, rails): the Hertzian spring k_H of each
        wheel now acts between the wheel and its rail, energy
        ½ k_H (z ± l0 roll - z_rail - V ∓ C/2)², and each rail mass m_track
        sits on k_track and c_track. The contact element keeps the wheel's
        side of the Hertzian springs; this element adds the coupling and rail
        terms (:func:`track_support_matrices`). Track inputs: -k_H (V ± C/2) on
        each rail (:meth:`input_matrix_track`). The static wheel load passes
        through the rail to the support (no preload: the rail's weight is left out).
        """
        for j in range(self.n_wheelsets):
            node = self.add_effect_node("track", (f"wheelset_{j + 1}_left", f"wheelset_{j + 1}_right"))
            self.track_nodes.append(node)
            self.add_linear_element([self.nodes[f"wheelset_{j + 1}"], node], 8,
                                    lambda q, j=j: track_support_matrices(q, self.layout.wheel_load(q, j)))

    def _gravity_roll_sensors(self) -> list[int]:
        """Indices of the lateral sensors that see g × roll (all lateral ones when ``gravity_roll``)."""
        if not self.gravity_roll:
            return []
        return [i for i, s in enumerate(self.sensors) if s.direction == "lateral"]

    def _track(self, setter: Callable[[object], None], getter: Callable[[dict], object]) -> None:
        """Register an item field that depends on parameter values."""
        self._updaters.append((setter, getter))
        self._current.append(None)

    def _marker(self, obj, local) -> object:
        from exudyn import itemInterface as ii

        return self.mbs.AddMarker(ii.MarkerBodyPosition(bodyNumber=obj, localPosition=[float(v) for v in local]))

    def _cartesian(self, m0, m1, stiffness, damping, offset) -> object:
        from exudyn import itemInterface as ii

        mbs = self.mbs
        csd = mbs.AddObject(ii.CartesianSpringDamper(markerNumbers=[m0, m1]))
        self._track(lambda v, o=csd: mbs.SetObjectParameter(o, "stiffness", list(v)), stiffness)
        self._track(lambda v, o=csd: mbs.SetObjectParameter(o, "damping", list(v)), damping)
        self._track(lambda v, o=csd: mbs.SetObjectParameter(o, "offset", list(v)), offset)
        return csd

    def add_effect_node(self, effect: str, labels: tuple[str, ...]) -> object:
        """A node of an effect with ``len(labels)`` free coordinates, labelled (effect, label)."""
        from exudyn import itemInterface as ii

        n = len(labels)
        node = self.mbs.AddNode(ii.NodeGenericODE2(referenceCoordinates=[0.0] * n, initialCoordinates=[0.0] * n,
                                                   initialCoordinates_t=[0.0] * n, numberOfODE2Coordinates=n))
        self.effect_nodes.append((node, effect, tuple(labels)))
        return node

    def add_linear_element(self, nodes: Sequence[object], n: int,
                           matrices: Callable[[dict], tuple[np.ndarray, np.ndarray, np.ndarray]]) -> object:
        """A linear ``ObjectGenericODE2`` on ``nodes`` (``n`` coordinates in all) whose mass, stiffness and
        damping matrices ``matrices(values)`` follow the parameter values."""
        from exudyn import itemInterface as ii

        mbs = self.mbs
        zeros = np.zeros((n, n))
        obj = mbs.AddObject(ii.ObjectGenericODE2(nodeNumbers=list(nodes), massMatrix=zeros, stiffnessMatrix=zeros,
                                                 dampingMatrix=zeros, forceVector=[0.0] * n))
        for k, field in enumerate(("massMatrix", "stiffnessMatrix", "dampingMatrix")):
            self._track(lambda v, o=obj, f=field: mbs.SetObjectParameter(o, f, v), lambda q, k=k: matrices(q)[k])
        return obj

    def periodic_inputs(self, values: dict[str, float] | None = None) -> tuple:
        """The effects' periodic wheel inputs at ``values`` (default: the model's)."""
        values = self.values if values is None else values
        return tuple(pi for e in self.effects for pi in e.periodic_inputs(values))

    def _body_positions(self, p: dict[str, float]) -> dict[str, np.ndarray]:
        lay = self.layout
        out = {}
        for name, x in zip(lay.carbodies, lay.carbody_x(p)):
            out[name] = np.array([x, 0.0, p["h_car"]])
        for name, x in zip(lay.bogies, lay.bogie_x(p)):
            out[name] = np.array([x, 0.0, p["h_bogie"]])
        for name, x in zip(lay.wheelsets, lay.wheelset_x(p)):
            out[name] = np.array([x, 0.0, p["r0"]])
        return out

    def _apply(self, values: dict[str, float], force: bool = False) -> None:
        for i, (setter, getter) in enumerate(self._updaters):
            new = getter(values)
            old = self._current[i]
            if force or not _same(old, new):
                setter(new)
                self._current[i] = new

    # ------------------------------------------------------------------ updating
    def needs_rebuild(self, values: dict[str, float], sensors: Sequence[Sensor],
                      features: TimeFeatures) -> bool:
        """True when ``values``, ``sensors`` or ``features`` change the structure of the system."""
        return (any(values.get(k) != self.values.get(k) for k in GEOMETRY) or list(sensors) != self.sensors
                or features.key() != self.features.key())

    def update(self, values: dict[str, float], speed: float) -> None:
        """Set new parameter values and speed (geometry must be unchanged: see :meth:`needs_rebuild`)."""
        self.values = dict(values)
        self.speed = float(speed)
        self._apply(self.values)

    # ------------------------------------------------------------------ contact
    def wheelset_matrices(self, p: dict[str, float], speed: float, wheel: float | None = None
                          ) -> tuple[np.ndarray, np.ndarray]:
        """Stiffness and damping (6 x 6) of one wheelset's contact, coordinates x, y, z, roll, pitch, yaw.

        With creep computed by the symbolic function (saturation, variable
        speed) only the Hertzian and gravitational terms stay here. ``wheel``:
        the static wheel load, N (default: that of a conventional car's bogie).
        """
        kh = P.hertz_stiffness(p, wheel)
        f11, f22 = P.creep_coefficients(p, wheel)
        lam, l0, r0 = p["conicity"], p["l0"], p["r0"]
        K = np.zeros((6, 6))
        D = np.zeros((6, 6))
        K[2, 2] = 2.0 * kh
        K[3, 3] = 2.0 * kh * l0 ** 2
        K[1, 1] = P.gravitational_stiffness(p, wheel)
        if not self.features.creep_in_user_function:
            K[1, 5] = -2.0 * f22
            K[5, 1] = 2.0 * f11 * l0 * lam / r0
            D[1, 1] = 2.0 * f22 / speed
            D[5, 5] = 2.0 * f11 * l0 ** 2 / speed
            if self.contact_point:
                # the lateral creep force at the contact points (y_c = y + r0 roll): creepage (y' + r0 roll') / v
                # - yaw, and its moment r0 F_y on the roll
                D[1, 3] = D[3, 1] = 2.0 * f22 * r0 / speed
                D[3, 3] = 2.0 * f22 * r0 ** 2 / speed
                K[3, 5] = -2.0 * f22 * r0
            if self.rolling:
                # longitudinal creepage (x' - r0 pitch') / v, the same on both wheels: force -2 f11 on x,
                # its moment -r0 F_x on the spin (contact points r0 below the axle)
                D[np.ix_((0, 4), (0, 4))] = 2.0 * f11 / speed * np.array([[1.0, -r0], [-r0, r0 ** 2]])
        return K, D

    def contact_matrices(self, p: dict[str, float], speed: float, j: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """Stiffness and damping (7 x 7) of the contact element of wheelset ``j``: its coordinates, the odometer."""
        k6, d6 = self.wheelset_matrices(p, speed, self.layout.wheel_load(p, j))
        K = np.zeros((7, 7))
        D = np.zeros((7, 7))
        K[:6, :6] = k6
        D[:6, :6] = d6
        return K, D

    @staticmethod
    def input_matrix(p: dict[str, float], wheel: float | None = None) -> np.ndarray:
        """G (6 x 3): generalised contact force on a wheelset per unit track input, columns :data:`TRACK_INPUTS`.

        The force on the wheelset is G @ (V, Y, C) at its position: the
        Hertzian springs pull towards the rail level V and cross-level C; the
        gravitational stiffness and the conicity term act on y - Y. ``wheel``: the static wheel load, N.
        """
        kh = P.hertz_stiffness(p, wheel)
        f11 = P.creep_coefficients(p, wheel)[0]
        G = np.zeros((6, 3))
        G[2, 0] = 2.0 * kh
        G[3, 2] = kh * p["l0"]
        G[1, 1] = P.gravitational_stiffness(p, wheel)
        G[5, 1] = 2.0 * f11 * p["l0"] * p["conicity"] / p["r0"]
        return G

    @staticmethod
    def input_matrix_track(p: dict[str, float], wheel: float | None = None) -> np.ndarray:
        """G (2 x 3): force on the left and right rail mass under a wheelset per unit track input
        (columns :data:`TRACK_INPUTS`): -k_H (V ± C/2); ``wheel``: the static wheel load, N."""
        kh = P.hertz_stiffness(p, wheel)
        return np.array([[-kh, 0.0, -0.5 * kh], [-kh, 0.0, 0.5 * kh]])

    # ------------------------------------------------------------------ time-solver extras
    def _time_extras(self) -> None:
        """Symbolic track tables, creep laws, speed prescription and bump stops (time solver)."""
        feat = self.features
        self.track_leaves: list[list] = []
        self.speed_leaves: list = []
        self._keep: list = []
        self.speed_constraint = None
        if feat.bump_stops:
            self._add_bump_stops()
        if feat.track_capacity <= 0:
            return
        from exudyn import itemInterface as ii
        from exudyn.advancedUtilities import CreateSymbolicUserFunction

        esym = self.exu.symbolic
        n = feat.track_capacity
        self.track_leaves = [[esym.Real(f"{ch}_{i}", 0.0) for i in range(n + 1)] for ch in TRACK_INPUTS]
        self._uf_constants()
        self._periodic_leaves()
        sys.setrecursionlimit(max(sys.getrecursionlimit(), 10000))
        for j, contact in enumerate(self.contacts):
            uf = CreateSymbolicUserFunction(self.mbs, self._contact_force_function(j), "forceUserFunction", contact)
            self.mbs.SetObjectParameter(contact, "forceUserFunction", uf)
            self._keep.append(uf)
        self._track_support_forces()
        if feat.yaw_blow_off:
            self._yaw_blow_off()
        for e in self.effects:
            e.build_time(self)
        if feat.variable_speed:
            m = feat.speed_capacity
            self.speed_leaves = [esym.Real(f"speed_{i}", 0.0) for i in range(m + 1)]
            self.speed_step = esym.Real("speed_dt_inv", 1.0)
            m_odo = [self.mbs.AddMarker(ii.MarkerNodeCoordinate(nodeNumber=o, coordinate=0))
                     for o in self.odometers]
            con = self.mbs.AddObject(ii.CoordinateConstraint(markerNumbers=[self._m_ground, m_odo[0]],
                                                             velocityLevel=True))
            # the other wheelsets keep their distance to the leading one
            self.odometer_links = [self.mbs.AddObject(ii.CoordinateConstraint(markerNumbers=[m_odo[0], m_odo[j]]))
                                   for j in range(1, self.n_wheelsets)]

            def speed_function(mbs, t, itemNumber, lOffset):
                return _lookup(esym, self.speed_leaves, t * self.speed_step, m)

            uf = CreateSymbolicUserFunction(self.mbs, speed_function, "offsetUserFunction_t", con)
            self.mbs.SetObjectParameter(con, "offsetUserFunction_t", uf)
            self._keep.append(uf)
            self.speed_constraint = con

    def _track_support_forces(self) -> None:
        """Symbolic track input on the rail masses: -k_H (V ± C/2) at each wheelset's odometer."""
        if not self.track_nodes:
            return
        from exudyn import itemInterface as ii
        from exudyn.advancedUtilities import CreateSymbolicUserFunction

        n = self.features.track_capacity
        zeros = np.zeros((3, 3))
        for j, node in enumerate(self.track_nodes):
            kh = self.uf_wheel[j]["kh"]
            element = self.mbs.AddObject(ii.ObjectGenericODE2(
                nodeNumbers=[node, self.odometers[j]], massMatrix=zeros, stiffnessMatrix=zeros,
                dampingMatrix=zeros, forceVector=[0.0, 0.0, 0.0]))

            uf = CreateSymbolicUserFunction(self.mbs, self._rail_force_function(j, kh, n), "forceUserFunction",
                                            element)
            self.mbs.SetObjectParameter(element, "forceUserFunction", uf)
            self._keep.append(uf)

    def _yaw_blow_off(self) -> None:
        """The dampers of the Maxwell yaw dampers with blow-off (time solver; symbolic force law).

        Per damper an element on (carbody, internal coordinate u), 7 coordinates:
        stroke velocity v = u' - d'_carbody (d the longitudinal displacement of the
        carbody attachment point), force F = c2 v + (c_yaw - c2) v_b tanh(v / v_b):
        c_yaw v at small strokes, c2 v + (c_yaw - c2) v_b well above the blow-off
        velocity v_b (a smooth version of the bilinear law, which stalls the
        Newton iterations at the kink); generalised forces -F on u and
        +F ∂d/∂q on the carbody coordinates.
        """
        from exudyn import itemInterface as ii
        from exudyn.advancedUtilities import CreateSymbolicUserFunction

        esym = self.exu.symbolic
        p = self.values
        c = esym.Real("yaw_c", 0.0)
        self._track(lambda v, r=c: r.SetValue(float(v)), lambda q: q["c_yaw"])
        c2 = float(self.features.blow_off_rate)
        vb = float(self.features.blow_off_velocity)
        zeros = np.zeros((7, 7))
        for car, end, side, node in self.yaw_nodes:
            w = point_jacobian((end * p["a_bogie"], side * p["b_yaw"], p["h_yaw"] - p["h_car"]))[0]
            element = self.mbs.AddObject(ii.ObjectGenericODE2(
                nodeNumbers=[self.nodes[car], node], massMatrix=zeros, stiffnessMatrix=zeros,
                dampingMatrix=zeros, forceVector=[0.0] * 7))
            uf = CreateSymbolicUserFunction(self.mbs, _blow_off_force(esym, w, c, c2, vb), "forceUserFunction",
                                            element)
            self.mbs.SetObjectParameter(element, "forceUserFunction", uf)
            self._keep.append(uf)
        self._keep.append(c)

    def _rail_force_function(self, j: int, kh, n: int):
        """Symbolic force on (left rail, right rail, odometer) under wheelset ``j``: -k_H (V ± C/2)."""
        esym = self.exu.symbolic

        def force(mbs, t, itemNumber, q, q_t):
            q.SetVector([0.0, 0.0, 0.0])
            q_t.SetVector([0.0, 0.0, 0.0])
            V = self.vertical_input(j, q[2])
            C = _lookup(esym, self.track_leaves[2], q[2], n)
            return [-kh * (V + 0.5 * C), -kh * (V - 0.5 * C), 0.0]

        return force

    def _periodic_leaves(self) -> None:
        """Symbolic amplitude, wavenumber and phase of each periodic wheel input, following the values."""
        esym = self.exu.symbolic
        self.periodic_leaves: list[tuple[int, object, object, object]] = []
        for i, pi in enumerate(self.periodic_inputs()):
            leaves = tuple(esym.Real(f"periodic_{i}_{what}", 0.0) for what in ("amplitude", "wavenumber", "phase"))
            self.periodic_leaves.append((pi.wheelset,) + leaves)
            for k, leaf in enumerate(leaves):
                self._track(lambda v, r=leaf: r.SetValue(float(v)),
                            lambda q, i=i, k=k: (lambda x: (x.amplitude, 2 * math.pi / x.wavelength, x.phase)[k])(
                                self.periodic_inputs(q)[i]))

    def vertical_input(self, j: int, where):
        """Symbolic vertical track level (m) under wheelset ``j`` at odometer ``where`` (track samples):
        the track table plus the periodic inputs of effects on that wheelset."""
        esym = self.exu.symbolic
        V = _lookup(esym, self.track_leaves[0], where, self.features.track_capacity)
        s = (where - float(TABLE_PAD)) * self.uf_values["dx"]     # distance from the segment start, m
        for wheelset, amplitude, wavenumber, phase in self.periodic_leaves:
            if wheelset == j:
                V = V + amplitude * esym.cos(wavenumber * s + phase)
        return V

    def _contact_force_function(self, j: int = 0):
        """The symbolic force function of the contact element of wheelset ``j`` (track input, creep laws).

        Element coordinates: the wheelset's x, y, z, roll, pitch, yaw (0-5) and
        its odometer (distance in track samples, 6). Parameter-dependent
        constants are named symbolic ``Real`` values (:attr:`uf_values`),
        updated with the parameters: the function itself is recorded once.
        """
        esym = self.exu.symbolic
        feat = self.features
        n = feat.track_capacity
        leaves = self.track_leaves
        c = self.uf_wheel[j]

        def force(mbs, t, itemNumber, q, q_t):
            q.SetVector([0.0] * 7)
            q_t.SetVector([0.0] * 7)
            where = q[6]
            V = self.vertical_input(j, where)
            Y = _lookup(esym, leaves[1], where, n)
            C = _lookup(esym, leaves[2], where, n)
            if not feat.creep_in_user_function:
                # one lookup per channel: each table value scales a constant force pattern
                return (V * esym.Vector([0.0, 0.0, c["two_kh"], 0.0, 0.0, 0.0, 0.0])
                        + Y * esym.Vector([0.0, c["kg"], 0.0, 0.0, 0.0, c["yaw_y"], 0.0])
                        + C * esym.Vector([0.0, 0.0, 0.0, c["kh_l0"], 0.0, 0.0, 0.0]))
            fz = c["two_kh"] * V
            mx = c["kh_l0"] * C
            fy = c["kg"] * Y
            # creep forces computed here: speed from the odometer, optional saturation
            v = q_t[6] * c["dx"]
            nu_y = (q_t[1] + c["r0"] * q_t[3] if self.contact_point else q_t[1]) / v - q[5]   # lateral creepage
            a_long = c["l0"] * q_t[5] / v + c["lam_r0"] * (q[1] - Y)  # minus the left wheel's long. creepage
            fy_wheel = -c["f22"] * nu_y                               # lateral creep force per wheel
            fx_left = c["f11"] * a_long                               # longitudinal, left wheel; right: -fx_left
            # rolling wheelsets: the common longitudinal creepage (x' - r0 pitch') / v of both wheels
            fx_wheel = -c["f11"] * (q_t[0] - c["r0"] * q_t[4]) / v if self.rolling else 0.0
            fx_l, fx_r = fx_wheel + fx_left, fx_wheel - fx_left     # each wheel's longitudinal creep force
            if feat.saturation:
                # per wheel, friction limit mu N with the static wheel load N (the dynamic wheel load needs
                # the rail deflection, which this element does not see)
                eps_l = _saturation(esym, fx_l, fy_wheel, c["mu"] * c["n0"])
                eps_r = _saturation(esym, fx_r, fy_wheel, c["mu"] * c["n0"])
                fx_l, fx_r = eps_l * fx_l, eps_r * fx_r
                fy_creep = (eps_l + eps_r) * fy_wheel
            else:
                fy_creep = 2.0 * fy_wheel
            fy = fy + fy_creep
            if self.contact_point:                                    # the creep force r0 below the axle
                mx = mx + c["r0"] * fy_creep
            fx = fx_l + fx_r
            mz = -c["l0"] * (fx_l - fx_r)
            return [fx, fy, fz, mx, -c["r0"] * fx, mz, 0.0]

        return force

    def _uf_constants(self) -> None:
        """Named symbolic constants of the contact functions, kept in step with the parameters: one set per
        wheelset (:attr:`uf_wheel`; the wheel loads of an articulated layout differ), the track sampling
        step ``dx`` shared (:attr:`uf_values`)."""
        esym = self.exu.symbolic
        load = self.layout.wheel_load
        getters = {
            "two_kh": lambda q, j: 2.0 * P.hertz_stiffness(q, load(q, j)),
            "kh": lambda q, j: P.hertz_stiffness(q, load(q, j)),
            "kh_l0": lambda q, j: P.hertz_stiffness(q, load(q, j)) * q["l0"],
            "kg": lambda q, j: P.gravitational_stiffness(q, load(q, j)),
            "f11": lambda q, j: P.creep_coefficients(q, load(q, j))[0],
            "f22": lambda q, j: P.creep_coefficients(q, load(q, j))[1],
            "yaw_y": lambda q, j: 2.0 * P.creep_coefficients(q, load(q, j))[0] * q["l0"] * q["conicity"] / q["r0"],
            "l0": lambda q, j: q["l0"],
            "r0": lambda q, j: q["r0"],
            "lam_r0": lambda q, j: q["conicity"] / q["r0"],
            "n0": lambda q, j: load(q, j),
            "mu": lambda q, j: self.features.friction,
        }
        self.uf_values = {"dx": esym.Real("dx", 1.0)}
        self.uf_wheel: list[dict[str, object]] = []
        for j in range(self.n_wheelsets):
            leaves = {"dx": self.uf_values["dx"]}
            for name, getter in getters.items():
                leaf = esym.Real(f"{name}_{j}", 0.0)
                leaves[name] = leaf
                self._track(lambda v, r=leaf: r.SetValue(float(v)), lambda q, g=getter, j=j: g(q, j))
            self.uf_wheel.append(leaves)

    def _add_bump_stops(self) -> None:
        """Lateral bump stops between carbody and each bogie frame (symbolic force law)."""
        from exudyn import itemInterface as ii
        from exudyn.advancedUtilities import CreateSymbolicUserFunction

        esym = self.exu.symbolic
        p = self.values
        gap, k = self.features.bump_gap, self.features.bump_stiffness
        for b, bogie in enumerate(self.layout.bogies):
            c, end = self.layout.bogie_cars(b)[0]
            car = self.objects[self.layout.carbodies[c]]
            m0 = self._marker(self.objects[bogie], (0.0, 0.0, p["h_sec"] - p["h_bogie"]))
            m1 = self._marker(car, (end * p["a_bogie"], 0.0, p["h_sec"] - p["h_car"]))
            csd = self.mbs.AddObject(ii.CartesianSpringDamper(markerNumbers=[m0, m1]))

            def stop(mbs, t, itemNumber, displacement, velocity, stiffness, damping, offset):
                u = displacement[1]
                over = u - esym.min(gap, esym.max(-gap, u))
                return [0.0, k * over, 0.0]

            uf = CreateSymbolicUserFunction(self.mbs, stop, "springForceUserFunction", csd)
            self.mbs.SetObjectParameter(csd, "springForceUserFunction", uf)
            self._keep.append(uf)

    # ------------------------------------------------------------------ bookkeeping
    def _coordinate_map(self) -> None:
        """Global ODE2 indices: free coordinates, their labels, per-wheelset index lists."""
        mbs = self.mbs
        self.n_ode2 = len(mbs.systemData.GetODE2Coordinates())
        free, labels = [], []
        self.node_index: dict[str, int] = {}
        for name in self.bodies:
            start = mbs.GetNodeODE2Index(self.nodes[name])
            self.node_index[name] = start
            for k, motion in enumerate(COORDINATES):
                if k in self.restrained.get(name.split("_")[0], ()):
                    continue
                free.append(start + k)
                labels.append((name, motion))
        for node, effect, node_labels in self.effect_nodes:
            start = mbs.GetNodeODE2Index(node)
            for k, label in enumerate(node_labels):
                free.append(start + k)
                labels.append((effect, label))
        self.free = np.array(free)
        self.labels = labels
        position = {g: i for i, g in enumerate(free)}
        self.ode2_to_free = position
        self.free_position = {label: i for i, label in enumerate(labels)}
        # coordinate k of wheelset j -> free index (or -1)
        self.contact_rows = []
        for j in range(self.n_wheelsets):
            start = self.node_index[f"wheelset_{j + 1}"]
            self.contact_rows.append([position.get(start + k, -1) for k in range(6)])

    # ------------------------------------------------------------------ linearisation
    def linear_system(self) -> LinearSystem:
        """Linearise with exudyn about the static equilibrium at the model's speed."""
        ss = self.exu.SimulationSettings()
        ss.solution.file.write = False
        ss.solution.sensors.active = False
        ss.timeIntegration.verboseMode = 0
        ss.staticSolver.verboseMode = 0
        with quiet(self.exu), single_blas_thread():
            M, K, D = self.mbs.ComputeLinearizedSystem(ss)[:3]
        idx = self.free
        M = np.asarray(M)[np.ix_(idx, idx)]
        K = np.asarray(K)[np.ix_(idx, idx)]
        D = np.asarray(D)[np.ix_(idx, idx)]
        n = len(idx)
        n_w = self.n_wheelsets
        G = np.zeros((n_w, n, 3))
        for j in range(n_w):
            G6 = self.input_matrix(self.values, self.layout.wheel_load(self.values, j))
            for k, row in enumerate(self.contact_rows[j]):
                if row >= 0:
                    G[j, row] = G6[k]
        if self.track_nodes:
            for j in range(n_w):
                Gt = self.input_matrix_track(self.values, self.layout.wheel_load(self.values, j))
                for k, side in enumerate(("left", "right")):
                    G[j, self.free_position[("track", f"wheelset_{j + 1}_{side}")]] = Gt[k]
        for e in self.effects:
            e.input_rows(self, G, self.values)
        C, C_disp = self.sensor_matrices()
        return LinearSystem(M, K, D, G, C, list(self.labels), self.layout.wheelset_x(self.values), self.speed,
                            C_disp=C_disp if np.any(C_disp) else None, periodic=self.periodic_inputs())

    def static_residual(self) -> np.ndarray:
        """Generalised forces (N, N m) on the free coordinates at the reference configuration.

        Zero at static equilibrium: gravity and the spring preloads balance
        (computed by exudyn's own right-hand side with every velocity zero).
        """
        exu = self.exu
        ss = exu.SimulationSettings()
        ss.solution.file.write = False
        ss.solution.sensors.active = False
        ss.staticSolver.verboseMode = 0
        solver = exu.MainSolverStatic()
        with quiet(exu):
            solver.InitializeSolver(self.mbs, ss)
            solver.ComputeODE2RHS(self.mbs)
            residual = np.array(solver.GetSystemResidual())[: self.n_ode2]
            solver.FinalizeSolver(self.mbs, ss)
        return residual[self.free]

    def sensor_matrices(self, values: dict[str, float] | None = None) -> tuple[np.ndarray, np.ndarray]:
        """``(C, C_disp)``, each ``(n_sensors, n_free)``: sensor = C q'' + C_disp q on the free coordinates.

        Built from the acceleration of each sensor point in x, y, z (rigid
        kinematics, then the effects' additions, e.g. a flexible mode), the
        row of the sensor's direction, then the effects' output changes (tilt).
        """
        values = self.values if values is None else values
        n_s, n = len(self.sensors), len(self.free)
        R = np.zeros((n_s, 3, n))
        for i, s in enumerate(self.sensors):
            start = self.node_index[s.body]
            for k in range(6):
                col = self.ode2_to_free.get(start + k)
                if s.body.startswith("wheelset") and k == 4:
                    continue   # a sensor on a wheelset sits on its axlebox, which does not spin with it
                if col is not None:
                    R[i, :, col] = self.point_jacobians_xyz[i, :, k]
        for e in self.effects:
            e.kinematic_rows(self, R, values)
        C = np.array([R[i, DIRECTIONS[s.direction]] for i, s in enumerate(self.sensors)]).reshape(n_s, n)
        C_disp = np.zeros((n_s, n))
        for i in self._gravity_roll_sensors():
            # body-fixed accelerometer: the lateral axis tilts with the body's roll and picks up g sin(roll)
            C_disp[i, self.free_position[(self.sensors[i].body, "roll")]] += P.GRAVITY
        for e in self.effects:
            e.outputs(self, R, C, C_disp, values)
        return C, C_disp

    def _sensor_jacobians(self) -> np.ndarray:
        """``(n_sensors, 3, 6)``: d(sensor position x, y, z)/d(coordinate) of the sensor's body node.

        Read back from exudyn's kinematics for small perturbations of each
        coordinate: the sensor acceleration is J q''_body to first order in
        the small rotations (the time solver uses it on exudyn's node
        accelerations, the frequency solver on the linear model).
        """
        exu = self.exu
        mbs = self.mbs
        cfg = exu.ConfigurationType.Current
        q0 = np.array(mbs.systemData.GetODE2Coordinates(configuration=cfg))
        J = np.zeros((len(self.sensors), 3, 6))
        eps = 1e-6
        try:
            for i, s in enumerate(self.sensors):
                obj = self.objects[s.body]
                start = self.node_index[s.body]
                for k in range(6):
                    vals = []
                    for sign in (1.0, -1.0):
                        q = q0.copy()
                        q[start + k] += sign * eps
                        mbs.systemData.SetODE2Coordinates(list(q), configuration=cfg)
                        vals.append(np.asarray(mbs.GetObjectOutputBody(obj, exu.OutputVariableType.Position,
                                                                       localPosition=list(s.position),
                                                                       configuration=cfg)))
                    J[i, :, k] = (vals[0] - vals[1]) / (2 * eps)
        finally:
            mbs.systemData.SetODE2Coordinates(list(q0), configuration=cfg)
        return J

    def sensor_accelerations(self) -> np.ndarray:
        """``(n_sensors, n_records)`` accelerations from the node records of the last run: C q'' + C_disp q.

        The free coordinates only, like the frequency solver (wheelsets that do not roll: their
        restrained longitudinal and pitch coordinates move by less than 1e-4 of the suspension motions).
        """
        C, C_disp = self.sensor_matrices()
        out = None
        for node, kind, item in self.sensor_items:
            data = np.asarray(self.mbs.GetSensorStoredData(item))
            start = self.mbs.GetNodeODE2Index(node)
            matrix = C if kind == "acceleration" else C_disp
            for k in range(data.shape[1] - 1):
                col = self.ode2_to_free.get(start + k)
                if col is None or not np.any(matrix[:, col]):
                    continue
                term = np.outer(matrix[:, col], data[:, 1 + k])
                out = term if out is None else out + term
        if out is None:
            n_rec = np.asarray(self.mbs.GetSensorStoredData(self.sensor_items[0][2])).shape[0]
            out = np.zeros((len(self.sensors), n_rec))
        return out

    # ------------------------------------------------------------------ track tables
    def set_track(self, table: np.ndarray, dx: float) -> None:
        """Put a track table into the symbolic leaves.

        :param table: ``(3, n)`` rows :data:`TRACK_INPUTS`, m, at spacing ``dx``:
            sample i goes to leaf ``TABLE_PAD + i``; the other leaves are zero
            (the table must start and end at zero: tapered).
        """
        n = table.shape[1]
        cap = self.features.track_capacity
        if n + 2 * TABLE_PAD > cap + 1:
            raise ValueError(f"track table of {n} samples exceeds the capacity {cap + 1 - 2 * TABLE_PAD}")
        stop = TABLE_PAD + n
        for leaves, row in zip(self.track_leaves, table):
            for i in range(cap + 1):
                leaves[i].SetValue(float(row[i - TABLE_PAD]) if TABLE_PAD <= i < stop else 0.0)
        self.uf_values["dx"].SetValue(float(dx))

    def set_speed_table(self, speeds_per_sample: np.ndarray, dt: float) -> None:
        """Odometer velocity (samples/s) at times k dt, for the variable-speed constraint.

        The last value is held to the end of the table (and extrapolated as a constant).
        """
        cap = self.features.speed_capacity
        if len(speeds_per_sample) > cap:
            raise ValueError("speed table exceeds its capacity")
        last = float(speeds_per_sample[-1])
        for i in range(cap + 1):
            self.speed_leaves[i].SetValue(float(speeds_per_sample[i]) if i < len(speeds_per_sample) else last)
        self.speed_step.SetValue(1.0 / dt)


class quiet:
    """Context manager: no exudyn console output and warnings (restored afterwards)."""

    def __init__(self, exu) -> None:
        self.cfg = exu.config

    def __enter__(self) -> "quiet":
        self.saved = (self.cfg.suppressWarnings, self.cfg.printToConsole)
        self.cfg.suppressWarnings = True
        self.cfg.printToConsole = False
        return self

    def __exit__(self, *exc) -> None:
        self.cfg.suppressWarnings, self.cfg.printToConsole = self.saved


def _element(q: dict[str, float], placement: str, tags: tuple[str, ...]) -> dict[str, float]:
    """The values the element at ``tags`` of a placement of :data:`.parameters.ELEMENT_KINDS` sees (its
    groups' values in place of the kinds', :func:`.parameters.element_view`; ``q`` itself without groups)."""
    return P.element_view(q, P.ELEMENT_KINDS[placement], tags)


def _primary(q: dict[str, float], tags: tuple[str, ...], x: str | None, y: str | None,
             z: str | None) -> tuple[float, float, float]:
    """(x, y, z) rates of one axlebox's primary element: the named parameters, 0.0 for ``None``."""
    v = _element(q, "primary", tags)
    return tuple(0.0 if n is None else v[n] for n in (x, y, z))


def _secondary(q: dict[str, float], tags: tuple[str, ...], x: str | None, y: str | None,
               z: str | None) -> tuple[float, float, float]:
    """(x, y, z) rates of one secondary element (one side of a carbody end), as :func:`_primary`."""
    v = _element(q, "secondary", tags)
    return tuple(0.0 if n is None else v[n] for n in (x, y, z))


def _secondary_tags(layout: Layout, b: int, c: int, side_name: str) -> tuple[str, ...]:
    """Tags of the secondary element of bogie ``b`` under carbody ``c`` on a side (:meth:`.layout.Layout.element_tags`)."""
    return (f"bogie{b + 1}",) + ((f"car{c + 1}",) if layout.articulated else ()) + (side_name,)


def _yaw_damper(q: dict[str, float], end: float, side: float, damped: bool):
    return maxwell_yaw_damper(q, end, side, q["k_yaw_s"], damped)


def _kind(body: str) -> str:
    """The parameter infix of a body's mass and inertias: carbody_2 -> car, bogie_front -> bogie, wheelset_1 -> ws."""
    return body.split("_")[0].replace("carbody", "car").replace("wheelset", "ws")


def _sparse(n: int, triplets) -> object:
    """An exudyn MatrixContainer (n x n) in sparse triplet mode."""
    import exudyn

    mc = exudyn.MatrixContainer()
    if triplets:
        mc.SetWithSparseMatrix(np.array(triplets, dtype=float), numberOfRows=n, numberOfColumns=n,
                               useDenseMatrix=False)
    else:
        mc.Initialize(n, n, useDenseMatrix=False)
    return mc


def _same(a, b) -> bool:
    if a is None or b is None:
        return False
    return np.array_equal(np.asarray(a, dtype=float), np.asarray(b, dtype=float))


def _tree(esym, leaves, tau, lo: int, hi: int):
    """Linear interpolation of ``leaves`` at ``tau`` in [lo, hi) by bisection (IfThenElse is lazy)."""
    if hi - lo == 1:
        return leaves[lo] + (leaves[lo + 1] - leaves[lo]) * (tau - float(lo))
    mid = (lo + hi) // 2
    return esym.IfThenElse(tau < float(mid), _tree(esym, leaves, tau, lo, mid), _tree(esym, leaves, tau, mid, hi))


def _lookup(esym, leaves, tau, n: int):
    """Table value at fractional sample ``tau`` by linear interpolation of ``leaves[0..n]``.

    Outside [0, n] the first or last interval is extrapolated: tables keep
    :data:`TABLE_PAD` equal leaves at both ends, so that the value stays
    constant there (no range test needed).
    """
    return _tree(esym, leaves, tau, 0, n)


def _blow_off_force(esym, w: np.ndarray, c, c2: float, vb: float):
    """Symbolic force function of one yaw damper with blow-off (see :meth:`TrainModel._yaw_blow_off`).

    :param w: ``(6,)`` longitudinal displacement of the carbody attachment point per carbody coordinate.
    """
    def force(mbs, t, itemNumber, q, q_t):
        q.SetVector([0.0] * 7)
        q_t.SetVector([0.0] * 7)
        v = q_t[6]
        for k in range(6):
            if w[k] != 0.0:
                v = v - float(w[k]) * q_t[k]
        f = c2 * v + (c - c2) * vb * esym.tanh(v / vb)
        return [float(w[k]) * f if w[k] != 0.0 else 0.0 for k in range(6)] + [-f]

    return force


def _saturation(esym, fx, fy, limit):
    """Shen-Hedrick-Elkins factor eps on linear creep forces (fx, fy) for the limit mu N.

    u = |F| / (mu N); eps = 1 - u/3 + u^2/27 for u < 3, else 1/u.
    """
    u = esym.sqrt(fx * fx + fy * fy) / esym.max(limit, 1.0)
    return esym.IfThenElse(u < 3.0, 1.0 - u / 3.0 + u * u / 27.0, 1.0 / esym.max(u, 1e-12))


def _dead_load_matrices(load: float, height: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mass, stiffness, damping (6 x 6, rigid-body node coordinates) of a constant downward force ``load``
    (N) applied symmetrically ``height`` (m) above the node: stiffness -load height in roll and pitch."""
    zeros = np.zeros((6, 6))
    k = np.zeros((6, 6))
    k[3, 3] = k[4, 4] = -load * height
    return zeros, k, zeros


def track_support_matrices(q: dict[str, float], wheel: float | None = None
                           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(M, K, D) ``(8, 8)`` of the track support under one wheelset: coordinates the wheelset's x, y, z,
    roll, pitch, yaw and the left and right rail displacements (see :meth:`TrainModel._add_track_support`);
    ``wheel``: the static wheel load, N."""
    kh = P.hertz_stiffness(q, wheel)
    l0 = q["l0"]
    M, K, D = np.zeros((8, 8)), np.zeros((8, 8)), np.zeros((8, 8))
    for r, sign in ((6, 1.0), (7, -1.0)):
        M[r, r] = q["m_track"]
        K[r, r] = kh + q["k_track"]
        D[r, r] = q["c_track"]
        K[2, r] = K[r, 2] = -kh
        K[3, r] = K[r, 3] = -sign * kh * l0
    return M, K, D
