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
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from .model import LinearSystem

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

    def as_dict(self) -> dict:
        return asdict(self)


def state_matrix(linear: LinearSystem) -> np.ndarray:
    """A (2n x 2n) of x' = A x with x = (q, q')."""
    n = linear.M.shape[0]
    Minv = np.linalg.inv(linear.M)
    A = np.zeros((2 * n, 2 * n))
    A[:n, n:] = np.eye(n)
    A[n:, :n] = -Minv @ linear.K
    A[n:, n:] = -Minv @ linear.D
    return A


def compute_modes(linear: LinearSystem) -> list[Mode]:
    """All modes, sorted by natural frequency."""
    n = linear.M.shape[0]
    lam, V = np.linalg.eig(state_matrix(linear))
    mass = np.abs(np.diag(linear.M))
    keep = []
    for i, l in enumerate(lam):
        if l.imag < -1e-9 * max(1.0, abs(l)):
            continue  # the conjugate of a reported mode
        keep.append(i)
    modes = []
    for i in keep:
        l = lam[i]
        phi = V[:n, i]
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
    modes.sort(key=lambda m: m.frequency_hz)
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
