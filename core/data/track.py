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


# ---------------------------------------------------------------------------------------------- record bands
EN13848_BANDS = {"D1": (3.0, 25.0), "D2": (25.0, 70.0), "D3": (70.0, 150.0)}
"""Wavelength ranges (shortest, longest) in m of the EN 13848 bands D1, D2 and D3 (EN 13848-1 and -5, as
summarised in the public literature on track geometry, e.g. the UIC/CEN track quality documents); D3's
longest wavelength is 150 m for the longitudinal level and 200 m for the alignment (``TrackBand.d3_long_m``)."""


class TrackBand(BaseModel):
    """How a track record was measured: the transfer function H(k) from the true rail position to the record.

    ``filter``:

    - ``full``: the full band (H = 1), e.g. an inertial record without filtering;
    - ``en13848``: the EN 13848 wavelength bands ``bands`` (D1 3-25 m, D2 25-70 m, D3 70-150 or 200 m,
      :data:`EN13848_BANDS`). The standard prescribes the band limits; the filter that realises them is
      modelled here as a zero-phase Butterworth band-pass of ``order`` per edge, |H|² = 1 / (1 + (k_c / k)^(2n))
      / (1 + (k / k_h)^(2n)) with k = 1 / wavelength, -3 dB at the band's edges (no public text of the
      standard's own filter coefficients could be consulted; a recording car with another filter is
      described with ``transfer``);
    - ``chord``: a versine (chord offset) measurement, chord length ``chord_m``, the measuring point
      ``chord_offset_m`` from the chord's rear end (default: the middle):
      v(x) = z(x) - (b z(x - a) + a z(x + b)) / L with a = chord_offset_m, b = L - a, so
      H(k) = 1 - (b e^(-2 pi i k a) + a e^(2 pi i k b)) / L (symmetric: 1 - cos(pi k L));
    - ``transfer``: a user transfer function, gains ``transfer_gain`` at ``transfer_wavelength_m`` (m),
      interpolated linearly in log(wavelength), 0 outside.

    The record *supports* the wavelengths where ``min_gain <= |H| <= 1 / min_gain`` (the contiguous range of the longest
    such wavelengths: a chord's main lobe); at speed v that is the frequency band f = v / wavelength, where the model's response
    to the record and the vehicle's to the real track agree within 10 log10(1 / min_gain) dB of Y. A chord
    record amplifies (|H| up to 2) and nulls wavelengths: only a narrow band of it is the rail position
    itself; reconstruct the rail position from it first for a wider band.
    """

    model_config = ConfigDict(extra="forbid")

    filter: Literal["full", "en13848", "chord", "transfer"] = Field(default="full", description="how the "
                                                                    "record was measured")
    bands: list[Literal["D1", "D2", "D3"]] = Field(default_factory=lambda: ["D1", "D2"], min_length=1,
                                                   description="EN 13848 bands of the record (contiguous)")
    d3_long_m: Literal[150.0, 200.0] = Field(default=150.0, description="D3's longest wavelength, m "
                                             "(150: longitudinal level, 200: alignment)")
    order: int = Field(default=4, ge=1, le=12, description="Butterworth order per band edge (en13848)")
    chord_m: PositiveFloat | None = Field(default=None, description="chord length L, m (chord)")
    chord_offset_m: PositiveFloat | None = Field(default=None, description="measuring point from the "
                                                 "chord's rear end, m (chord; default L / 2)")
    transfer_wavelength_m: list[PositiveFloat] | None = Field(default=None, description="wavelengths of "
                                                              "the user transfer function, m, increasing")
    transfer_gain: list[float] | None = Field(default=None, description="|H| at transfer_wavelength_m")
    min_gain: float = Field(default=0.99, gt=0.0, le=1.0, description="|H| from which a wavelength counts "
                            "as supported by the record")
    restrict: bool = Field(default=True, description="restrict the spectra to the band every segment's "
                           "record supports at its speed (false: only report it)")

    @model_validator(mode="after")
    def _check(self) -> "TrackBand":
        if self.filter == "en13848":
            idx = sorted("D1 D2 D3".split().index(b) for b in self.bands)
            if len(set(idx)) != len(idx) or idx != list(range(idx[0], idx[0] + len(idx))):
                raise ValueError(f"bands must be distinct and contiguous (D1, D2, D3), got {self.bands}")
        if self.filter == "chord":
            if self.chord_m is None:
                raise ValueError("filter chord needs chord_m (the chord length, m)")
            if self.chord_offset_m is not None and not self.chord_offset_m < self.chord_m:
                raise ValueError(f"chord_offset_m ({self.chord_offset_m:g}) must lie within the chord "
                                 f"(chord_m = {self.chord_m:g})")
        if self.filter == "transfer":
            w, g = self.transfer_wavelength_m, self.transfer_gain
            if w is None or g is None or len(w) != len(g) or len(w) < 2:
                raise ValueError("filter transfer needs transfer_wavelength_m and transfer_gain, two or more "
                                 "values each, of the same length")
            if any(b <= a for a, b in zip(w, w[1:])):
                raise ValueError("transfer_wavelength_m must increase")
            if any(x < 0 for x in g):
                raise ValueError("transfer_gain must be >= 0")
        return self

    @property
    def wavelengths_m(self) -> tuple[float, float]:
        """The EN 13848 bands' (shortest, longest) wavelength, m."""
        edges = [EN13848_BANDS[b] for b in self.bands]
        long = max(e[1] for e in edges)
        return min(e[0] for e in edges), (self.d3_long_m if "D3" in self.bands else long)

    def describe(self) -> str:
        """One phrase naming the band, for reports."""
        if self.filter == "full":
            return "full band"
        if self.filter == "en13848":
            lo, hi = self.wavelengths_m
            return f"EN 13848 {'+'.join(self.bands)} ({lo:g}-{hi:g} m, Butterworth order {self.order})"
        if self.filter == "chord":
            a = self.chord_offset_m if self.chord_offset_m is not None else self.chord_m / 2
            return f"chord {self.chord_m:g} m, measuring point {a:g} m from its rear end"
        return f"user transfer function ({len(self.transfer_gain)} points)"

    def response(self, k: np.ndarray) -> np.ndarray:
        """H(k), complex, at wavenumbers ``k`` (cycles per m, >= 0), ``k.shape``."""
        k = np.asarray(k, dtype=float)
        if self.filter == "full":
            return np.ones_like(k, dtype=complex)
        if self.filter == "en13848":
            lo, hi = self.wavelengths_m
            n = 2 * self.order
            with np.errstate(divide="ignore", over="ignore"):
                high = 1.0 / np.sqrt(1.0 + np.where(k > 0, (1.0 / hi) / np.maximum(k, 1e-300), np.inf) ** n)
            low = 1.0 / np.sqrt(1.0 + (k * lo) ** n)
            return (high * low).astype(complex)
        if self.filter == "chord":
            length = self.chord_m
            a = self.chord_offset_m if self.chord_offset_m is not None else length / 2
            b = length - a
            return 1.0 - (b * np.exp(-2j * np.pi * k * a) + a * np.exp(2j * np.pi * k * b)) / length
        w = np.asarray(self.transfer_wavelength_m, dtype=float)
        with np.errstate(divide="ignore"):
            lam = np.where(k > 0, 1.0 / np.maximum(k, 1e-300), np.inf)
        g = np.interp(np.log(np.minimum(lam, 1e300)), np.log(w), np.asarray(self.transfer_gain, float),
                      left=0.0, right=0.0)
        return g.astype(complex)

    def supported_wavelengths(self) -> tuple[float, float]:
        """(shortest, longest) wavelength in m where |H| >= ``min_gain`` around the largest gain
        (``(0, inf)`` for the full band)."""
        if self.filter == "full":
            return 0.0, math.inf
        lam = np.geomspace(0.05, 5000.0, 20000)
        g = np.abs(self.response(1.0 / lam))
        ok = (g >= self.min_gain * (1 - 1e-12)) & (g <= (1 + 1e-12) / self.min_gain)
        if not ok.any():
            raise ValueError(f"the record's gain never reaches min_gain = {self.min_gain:g}")
        i = int(np.flatnonzero(ok)[-1])      # the run of the longest supported wavelengths (a chord's main lobe)
        j0, j1 = i, i
        while j0 > 0 and ok[j0 - 1]:
            j0 -= 1
        while j1 < lam.size - 1 and ok[j1 + 1]:
            j1 += 1
        return float(lam[j0]), float(lam[j1]) if j1 < lam.size - 1 else math.inf

    def supported_hz(self, speed_mps: float) -> tuple[float, float]:
        """The frequency band (Hz) the record supports at ``speed_mps``: f = v / wavelength."""
        short, long = self.supported_wavelengths()
        return (0.0 if math.isinf(long) else speed_mps / long), (math.inf if short == 0 else speed_mps / short)


def filter_track(segment: TrackSegment, band: TrackBand) -> TrackSegment:
    """``segment`` as a recording car of ``band`` records it: each irregularity channel filtered by H(k) over
    distance (by FFT of the mean-removed record, zero-padded to twice its length so that its ends do not wrap).

    Curvature, cant, speed and name are kept; ``meta['track_band']`` names the band.
    """
    if band.filter == "full":
        return segment
    irr = np.asarray(segment.irregularities, dtype=float)
    n = irr.shape[1]
    m = 2 * n
    k = np.fft.rfftfreq(m, segment.dx)
    mean = irr.mean(axis=1, keepdims=True)
    out = np.fft.irfft(np.fft.rfft(irr - mean, n=m, axis=1) * band.response(k), n=m, axis=1)[:, :n]
    return TrackSegment(segment.name, segment.distance, out, segment.speed,
                        meta=dict(segment.meta) | {"track_band": band.describe()},
                        curvature=segment.curvature, cant=segment.cant)


def band_note(band: TrackBand, speeds_mps: np.ndarray, f_min_hz: float, f_max_hz: float
              ) -> tuple[float, float, str]:
    """The spectra's band restricted to what the record supports on every segment, and one line saying so.

    :param speeds_mps: ``(n_segments,)`` each segment's mean speed.
    :returns: ``(f_min, f_max, note)``: the supported band intersected with ``[f_min_hz, f_max_hz]``
        (unchanged when ``band.restrict`` is false or the record is full band).
    :raises ValueError: no frequency of the spectra is supported on every segment.
    """
    v = np.asarray(speeds_mps, dtype=float)
    if band.filter == "full" or v.size == 0:
        return f_min_hz, f_max_hz, ""
    lo = max(band.supported_hz(float(s))[0] for s in v)
    hi = min(band.supported_hz(float(s))[1] for s in v)
    short, long = band.supported_wavelengths()
    what = (f"the track record ({band.describe()}) supports wavelengths {short:.3g}-{long:.4g} m "
            f"(|H| >= {band.min_gain:g}), at the segments' speeds {v.min() * 3.6:.0f}-{v.max() * 3.6:.0f} km/h "
            f"the band {lo:.3g}-{hi:.3g} Hz on every segment")
    new_lo, new_hi = max(f_min_hz, lo), min(f_max_hz, hi)
    if not band.restrict:
        outside = new_lo > f_min_hz or new_hi < f_max_hz
        return f_min_hz, f_max_hz, what + (f"; the spectra ({f_min_hz:g}-{f_max_hz:g} Hz) reach outside it and "
                                           f"are NOT restricted (track_band.restrict: false): the model's "
                                           f"input lacks track there" if outside else "")
    if not new_hi > new_lo:
        raise ValueError(f"{what}, which leaves nothing of the spectra's {f_min_hz:g}-{f_max_hz:g} Hz")
    if (new_lo, new_hi) == (f_min_hz, f_max_hz):
        return f_min_hz, f_max_hz, what + f"; the spectra ({f_min_hz:g}-{f_max_hz:g} Hz) lie within it"
    return new_lo, new_hi, what + f"; spectra restricted from {f_min_hz:g}-{f_max_hz:g} Hz to {new_lo:.4g}-{new_hi:.4g} Hz"
