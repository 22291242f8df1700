"""What a curve does to the spectra Y of the exudyn-train records (frequency solver; RESULTS.md has the figures).

Case: 2 km of German low disturbance at 300 km/h, fs 100 Hz, one seed per run (``--seed``), nominal car:
the same irregularities on straight track, in a constant arc (R 4000 m, cant 0.10 m: cant deficiency
1.08 m/s^2) and through an entry clothoid (300 m from 500 m on, then the arc). Prints, per lateral channel,
the median and largest |Y_curve - Y_straight| (dB, default grid 0.3-30 Hz) and the share of grid lines
above 0.5 dB, for the default spectra (boxcar, mean removed), a linear detrend and a Hann window.
Vertical channels: 0 dB in every case (the curve acts laterally and in roll only, to first order).

    python benchmarks/bench_curve_spectra.py [--seed 3]
"""

from __future__ import annotations

import argparse
import datetime
import os
import subprocess

import numpy as np

from suspid.data.track import synthetic_segments
from suspid.method.spectra import record_spectrum
from suspid.plugins.simulators.exudyn_train import ExudynTrain


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=3)
    args = ap.parse_args()
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    print(f"# bench_curve_spectra  {datetime.date.today()}  commit {commit}  seed {args.seed}  "
          f"load average {os.getloadavg()[0]:.2f}")
    base = {"n_segments": 1, "length_m": 2000.0, "speed_kmh": 300.0, "seed": args.seed}
    cases = {"arc": {"radius_m": 4000.0, "cant_m": 0.1},
             "clothoid": {"radius_m": 4000.0, "cant_m": 0.1, "start_m": 500.0, "transition_m": 300.0}}
    segments = [synthetic_segments(base)[0]] + [synthetic_segments({**base, "curve": c})[0] for c in cases.values()]
    sim = ExudynTrain(fs_hz=100.0)
    records = sim.simulate({}, segments)
    lateral = [i for i, c in enumerate(records[0].channels) if c.endswith("lateral")]
    print("| case | spectra | channel | median abs dY (dB) | largest (dB) | lines > 0.5 dB |")
    print("| --- | --- | --- | --- | --- | --- |")
    for label, options in (("boxcar, mean (default)", {}), ("linear detrend", {"detrend": "linear"}),
                           ("hann", {"window": "hann"})):
        y0 = record_spectrum(records[0].accelerations, 100.0, options)
        for name, record in zip(cases, records[1:]):
            d = np.abs(record_spectrum(record.accelerations, 100.0, options) - y0)
            for i in lateral:
                print(f"| {name} | {label} | {records[0].channels[i]} | {np.median(d[i]):.3f} | {d[i].max():.2f} | "
                      f"{100 * np.mean(d[i] > 0.5):.0f} % |")


if __name__ == "__main__":
    main()
