"""How the exudyn model implements the registered effects (``simulator.options.effects``).

An effect is declared backend-neutrally in the effect registry
(:mod:`suspid.plugins.effects`: parameters, bounds, signature); this module
says what it does to *this* model, for both solvers at once: every effect
either adds exudyn items to the one ``MainSystem`` (nodes, linear
``ObjectGenericODE2`` elements, symbolic force functions for the time
solver), changes parameter values, changes the sensor output matrices, or adds
periodic wheel inputs. Since the frequency solver linearises the same system
(``ComputeLinearizedSystem``) and both solvers compute the sensors from the
same output matrices, an effect implemented here acts identically in both.

Hooks of :class:`ExudynEffect` (each optional), in the order the model calls them:

1. :meth:`~ExudynEffect.adjust_values`: change parameter values (conicity);
2. :attr:`~ExudynEffect.replaces`: built-in elements the effect takes over
   (``"yaw_damper"``: the model then builds no yaw dampers of its own;
   ``"track_support"``: no rail masses of its own);
3. :meth:`~ExudynEffect.build`: add nodes and linear elements (before ``Assemble``);
4. :meth:`~ExudynEffect.build_time`: add symbolic force functions that need the
   track tables (time solver only);
5. :meth:`~ExudynEffect.kinematic_rows`: add to the acceleration of the sensor
   points (a flexible mode moves the points it deforms);
6. :meth:`~ExudynEffect.outputs`: change what the sensors measure (tilt);
7. :meth:`~ExudynEffect.input_rows`: track input of added coordinates (frequency solver);
8. :meth:`~ExudynEffect.periodic_inputs`: periodic vertical wheel inputs (polygons).

The parameters listed in the effect's ``fitted`` are read from the model's
parameter values under ``<effect>/<parameter>`` (so that they change without a
rebuild); the others come from the effect's options.

Linear elements use the rigid-body kinematics of the nodes (x, y, z, roll,
pitch, yaw; small rotations): the displacement of a body point r (relative to
the centre of mass) is t + θ × r, see :func:`point_jacobian`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar, Mapping, Sequence

import numpy as np

from . import parameters as P

MAXWELL_FAST_HZ = 2000.0
"""The internal node of a Maxwell element has mass c / (2π × this): its fast pole sits at this
frequency, and its inertia changes the element's force by about f / 2000 Hz (1.5 % at 30 Hz)."""


@dataclass(frozen=True)
class PeriodicInput:
    """A periodic vertical input on one wheelset: A cos(2π s / wavelength + phase).

    :ivar wheelset: 0-based wheelset index (0 leads).
    :ivar wavelength: m along the track.
    :ivar amplitude: m (added to the vertical track level under the wheelset).
    :ivar phase: rad at s = 0, s the distance of the wheelset from the segment start.
    """

    wheelset: int
    wavelength: float
    amplitude: float
    phase: float


def point_jacobian(r: Sequence[float]) -> np.ndarray:
    """``(3, 6)``: displacement of body point r (m, body axes at the centre of mass) per node coordinate.

    Node coordinates x, y, z, roll, pitch, yaw (small rotations): d = t + θ × r = t - [r]× θ.
    """
    rx, ry, rz = (float(c) for c in r)
    J = np.zeros((3, 6))
    J[:, :3] = np.eye(3)
    J[:, 3:] = -np.array([[0.0, -rz, ry], [rz, 0.0, -rx], [-ry, rx, 0.0]])
    return J


class ExudynEffect:
    """The exudyn implementation of one effect; ``params`` are its validated options (without ``name``)."""

    name: ClassVar[str]
    replaces: ClassVar[frozenset[str]] = frozenset()
    fitted: ClassVar[tuple[str, ...]] = ()

    def __init__(self, params: Mapping[str, Any]) -> None:
        self.params = dict(params)

    def key(self, parameter: str) -> str:
        """The name of a fitted parameter among the model's values: ``<effect>/<parameter>``."""
        return f"{self.name}/{parameter}"

    def get(self, values: Mapping[str, float], parameter: str) -> Any:
        """A parameter's current value: from ``values`` when fitted, else from the options."""
        if parameter in self.fitted:
            return values.get(self.key(parameter), self.params[parameter])
        return self.params[parameter]

    @property
    def needs_coordinates(self) -> bool:
        """True when the sensors read displacements too (the time solver then records them)."""
        return False

    def check(self, sensors: Sequence, n_wheelsets: int) -> None:
        """Raise ValueError when the options do not fit the model (unknown channel, wheelset)."""

    def adjust_values(self, values: dict[str, float]) -> None:
        """Change parameter values in place."""

    def build(self, model) -> None:
        """Add nodes and elements to ``model.mbs`` (before ``Assemble``)."""

    def build_time(self, model) -> None:
        """Add what the time solver needs besides the linear elements (after the track tables exist)."""

    def kinematic_rows(self, model, R: np.ndarray, values: Mapping[str, float]) -> None:
        """Add to ``R`` ``(n_sensors, 3, n_free)``: acceleration of each sensor point per free coordinate."""

    def outputs(self, model, R: np.ndarray, C: np.ndarray, C_disp: np.ndarray, values: Mapping[str, float]) -> None:
        """Change the output matrices in place: sensor = C q'' + C_disp q (``(n_sensors, n_free)`` each)."""

    def input_rows(self, model, G: np.ndarray, values: Mapping[str, float]) -> None:
        """Fill rows of ``G`` ``(n_wheelsets, n_free, 3)`` for the coordinates the effect added."""

    def periodic_inputs(self, values: Mapping[str, float]) -> list[PeriodicInput]:
        """Periodic wheel inputs; their number and wheelsets must not depend on ``values``."""
        return []


def maxwell_element(r_bogie: Sequence[float], r_car: Sequence[float], axis: int, stiffness: float, c: float,
                    damped: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(M, K, D) ``(13, 13)`` of a Maxwell element on (bogie, carbody, internal coordinate u): a spring
    ``stiffness`` (N/m) from the bogie point ``r_bogie`` to u, in series with a damper ``c`` (N s/m) from u
    to the carbody point ``r_car`` (m, body axes at each body's centre of mass), along ``axis`` (0 x, 2 z).

    Energy ½ k (u - d_bogie)², dissipation ½ c (u' - d'_carbody)², d the
    displacement of the attachment points along ``axis``; the internal mass
    c / (2π :data:`MAXWELL_FAST_HZ`) keeps the system second order. ``damped=False``
    leaves the damper out.
    """
    n = 13
    ws = np.zeros(n)
    ws[0:6] = -point_jacobian(r_bogie)[axis]
    ws[12] = 1.0
    wd = np.zeros(n)
    wd[6:12] = -point_jacobian(r_car)[axis]
    wd[12] = 1.0
    M = np.zeros((n, n))
    M[12, 12] = c / (2 * math.pi * MAXWELL_FAST_HZ)
    D = c * np.outer(wd, wd) if damped else np.zeros((n, n))
    return M, stiffness * np.outer(ws, ws), D


def maxwell_yaw_damper(q: dict[str, float], end: float, side: float, stiffness: float, damped: bool = True
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(M, K, D) ``(13, 13)`` of one Maxwell yaw damper on (bogie, carbody, internal coordinate u).

    ``end``: +1 for a bogie under the carbody's front pivot, -1 under its rear pivot; ``side``: +1 left, -1 right.

    Energy ½ k_s (u - d_bogie)², dissipation ½ c_yaw (u' - d'_carbody)², d the
    longitudinal displacement of the attachment points (:func:`maxwell_element`).
    ``damped=False`` leaves the damper out (the time solver's blow-off law then
    supplies it, :meth:`.model.TrainModel._yaw_blow_off`).
    """
    return maxwell_element((0.0, side * q["b_yaw"], q["h_yaw"] - q["h_bogie"]),
                           (end * q["a_bogie"], side * q["b_yaw"], q["h_yaw"] - q["h_car"]), 0,
                           stiffness, q["c_yaw"], damped)


def maxwell_secondary_damper(q: dict[str, float], end: float, side: float) -> tuple[np.ndarray, np.ndarray,
                                                                                       np.ndarray]:
    """(M, K, D) ``(13, 13)`` of one secondary vertical damper on (bogie, carbody, internal coordinate u).

    The damper c_sec_z in series with the stiffness k_sec_z_s of its rubber end
    mounts, at the secondary spring's place (±a_bogie on the carbody, ±b_sec,
    h_sec): energy ½ k_sec_z_s (u - z_bogie)², dissipation ½ c_sec_z (u' - z'_carbody)²,
    z the vertical displacement of the attachment points (:func:`maxwell_element`).
    """
    return maxwell_element((0.0, side * q["b_sec"], q["h_sec"] - q["h_bogie"]),
                           (end * q["a_bogie"], side * q["b_sec"], q["h_sec"] - q["h_car"]), 2,
                           q["k_sec_z_s"], q["c_sec_z"])


def _symmetric_outer(u: np.ndarray, e: np.ndarray) -> np.ndarray:
    return np.outer(u, e) + np.outer(e, u)


# ------------------------------------------------------------------------------------------ carbody bending
class CarbodyBending(ExudynEffect):
    """First vertical bending mode of the carbody: one modal coordinate q (mid-car deflection, m).

    Element on (carbody, front bogie, rear bogie, q, the internal coordinates of
    the four secondary vertical dampers), 23 coordinates:
    m_q q'' + c_q q' + k_q q with k_q = m_q (2π f)², c_q = 2 ζ m_q 2π f, and the
    secondary vertical springs (per side, k_sec_z) and Maxwell dampers (c_sec_z)
    seeing the carbody point at the pivot x_p = ±a_bogie move by φ(x_p) q more:
    the energy ½ k (δ_rigid + φ_p q)² adds k (φ_p (u e_q^T + e_q u^T) + φ_p² e_q e_q^T)
    to the rigid terms the secondary suspension already has (u: δ_rigid per
    coordinate), and the damper's dissipation ½ c (δ_d - φ_p q')² adds
    c (-φ_p (w e_q^T + e_q w^T) + φ_p² e_q e_q^T) (w: the damper's elongation u_d - z_carbody). Sensors on the carbody at x move by φ(x) q more (every direction
    row gets it in the vertical component). Linearised about the sagged shape:
    the static deflection of the mode does not enter.
    """

    name = "carbody-bending"
    fitted = ("frequency_hz", "damping")

    def _shape(self, x):
        from suspid.plugins.effects import beam_mode_shape

        return beam_mode_shape(x, self.params["length_m"])

    def modal_mass(self, values: Mapping[str, float]) -> float:
        from suspid.plugins.effects.catalogue import beam_modal_mass_ratio

        m = self.params.get("modal_mass_kg")
        return float(m) if m else beam_modal_mass_ratio() * values["m_car"]

    def matrices(self, q: Mapping[str, float]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        n = 23
        M, K, D = np.zeros((n, n)), np.zeros((n, n)), np.zeros((n, n))
        m = self.modal_mass(q)
        w = 2 * math.pi * self.get(q, "frequency_hz")
        M[18, 18] = m
        K[18, 18] = m * w * w
        D[18, 18] = 2.0 * self.get(q, "damping") * m * w
        e = np.zeros(n)
        e[18] = 1.0
        for b, xb in enumerate((q["a_bogie"], -q["a_bogie"])):
            phi = float(self._shape(xb))
            for k, side in enumerate((1.0, -1.0)):
                car_z = point_jacobian((xb, side * q["b_sec"], q["h_sec"] - q["h_car"]))[2]
                u = np.zeros(n)
                u[0:6] = car_z
                u[6 + 6 * b: 12 + 6 * b] = -point_jacobian((0.0, side * q["b_sec"], q["h_sec"] - q["h_bogie"]))[2]
                K += q["k_sec_z"] * (phi * _symmetric_outer(u, e) + phi * phi * np.outer(e, e))
                w_damper = np.zeros(n)                 # elongation u_damper - z_carbody of the Maxwell damper
                w_damper[0:6] = -car_z
                w_damper[19 + 2 * b + k] = 1.0
                D += q["c_sec_z"] * (-phi * _symmetric_outer(w_damper, e) + phi * phi * np.outer(e, e))
        return M, K, D

    def build(self, model) -> None:
        if model.layout.articulated:
            raise ValueError("the carbody-bending effect is implemented for one car on two bogies; the "
                             "articulated preset has several carbodies")
        node = model.add_effect_node(self.name, ("bending",))
        nodes = [model.nodes["carbody"], model.nodes["bogie_front"], model.nodes["bogie_rear"], node]
        nodes += [model.secondary_damper_nodes[(bogie, side)]
                  for bogie in ("bogie_front", "bogie_rear") for side in (1.0, -1.0)]
        model.add_linear_element(nodes, 23, self.matrices)

    def kinematic_rows(self, model, R, values) -> None:
        col = model.free_position[(self.name, "bending")]
        for i, s in enumerate(model.sensors):
            if s.body == "carbody":
                R[i, 2, col] += float(self._shape(s.position[0]))


# ------------------------------------------------------------------------------------------ yaw damper
class YawDamperSeriesStiffness(ExudynEffect):
    """Each yaw damper becomes a Maxwell element: spring k_s (bogie side) in series with the damper c_yaw.

    One internal coordinate u per damper (longitudinal, m) with a small mass
    c_yaw / (2π :data:`MAXWELL_FAST_HZ`); element on (bogie, carbody, u):
    energy ½ k_s (u - d_bogie)², dissipation ½ c_yaw (u' - d'_carbody)², with
    d the longitudinal displacement of the attachment points. It replaces the
    model's own Maxwell yaw dampers (series stiffness ``k_yaw_s``): the effect's
    stiffness is then the one identified.
    """

    name = "yaw-damper-series-stiffness"
    fitted = ("stiffness_n_per_m",)
    replaces = frozenset({"yaw_damper"})

    def build(self, model) -> None:
        for bogie, car, end, side, side_name in model.yaw_damper_places():
            node = model.add_effect_node(self.name, (f"{bogie}_{side_name}",))
            nodes = [model.nodes[bogie], model.nodes[car], node]
            model.add_linear_element(nodes, 13, lambda q, e=end, s=side: self.matrices(q, e, s))

    def matrices(self, q: Mapping[str, float], end: float, side: float):
        return maxwell_yaw_damper(q, end, side, self.get(q, "stiffness_n_per_m"))


# ------------------------------------------------------------------------------------------ sensor tilt
class SensorTilt(ExudynEffect):
    """Tilted lateral accelerometers: cos α a_lat + sin α a_vert (+ g φ_roll of the body).

    a_vert is the vertical acceleration of the same point (with any flexible
    mode), φ_roll the roll coordinate of the sensor's body.
    """

    name = "sensor-tilt"
    fitted = ("angle_deg",)

    @property
    def needs_coordinates(self) -> bool:
        return bool(self.params["gravity_roll"])

    def tilted(self, sensors: Sequence) -> list[int]:
        wanted = self.params["channels"]
        return [i for i, s in enumerate(sensors)
                if s.direction == "lateral" and (wanted is None or s.name in wanted)]

    def check(self, sensors, n_wheelsets) -> None:
        wanted = self.params["channels"] or []
        lateral = {s.name for s in sensors if s.direction == "lateral"}
        unknown = [c for c in wanted if c not in lateral]
        if unknown:
            raise ValueError(f"sensor-tilt: '{unknown[0]}' is not a lateral channel; lateral channels: "
                             f"{', '.join(sorted(lateral)) or 'none'}")

    def outputs(self, model, R, C, C_disp, values) -> None:
        alpha = math.radians(self.get(values, "angle_deg"))
        for i in self.tilted(model.sensors):
            C[i] = math.cos(alpha) * R[i, 1] + math.sin(alpha) * R[i, 2]
            if self.params["gravity_roll"] and i not in model._gravity_roll_sensors():
                # (the model adds g × roll to every lateral channel unless its gravity_roll option is off)
                C_disp[i, model.free_position[(model.sensors[i].body, "roll")]] += P.GRAVITY


# ------------------------------------------------------------------------------------------ conicity
class ConicityChange(ExudynEffect):
    """The equivalent conicity of the contact takes the effect's value (it overrides ``conicity``)."""

    name = "conicity-change"
    fitted = ("conicity",)

    def adjust_values(self, values) -> None:
        values["conicity"] = float(self.get(values, "conicity"))


# ------------------------------------------------------------------------------------------ polygon
class WheelPolygon(ExudynEffect):
    """A polygonal wheel: vertical input A cos(2π s k / (π D) + φ + i Δφ) on the i-th listed wheelset.

    Both wheels of a wheelset are out of round alike (a vertical input on the
    wheelset); s is the distance the wheelset has rolled from the segment
    start. Time solver: added to the track level in the contact force
    function; frequency solver: the steady-state response to the sinusoid,
    added to each segment's record (starting from rest, the time solver has a
    transient during its run-in before the record).
    """

    name = "wheel-polygon"
    fitted = ("amplitude_m", "phase_step_rad")

    def check(self, sensors, n_wheelsets) -> None:
        bad = [j for j in self.params["wheelsets"] if j > n_wheelsets]
        if bad:
            raise ValueError(f"wheel-polygon: wheelset {bad[0]} does not exist (1-{n_wheelsets})")

    def periodic_inputs(self, values) -> list[PeriodicInput]:
        wavelength = math.pi * self.params["wheel_diameter_m"] / self.params["order"]
        step = float(self.get(values, "phase_step_rad"))
        return [PeriodicInput(j - 1, wavelength, float(self.get(values, "amplitude_m")), self.params["phase_rad"] + i * step)
                for i, j in enumerate(self.params["wheelsets"])]


# ------------------------------------------------------------------------------------------ track flexibility
class TrackFlexibility(ExudynEffect):
    """A track mass under each wheelset on a flexible support (rail pad and ballast).

    Per wheelset j a vertical coordinate z_t (m); the Hertzian springs (2 k_H
    per wheelset) now act between wheelset and track mass, with the track level
    V between them: energy k_H (z_w - z_t - V)². The contact element keeps its
    k_H z_w² part; the added element on (wheelset, z_t) holds -2 k_H z_w z_t,
    (2 k_H + k_t) z_t², the support damping c_t and the mass m_t, with
    k_t = (2π f_P2)² (m_wheelset + m_t) and c_t = 2 ζ sqrt(k_t (m_wheelset + m_t)).
    The force -2 k_H V on z_t is an input row (frequency solver) or a symbolic
    force reading the track table at the wheelset's odometer (time solver).
    The cross-level (roll) contact stays on rigid track. Static loads balance
    (the support carries the wheel load): no preload is needed. It replaces the
    model's own track support (two rail masses per wheelset, vertical and roll).
    """

    name = "track-flexibility"
    fitted = ("frequency_hz", "damping")
    replaces = frozenset({"track_support"})

    def support(self, q: Mapping[str, float]) -> tuple[float, float, float]:
        m_t = float(self.params["track_mass_kg"])
        m = q["m_ws"] + m_t
        k_t = (2 * math.pi * self.get(q, "frequency_hz")) ** 2 * m
        return m_t, k_t, 2.0 * self.get(q, "damping") * math.sqrt(k_t * m)

    def matrices(self, q: Mapping[str, float], wheel: float | None = None):
        m_t, k_t, c_t = self.support(q)
        kh2 = 2.0 * P.hertz_stiffness(q, wheel)
        M, K, D = np.zeros((7, 7)), np.zeros((7, 7)), np.zeros((7, 7))
        M[6, 6] = m_t
        K[2, 6] = K[6, 2] = -kh2
        K[6, 6] = kh2 + k_t
        D[6, 6] = c_t
        return M, K, D

    def build(self, model) -> None:
        self.nodes = []
        for j in range(model.n_wheelsets):
            node = model.add_effect_node(self.name, (f"track_{j + 1}",))
            self.nodes.append(node)
            model.add_linear_element([model.nodes[f"wheelset_{j + 1}"], node], 7,
                                     lambda q, j=j: self.matrices(q, model.layout.wheel_load(q, j)))

    def build_time(self, model) -> None:
        from exudyn import itemInterface as ii
        from exudyn.advancedUtilities import CreateSymbolicUserFunction

        esym = model.exu.symbolic
        zeros = np.zeros((2, 2))
        self._keep = []
        for j, node in enumerate(self.nodes):
            kh2 = esym.Real(f"{self.name}_kh2_{j}", 0.0)
            model._track(lambda v, r=kh2: r.SetValue(float(v)),
                         lambda q, j=j: 2.0 * P.hertz_stiffness(q, model.layout.wheel_load(q, j)))
            model._keep.append(kh2)
            element = model.mbs.AddObject(ii.ObjectGenericODE2(
                nodeNumbers=[node, model.odometers[j]], massMatrix=zeros, stiffnessMatrix=zeros,
                dampingMatrix=zeros, forceVector=[0.0, 0.0]))

            uf = CreateSymbolicUserFunction(model.mbs, self._force_function(model, j, kh2), "forceUserFunction",
                                            element)
            model.mbs.SetObjectParameter(element, "forceUserFunction", uf)
            self._keep.append(uf)

    @staticmethod
    def _force_function(model, j: int, kh2):
        """Symbolic force on (track mass j, odometer j): -2 k_H V under wheelset j."""
        def force(mbs, t, itemNumber, q, q_t):
            q.SetVector([0.0, 0.0])
            q_t.SetVector([0.0, 0.0])
            return [-kh2 * model.vertical_input(j, q[1]), 0.0]

        return force

    def input_rows(self, model, G, values) -> None:
        for j in range(model.n_wheelsets):
            kh2 = 2.0 * P.hertz_stiffness(values, model.layout.wheel_load(values, j))
            G[j, model.free_position[(self.name, f"track_{j + 1}")], 0] = -kh2


IMPLEMENTATIONS: dict[str, type[ExudynEffect]] = {cls.name: cls for cls in (
    CarbodyBending, YawDamperSeriesStiffness, SensorTilt, ConicityChange, WheelPolygon, TrackFlexibility)}
"""Effect name -> its implementation in this model."""


def supported() -> list[str]:
    """Names of the effects this model implements."""
    return sorted(IMPLEMENTATIONS)


def make(spec: Mapping[str, Any]) -> ExudynEffect:
    """The implementation of one validated entry of ``options.effects`` (``{name, **params}``)."""
    params = dict(spec)
    name = params.pop("name")
    return IMPLEMENTATIONS[name](params)
