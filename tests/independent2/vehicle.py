"""A second independent vehicle model, integrated in the time domain with nonlinear elements.

Written apart from suspid's ``exudyn-train`` and from ``tests/independent``
(numpy, scipy and numba; nothing imported from either): data that neither suspid's
model nor the first independent generator made.

Vehicle
-------
One high-speed car with suspid's ``conventional-hs`` data (the quickstart's
car: masses, inertias and geometry of the AVE S103 / ICE3 Velaro E
intermediate coach after Goicolea, *Simplified mechanical description of
AVE S-103 (ICE3 Velaro E) high speed train*, UPM 2014; lateral and
longitudinal stiffnesses of a CRH380A-class car; lateral damper and Maxwell
yaw damper with its blow-off of the high-speed car of *Mathematical
Problems in Engineering* 2019, article 7163732, Table 2). Axes x forward,
y left, z up; roll about x, pitch about y, yaw about z; SI units.

Degrees of freedom (24): carbody y, z, roll, pitch, yaw and its first
vertical bending mode (free-free uniform beam); each bogie frame y, z, roll,
pitch, yaw; each wheelset y, yaw. Internal states (16): the stroke of every
damper mounted on series bushes (4 yaw, 4 secondary vertical, 4 lateral)
and the orifice flow coordinate of every air spring (4).

Modelling choices that differ from both other models
----------------------------------------------------
1. **Time domain**, fixed-step classical Runge-Kutta (RK4) at 800 Hz,
   compiled with numba (:mod:`.kernel`), from rest with a tapered run-in
   (track amplitude ramped over the first 100 m, then 400 m before the
   recorded segment).
2. **Every element its own parameter** (:data:`ELEMENTS`): each air spring,
   secondary vertical damper, lateral damper and yaw damper per bogie and
   side, each primary spring and damper per axlebox, each anti-roll bar per
   bogie. A kind name (``c_yaw``) sets every element of the kind; an element
   name (``c_yaw[bogie1,left]``) one element; element values override kind
   values.
3. **Nonlinear dampers**: asymmetric piecewise-linear force-velocity curves
   (rebound rate (1 + a) c, compression (1 - a) c) with blow-off (beyond
   the blow-off velocity the rate drops to r c); the yaw, secondary vertical
   and lateral dampers sit on series bushes (the damper stroke is a state:
   F = k_s (delta - x_d), x_d' = v(F), the inverse curve). The yaw damper's
   rate after blow-off (20 kN s/m for 300 kN s/m) is the published one of
   the car of article 7163732; its blow-off force there (3 kN at 0.01 m/s)
   makes this car hunt at 300 km/h (a bogie lateral limit cycle near 4 Hz),
   so 8 kN is assumed. The blow-off force is the relief valve's, fixed: a
   degraded damper (lower c) blows off at a higher velocity.
4. **Air springs with reservoir**: the static stiffness k_sec_z (bag with
   reservoir) in parallel with an extra stiffness ``air_res_ratio`` x k_sec_z
   in series with the orifice's viscous damping, corner frequency
   ``air_orifice_hz`` (the bag-only stiffness is felt above it).
5. **Wheel-rail contact**: rigid in the vertical (the wheelset follows the
   rails: its height and roll are the track's), creep forces of Kalker's
   linear coefficients f11 = f22 (7 MN at 55 kN wheel load, scaled with the
   load to the power 2/3) saturated by the Shen-Hedrick-Elkins law (friction
   0.3), no spin creep; a gravitational stiffness W lambda / l0; the lateral
   component of the normal forces on a cross-levelled track (-W C / (2 l0));
   flange contact as a stiff piecewise-linear spring beyond the flange
   clearance (8 mm plus half the gauge widening).
6. **No longitudinal degrees of freedom**: longitudinal elements (primary
   and secondary longitudinal springs, yaw dampers) act on the yaw of the
   bodies they join.
7. **Carbody bending** at ``f_bend`` (10.5 Hz) with ``zeta_bend`` (1.5 %),
   the exact first free-free beam mode over ``car_length``.
8. Roll preloads: the static loads of the secondary and primary suspensions
   make the destabilising roll stiffness m g (h_cg - h_support) of the
   carbody and of each bogie frame.

Not modelled: longitudinal dynamics and traction rods, wheelset spin,
gyroscopic terms, spin creep, track flexibility, sleeper passing (at 300
km/h above 120 Hz, outside the band), curves, speed changes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping

import numpy as np

from . import kernel as KN

GRAVITY = 9.81
"""m/s^2."""

KINDS: dict[str, float] = {
    # masses and inertias (ICE3 intermediate coach after Goicolea 2014; roll and yaw inertias assumed as
    # suspid's conventional-hs car)
    "m_car": 47800.0, "I_car_x": 85e3, "I_car_y": 1.958e6, "I_car_z": 1.958e6, "h_car": 1.8,
    "m_bogie": 3500.0, "I_bogie_x": 2300.0, "I_bogie_y": 1715.0, "I_bogie_z": 4100.0, "h_bogie": 0.6,
    "m_ws": 1800.0, "I_ws_z": 1120.0, "r0": 0.46,
    # geometry (half distances)
    "a_bogie": 8.6875, "a_ws": 1.25, "b_prim": 1.0, "b_sec": 1.0, "l0": 0.75, "h_sec": 1.0,
    "b_yaw": 1.35, "h_yaw": 0.65,
    # suspension, the value of every element of the kind (per axlebox, per side, per damper)
    "k_prim_x": 14.68e6, "k_prim_y": 6.47e6, "k_prim_z": 1.2e6, "c_prim_z": 10e3,
    "k_sec_x": 160e3, "k_sec_y": 160e3, "k_sec_z": 350e3, "c_sec_z": 20e3, "c_sec_y": 30e3,
    "c_yaw": 300e3, "k_arb": 2.0e6,
    "conicity": 0.15,
}
"""Kind-level nominal values with suspid's names and meanings (the ``conventional-hs`` preset's values)."""

OWN: dict[str, float] = {
    "k_yaw_s": 10e6,          # N/m, yaw damper series stiffness (article 7163732, Table 2)
    "yaw_f_blow": 8e3,        # N, yaw damper blow-off force (assumption: article 7163732 gives 3 kN, with which
                              # this car hunts at 300 km/h at conicity 0.15)
    "yaw_r_blow": 20e3 / 300e3,   # rate after blow-off / rate (20 kN s/m after 300 kN s/m)
    "k_bush_z": 3.0e6,        # N/m, series bushes of a secondary vertical damper (assumption)
    "k_bush_y": 4.0e6,        # N/m, series bushes of a lateral damper (assumption)
    "damper_asym": 0.15,      # rebound (1 + a) c, compression (1 - a) c (assumption)
    "f_blow_z": 3e3,          # N, secondary vertical damper blow-off force (assumption: 0.15 m/s at nominal)
    "f_blow_y": 4.5e3,        # N, lateral damper blow-off force (0.15 m/s at nominal, as a CRH-class damper)
    "f_blow_prim": 3e3,       # N, primary vertical damper blow-off force (assumption: 0.3 m/s at nominal)
    "r_blow": 0.3,            # rate after blow-off / rate, vertical and lateral dampers (assumption)
    "h_lat_damper": 0.8,      # m above rail, lateral dampers (assumption)
    "air_res_ratio": 0.3,     # extra (bag-only) stiffness behind the orifice / k_sec_z (assumption)
    "air_orifice_hz": 3.0,    # Hz, corner of the orifice-reservoir branch (assumption)
    "f_bend": 10.5,           # Hz, carbody first vertical bending (EMU carbodies: 7-12 Hz)
    "zeta_bend": 0.015,
    "car_length": 24.775,     # m, ICE3 intermediate car body length
    "f_creep_ref": 7.0e6,     # N, Kalker f11 = f22 at the reference wheel load (assumption, order of Kalker)
    "creep_load_ref": 55e3,   # N
    "mu": 0.3,                # friction coefficient of the creep saturation
    "flange_gap": 0.008,      # m, flange clearance on each side
    "k_flange": 30e6,         # N/m, lateral rail stiffness at flange contact (assumption)
}
"""This model's own parameters (SI), with their source or "assumption"."""

BOGIES = ("bogie1", "bogie2")
"""Front (leading) and rear bogie."""
SIDES = ("left", "right")
WHEELSETS = ("ws1", "ws2", "ws3", "ws4")
"""Wheelsets from the front; ws1, ws2 in bogie1."""

PER_SIDE = ("k_sec_z", "c_sec_z", "c_sec_y", "c_yaw", "k_sec_y", "k_sec_x")
PER_AXLEBOX = ("k_prim_z", "c_prim_z", "k_prim_y", "k_prim_x")
PER_BOGIE = ("k_arb",)


def _element_names() -> dict[str, tuple[str, ...]]:
    out = {}
    for kind in PER_SIDE:
        out[kind] = tuple(f"{kind}[{b},{s}]" for b in BOGIES for s in SIDES)
    for kind in PER_AXLEBOX:
        out[kind] = tuple(f"{kind}[{j},{s}]" for j in WHEELSETS for s in SIDES)
    for kind in PER_BOGIE:
        out[kind] = tuple(f"{kind}[{b}]" for b in BOGIES)
    return out


ELEMENTS: dict[str, tuple[str, ...]] = _element_names()
"""Kind -> its elements' names, e.g. ``c_yaw`` -> ``c_yaw[bogie1,left]``, ..."""


def parameters(w: Mapping[str, float] | None = None) -> dict[str, float]:
    """Every value (kinds, elements, own), nominal updated with ``w``.

    ``w`` may name kinds (every element of the kind takes the value) and
    elements (that element only; applied after the kinds). Unknown names raise KeyError.
    """
    w = dict(w or {})
    p = dict(KINDS) | dict(OWN)
    known_elements = {e for names in ELEMENTS.values() for e in names}
    for k, v in w.items():
        if k not in p and k not in known_elements:
            raise KeyError(f"unknown parameter '{k}'; kinds: {', '.join(sorted(p))}; elements as "
                           f"'c_yaw[bogie1,left]', 'k_prim_z[ws3,right]', 'k_arb[bogie2]'")
        if k in p:
            p[k] = float(v)
    for kind, names in ELEMENTS.items():
        for e in names:
            p[e] = float(w.get(e, p[kind]))
    return p


# ------------------------------------------------------------------------------------------- geometry
N_DOF = 24
CAR = 0                   # y z roll pitch yaw bend
BOGIE = (6, 11)           # y z roll pitch yaw
WS = (16, 18, 20, 22)     # y yaw
BEND = 5
Y, Z, ROLL, PITCH, YAW = range(5)


def wheelset_x(p: Mapping[str, float]) -> np.ndarray:
    """``(4,)`` m: wheelset positions ahead of the car centre."""
    a, b = p["a_bogie"], p["a_ws"]
    return np.array([a + b, a - b, -a + b, -a - b])


def bending_shape(x: np.ndarray | float, length: float) -> np.ndarray:
    """First free-free mode of a uniform beam of ``length`` m centred on x = 0, 1 at mid-length."""
    bl = 4.730040744862704            # root of cos(bl) cosh(bl) = 1
    sigma = (math.cosh(bl) - math.cos(bl)) / (math.sinh(bl) - math.sin(bl))

    def raw(u):
        u = np.asarray(u, dtype=float) * bl
        return np.cosh(u) + np.cos(u) - sigma * (np.sinh(u) + np.sin(u))

    xi = np.asarray(x, dtype=float) / length + 0.5
    return raw(xi) / raw(0.5)


def _row(body: str, r: tuple[float, float, float], direction: str, p: Mapping[str, float]) -> np.ndarray:
    """``(N_DOF,)``: displacement of point r (relative to the body's centre of mass) in ``direction``."""
    row = np.zeros(N_DOF)
    rx, ry, rz = r
    if body.startswith("ws"):
        i = WS[int(body[2]) - 1]
        if direction == "y":
            row[i] = 1.0
            row[i + 1] = rx
        elif direction == "x":
            row[i + 1] = -ry
        return row                         # vertical: prescribed by the track
    i = CAR if body == "car" else BOGIE[int(body[-1]) - 1]
    if direction == "x":
        row[i + YAW] = -ry                 # no longitudinal freedom: yaw only
    elif direction == "y":
        row[i + Y], row[i + YAW], row[i + ROLL] = 1.0, rx, -rz
    elif direction == "z":
        row[i + Z], row[i + ROLL], row[i + PITCH] = 1.0, ry, -rx
        if body == "car":
            row[BEND] = float(bending_shape(rx, p["car_length"]))
    elif direction == "roll":
        row[i + ROLL] = 1.0
    return row


@dataclass
class Model:
    """Matrices and element tables of the car at speed ``v`` (see the module docstring).

    Arrays: ``mass`` ``(N_DOF,)`` (diagonal), ``K``, ``C`` ``(N_DOF, N_DOF)`` linear parts;
    Maxwell dampers: ``J_m`` ``(12, N_DOF)``, ``k_m``, ``c_m``, ``asym_m``, ``vbo_m``, ``r_m`` ``(12,)``;
    air-spring orifice branches ``J_a`` ``(4, N_DOF)``, ``k_a``, ``c_a`` ``(4,)``; primary vertical dampers
    ``J_p`` ``(8, N_DOF)``, ``c_p``, ``vbo_p`` ``(8,)``, primary vertical springs ``k_pz`` ``(8,)``, with the track's
    displacement under each one ``V_j + side b_prim C_j / (2 l0)`` (``ws_p``, ``side_p`` ``(8,)``);
    sensors ``S`` ``(10, N_DOF)`` on accelerations and ``S_g`` ``(10, N_DOF)`` on displacements (g roll).
    """

    p: dict
    v: float
    mass: np.ndarray
    K: np.ndarray
    C: np.ndarray
    J_m: np.ndarray
    k_m: np.ndarray
    c_m: np.ndarray
    asym_m: np.ndarray
    vbo_m: np.ndarray
    r_m: np.ndarray
    J_a: np.ndarray
    k_a: np.ndarray
    c_a: np.ndarray
    J_p: np.ndarray
    k_pz: np.ndarray
    c_p: np.ndarray
    vbo_p: np.ndarray
    ws_p: np.ndarray
    side_p: np.ndarray
    S: np.ndarray
    S_g: np.ndarray
    f_creep: float
    wheel_load: float
    x_ws: np.ndarray

    @property
    def n_internal(self) -> int:
        return self.J_m.shape[0] + self.J_a.shape[0]


CHANNELS = ("carbody_front_vertical", "carbody_front_lateral", "carbody_middle_vertical",
            "carbody_middle_lateral", "carbody_rear_vertical", "carbody_rear_lateral",
            "bogie_front_vertical", "bogie_front_lateral", "bogie_rear_vertical", "bogie_rear_lateral")
"""The channels suspid's exudyn-train writes by default (names and order): carbody floor (1.2 m above rail)
above each bogie and mid-car, bogie frames at their centre."""
FLOOR = 1.2


def build(w: Mapping[str, float] | None, speed: float, flexible: bool = True) -> Model:
    """The car with parameters ``w`` (kinds and/or elements) at ``speed`` m/s."""
    p = parameters(w)
    v = float(speed)
    g = GRAVITY
    mass = np.zeros(N_DOF)
    mass[CAR:CAR + 5] = [p["m_car"], p["m_car"], p["I_car_x"], p["I_car_y"], p["I_car_z"]]
    for i in BOGIE:
        mass[i:i + 5] = [p["m_bogie"], p["m_bogie"], p["I_bogie_x"], p["I_bogie_y"], p["I_bogie_z"]]
    for i in WS:
        mass[i:i + 2] = [p["m_ws"], p["I_ws_z"]]
    K = np.zeros((N_DOF, N_DOF))
    C = np.zeros((N_DOF, N_DOF))
    L = p["car_length"]
    xs = np.linspace(-L / 2, L / 2, 2001)
    modal_mass = p["m_car"] * float(np.mean(bending_shape(xs, L) ** 2))
    mass[BEND] = modal_mass
    wb = 2 * math.pi * p["f_bend"]
    K[BEND, BEND] = modal_mass * wb ** 2 if flexible else 1e3 * modal_mass * wb ** 2
    C[BEND, BEND] = 2 * p["zeta_bend"] * wb * modal_mass

    def spring(row, k):
        K[:] += k * np.outer(row, row)

    hc, hb = p["h_car"], p["h_bogie"]
    J_m, k_m, c_m, asym_m, vbo_m, r_m = [], [], [], [], [], []

    def damper_on_bushes(row, k_bush, c, asym, f_blow, r):
        for lst, val in zip((J_m, k_m, c_m, asym_m, vbo_m, r_m), (row, k_bush, c, asym, f_blow / c, r)):
            lst.append(val)

    J_a, k_a, c_a = [], [], []
    J_p, k_pz, c_p, vbo_p, ws_p, side_p = [], [], [], [], [], []
    for ib, b in enumerate(BOGIES):
        xb = p["a_bogie"] * (1 if ib == 0 else -1)
        body = f"bogie{ib + 1}"
        for s, sgn in zip(SIDES, (1.0, -1.0)):
            tag = f"[{b},{s}]"
            # secondary vertical: air spring (static part in K, orifice branch a state) and damper on bushes
            rz = _row("car", (xb, sgn * p["b_sec"], p["h_sec"] - hc), "z", p) \
                - _row(body, (0.0, sgn * p["b_sec"], p["h_sec"] - hb), "z", p)
            spring(rz, p["k_sec_z" + tag])
            kx = p["air_res_ratio"] * p["k_sec_z" + tag]
            J_a.append(rz)
            k_a.append(kx)
            c_a.append(kx / (2 * math.pi * p["air_orifice_hz"]))
            damper_on_bushes(rz, p["k_bush_z"], p["c_sec_z" + tag], p["damper_asym"], p["f_blow_z"], p["r_blow"])
            # secondary lateral spring (air spring shear) and lateral damper on bushes
            ry = _row("car", (xb, sgn * p["b_sec"], p["h_sec"] - hc), "y", p) \
                - _row(body, (0.0, sgn * p["b_sec"], p["h_sec"] - hb), "y", p)
            spring(ry, p["k_sec_y" + tag])
            rd = _row("car", (xb, sgn * p["b_sec"], p["h_lat_damper"] - hc), "y", p) \
                - _row(body, (0.0, sgn * p["b_sec"], p["h_lat_damper"] - hb), "y", p)
            damper_on_bushes(rd, p["k_bush_y"], p["c_sec_y" + tag], p["damper_asym"], p["f_blow_y"], p["r_blow"])
            # secondary longitudinal spring and yaw damper (yaw only)
            rx_ = _row("car", (xb, sgn * p["b_sec"], 0.0), "x", p) - _row(body, (0.0, sgn * p["b_sec"], 0.0), "x", p)
            spring(rx_, p["k_sec_x" + tag])
            ryaw = _row("car", (xb, sgn * p["b_yaw"], 0.0), "x", p) - _row(body, (0.0, sgn * p["b_yaw"], 0.0), "x", p)
            damper_on_bushes(ryaw, p["k_yaw_s"], p["c_yaw" + tag], 0.0, p["yaw_f_blow"], p["yaw_r_blow"])
        spring(_row("car", (0, 0, 0), "roll", p) - _row(body, (0, 0, 0), "roll", p), p[f"k_arb[{b}]"])
        for jj in range(2):
            j = 2 * ib + jj
            ws = WHEELSETS[j]
            xw = p["a_ws"] * (1 if jj == 0 else -1)
            for s, sgn in zip(SIDES, (1.0, -1.0)):
                tag = f"[{ws},{s}]"
                bp = sgn * p["b_prim"]
                rz_ = _row(body, (xw, bp, p["r0"] - hb), "z", p)      # minus the track's, prescribed
                spring(rz_, p["k_prim_z" + tag])
                J_p.append(rz_)
                k_pz.append(p["k_prim_z" + tag])
                c_p.append(p["c_prim_z" + tag])
                vbo_p.append(p["f_blow_prim"] / p["c_prim_z" + tag])
                ws_p.append(j)
                side_p.append(sgn)
                ryy = _row(body, (xw, bp, p["r0"] - hb), "y", p) - _row(f"ws{j + 1}", (0.0, bp, 0.0), "y", p)
                spring(ryy, p["k_prim_y" + tag])
                rxx = _row(body, (xw, bp, 0.0), "x", p) - _row(f"ws{j + 1}", (0.0, bp, 0.0), "x", p)
                spring(rxx, p["k_prim_x" + tag])
    # roll preloads (destabilising): carbody on the air springs, bogie frames under the carbody and on the primary
    K[CAR + ROLL, CAR + ROLL] -= p["m_car"] * g * (hc - p["h_sec"])
    for i in BOGIE:
        K[i + ROLL, i + ROLL] -= (p["m_car"] / 2 * g * (p["h_sec"] - hb)
                                  + (p["m_car"] / 2 + p["m_bogie"]) * g * (hb - p["r0"]))
    # wheel-rail: gravitational stiffness (the cant and creep terms are in the right-hand side)
    wheel_load = (p["m_car"] / 8 + p["m_bogie"] / 4 + p["m_ws"] / 2) * g
    for i in WS:
        K[i, i] += 2 * wheel_load * p["conicity"] / p["l0"]
    f_creep = p["f_creep_ref"] * (wheel_load / p["creep_load_ref"]) ** (2.0 / 3.0)
    # sensors
    S, S_g = np.zeros((10, N_DOF)), np.zeros((10, N_DOF))
    k = 0
    for x in (p["a_bogie"], 0.0, -p["a_bogie"]):
        S[k] = _row("car", (x, 0.0, FLOOR - hc), "z", p)
        S[k + 1] = _row("car", (x, 0.0, FLOOR - hc), "y", p)
        S_g[k + 1, CAR + ROLL] = g
        k += 2
    for i in BOGIE:
        S[k, i + Z] = 1.0
        S[k + 1, i + Y] = 1.0
        S_g[k + 1, i + ROLL] = g
        k += 2
    arr = np.asarray
    return Model(p, v, mass, K, C, arr(J_m), arr(k_m), arr(c_m), arr(asym_m), arr(vbo_m), arr(r_m),
                 arr(J_a), arr(k_a), arr(c_a), arr(J_p), arr(k_pz), arr(c_p), arr(vbo_p), arr(ws_p, dtype=int),
                 arr(side_p), S, S_g, f_creep, wheel_load, wheelset_x(p))


# ------------------------------------------------------------------------------ equations of motion
def kernel_args(m: Model) -> tuple:
    """The model's arrays in the order :func:`.kernel.rhs_one` takes them after the state and track."""
    p = m.p
    sc = np.array([p["b_prim"] / (2 * p["l0"]), p["damper_asym"], p["r_blow"], p["conicity"], p["r0"], p["l0"],
                   m.v, m.f_creep, p["mu"] * m.wheel_load, m.wheel_load, p["flange_gap"], p["k_flange"]])
    return (m.K, m.C, m.mass, m.J_m, m.k_m, m.c_m, m.asym_m, m.vbo_m, m.r_m, m.J_a, m.k_a, m.c_a,
            m.J_p, m.k_pz, m.c_p, m.vbo_p, m.ws_p, m.side_p, sc)


def _linear_rhs(m: Model, x: np.ndarray, u: np.ndarray) -> np.ndarray:
    """First-order right-hand side ``(B, n)`` at states ``x`` ``(B, n)`` and track inputs ``u`` ``(B, 24)``
    (per wheelset V, dV/dt, C, dC/dt, Y, G, wheelset-major), creep linear, flange open."""
    nm, na = m.J_m.shape[0], m.J_a.shape[0]
    args = kernel_args(m)
    out = np.empty_like(x)
    for b in range(x.shape[0]):
        q, qd = x[b, :N_DOF], x[b, N_DOF:2 * N_DOF]
        acc, zmd, zad = np.empty(N_DOF), np.empty(nm), np.empty(na)
        KN.rhs_one(q.copy(), qd.copy(), x[b, 2 * N_DOF:2 * N_DOF + nm].copy(), x[b, 2 * N_DOF + nm:].copy(),
                   u[b].reshape(4, 6).copy(), *args, True, acc, zmd, zad)
        out[b] = np.concatenate([qd, acc, zmd, zad])
    return out


def state_matrix(m: Model, eps: float = 1e-7) -> tuple[np.ndarray, np.ndarray]:
    """Linearisation (central differences) about rest: ``A`` ``(n, n)`` and ``B`` ``(n, 24)``, n = 2 N_DOF + 16.

    State order: q, qd, damper strokes, orifice coordinates; inputs as :func:`_linear_rhs`. The central
    difference averages each damper's rebound and compression slopes (a dashpot at rate c; a damper on
    bushes at c (1 - asym^2)), creep linear, flange open.
    """
    n = 2 * N_DOF + m.n_internal
    X = np.concatenate([eps * np.eye(n), -eps * np.eye(n)])
    F = _linear_rhs(m, X, np.zeros((2 * n, 24)))
    A = ((F[:n] - F[n:]) / (2 * eps)).T
    U = np.concatenate([eps * np.eye(24), -eps * np.eye(24)])
    G = _linear_rhs(m, np.zeros((48, n)), U)
    return A, ((G[:24] - G[24:]) / (2 * eps)).T


def eigenfrequencies(m: Model) -> tuple[np.ndarray, np.ndarray]:
    """Oscillating modes of the linearisation: frequencies (Hz) and damping ratios, sorted by frequency."""
    ev = np.linalg.eigvals(state_matrix(m)[0])
    ev = ev[ev.imag > 1e-6]
    wn = np.abs(ev)
    order = np.argsort(wn)
    return wn[order] / (2 * math.pi), -ev.real[order] / wn[order]
