"""Curves and cant as inputs of the linear model: quasi-static curving and its transitions.

Frame. The model's coordinates are taken in the track frame at the car
centre: it runs along the design track with the car, its x axis on the
track's tangent, its y axis in the plane of the rails (rolled by the cant
angle phi = cant / (2 l0) about the track's centre line; 2 l0 the lateral
distance of the contact points, cant the height of the right rail above the
left one, positive in a left-hand curve: curvature kappa > 0). On straight
untilted track this is the frame of the straight-track model. On a curve
it turns at v kappa and carries the car: the design geometry enters as

- **inertia and gravity in the rails' plane** on every rigid body b (mass
  m_b, at x_b ahead of the car centre): the lateral force
  -m_b (v^2 kappa_b - g phi_b) = -m_b a_q,b, a_q the cant deficiency
  (uncompensated lateral acceleration) at the body, and the yaw moment
  -I_z,b v^2 dkappa/ds of the frame's yaw acceleration (transitions);
- **the track under each wheelset j** as seen from the car centre's frame:
  alignment Y_j = the versine of the curve over x_j (kappa x_j^2 / 2 in a
  curve of constant radius) plus r0 (phi_j - phi_c) (the axle centre of a
  wheelset on rails rolled relative to the frame), cross-level
  -(cant_j - cant_c) (the rails' twist between the wheelset and the car
  centre); they act through the same input matrices as the irregularities;
- **the creepages of the turning frame**: the lateral creepage of wheelset j
  gains kappa_c x_j (the frame's rotation moves a point x_j ahead sideways),
  the longitudinal one l0 kappa_c (the outer wheel runs the longer path):
  the lateral force -2 f22 kappa_c x_j and the yaw moment -2 f11 l0^2 kappa_c.

Steady curving (constant kappa and cant, all terms constant) then gives the
known closed forms, without any term fitted to them: a wheelset that steers
freely rolls without longitudinal creep at the lateral offset

    y0 = -r0 l0 kappa / lambda          (Wickens, "Fundamentals of rail vehicle
                                          dynamics", 2003, ch. 4; Iwnicki (ed.),
                                          "Handbook of railway vehicle dynamics", 2006)

(outwards: the outer wheel rolls on the larger radius r0 + lambda |y0|,
lambda the equivalent conicity), and a lateral sensor fixed to the carbody
reads the cant deficiency plus the carbody's roll in the suspension,

    a_y = v^2 kappa - g phi + g theta_c,

theta_c the carbody's roll relative to the rails' plane under the lateral
loads m a_q (its roll flexibility). The sensors read the frame's own
acceleration and tilt besides the coordinates: v^2 kappa at the sensor and
-g phi_c on lateral sensors (the latter with ``gravity_roll``, as the g roll
term of the coordinates).

Transitions (clothoids: kappa and cant linear in distance) enter through the
same terms as functions of distance; the frame's roll acceleration
-v^2 d^2phi/ds^2 (a step of the roll rate at each end of a linear cant ramp)
is left out: a real transition rounds these ends, and the vehicle follows the
rails' roll through the wheelsets' cross-level inputs. Not modelled: flange
contact (the contact stays linear: equivalent conicity, linear creep; a
tight curve that needs more lateral offset than the flangeway clearance is
outside the model), the change of the wheel loads with the cant deficiency
(the creep coefficients keep the static loads), gravity's tilt terms beyond
first order in phi, and the vertical sensors' second-order terms
(v^2 kappa phi).

Outside the segment the curvature and the cant keep their first and last
values: a segment that starts in a curve starts in steady curving.

Solution (linear model, both solvers). The response to the curve forces F(t)
is superposed on the response to the irregularities. In the frequency solver
F changes only over the segment (it is constant before and after), so it is
its difference G[n] = F[n] - F[n - 1] that is transformed (zero padded like
the track): q = q_static + q_dyn with q_static = K^-1 F(t) the instantaneous
equilibrium (in the time domain, exact at any frequency down to 0 Hz: a
constant curve is a 0 Hz input that no FFT grid resolves) and q_dyn the
modal response to G; the accelerations come from G alone (the second
derivative of the static part is in it). So the spectra on a curve are right
whether or not their grid reaches down to the transition's frequencies.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import fft as sfft

from suspid.errors import SimulatorError
from suspid.infra.threads import single_blas_thread
from suspid.interfaces import TrackSegment

from . import parameters as P
from .layout import Layout
from .model import COORDINATES, Sensor
from .modes import acting_positions
from .solvers import FrequencyResponse

GRAVITY = P.GRAVITY


def has_curve(segment: TrackSegment) -> bool:
    """True when the segment carries a non-zero curvature or cant record."""
    return any(c is not None and np.any(np.asarray(c, dtype=float) != 0.0)
               for c in (segment.curvature, segment.cant))


def check_curve(segment: TrackSegment) -> None:
    """Raise SimulatorError for curvature or cant records the model cannot take."""
    n = np.asarray(segment.distance).size
    for what, rec in (("curvature", segment.curvature), ("cant", segment.cant)):
        if rec is None:
            continue
        a = np.asarray(rec, dtype=float)
        if a.shape != (n,):
            raise SimulatorError(f"segment '{segment.name}': {what} of shape {a.shape}, expected ({n},)")
        if not np.all(np.isfinite(a)):
            raise SimulatorError(f"segment '{segment.name}': {what} contains NaN or inf")


class DesignTrack:
    """Curvature (1/m), its derivative, heading (rad), versine offset (m) and cant (m) of a segment as
    functions of distance, continued outside the segment with the first and last values (straight
    continuation of the curvature: a circle before and after)."""

    def __init__(self, segment: TrackSegment) -> None:
        x = np.asarray(segment.distance, dtype=float)
        n = x.size
        self.x = x
        self.kappa = np.zeros(n) if segment.curvature is None else np.asarray(segment.curvature, dtype=float)
        self.cant = np.zeros(n) if segment.cant is None else np.asarray(segment.cant, dtype=float)
        dx = np.diff(x)
        self.dkappa = np.gradient(self.kappa, x)
        # heading and offset integrated exactly for a curvature linear between samples (a linear interpolation
        # of the offset, a cubic, would err by kappa dx^2 / 8: 2e-6 m at R 4000 m, 10 N on a wheelset)
        k0, k1 = self.kappa[:-1], self.kappa[1:]
        self.heading = np.concatenate([[0.0], np.cumsum(0.5 * (k0 + k1) * dx)])
        step = self.heading[:-1] * dx + k0 * dx ** 2 / 2 + (k1 - k0) * dx ** 2 / 6
        self.offset = np.concatenate([[0.0], np.cumsum(step)])

    def at(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(kappa, dkappa/ds, heading, offset, cant)`` at distances ``s`` (any shape)."""
        x, k = self.x, self.kappa
        s = np.asarray(s, dtype=float)
        kappa = np.interp(s, x, k)
        dk = np.where((s < x[0]) | (s > x[-1]), 0.0, np.interp(s, x, self.dkappa))
        cant = np.interp(s, x, self.cant)
        # the interval of each s (the first or last one outside, where the curvature holds: a circle)
        i = np.clip(np.searchsorted(x, s, side="right") - 1, 0, x.size - 2)
        outside_hi = s > x[-1]
        i = np.where(outside_hi, x.size - 1, i)
        d = s - x[i]
        slope = np.where(outside_hi, 0.0, (k[np.minimum(i + 1, x.size - 1)] - k[i]) / (x[1] - x[0]))
        slope = np.where(s < x[0], 0.0, slope)
        heading = self.heading[i] + k[i] * d + slope * d ** 2 / 2
        offset = self.offset[i] + self.heading[i] * d + k[i] * d ** 2 / 2 + slope * d ** 3 / 6
        return kappa, dk, heading, offset, cant


@dataclass
class CurveModel:
    """What the curve terms need of the model besides its linear system.

    :ivar body_x: rigid body name -> its position ahead of the car centre, m.
    :ivar wheel_loads: ``(n_wheelsets,)`` static wheel loads, N.
    :ivar l0, r0, conicity: half the distance of the contact points (m), rolling radius (m), equivalent
        conicity.
    :ivar creep: ``(n_wheelsets, 2)`` Kalker's f11, f22 per wheelset, N.
    :ivar sensors: the sensors; ``gravity_roll``: lateral sensors read g times the roll.
    """

    body_x: dict[str, float]
    l0: float
    r0: float
    creep: np.ndarray
    sensors: list[Sensor]
    gravity_roll: bool

    @classmethod
    def of(cls, values: dict[str, float], layout: Layout, sensors: list[Sensor], gravity_roll: bool
           ) -> "CurveModel":
        body_x = {}
        for name, x in zip(layout.carbodies, layout.carbody_x(values)):
            body_x[name] = float(x)
        for name, x in zip(layout.bogies, layout.bogie_x(values)):
            body_x[name] = float(x)
        for name, x in zip(layout.wheelsets, layout.wheelset_x(values)):
            body_x[name] = float(x)
        creep = np.array([P.creep_coefficients(values, layout.wheel_load(values, j))
                          for j in range(layout.n_wheelsets)])
        return cls(body_x, float(values["l0"]), float(values["r0"]), creep, list(sensors), bool(gravity_roll))


def curve_forces(cm: CurveModel, lin, design: DesignTrack, s: np.ndarray, v: np.ndarray) -> np.ndarray:
    """F ``(n, n_t)``: generalised forces of the curve on the free coordinates (N, N m), see the module
    docstring, for the car centre at distances ``s`` (m) with speeds ``v`` (m/s), both ``(n_t,)``."""
    n = lin.M.shape[0]
    index = {label: i for i, label in enumerate(lin.labels)}
    lat, yaw = COORDINATES.index("lateral"), COORDINATES.index("yaw")
    a_T = np.zeros((n, s.size))                     # acceleration of the frame at each coordinate
    two_l0 = 2.0 * cm.l0
    for body, xb in cm.body_x.items():
        kappa, dk, _, _, cant = design.at(s + xb)
        if (body, COORDINATES[lat]) in index:
            a_T[index[(body, COORDINATES[lat])]] = v ** 2 * kappa - GRAVITY * cant / two_l0
        if (body, COORDINATES[yaw]) in index:
            a_T[index[(body, COORDINATES[yaw])]] = v ** 2 * dk
    F = -lin.M @ a_T
    kappa_c, _, heading_c, offset_c, cant_c = design.at(s)
    wheelsets = [b for b in cm.body_x if b.startswith("wheelset")]
    for j, (name, xj) in enumerate(zip(wheelsets, lin.wheelset_x)):
        _, _, _, offset_j, cant_j = design.at(s + xj)
        versine = offset_j - offset_c - xj * heading_c
        alignment = versine + cm.r0 * (cant_j - cant_c) / two_l0
        cross_level = -(cant_j - cant_c)
        F += np.outer(lin.G[j][:, 1], alignment) + np.outer(lin.G[j][:, 2], cross_level)
        f11, f22 = cm.creep[j]
        F[index[(name, "lateral")]] += -2.0 * f22 * kappa_c * xj
        F[index[(name, "yaw")]] += -2.0 * f11 * cm.l0 ** 2 * kappa_c
    return F


def frame_outputs(cm: CurveModel, design: DesignTrack, s: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``(n_sensors, n_t)``: what the sensors read of the frame's own motion: v^2 kappa at the sensor on
    lateral sensors, minus g phi_c with ``gravity_roll`` (m/s^2)."""
    out = np.zeros((len(cm.sensors), s.size))
    _, _, _, _, cant_c = design.at(s)
    for i, sensor in enumerate(cm.sensors):
        if sensor.direction != "lateral":
            continue
        kappa = design.at(s + cm.body_x[sensor.body] + sensor.position[0])[0]
        out[i] = v ** 2 * kappa
        if cm.gravity_roll:
            out[i] -= GRAVITY * cant_c / (2.0 * cm.l0)
    return out


def static_matrix(response: FrequencyResponse) -> np.ndarray:
    """``(n_sensors, n)``: the sensors' displacement part C_disp q_static per unit force, q_static the
    static equilibrium (modal form: -Ld diag(1/lambda) V^-1 [0; M^-1])."""
    n = response.linear.M.shape[0]
    p = response.n_state - n
    if response.Ld is None:
        return np.zeros((response.L.shape[0], n))
    Rf = response.Vinv[:, p:] @ response.Minv
    return np.real(-(response.Ld * (1.0 / response.eigenvalues)[None, :]) @ Rf)


def static_coordinates(lin, F: np.ndarray) -> dict[tuple[str, str], np.ndarray]:
    """The static equilibrium K^-1 F of a linear system ``lin`` under forces ``F`` ``(n, ...)``: (body,
    motion) -> displacement (m, rad), the acting coordinates (spin angles, which act nowhere, left out)."""
    acting = acting_positions(lin.K)
    q = np.linalg.solve(lin.K[np.ix_(acting, acting)], F[acting])
    return {lin.labels[i]: q[k] for k, i in enumerate(acting)}


def curve_response(response: FrequencyResponse, cm: CurveModel, segment: TrackSegment, fs: float,
                   n_t: int, settle_s: float, s_of_t, v_of_t) -> np.ndarray:
    """``(n_sensors, n_t)``: the sensors' response to the segment's curvature and cant (frequency solver).

    :param s_of_t, v_of_t: car-centre distance (m) and speed (m/s) as functions of time (s, 0 at the
        segment's first sample), continued at constant speed outside the record.
    """
    if not response.modal:
        raise SimulatorError(f"segment '{segment.name}': the eigenvectors of the linear model are "
                             f"ill-conditioned; curves need the modal form (use solver: time)")
    lin = response.linear
    design = DesignTrack(segment)
    x_max = max(0.0, max(cm.body_x.values()))
    x_min = min(0.0, min(cm.body_x.values()))
    v_lo = float(np.min(np.asarray(segment.speed, dtype=float)))
    n_a = -int(math.ceil(x_max / v_lo * fs)) - 2
    n_b = n_t + int(math.ceil(-x_min / v_lo * fs)) + 2
    pad = min(max(settle_s, response.settling_time), 120.0)
    n_fft = 1 << int(math.ceil(math.log2(n_b - n_a + 2 + int(math.ceil(pad * fs)))))
    idx = np.arange(n_a - 1, n_b + 1)
    t = idx / fs
    s, v = s_of_t(t), v_of_t(t)
    F = curve_forces(cm, lin, design, s, v)                           # (n, len(idx))
    G = np.diff(F, axis=1)                                            # G[n] = F[n] - F[n - 1], n = n_a .. n_b
    buf = np.zeros((F.shape[0], n_fft))
    buf[:, np.arange(n_a, n_b + 1) % n_fft] = G
    n = lin.M.shape[0]
    p = response.n_state - n
    w = 2 * math.pi * np.arange(n_fft // 2 + 1) * fs / n_fft
    with single_blas_thread():
        Gw = sfft.rfft(buf, axis=1)                                    # (n, n_f)
        z = 1.0 / (1j * w[None, :] - response.eigenvalues[:, None])
        S = (response.Vinv[:, p:] @ (response.Minv @ Gw)) * z          # (m2, n_f)
        e = 1.0 - np.exp(-1j * w / fs)
        rho = np.where(w > 0, 1j * w / np.where(w > 0, e, 1.0), fs)     # i w / (1 - e^{-i w / fs}), fs at 0
        Y = (1j * w * rho) * (response.L @ S)
        if response.Ld is not None:
            Y += rho * (response.Ld @ (S / response.eigenvalues[:, None]))
        if n_fft % 2 == 0:
            Y[:, -1] = 0.0
    y = sfft.irfft(Y, n=n_fft, axis=1)[:, :n_t]
    inside = slice(1 - n_a, 1 - n_a + n_t)                            # F on the record's samples 0 .. n_t - 1
    y += static_matrix(response) @ F[:, inside]
    y += frame_outputs(cm, design, s[inside], v[inside])
    return y


# ====================================================================== time solver
CURVE_DT = 0.02
"""Time step (s) of the curve force tables of the time solver (the forces change over transitions of
tens of metres: seconds)."""


def forced_rows(cm: CurveModel, lin) -> np.ndarray:
    """Free coordinates on which a curve can act (those with a non-zero force for some curve)."""
    x = np.arange(0.0, 64.0, 1.0)
    probe = TrackSegment("probe", x, np.zeros((4, x.size)), 50.0, curvature=1e-3 * np.sin(x / 5.0),
                         cant=0.1 * np.cos(x / 7.0))
    s = np.linspace(20.0, 44.0, 7)
    F = curve_forces(cm, lin, DesignTrack(probe), s, np.full(s.size, 50.0))
    return np.flatnonzero(np.any(F != 0.0, axis=1))


def _node_coordinates(model) -> dict[int, tuple[object, int, int]]:
    """Global ODE2 index -> (node, coordinate within the node, number of the node's coordinates)."""
    out = {}
    for name in model.bodies:
        start = model.node_index[name]
        for k in range(6):
            out[start + k] = (model.nodes[name], k, 6)
    for node, _, labels in model.effect_nodes:
        start = model.mbs.GetNodeODE2Index(node)
        for k in range(len(labels)):
            out[start + k] = (node, k, len(labels))
    return out


class CurveTables:
    """Curve forces in the time solver: per node with forced coordinates, a linear element whose symbolic
    force function reads time tables (``capacity`` samples at :data:`CURVE_DT`) of the forces on that node's
    coordinates; :meth:`set` fills the tables and the nodes' initial coordinates (the static equilibrium of
    the forces at the start) for one segment."""

    def __init__(self, model, rows: np.ndarray, capacity: int) -> None:
        from exudyn import itemInterface as ii
        from exudyn.advancedUtilities import CreateSymbolicUserFunction

        from .model import _lookup

        esym = model.exu.symbolic
        mbs = model.mbs
        self.model, self.rows, self.capacity = model, np.asarray(rows), int(capacity)
        self.step = esym.Real("curve_dt_inv", 1.0 / CURVE_DT)
        where = _node_coordinates(model)
        by_node: dict[object, list[tuple[int, int]]] = {}
        sizes: dict[object, int] = {}
        for i in self.rows:
            node, k, size = where[int(model.free[i])]
            by_node.setdefault(node, []).append((k, int(i)))
            sizes[node] = size
        self.leaves: dict[int, list] = {}
        self._keep: list = []
        self.nodes = list(by_node)
        for node, items in by_node.items():
            n_c = sizes[node]
            forced = {}
            for k, i in items:
                leaves = [esym.Real(f"curve_{i}_{m}", 0.0) for m in range(self.capacity + 1)]
                self.leaves[i] = leaves
                forced[k] = leaves
            zeros = np.zeros((n_c, n_c))
            element = mbs.AddObject(ii.ObjectGenericODE2(nodeNumbers=[node], massMatrix=zeros,
                                                         stiffnessMatrix=zeros, dampingMatrix=zeros,
                                                         forceVector=[0.0] * n_c))

            uf = CreateSymbolicUserFunction(mbs, self._force_function(esym, _lookup, forced, n_c),
                                            "forceUserFunction", element)
            mbs.SetObjectParameter(element, "forceUserFunction", uf)
            self._keep.append(uf)
        mbs.Assemble()

    def _force_function(self, esym, lookup, forced: dict[int, list], n_c: int):
        """The symbolic force function of one node: its forced coordinates read their tables at t / dt."""
        step, capacity = self.step, self.capacity

        def force(mbs, t, itemNumber, q, q_t):
            q.SetVector([0.0] * n_c)
            q_t.SetVector([0.0] * n_c)
            tau = t * step
            return [lookup(esym, forced[k], tau, capacity) if k in forced else 0.0 for k in range(n_c)]

        return force

    def set(self, F: np.ndarray, q0: dict[int, float]) -> None:
        """Fill the tables with F ``(n_free, n_samples)`` (N, N m) at times k :data:`CURVE_DT` from the start of
        the integration (held after the last sample) and set the initial coordinates ``q0`` (free index -> m
        or rad; every other coordinate of the forced nodes 0)."""
        if F.shape[1] > self.capacity:
            raise SimulatorError(f"curve table of {F.shape[1]} samples exceeds its capacity {self.capacity}")
        for i, leaves in self.leaves.items():
            row = F[i]
            last = float(row[-1])
            for m in range(self.capacity + 1):
                leaves[m].SetValue(float(row[m]) if m < row.size else last)
        model = self.model
        where = _node_coordinates(model)
        initial: dict[object, list[float]] = {}
        for i, g in enumerate(model.free):        # every free node: a straight segment resets a curve's offsets
            node, k, size = where[int(g)]
            initial.setdefault(node, [0.0] * size)[k] = float(q0.get(i, 0.0))
        for node, values in initial.items():
            model.mbs.SetNodeParameter(node, "initialCoordinates", values)
