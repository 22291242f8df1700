"""Example recordings of an instrumented train, for ``suspid ingest``: one per format.

A test run over a long synthetic track (German low-level spectra): a station
stop, an acceleration, a cruise at 300 km/h, a braking and a stop. The
accelerations come from suspid's built-in model (``exudyn-train``, time
solver, variable speed) on the track under the car, plus sensor noise; the
track recording car's record starts ``offset_m`` before the odometry's zero,
uses its own step (0.5 m) and millimetres. Each file is written with its own
format's library, with the channel names and units of a data-acquisition
system (the ingest file maps them back):

| file | library | content |
| --- | --- | --- |
| ``recording.mf4`` | asammdf | accelerations at ``fs`` Hz, speed at 50 Hz (its own time base) |
| ``recording.mat`` | scipy.io.savemat (v5) | one time vector ``t``, speed and odometry ``ODO`` on it |
| ``recording-v73.mat`` | h5py (MATLAB 7.3 layout: HDF5 with a 512-byte header) | the same |
| ``recording.tdms`` | npTDMS | waveform channels (``wf_increment``), speed at 50 Hz |
| ``recording.csv`` | numpy text | ``time_s``, one column per channel with ``[unit]``, ``ODO [m]`` |
| ``track-record.csv`` | numpy text | distance (m), LL, AL, XL, GA in mm |

Beside them: ``suspid.yaml`` (the simulator with the four recorded sensors),
``ingest-<format>.yaml``, ready for ``suspid ingest``, ``measured.yaml`` (a
measured-data config on what ``ingest-mf4.yaml`` writes, for ``suspid
validate``); ``truth.json`` holds the offset and the speed profile.

With ``--reference REF_DIR`` (a folder this script wrote before, e.g. with another ``--seed``: the
reference date) it also writes ``identify.yaml`` (the simulator, five parameters, their example
``limits:``, the spectra) and ``ingest-two-dates.yaml``: the measurement date's first format here and the
reference date's recording in REF_DIR, for ``suspid ingest`` to write both dates and
``ingested/two-dates.yaml``. ``--param NAME=VALUE`` (SI, repeatable) gives the vehicle of this date a
parameter other than exudyn-train's nominal one: a worn element for the measurement date to find.

Run: ``python examples/recordings/make_recordings.py OUT_DIR [--formats mf4 mat ...] [--reference REF_DIR]
[--param c_yaw=150e3] [--cruise-km 9]`` (about a minute of computing, the time solver at variable speed;
the default 9 km at 300 km/h gives 9 segments of 1000 m, one more than the reference-date self-check's 8;
tests call :func:`make` with a ``tmp_path`` and a shorter run). Nothing is written unless every format's
library is there (mf4 needs asammdf, tdms npTDMS: ``pip install 'suspid[ingest]'``); the files are written
in a folder beside OUT_DIR and moved in once all are written.
"""

from __future__ import annotations

import argparse
import functools
import datetime as dt
import importlib
import json
import math
import os
import shutil
import sys
import tempfile
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np
import yaml

from suspid.data.track import realise
from suspid.interfaces import IRREGULARITY_CHANNELS, TrackSegment
from suspid.plugins.simulators.exudyn_train import ExudynTrain

G = 9.80665
FORMATS = ("mf4", "mat", "mat73", "tdms", "csv")

# simulator channel -> (recorded name, unit written in the file, factor from m/s^2 to that unit)
CHANNELS = {
    "carbody_front_vertical": ("ACC_Z_K1", "mm/s^2", 1e3),
    "carbody_middle_lateral": ("ACC_Y_K2", "mm/s^2", 1e3),
    "bogie_front_vertical": ("ACC_Z_B1", "g", 1 / G),
    "bogie_front_lateral": ("ACC_Y_B1", "m/s^2", 1.0),
}
TRACK_CHANNELS = {"vertical": "LL", "lateral": "AL", "cross_level": "XL", "gauge": "GA"}


@dataclass(frozen=True)
class Profile:
    """Speed profile of the test run (m/s, m, s)."""

    cruise_kmh: float = 300.0
    accel_mps2: float = 2.0        # brisk, to keep the files small
    stop_s: float = 4.0
    cruise_m: float = 4000.0

    def speed(self, t: np.ndarray) -> np.ndarray:
        vc, a = self.cruise_kmh / 3.6, self.accel_mps2
        t_acc = vc / a
        t_cruise = self.cruise_m / vc
        t1, t2, t3, t4 = self.stop_s, self.stop_s + t_acc, self.stop_s + t_acc + t_cruise, \
            self.stop_s + 2 * t_acc + t_cruise
        return np.select([t < t1, t < t2, t < t3, t < t4], [0.0 * t, a * (t - t1), vc + 0 * t, vc - a * (t - t3)],
                         0.0 * t)

    @property
    def duration(self) -> float:
        vc = self.cruise_kmh / 3.6
        return 2 * self.stop_s + 2 * vc / self.accel_mps2 + self.cruise_m / vc


@dataclass
class Artefacts:
    """Faults to put into the recording (for tests of the quality checks)."""

    saturate: dict[str, tuple[float, float, float]] = field(default_factory=dict)  # channel -> (level m/s^2, t0, t1)
    dropout: dict[str, tuple[float, float]] = field(default_factory=dict)   # channel -> (t0, t1) s of NaN
    flat: dict[str, tuple[float, float]] = field(default_factory=dict)      # channel -> (t0, t1) s held constant
    spike: dict[str, tuple[float, float]] = field(default_factory=dict)     # channel -> (t s, value m/s^2)
    jitter_s: float = 0.0        # rms jitter of the acceleration time stamps (MDF4 only: it stores them)


def sensors_options() -> list[dict]:
    """The simulator's ``sensors`` option for the four recorded channels (the default sensors of those names)."""
    sim = ExudynTrain()
    return [{"name": s.name, "body": s.body, "direction": s.direction, "position": [float(c) for c in s.position]}
            for s in sim.sensors() if s.name in CHANNELS]


@functools.lru_cache(maxsize=4)
def simulate(profile: Profile, fs: float, offset_m: float, seed: int, noise_mps2: float = 0.004,
             w: tuple[tuple[str, float], ...] = ()):
    """Accelerations ``(4, n)`` m/s^2 on the recording's time grid, speed ``(n,)``, odometry ``(n,)``,
    and the fine track (x in track coordinates, irregularities (4, n_x) m)."""
    n = int(math.floor(profile.duration * fs)) + 1
    t = np.arange(n) / fs
    v = profile.speed(t)
    d = np.concatenate(([0.0], np.cumsum((v[1:] + v[:-1]) / (2 * fs))))
    rng = np.random.default_rng(seed)
    dx = 0.25
    margin = 400.0
    x_track = np.arange(-margin, d[-1] + 2 * margin, dx) + offset_m
    x_track -= x_track[0] % dx                       # a grid of the track record's own origin
    irr = realise("german-low", x_track.size, dx, rng, (2.0, 250.0))
    v_sim = 3.0                                      # below this the train is taken as standing (no input)
    moving = np.flatnonzero(v >= v_sim)
    i_a, i_b = int(moving[0]), int(moving[-1])
    xs = np.arange(0.0, d[i_b] - d[i_a], dx)
    speed_x = np.interp(d[i_a] + xs, d[i_a:i_b + 1], v[i_a:i_b + 1])
    seg_irr = np.array([np.interp(d[i_a] + xs + offset_m, x_track, row) for row in irr])
    seg = TrackSegment("run", xs, seg_irr, np.maximum(speed_x, v_sim))
    sim = ExudynTrain(solver="time", fs_hz=fs, sensors=sensors_options(), taper_m=10.0, step_s=0.001)
    resp = sim.simulate(dict(w), [seg])[0]
    acc = rng.normal(0.0, noise_mps2, (len(CHANNELS), n))
    order = [list(resp.channels).index(c) for c in CHANNELS]
    m = min(resp.accelerations.shape[1], n - i_a)
    acc[:, i_a:i_a + m] += resp.accelerations[order, :m]
    return t, v, d, acc, x_track, irr


def _write_mf4(path: Path, t, acc, t_v, v_kmh, fs):
    from asammdf import MDF, Signal

    mdf = MDF(version="4.10")
    mdf.append([Signal(acc[i] * f, t, name=name, unit=unit) for i, (name, unit, f) in enumerate(CHANNELS.values())],
               comment=f"accelerations {fs:g} Hz")
    mdf.append([Signal(v_kmh, t_v, name="V_TRAIN", unit="km/h")], comment="speed 50 Hz")
    mdf.save(path, overwrite=True)
    mdf.close()


def _mat_vars(t, acc, v_kmh_t, odo) -> dict:
    out = {"t": t, "V_TRAIN": v_kmh_t, "ODO": odo}
    for i, (name, unit, f) in enumerate(CHANNELS.values()):
        out[name] = acc[i] * f
    return out


def _write_mat73(path: Path, variables: dict) -> None:
    """A MATLAB 7.3 file: HDF5 with a 512-byte user block holding MATLAB's text header."""
    import h5py

    with h5py.File(path, "w", userblock_size=512) as f:
        for name, value in variables.items():
            d = f.create_dataset(name, data=np.asarray(value, dtype=float).reshape(1, -1))  # MATLAB n x 1, transposed
            d.attrs["MATLAB_class"] = np.bytes_("double")
    header = (f"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: {dt.datetime(2026, 11, 23):%a %b %d %H:%M:%S %Y} "
              f"HDF5 schema 1.00 .").encode()
    header = header.ljust(116, b" ") + b"\x00" * 8 + b"\x00\x02" + b"IM"
    with open(path, "r+b") as fh:
        fh.write(header.ljust(512, b"\x00"))


def _write_tdms(path: Path, acc, v_kmh_50, fs):
    from nptdms import ChannelObject, GroupObject, RootObject, TdmsWriter

    objs = [RootObject(properties={"title": "suspid example recording"}), GroupObject("acc"), GroupObject("vehicle")]
    for i, (name, unit, f) in enumerate(CHANNELS.values()):
        objs.append(ChannelObject("acc", name, acc[i] * f, properties={
            "wf_increment": 1.0 / fs, "wf_start_offset": 0.0, "unit_string": unit}))
    objs.append(ChannelObject("vehicle", "V_TRAIN", v_kmh_50, properties={
        "wf_increment": 1.0 / 50.0, "wf_start_offset": 0.0, "unit_string": "km/h"}))
    with TdmsWriter(str(path)) as w:
        w.write_segment(objs)


def _write_csv(path: Path, t, acc, v_kmh_t, odo):
    cols = ["time_s"] + [f"{name} [{unit}]" for name, unit, _ in CHANNELS.values()] + ["V_TRAIN [km/h]", "ODO [m]"]
    data = np.column_stack([t] + [acc[i] * f for i, (_, _, f) in enumerate(CHANNELS.values())] + [v_kmh_t, odo])
    with open(path, "w", encoding="utf-8") as fh:
        fh.write("# example recording written by make_recordings.py\n" + ",".join(cols) + "\n")
        np.savetxt(fh, data, delimiter=",", fmt="%.9g")


def _write_track(path: Path, x_track, irr, step: float = 0.5):
    k = int(round(step / (x_track[1] - x_track[0])))
    data = np.column_stack([x_track[::k]] + [irr[i, ::k] * 1e3 for i in range(4)])
    with open(path, "w", encoding="utf-8") as fh:
        fh.write("# track recording car, EN 13848 quantities in mm\n")
        fh.write("dist_m," + ",".join(TRACK_CHANNELS.values()) + "\n")
        np.savetxt(fh, data, delimiter=",", fmt="%.6f")


def ingest_file(fmt: str, recording: str, out_name: str, units: dict[str, str] | None = None) -> dict:
    """The ingest file for one of the recordings."""
    units = units or {}
    channels = {c: {"name": f"acc/{n}" if fmt == "tdms" else n, "unit": units.get(c, u)}
                for c, (n, u, _) in CHANNELS.items()}
    options = {"mf4": {}, "mat": {"index": "t"}, "mat73": {"index": "t"}, "tdms": {},
               "csv": {"index": "time_s"}}[fmt]
    speed = "vehicle/V_TRAIN" if fmt == "tdms" else "V_TRAIN"
    return {
        "config": "suspid.yaml",
        "recording": {"path": recording, "options": options, "channels": channels,
                      "speed": {"name": speed, "unit": "km/h"}},
        "track": {"path": "track-record.csv", "options": {"index": "dist_m"},
                  "channels": {q: {"name": n, "unit": "mm"} for q, n in TRACK_CHANNELS.items()},
                  "step_m": 0.25},
        "alignment": {"channel": "bogie_front_vertical", "lever_m": "model"},
        "segments": {"length_m": 1000.0, "speed_tolerance": 0.02, "min_speed_kmh": 100.0},
        "output": {"dir": f"ingested/{out_name}", "format": "csv"},
    }


FILES = {"mf4": "recording.mf4", "mat": "recording.mat", "mat73": "recording-v73.mat", "tdms": "recording.tdms",
         "csv": "recording.csv"}
LIBRARIES = {"mf4": ("asammdf", "asammdf"), "tdms": ("nptdms", "npTDMS")}
"""Format -> (module, distribution) of the optional libraries that write it (the ``ingest`` extra)."""
PARAMETERS = ("k_sec_z", "c_sec_z", "k_prim_z", "c_sec_y", "c_yaw")
"""The parameters ``identify.yaml`` identifies."""
BOUNDS = {"c_yaw": {"lower": 90.0e3}}
"""``identify.yaml``'s bounds where exudyn-train's do not do: a yaw damper worn to half its rate (150 kN s/m, the
default lower bound) is identified inside the interval, not on its edge."""
LIMITS = {"k_sec_z": {"warning": [-15, 15], "alarm": [-30, 30]}, "c_sec_z": {"warning": -25, "alarm": -40},
          "k_prim_z": {"warning": [-15, 15], "alarm": [-30, 30]}, "c_sec_y": {"warning": -25, "alarm": -40},
          "c_yaw": {"warning": -25, "alarm": -40}}
"""Example warning and alarm levels of ``identify.yaml`` (% of nominal, as configs/quickstart.yaml's): not a
standard, the operator's maintenance rules set them."""


def _importable(module: str) -> bool:
    try:
        importlib.import_module(module)
    except ImportError:
        return False
    return True


def missing_libraries(formats: Sequence[str]) -> list[str]:
    """``'asammdf' (for mf4)``, ...: the libraries the formats need that cannot be imported."""
    return [f"'{dist}' (for {fmt})" for fmt in formats if fmt in LIBRARIES
            for module, dist in [LIBRARIES[fmt]] if not _importable(module)]


def make(out: str | Path, formats: Sequence[str] = FORMATS, *, fs: float = 200.0, offset_m: float = 137.37,
         seed: int = 3, profile: Profile | None = None, artefacts: Artefacts | None = None,
         w: dict[str, float] | None = None) -> dict:
    """Write the recordings, the track record, ``suspid.yaml``, ``ingest-<format>.yaml`` and ``truth.json``.

    :param w: the vehicle's parameters (SI) where they differ from exudyn-train's nominal ones.

    :returns: the truth: offset, profile, files.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    unknown = sorted(set(w or {}) - {p.name for p in ExudynTrain().parameters()})
    if unknown:
        raise ValueError(f"unknown parameter(s) {', '.join(unknown)} of exudyn-train")
    profile = profile or Profile()
    t, v, d, acc, x_track, irr = simulate(profile, fs, offset_m, seed, w=tuple(sorted((w or {}).items())))
    # simulate() is cached: copy what is changed
    acc = acc.copy()
    for c, (level, t0, t1) in (artefacts.saturate if artefacts else {}).items():
        row, sel = list(CHANNELS).index(c), (t >= t0) & (t < t1)
        acc[row, sel] = np.clip(acc[row, sel], -level, level)
    for c, (t0, t1) in (artefacts.dropout if artefacts else {}).items():
        acc[list(CHANNELS).index(c), (t >= t0) & (t < t1)] = np.nan
    for c, (t0, t1) in (artefacts.flat if artefacts else {}).items():
        sel = np.flatnonzero((t >= t0) & (t < t1))
        acc[list(CHANNELS).index(c), sel] = acc[list(CHANNELS).index(c), sel[0]]
    for c, (ts, value) in (artefacts.spike if artefacts else {}).items():
        acc[list(CHANNELS).index(c), int(round(ts * fs))] = value
    t_acc = t
    if artefacts and artefacts.jitter_s:
        t_acc = t + np.random.default_rng(seed + 1).normal(0.0, artefacts.jitter_s, t.size)
        t_acc = np.maximum.accumulate(t_acc)
    v_kmh = np.round(v * 3.6, 2)
    odo = np.round(d, 2)                             # odometry (MAT and CSV), cm resolution
    t_v = np.arange(0.0, t[-1] + 1e-9, 1 / 50.0)
    v_kmh_50 = np.round(profile.speed(t_v) * 3.6, 2)
    _write_track(out / "track-record.csv", x_track, irr)
    simulator = {"plugin": "exudyn-train", "options": {"fs_hz": fs, "sensors": sensors_options()}}
    parameters = {p: {} for p in PARAMETERS}
    (out / "suspid.yaml").write_text(yaml.safe_dump({"name": "recordings", "simulator": simulator,
                                                     "parameters": parameters}, sort_keys=False))
    (out / "measured.yaml").write_text(yaml.safe_dump({   # what `suspid validate` reads after ingest-mf4.yaml
        "name": "measured", "simulator": simulator, "parameters": parameters, "data": {
            "source": "measured", "track_file": "ingested/mf4/track",
            "measurements": "ingested/mf4/accelerations"}}, sort_keys=False))
    for fmt in formats:
        path = out / FILES[fmt]
        if fmt == "mf4":
            _write_mf4(path, t_acc, acc, t_v, v_kmh_50, fs)
        elif fmt == "mat":
            import scipy.io
            scipy.io.savemat(path, _mat_vars(t, acc, v_kmh, odo), oned_as="column")
        elif fmt == "mat73":
            _write_mat73(path, _mat_vars(t, acc, v_kmh, odo))
        elif fmt == "tdms":
            _write_tdms(path, acc, v_kmh_50, fs)
        elif fmt == "csv":
            _write_csv(path, t, acc, v_kmh, odo)
        else:
            raise ValueError(f"unknown format {fmt}; formats: {', '.join(FORMATS)}")
        (out / f"ingest-{fmt}.yaml").write_text(yaml.safe_dump(ingest_file(fmt, FILES[fmt], fmt), sort_keys=False))
    truth = {"offset_m": offset_m, "fs_hz": fs, "seed": seed, "profile": asdict(profile), "w": dict(w or {}),
             "distance_m": float(d[-1]), "duration_s": float(t[-1]), "files": {f: FILES[f] for f in formats},
             "track_channels": list(IRREGULARITY_CHANNELS)}
    (out / "truth.json").write_text(json.dumps(truth, indent=2))
    return truth


def two_date_ingest(out: str | Path, reference: str | Path, fmt: str = "csv", ref_fmt: str | None = None) -> Path:
    """Write ``identify.yaml`` and ``ingest-two-dates.yaml`` in ``out`` (module docstring); returns the latter."""
    out, reference = Path(out), Path(reference)
    ref_fmt = ref_fmt or next(f for f in FORMATS if (reference / FILES[f]).exists())
    config = yaml.safe_load((out / "suspid.yaml").read_text())
    config["simulator"]["options"]["solver"] = "frequency"
    config |= {"name": "recordings-two-dates", "seed": 7, "parameters": {p: BOUNDS.get(p, {}) for p in PARAMETERS},
               "limits": LIMITS,
               "spectra": {"f_min_hz": 0.5, "f_max_hz": 20.0, "n_freqs": 100, "window": "hann"},
               "design": {"n_initial": 30}, "ego": {"max_iter": 30}}
    (out / "identify.yaml").write_text(yaml.safe_dump(config, sort_keys=False))
    meas = ingest_file(fmt, FILES[fmt], "measurement")
    ref = ingest_file(ref_fmt, str((reference / FILES[ref_fmt]).resolve()), "reference")
    ref["track"]["path"] = str((reference / "track-record.csv").resolve())
    meas |= {"config": "identify.yaml", "output": {"dir": "ingested", "format": "csv"},
             "reference": {"recording": ref["recording"], "track": ref["track"]}}
    path = out / "ingest-two-dates.yaml"
    path.write_text(yaml.safe_dump(meas, sort_keys=False))
    return path


def _fail(message: str) -> None:
    """One line on stderr and exit code 2 (a user's mistake or a missing library: no traceback)."""
    print(f"{Path(sys.argv[0]).name}: error: {message}", file=sys.stderr)
    raise SystemExit(2)


def main(argv: Sequence[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("out", type=Path)
    p.add_argument("--formats", nargs="+", default=list(FORMATS), choices=FORMATS)
    p.add_argument("--fs", type=float, default=200.0)
    p.add_argument("--offset", type=float, default=137.37, help="track record offset, m")
    p.add_argument("--seed", type=int, default=3)
    p.add_argument("--cruise-km", type=float, default=9.0, help="length of the cruise at 300 km/h, km (default "
                   "9: 9 segments of 1000 m, the reference-date self-check needs 8)")
    p.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                   help="a parameter of this date's vehicle other than nominal, SI units (repeatable), e.g. "
                        "c_yaw=150e3: a worn yaw damper for the measurement date")
    p.add_argument("--reference", type=Path, default=None, help="folder of the reference date's recording "
                   "(written before by this script): also write ingest-two-dates.yaml")
    a = p.parse_args(argv)
    missing = missing_libraries(a.formats)
    if missing:   # before anything is simulated or written
        _fail(f"writing {' and '.join(missing)} needs the ingest extra: pip install 'suspid[ingest]' (or choose "
              f"other --formats: {', '.join(f for f in FORMATS if f not in LIBRARIES)} need nothing more)")
    if a.reference is not None and not (a.reference / "track-record.csv").is_file():
        _fail(f"--reference {a.reference}: no recording written by this script there (no track-record.csv)")
    known = {q.name for q in ExudynTrain().parameters()}
    w = {}
    for item in a.param:
        name, _, value = item.partition("=")
        if name not in known:
            _fail(f"--param {name}: not a parameter of exudyn-train; known: {', '.join(sorted(known))}")
        try:
            w[name] = float(value)
        except ValueError:
            _fail(f"--param {item}: expected NAME=VALUE with a number (SI units)")
    out = a.out.resolve()
    out.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{out.name}-", dir=out.parent))   # moved in once complete
    try:
        truth = make(staging, a.formats, fs=a.fs, offset_m=a.offset, seed=a.seed,
                     profile=Profile(cruise_m=1000.0 * a.cruise_km), w=w)
        two = two_date_ingest(staging, a.reference, a.formats[0]) if a.reference is not None else None
        out.mkdir(exist_ok=True)
        for f in sorted(staging.iterdir()):
            os.replace(f, out / f.name)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    changed = "".join(f", {name} = {value:g}" for name, value in w.items())
    print(f"wrote {', '.join(truth['files'].values())} and track-record.csv to {out} "
          f"({truth['distance_m'] / 1000:.2f} km, {truth['duration_s']:.0f} s, offset {truth['offset_m']} m{changed})")
    if two is not None:
        print(f"wrote {out / two.name}")


if __name__ == "__main__":
    main()
