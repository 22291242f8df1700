"""Accuracy and speed of the exudyn-train frequency solver on segments with a speed record, against the
time solver (which integrates the varying speed exactly), measured in the same run.

Case: 2 km segments of synthetic track (German low disturbance, dx 0.25 m), speed rising linearly in
distance from 270 to 330 km/h (300 km/h +- 10 %), 10 channels at fs = 100 Hz; each seed draws its own
track and its own parameter vector in the default identification box (a new vector for both solvers:
the frequency solver linearises again, as in an identification). Per seed: the median over channels and
grid frequencies of |Y_frequency - Y_time| (dB, the default spectra grid) and the wall-time ratio time
solver / frequency solver (models built before the timed calls). Prints mean +- sd over the seeds.

Targets: median |dY| <= 0.5 dB; the frequency solver >= 10x faster.

    python benchmarks/bench_variable_speed.py [--seeds 3] [--spread 0.1]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import datetime  # noqa: E402
import platform  # noqa: E402
import subprocess  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from suspid.data.track import synthetic_segments  # noqa: E402
from suspid.interfaces import TrackSegment  # noqa: E402
from suspid.method.spectra import record_spectrum  # noqa: E402
from suspid.plugins.simulators.exudyn_train import ExudynTrain  # noqa: E402

LENGTH_M, SPEED_KMH, FS_HZ, STEP_S = 2000.0, 300.0, 100.0, 0.002


def ramp(seed: int, spread: float) -> TrackSegment:
    seg = synthetic_segments({"spectrum": "german-low", "n_segments": 1, "length_m": LENGTH_M,
                              "speed_kmh": SPEED_KMH, "seed": seed})[0]
    x = seg.distance
    v0 = SPEED_KMH / 3.6
    v = v0 * (1.0 - spread + 2.0 * spread * (x - x[0]) / (x[-1] - x[0]))
    return TrackSegment(f"ramp-{seed}", x, seg.irregularities, v)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=3, help="number of seeds (track and parameter vector)")
    ap.add_argument("--spread", type=float, default=0.1, help="relative speed change each way (0.1: +-10 %%)")
    args = ap.parse_args()
    import exudyn

    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    print(f"# bench_variable_speed  {datetime.date.today()}  commit {commit}  python {platform.python_version()}  "
          f"exudyn {exudyn.__version__}  {os.cpu_count()} cpus  load average {os.getloadavg()[0]:.2f}")
    print(f"# case: {LENGTH_M:g} m, German low, {SPEED_KMH * (1 - args.spread):.0f}-{SPEED_KMH * (1 + args.spread):.0f}"
          f" km/h linear in distance, fs {FS_HZ:g} Hz, time step {STEP_S:g} s, {args.seeds} seeds")
    fsim = ExudynTrain(solver="frequency", fs_hz=FS_HZ)
    tsim = ExudynTrain(solver="time", fs_hz=FS_HZ, step_s=STEP_S)
    bounds = {p.name: (p.lower, p.upper) for p in fsim.parameters()}
    warm = ramp(1000, args.spread)
    fsim.simulate({}, [warm])                      # build the models (and the time solver's symbolic tables)
    tsim.simulate({}, [warm])
    rows = []
    print("| seed | median abs dY (dB) | 90th pct (dB) | time solver (s) | frequency solver (s) | ratio |")
    print("| --- | --- | --- | --- | --- | --- |")
    for seed in range(args.seeds):
        rng = np.random.default_rng(seed)
        w = {n: float(rng.uniform(*bounds[n])) for n in fsim.default_parameters()}
        seg = ramp(seed, args.spread)
        t0 = time.perf_counter()
        (rt,) = tsim.simulate(w, [seg])
        t_time = time.perf_counter() - t0
        t0 = time.perf_counter()
        (rf,) = fsim.simulate(w, [seg])
        t_freq = time.perf_counter() - t0
        d = np.abs(record_spectrum(rf.accelerations, FS_HZ) - record_spectrum(rt.accelerations, FS_HZ))
        rows.append((np.median(d), np.percentile(d, 90), t_time, t_freq, t_time / t_freq))
        print(f"| {seed} | {rows[-1][0]:.3f} | {rows[-1][1]:.3f} | {t_time:.2f} | {t_freq:.3f} | {rows[-1][4]:.1f}x |",
              flush=True)
    a = np.array(rows)
    mean, sd = a.mean(axis=0), a.std(axis=0, ddof=1) if len(a) > 1 else np.zeros(a.shape[1])
    print(f"| mean +- sd | {mean[0]:.3f} +- {sd[0]:.3f} | {mean[1]:.3f} +- {sd[1]:.3f} | {mean[2]:.2f} +- {sd[2]:.2f}"
          f" | {mean[3]:.3f} +- {sd[3]:.3f} | {mean[4]:.1f}x +- {sd[4]:.1f} |")
    print(f"targets: median |dY| <= 0.5 dB: {'met' if mean[0] <= 0.5 else 'NOT met'}; "
          f">= 10x faster: {'met' if mean[4] >= 10 else 'NOT met'}")
    print(f"load average after the run: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
