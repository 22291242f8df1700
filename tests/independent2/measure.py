"""Track, time integration and the measurement chain of the second independent generator; files.

Nothing here imports suspid or ``tests/independent``: the CSV files are
written in suspid's documented measured-data layout (``track/<segment>.csv``
with ``distance_m,vertical_m,lateral_m,cross_level_m,gauge_m``;
``accelerations/<segment>.csv`` with ``time_s`` and one column per channel;
``# key: value`` header lines) by this module.

Track (:func:`true_track`)
--------------------------
The German low-disturbance spectra (vertical, alignment, cross-level,
gauge; public constants A_v = 4.032e-7, A_a = 2.119e-7, A_g = 0.532e-7 m rad,
Omega_c = 0.8246, Omega_r = 0.0206, Omega_s = 0.4380 rad/m) realised as a
random-phase harmonic series (Rice's method): deterministic amplitudes
sqrt(2 S dOmega) and uniform phases, wavelengths 1.5 to 400 m.
The cross-level spectrum is published for the track's roll angle: the rail
height difference is that angle times the 1.5 m between the contact points.

Recording car (:class:`RecordingCar`)
-------------------------------------
Samples every 0.25 m; a zero-phase band limit like the D1-D3 ranges of EN
13848 (a 4th-order high-pass at 200 m wavelength), white noise, an
odometer offset and a small odometer scale error (the recorded chainage
runs faster or slower than the true one).

Measurement chain (:class:`Instrument`)
---------------------------------------
Every channel: the body acceleration (lateral sensors also g roll) ->
sensor noise (a white floor and a 1/f part below ``flicker_corner_hz``) ->
the IEPE sensor's first-order high-pass (``highpass_hz``) -> a per-channel
calibration gain fixed for the instrumented train (the same on every date,
differing between channels) and a per-channel per-segment gain -> a
linear-phase FIR anti-alias and decimation filter (delay compensated, as a
sigma-delta acquisition does) from the integration rate to ``fs_hz``.
"""

from __future__ import annotations

import json
import math
import os
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np
from scipy import signal
from scipy.interpolate import CubicSpline

from . import kernel as KN
from . import vehicle as VH

TRACK_CHANNELS = ("vertical", "lateral", "cross_level", "gauge")
A_V, A_A, A_G = 4.032e-7, 2.119e-7, 0.532e-7
OMEGA_C, OMEGA_R, OMEGA_S = 0.8246, 0.0206, 0.4380
CONTACT_SPACING = 1.5
"""m, between the wheel-rail contact points (the cross-level angle's arm)."""


def german_low(channel: str, omega: np.ndarray) -> np.ndarray:
    """One-sided PSD m^2/(rad/m) of a track channel at wavenumbers ``omega`` rad/m, shape of ``omega``."""
    o2 = np.asarray(omega, dtype=float) ** 2
    shape = OMEGA_C ** 2 / ((o2 + OMEGA_R ** 2) * (o2 + OMEGA_C ** 2))
    if channel == "vertical":
        return A_V * shape
    if channel == "lateral":
        return A_A * shape
    cross = shape * o2 / (o2 + OMEGA_S ** 2)
    if channel == "cross_level":
        return (A_V / (CONTACT_SPACING / 2) ** 2) * cross * CONTACT_SPACING ** 2
    if channel == "gauge":
        return A_G * cross
    raise KeyError(channel)


def true_track(n: int, dx: float, rng: np.random.Generator, shifts: Sequence[float] = (0.0,),
               lambda_min: float = 1.5, lambda_max: float = 400.0, scale: float = 1.0
               ) -> tuple[np.ndarray, np.ndarray]:
    """Track and its distance derivative under points ``shifts`` m ahead of ``s = dx * arange(n)``.

    :returns: ``values``, ``slopes`` ``(len(shifts), 4, n)`` in m and m/m (rows: vertical, lateral,
        cross_level, gauge). The series is periodic over ``n dx``; the same ``rng`` state gives the same track.
    """
    k = np.arange(n // 2 + 1)
    d_omega = 2 * math.pi / (n * dx)
    omega = k * d_omega
    keep = (omega >= 2 * math.pi / lambda_max) & (omega <= 2 * math.pi / lambda_min)
    vals = np.empty((len(shifts), 4, n))
    slopes = np.empty((len(shifts), 4, n))
    for c, ch in enumerate(TRACK_CHANNELS):
        amp = np.where(keep, np.sqrt(2 * german_low(ch, np.maximum(omega, 1e-9)) * d_omega), 0.0) * scale
        coef = amp * np.exp(1j * rng.uniform(0, 2 * math.pi, omega.size)) * (n / 2)   # irfft of cosines
        for i, sh in enumerate(shifts):
            cs = coef * np.exp(1j * omega * sh)
            vals[i, c] = np.fft.irfft(cs, n)
            slopes[i, c] = np.fft.irfft(1j * omega * cs, n)
    return vals, slopes


@dataclass(frozen=True)
class RecordingCar:
    """How the track is measured: sample step (m), noise (m), odometer offset std (m), odometer scale error
    std (fraction), high-pass wavelength (m)."""

    dx_m: float = 0.25
    noise_std_m: float = 1.5e-4
    odometer_offset_std_m: float = 1.0
    odometer_scale_std: float = 1e-3
    highpass_wavelength_m: float = 200.0


def record_track(track: np.ndarray, dx: float, start_m: float, length_m: float, car: RecordingCar,
                 rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """The recording car's view of ``track`` ``(4, n)`` (periodic, step ``dx``) from ``start_m`` over ``length_m``.

    :returns: nominal offsets ``(n_x,)`` m from the segment start and the recorded values ``(4, n_x)`` m.
    """
    n = track.shape[1]
    kk = np.fft.rfftfreq(n, d=dx)
    spec = np.fft.rfft(track, axis=1)
    if car.highpass_wavelength_m > 0:
        x = (kk * car.highpass_wavelength_m) ** 4
        spec = spec * (x / (1 + x))                       # |H|^2 of a 4th-order high-pass: zero phase
    offset = rng.normal(0.0, car.odometer_offset_std_m)
    scale = 1.0 + rng.normal(0.0, car.odometer_scale_std)
    n_x = int(round(length_m / car.dx_m)) + 1
    nominal = np.arange(n_x) * car.dx_m
    where = start_m + offset + nominal * scale
    filtered = np.fft.irfft(spec, n, axis=1)
    grid = np.arange(n + 1) * dx
    spline = CubicSpline(grid, np.concatenate([filtered, filtered[:, :1]], axis=1), axis=1, bc_type="periodic")
    rec = spline(np.mod(where, n * dx))
    return nominal, rec + rng.normal(0.0, car.noise_std_m, rec.shape)


@dataclass(frozen=True)
class Instrument:
    """The measurement chain (module docstring). ASDs in m/s^2/sqrt(Hz); gains as 1 + std x N(0, 1)."""

    fs_hz: float = 100.0
    noise_asd: float = 2e-4
    flicker_corner_hz: float = 1.0
    highpass_hz: float = 0.1
    calibration_std: float = 0.04
    segment_gain_std: float = 0.015
    fir_taps: int = 161
    fir_cutoff_ratio: float = 0.42

    def calibration(self, instrument_seed: int) -> np.ndarray:
        """``(10,)`` calibration gains of the instrumented train ``instrument_seed`` (differ between channels)."""
        rng = np.random.default_rng([int(instrument_seed), 77])
        return 1.0 + self.calibration_std * rng.standard_normal(len(VH.CHANNELS))


FS_INT = 800.0
"""Hz, integration rate (RK4)."""
RAMP_M, RUN_IN_M = 100.0, 400.0
"""m: the track's amplitude ramps up over RAMP_M, then RUN_IN_M more before the recorded segment."""


def integrate(model: VH.Model, tracks: np.ndarray, slopes: np.ndarray, dx: float, n_steps: int,
              progress: bool = False) -> np.ndarray:
    """RK4 over ``n_steps`` steps of 1/FS_INT for a batch of B segments; returns accelerations
    ``(B, 10, n_steps)`` m/s^2 at the channels (lateral with g roll), sampled at the step starts.

    :param tracks, slopes: ``(B, 4, 4, n_half)`` m and m/m: per segment, wheelset, track channel, on the
        half-step grid ``dx = v / (2 FS_INT)`` (index 2 i at step i).
    """
    n_batch = tracks.shape[0]
    t0 = time.time()
    out = KN.rk4(np.zeros(VH.N_DOF), tracks, slopes, n_steps, 1.0 / FS_INT, *VH.kernel_args(model), model.S,
                 model.S_g)
    if progress:
        print(f"  integrated {n_batch} segments, {n_steps} steps ({time.time() - t0:.0f} s)", flush=True)
    if not np.all(np.isfinite(out)):
        raise FloatingPointError("the time integration diverged (unstable parameters or step)")
    return out


@dataclass
class SegmentRecord:
    """One measured segment: ``distance`` ``(n_x,)`` m, ``track`` ``(4, n_x)`` m, ``accelerations``
    ``(10, n_t)`` m/s^2 at ``fs`` Hz, the segment gains ``(10,)``."""

    name: str
    speed: float
    distance: np.ndarray
    track: np.ndarray
    fs: float
    accelerations: np.ndarray
    segment_gain: np.ndarray = field(default_factory=lambda: np.ones(10))


def _chain(raw: np.ndarray, instrument: Instrument, gains: np.ndarray, rng: np.random.Generator,
           i_start: int, n_out: int) -> np.ndarray:
    """``(10, n_int)`` accelerations at FS_INT -> ``(10, n_out)`` measured at fs from step ``i_start``."""
    n_ch, n = raw.shape
    # sensor noise: white floor plus a 1/f part below the corner
    f = np.fft.rfftfreq(n, d=1.0 / FS_INT)
    asd = instrument.noise_asd * np.sqrt(1.0 + instrument.flicker_corner_hz / np.maximum(f, f[1]))
    white = rng.standard_normal((n_ch, n))
    noise = np.fft.irfft(np.fft.rfft(white, axis=1) * asd * math.sqrt(FS_INT / 2.0), n, axis=1)
    x = raw + noise
    if instrument.highpass_hz > 0:
        b, a = signal.butter(1, instrument.highpass_hz, btype="highpass", fs=FS_INT)
        x = signal.lfilter(b, a, x, axis=1)
    x = x * gains[:, None]
    step = int(round(FS_INT / instrument.fs_hz))
    taps = signal.firwin(instrument.fir_taps, instrument.fir_cutoff_ratio * instrument.fs_hz, fs=FS_INT)
    y = signal.lfilter(taps, 1.0, x, axis=1)
    delay = (instrument.fir_taps - 1) // 2                 # linear phase: compensated
    idx = i_start + delay + step * np.arange(n_out)
    return y[:, idx]


def simulate_segments(w: Mapping[str, float] | None, *, seed: int, n_segments: int, speed_mps: float,
                      length_m: float = 1000.0, instrument: Instrument = Instrument(), instrument_seed: int = 0,
                      recording: RecordingCar = RecordingCar(), track_scale: float = 1.0,
                      chainage_m: float = 10_000.0, batch: int = 20, progress: bool = False
                      ) -> list[SegmentRecord]:
    """The car at ``w`` (kinds and/or elements) over ``n_segments`` independent segments.

    Every draw (track, recording car, sensor noise, segment gains) derives from ``seed`` and the
    segment's index; the calibration gains from ``instrument_seed``.
    """
    v = float(speed_mps)
    model = VH.build(w, v)
    dx = v / (2 * FS_INT)
    step = int(round(FS_INT / instrument.fs_hz))
    n_out = max(2, int(round(length_m / v * instrument.fs_hz)))
    i_start = int(round((RAMP_M + RUN_IN_M) / v * FS_INT))
    tail = instrument.fir_taps                              # the FIR's look-ahead
    n_steps = i_start + step * n_out + tail
    n_half = 2 * n_steps + 1
    n_grid = int(2 ** math.ceil(math.log2(n_half + 2 * 400.0 / dx)))  # periodic over more than the run
    gains = instrument.calibration(instrument_seed)
    ramp_s = np.clip(np.arange(n_half) * dx / RAMP_M, 0.0, 1.0)
    ramp = 0.5 - 0.5 * np.cos(math.pi * ramp_s)
    out: list[SegmentRecord] = []
    for b0 in range(0, n_segments, batch):
        ks = list(range(b0, min(n_segments, b0 + batch)))
        tr = np.empty((len(ks), 4, 4, n_half))
        sl = np.empty_like(tr)
        centre_tracks = []
        for i, k in enumerate(ks):
            rng = np.random.default_rng([int(seed), 11, k])
            vals, slopes = true_track(n_grid, dx, rng, shifts=list(model.x_ws) + [0.0], scale=track_scale)
            tr[i] = vals[:4, :, :n_half] * ramp
            sl[i] = slopes[:4, :, :n_half] * ramp       # the ramp's own slope is left out (run-in only)
            centre_tracks.append(vals[4])
        if progress:
            print(f"segments {ks[0] + 1}-{ks[-1] + 1} of {n_segments}", flush=True)
        acc = integrate(model, tr, sl, dx, n_steps, progress=progress)
        for i, k in enumerate(ks):
            rng_meas = np.random.default_rng([int(seed), 13, k])
            seg_gain = 1.0 + instrument.segment_gain_std * rng_meas.standard_normal(10)
            meas = _chain(acc[i], instrument, gains * seg_gain, rng_meas, i_start, n_out)
            start_s = (i_start * 2) * dx                  # the car centre's position at the record's t = 0
            nominal, rec = record_track(centre_tracks[i], dx, start_s, length_m, recording,
                                        np.random.default_rng([int(seed), 12, k]))
            start = chainage_m + k * (length_m + 500.0)
            out.append(SegmentRecord(f"seg-{k + 1:03d}", v, start + nominal, rec, instrument.fs_hz, meas, seg_gain))
    return out


# ------------------------------------------------------------------------------------------ files
def _write_atomic(path: Path, text: str) -> None:
    """Write ``text`` to a temporary name in the same folder, then rename it over ``path``."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.part")
    try:
        tmp.write_text(text, encoding="utf-8")
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def _csv(header: list[str], columns: list[str], table: np.ndarray) -> str:
    body = "\n".join(",".join([f"{row[0]:.6f}"] + [f"{x:.9e}" for x in row[1:]]) for row in table)
    return "\n".join(header + [",".join(columns)]) + "\n" + body + "\n"


def generate_date(out_dir: str | Path, w: Mapping[str, float] | None, *, seed: int, n_segments: int,
                  speed_mps: float, length_m: float = 1000.0, instrument: Instrument = Instrument(),
                  instrument_seed: int = 0, recording: RecordingCar = RecordingCar(), track_scale: float = 1.0,
                  chainage_m: float = 10_000.0, progress: bool = False) -> Path:
    """Measure one date into ``out_dir/{track,accelerations}/<segment>.csv`` and ``out_dir/truth.json``."""
    out = Path(out_dir)
    recs = simulate_segments(w, seed=seed, n_segments=n_segments, speed_mps=speed_mps, length_m=length_m,
                             instrument=instrument, instrument_seed=instrument_seed, recording=recording,
                             track_scale=track_scale, chainage_m=chainage_m, progress=progress)
    for r in recs:
        _write_atomic(out / "track" / f"{r.name}.csv",
                      _csv(["# suspid track segment", f"# name: {r.name}", f"# speed_mps: {r.speed!r}"],
                           ["distance_m", "vertical_m", "lateral_m", "cross_level_m", "gauge_m"],
                           np.column_stack([r.distance, r.track.T])))
        t = np.arange(r.accelerations.shape[1]) / r.fs
        _write_atomic(out / "accelerations" / f"{r.name}.csv",
                      _csv(["# suspid accelerations", f"# segment: {r.name}", f"# fs_hz: {r.fs!r}"],
                           ["time_s", *VH.CHANNELS], np.column_stack([t, r.accelerations.T])))
    p = VH.parameters(w)
    truth = {"parameters": {k: p[k] for k in VH.KINDS},
             "elements": {e: p[e] for names in VH.ELEMENTS.values() for e in names},
             "own": {k: p[k] for k in VH.OWN}, "given": dict(w or {}), "seed": seed, "speed_mps": speed_mps,
             "length_m": length_m, "instrument": asdict(instrument), "instrument_seed": instrument_seed,
             "recording_car": asdict(recording), "track_scale": track_scale,
             "calibration_gains": dict(zip(VH.CHANNELS, instrument.calibration(instrument_seed).tolist())),
             "segments": [{"name": r.name, "chainage_m": float(r.distance[0]),
                           "segment_gains": dict(zip(VH.CHANNELS, r.segment_gain.tolist()))} for r in recs]}
    # the kind-level truth of an element-level w: the mean of the kind's elements (what one value per kind sees)
    for kind, names in VH.ELEMENTS.items():
        truth["parameters"][kind] = float(np.mean([p[e] for e in names]))
    _write_atomic(out / "truth.json", json.dumps(truth, indent=1, sort_keys=True) + "\n")
    return out


def generate_two_dates(out_dir: str | Path, w0: Mapping[str, float] | None, w_ref: Mapping[str, float], *,
                       seed: int, n_segments: int, speed_mps: float, length_m: float = 1000.0,
                       n_segments_reference: int | None = None, instrument: Instrument = Instrument(),
                       progress: bool = False) -> tuple[Path, Path]:
    """A reference date at ``w0`` and a measurement date at ``w_ref`` (kinds and/or elements), other segments,
    the same instrumented train (calibration gains from ``seed``). Writes ``out_dir/reference`` and
    ``out_dir/measurement``; returns both paths. The interface of ``tests/independent``'s function."""
    out = Path(out_dir)
    common = dict(speed_mps=speed_mps, length_m=length_m, instrument=instrument, instrument_seed=seed,
                  progress=progress)
    ref = generate_date(out / "reference", w0, seed=int(seed) * 2 + 1,
                        n_segments=n_segments_reference or n_segments, chainage_m=10_000.0, **common)
    mes = generate_date(out / "measurement", dict(w0 or {}) | dict(w_ref), seed=int(seed) * 2 + 2,
                        n_segments=n_segments, chainage_m=200_000.0, **common)
    return ref, mes
