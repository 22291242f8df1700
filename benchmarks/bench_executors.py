"""Executors and batch EGO.

1. Design evaluation with the exudyn *time* solver: the same parameter
   vectors simulated by the ``serial`` executor and by ``processes`` (2
   workers) and ``dask`` (LocalCluster, 2 workers); wall time and speed-up
   against serial, measured in the same run.
2. Batch EGO (``ego.batch`` = 1, 2, 4) on a small numerical experiment with
   the frequency solver and the ``processes`` executor: simulator calls,
   EGO iterations (batches), wall time and the largest error in % of the
   admissible interval.
3. ``--whole-run``: one quickstart-sized identification (q = 5, exudyn time
   solver, ``ego.batch: 1``) with the serial, ``processes`` (2 workers) and
   ``dask`` (LocalCluster, 2 workers of one thread) executors in the same
   script run; with two workers EGO runs asynchronously (one point in flight
   per worker). Wall time of the design phase, of the EGO phase and of the
   whole run, the speed-ups against serial, the time of one simulation and of
   one EGO proposal in the driver (the Kriging fits must stay small beside the
   simulations), and the load average. About 6 minutes on 2 idle cores.
4. ``--scheduler-memory``: the resident memory (psutil) of a real ``dask
   scheduler`` process, with two ``dask worker`` processes, while ``--tasks``
   tasks of ``configs/table1.yaml`` run, each task sending its track with its
   item (``simulate_spectra_task``, as before the track was sent once per
   worker) and with the track held by the task function (``SpectraTask``,
   sent once per worker). The tasks do not simulate (a Table 1 simulation
   takes 0.7 s, 500 of them on 2 cores about 3 minutes): they return an
   array of the size of a Table 1 result, so that the scheduler sees the same
   task specifications, data sizes and results as in a run.

    python benchmarks/bench_executors.py [--points 8] [--quick]
    python benchmarks/bench_executors.py --whole-run [--segments 8] [--segment-m 1000] [--m0 20] [--m1 16]
    python benchmarks/bench_executors.py --scheduler-memory [--tasks 500] [--tasks-before 30]
"""

from __future__ import annotations

import argparse
import socket
import subprocess
import sys
import tempfile
import threading
import time
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from suspid import registry
from suspid.workflows.tasks import SpectraTask
from suspid.data.track import synthetic_segments

EXPERIMENT = """\
name: bench-batch-{batch}   # a run directory per batch size (a run directory holds one config)
seed: 11
simulator: {{plugin: exudyn-train, options: {{solver: frequency}}}}
parameters: {{k_sec_z: {{}}, c_sec_z: {{}}, c_sec_y: {{}}}}
data:
  source: experiment
  track: {{spectrum: german-low, n_segments: 16, length_m: 1000.0, speed_kmh: 300.0}}
  w_ref: {{k_sec_z: 280.0e3, c_sec_z: 14.0e3, c_sec_y: 21.0e3}}   # the quickstart's damaged values
spectra: {{f_min_hz: 0.4, f_max_hz: 20.0, n_freqs: 120}}
design: {{n_initial: 12}}
ego: {{max_iter: {m1}, batch: {batch}}}
executor: {{plugin: processes, options: {{workers: 2}}}}
"""


def design_speedup(n_points: int, length_m: float) -> None:
    segments = synthetic_segments({"n_segments": 1, "length_m": length_m, "speed_kmh": 300.0, "seed": 1})
    rng = np.random.default_rng(0)
    ks = 215e3 + rng.random(n_points) * 430e3
    tasks = [{"k_sec_z": float(k)} for k in ks]
    simulate = SpectraTask(registry.get("simulator", "exudyn-train"), {"solver": "time"}, segments, {})
    rows = []
    reference = None
    for name, options in (("serial", {}), ("processes", {"workers": 2}), ("dask", {"n_workers": 2})):
        cls = registry.get("executor", name)
        with cls(**options) as ex:
            if name != "serial":  # warm the workers (imports, exudyn) before timing
                list(ex.map_unordered(simulate, tasks[:2]))
            t0 = time.perf_counter()
            out = dict(ex.map_unordered(simulate, tasks))
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


WHOLE_RUN = """\
name: bench-whole-{executor}
seed: 7
simulator: {{plugin: exudyn-train, options: {{solver: time, fs_hz: 100.0}}}}
parameters: {{k_sec_z: {{}}, c_sec_z: {{}}, k_prim_z: {{}}, c_sec_y: {{}}, c_yaw: {{}}}}
data:
  source: experiment
  track: {{spectrum: german-low, n_segments: {segments}, length_m: {length_m}, speed_kmh: 300.0}}
  w_ref: {{k_sec_z: 280.0e3, c_sec_z: 14.0e3, k_prim_z: 1.28e6, c_sec_y: 21.0e3, c_yaw: 210.0e3}}
  reference: {{model_error_db: 1.5, model_error_scatter_db: 1.0, sensor_noise_rms: 0.005}}
spectra: {{f_min_hz: 0.4, f_max_hz: 20.0, n_freqs: 200}}
objective: {{plugin: overlap}}
design: {{n_initial: {m0}}}
ego: {{max_iter: {m1}, tol: 0.0, explore_tol: 0.0}}
identifiability: {{n_redraws: 4}}
executor: {{plugin: {executor}, options: {options}}}
output: {{dir: {out}}}
"""
WHOLE_RUN_EXECUTORS = (("serial", "{}"), ("processes", "{workers: 2}"),
                       ("dask", "{n_workers: 2, threads_per_worker: 1}"))


def whole_run(segments: int, length_m: float, m0: int, m1: int) -> None:
    """Section 3 of the module docstring."""
    import os

    from suspid.config import load_config
    from suspid.infra.ledger import Ledger
    from suspid.workflows.identify import run

    print(f"\n3. whole run, quickstart's q = 5 and numerical experiment, exudyn time solver, {segments} segments of "
          f"{length_m:g} m at 300 km/h, m0 = {m0}, m1 = {m1} (tol = 0: every run makes m0 + m1 evaluations), "
          f"ego.batch = 1 (asynchronous with 2 workers); load average at the start "
          f"{' '.join(f'{v:.2f}' for v in os.getloadavg())}")
    print(f"{'executor':<10} {'design (s)':>10} {'x':>5} {'EGO (s)':>8} {'x':>5} {'run (s)':>8} {'x':>5} "
          f"{'sim (s)':>8} {'fit (s)':>8} {'load':>5} {'max err %':>9}  w_opt")
    first, w_opts = None, {}
    with tempfile.TemporaryDirectory() as tmp:
        for i, (executor, options) in enumerate(WHOLE_RUN_EXECUTORS):
            cfg = Path(tmp) / f"{executor}.yaml"
            cfg.write_text(WHOLE_RUN.format(executor=executor, options=options, segments=segments,
                                            length_m=length_m, m0=m0, m1=m1, out=Path(tmp) / executor))
            if i == 0:
                load_config(cfg)  # the plugins' imports, once, outside the timings
            t0 = time.time()
            r = run(load_config(cfg), progress=False, log=lambda s: None)
            wall = time.time() - t0
            ledger = Ledger(r.run_dir / "ledger.sqlite")
            evaluations = sorted(ledger.evaluations(), key=lambda e: e.finished_at)
            finished = [e.finished_at for e in evaluations]
            design = finished[m0 - 1] - t0  # start-up, the reference and measurement dates, the m0 design points
            ego = finished[-1] - finished[m0 - 1]  # the m1 EGO points
            sim = float(np.median([e.wall_time_s for e in evaluations[m0:]]))  # EGO points: one simulation each
            steps = [t for t in ledger.trials() if t["phase"] == "ego"]
            fit = float(np.mean([row["fit_seconds"] + row["search_seconds"] for row in steps])) if steps else float("nan")
            times = (design, ego, wall)
            if first is None:
                first = (times, r.w_opt)
            speedups = [a / b for a, b in zip(first[0], times)]
            same = [name for name, w in w_opts.items() if w == r.w_opt]
            w_opts[executor] = r.w_opt
            print(f"{executor:<10} {design:10.1f} {speedups[0]:5.2f} {ego:8.1f} {speedups[1]:5.2f} {wall:8.1f} "
                  f"{speedups[2]:5.2f} {sim:8.2f} {fit:8.2f} {os.getloadavg()[0]:5.2f} {r.max_error_percent:9.2f}  "
                  f"{'the same as ' + ', '.join(same) if same else 'its own'}", flush=True)
    print("sim: median wall time of one EGO point's simulation, from its submission to its J; "
          "fit: mean time of one EGO proposal in the driver (Kriging fits and EI search; asynchronous: the "
          "believer's two fits); x: speed-up against serial; load: 1-min load average at the end of the run; "
          "max err %: largest error of w_opt in % of the admissible intervals; w_opt: asynchronous EGO (2 workers) "
          "chooses other points than the serial loop, the same on processes and dask")


@dataclass(frozen=True)
class ResultOnly(SpectraTask):
    """A Table 1 task that does not simulate: a zero result of the size of a Table 1 one (benchmark only)."""

    shape: tuple = (60, 10, 200)

    def __call__(self, w):
        return np.zeros(self.shape)


def result_only(task: tuple) -> np.ndarray:
    """The item-carries-the-track form: ``(plugin, options, w, segments, spectra)``, result as :class:`ResultOnly`."""
    return np.zeros(ResultOnly.shape)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _wait_listening(port: int, timeout_s: float) -> None:
    """Return once something accepts connections on 127.0.0.1:``port`` (the scheduler we started takes a few
    seconds to listen on a busy machine, and the executor's probe refuses an address nobody listens on)."""
    deadline = time.monotonic() + timeout_s
    while True:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=1.0).close()
            return
        except OSError:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.2)


def scheduler_memory(n_tasks: int, n_tasks_before: int) -> None:
    """Section 4 of the module docstring."""
    import cloudpickle
    from suspid.config import load_config
    from suspid.workflows.problem import synthetic_track

    config = load_config(Path(__file__).resolve().parents[1] / "configs" / "table1.yaml")
    segments = synthetic_track(config, "measurement")
    cls = registry.get("simulator", config.simulator.plugin)
    options = dict(config.simulator.options)
    ws = [{"k_sec_z": 230e3 + i} for i in range(max(n_tasks, n_tasks_before))]
    task = ResultOnly(cls, options, segments, config.spectra)
    print(f"\n4. dask scheduler memory, Table 1 tasks ({len(segments)} segments of "
          f"{config.data.track.length_m:g} m), 2 workers, a new scheduler for each line")
    print(f"   bytes per task: {len(cloudpickle.dumps(ws[0]))} (w only, the task function sent once per worker: "
          f"{len(cloudpickle.dumps(task)) / 1e6:.1f} MB); "
          f"{len(cloudpickle.dumps(('exudyn-train', options, ws[0], segments, config.spectra))) / 1e6:.1f} MB "
          f"with the track in the item")
    print(f"{'tasks':>6} {'track sent':<16} {'RSS idle (MB)':>13} {'peak (MB)':>10} {'per task (MB)':>14} "
          f"{'wall (s)':>9}")
    for label, fn, items in (("with every task", result_only,
                              [("exudyn-train", options, w, segments, config.spectra) for w in ws[:n_tasks_before]]),
                             ("once per worker", task, ws[:n_tasks])):
        base, peak, wall = _scheduler_rss(fn, items)
        print(f"{len(items):6d} {label:<16} {base / 1e6:13.0f} {peak / 1e6:10.0f} "
              f"{(peak - base) / 1e6 / len(items):14.3f} {wall:9.1f}", flush=True)


def _scheduler_rss(fn, items) -> tuple[int, int, float]:
    """``(RSS once connected, peak RSS, wall s)`` of a new ``dask scheduler`` process while ``fn`` maps ``items``."""
    import psutil
    from suspid.plugins.executors.dask import DaskExecutor

    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    quiet = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL}
    procs = [subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1",
                               "--port", str(port), "--no-dashboard"], **quiet)]
    procs += [subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker", address, "--nthreads", "1",
                                "--no-dashboard"], **quiet) for _ in range(2)]
    scheduler = psutil.Process(procs[0].pid)
    try:
        _wait_listening(port, 120.0)
        with DaskExecutor(address=address, n_workers=2, timeout_s=120) as executor:
            time.sleep(1.0)  # let the scheduler settle
            base = scheduler.memory_info().rss
            peak, done = [base], threading.Event()

            def sample() -> None:
                while not done.is_set():
                    peak[0] = max(peak[0], scheduler.memory_info().rss)
                    time.sleep(0.05)

            sampler = threading.Thread(target=sample)
            sampler.start()
            t0 = time.perf_counter()
            with warnings.catch_warnings():  # dask's "large graph" warning: the point of the first line
                warnings.simplefilter("ignore", UserWarning)
                for _ in executor.map_unordered(fn, items):
                    pass
            wall = time.perf_counter() - t0
            done.set()
            sampler.join()
            return base, peak[0], wall
    finally:
        for p in procs:
            p.kill()
            p.wait(timeout=30)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=8)
    parser.add_argument("--length-m", type=float, default=1000.0)
    parser.add_argument("--m1", type=int, default=16)
    parser.add_argument("--quick", action="store_true", help="design part only")
    parser.add_argument("--whole-run", action="store_true", help="only section 3: a whole run per executor")
    parser.add_argument("--segments", type=int, default=8, help="section 3: track segments")
    parser.add_argument("--segment-m", type=float, default=1000.0, help="section 3: length of each segment, m")
    parser.add_argument("--m0", type=int, default=20, help="section 3: initial design size")
    parser.add_argument("--scheduler-memory", action="store_true", help="only section 4")
    parser.add_argument("--tasks", type=int, default=500, help="section 4: tasks, track once per worker")
    parser.add_argument("--tasks-before", type=int, default=30, help="section 4: tasks, track with every task")
    args = parser.parse_args()
    if args.scheduler_memory:
        scheduler_memory(args.tasks, args.tasks_before)
        return
    if args.whole_run:
        whole_run(args.segments, args.segment_m, args.m0, args.m1)
        return
    design_speedup(args.points, args.length_m)
    if not args.quick:
        batch_ego(args.m1)


if __name__ == "__main__":
    main()
