"""Eigen-analysis of the linearised model: modes, damping, dominant body and motion, stability.

The eigenvalues are those of the first-order form of exudyn's linearisation
(M q'' + D q' + K q = 0 on the free coordinates, :class:`LinearSystem`):
lambda = -zeta omega_n +- i omega_n sqrt(1 - zeta^2). A mode is reported
once (the eigenvalue with positive imaginary part; an overdamped pair gives
two real eigenvalues, reported with damping ratio 1 and the frequency
|lambda| / 2 pi). The model is **stable** when every eigenvalue has a
negative real part.

Dominant body and motion: the mode's kinetic energy is split over the free
coordinates (m_kk |phi_k|^2 with the diagonal mass of each coordinate, kg or
kg m^2); the body with the largest share is the dominant body and its
coordinate with the largest share the dominant motion.

Groups (the order of the listing): ``carbody`` and ``bogie`` (rigid-body
suspension modes), ``wheelset`` (wheelset modes below
:data:`CONTACT_HZ`: kinematic and creep-damped modes), ``articulation``
(carbody modes at or above :data:`CONTACT_HZ`: the carbody ends of an
articulated rake on the stiff articulation springs), ``track/contact``
(wheelsets on the contact and the track support, at or above
:data:`CONTACT_HZ`, and track modes), ``internal`` (internal coordinates:
Maxwell yaw dampers, effects). Within a group, by frequency.

Stability (:class:`SpeedDependentSystem`, :func:`critical_speed`,
:func:`stability_sweep`): the linear critical speed is the lowest speed at
which an eigenvalue crosses into the right half-plane.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from .model import LinearSystem

GROUPS = ("carbody", "bogie", "wheelset", "articulation", "track/contact", "internal", "relaxation")
"""Mode groups in the order of the listing; "relaxation": real (overdamped, non-oscillating) poles, such as
those of the Maxwell dampers' series springs relaxing through the damper."""

CONTACT_HZ = 30.0
"""Wheelset-dominated modes at or above this frequency count as track/contact modes."""

STABILITY_TOLERANCE = 1e-9
"""Real parts above -tolerance * |lambda| count as not damped (rigid-body or unstable)."""


@dataclass
class Mode:
    """One mode of the linearised car.

    :ivar frequency_hz: undamped natural frequency |lambda| / 2 pi.
    :ivar damped_frequency_hz: |Im lambda| / 2 pi (0 for overdamped modes).
    :ivar damping_ratio: -Re lambda / |lambda| (negative: the mode grows).
    :ivar body: dominant body; :ivar motion: its dominant motion.
    :ivar share: fraction of the mode's kinetic energy in that body.
    :ivar participation: body -> energy fraction (bodies above 5 %).
    """

    frequency_hz: float
    damped_frequency_hz: float
    damping_ratio: float
    body: str
    motion: str
    share: float
    participation: dict[str, float]
    eigenvalue: tuple[float, float]
    group: str = "internal"

    def as_dict(self) -> dict:
        return asdict(self)


def acting_positions(K: np.ndarray, *outputs: np.ndarray | None, rtol: float = 1e-12) -> np.ndarray:
    """Indices of the coordinates whose displacement acts: a nonzero column of K or of an output matrix.

    The others are cyclic: only their rate enters the equations (a rolling
    wheelset's spin angle: the creepages read the spin rate). Their
    displacement is a neutral direction (an eigenvalue 0 that neither decays
    nor grows and moves nothing); the state x = (q_acting, q') leaves it out.

    :param K: ``(n, n)`` stiffness; ``outputs``: ``(n_out, n)`` matrices applied to q (or None).
    """
    acting = np.any(np.abs(K) > rtol * max(float(np.max(np.abs(K))), 1e-300), axis=0)
    for C in outputs:
        if C is not None:
            acting |= np.any(C != 0.0, axis=0)
    return np.flatnonzero(acting)


def state_matrix(linear: LinearSystem | None = None, *, M: np.ndarray | None = None, K: np.ndarray | None = None,
                 D: np.ndarray | None = None, positions: np.ndarray | None = None) -> np.ndarray:
    """A of x' = A x with x = (q[positions], q'), ``(p + n, p + n)``; positions default to
    :func:`acting_positions` of K and of the sensors' matrices (all coordinates when none is cyclic)."""
    if linear is not None:
        M, K, D = linear.M, linear.K, linear.D
        if positions is None:
            positions = acting_positions(K, linear.C, linear.C_disp)
    n = M.shape[0]
    p = np.arange(n) if positions is None else np.asarray(positions)
    m = p.size
    Minv = np.linalg.inv(M)
    A = np.zeros((m + n, m + n))
    A[:m, m:] = np.eye(n)[p]
    A[m:, :m] = -Minv @ K[:, p]
    A[m:, m:] = -Minv @ D
    return A


def mode_group(body: str, frequency_hz: float, oscillating: bool = True) -> str:
    """The group (:data:`GROUPS`) of a mode from its dominant body and frequency."""
    if not oscillating:
        return "relaxation"
    if body.startswith("carbody"):
        return "carbody" if frequency_hz < CONTACT_HZ else "articulation"
    if body.startswith("bogie"):
        return "bogie"
    if body.startswith("wheelset"):
        return "wheelset" if frequency_hz < CONTACT_HZ else "track/contact"
    if body == "track" or body == "track-flexibility":
        return "track/contact"
    return "internal"


def compute_modes(linear: LinearSystem) -> list[Mode]:
    """All modes, by group (:data:`GROUPS`: carbody and bogie first) and within a group by frequency."""
    n = linear.M.shape[0]
    lam, V = np.linalg.eig(state_matrix(linear))
    mass = np.abs(np.diag(linear.M))
    V = V[-n:]          # the velocities q' = lambda phi: the kinetic energy's split is that of phi
    keep = []
    for i, l in enumerate(lam):
        if l.imag < -1e-9 * max(1.0, abs(l)):
            continue  # the conjugate of a reported mode
        keep.append(i)
    modes = []
    for i in keep:
        l = lam[i]
        phi = V[:, i]
        energy = mass * np.abs(phi) ** 2
        total = energy.sum()
        energy = energy / total if total > 0 else energy
        per_body: dict[str, float] = {}
        for (body, _), e in zip(linear.labels, energy):
            per_body[body] = per_body.get(body, 0.0) + float(e)
        body = max(per_body, key=per_body.get)
        idx = [k for k, (b, _) in enumerate(linear.labels) if b == body]
        motion = linear.labels[max(idx, key=lambda k: energy[k])][1]
        wn = abs(l)
        modes.append(Mode(
            frequency_hz=float(wn / (2 * math.pi)),
            damped_frequency_hz=float(abs(l.imag) / (2 * math.pi)),
            damping_ratio=float(-l.real / wn) if wn > 0 else 0.0,
            body=body, motion=motion, share=float(per_body[body]),
            participation={b: round(e, 4) for b, e in sorted(per_body.items(), key=lambda kv: -kv[1]) if e >= 0.05},
            eigenvalue=(float(l.real), float(l.imag))))
    for m in modes:
        m.group = mode_group(m.body, m.frequency_hz, m.damped_frequency_hz > 0.0)
    modes.sort(key=lambda m: (GROUPS.index(m.group), m.frequency_hz))
    return modes


def is_stable(modes: list[Mode]) -> bool:
    """Every mode decays (real part of its eigenvalue below zero)."""
    return all(m.eigenvalue[0] < -STABILITY_TOLERANCE * max(1.0, 2 * math.pi * m.frequency_hz) for m in modes)


def modes_summary(linear: LinearSystem) -> dict:
    """``{"speed_mps", "speed_kmh", "stable", "least_damped", "modes": [...]}`` (JSON-ready)."""
    modes = compute_modes(linear)
    least = min(modes, key=lambda m: m.damping_ratio)
    return {"speed_mps": float(linear.speed), "speed_kmh": float(linear.speed * 3.6),
            "stable": is_stable(modes), "least_damped": least.as_dict(),
            "modes": [m.as_dict() for m in modes]}


# ------------------------------------------------------------------------------------------ stability
@dataclass
class SpeedDependentSystem:
    """The linear model as a function of speed: M q'' + (D_inf + D_creep / v) q' + K q = 0.

    Only the creep damping of the contact depends on the speed (f / v); it is
    separated from two linearisations (``from_simulator``), so that the
    eigenvalues at any speed cost one eigen-decomposition, no new linearisation.

    :ivar M, K, D_inf, D_creep: ``(n, n)``, SI units (D_creep in N s/m times m/s).
    :ivar labels: ``(n,)`` (body, motion) of each free coordinate.
    """

    M: np.ndarray
    K: np.ndarray
    D_inf: np.ndarray
    D_creep: np.ndarray
    labels: list[tuple[str, str]]

    @classmethod
    def from_simulator(cls, simulator, w=None) -> "SpeedDependentSystem":
        """From a simulator with ``linear_system(w, speed)`` (e.g. ``exudyn-train``), at parameters ``w``."""
        a = simulator.linear_system(w, 50.0)
        b = simulator.linear_system(w, 100.0)
        d_creep = (a.D - b.D) * 100.0        # D(50) - D(100) = D_creep (1/50 - 1/100)
        return cls(b.M, b.K, b.D - d_creep / 100.0, d_creep, list(b.labels))

    def max_growth(self, speed: float) -> float:
        """Largest real part / |eigenvalue| at ``speed`` (m/s): > 0 unstable, the least damping ratio negated."""
        A = state_matrix(M=self.M, K=self.K, D=self.D_inf + self.D_creep / speed,
                         positions=acting_positions(self.K))
        lam = np.linalg.eigvals(A)
        return float(np.max(lam.real / np.maximum(np.abs(lam), 1e-12)))

    def critical_speed(self, v_min: float = 10.0, v_max: float = 1500 / 3.6, step: float = 5.0,
                       tol: float = 0.05) -> float:
        """Lowest speed (m/s) in [v_min, v_max] at which a mode grows (linear critical speed); ``inf`` when
        the model is stable over the whole range. A scan every ``step`` m/s, then bisection to ``tol`` m/s."""
        lo = v_min
        if self.max_growth(lo) > 0.0:
            return float(lo)
        v = lo
        while v < v_max:
            hi = min(v + step, v_max)
            if self.max_growth(hi) > 0.0:
                lo = v
                while hi - lo > tol:
                    mid = 0.5 * (lo + hi)
                    if self.max_growth(mid) > 0.0:
                        hi = mid
                    else:
                        lo = mid
                return float(0.5 * (lo + hi))
            v = hi
        return math.inf


def critical_speed(simulator, w=None, **kwargs) -> float:
    """Linear critical speed (m/s) of a simulator with ``linear_system(w, speed)`` at parameters ``w``
    (``inf``: stable up to ``v_max``, default 1500 km/h). See :meth:`SpeedDependentSystem.critical_speed`."""
    return SpeedDependentSystem.from_simulator(simulator, w).critical_speed(**kwargs)


def stability_sweep(simulator, parameters=None, conicities=(0.05, 0.1, 0.15, 0.2, 0.25, 0.3, 0.4),
                    n_points: int = 3) -> dict:
    """Linear critical speed at the nominal parameters, against conicity, and against each parameter.

    :param simulator: e.g. ``ExudynTrain(...)``; it must list ``parameters()`` with bounds.
    :param parameters: names to sweep over their bounds (default: the simulator's
        ``default_parameters()``).
    :param conicities: equivalent conicities to sweep (the other parameters nominal).
    :param n_points: values per parameter, evenly spaced from its lower to its upper bound.
    :returns: ``{"nominal_kmh": float, "conicity": [(lambda, v_kmh)], "parameters": {name: [(value, v_kmh)]}}``
        speeds in km/h (``inf``: stable up to 1500 km/h).
    """
    names = list(parameters or simulator.default_parameters())
    bounds = {p.name: (p.lower, p.upper) for p in simulator.parameters()}
    kmh = lambda w: 3.6 * critical_speed(simulator, w)  # noqa: E731
    out = {"nominal_kmh": kmh({}), "conicity": [(float(c), kmh({"conicity": float(c)})) for c in conicities],
           "parameters": {}}
    for name in names:
        lo, hi = bounds[name]
        out["parameters"][name] = [(float(v), kmh({name: float(v)})) for v in np.linspace(lo, hi, n_points)]
    return out
