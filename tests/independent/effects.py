"""Hidden effects written into the independent train's measurements, for testing ``suspid diagnose``.

Nothing here calls suspid's effect implementations (nor anything else of
suspid's, except in :func:`prepare`, the consumer side, which fits the
reference-date noise model and writes a config as a user would). Each hidden
effect acts on the independent train (:mod:`.train`) or on its measurement
chain, in the frequency domain, before the sensor noise floor, the anti-alias
filter, the calibration and segment gains of :class:`.train.Instrument`:

- :class:`FlexibleCarbody`: the train's own bending mode (its modal model,
  :func:`.train.build_model`), on the measurement date only; the reference date
  runs a rigid carbody;
- :class:`BracketResonance`: a 2nd-order base-excited resonance of one
  accelerometer's bracket, H = (ω0² + 2jζω0ω) / (ω0² - ω² + 2jζω0ω), on one channel;
- :class:`CalibrationGain`: a gain on some channels (a mis-calibrated bogie);
- :class:`SensorTilt`: a lateral accelerometer tilted by α about the
  longitudinal axis reads cos α a_lat + sin α a_vert of its point (the vertical
  channel at the same point);
- :class:`WheelPolygon`: a periodic vertical wheel input a cos(2π k s / (πD) + φ_j)
  per listed wheelset (s the distance it rolled, φ_j its own phase), through
  the train's response to a vertical input under that wheelset.

Several effects combine; data at several speeds are written in one folder.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Mapping, NamedTuple, Sequence

import numpy as np
from scipy.fft import next_fast_len

from . import track as T
from . import train as TR


@dataclass(frozen=True)
class FlexibleCarbody:
    """The carbody's first vertical bending mode at ``frequency_hz`` (the train's own modal model)."""

    frequency_hz: float = 9.5
    damping: float = 0.02


@dataclass(frozen=True)
class BracketResonance:
    """A resonance of the bracket of one accelerometer (``channel``): a base-excited oscillator."""

    channel: str = "carbody_middle_vertical"
    frequency_hz: float = 14.0
    damping: float = 0.05

    def filter(self, f: np.ndarray) -> np.ndarray:
        w, w0 = 2 * math.pi * np.asarray(f, dtype=float), 2 * math.pi * self.frequency_hz
        return (w0 ** 2 + 2j * self.damping * w0 * w) / (w0 ** 2 - w ** 2 + 2j * self.damping * w0 * w)


@dataclass(frozen=True)
class CalibrationGain:
    """A calibration gain on ``channels`` (default: the front bogie's)."""

    channels: tuple[str, ...] = ("bogie_front_vertical", "bogie_front_lateral")
    gain: float = 1.25


@dataclass(frozen=True)
class SensorTilt:
    """A lateral accelerometer tilted by ``angle_deg`` about the longitudinal axis."""

    channel: str = "bogie_front_lateral"
    angle_deg: float = 6.0


@dataclass(frozen=True)
class WheelPolygon:
    """Polygonal wheels of ``order`` on ``wheelsets`` (1 leads), each with its own phase."""

    order: int = 1
    amplitude_m: float = 1.0e-4
    wheelsets: tuple[int, ...] = (2, 3)
    phases_rad: tuple[float, ...] = (0.3, 2.1)
    diameter_m: float = 0.92


HIDDEN = (FlexibleCarbody, BracketResonance, CalibrationGain, SensorTilt, WheelPolygon)


def simulate(w: Mapping[str, float] | None, hidden: Sequence = (), *, seed: int, n_segments: int,
             speed_mps: float, length_m: float = 600.0, instrument: TR.Instrument = TR.Instrument(),
             instrument_seed: int = 0, chainage_m: float = 10_000.0, prefix: str = "seg") -> list[TR.SegmentRecord]:
    """As :func:`.train.simulate_segments` (the same measurement process), with ``hidden`` effects."""
    v = float(speed_mps)
    fs_int = instrument.fs_hz * instrument.oversampling
    dx = v / fs_int
    i0 = int(round(TR.PAD_M / dx))
    n_ext = next_fast_len(int(math.ceil((length_m + 2 * TR.PAD_M) / dx)), real=True)
    n_out = max(2, int(round(length_m / v * instrument.fs_hz)))
    f = np.fft.rfftfreq(n_ext, d=1.0 / fs_int)
    bend = [h for h in hidden if isinstance(h, FlexibleCarbody)]
    p_over = dict(w or {})
    if bend:
        p_over |= {"f_bend": bend[0].frequency_hz, "zeta_bend": bend[0].damping}
    model = TR.build_model(p_over, v, flexible=bool(bend))
    H = np.zeros((f.size, len(TR.CHANNELS), 4, 4), dtype=complex)
    H[1:] = model.sensor_response(2 * math.pi * f[1:])
    x_ws = TR.wheelset_positions(TR.parameters(p_over))
    delays = np.exp(2j * math.pi * f[:, None] * x_ws[None, :] / v)
    Hd = np.einsum("fcjk,fj->fck", H, delays)
    # the chain: tilt (mixing at the sensor), bracket (the sensor's mount), gain (its calibration)
    ch = {c: i for i, c in enumerate(TR.CHANNELS)}
    mix = np.eye(len(TR.CHANNELS), dtype=complex)[None].repeat(f.size, axis=0)      # (F, ch, ch)
    for h in hidden:
        if isinstance(h, SensorTilt):
            i, j = ch[h.channel], ch[h.channel.replace("lateral", "vertical")]
            a = math.radians(h.angle_deg)
            row = np.zeros(len(TR.CHANNELS))
            row[i], row[j] = math.cos(a), math.sin(a)
            mix[:, i, :] = row[None]
    chain = np.ones((f.size, len(TR.CHANNELS)), dtype=complex)
    for h in hidden:
        if isinstance(h, BracketResonance):
            chain[:, ch[h.channel]] *= h.filter(f)
        if isinstance(h, CalibrationGain):
            for c in h.channels:
                chain[:, ch[c]] *= h.gain
    polygons = [h for h in hidden if isinstance(h, WheelPolygon)]
    aa = instrument.antialias(f)
    gains = instrument.calibration(instrument_seed)
    sigma = instrument.noise_asd * math.sqrt(fs_int / 2.0)
    s = np.arange(n_ext) * dx
    out = []
    for k in range(n_segments):
        rng_track = np.random.default_rng([int(seed), 1, k])
        rng_rec = np.random.default_rng([int(seed), 2, k])
        rng_meas = np.random.default_rng([int(seed), 3, k])
        rng_wheel = np.random.default_rng([int(seed), 5, k])
        true = T.true_track(n_ext, dx, rng_track, 1.0)
        U = np.fft.rfft(true, axis=1)
        A = np.einsum("fck,kf->cf", Hd, U)
        for poly in polygons:
            start = rng_wheel.uniform(0, 2 * math.pi)          # where the wheels are at the segment start
            for j, phase in zip(poly.wheelsets, poly.phases_rad):
                z = poly.amplitude_m * np.cos(2 * math.pi * poly.order * s / (math.pi * poly.diameter_m)
                                              + phase + start)
                A += H[:, :, j - 1, 0].T * np.fft.rfft(z)[None, :]
        A = np.einsum("fcd,df->cf", mix, A) * chain.T
        noise = np.fft.rfft(sigma * rng_meas.standard_normal((len(TR.CHANNELS), n_ext)), axis=1)
        a_int = np.fft.irfft((A + noise) * aa[None, :], n_ext, axis=1)
        idx = (i0 + instrument.oversampling * np.arange(n_out)) % n_ext
        seg_gain = 1.0 + instrument.segment_gain_std * rng_meas.standard_normal(len(TR.CHANNELS))
        acc = a_int[:, idx] * (gains * seg_gain)[:, None]
        offsets, measured = T.record(true, dx, i0 * dx, length_m, T.RecordingCar(), rng_rec)
        start_m = chainage_m + k * (length_m + 500.0)
        out.append(TR.SegmentRecord(f"{prefix}-{k + 1:03d}", v, start_m + offsets, measured, instrument.fs_hz,
                                    acc, seg_gain))
    return out


def generate_date(out_dir: str | Path, w: Mapping[str, float] | None, hidden: Sequence = (), *, seed: int,
                  n_segments: int, speeds_kmh: Sequence[float] = (300.0,), length_m: float = 600.0,
                  instrument_seed: int = 0, chainage_m: float = 10_000.0,
                  instrument: TR.Instrument = TR.Instrument()) -> Path:
    """Write one date's files (``track/``, ``accelerations/``, ``truth.json``): ``n_segments`` per speed."""
    out = Path(out_dir)
    recs = []
    for i, kmh in enumerate(speeds_kmh):
        recs += simulate(w, hidden, seed=int(seed) * 10 + i, n_segments=n_segments, speed_mps=kmh / 3.6,
                         length_m=length_m, instrument_seed=instrument_seed, instrument=instrument,
                         chainage_m=chainage_m + i * 100_000.0, prefix=f"v{int(kmh)}")
    for rec in recs:
        TR._write_atomic(out / "track" / f"{rec.name}.csv", TR._track_csv(rec))
        TR._write_atomic(out / "accelerations" / f"{rec.name}.csv", TR._accelerations_csv(rec))
    truth = {"parameters": TR.parameters(w), "given": dict(w or {}), "seed": seed, "speeds_kmh": list(speeds_kmh),
             "hidden": [{"type": type(h).__name__, **asdict(h)} for h in hidden]}
    TR._write_atomic(out / "truth.json", json.dumps(truth, indent=1, sort_keys=True) + "\n")
    return out


VERTICAL_W_REF = {"k_sec_z": 340.0e3, "c_sec_z": 14.0e3, "k_prim_z": 1.30e6}
"""A damaged vertical suspension (the quickstart's values): what the experiments identify."""

SPECTRA = {"f_min_hz": 0.4, "f_max_hz": 40.0, "n_freqs": 200}


def prepare(out_dir: str | Path, hidden: Sequence = (), *, seed: int = 3, n_segments: int = 40,
            n_reference: int = 48, speeds_kmh: Sequence[float] = (300.0,),
            w_ref: Mapping[str, float] | None = None, w_reference: Mapping[str, float] | None = None,
            identified: Sequence[str] = tuple(VERTICAL_W_REF), diagnose: Mapping | None = None,
            ego: Mapping | None = None, noise: Mapping | None = None, noise_asd: float | None = None) -> Path:
    """Both dates (the reference date without ``hidden``, at ``w_reference``, default w0; the measurement date
    with it, at ``w_ref``, default w0 too), the reference noise model and a ``suspid diagnose`` config; returns
    its path.

    The measurement date is at w0 by default: the noise model of the reference date absorbs the model-form error
    of suspid's model against this train at w0 only, and a suspension change leaves a discrepancy of its own
    (``VERTICAL_W_REF``: 15-25 % of the cells flagged without any hidden effect), which is not what these
    experiments are about.

    The consumer side: uses suspid to fit the noise model (with the ``noise:`` options ``noise``, e.g. a
    sensor-noise floor) and reads nothing of the truth. ``noise_asd``: the sensors' white noise (m/s²/√Hz) on
    both dates (default: :class:`.train.Instrument`'s).
    """
    from .protocol import fit_reference_noise, write_config
    import yaml

    out = Path(out_dir).resolve()
    w_mes = dict(w_ref or {})
    inst = TR.Instrument() if noise_asd is None else TR.Instrument(noise_asd=noise_asd)
    ref = generate_date(out / "reference", w_reference, (), seed=2 * seed + 1, n_segments=n_reference,
                        speeds_kmh=speeds_kmh, instrument_seed=seed, instrument=inst)
    mes = generate_date(out / "measurement", w_mes, hidden, seed=2 * seed + 2, n_segments=n_segments,
                        speeds_kmh=speeds_kmh, instrument_seed=seed, chainage_m=200_000.0, instrument=inst)
    noise_path = fit_reference_noise(ref, out / "noise.npz", spectra=SPECTRA, noise=noise)
    path = write_config(out / "config.yaml", mes, noise_path, seed=seed, objective="likelihood", n_initial=16,
                        max_iter=20, identified=tuple(identified))
    cfg = yaml.safe_load(path.read_text())
    cfg["spectra"] = dict(SPECTRA)
    cfg["ego"] = dict(ego or {"max_iter": 20})
    cfg["diagnose"] = {"n_bootstrap": 100, **dict(diagnose or {})}
    path.write_text(yaml.safe_dump(cfg, sort_keys=False), encoding="utf-8")
    return path


def parameter_errors(diagnosis: Mapping, truth_json: str | Path, result_json: str | Path | None = None
                     ) -> dict[str, dict[str, float]]:
    """Per identified parameter, the error before and after (``gap_*['w']``): in % of the true value
    (``gap_before``, ``gap_after``) and, with a run's ``result.json`` (its bounds), signed in % of the admissible
    interval (``gap_before_interval``, ``gap_after_interval``), suspid's own measure."""
    truth = json.loads(Path(truth_json).read_text())["parameters"]
    bounds = json.loads(Path(result_json).read_text())["bounds"] if result_json is not None else {}
    out = {}
    for stage in ("gap_before", "gap_after"):
        w = (diagnosis.get(stage) or {}).get("w") or {}
        out[stage] = {n: 100.0 * abs(v - truth[n]) / abs(truth[n]) for n, v in w.items() if n in truth}
        if bounds:
            out[stage + "_interval"] = {n: 100.0 * (v - truth[n]) / (bounds[n][1] - bounds[n][0])
                                        for n, v in w.items() if n in truth and n in bounds}
    return out


def main(argv: list[str] | None = None) -> None:
    import argparse

    ap = argparse.ArgumentParser(description="write a hidden-effect experiment on the independent train")
    ap.add_argument("out_dir", type=Path)
    ap.add_argument("case", choices=sorted(CASES))
    ap.add_argument("--seed", type=int, default=3)
    ap.add_argument("--segments", type=int, default=40)
    ap.add_argument("--damaged", action="store_true", help="measurement date at VERTICAL_W_REF")
    a = ap.parse_args(argv)
    case = CASES[a.case]
    print(prepare(a.out_dir, case.hidden, seed=a.seed, n_segments=a.segments, n_reference=a.segments + 8,
                  speeds_kmh=case.speeds, w_ref=VERTICAL_W_REF if a.damaged else case.w_ref,
                  noise_asd=case.noise_asd))


SENSOR_NOISE_ASD = 7.5e-4
"""White sensor noise, m/s²/√Hz: 0.005 m/s² rms in the 0-40 Hz band the anti-alias filter passes (a
realistic floor for service accelerometers and their cabling; the instrument's default is a quiet laboratory's)."""


class Case(NamedTuple):
    """One experiment: the hidden effects, the speeds (km/h) and the measurement date's suspension (None: w0,
    as the reference date's)."""

    hidden: tuple
    speeds: tuple[float, ...]
    w_ref: Mapping[str, float] | None = None
    noise_asd: float | None = None


CASES: dict[str, Case] = {
    "none": Case((), (300.0,)),
    "two-speeds": Case((), (200.0, 300.0)),
    "other-suspension": Case((), (300.0,), VERTICAL_W_REF),
    "bending": Case((FlexibleCarbody(9.5, 0.02),), (300.0,)),
    "bracket": Case((BracketResonance("carbody_middle_vertical", 14.0, 0.05),), (300.0,)),
    "gain": Case((CalibrationGain(),), (300.0,)),
    "tilt": Case((SensorTilt("bogie_front_lateral", 6.0),), (300.0,)),
    "polygon": Case((WheelPolygon(1, 1.0e-4, (2, 3)),), (200.0, 300.0)),
    "bending+tilt": Case((FlexibleCarbody(9.5, 0.02), SensorTilt("bogie_front_lateral", 6.0)), (300.0,)),
    "shared-tilt": Case(tuple(SensorTilt(c, 4.0) for c in ("bogie_front_lateral", "bogie_rear_lateral",
                                                            "carbody_middle_lateral")), (300.0,),
                        noise_asd=SENSOR_NOISE_ASD),
    "bracket-lateral": Case((BracketResonance("carbody_front_lateral", 14.0, 0.05),), (300.0,),
                            noise_asd=SENSOR_NOISE_ASD),
    "polygon-one": Case((WheelPolygon(1, 1.0e-4, (3,), (0.3,)),), (200.0, 300.0)),
    "gain-8": Case((CalibrationGain(("bogie_rear_vertical",), 1.08),), (300.0,)),
}
"""The experiments (``other-suspension``: no hidden effect, the measurement date at :data:`VERTICAL_W_REF`)."""


if __name__ == "__main__":
    main()
