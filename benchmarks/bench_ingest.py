"""Speed and memory of ``suspid ingest`` on a one-hour recording: 10 channels at 500 Hz.

Recording (written once with asammdf into ``--work``, reused afterwards): a
one-hour run with three station stops, accelerations and brakings at
0.6 m/s^2, cruises at 300 km/h; the ten channels of exudyn-train's default
sensors at 500 Hz (float64, 1.8 M samples each) in one MDF4 data group, the
speed at 50 Hz in another. The bogie vertical channels are v^2 z''(x + 9.5 m)
of a synthetic German-low track under each bogie plus noise, the others
band-limited noise of the right RMS: what matters here is the volume of data
(the physics of the ingest is tested on exudyn-train recordings in
``tests/test_ingest.py``). The track record is a CSV file in mm at a 0.25 m
step, starting 1234.5 m before the odometry's zero. Output: HDF5.

The ingest runs in a subprocess (so its peak resident memory is its own):
wall time, CPU time, peak RSS (``resource.getrusage``), with ``--tracemalloc``
the peak of the Python allocations (numpy arrays included; slower), and the
file sizes.
Target: under a minute on 2 cores.

    python benchmarks/bench_ingest.py [--work /tmp/suspid-bench-ingest] [--hours 1] [--fs 500]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import datetime  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import resource  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import yaml  # noqa: E402

OFFSET_M = 1234.5
CHANNELS = ["carbody_front_vertical", "carbody_front_lateral", "carbody_middle_vertical", "carbody_middle_lateral",
            "carbody_rear_vertical", "carbody_rear_lateral", "bogie_front_vertical", "bogie_front_lateral",
            "bogie_rear_vertical", "bogie_rear_lateral"]


def speed_profile(hours: float, fs: float, legs: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """Time (s) and speed (m/s): ``legs`` times a stop, an acceleration at 0.6 m/s^2, a cruise at 300 km/h
    and a braking (a leg needs 338 s besides its cruise)."""
    vc, a = 300 / 3.6, 0.6
    total = 3600.0 * hours
    ramp = vc / a
    cruise = (total - legs * (2 * ramp + 60.0)) / legs
    t = np.arange(int(total * fs)) / fs
    v = np.zeros_like(t)
    start = 0.0
    for _ in range(legs):
        t0 = start + 60.0                       # station stop
        t1, t2, t3 = t0 + ramp, t0 + ramp + cruise, t0 + 2 * ramp + cruise
        v = np.where((t >= t0) & (t < t1), a * (t - t0), v)
        v = np.where((t >= t1) & (t < t2), vc, v)
        v = np.where((t >= t2) & (t < t3), vc - a * (t - t2), v)
        start = t3
    return t, v


def make_recording(work: Path, hours: float, fs: float, legs: int = 3) -> tuple[Path, Path, Path]:
    from asammdf import MDF, Signal

    from suspid.data.track import realise

    work.mkdir(parents=True, exist_ok=True)
    tag = "" if legs == 3 else f"-{legs}legs"
    rec, trk = work / f"recording-{hours:g}h-{fs:g}hz{tag}.mf4", work / f"track-{hours:g}h{tag}.csv"
    cfg = work / "suspid.yaml"
    cfg.write_text("name: bench-ingest\nsimulator: {plugin: exudyn-train, options: {fs_hz: %g}}\n" % fs)
    if rec.exists() and trk.exists():
        return rec, trk, cfg
    rng = np.random.default_rng(0)
    t, v = speed_profile(hours, fs, legs)
    d = np.concatenate(([0.0], np.cumsum((v[1:] + v[:-1]) / (2 * fs))))
    dx = 0.25
    x = np.arange(-2000.0, d[-1] + 2000.0, dx) + OFFSET_M
    irr = realise("german-low", x.size, dx, rng, (2.0, 250.0))
    z2 = np.gradient(np.gradient(irr[0], dx), dx)             # z'' of the vertical profile
    signals = []
    for c in CHANNELS:
        if c.startswith("bogie") and c.endswith("vertical"):
            lever = 9.5 if "front" in c else -9.5
            a = v ** 2 * np.interp(d + OFFSET_M + lever, x, z2) + rng.normal(0, 0.05, t.size)
        else:
            rms = 0.2 if c.startswith("carbody") else 1.0
            a = np.convolve(rng.normal(0, rms, t.size), np.ones(5) / np.sqrt(5), mode="same") * (v > 0.5) \
                + rng.normal(0, 0.004, t.size)
        signals.append(Signal(a, t, name=c.upper(), unit="m/s^2"))
    mdf = MDF(version="4.10")
    mdf.append(signals, comment="accelerations")
    t50 = t[:: int(fs // 50)]
    mdf.append([Signal(np.round(v[:: int(fs // 50)] * 3.6, 2), t50, name="V_TRAIN", unit="km/h")], comment="speed")
    mdf.save(rec, overwrite=True)
    mdf.close()
    del signals
    with open(trk, "w", encoding="utf-8") as fh:
        fh.write("dist_m,LL,AL,XL,GA\n")
        np.savetxt(fh, np.column_stack([x, *(irr * 1e3)]), delimiter=",", fmt="%.4f")
    return rec, trk, cfg


def ingest_file(work: Path, rec: Path, trk: Path, cfg: Path) -> Path:
    data = {"config": str(cfg),
            "recording": {"path": str(rec), "channels": {c: {"name": c.upper(), "unit": "m/s^2"} for c in CHANNELS},
                          "speed": {"name": "V_TRAIN", "unit": "km/h"}},
            "track": {"path": str(trk), "options": {"index": "dist_m"},
                      "channels": {q: {"name": n, "unit": "mm"} for q, n in
                                   zip(("vertical", "lateral", "cross_level", "gauge"), ("LL", "AL", "XL", "GA"))}},
            "alignment": {"channel": "bogie_front_vertical", "lever_m": 9.5, "search_m": 2000.0},
            "segments": {"length_m": 1000.0},
            "output": {"dir": str(work / "out"), "format": "hdf5"}}
    path = work / "ingest.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def child(path: Path, trace: bool) -> None:
    """Run the ingest and print one JSON line: wall, CPU, peaks (tracemalloc slows numpy-heavy code
    twofold: it runs only with --tracemalloc, and then the times are not the ones to quote).

    The libraries the ingest uses are imported before tracemalloc starts: their modules (some 80 MiB
    of Python objects for asammdf, pandas and matplotlib) are not data. Peak RSS includes them.
    """
    import importlib
    import tracemalloc

    import suspid

    for module in ("asammdf", "h5py", "matplotlib.pyplot", "scipy.signal"):
        importlib.import_module(module)

    if trace:
        tracemalloc.start()
    w0, c0 = time.perf_counter(), time.process_time()
    r = suspid.ingest(path)
    wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    peak = tracemalloc.get_traced_memory()[1] if trace else float("nan")
    print(json.dumps({"wall_s": wall, "cpu_s": cpu, "tracemalloc_peak_mb": peak / 2 ** 20,
                      "maxrss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                      "segments": len(r.segments), "offset_m": r.offset_m, "peak_ratio": r.peak_ratio,
                      "warnings": r.warnings}))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--work", type=Path, default=Path("/tmp/suspid-bench-ingest"))
    p.add_argument("--hours", type=float, default=1.0)
    p.add_argument("--fs", type=float, default=500.0)
    p.add_argument("--tracemalloc", action="store_true", help="also trace Python allocations (slower)")
    p.add_argument("--child", type=Path, help=argparse.SUPPRESS)
    a = p.parse_args()
    if a.child:
        child(a.child, a.tracemalloc)
        return
    w0 = time.perf_counter()
    rec, trk, cfg = make_recording(a.work, a.hours, a.fs)
    print(f"recording ready in {time.perf_counter() - w0:.1f} s: {rec} ({rec.stat().st_size / 2 ** 20:.0f} MiB), "
          f"{trk} ({trk.stat().st_size / 2 ** 20:.0f} MiB)")
    path = ingest_file(a.work, rec, trk, cfg)
    out = subprocess.run([sys.executable, __file__, "--child", str(path)] + ["--tracemalloc"] * a.tracemalloc,
                         capture_output=True, text=True)
    if out.returncode:
        sys.exit(out.stderr)
    res = json.loads(out.stdout.strip().splitlines()[-1])
    print(f"{datetime.date.today()} {platform.node()} {os.cpu_count()} cores, python {platform.python_version()}")
    print(f"ingest of {a.hours:g} h x {len(CHANNELS)} channels at {a.fs:g} Hz: wall {res['wall_s']:.1f} s "
          f"(cpu {res['cpu_s']:.1f} s), {res['segments']} segments, offset {res['offset_m']:.2f} m "
          f"(true {OFFSET_M}, peak ratio {res['peak_ratio']:.2f})")
    print(f"memory: peak RSS {res['maxrss_mb']:.0f} MiB, tracemalloc peak {res['tracemalloc_peak_mb']:.0f} MiB; "
          f"recording file {rec.stat().st_size / 2 ** 20:.0f} MiB (peak RSS / file = "
          f"{res['maxrss_mb'] / (rec.stat().st_size / 2 ** 20):.2f})")
    if res["warnings"]:
        print("warnings:", *res["warnings"], sep="\n  ")


if __name__ == "__main__":
    main()
