"""An independent "real train" that writes measured-data files for suspid.

Everything here is numpy/scipy and written apart from suspid's own train
model (``exudyn-train``), its effects and its spectra/noise code: the point
is data that suspid's model did not make (circular validation is the thing
to avoid). Nothing from suspid is imported: the CSV files are written by this
module in suspid's documented measured-data layout.

Model
-----
A single high-speed car: carbody, two bogie frames, four wheelsets (1 leads;
1-2 in the front bogie) and a rail mass under each wheel, linear(ised)
about straight-track running at constant speed v, solved in the frequency
domain with the track as input. Axes x forward, y left, z up; small angles
roll (about x), pitch (about y), yaw (about z). SI units throughout.

Degrees of freedom (51): carbody x, y, z, roll, pitch, yaw and the modal
coordinate of its first vertical bending mode (7); each bogie x, y, z, roll,
pitch, yaw (12); each wheelset x, y, z, roll, spin perturbation, yaw (24);
each rail mass z (8).

Equations: M q'' + D q' + K q + sum_e k_e(w) J_e^T J_e q = sum_j B_j u_j,
with u_j = (V, Y, C, G) the four track channels (see ``track.py``) under
wheelset j, k_e(w) the dynamic stiffness of element e (a Kelvin element
k + i w c, or a Maxwell element i w c k_s / (k_s + i w c)) and J_e its
relative-displacement row. Response: q(w) = Z(w)^-1 sum_j B_j u_j(w) with
Z(w) = -w^2 M + i w D + K + sum_e k_e(w) J_e^T J_e.

Differences from suspid's built-in ``exudyn-train`` model
---------------------------------------------------------
1. **Yaw dampers are Maxwell elements**: c_yaw in series with k_yaw_series
   (10 MN/m), not pure dashpots.
2. **Free longitudinal motion**: carbody, bogies and wheelsets move
   longitudinally; the carbody is held on each bogie by a traction rod
   (k_traction, c_traction at height h_traction) besides the secondary
   longitudinal springs; the wheelsets by the primary longitudinal springs
   and their longitudinal creep. No spring to ground. The whole car has a
   free longitudinal rigid mode (a zero eigenvalue): the zero-frequency line
   is not computed (records have zero mean).
3. **Wheelset spin perturbation** is a degree of freedom (inertia I_ws_y)
   entering the longitudinal creepages; gyroscopic couplings of the
   spinning wheelset (I_ws_y v / r0) between its roll and yaw.
4. **Flexible carbody**: first vertical bending mode (f_bend 9.5 Hz,
   zeta_bend 0.02) of a uniform free-free beam of length ``car_length``,
   mode shape normalised to 1 at mid-car; modal mass m_car x mean(phi^2);
   driven through the mode shape at every secondary vertical attachment;
   carbody vertical sensors read phi(x_s) q'' in addition.
5. **Secondary dampers with series bushes**: the vertical damper c_sec_z is
   in series with k_bush_sec_z (2 MN/m) and the lateral damper c_sec_y with
   k_bush_sec_y (4 MN/m): linear equivalent of rubber end-mounts (Maxwell
   elements; no blow-off, no bilinear law: the model stays linear).
6. **Own creep model**: linear Kalker coefficients per wheel with f11 != f22:
   f11 = 9.9 MN, f22 = 8.75 MN at 54.5 kN wheel load (Kalker's theory for a
   300 mm rail crown), scaled by (N / 54.5 kN)^(2/3) and by creep_factor
   (0.75, an in-service reduction); spin-lateral coupling f23 = f23_length x
   f22; per-wheel rolling radii r0 +/- lambda (y - y_rail) with each rail's
   own lateral position (so the gauge lowers the wheelset by lambda G / 2),
   lateral creepage (y' + r0 roll') / v - yaw: the contact point of a rolling
   wheelset slides sideways, so cross-level excites the bogie's lateral
   motion (about +10 dB in the bogie lateral spectra at 5-20 Hz compared with
   roll_creep = 0, which drops the term).
7. **Normal-force geometry**: lateral force -W roll_ws - lambda (N_L - N_R)
   on the wheelset (W axle load) instead of a gravitational stiffness on
   y - Y; the roll moment of the static loads about the shifted wheelset
   (-W (y - Y)); geometric stiffness of the static suspension preloads on
   the roll and pitch of every body (vertical preload F at a point r:
   K_roll += F r_z, K_pitch += F r_z, on both bodies with opposite F).
8. **Elastic track**: a rail mass m_track under each wheel on a pad/ballast
   spring k_track and damper c_track (P2 resonance near 55 Hz); the wheel on
   it through a linear Hertz spring k_hertz; the irregularity is the rail
   top's geometric deviation in that spring.
9. **Measurement process** (:class:`Instrument`): sensors at the same places
   as suspid's default channels; lateral accelerometers tilt with the body
   (a_y + g roll); a per-channel calibration gain fixed for the instrumented
   train (same on every date), a per-channel per-segment gain, white sensor
   noise (one-sided PSD ``noise_asd``^2) before a 4th-order Butterworth
   anti-alias low-pass (0.4 fs), the response computed at 4 fs then sampled
   at fs. Vertical channels have gravity's 1 g removed (a static offset).
10. **Measured track** (:mod:`.track`): the recording car samples every
   0.25 m with noise, an odometry offset and a long-wavelength high-pass;
   the true track under the train is another, finer, periodic signal.

Not modelled (the same as suspid, or left out on purpose): creep saturation,
flange contact and bump stops, air-spring pneumatics, carbody torsion, wheel
out-of-roundness, sleeper passing, lateral track flexibility, couplers to
neighbouring cars, curves and speed changes.

Modes at 300 km/h with the nominal values (:func:`eigenvalues`; all damped,
every corner of suspid's identification box stable from 30 to 90 m/s):
carbody lateral 0.61 Hz (zeta 0.13), bounce 1.09, yaw 1.11, roll 1.19,
pitch 1.32 Hz; bogie kinematic modes 6.4 Hz (heavily damped: the Maxwell yaw
dampers tie the bogies' yaw to the carbody); bogie bounce 8.1 Hz; carbody
bending 9.5 Hz (zeta 0.038 with the secondary dampers); carbody longitudinal
on the traction rods with bogie pitch 9.7 Hz; wheelset longitudinal/spin
18 Hz; wheelsets on the elastic track (P2) above 50 Hz.

Parameters: suspid's names (:data:`SHARED`) with suspid's meaning, per-element
convention and nominal values (so w0 is comparable), plus this model's own
(:data:`OWN`). Every suspension element is also its own parameter
(:data:`ELEMENTS`: ``c_yaw[bogie1,left]``, ``c_prim_z[ws3,right]``, ...), which
overrides its kind's value. Unknown names raise ``KeyError``.

Files (:func:`generate_date`): ``out_dir/track/<segment>.csv``,
``out_dir/accelerations/<segment>.csv`` in suspid's layout and
``out_dir/truth.json`` (the hidden truth: parameters, gains, chainages).
Time convention (the same as suspid's): t = 0 when the car centre is at the
segment's first distance sample ``distance_m[0]``; the record lasts
length / v, sample m at t = m / fs; wheelset j is a_j ahead of the car centre.
"""

from __future__ import annotations

import json
import math
import os
import tempfile
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np
from scipy import signal
from scipy.fft import next_fast_len

from . import track as T

GRAVITY = 9.81
"""m/s^2."""

SHARED: dict[str, float] = {
    # masses, inertias, heights (the same meaning and nominal values as suspid's exudyn-train)
    "m_car": 32000.0, "I_car_x": 56.8e3, "I_car_y": 1.97e6, "I_car_z": 1.97e6, "h_car": 1.8,
    "m_bogie": 2615.0, "I_bogie_x": 1722.0, "I_bogie_y": 1476.0, "I_bogie_z": 3067.0, "h_bogie": 0.6,
    "m_ws": 1813.0, "I_ws_x": 1120.0, "I_ws_y": 112.0, "I_ws_z": 1120.0, "r0": 0.46,
    # geometry, half distances
    "a_bogie": 9.5, "a_ws": 1.28, "b_prim": 1.0, "b_sec": 1.0, "l0": 0.75, "h_sec": 1.0,
    "b_yaw": 1.35, "h_yaw": 0.65,
    # primary suspension, per axlebox
    "k_prim_x": 14.68e6, "k_prim_y": 3.884e6, "k_prim_z": 1.22e6, "c_prim_z": 4e3,
    # secondary suspension, per side; yaw damper per damper (one per side of each bogie)
    "k_sec_x": 160e3, "k_sec_y": 160e3, "k_sec_z": 430e3, "c_sec_z": 20e3, "c_sec_y": 16e3,
    "c_yaw": 800e3, "k_arb": 940e3,
    # contact
    "conicity": 0.25,
}
"""Parameters with suspid's names: N/m, N s/m, kg, kg m^2, m, N m/rad (per axlebox / per side /
per damper as in suspid). ``c_yaw`` here is the damper of a Maxwell element."""

OWN: dict[str, float] = {
    "k_yaw_series": 10e6,        # N/m, yaw damper series stiffness (Math. Probl. Eng. 2019, art. 7163732: 10 MN/m)
    "k_bush_sec_z": 2.0e6,       # N/m, series bush of the secondary vertical damper (assumption)
    "k_bush_sec_y": 4.0e6,       # N/m, series bush of the secondary lateral damper (assumption)
    "k_traction": 5.0e6,         # N/m, traction rod per bogie (assumption)
    "c_traction": 20e3,          # N s/m, traction rod bush damping (assumption)
    "h_traction": 0.5,           # m above rail (assumption)
    "f_bend": 9.5,               # Hz, carbody first vertical bending (EMU carbodies 7-12 Hz)
    "zeta_bend": 0.02,
    "car_length": 26.0,          # m, carbody length for the beam mode shape
    "f11_ref": 9.9e6,            # N, Kalker f11 at 54.5 kN, 300 mm rail crown (published: 9.4-10.4 MN)
    "f22_ref": 8.75e6,           # N, Kalker f22 at 54.5 kN, 300 mm rail crown (published: 8.3-9.2 MN)
    "creep_load_ref": 54.5e3,    # N
    "creep_factor": 0.75,        # in-service reduction of Kalker's coefficients (assumption)
    "f23_length": 0.0025,        # m, f23 = f23_length f22 (spin-lateral, order sqrt(ab) C23/C22)
    "roll_creep": 1.0,           # 1: the roll rate's term r0 roll' / v in the lateral creepage; 0: without
    "k_hertz": 1.2e9,            # N/m per wheel, linearised Hertz (assumption)
    "m_track": 250.0,            # kg per wheel, rail and sleeper share (assumption)
    "k_track": 120e6,            # N/m per wheel, pad and ballast in series (assumption)
    "c_track": 200e3,            # N s/m per wheel (assumption; P2 well damped)
}
"""This model's own parameters (SI)."""

CHANNELS = ("carbody_front_vertical", "carbody_front_lateral", "carbody_middle_vertical",
            "carbody_middle_lateral", "carbody_rear_vertical", "carbody_rear_lateral",
            "bogie_front_vertical", "bogie_front_lateral", "bogie_rear_vertical", "bogie_rear_lateral")
"""Output channels: suspid exudyn-train's default channel names and order."""

FLOOR_HEIGHT = 1.2
"""Carbody sensors' height above rail, m (the same places as suspid's default sensors)."""

N_DOF = 51
CAR = 0                       # carbody: x y z roll pitch yaw, modal coordinate at 6
BOGIE = (7, 13)               # bogies: x y z roll pitch yaw
WHEELSET = (19, 25, 31, 37)   # wheelsets: x y z roll spin yaw
RAIL = 43                     # rail masses: 43 + 2 j + (0 left, 1 right)
X, Y, Z, ROLL, PITCH, YAW = range(6)
SPIN = 4                      # wheelset slot 4 is the spin perturbation, not a pitch


PER_SIDE = ("k_sec_x", "k_sec_y", "c_sec_y", "k_sec_z", "c_sec_z", "c_yaw")
"""Kinds with one element per side of each bogie, named ``kind[bogieN,side]`` (bogie1 the front one; left is
+y)."""
PER_AXLEBOX = ("k_prim_x", "k_prim_y", "k_prim_z", "c_prim_z")
"""Kinds with one element per axlebox, named ``kind[wsN,side]`` (ws1 the leading wheelset; ws1, ws2 in bogie1)."""
ELEMENTS: dict[str, tuple[str, ...]] = {
    **{k: tuple(f"{k}[bogie{b},{s}]" for b in (1, 2) for s in ("left", "right")) for k in PER_SIDE},
    **{k: tuple(f"{k}[ws{j},{s}]" for j in (1, 2, 3, 4) for s in ("left", "right")) for k in PER_AXLEBOX}}
"""Kind -> its elements' names. A kind name in ``w`` sets every element of the kind; an element name that
element only (applied after the kinds)."""


def parameters(w: Mapping[str, float] | None = None) -> dict[str, float]:
    """Nominal values of every parameter, updated with ``w`` (unknown names raise KeyError).

    Element names (:data:`ELEMENTS`) are kept as their own keys; :func:`element` reads them."""
    p = dict(SHARED) | dict(OWN)
    known = {e for names in ELEMENTS.values() for e in names}
    for k, v in (w or {}).items():
        if k not in p and k not in known:
            raise KeyError(f"unknown parameter '{k}'; known: {', '.join(sorted(p))}, and elements as "
                           f"'c_yaw[bogie1,left]', 'c_prim_z[ws3,right]'")
    for k, v in (w or {}).items():
        if "[" not in k:
            p[k] = float(v)
    for k, v in (w or {}).items():
        if "[" in k:
            p[k] = float(v)
    return p


def element(p: Mapping[str, float], kind: str, *tags: str) -> float:
    """The value of the element of ``kind`` at ``tags`` (e.g. ``"bogie1", "left"``): its own, else the kind's."""
    return float(p.get(f"{kind}[{','.join(tags)}]", p[kind]))


def static_loads(p: Mapping[str, float]) -> dict[str, float]:
    """Static forces, N: per secondary side, per axlebox, per wheel, per axle."""
    sec = p["m_car"] * GRAVITY / 4.0
    box = sec / 2.0 + p["m_bogie"] * GRAVITY / 4.0
    wheel = box + p["m_ws"] * GRAVITY / 2.0
    return {"secondary": sec, "axlebox": box, "wheel": wheel, "axle": 2.0 * wheel}


def creep_coefficients(p: Mapping[str, float]) -> tuple[float, float, float]:
    """(f11, f22, f23) per wheel: N, N, N m (scaled with the static wheel load^(2/3))."""
    s = (static_loads(p)["wheel"] / p["creep_load_ref"]) ** (2.0 / 3.0) * p["creep_factor"]
    f22 = p["f22_ref"] * s
    return p["f11_ref"] * s, f22, p["f23_length"] * f22


def wheelset_positions(p: Mapping[str, float]) -> np.ndarray:
    """``(4,)`` m, longitudinal positions of wheelsets 1-4 ahead of the car centre."""
    a, b = p["a_bogie"], p["a_ws"]
    return np.array([a + b, a - b, -a + b, -a - b])


def bending_shape(x: np.ndarray | float, length: float) -> np.ndarray:
    """First free-free bending mode of a uniform beam of ``length`` m centred on x = 0, 1 at x = 0."""
    bl = 4.730040745
    s = (np.asarray(x, dtype=float) / length + 0.5) * bl
    sig = (math.cosh(bl) - math.cos(bl)) / (math.sinh(bl) - math.sin(bl))
    phi = np.cosh(s) + np.cos(s) - sig * (np.sinh(s) + np.sin(s))
    mid = 0.5 * bl
    phi0 = math.cosh(mid) + math.cos(mid) - sig * (math.sinh(mid) + math.sin(mid))
    return phi / phi0


def maxwell_stiffness(omega: np.ndarray, k_series: float, c: float) -> np.ndarray:
    """Dynamic stiffness (force / elongation) of a damper c in series with a spring k_series.

    F / x = i w c k_s / (k_s + i w c): a dashpot at low frequency, the spring at high.
    :param omega: ``(n,)`` rad/s. :returns: ``(n,)`` complex N/m.
    """
    iwc = 1j * np.asarray(omega, dtype=float) * c
    if c == 0.0:
        return np.zeros_like(iwc)
    return iwc * k_series / (k_series + iwc)


# ------------------------------------------------------------------------------------------- assembly
def _point_row(body: str, r: Sequence[float], direction: int, p: Mapping[str, float]) -> np.ndarray:
    """``(N_DOF,)`` row: displacement along ``direction`` (0 x, 1 y, 2 z) of point ``r`` (relative to
    the body's centre of mass, m) of ``body`` ('car', 'bogie0', 'bogie1', 'ws0'..'ws3', 'rail<j><s>')."""
    row = np.zeros(N_DOF)
    rx, ry, rz = r
    if body.startswith("rail"):
        if direction == 2:
            row[RAIL + int(body[4:])] = 1.0
        return row
    if body == "car":
        b = CAR
    elif body.startswith("bogie"):
        b = BOGIE[int(body[5:])]
    else:
        b = WHEELSET[int(body[2:])]
    is_ws = body.startswith("ws")
    pitch = 0.0 if is_ws else 1.0      # axleboxes do not turn with the wheel's spin
    row[b + direction] = 1.0
    if direction == 0:
        row[b + PITCH] += pitch * rz
        row[b + YAW] += -ry
    elif direction == 1:
        row[b + YAW] += rx
        row[b + ROLL] += -rz
    else:
        row[b + ROLL] += ry
        row[b + PITCH] += -pitch * rx
        if body == "car":
            row[CAR + 6] = float(bending_shape(rx, p["car_length"]))
    return row


@dataclass
class Element:
    """A linear element between two points: elongation J q; Kelvin (k + i w c) or Maxwell (c, k_s)."""

    name: str
    row: np.ndarray
    kind: str              # "kelvin" | "maxwell"
    k: float
    c: float

    def stiffness(self, omega: np.ndarray) -> np.ndarray:
        if self.kind == "kelvin":
            return self.k + 1j * omega * self.c
        return maxwell_stiffness(omega, self.k, self.c)


@dataclass
class Model:
    """Matrices of the linear car at one speed (see the module docstring).

    :ivar M, D, K: ``(N_DOF, N_DOF)``: mass, speed-dependent damping (creep,
        gyroscopic, modal, track) and stiffness not held in ``elements``.
    :ivar B: ``(4, N_DOF, 4)``: generalised force of wheelset j's track
        inputs (V, Y, C, G), stiffness-type.
    :ivar elements: suspension elements.
    :ivar S_acc, S_tilt: ``(n_channels, N_DOF)``: channel = S_acc q'' + S_tilt q.
    """

    M: np.ndarray
    D: np.ndarray
    K: np.ndarray
    B: np.ndarray
    elements: list[Element]
    S_acc: np.ndarray
    S_tilt: np.ndarray

    def dynamic_stiffness(self, omega: np.ndarray) -> np.ndarray:
        """``(n, N_DOF, N_DOF)`` complex Z(w) for ``omega`` ``(n,)`` rad/s."""
        w = np.asarray(omega, dtype=float)[:, None, None]
        J = np.array([e.row for e in self.elements])                         # (n_e, N)
        outer = np.einsum("en,em->enm", J, J).reshape(len(J), -1)              # (n_e, N*N)
        k = np.stack([e.stiffness(w[:, 0, 0]) for e in self.elements], axis=1)  # (n, n_e)
        Z = (k @ outer).reshape(-1, N_DOF, N_DOF)
        return Z + (-w ** 2 * self.M + 1j * w * self.D + self.K)

    def displacements(self, omega: np.ndarray, chunk: int = 256) -> np.ndarray:
        """``(n, 4, N_DOF, 4)`` q per unit input: [frequency, wheelset, dof, track channel]."""
        omega = np.asarray(omega, dtype=float)
        rhs = np.concatenate(list(self.B), axis=1)                      # (N, 16)
        out = np.empty((omega.size, N_DOF, 16), dtype=complex)
        for i in range(0, omega.size, chunk):
            out[i:i + chunk] = np.linalg.solve(self.dynamic_stiffness(omega[i:i + chunk]), rhs)
        return out.reshape(omega.size, N_DOF, 4, 4).transpose(0, 2, 1, 3)

    def sensor_response(self, omega: np.ndarray) -> np.ndarray:
        """``(n, n_channels, 4, 4)`` m/s^2 per m: [frequency, channel, wheelset, track channel]."""
        omega = np.asarray(omega, dtype=float)
        q = self.displacements(omega)
        S = -omega[:, None, None] ** 2 * self.S_acc[None] + self.S_tilt[None]   # (n, ch, N)
        return np.einsum("fcn,fjnk->fcjk", S, q)


class _Lin:
    """A linear quantity kq . q + dq . q' + ku . u (u = the wheelset's four track channels)."""

    def __init__(self, kq=None, dq=None, ku=None):
        self.kq = np.zeros(N_DOF) if kq is None else kq
        self.dq = np.zeros(N_DOF) if dq is None else dq
        self.ku = np.zeros(4) if ku is None else ku

    def __add__(self, o: "_Lin") -> "_Lin":
        return _Lin(self.kq + o.kq, self.dq + o.dq, self.ku + o.ku)

    def __sub__(self, o: "_Lin") -> "_Lin":
        return _Lin(self.kq - o.kq, self.dq - o.dq, self.ku - o.ku)

    def __mul__(self, s: float) -> "_Lin":
        return _Lin(self.kq * s, self.dq * s, self.ku * s)

    __rmul__ = __mul__


def _q(i: int, s: float = 1.0) -> _Lin:
    v = _Lin()
    v.kq[i] = s
    return v


def _qd(i: int, s: float = 1.0) -> _Lin:
    v = _Lin()
    v.dq[i] = s
    return v


def _u(c: int, s: float = 1.0) -> _Lin:
    v = _Lin()
    v.ku[c] = s
    return v


def _add_preload(K: np.ndarray, base: int, force: float, r: Sequence[float], has_pitch: bool = True) -> None:
    """Geometric stiffness of a constant vertical force ``force`` (N, up) at point ``r`` of a body."""
    rx, ry, rz = r
    K[base + ROLL, base + ROLL] += force * rz
    K[base + ROLL, base + YAW] += -force * rx
    if has_pitch:
        K[base + PITCH, base + PITCH] += force * rz
        K[base + PITCH, base + YAW] += -force * ry


def build_model(w: Mapping[str, float] | None, speed: float, flexible: bool = True,
                creep_scale: float = 1.0) -> Model:
    """Assemble the car at ``speed`` m/s with parameters ``w`` (suspid and own names, SI).

    :param flexible: False freezes the bending mode (rigid carbody; for checks).
    :param creep_scale: factor on the creep coefficients (for checks).
    """
    p = parameters(w)
    v = float(speed)
    M = np.zeros((N_DOF, N_DOF))
    D = np.zeros((N_DOF, N_DOF))
    K = np.zeros((N_DOF, N_DOF))
    B = np.zeros((4, N_DOF, 4))
    els: list[Element] = []
    loads = static_loads(p)
    # --- masses
    M[np.arange(6), np.arange(6)] = [p["m_car"]] * 3 + [p["I_car_x"], p["I_car_y"], p["I_car_z"]]
    L = p["car_length"]
    xs = np.linspace(-L / 2, L / 2, 2001)
    m_modal = p["m_car"] * float(np.trapezoid(bending_shape(xs, L) ** 2, xs) / L)
    wb = 2 * math.pi * p["f_bend"]
    M[6, 6] = m_modal
    K[6, 6] = m_modal * wb ** 2 if flexible else 1e6 * m_modal * wb ** 2
    D[6, 6] = 2 * p["zeta_bend"] * m_modal * wb
    for b in BOGIE:
        M[b + np.arange(6), b + np.arange(6)] = [p["m_bogie"]] * 3 + [p["I_bogie_x"], p["I_bogie_y"],
                                                                       p["I_bogie_z"]]
    for b in WHEELSET:
        M[b + np.arange(6), b + np.arange(6)] = [p["m_ws"]] * 3 + [p["I_ws_x"], p["I_ws_y"], p["I_ws_z"]]
    for i in range(8):
        M[RAIL + i, RAIL + i] = p["m_track"]
        K[RAIL + i, RAIL + i] += p["k_track"]
        D[RAIL + i, RAIL + i] += p["c_track"]

    def link(name, body_a, ra, body_b, rb, direction, kind, k, c):
        row = _point_row(body_a, ra, direction, p) - _point_row(body_b, rb, direction, p)
        els.append(Element(name, row, kind, k, c))

    # --- secondary suspension and yaw dampers, per bogie and side
    hc, hb = p["h_car"], p["h_bogie"]
    for ib, xb in enumerate((p["a_bogie"], -p["a_bogie"])):
        bog = f"bogie{ib}"
        for side in (1.0, -1.0):
            e = lambda kind: element(p, kind, f"bogie{ib + 1}", "left" if side > 0 else "right")  # noqa: E731,B023
            rc = (xb, side * p["b_sec"], p["h_sec"] - hc)
            rbg = (0.0, side * p["b_sec"], p["h_sec"] - hb)
            link("sec_x", "car", rc, bog, rbg, 0, "kelvin", e("k_sec_x"), 0.0)
            link("sec_y", "car", rc, bog, rbg, 1, "kelvin", e("k_sec_y"), 0.0)
            link("sec_y_damper", "car", rc, bog, rbg, 1, "maxwell", p["k_bush_sec_y"], e("c_sec_y"))
            link("sec_z", "car", rc, bog, rbg, 2, "kelvin", e("k_sec_z"), 0.0)
            link("sec_z_damper", "car", rc, bog, rbg, 2, "maxwell", p["k_bush_sec_z"], e("c_sec_z"))
            _add_preload(K, CAR, loads["secondary"], rc)
            _add_preload(K, BOGIE[ib], -loads["secondary"], rbg)
            ry = (xb, side * p["b_yaw"], p["h_yaw"] - hc)
            ryb = (0.0, side * p["b_yaw"], p["h_yaw"] - hb)
            link("yaw_damper", "car", ry, bog, ryb, 0, "maxwell", p["k_yaw_series"], e("c_yaw"))
        link("traction_rod", "car", (xb, 0.0, p["h_traction"] - hc), bog, (0.0, 0.0, p["h_traction"] - hb),
             0, "kelvin", p["k_traction"], p["c_traction"])
        row = np.zeros(N_DOF)
        row[CAR + ROLL], row[BOGIE[ib] + ROLL] = 1.0, -1.0
        els.append(Element("anti_roll_bar", row, "kelvin", p["k_arb"], 0.0))
    # --- primary suspension, per axlebox
    xw = wheelset_positions(p)
    for j in range(4):
        ib = j // 2
        xrel = xw[j] - (p["a_bogie"] if ib == 0 else -p["a_bogie"])
        for side in (1.0, -1.0):
            rbg = (xrel, side * p["b_prim"], p["r0"] - hb)
            rw = (0.0, side * p["b_prim"], 0.0)
            e = lambda kind: element(p, kind, f"ws{j + 1}", "left" if side > 0 else "right")  # noqa: E731,B023
            for d, k, c in ((0, e("k_prim_x"), 0.0), (1, e("k_prim_y"), 0.0), (2, e("k_prim_z"), e("c_prim_z"))):
                link(f"prim_{'xyz'[d]}", f"bogie{ib}", rbg, f"ws{j}", rw, d, "kelvin", k, c)
            _add_preload(K, BOGIE[ib], loads["axlebox"], rbg)
    # --- wheel-rail contact
    f11, f22, f23 = (c * creep_scale for c in creep_coefficients(p))
    lam, l0, r0, kh = p["conicity"], p["l0"], p["r0"], p["k_hertz"]
    W = loads["axle"]
    spin_rate = v / r0
    for j, b in enumerate(WHEELSET):
        u = _q(b + Y) - _u(1)                                          # y - Y
        xi_y = (_qd(b + Y) + _qd(b + ROLL, r0 * p["roll_creep"])) * (1.0 / v) - _q(b + YAW)
        spin = _qd(b + YAW, 1.0 / v)
        Fx, Fy, Mz, N = {}, {}, {}, {}
        for s in (1.0, -1.0):
            dr = u * (s * lam) - _u(3, lam / 2.0)                       # r_w - r0
            rail = RAIL + 2 * j + (0 if s > 0 else 1)
            delta = _q(rail) + _u(0) + _u(2, s / 2.0) - _q(b + Z) - _q(b + ROLL, s * l0) + dr
            N[s] = delta * kh
            xi_x = (_qd(b + X) - _qd(b + YAW, s * l0) - _qd(b + SPIN, r0)) * (1.0 / v) - dr * (1.0 / r0)
            Fx[s] = xi_x * (-f11)
            Fy[s] = xi_y * (-f22) - spin * f23
            Mz[s] = xi_y * f23
        Fy_normal = _q(b + ROLL, -W) - (N[1.0] - N[-1.0]) * lam
        Fy_tot = Fy[1.0] + Fy[-1.0] + Fy_normal
        gen = {
            b + X: Fx[1.0] + Fx[-1.0],
            b + Y: Fy_tot,
            b + Z: N[1.0] + N[-1.0],
            b + ROLL: (N[1.0] - N[-1.0]) * l0 + Fy_tot * r0 - u * W,
            b + SPIN: (Fx[1.0] + Fx[-1.0]) * (-r0),
            b + YAW: (Fx[-1.0] - Fx[1.0]) * l0 + Mz[1.0] + Mz[-1.0],
            RAIL + 2 * j: N[1.0] * -1.0,
            RAIL + 2 * j + 1: N[-1.0] * -1.0,
        }
        for dof, lin in gen.items():
            K[dof] -= lin.kq
            D[dof] -= lin.dq
            B[j, dof] += lin.ku
        D[b + ROLL, b + YAW] += -p["I_ws_y"] * spin_rate        # gyroscopic
        D[b + YAW, b + ROLL] += p["I_ws_y"] * spin_rate
    # --- sensors
    a = p["a_bogie"]
    S_acc = np.zeros((len(CHANNELS), N_DOF))
    S_tilt = np.zeros((len(CHANNELS), N_DOF))
    zc = FLOOR_HEIGHT - hc
    i = 0
    for x in (a, 0.0, -a):
        S_acc[i] = _point_row("car", (x, 0.0, zc), 2, p)
        S_acc[i + 1] = _point_row("car", (x, 0.0, zc), 1, p)
        S_tilt[i + 1, CAR + ROLL] = GRAVITY
        i += 2
    for ib in range(2):
        S_acc[i] = _point_row(f"bogie{ib}", (0.0, 0.0, 0.0), 2, p)
        S_acc[i + 1] = _point_row(f"bogie{ib}", (0.0, 0.0, 0.0), 1, p)
        S_tilt[i + 1, BOGIE[ib] + ROLL] = GRAVITY
        i += 2
    return Model(M, D, K, B, els, S_acc, S_tilt)


def eigenvalues(model: Model, clamp: Sequence[int] = ()) -> np.ndarray:
    """Eigenvalues (1/s) of the free system, Maxwell elements as first-order force states.

    :param clamp: DOF indices held at zero. Zero eigenvalues (the free
        longitudinal rigid mode) are included; sort/filter them yourself.
    """
    keep = np.setdiff1d(np.arange(N_DOF), np.asarray(clamp, dtype=int))
    n = keep.size
    Kt = model.K.copy()
    Dt = model.D.copy()
    maxw = []
    for e in model.elements:
        if e.kind == "kelvin":
            Kt += e.k * np.outer(e.row, e.row)
            Dt += e.c * np.outer(e.row, e.row)
        elif e.c > 0:
            maxw.append(e)
    Mi = np.linalg.inv(model.M[np.ix_(keep, keep)])
    m = len(maxw)
    A = np.zeros((2 * n + m, 2 * n + m))
    A[:n, n:2 * n] = np.eye(n)
    A[n:2 * n, :n] = -Mi @ Kt[np.ix_(keep, keep)]
    A[n:2 * n, n:2 * n] = -Mi @ Dt[np.ix_(keep, keep)]
    for i, e in enumerate(maxw):
        J = e.row[keep]
        A[n:2 * n, 2 * n + i] = -Mi @ J
        A[2 * n + i, n:2 * n] = e.k * J
        A[2 * n + i, 2 * n + i] = -e.k / e.c
    return np.linalg.eigvals(A)


# ------------------------------------------------------------------------------- measurement process
@dataclass(frozen=True)
class Instrument:
    """The measurement chain of the instrumented train.

    :ivar fs_hz: output sampling rate, Hz.
    :ivar oversampling: the response is computed at oversampling x fs, then
        anti-alias filtered and sampled.
    :ivar noise_asd: sensor noise amplitude spectral density, m/s^2/sqrt(Hz), white.
    :ivar antialias_order, antialias_ratio: Butterworth low-pass order (0: an
        ideal sampler, for checks) and cut-off as a fraction of fs.
    :ivar calibration_std: std of the per-channel calibration gain (fixed per train).
    :ivar segment_gain_std: std of the per-channel, per-segment gain.
    """

    fs_hz: float = 100.0
    oversampling: int = 4
    noise_asd: float = 1e-4
    antialias_order: int = 4
    antialias_ratio: float = 0.4
    calibration_std: float = 0.03
    segment_gain_std: float = 0.01

    def antialias(self, f: np.ndarray) -> np.ndarray:
        """Complex response ``(n,)`` of the analog anti-alias filter at ``f`` ``(n,)`` Hz (order 0: none)."""
        if self.antialias_order == 0:
            return np.ones(np.shape(f), dtype=complex)
        b, a = signal.butter(self.antialias_order, 2 * math.pi * self.antialias_ratio * self.fs_hz,
                             analog=True)
        return signal.freqs(b, a, worN=2 * math.pi * np.asarray(f, dtype=float))[1]

    def calibration(self, instrument_seed: int) -> np.ndarray:
        """``(n_channels,)`` calibration gains of the instrumented train ``instrument_seed``."""
        rng = np.random.default_rng([int(instrument_seed), 4])
        return 1.0 + self.calibration_std * rng.standard_normal(len(CHANNELS))


@dataclass
class SegmentRecord:
    """One segment as measured: track (recording car) and accelerations.

    :ivar distance: ``(n_x,)`` m chainage of the recorded track samples.
    :ivar track: ``(4, n_x)`` m measured track (rows: vertical, lateral, cross_level, gauge).
    :ivar accelerations: ``(n_channels, n_t)`` m/s^2 at ``fs`` Hz.
    """

    name: str
    speed: float
    distance: np.ndarray
    track: np.ndarray
    fs: float
    accelerations: np.ndarray
    segment_gain: np.ndarray = field(default_factory=lambda: np.ones(len(CHANNELS)))


PAD_M = 300.0
"""Track before and after each segment (m) in the periodic realisation the train runs on."""


def simulate_segments(w: Mapping[str, float] | None, *, seed: int, n_segments: int, speed_mps: float,
                      length_m: float = 1000.0, instrument: Instrument = Instrument(),
                      instrument_seed: int = 0, recording: T.RecordingCar = T.RecordingCar(),
                      track_scale: float = 1.0, chainage_m: float = 10_000.0,
                      names: Sequence[str] | None = None) -> list[SegmentRecord]:
    """Run the car at parameters ``w`` over ``n_segments`` independent track segments.

    :param seed: every draw (track, recording car, noise, segment gains) derives from it.
    :param instrument_seed: the instrumented train (its calibration gains).
    :param track_scale: factor on the true track (0: a perfect track, noise only).
    :param chainage_m: chainage of the first segment; segments follow every length_m + 500 m.
    """
    v = float(speed_mps)
    fs_int = instrument.fs_hz * instrument.oversampling
    dx = v / fs_int
    i0 = int(round(PAD_M / dx))
    n_ext = next_fast_len(int(math.ceil((length_m + 2 * PAD_M) / dx)), real=True)
    n_out = max(2, int(round(length_m / v * instrument.fs_hz)))
    f = np.fft.rfftfreq(n_ext, d=1.0 / fs_int)                                 # Hz
    model = build_model(w, v)
    H = np.zeros((f.size, len(CHANNELS), 4, 4), dtype=complex)
    H[1:] = model.sensor_response(2 * math.pi * f[1:])
    delays = np.exp(2j * math.pi * f[:, None] * wheelset_positions(parameters(w))[None, :] / v)  # (n_f, 4)
    Hd = np.einsum("fcjk,fj->fck", H, delays)                                   # (n_f, ch, 4)
    aa = instrument.antialias(f)
    gains = instrument.calibration(instrument_seed)
    sigma = instrument.noise_asd * math.sqrt(fs_int / 2.0)
    out = []
    for k in range(n_segments):
        rng_track = np.random.default_rng([int(seed), 1, k])
        rng_rec = np.random.default_rng([int(seed), 2, k])
        rng_meas = np.random.default_rng([int(seed), 3, k])
        true = T.true_track(n_ext, dx, rng_track, track_scale)                 # (4, n_ext)
        U = np.fft.rfft(true, axis=1)                                           # (4, n_f)
        A = np.einsum("fck,kf->cf", Hd, U)
        noise = np.fft.rfft(sigma * rng_meas.standard_normal((len(CHANNELS), n_ext)), axis=1)
        a_int = np.fft.irfft((A + noise) * aa[None, :], n_ext, axis=1)
        idx = (i0 + instrument.oversampling * np.arange(n_out)) % n_ext
        seg_gain = 1.0 + instrument.segment_gain_std * rng_meas.standard_normal(len(CHANNELS))
        acc = a_int[:, idx] * (gains * seg_gain)[:, None]
        offsets, measured = T.record(true, dx, i0 * dx, length_m, recording, rng_rec)
        start = chainage_m + k * (length_m + 500.0)
        name = names[k] if names is not None else f"seg-{k + 1:03d}"
        out.append(SegmentRecord(name, v, start + offsets, measured, instrument.fs_hz, acc, seg_gain))
    return out


# --------------------------------------------------------------------------------------------- files
def _write_atomic(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(text)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _track_csv(rec: SegmentRecord) -> str:
    lines = ["# suspid track segment", f"# name: {rec.name}", f"# speed_mps: {rec.speed!r}",
             "distance_m,vertical_m,lateral_m,cross_level_m,gauge_m"]
    table = np.column_stack([rec.distance, rec.track.T])
    lines += [",".join(f"{x:.6f}" if i == 0 else f"{x:.9e}" for i, x in enumerate(row)) for row in table]
    return "\n".join(lines) + "\n"


def _accelerations_csv(rec: SegmentRecord) -> str:
    lines = ["# suspid accelerations", f"# segment: {rec.name}", f"# fs_hz: {rec.fs!r}",
             ",".join(("time_s",) + CHANNELS)]
    t = np.arange(rec.accelerations.shape[1]) / rec.fs
    table = np.column_stack([t, rec.accelerations.T])
    lines += [",".join(f"{x:.6f}" if i == 0 else f"{x:.9e}" for i, x in enumerate(row)) for row in table]
    return "\n".join(lines) + "\n"


def generate_date(out_dir: str | Path, w: Mapping[str, float] | None, *, seed: int, n_segments: int,
                  speed_mps: float, length_m: float = 1000.0, instrument: Instrument = Instrument(),
                  instrument_seed: int = 0, recording: T.RecordingCar = T.RecordingCar(),
                  track_scale: float = 1.0, chainage_m: float = 10_000.0) -> Path:
    """Measure one date: write ``out_dir/track/*.csv``, ``out_dir/accelerations/*.csv`` and
    ``out_dir/truth.json``; returns ``out_dir``.

    Arguments as :func:`simulate_segments`. The same arguments give the same files.
    """
    out = Path(out_dir)
    recs = simulate_segments(w, seed=seed, n_segments=n_segments, speed_mps=speed_mps, length_m=length_m,
                             instrument=instrument, instrument_seed=instrument_seed, recording=recording,
                             track_scale=track_scale, chainage_m=chainage_m)
    for rec in recs:
        _write_atomic(out / "track" / f"{rec.name}.csv", _track_csv(rec))
        _write_atomic(out / "accelerations" / f"{rec.name}.csv", _accelerations_csv(rec))
    truth = {
        "parameters": parameters(w), "given": dict(w or {}), "seed": seed, "speed_mps": speed_mps,
        "length_m": length_m, "instrument": asdict(instrument), "instrument_seed": instrument_seed,
        "recording_car": asdict(recording), "track_scale": track_scale,
        "calibration_gains": dict(zip(CHANNELS, instrument.calibration(instrument_seed).tolist())),
        "segments": [{"name": r.name, "chainage_m": float(r.distance[0]),
                      "segment_gains": dict(zip(CHANNELS, r.segment_gain.tolist()))} for r in recs],
    }
    _write_atomic(out / "truth.json", json.dumps(truth, indent=1, sort_keys=True) + "\n")
    return out


def generate_two_dates(out_dir: str | Path, w0: Mapping[str, float] | None, w_ref: Mapping[str, float], *,
                       seed: int, n_segments: int, speed_mps: float, length_m: float = 1000.0,
                       n_segments_reference: int | None = None,
                       instrument: Instrument = Instrument()) -> tuple[Path, Path]:
    """A reference date at ``w0`` and a measurement date at ``w_ref`` on other track segments.

    Both dates use the same instrumented train (calibration gains from
    ``seed``); tracks, noise and segment gains are independent. Writes
    ``out_dir/reference`` and ``out_dir/measurement`` (each as
    :func:`generate_date`) and returns both paths.
    """
    out = Path(out_dir)
    common = dict(speed_mps=speed_mps, length_m=length_m, instrument=instrument, instrument_seed=seed)
    ref = generate_date(out / "reference", w0, seed=int(seed) * 2 + 1,
                        n_segments=n_segments_reference or n_segments, chainage_m=10_000.0, **common)
    mes = generate_date(out / "measurement", w_ref, seed=int(seed) * 2 + 2, n_segments=n_segments,
                        chainage_m=200_000.0, **common)
    return ref, mes
