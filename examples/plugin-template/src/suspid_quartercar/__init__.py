"""An example suspid simulator plugin: a vertical quarter car.

Two masses in series: a sprung mass ``m_body`` (a quarter of a carbody, with
its share of the bogie) on the secondary spring ``k_secondary`` and damper
``c_secondary``, over an unsprung mass ``m_wheel`` on the primary spring
``k_primary`` and damper ``c_primary``, whose base follows the vertical track
irregularity. The frequency response is exact (linear, constant speed), so
the accelerations are the inverse FFT of H(ω) times the FFT of the input.

This package is a template: copy it, rename it, and replace the physics.
"""

from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from suspid import hookimpl
from suspid.errors import SimulatorError
from suspid.interfaces import Parameter, Response, Simulator, TrackSegment

# Masses and nominal rates: a quarter of a 40 t high-speed carbody with its
# bogie share (values of the order of the Manchester Benchmark vehicle: Iwnicki,
# Vehicle System Dynamics 30 (1998) 295-313).
PARAMETERS = [
    Parameter("k_secondary", "N/m", 0.4e6, 0.2e6, 0.8e6, "secondary vertical stiffness"),
    Parameter("c_secondary", "N s/m", 15e3, 5e3, 40e3, "secondary vertical damping"),
    Parameter("k_primary", "N/m", 1.2e6, 0.6e6, 2.4e6, "primary vertical stiffness"),
    Parameter("c_primary", "N s/m", 8e3, 2e3, 20e3, "primary vertical damping"),
]


class QuarterCarOptions(BaseModel):
    model_config = ConfigDict(extra="forbid")
    fs_hz: float = Field(100.0, gt=0, description="output sampling rate in Hz")
    m_body_kg: float = Field(10_000.0, gt=0, description="sprung mass")
    m_wheel_kg: float = Field(2_000.0, gt=0, description="unsprung mass")


class QuarterCar(Simulator):
    """Two-mass vertical quarter car; channels ``body_vertical``, ``wheel_vertical`` (m/s^2)."""

    name = "quarter-car"
    Options = QuarterCarOptions

    def __init__(self, fs_hz: float = 100.0, m_body_kg: float = 10_000.0, m_wheel_kg: float = 2_000.0):
        super().__init__(fs_hz=fs_hz, m_body_kg=m_body_kg, m_wheel_kg=m_wheel_kg)
        self.fs_hz, self.m_body_kg, self.m_wheel_kg = fs_hz, m_body_kg, m_wheel_kg

    def parameters(self) -> list[Parameter]:
        return list(PARAMETERS)

    def default_parameters(self) -> list[str]:
        return ["k_secondary", "c_secondary", "k_primary"]

    def channels(self) -> list[str]:
        return ["body_vertical", "wheel_vertical"]

    def frequency_response(self, w: Mapping[str, float], omega: np.ndarray) -> np.ndarray:
        """Acceleration per unit base displacement, ``(2, n_omega)`` complex, (m/s^2)/m.

        Solves [-ω² M + iω C + K] z = f(ω) for the body and wheel displacements.
        """
        p = {q.name: q.nominal for q in PARAMETERS} | dict(w)
        ks, cs, kp, cp = p["k_secondary"], p["c_secondary"], p["k_primary"], p["c_primary"]
        mb, mw = self.m_body_kg, self.m_wheel_kg
        s = 1j * omega
        zs, zp = ks + cs * s, kp + cp * s  # complex stiffnesses of the two stages
        a11, a12 = mb * s**2 + zs, -zs
        a21, a22 = -zs, mw * s**2 + zs + zp
        det = a11 * a22 - a12 * a21
        body = (-a12 * zp) / det  # Cramer's rule with right-hand side (0, zp)
        wheel = (a11 * zp) / det
        return np.stack([body, wheel]) * s**2

    def simulate(self, w: Mapping[str, float], segments: Sequence[TrackSegment]) -> list[Response]:
        unknown = set(w) - {p.name for p in PARAMETERS}
        if unknown:
            raise SimulatorError(f"quarter-car: unknown parameters {sorted(unknown)}")
        out = []
        for seg in segments:
            if np.ndim(seg.speed) != 0:
                raise SimulatorError(f"quarter-car: segment {seg.name}: only constant speed is supported")
            v = float(seg.speed)
            n_t = int(seg.length / v * self.fs_hz)
            if n_t < 16:
                raise SimulatorError(f"quarter-car: segment {seg.name} is too short ({n_t} samples)")
            t = np.arange(n_t) / self.fs_hz
            z = np.interp(t * v + seg.distance[0], seg.distance, seg.irregularities[0])
            omega = 2 * np.pi * np.fft.rfftfreq(n_t, 1 / self.fs_hz)
            acc = np.fft.irfft(self.frequency_response(w, omega) * np.fft.rfft(z), n=n_t)
            out.append(Response(tuple(self.channels()), self.fs_hz, acc, seg.name))
        return out


@hookimpl
def suspid_register_simulators(register):
    register(QuarterCar)
