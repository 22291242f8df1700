"""Identification on data from an independent train (``tests/independent``): the two-date protocol, scored.

The measurements come from ``tests/independent/``, a train model written apart
from suspid (its own equations, creep model, flexible carbody, elastic track,
recording car, measurement chain; its module docstring lists the differences).
For each seed, :func:`independent.protocol.prepare` writes a reference date at
w0 and a measurement date at w_true (other track segments), fits the noise
model of the reference date against ``exudyn-train`` at w0 on the measured
track, and writes a quickstart-sized config on the measurement date's files
(q = 5, maximin LHS of ``--n-initial`` points, at most ``--max-iter`` EGO
steps, frequency solver); ``suspid.identify`` then runs it once per objective
on the same files.

Printed per (date, seed, objective): the signed error w_opt - w_true of every
component in % of its admissible interval, how many reported intervals contain
w_true, the simulator calls and the wall time. "w0" is a measurement date at
the nominal suspension (nothing to find), "damaged" the quickstart's w_ref
(k_sec_z -21 %, c_sec_z -30 %, k_prim_z +7 %, c_sec_y -31 %, c_yaw -30 %).

    python benchmarks/bench_independent.py [--seeds 7] [--dates w0 damaged] [--objectives overlap likelihood]
        [--segments 24] [--n-initial 30] [--max-iter 40] [--out DIR]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from independent import protocol as PR  # noqa: E402

import suspid  # noqa: E402

DATES = {"w0": {}, "damaged": PR.QUICKSTART_W_REF}
"""Measurement date -> the independent train's parameters on it (empty: its nominal w0)."""


def run_case(config: Path, objective: str, out: Path) -> tuple[dict, float]:
    """``suspid.identify`` on ``config`` with ``objective`` (a copy of the config next to it); result, wall s."""
    cfg = yaml.safe_load(config.read_text(encoding="utf-8"))
    cfg["name"] = f"{config.parent.name}-{objective}"
    cfg["objective"] = {"plugin": objective}
    cfg["output"] = {"dir": str(out)}
    path = config.with_name(f"config-{objective}.yaml")
    path.write_text(yaml.safe_dump(cfg, sort_keys=False), encoding="utf-8")
    t0 = time.perf_counter()
    result = suspid.identify(path, fresh=True).result
    return result, time.perf_counter() - t0


def row(date: str, seed: int, objective: str, result: dict, truth: Path, wall: float) -> str:
    """One table row: signed errors (% of the interval), intervals holding w_true, calls, wall time."""
    w_true = json.loads(truth.read_text())["parameters"]
    cells, held, identifiable = [], 0, 0
    for name in PR.QUICKSTART_W_REF:
        lo, hi = result["bounds"][name]
        error = 100.0 * (result["w_opt"][name] - w_true[name]) / (hi - lo)
        if result["identifiable"].get(name, True):
            a, b = result["interval"][name]
            identifiable += 1
            held += a <= w_true[name] <= b
            cells.append(f"{error:+.1f}")
        else:
            cells.append(f"({error:+.1f}) n.i.")
    return (f"| {date} | {seed} | {objective} | " + " | ".join(cells)
            + f" | {held}/{identifiable} | {result['n_simulator_calls']} | {wall:.0f} |")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[7])
    ap.add_argument("--dates", nargs="+", choices=list(DATES), default=list(DATES))
    ap.add_argument("--objectives", nargs="+", default=["overlap", "likelihood"])
    ap.add_argument("--segments", type=int, default=24, help="segments per date (1000 m each)")
    ap.add_argument("--n-initial", type=int, default=30)
    ap.add_argument("--max-iter", type=int, default=40)
    ap.add_argument("--out", type=Path, default=None, help="folder of the dates and runs (default: a temporary one)")
    a = ap.parse_args(argv)
    base = (a.out or Path(tempfile.mkdtemp(prefix="bench-independent-"))).resolve()
    print(f"# bench_independent  load average {os.getloadavg()[0]:.2f}; {a.segments} segments per date, "
          f"m0 = {a.n_initial}, at most {a.max_iter} EGO steps; files in {base}", flush=True)
    lines = []
    for seed in a.seeds:
        for date in a.dates:
            folder = base / f"{date}-{seed}"
            t0 = time.perf_counter()
            config = PR.prepare(folder, seed=seed, n_segments=a.segments, w_ref=DATES[date],
                                n_initial=a.n_initial, max_iter=a.max_iter)
            print(f"{date} seed {seed}: both dates generated and the noise model fitted in "
                  f"{time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
            truth = folder / "measurement" / "truth.json"
            for objective in a.objectives:
                result, wall = run_case(config, objective, folder / f"run-{objective}")
                lines.append(row(date, seed, objective, result, truth, wall))
                print(lines[-1], file=sys.stderr, flush=True)
    names = list(PR.QUICKSTART_W_REF)
    print("\n| measurement date | seed | objective | " + " | ".join(names)
          + " | identifiable intervals holding w_true | simulator calls | wall (s) |")
    print("|" + " --- |" * (len(names) + 6))
    print("\n".join(lines))
    print(f"\nerrors w_opt - w_true in % of the admissible interval (n.i.: flagged not identifiable, its value "
          f"is not a finding); load average at the end {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
