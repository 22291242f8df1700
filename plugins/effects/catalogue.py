"""The built-in effects: parameters (units, bounds, sources), signatures and fit starting points.

Values and bands are typical figures from public sources on high-speed
vehicles and track unless a field's description says "assumption".
Frequencies in Hz, speeds in m/s, lengths in m, masses in kg, stiffnesses in
N/m, angles in degrees.
"""

from __future__ import annotations

import functools
import math
from typing import Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, field_validator

from suspid.interfaces import Effect, EffectSignature

LOG = {"scale": "log"}

BEAM_BETA_L = 4.730040744862704
"""First root of cos(βL) cosh(βL) = 1: the first bending mode of a free-free uniform beam."""
BEAM_SIGMA = (math.cosh(BEAM_BETA_L) - math.cos(BEAM_BETA_L)) / (math.sinh(BEAM_BETA_L) - math.sin(BEAM_BETA_L))


def beam_mode_shape(x: np.ndarray | float, length: float) -> np.ndarray:
    """First bending mode φ(x) of a free-free uniform beam of ``length`` m, x from its centre (m).

    Normalised to φ(0) = 1 (the centre moves up by q when the modal
    coordinate is q). Nodes at ±0.276 L from the centre; the ends move by
    -1.645 q. Outside the beam the value at the nearest end is returned.
    """
    xi = np.clip(np.asarray(x, dtype=float) / length + 0.5, 0.0, 1.0) * BEAM_BETA_L

    def shape(b):
        return np.cosh(b) + np.cos(b) - BEAM_SIGMA * (np.sinh(b) + np.sin(b))

    return shape(xi) / shape(0.5 * BEAM_BETA_L)


@functools.cache
def beam_modal_mass_ratio() -> float:
    """∫φ² dx / L for :func:`beam_mode_shape` (0.677): modal mass over beam mass."""
    x = np.linspace(-0.5, 0.5, 20001)
    return float(np.mean(beam_mode_shape(x, 1.0) ** 2))


def klingel_hz(speed_mps: float, conicity: float, r0: float = 0.46, l0: float = 0.75) -> float:
    """Klingel kinematic frequency of a free wheelset, f = v/(2π) sqrt(λ/(r0 l0))."""
    return speed_mps / (2 * math.pi) * math.sqrt(conicity / (r0 * l0))


class _Params(BaseModel):
    model_config = ConfigDict(extra="forbid")


def _frequencies_in_cells(effect: Effect, parameter: str, flagged, per_cell: int = 4) -> list[float]:
    """Frequencies spread over each matching flagged cell, within the parameter's bounds (Hz)."""
    lo_b, hi_b = effect.bounds(parameter)
    values: list[float] = []
    for _, lo, hi, _ in effect.matching_cells(flagged):
        a, b = max(lo, lo_b), min(hi, hi_b)
        if a <= b:
            values += list(np.linspace(a, b, per_cell + 2)[1:-1]) if b > a else [a]
    values = sorted({round(v, 3) for v in values})
    return values


class _Resonance(Effect):
    """An added resonance with ``frequency_hz`` and ``damping``: fixed in Hz, shows on ``bodies`` x ``directions``.

    Fit starts: frequencies spread over the flagged cells its signature covers.
    """

    main_parameter = "frequency_hz"
    fitted = ("frequency_hz", "damping")
    bodies: tuple[str, ...] = ()
    directions: tuple[str, ...] = ("vertical",)
    starts_per_cell = 4

    def signature(self, speed_mps: float) -> EffectSignature:
        return EffectSignature(self.bodies, self.directions, self.bounds("frequency_hz"), "none")

    def candidates(self, speeds_mps, flagged, channels) -> list[dict[str, Any]]:
        freqs = _frequencies_in_cells(self, "frequency_hz", flagged, self.starts_per_cell)
        return [{"frequency_hz": f} for f in freqs] or super().candidates(speeds_mps, flagged, channels)


# ------------------------------------------------------------------------------------------ carbody bending
class CarbodyBendingOptions(_Params):
    frequency_hz: float = Field(default=10.0, ge=5.0, le=20.0,
                                description="natural frequency of the first vertical bending mode, Hz "
                                "(7-12 Hz for EMU carbodies, 8-15 Hz first flexible modes)")
    damping: float = Field(default=0.02, ge=0.005, le=0.2, description="modal damping ratio", json_schema_extra=LOG)
    length_m: float = Field(default=26.0, ge=10.0, le=40.0,
                            description="carbody length, m (assumption: a 26 m car on bogie centres 19 m apart)")
    modal_mass_kg: float | None = Field(
        default=None, gt=0.0, description="modal mass for φ(centre) = 1, kg (default: a uniform beam of the "
        "carbody's mass, 0.677 m_car)")


class CarbodyBending(_Resonance):
    """First vertical bending mode of the carbody (free-free beam shape).

    A modal coordinate q (deflection at mid-car, m) driven by the secondary
    vertical suspension forces through the mode shape at the bogie pivots;
    a carbody sensor at x adds φ(x) q'' (strongest mid-car, opposite sign and
    weaker over the bogies).
    """

    name = "carbody-bending"
    Options = CarbodyBendingOptions
    description = "carbody first vertical bending mode (modal coordinate driven through the pivots)"
    bodies = ("carbody",)


# ------------------------------------------------------------------------------------------ wheel polygon
class WheelPolygonOptions(_Params):
    order: int = Field(default=1, ge=1, le=20, description="polygon order k (harmonics per wheel revolution)")
    amplitude_m: float = Field(default=5.0e-5, ge=1.0e-7, le=2.0e-3, json_schema_extra=LOG,
                               description="amplitude of the wheel radius deviation, m")
    wheelsets: list[int] = Field(default=[1], min_length=1, description="out-of-round wheelsets, 1 leads")
    phase_rad: float = Field(default=0.0, description="phase of the polygon at the segment start, rad")
    phase_step_rad: float = Field(default=0.0, ge=0.0, le=2 * math.pi,
                                  description="phase of each listed wheelset's polygon after the previous one's, "
                                  "rad: the wheels' relative angle (each wheel is out of round at its own angle)")
    wheel_diameter_m: float = Field(default=0.92, ge=0.6, le=1.3,
                                    description="wheel diameter D, m (0.92 m: EN 15302 reference wheel)")

    @field_validator("wheelsets")
    @classmethod
    def _positive(cls, value: list[int]) -> list[int]:
        if any(j < 1 for j in value) or len(set(value)) != len(value):
            raise ValueError("wheelsets are distinct numbers from 1 (the leading wheelset)")
        return value


WHEELSET_SETS: tuple[tuple[int, ...], ...] = ((1,), (2,), (3,), (4,), (1, 2), (1, 3), (1, 4), (2, 3), (2, 4),
                                              (3, 4), (1, 2, 3, 4))
"""Wheelsets a polygon fit tries (1 leads): each one, each pair (a bogie's, or one per bogie), all four. A line on
both bogies (a re-profiling batch, or a rail corrugation every wheelset passes over) is explained by the set,
not by one wheelset."""


class WheelPolygon(Effect):
    """Out-of-round wheel, a polygon of order k: a periodic vertical input on the wheel.

    Shows on axlebox and bogie vertical channels, and on the carbody where the
    secondary suspension filters it less (low orders at low speed).

    Radius deviation A cos(2π s / (πD/k) + φ + i Δφ) on the i-th listed
    wheelset (i = 0, 1, ...), s the distance it rolled: a vertical input at
    f = k v / (π D) (28.8 Hz per order at 300 km/h). Wheels are out of round
    at their own angles: the phase step Δφ sets how the lines of two wheelsets
    add up where a channel sees both (the carbody), exactly for a pair and
    as a uniform step for more (it does nothing on one wheelset).
    """

    name = "wheel-polygon"
    Options = WheelPolygonOptions
    main_parameter = "order"
    fitted = ("amplitude_m", "phase_step_rad")
    description = "wheel out-of-roundness, polygon of order k (periodic vertical input at k v / (π D))"

    def wavelength(self) -> float:
        """Wavelength on the track, πD/k, m."""
        opts = self.Options.model_validate(self.options)
        return math.pi * opts.wheel_diameter_m / opts.order

    def signature(self, speed_mps: float) -> EffectSignature:
        d = self.Options.model_validate(self.options).wheel_diameter_m
        k_lo, k_hi = self.bounds("order")
        f1 = speed_mps / (math.pi * d)
        return EffectSignature(("axlebox", "wheelset", "bogie", "carbody"), ("vertical",), (k_lo * f1, k_hi * f1),
                               "proportional")

    def candidates(self, speeds_mps, flagged, channels) -> list[dict[str, Any]]:
        d = self.Options.model_validate(self.options).wheel_diameter_m
        k_lo, k_hi = self.bounds("order")
        orders: set[int] = set()
        for _, lo, hi, v in self.matching_cells(flagged):
            f1 = v / (math.pi * d)
            ks = range(max(int(k_lo), math.ceil(lo / f1 - 1e-9)), min(int(k_hi), math.floor(hi / f1 + 1e-9)) + 1)
            orders.update(ks)
            if not ks:   # a band between two orders: both neighbours
                orders.update(k for k in (math.floor(lo / f1), math.ceil(hi / f1)) if k_lo <= k <= k_hi)
        steps = [0.0, 0.5 * math.pi, math.pi, 1.5 * math.pi]
        return [{"order": k, "wheelsets": list(ws), "phase_step_rad": step} for k in sorted(orders)
                for ws in WHEELSET_SETS for step in (steps if len(ws) > 1 else [0.0])]


# ------------------------------------------------------------------------------------------ yaw damper
class YawDamperSeriesStiffnessOptions(_Params):
    stiffness_n_per_m: float = Field(default=10.0e6, ge=0.5e6, le=100.0e6, json_schema_extra=LOG,
                                     description="series stiffness of each yaw damper (rubber mounts, oil "
                                     "compressibility), N/m; e.g. 10 MN/m")


class YawDamperSeriesStiffness(Effect):
    """Yaw dampers as Maxwell elements: the damper in series with a spring.

    Above k_s / (2π c) the damper stiffens into a spring of rate k_s: the
    bogie yaw and hunting behaviour changes (bogie and carbody lateral).
    """

    name = "yaw-damper-series-stiffness"
    Options = YawDamperSeriesStiffnessOptions
    main_parameter = "stiffness_n_per_m"
    fitted = ("stiffness_n_per_m",)
    description = "yaw damper series stiffness (Maxwell element: spring in series with the damper)"

    def signature(self, speed_mps: float) -> EffectSignature:
        f = klingel_hz(speed_mps, 0.25)
        return EffectSignature(("bogie", "carbody"), ("lateral",), (0.15 * f, 2.0 * f), "kinematic")

    def candidates(self, speeds_mps, flagged, channels) -> list[dict[str, Any]]:
        lo, hi = self.bounds("stiffness_n_per_m")
        return [{"stiffness_n_per_m": float(v)} for v in np.geomspace(lo, hi, 7)[1:-1]]


# ------------------------------------------------------------------------------------------ sensor tilt
class SensorTiltOptions(_Params):
    angle_deg: float = Field(default=3.0, ge=0.0, le=20.0,
                             description="tilt of the sensing axis about the longitudinal axis, degrees")
    channels: list[str] | None = Field(default=None, description="tilted lateral channels (default: every "
                                       "lateral channel)")
    gravity_roll: bool = Field(default=True, description="the sensor also measures g times the roll angle of "
                               "its body (a body-fixed accelerometer sees gravity tilt with the body)")


class SensorTilt(Effect):
    """Accelerometer tilt or misalignment on lateral channels.

    a_meas = cos α a_lat + sin α a_vert (+ g φ_roll with ``gravity_roll``),
    α the tilt angle, a_vert the vertical acceleration at the same point and
    φ_roll the roll angle of the body carrying the sensor.
    """

    name = "sensor-tilt"
    Options = SensorTiltOptions
    main_parameter = "angle_deg"
    fitted = ("angle_deg",)
    description = "accelerometer tilt or misalignment (lateral channel sees sin α of the vertical and g φ_roll)"

    def signature(self, speed_mps: float) -> EffectSignature:
        return EffectSignature(("carbody", "bogie", "axlebox", "wheelset"), ("lateral",), (0.0, math.inf), "none")

    def candidates(self, speeds_mps, flagged, channels) -> list[dict[str, Any]]:
        lateral = sorted({c for c, *_ in self.matching_cells(flagged)})
        choices = [[c] for c in lateral] + ([lateral] if len(lateral) > 1 else [])
        # gravity_roll False: the tilt itself (cos α a_lat + sin α a_vert), e.g. when the base model already
        # has g φ_roll in its lateral sensors, or the reference-date noise model took it in
        return [{"channels": ch, "angle_deg": a, "gravity_roll": gr} for ch in choices for a in (2.0, 6.0, 12.0)
                for gr in (False, True)]

    def starts_from_spectra(self, speeds_mps, flagged, channels, spectra: dict[str, Any]) -> list[dict[str, Any]]:
        """Starting points read from the cross-coupling of vertical into lateral at the same sensor point.

        A tilt α mixes the vertical acceleration of the point into the lateral channel: in power,
        P_lat,meas = cos²α L + sin²α V, so the excess E = P_meas - L is s (V - L) with s = sin²α (L: the
        model's lateral power, V: the measured vertical power of the same point, both corrected by μ_B).
        s is a weighted least-squares fit over the bins where V > L (weights 1/L², relative errors), per
        flagged lateral channel with a vertical partner (the same name with ``vertical``). The fit's R² is
        returned as ``coupling_r2``: near 1 when the excess follows the vertical spectrum's shape, which a
        tilt predicts and few other discrepancies do.

        :param spectra: ``freqs`` (F,) Hz; ``measured`` (G, K, F) dB group means of y_mes - μ_B;
            ``model`` (G, K, F) dB group means of y_sim; ``channels`` (K,) names.
        :returns: starts ``{"channels", "angle_deg", "gravity_roll": False, "coupling_r2"}``
            (``coupling_r2`` is evidence, not an option: the fitter removes it).
        """
        names = list(spectra["channels"])
        meas, model = np.asarray(spectra["measured"]), np.asarray(spectra["model"])
        starts = []
        for c in sorted({c for c, *_ in self.matching_cells(flagged)}):
            partner = c.replace("lateral", "vertical")
            if partner == c or partner not in names:
                continue
            k, kv = names.index(c), names.index(partner)
            L = 10.0 ** (model[:, k] / 10.0)
            E = 10.0 ** (meas[:, k] / 10.0) - L
            X = 10.0 ** (meas[:, kv] / 10.0) - L
            use = X > 0
            if use.sum() < 3:
                continue
            w = 1.0 / L[use] ** 2
            s = float(np.sum(w * E[use] * X[use]) / np.sum(w * X[use] ** 2))
            if not s > 0:
                continue
            r2 = 1.0 - float(np.sum(w * (E[use] - s * X[use]) ** 2) / max(np.sum(w * E[use] ** 2), 1e-300))
            angle = math.degrees(math.asin(min(math.sqrt(s), math.sin(math.radians(self.bounds("angle_deg")[1])))))
            starts.append({"channels": [c], "angle_deg": round(angle, 4), "gravity_roll": False,
                           "coupling_r2": round(r2, 4)})
        return starts


# ------------------------------------------------------------------------------------------ conicity
class ConicityChangeOptions(_Params):
    conicity: float = Field(default=0.25, ge=0.05, le=0.5,
                            description="equivalent conicity λ (worn wheels and rails: 0.05-0.3)")


class ConicityChange(Effect):
    """A change of the equivalent conicity λ of the wheel-rail contact.

    Moves the kinematic (Klingel) frequencies ∝ v sqrt(λ): wheelset 5-12 Hz,
    bogie 2-6 Hz for λ 0.05-0.3 at 300 km/h (bogie and carbody lateral).
    """

    name = "conicity-change"
    Options = ConicityChangeOptions
    main_parameter = "conicity"
    fitted = ("conicity",)
    description = "equivalent conicity change (kinematic frequencies ∝ v sqrt(λ))"

    def signature(self, speed_mps: float) -> EffectSignature:
        lo, hi = self.bounds("conicity")
        return EffectSignature(("bogie", "carbody"), ("lateral",),
                               (0.15 * klingel_hz(speed_mps, lo), 1.5 * klingel_hz(speed_mps, hi)), "kinematic")

    def candidates(self, speeds_mps, flagged, channels) -> list[dict[str, Any]]:
        return [{"conicity": v} for v in (0.08, 0.14, 0.2, 0.3, 0.4)]


# ------------------------------------------------------------------------------------------ track flexibility
class TrackFlexibilityOptions(_Params):
    frequency_hz: float = Field(default=60.0, ge=30.0, le=120.0,
                                description="P2 resonance: wheelset and track mass on the track support, Hz "
                                "(typically 50-70 Hz)")
    damping: float = Field(default=0.3, ge=0.05, le=0.9, description="damping ratio of the P2 resonance")
    track_mass_kg: float = Field(default=400.0, ge=50.0, le=3000.0,
                                 description="rail and sleeper mass moving with one wheelset, kg (assumption)")


class TrackFlexibility(_Resonance):
    """Track flexibility under each wheelset: a track mass on the pad and ballast support.

    The wheelset rests on the track mass through the Hertzian contact, the
    irregularity acts between them, and the track mass sits on a support of
    stiffness k_t = (2π f_P2)² (m_wheelset + m_track) with damping ratio ζ.
    """

    name = "track-flexibility"
    Options = TrackFlexibilityOptions
    description = "track flexibility (rail pad and ballast): P2 resonance of wheelset and track mass"
    bodies = ("axlebox", "wheelset", "bogie")
    starts_per_cell = 3
