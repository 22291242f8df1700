"""Executors and batch EGO.

1. Design evaluation with the exudyn *time* solver: the same parameter
   vectors simulated by the ``serial`` executor and by ``processes`` (2
   workers) and ``dask`` (LocalCluster, 2 workers); wall time and speed-up
   against serial, measured in the same run.
2. Batch EGO (``ego.batch`` = 1, 2, 4) on a small numerical experiment with
   the frequency solver and the ``processes`` executor: simulator calls,
   EGO iterations (batches), wall time and the largest error in % of the
   admissible interval.

    python benchmarks/bench_executors.py [--points 8] [--quick]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from suspid import registry
from suspid.workflows.evaluation import simulate_spectra_task
from suspid.data.track import synthetic_segments

EXPERIMENT = """\
name: bench-batch
seed: 11
simulator: {{plugin: exudyn-train, options: {{solver: frequency}}}}
parameters: {{k_sec_z: {{}}, c_sec_z: {{}}, c_sec_y: {{}}}}
data:
  source: experiment
  track: {{spectrum: german-low, n_segments: 16, length_m: 1000.0, speed_kmh: 300.0}}
  w_ref: {{k_sec_z: 340.0e3, c_sec_z: 14.0e3, c_sec_y: 11.0e3}}
spectra: {{f_min_hz: 0.4, f_max_hz: 20.0, n_freqs: 120}}
design: {{n_initial: 12}}
ego: {{max_iter: {m1}, batch: {batch}}}
executor: {{plugin: processes, options: {{workers: 2}}}}
"""


def design_speedup(n_points: int, length_m: float) -> None:
    segments = synthetic_segments({"n_segments": 1, "length_m": length_m, "speed_kmh": 300.0, "seed": 1})
    rng = np.random.default_rng(0)
    ks = 215e3 + rng.random(n_points) * 430e3
    tasks = [("exudyn-train", {"solver": "time"}, {"k_sec_z": float(k)}, segments, {}) for k in ks]
    rows = []
    reference = None
    for name, options in (("serial", {}), ("processes", {"workers": 2}), ("dask", {"n_workers": 2})):
        cls = registry.get("executor", name)
        with cls(**options) as ex:
            if name != "serial":  # warm the workers (imports, exudyn) before timing
                list(ex.map_unordered(simulate_spectra_task, tasks[:2]))
            t0 = time.perf_counter()
            out = dict(ex.map_unordered(simulate_spectra_task, tasks))
            wall = time.perf_counter() - t0
        ys = np.array([out[i] for i in range(len(tasks))])
        if reference is None:
            reference = (wall, ys)
        same = bool(np.array_equal(ys, reference[1]))
        rows.append((name, wall, reference[0] / wall, same))
    print(f"\n1. design of {n_points} points, time solver, one {length_m:.0f} m segment at 300 km/h each")
    print(f"{'executor':<10} {'wall (s)':>9} {'speed-up':>9}  same spectra as serial")
    for name, wall, speedup, same in rows:
        print(f"{name:<10} {wall:9.2f} {speedup:9.2f}  {same}")


def batch_ego(m1: int) -> None:
    from suspid.config import load_config
    from suspid.workflows.identify import run

    print(f"\n2. batch EGO, numerical experiment (q = 3, 16 segments, m0 = 12, m1 = {m1}), processes executor")
    print(f"{'batch':>5} {'calls':>6} {'batches':>8} {'wall (s)':>9} {'max error %':>12}")
    with tempfile.TemporaryDirectory() as tmp:
        for batch in (1, 2, 4):
            cfg = Path(tmp) / f"b{batch}.yaml"
            cfg.write_text(EXPERIMENT.format(m1=m1, batch=batch))
            t0 = time.perf_counter()
            r = run(load_config(cfg), progress=False, log=lambda s: None).result
            wall = time.perf_counter() - t0
            batches = int(np.ceil(r["n_iterations"] / batch))
            print(f"{batch:5d} {r['n_simulator_calls']:6d} {batches:8d} {wall:9.1f} "
                  f"{max(r['errors_percent'].values()):12.2f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=8)
    parser.add_argument("--length-m", type=float, default=1000.0)
    parser.add_argument("--m1", type=int, default=16)
    parser.add_argument("--quick", action="store_true", help="design part only")
    args = parser.parse_args()
    design_speedup(args.points, args.length_m)
    if not args.quick:
        batch_ego(args.m1)


if __name__ == "__main__":
    main()
