"""How often do the reported intervals contain w_ref? Coverage over seeds of the quickstart experiment.

Each seed is a new numerical experiment (track, noise paths, model-error
draws, design). The quickstart config runs for both objectives with the local
refinement on (``ego.refine``, so that w_opt is the maximiser of J and the
intervals are judged, not the optimiser), as a ``suspid study`` with
``study.seeds``: the runs land in ``OUT/variants/<objective>-seed<s>/`` and are
resumed from their ledgers when the script is run again. The script prints,
per objective, the share of intervals (± ``identifiability.n_sigmas`` σ, 2 by
default: nominal 95 % for a Gaussian estimator) on identifiable components
that contain w_ref, per component and overall, and the errors |w_opt - w_ref|
against the interval half-widths.

    python benchmarks/bench_coverage.py [--seeds 20] [--out runs/coverage] [--set key=value ...] [--workers 2]

With ``--workers N`` the study's runs go to N processes (each run as the study
would run it, skipping a run that has its ``result.json``: delete it to redo),
then the study is reported from them (``suspid study --report-only``).
"""

from __future__ import annotations

import argparse
import datetime
import multiprocessing
import platform
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def run_one(job: tuple[Path, list[str], str]) -> tuple[str, float]:
    """One run of the study (its config as the study derives it), in a worker process; returns its wall time."""
    import time

    from suspid.config import load_config
    from suspid.workflows.identify import run
    from suspid.workflows.study import study_variants

    config_path, overrides, label = job
    t = time.perf_counter()
    study_run = next(r for r in study_variants(config_path, overrides, load_config(config_path, overrides))
                     if r.label == label)
    run(study_run.config)
    return label, time.perf_counter() - t


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=20, help="seeds 1..N")
    parser.add_argument("--out", type=Path, default=ROOT / "runs" / "coverage")
    parser.add_argument("--config", type=Path, default=ROOT / "configs" / "quickstart.yaml")
    parser.add_argument("--set", dest="sets", action="append", default=[], metavar="KEY=VALUE",
                        help="more config overrides, e.g. identifiability.bootstrap=paired")
    parser.add_argument("--workers", type=int, default=1, help="processes running the study's runs")
    args = parser.parse_args()

    import suspid

    overrides = [f"output.dir={args.out}", "ego.refine={enabled: true}",
                 f"study.seeds=[{', '.join(str(s) for s in range(1, args.seeds + 1))}]",
                 "study.variants=[{name: likelihood, set: {objective.plugin: likelihood}}, "
                 "{name: overlap, set: {objective.plugin: overlap}}]", *args.sets]
    if args.workers > 1:
        from suspid.config import load_config
        from suspid.workflows.study import study_variants

        labels = [r.label for r in study_variants(args.config, overrides, load_config(args.config, overrides))
                  if not (r.config.run_dir() / "result.json").is_file()]
        with ProcessPoolExecutor(args.workers, mp_context=multiprocessing.get_context("spawn")) as pool:
            for label, wall in pool.map(run_one, [(args.config, overrides, label) for label in labels]):
                print(f"{label}: {wall:.0f} s", flush=True)
    study_dir = suspid.study(args.config, overrides, report_only=args.workers > 1).study_dir

    import json

    results = json.loads((study_dir / "study.json").read_text())
    print(f"# bench_coverage  {datetime.date.today()}  python {platform.python_version()}  "
          f"config {args.config.name}, seeds 1-{args.seeds}, ego.refine on {' '.join(args.sets)}")
    for objective in ("likelihood", "overlap"):
        runs = [r for label, r in results.items() if r["objective"] == objective]
        names = runs[0]["parameters"]
        print(f"\n## {objective}: {len(runs)} runs\n")
        print("| component | identifiable in | interval contains w_ref | mean half-width (% of interval) "
              "| RMS error (% of interval) | RMS error / mean half-width × 2 |")
        print("| --- | --- | --- | --- | --- | --- |")
        hits = total = 0
        for n in names:
            rows = [r for r in runs if r["identifiable"][n]]
            inside = [r["interval_normalized"][n][0] <= r["w_ref_normalized"][n] <= r["interval_normalized"][n][1]
                      for r in rows]
            half = np.array([100 * (r["interval_normalized"][n][1] - r["interval_normalized"][n][0]) / 2
                             for r in rows])
            err = np.array([r["errors_percent"][n] for r in rows])
            hits, total = hits + sum(inside), total + len(rows)
            if rows:
                rms = float(np.sqrt(np.mean(err ** 2)))
                print(f"| {n} | {len(rows)}/{len(runs)} | {sum(inside)}/{len(rows)} | {half.mean():.2f} "
                      f"| {rms:.2f} | {2 * rms / half.mean():.2f} |")
            else:
                print(f"| {n} | 0/{len(runs)} | - | - | - | - |")
        print(f"\noverall: {hits}/{total} = {100 * hits / max(total, 1):.0f} % of intervals contain w_ref "
              f"(nominal 95 % for ± 2 σ); the last column is about 1 when the half-width is 2 RMS errors")


if __name__ == "__main__":
    main()
