"""Track segments: synthetic realisations from published spectra.

Channels. A track segment carries four irregularity channels as functions of
distance, rows of ``TrackSegment.irregularities`` in metres, in the order of
:data:`suspid.interfaces.IRREGULARITY_CHANNELS`: ``vertical`` (longitudinal
level, up positive), ``lateral`` (alignment, left positive), ``cross_level``
(left rail height minus right rail height) and ``gauge`` (deviation from
nominal, wider positive).

Synthetic track (:class:`TrackOptions`, :func:`synthetic_segments`)
-------------------------------------------------------------------
Distance-domain one-sided PSDs S(Omega), Omega in rad/m, S in m^2/(rad/m)
(the German spectra as published for ORE B176 and used in railway vehicle dynamics; the FRA classes of
the US Federal Railroad Administration):

- ``german-low`` / ``german-high`` (Omega_c = 0.8246, Omega_r = 0.0206,
  Omega_s = 0.4380 rad/m, b = 0.75 m): vertical and lateral
  A Omega_c^2 / ((Omega^2 + Omega_r^2)(Omega^2 + Omega_c^2)) with A_v, A_a;
  gauge A_g Omega_c^2 Omega^2 / ((Omega^2 + Omega_r^2)(Omega^2 + Omega_c^2)(Omega^2 + Omega_s^2));
  cross-level: the sources give (A_v / b^2) times the gauge shape, which has
  the units of an *angle* PSD (rad^2/(rad/m)); it is read as the roll angle
  of the track and turned into the height difference of the rails by the
  factor (2 b)^2. Constants A (m rad): low 4.032e-7, 2.119e-7, 0.532e-7;
  high 1.080e-6, 6.125e-7, 1.032e-7 (vertical, alignment, gauge).
- ``fra-1`` ... ``fra-6`` (US FRA track classes): vertical
  k A_v Omega_c^2 / (Omega^2 (Omega^2 + Omega_c^2)) cm^2/(rad/m), k = 0.25,
  Omega_c = 0.8245, A_v = 1.2107, 1.0181, 0.6816, 0.5376, 0.2095, 0.0339
  cm^2 rad/m for classes 1-6. The FRA constants of the other channels could
  not be confirmed from public sources, so alignment, cross-level and gauge
  of an FRA track **fall back to the German spectra**: ``german-high`` for
  classes 1-4, ``german-low`` for classes 5 and 6.

Realisation: each channel of each segment is an independent stationary
Gaussian process sampled every ``dx_m`` over ``length_m``, generated in the
frequency domain: Fourier coefficients c_k complex normal with
E|c_k|^2 = 2 S(Omega_k) dOmega at Omega_k = 2 pi k / (N dx), then an inverse
FFT (the periodogram of a realisation scatters about S like a measured one;
the process is periodic over the segment; content below 2 pi / length_m is
absent; ``min_wavelength_m`` and ``max_wavelength_m`` restrict the band, e.g.
to the 1-120 m of EN 13848 D1-D2). Seeded through
``numpy.random.default_rng(seed)``: the same options give the same segments.

Files of track segments and accelerations (CSV, HDF5) are read and written by
:mod:`suspid.data.files`; its functions are also importable from this module.
"""

from __future__ import annotations

import math
from typing import Any, Literal, Mapping

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, PositiveFloat, PositiveInt, model_validator

from suspid.interfaces import IRREGULARITY_CHANNELS, TrackSegment
from suspid.options import parse_options

# ---------------------------------------------------------------------------------------------- spectra
GERMAN = {"omega_c": 0.8246, "omega_r": 0.0206, "omega_s": 0.4380, "b": 0.75}
"""Constants of the German spectra (rad/m, and b in m)."""

GERMAN_A = {
    "german-low": {"vertical": 4.032e-7, "lateral": 2.119e-7, "gauge": 0.532e-7},
    "german-high": {"vertical": 1.080e-6, "lateral": 6.125e-7, "gauge": 1.032e-7},
}
"""A_v, A_a, A_g in m rad: the German high-speed track spectra, low and high disturbance, as tabulated in
the vehicle-dynamics literature."""

FRA = {"k": 0.25, "omega_c": 0.8245, "A_v": (1.2107, 1.0181, 0.6816, 0.5376, 0.2095, 0.0339)}
"""FRA vertical constants, A_v in cm^2 rad/m for classes 1-6 (US Federal Railroad Administration track
classes, e.g. V. K. Garg and R. V. Dukkipati, Dynamics of Railway Vehicle Systems, Academic Press 1984)."""

SPECTRA = ("german-low", "german-high", "fra-1", "fra-2", "fra-3", "fra-4", "fra-5", "fra-6")
"""Names of the available spectra."""


def psd(spectrum: str, channel: str, omega: np.ndarray | float) -> np.ndarray:
    """One-sided PSD in m^2/(rad/m) of ``channel`` for ``spectrum`` at ``omega`` (rad/m).

    :raises ValueError: unknown spectrum or channel.
    """
    if channel not in IRREGULARITY_CHANNELS:
        raise ValueError(f"unknown channel '{channel}'; channels: {', '.join(IRREGULARITY_CHANNELS)}")
    w = np.asarray(omega, dtype=float)
    if spectrum.startswith("fra-"):
        try:
            cls = int(spectrum[4:])
            a_v = FRA["A_v"][cls - 1]
        except (ValueError, IndexError):
            raise ValueError(f"unknown spectrum '{spectrum}'; spectra: {', '.join(SPECTRA)}") from None
        if cls < 1:
            raise ValueError(f"unknown spectrum '{spectrum}'; spectra: {', '.join(SPECTRA)}")
        if channel == "vertical":
            oc = FRA["omega_c"]
            with np.errstate(divide="ignore"):
                s_cm2 = FRA["k"] * a_v * oc ** 2 / (w ** 2 * (w ** 2 + oc ** 2))
            return s_cm2 * 1e-4
        return psd("german-high" if cls <= 4 else "german-low", channel, w)
    if spectrum not in GERMAN_A:
        raise ValueError(f"unknown spectrum '{spectrum}'; spectra: {', '.join(SPECTRA)}")
    a = GERMAN_A[spectrum]
    oc, orr, os_, b = GERMAN["omega_c"], GERMAN["omega_r"], GERMAN["omega_s"], GERMAN["b"]
    base = oc ** 2 / ((w ** 2 + orr ** 2) * (w ** 2 + oc ** 2))
    if channel == "vertical":
        return a["vertical"] * base
    if channel == "lateral":
        return a["lateral"] * base
    shape = base * w ** 2 / (w ** 2 + os_ ** 2)
    if channel == "gauge":
        return a["gauge"] * shape
    return (2 * b) ** 2 * (a["vertical"] / b ** 2) * shape   # cross-level: roll angle PSD x (2b)^2


class CurveOptions(BaseModel):
    """A curve laid on every synthetic segment: straight, entry transition, circular arc, exit transition,
    straight (distances from the segment's start). In the transitions (clothoids) the curvature and the
    cant ramp linearly between zero and their values in the arc."""

    model_config = ConfigDict(extra="forbid")

    radius_m: PositiveFloat = Field(description="radius of the circular arc, m")
    direction: Literal["left", "right"] = Field(default="left", description="direction of the curve in the "
                                                "direction of travel")
    cant_m: float = Field(default=0.0, ge=0.0, le=0.2, description="cant in the arc, m (height of the outer "
                          "rail above the inner one; EN 13803 allows at most 0.18-0.20 m)")
    start_m: float = Field(default=0.0, ge=0.0, description="where the entry transition begins, m")
    transition_m: float = Field(default=0.0, ge=0.0, description="length of each transition, m")
    arc_m: PositiveFloat | None = Field(default=None, description="length of the circular arc, m (default: "
                                        "to the end of the segment)")


def curve_geometry(distance: np.ndarray, curve: CurveOptions | Mapping[str, Any]) -> tuple[np.ndarray, np.ndarray]:
    """Design curvature (1/m, positive to the left) and cant (m, right rail above the left) of ``curve`` at
    ``distance`` ``(n_x,)`` m from the segment start (see :class:`CurveOptions`); each ``(n_x,)``."""
    c = parse_options(CurveOptions, curve, "data.track.curve")
    s = np.asarray(distance, dtype=float) - float(distance[0]) - c.start_m
    L = c.transition_m
    end_arc = L + (c.arc_m if c.arc_m is not None else math.inf)
    if L > 0:
        ramp = np.clip(s / L, 0.0, 1.0) - np.clip((s - end_arc) / L, 0.0, 1.0)
    else:
        ramp = ((s >= 0) & (s <= end_arc)).astype(float)
    sign = 1.0 if c.direction == "left" else -1.0
    return sign * ramp / c.radius_m, sign * ramp * c.cant_m


class TrackOptions(BaseModel):
    """A synthetic track section: ``n_segments`` independent segments of one spectrum.

    Give the speed as ``speed_kmh`` or ``speed_mps`` (not both; default 300 km/h).
    """

    model_config = ConfigDict(extra="forbid")

    spectrum: Literal[SPECTRA] = Field(default="german-low", description="published spectrum to realise")
    n_segments: PositiveInt = Field(default=10, description="number of segments")
    length_m: PositiveFloat = Field(default=2000.0, description="segment length, m")
    dx_m: PositiveFloat = Field(default=0.25, le=5.0, description="distance step, m (recording cars: 0.2-0.25)")
    speed_kmh: PositiveFloat | None = Field(default=None, description="train speed, km/h")
    speed_mps: PositiveFloat | None = Field(default=None, description="train speed, m/s")
    min_wavelength_m: PositiveFloat | None = Field(
        default=None, description="shortest wavelength realised, m (default: all up to the sampling limit 2 dx)")
    max_wavelength_m: PositiveFloat | None = Field(
        default=None, description="longest wavelength realised, m (default: the segment length)")
    seed: int = Field(default=0, ge=0, description="seed of numpy.random.default_rng")
    name_prefix: str = Field(default="seg", min_length=1, description="segment names are <prefix>-001, ...")
    curve: CurveOptions | None = Field(default=None, description="a curve with transitions on every segment "
                                       "(default: straight track)")

    @model_validator(mode="after")
    def _speed(self) -> "TrackOptions":
        if self.speed_kmh is not None and self.speed_mps is not None:
            raise ValueError("give the speed once: speed_kmh or speed_mps")
        if self.length_m < 4 * self.dx_m:
            raise ValueError(f"length_m = {self.length_m} holds fewer than 4 samples of dx_m = {self.dx_m}")
        if (self.min_wavelength_m is not None and self.max_wavelength_m is not None
                and self.min_wavelength_m >= self.max_wavelength_m):
            raise ValueError("min_wavelength_m must be below max_wavelength_m")
        return self

    @property
    def speed(self) -> float:
        """Train speed in m/s."""
        if self.speed_mps is not None:
            return float(self.speed_mps)
        return float(self.speed_kmh if self.speed_kmh is not None else 300.0) / 3.6


def realise(spectrum: str, n: int, dx: float, rng: np.random.Generator,
            wavelengths: tuple[float | None, float | None] = (None, None)) -> np.ndarray:
    """``(4, n)`` one realisation of the four channels, m (see the module docstring).

    :param wavelengths: (shortest, longest) wavelength realised in m; ``None``: no limit.
    """
    k = np.arange(n // 2 + 1)
    omega = 2 * math.pi * k / (n * dx)
    d_omega = 2 * math.pi / (n * dx)
    keep = k > 0
    if wavelengths[0] is not None:
        keep &= omega <= 2 * math.pi / wavelengths[0]
    if wavelengths[1] is not None:
        keep &= omega >= 2 * math.pi / wavelengths[1]
    out = np.empty((len(IRREGULARITY_CHANNELS), n))
    for i, ch in enumerate(IRREGULARITY_CHANNELS):
        s = np.zeros_like(omega)
        s[keep] = psd(spectrum, ch, omega[keep])
        if n % 2 == 0:
            s[-1] = 0.0   # the Nyquist line would be real: leave it out
        std = np.sqrt(2.0 * s * d_omega)          # E|c_k|^2 = 2 S dOmega
        c = std * (rng.standard_normal(k.size) + 1j * rng.standard_normal(k.size)) / math.sqrt(2.0)
        out[i] = np.fft.irfft(c * (n / 2.0), n=n)
    return out


def synthetic_segments(options: TrackOptions | Mapping[str, Any] | None = None,
                       rng: np.random.Generator | None = None) -> list[TrackSegment]:
    """Realisations of a synthetic track section.

    :param options: the track options (``data.track`` of a config).
    :param rng: a generator to draw from; default ``numpy.random.default_rng(options.seed)``.
    :returns: ``n_segments`` segments named ``<prefix>-001`` ..., constant speed.
    """
    opt = parse_options(TrackOptions, options, "data.track")
    rng = rng if rng is not None else np.random.default_rng(opt.seed)
    n = int(round(opt.length_m / opt.dx_m)) + 1
    x = np.arange(n) * opt.dx_m
    width = max(3, len(str(opt.n_segments)))
    out = []
    for i in range(opt.n_segments):
        irr = realise(opt.spectrum, n, opt.dx_m, rng, (opt.min_wavelength_m, opt.max_wavelength_m))
        curvature, cant = curve_geometry(x, opt.curve) if opt.curve is not None else (None, None)
        out.append(TrackSegment(f"{opt.name_prefix}-{i + 1:0{width}d}", x.copy(), irr, opt.speed,
                                meta={"spectrum": opt.spectrum, "seed": opt.seed, "index": i},
                                curvature=curvature, cant=cant))
    return out
