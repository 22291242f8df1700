"""Long recordings as a measurement train writes them, from the independent train (no suspid import).

One continuous run per date over a long track, written as a data-acquisition
system and a track recording car deliver it:

- **variable speed**: plateaus at several speeds (default 300, 270, 330 and
  300 km/h: +-10 %) joined by ramps in which the speed changes linearly with
  distance, with a slow +-0.5 % wobble on every plateau;
- **a curve with cant and transitions**: the design curvature and cant rise
  linearly over the transitions, stay constant over the body of the curve;
  the sensors feel the quasi-static lateral acceleration of the cant
  deficiency, v^2 kappa - g cant / 1.5 (left positive, the contact-point
  spacing 1.5 m), and the vertical v^2 kappa cant / 1.5;
- the **accelerations** are the independent car's (:mod:`.train`, linear,
  frequency domain) at each stretch's own mean speed, as functions of the
  car's position, read at the position the train has at every sample (a
  quasi-stationary account of the speed changes; exact on the plateaus),
  through the instrument of :class:`.train.Instrument` (anti-alias filter,
  sensor noise, calibration gains);
- **1 g on the vertical channels** (the accelerometers measure gravity);
- **a slow channel**: one more channel (``ACC_SLOW``, a lateral carbody
  sensor) at 20 Hz, beside the others at ``fs_hz``;
- the **track record** of a recording car: the true track filtered to the
  EN 13848 D1+D2 wavelengths (3-70 m: a zero-phase Butterworth band-pass of
  order 4 per edge, -3 dB at 3 and 70 m), sampled every 0.25 m in mm, with
  the design radius (m, 0 for straight track) and cant (mm) channels, its
  chainage ``offset_m`` ahead of the odometry's (track chainage = odometry
  distance + offset_m).

Files: ``recording.mf4`` (asammdf; accelerations ``ACC_<channel>`` in m/s^2,
speed ``V_TRAIN`` in km/h at 50 Hz, ``ACC_SLOW`` at 20 Hz), ``track-record.csv``
and ``truth.json``.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np
from scipy.fft import next_fast_len
from scipy.interpolate import CubicSpline

from . import track as T
from . import train as TR

G = 9.80665
CONTACT_SPACING = 1.5
"""m, between the wheel-rail contact points: cant / spacing is the track's roll angle."""


@dataclass(frozen=True)
class Route:
    """Speeds and lengths of the run (km/h, m) and the curve (m from the run's start, m, 1/m, m)."""

    plateaus_kmh: tuple[float, ...] = (300.0, 270.0, 330.0, 300.0)
    plateau_m: tuple[float, ...] = (9000.0, 7000.0, 7000.0, 9000.0)
    ramp_m: float = 800.0
    wobble: float = 0.005
    wobble_m: float = 3000.0
    curve_start_m: float = 2000.0
    transition_m: float = 300.0
    curve_body_m: float = 1200.0
    curvature_per_m: float = 1.0 / 7000.0       # a left-hand curve
    cant_m: float = 0.150                        # right (outer) rail above the left

    @property
    def length_m(self) -> float:
        return float(sum(self.plateau_m) + self.ramp_m * (len(self.plateau_m) - 1))

    def speed(self, x: np.ndarray) -> np.ndarray:
        """``(n,)`` m/s at the run's distances ``x`` ``(n,)`` m."""
        knots, values = [], []
        s = 0.0
        for i, (v, length) in enumerate(zip(self.plateaus_kmh, self.plateau_m)):
            knots += [s, s + length]
            values += [v / 3.6, v / 3.6]
            s += length + (self.ramp_m if i < len(self.plateau_m) - 1 else 0.0)
        base = np.interp(x, knots, values)
        return base * (1.0 + self.wobble * np.sin(2 * math.pi * x / self.wobble_m))

    def design(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Curvature (1/m) and cant (m) ``(n,)`` at the run's distances ``x``."""
        a = self.curve_start_m
        shape = np.interp(x, [a, a + self.transition_m, a + self.transition_m + self.curve_body_m,
                              a + 2 * self.transition_m + self.curve_body_m], [0.0, 1.0, 1.0, 0.0],
                          left=0.0, right=0.0)
        return self.curvature_per_m * shape, self.cant_m * shape


def band_d1_d2(k: np.ndarray, order: int = 4, short_m: float = 3.0, long_m: float = 70.0) -> np.ndarray:
    """|H| of the recording car's D1+D2 filter at wavenumbers ``k`` (cycles/m): Butterworth band-pass."""
    k = np.asarray(k, dtype=float)
    with np.errstate(divide="ignore"):
        high = 1.0 / np.sqrt(1.0 + np.where(k > 0, 1.0 / (long_m * np.maximum(k, 1e-300)), np.inf) ** (2 * order))
    return high / np.sqrt(1.0 + (k * short_m) ** (2 * order))


def _stretch_response(w, v: float, track_fine: CubicSpline, x_a: float, x_b: float,
                      instrument: TR.Instrument) -> tuple[np.ndarray, np.ndarray]:
    """The car's accelerations ``(n_channels, n)`` at constant speed ``v`` over the run's [x_a, x_b] (m),
    as functions of the car centre's position ``(n,)`` m (steady state: a periodic stretch with pads)."""
    fs_int = instrument.fs_hz * instrument.oversampling
    dx = v / fs_int
    n = next_fast_len(int(math.ceil((x_b - x_a + 2 * TR.PAD_M) / dx)), real=True)
    s = x_a - TR.PAD_M + np.arange(n) * dx
    true = track_fine(s)                                         # (4, n)
    taper = np.clip(np.minimum(s - s[0], s[-1] - s) / 50.0, 0.0, 1.0)   # periodic closure within the pads
    true = true * taper
    f = np.fft.rfftfreq(n, d=1.0 / fs_int)
    model = TR.build_model(w, v)
    H = np.zeros((f.size, len(TR.CHANNELS), 4, 4), dtype=complex)
    H[1:] = model.sensor_response(2 * math.pi * f[1:])
    delays = np.exp(2j * math.pi * f[:, None] * TR.wheelset_positions(TR.parameters(w))[None, :] / v)
    A = np.einsum("fcjk,fj,kf->cf", H, delays, np.fft.rfft(true, axis=1)) * instrument.antialias(f)[None, :]
    return s, np.fft.irfft(A, n, axis=1)


def long_recording(w: Mapping[str, float] | None, *, seed: int, route: Route = Route(),
                   instrument: TR.Instrument = TR.Instrument(fs_hz=100.0), instrument_seed: int = 0,
                   offset_m: float = 612.3) -> dict:
    """One date's run: accelerations ``(n_channels, n)`` m/s^2 at ``instrument.fs_hz`` (gravity and curve
    included), speed ``(n,)`` m/s, the track record, the design; see the module docstring."""
    rng = np.random.default_rng([int(seed), 21])
    fs_int = instrument.fs_hz * instrument.oversampling
    length = route.length_m
    # the train's position at every integration time: t(x) = integral of dx / v
    x_fine = np.arange(0.0, length, 0.5)
    t_of_x = np.concatenate(([0.0], np.cumsum(0.5 / route.speed(0.5 * (x_fine[1:] + x_fine[:-1])))))
    t = np.arange(0.0, t_of_x[-1], 1.0 / fs_int)
    x = np.interp(t, t_of_x, x_fine)
    # one true track under the whole run (periodic, 0.1 m grid), with margins for the pads and the record
    dx0 = 0.1
    margin = 2 * TR.PAD_M + abs(offset_m) + 600.0
    n0 = next_fast_len(int((length + 2 * margin) / dx0), real=True)
    s0 = -margin + np.arange(n0) * dx0
    true = T.true_track(n0, dx0, rng)
    spline = CubicSpline(s0, true, axis=1)
    # stretches of (nearly) constant speed: every plateau, and each ramp in four parts
    edges = [0.0]
    for i, p in enumerate(route.plateau_m):
        edges.append(edges[-1] + p)
        if i < len(route.plateau_m) - 1:
            edges += list(edges[-1] + route.ramp_m * np.arange(1, 5) / 4)
    acc_int = np.zeros((len(TR.CHANNELS), t.size))
    for x_a, x_b in zip(edges[:-1], edges[1:]):
        v = float(np.mean(route.speed(np.linspace(x_a, x_b, 200))))
        s, a = _stretch_response(w, v, spline, x_a, x_b, instrument)
        sel = (x >= x_a) & (x < x_b) if x_b < edges[-1] else (x >= x_a)
        for c in range(a.shape[0]):
            acc_int[c, sel] = np.interp(x[sel], s, a[c])
    step = instrument.oversampling
    idx = np.arange(0, t.size, step)
    t_out, x_out, acc = t[idx], x[idx], acc_int[:, idx]
    v_out = route.speed(x_out)
    kappa, cant = route.design(x_out)
    phi = cant / CONTACT_SPACING
    lateral = np.array(["lateral" in c for c in TR.CHANNELS])
    vertical = ~lateral
    acc[lateral] += v_out ** 2 * kappa - G * phi                 # cant deficiency, left positive
    acc[vertical] += v_out ** 2 * kappa * phi
    sigma = instrument.noise_asd * math.sqrt(instrument.fs_hz / 2.0)
    acc += sigma * rng.standard_normal(acc.shape)
    acc *= instrument.calibration(instrument_seed)[:, None]
    acc[vertical] += G                                           # the accelerometers measure gravity
    # the recording car: D1+D2, 0.25 m, chainage = odometry + offset_m
    k0 = np.fft.rfftfreq(n0, d=dx0)
    recorded = np.fft.irfft(np.fft.rfft(true, axis=1) * band_d1_d2(k0), n0, axis=1)
    rec_x = np.arange(-400.0, length + 400.0, 0.25)              # odometry distances covered
    rec = CubicSpline(s0, recorded, axis=1)(rec_x) + rng.normal(0.0, 1e-4, (4, rec_x.size))
    kappa_r, cant_r = route.design(rec_x)
    radius = np.where(kappa_r == 0, 0.0, 1.0 / np.where(kappa_r == 0, 1.0, kappa_r))
    return {"t": t_out, "speed": v_out, "accelerations": acc, "track_x": rec_x + offset_m, "track": rec,
            "radius_m": radius, "cant_m": cant_r, "offset_m": offset_m}


def write_recording(out_dir: str | Path, w: Mapping[str, float] | None, *, seed: int, route: Route = Route(),
                    instrument: TR.Instrument = TR.Instrument(fs_hz=100.0), instrument_seed: int = 0,
                    offset_m: float = 612.3) -> Path:
    """Write ``recording.mf4``, ``track-record.csv`` and ``truth.json`` of one date in ``out_dir``."""
    from asammdf import MDF, Signal

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    r = long_recording(w, seed=seed, route=route, instrument=instrument, instrument_seed=instrument_seed,
                       offset_m=offset_m)
    t = r["t"]
    mdf = MDF(version="4.10")
    mdf.append([Signal(r["accelerations"][i], t, name=f"ACC_{c}", unit="m/s^2") for i, c in enumerate(TR.CHANNELS)],
               comment=f"accelerations {instrument.fs_hz:g} Hz")
    t50 = np.arange(0.0, t[-1], 1.0 / 50.0)
    mdf.append([Signal(np.round(np.interp(t50, t, r["speed"]) * 3.6, 2), t50, name="V_TRAIN", unit="km/h")],
               comment="speed 50 Hz")
    slow = TR.CHANNELS.index("carbody_middle_lateral")
    t20 = t[:: int(round(instrument.fs_hz / 20.0))]
    mdf.append([Signal(r["accelerations"][slow, :: int(round(instrument.fs_hz / 20.0))], t20, name="ACC_SLOW",
                       unit="m/s^2")], comment="a slow channel, 20 Hz")
    path = out / "recording.mf4"
    tmp = out / ".recording.mf4.tmp.mf4"
    mdf.save(tmp, overwrite=True)
    mdf.close()
    tmp.replace(path)
    table = np.column_stack([r["track_x"], *(r["track"] * 1e3), r["radius_m"], r["cant_m"] * 1e3])
    with open(out / ".track-record.csv.tmp", "w", encoding="utf-8") as fh:
        fh.write("# track recording car, EN 13848 D1+D2, mm; radius m (0: straight); cant mm\n")
        fh.write("dist_m,LL,AL,XL,GA,RADIUS,CANT\n")
        np.savetxt(fh, table, delimiter=",", fmt="%.6f")
    (out / ".track-record.csv.tmp").replace(out / "track-record.csv")
    truth = {"parameters": TR.parameters(w), "given": dict(w or {}), "seed": seed, "route": asdict(route),
             "instrument": asdict(instrument), "instrument_seed": instrument_seed, "offset_m": offset_m,
             "duration_s": float(t[-1])}
    (out / "truth.json").write_text(json.dumps(truth, indent=1, sort_keys=True) + "\n")
    return out


def ingest_sections(folder: str | Path, channels: Sequence[str] = TR.CHANNELS) -> dict:
    """The ``recording`` and ``track`` sections of a suspid ingest file for a folder :func:`write_recording`
    wrote (plain data: the channel names and units of the files)."""
    folder = Path(folder)
    return {
        "recording": {"path": str(folder / "recording.mf4"),
                      "channels": {c: {"name": f"ACC_{c}", "unit": "m/s^2"} for c in channels},
                      "speed": {"name": "V_TRAIN", "unit": "km/h"}},
        "track": {"path": str(folder / "track-record.csv"), "options": {"index": "dist_m"},
                  "channels": {q: {"name": n, "unit": "mm"} for q, n in
                               zip(T.CHANNELS, ("LL", "AL", "XL", "GA"))},
                  "curvature": {"name": "RADIUS", "quantity": "radius", "unit": "m"},
                  "cant": {"name": "CANT", "unit": "mm"},
                  "band": {"filter": "en13848", "bands": ["D1", "D2"]}},
    }
