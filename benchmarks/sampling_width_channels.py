"""Where a finished run's sampling interval comes from: the sandwich's gradient noise and curvature, per channel.

The sampling half-width of a component k (``interval_sampling`` in ``result.json``) is the sandwich
2 sd(g_k) / |c_k| (with the metamodel's correlations between components): g_k the gradient of J at w_opt
over bootstrap replicates of the data (the replicates of :func:`suspid.workflows.analysis.bootstrap_objectives`:
reference segments resampled and B fitted again, measured segments resampled in pairs, new noise paths) and
c_k the curvature d²J/du_k² of the run's own J. J = Σ α_ch Ψ_ch, so both split over the channels. This
script redoes the replicates on the run's cached spectra (no simulation) and prints, per component, the
diagonal sandwich with the run's curvature and the replicates' spread of the curvature, and for one component
per channel: the spread of its gradient, the mean and spread of its curvature, and the half-width J would give
without that channel (the same replicates, that channel's α set to 0).

Run it on a COPY of the run directory (the ledger is opened for reading; a resumed run writes into it)::

    python benchmarks/sampling_width_channels.py CASE/likelihood.yaml --parameter k_sec_z

``CASE/likelihood.yaml`` is a configuration written by ``bench_model_form.py``; its run is
``CASE/runs/likelihood``. Half-widths are in % of the admissible interval (2 standard deviations).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np


def replicates(problem, ledger, u: np.ndarray, h: float, n_redraws: int, paired: bool, reference: bool):
    """Per replicate and channel, the α-weighted gradient ``(R, q, n_ch)`` and curvature ``(R, q, n_ch)`` of Ψ at
    w_opt, and the run's own curvature of J ``(q,)`` (central differences over the clipped steps ±h)."""
    from suspid.workflows.analysis import cached_y_sim, second_difference
    from suspid.workflows.evaluation import j_of_spectra
    from suspid.workflows.weights import channel_replicates

    q = problem.q
    plus = [np.clip(u + h * e, 0, 1) for e in np.eye(q)]
    minus = [np.clip(u - h * e, 0, 1) for e in np.eye(q)]
    y0 = cached_y_sim(problem, ledger, u)
    yp = [cached_y_sim(problem, ledger, p) for p in plus]
    ym = [cached_y_sim(problem, ledger, m) for m in minus]
    hp = np.array([p[i] - u[i] for i, p in enumerate(plus)])
    hm = np.array([u[i] - m[i] for i, m in enumerate(minus)])
    c_run = second_difference(j_of_spectra(problem, y0)[0], np.array([j_of_spectra(problem, y)[0] for y in yp]),
                              np.array([j_of_spectra(problem, y)[0] for y in ym]), hp, hm)
    G, C = channel_replicates(problem, y0, yp, ym, hp, hm, n_redraws, paired, reference,
                              lambda r: print(f"\r  replicate {r}/{n_redraws}", end="", file=sys.stderr, flush=True))
    print(file=sys.stderr)
    alpha = np.asarray(problem.weights, float)   # J = Σ α_ch Ψ_ch: each channel's part of J's gradient and curvature
    return G * alpha, C * alpha, c_run


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("config", type=Path, help="the run's configuration (its run is runs/<stem> beside it)")
    ap.add_argument("--parameter", default="k_sec_z", help="the component to split by channel")
    ap.add_argument("--redraws", type=int, default=None, help="bootstrap replicates (default: the run's n_redraws)")
    args = ap.parse_args(argv)
    from suspid.config import load_config
    from suspid.infra.ledger import Ledger
    from suspid.workflows.problem import build_problem

    run = args.config.parent / "runs" / args.config.stem
    if not (run / "result.json").is_file():
        print(f"{run / 'result.json'}: no finished run beside {args.config}", file=sys.stderr)
        return 2
    res = json.loads((run / "result.json").read_text())
    config = load_config(args.config)
    ledger = Ledger(run / "ledger.sqlite")
    problem = build_problem(config, ledger)
    names = problem.names
    if args.parameter not in names:
        print(f"--parameter {args.parameter}: not identified in this run (expected one of {', '.join(names)})",
              file=sys.stderr)
        return 2
    u = np.array([res["w_opt_normalized"][n] for n in names])
    opts = config.identifiability
    G, C, c_run = replicates(problem, ledger, u, opts.step, args.redraws or opts.n_redraws,
                          opts.bootstrap == "paired", opts.bootstrap_reference)
    g, c = G.sum(axis=2), C.sum(axis=2)
    lo = np.array([res["bounds"][n][0] for n in names])
    hi = np.array([res["bounds"][n][1] for n in names])
    stored = np.array([np.diff(res["interval_sampling"][n])[0] / 2 for n in names]) / (hi - lo) * 100
    print(f"{run}  ({len(problem.segments)} segments, {G.shape[0]} replicates, objective {config.objective.plugin})")
    print(f"{'component':10s} {'stored':>7s} {'2sd(g)/|c_run|':>15s} {'c_run':>10s} {'replicates: mean c':>19s} {'cv c':>6s}")
    for k, n in enumerate(names):
        diag = 200 * g[:, k].std(ddof=1) / abs(c_run[k]) if c_run[k] < 0 else float("inf")
        print(f"{n:10s} {stored[k]:7.1f} {diag:15.1f} {c_run[k]:10.3g} {c[:, k].mean():19.3g} "
              f"{c[:, k].std(ddof=1) / abs(c[:, k].mean()):6.2f}")
    k = names.index(args.parameter)
    V, cm = np.cov(G[:, k, :], rowvar=False), C[:, k, :].mean(axis=0)
    ones = np.ones(cm.size)

    def half(alpha: np.ndarray) -> float:
        return 200 * float(np.sqrt(alpha @ V @ alpha)) / abs(float(alpha @ cm))

    print(f"\n{args.parameter} by channel (all channels, replicates' mean curvature: {half(ones):.1f} %)")
    print(f"{'channel':26s} {'sd(g)':>9s} {'mean c':>10s} {'cv c':>6s} {'share of var g':>15s} {'without it':>11s}")
    total = ones @ V @ ones
    for j, ch in enumerate(problem.channels):
        drop = ones.copy()
        drop[j] = 0.0
        cj = C[:, k, j]
        print(f"{ch:26s} {np.sqrt(V[j, j]):9.3g} {cm[j]:10.3g} {cj.std(ddof=1) / abs(cj.mean()):6.2f} "
              f"{(V[j] @ ones) / total:15.2f} {half(drop):10.1f}%")
    return 0


if __name__ == "__main__":
    sys.exit(main())
