"""EGO against peer Bayesian optimisers on standard test functions: evaluations to reach 1 %.

Usage (2 cores; ~40 min for everything at 5 seeds)::

    python benchmarks/bench_ego.py                              # 5 seeds, all tools, 2 processes
    python benchmarks/bench_ego.py --seeds 10 --functions branin,hartmann3 --tools suspid
    python benchmarks/bench_ego.py --tools skopt --json peers.json   # also save the runs
    python benchmarks/bench_ego.py --merge peers.json,suspid.json    # one table from saved runs

Peers (optional benchmark dependencies, not dependencies of suspid)::

    pip install optuna scikit-optimize torch     # torch: for Optuna's GPSampler

- ``suspid``: :func:`suspid.optimize.ego.maximize` with its defaults
  (``gpy-kriging``, maximin LHS, the EI search of ``EGOOptions``) and tol = 0,
  i.e. in budget mode (EI on a model of the warped J, every third step at the
  maximiser of the mean and once more after such a step missed by a hair,
  stalled basins set aside; see :class:`suspid.optimize.loop.EIProposer`);
- ``suspid-sklearn``: the same with the ``sklearn-gp`` surrogate;
- ``optuna-gp``: Optuna's ``GPSampler`` (log EI on a Matérn 5/2 GP with
  priors), ``n_startup_trials = m0`` random points;
- ``skopt``: scikit-optimize's ``gp_minimize`` (``gp_hedge``),
  ``n_initial_points = m0`` random points.

A tool that is not installed is skipped with a note.

What is measured. Every tool minimises f (Goldstein-Price: log f, a monotone
transform that makes its 3 .. 1e6 range learnable, the same for every tool;
the error is measured on f) with the same m0 initial points and the same
budget of evaluations (initial ones included). ``n_1%`` is the number of
evaluations after which the best point so far is within 1 % of the known
minimum, ``|min_{j<=n} f(x_j) - f*| / |f*| <= 0.01``; a run stops there. A run
that never gets there counts as budget + 100 in the mean and sd
(budget-censored), and is shown as ``>budget``.

BLAS and torch are limited to one thread per process (set before numpy is
imported), so the ``--jobs`` processes use the cores without oversubscription.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import datetime  # noqa: E402
import importlib.util  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402
from concurrent.futures import ProcessPoolExecutor  # noqa: E402

import numpy as np  # noqa: E402

from suspid.optimize.testfunctions import FUNCTIONS  # noqa: E402

SETTINGS = {"branin": (10, 60), "goldstein-price": (10, 100), "hartmann3": (10, 60), "hartmann6": (30, 200)}
"""Function -> (m0, budget): initial points and total evaluations, the same for every tool."""

PUBLISHED = {"branin": (21, 25), "goldstein-price": (44, 46), "hartmann3": (23, 48), "hartmann6": (131, 170)}
"""Evaluations to 1 %, range over six Kriging-based methods (Int. J. Aerospace Eng. 2023, Table 4)."""

TOOLS = {"suspid": "suspid", "suspid-sklearn": "sklearn", "optuna-gp": "optuna", "skopt": "skopt"}
"""Tool -> the module it needs."""

CENSOR = 100
"""A run that never reaches 1 % counts as budget + CENSOR."""


class _Tracker:
    """The function seen by a tool: f (or log f) with the running best; raises Reached at 1 %."""

    def __init__(self, name: str) -> None:
        self.f = FUNCTIONS[name]
        self.log = name == "goldstein-price"
        self.n = 0
        self.best = math.inf
        self.n_hit: int | None = None

    def __call__(self, x) -> float:
        value = float(self.f.func(np.asarray(x, dtype=float)))
        self.n += 1
        self.best = min(self.best, value)
        if self.n_hit is None and abs(self.best - self.f.f_min) / abs(self.f.f_min) <= 0.01:
            self.n_hit = self.n
        return math.log(value) if self.log else value


def _suspid(track: _Tracker, m0: int, budget: int, seed: int, surrogate: str = "gpy-kriging") -> None:
    from suspid.optimize.ego import maximize

    maximize(lambda x: -track(x), track.f.bounds, n_initial=m0, max_iter=budget - m0, tol=0.0, seed=seed,
             surrogate=surrogate, callback=lambda record: track.n_hit is not None)


def _suspid_sklearn(track: _Tracker, m0: int, budget: int, seed: int) -> None:
    _suspid(track, m0, budget, seed, surrogate="sklearn-gp")


def _optuna(track: _Tracker, m0: int, budget: int, seed: int) -> None:
    import optuna

    optuna.logging.set_verbosity(optuna.logging.ERROR)
    bounds = track.f.bounds
    study = optuna.create_study(sampler=optuna.samplers.GPSampler(seed=seed, n_startup_trials=m0))

    def objective(trial):
        return track([trial.suggest_float(f"x{i}", lo, hi) for i, (lo, hi) in enumerate(bounds)])

    def stop(study, trial):
        if track.n_hit is not None:
            study.stop()

    study.optimize(objective, n_trials=budget, callbacks=[stop])


def _skopt(track: _Tracker, m0: int, budget: int, seed: int) -> None:
    from skopt import gp_minimize

    gp_minimize(track, [(float(lo), float(hi)) for lo, hi in track.f.bounds], n_calls=budget,
                n_initial_points=m0, random_state=seed, callback=lambda res: track.n_hit is not None)


RUNNERS = {"suspid": _suspid, "suspid-sklearn": _suspid_sklearn, "optuna-gp": _optuna, "skopt": _skopt}


def run_one(tool: str, name: str, seed: int) -> dict:
    """One run of ``tool`` on function ``name``: evaluations to 1 % (None if never) and the time."""
    warnings.simplefilter("ignore")  # routine conditioning notes would flood the output
    m0, budget = SETTINGS[name]
    track = _Tracker(name)
    t0 = time.perf_counter()
    RUNNERS[tool](track, m0, budget, seed)
    return {"tool": tool, "name": name, "seed": seed, "n_1pct": track.n_hit, "n": track.n,
            "best_rel": abs(track.best - track.f.f_min) / abs(track.f.f_min),
            "seconds": time.perf_counter() - t0}


def table(rows: list[dict], names: list[str], tools: list[str]) -> str:
    """The markdown table: per function and tool, n_1% per seed and the censored mean ± sd."""
    out = ["| function | q | m0 | budget | tool | n_1% per seed | mean ± sd (censored) | reached 1 % | "
           "worst rel. error at the end | s/run | published |",
           "|---|---|---|---|---|---|---|---|---|---|---|"]
    for name in names:
        m0, budget = SETTINGS[name]
        means = {}
        for tool in tools:
            rs = sorted((r for r in rows if r["name"] == name and r["tool"] == tool), key=lambda r: r["seed"])
            if rs:
                means[tool] = np.mean([r["n_1pct"] or budget + CENSOR for r in rs])
        for tool in tools:
            rs = sorted((r for r in rows if r["name"] == name and r["tool"] == tool), key=lambda r: r["seed"])
            if not rs:
                continue
            vals = np.array([r["n_1pct"] or budget + CENSOR for r in rs], dtype=float)
            per_seed = ", ".join(str(r["n_1pct"]) if r["n_1pct"] else f">{budget}" for r in rs)
            mean = f"{vals.mean():.1f} ± {vals.std(ddof=1) if len(vals) > 1 else 0.0:.1f}"
            if means[tool] == min(means.values()):
                mean = f"**{mean}**"
            lo, hi = PUBLISHED[name]
            out.append(f"| {name} | {FUNCTIONS[name].q} | {m0} | {budget} | {tool} | {per_seed} | {mean} | "
                       f"{sum(1 for r in rs if r['n_1pct'])}/{len(rs)} | "
                       f"{100 * max(r['best_rel'] for r in rs):.2g} % | "
                       f"{np.mean([r['seconds'] for r in rs]):.0f} | {lo}-{hi} |")
    return "\n".join(out)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=5, help="seeds 0 .. N-1 (default 5)")
    parser.add_argument("--jobs", type=int, default=2, help="worker processes (default 2)")
    parser.add_argument("--functions", default=",".join(SETTINGS),
                        help="comma-separated subset of " + ", ".join(SETTINGS))
    parser.add_argument("--tools", default=",".join(TOOLS), help="comma-separated subset of " + ", ".join(TOOLS))
    parser.add_argument("--json", help="also write the runs (one dict each) to this JSON file")
    parser.add_argument("--merge", help="comma-separated JSON files written by --json: print their table, run nothing")
    args = parser.parse_args(argv)
    if args.merge:
        rows = [r for path in args.merge.split(",") for r in json.loads(open(path).read())]
        names = [n for n in SETTINGS if any(r["name"] == n for r in rows)]
        print(table(rows, names, [t for t in TOOLS if any(r["tool"] == t for r in rows)]))
        return
    names = [n.strip() for n in args.functions.split(",") if n.strip()]
    tools = [t.strip() for t in args.tools.split(",") if t.strip()]
    for label, chosen, known in (("function", names, SETTINGS), ("tool", tools, TOOLS)):
        unknown = sorted(set(chosen) - set(known))
        if unknown:
            parser.error(f"unknown {label}(s) {', '.join(unknown)}; choose from {', '.join(known)}")
    missing = [t for t in tools if importlib.util.find_spec(TOOLS[t]) is None]
    for t in missing:
        print(f"note: {t} skipped, module {TOOLS[t]!r} is not installed")
    tools = [t for t in tools if t not in missing]
    seeds = list(range(args.seeds))
    # longest runs first, so that the pool finishes together
    tasks = sorted(((t, n, s) for n in names for t in tools for s in seeds), key=lambda t: -SETTINGS[t[1]][1])
    t0 = time.perf_counter()
    load_before = os.getloadavg()[0]
    rows = []
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        for row in pool.map(run_one, *zip(*tasks)):
            rows.append(row)
            print(f"  {row['tool']} {row['name']} seed {row['seed']}: n_1% {row['n_1pct']}, "
                  f"{row['seconds']:.0f} s", file=sys.stderr, flush=True)
    print(f"EGO benchmark, {datetime.date.today().isoformat()}, seeds {seeds[0]}..{seeds[-1]}, {args.jobs} "
          f"processes, {time.perf_counter() - t0:.0f} s wall, load average {load_before:.1f} at the start, "
          f"{os.getloadavg()[0]:.1f} at the end")
    print(table(rows, names, tools))
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(rows, fh, indent=1)


if __name__ == "__main__":
    main()
