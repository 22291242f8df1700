"""Where each objective puts the suspension on data from the independent train, with no hidden effect.

Both dates at the same suspension (w0), the reference-date noise model
fitted at w0: the truth is known, no effect is missing, only the vehicle
differs from suspid's model. On a grid of (k_sec_z, c_sec_z, k_prim_z) around
the truth, the maximiser of J for the likelihood (eq. 6), the overlap (eq. 7-8)
and the mean-spectrum objective (the diagnosis's criterion D up to a constant
factor per channel: squared mean-residual over the noise variance), in % of
each admissible interval. Why ``suspid diagnose`` fits the base model's
suspension under D (docs/diagnose.md, "How it works", step 1).

    python benchmarks/bench_objective_bias.py [--seeds 3 4 5] [--segments 24]

Grid steps: k_sec_z 5 %, c_sec_z 2.5 %, k_prim_z 2 % of the interval; 550 simulations per seed (the frequency
solver, about 30 s).
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import sys
import tempfile
from pathlib import Path

import numpy as np

os.environ.setdefault("SUSPID_DISABLE_PLUGIN_AUTOLOAD", "1")
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from independent import effects as HE  # noqa: E402

from suspid import registry  # noqa: E402
from suspid.config import load_config  # noqa: E402
from suspid.infra.lock import open_run_dir  # noqa: E402
from suspid.method.objective import ObjectiveFunction  # noqa: E402
from suspid.workflows.problem import build_problem  # noqa: E402
from suspid.workflows.tasks import simulate_spectra  # noqa: E402

OBJECTIVES = ("likelihood", "overlap", "mean-spectrum")


def argmax_errors(case_dir: Path) -> dict[str, dict[str, float]]:
    """Per objective, the grid maximiser's error in % of each interval."""
    cfg = load_config(case_dir / "config.yaml")
    truth = json.loads((case_dir / "measurement" / "truth.json").read_text())["parameters"]
    with open_run_dir(case_dir / "grid-run", config_name=cfg.name, config_file=cfg.source_file, fresh=True,
                      log=lambda s: None) as ledger:
        problem = build_problem(cfg, ledger)
    fns = {n: ObjectiveFunction(registry.get("objective", n)(), problem.y_mes, problem.freqs, problem.b,
                                weights=problem.weights, channels=problem.channels,
                                floor=problem.noise_model.floor_) for n in OBJECTIVES}
    widths = {n: hi - lo for n, (lo, hi) in zip(problem.names, problem.bounds)}
    axes = {"k_sec_z": np.linspace(-0.30, 0.15, 10), "c_sec_z": np.linspace(-0.10, 0.15, 11),
            "k_prim_z": np.linspace(-0.04, 0.04, 5)}
    best = {n: (-np.inf, None) for n in OBJECTIVES}
    for a in axes["k_sec_z"]:
        for b in axes["c_sec_z"]:
            for c in axes["k_prim_z"]:
                offset = {"k_sec_z": a, "c_sec_z": b, "k_prim_z": c}
                w = {n: truth[n] + offset[n] * widths[n] for n in problem.names}
                y = simulate_spectra(problem.simulator, w, problem.segments, cfg.spectra)[0]
                for n, fn in fns.items():
                    J = fn.evaluate(y)[0]
                    if J > best[n][0]:
                        best[n] = (J, offset)
    return {n: {k: 100.0 * v for k, v in off.items()} for n, (_, off) in best.items()}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="*", default=[3, 4, 5])
    ap.add_argument("--segments", type=int, default=24)
    args = ap.parse_args()
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"# bench_objective_bias  {datetime.date.today()}  {os.cpu_count()} cpus  load average {load:.2f}  "
          f"{args.segments} segments per date")
    print("| seed | objective | k_sec_z | c_sec_z | k_prim_z |")
    print("|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for seed in args.seeds:
            path = HE.prepare(Path(tmp) / f"none-{seed}", (), seed=seed, n_segments=args.segments,
                              n_reference=args.segments + 8)
            for n, err in argmax_errors(path.parent).items():
                print(f"| {seed} | {n} | {err['k_sec_z']:+.1f} | {err['c_sec_z']:+.1f} | {err['k_prim_z']:+.1f} |",
                      flush=True)


if __name__ == "__main__":
    main()
