"""Do channel weights estimated at the reference date narrow a finished run's sampling interval?

For a finished run of ``bench_model_form.py`` this estimates the ``objective.weights: efficient`` weights at the
reference date, at w0 (:func:`suspid.workflows.weights.reference_channel_replicates`: 2q simulations on the
reference track, cached in the run's ledger), then evaluates them OUT OF SAMPLE on the measurement date's
replicates at the run's w_opt (:func:`sampling_width_channels.replicates`, no simulation): each component's
diagonal sandwich half-width (2σ, replicates' mean curvature, % of the interval) with equal weights, with the
reference date's weights (criteria ``trace`` and ``log``, shrunk by λ toward equal, each component keeping ρ of
its equal-weight curvature share; ``objective.weights: efficient`` is trace, λ 0, ρ 0.75) and with the
measurement date's own (in-sample) optimum. J's maximiser moves with α, so this is a first look, not the grid's figure.

Run it on a COPY of the case directory (it writes the reference date's simulations into the run's ledger)::

    python benchmarks/efficient_weights_check.py CASE/likelihood.yaml
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("config", type=Path, nargs="+", help="runs' configurations (each run is runs/<stem> beside it)")
    ap.add_argument("--shrink", type=float, nargs="*", default=[0.0, 0.25, 0.5])
    ap.add_argument("--keep-share", type=float, nargs="*", default=[0.0, 0.75],
                    help="each component's kept share of the curvatures (0.75: objective.weights: efficient)")
    args = ap.parse_args(argv)
    from sampling_width_channels import replicates
    from suspid.config import load_config
    from suspid.infra.ledger import Ledger
    from suspid.method.weights import component_variances, efficient_weights
    from suspid.workflows.problem import build_problem
    from suspid.workflows.weights import reference_channel_replicates

    for cfg in args.config:
        run = cfg.parent / "runs" / cfg.stem
        res = json.loads((run / "result.json").read_text())
        config = load_config(cfg)
        ledger = Ledger(run / "ledger.sqlite")
        problem = build_problem(config, ledger)
        names, n = problem.names, len(problem.channels)
        opts = config.identifiability
        g0, c0, n_sims = reference_channel_replicates(problem, ledger, opts.step, opts.n_redraws,
                                                      opts.bootstrap == "paired")
        u = np.array([res["w_opt_normalized"][k] for k in names])
        G, C, _ = replicates(problem, ledger, u, opts.step, opts.n_redraws, opts.bootstrap == "paired",
                             opts.bootstrap_reference)
        Vm = np.stack([np.cov(G[:, k, :], rowvar=False) for k in range(problem.q)])
        cm = C.mean(axis=0)
        equal = np.full(n, 1.0 / n)

        def row(label: str, a: np.ndarray) -> None:
            hw = 200 * np.sqrt(component_variances(a, Vm, cm))
            print(f"  {label:24s} " + " ".join(f"{x:9.1f}" for x in hw))

        print(f"\n{cfg}  ({problem.config.objective.plugin}, {len(problem.reference_segments)} reference segments, "
              f"{g0.shape[0]} replicates, {n_sims} simulations)")
        print(f"  {'measurement-date half-width %':24s} " + " ".join(f"{k:>9s}" for k in names))
        row("equal", equal)
        cand = {}
        for crit in ("trace", "log"):
            for rho in args.keep_share:
                for lam in args.shrink:
                    est = efficient_weights(g0, c0, crit, lam, rho)
                    cand[(crit, lam, rho)] = est.alpha
                    row(f"ref {crit} λ={lam:g} ρ={rho:g}", est.alpha)
        own = efficient_weights(G, C, "trace").alpha
        row("in-sample trace", own)
        row("in-sample log", efficient_weights(G, C, "log").alpha)
        ref_eq = 200 * np.sqrt(component_variances(equal, np.stack([np.cov(g0[:, k, :], rowvar=False)
                                                                    for k in range(problem.q)]), c0.mean(0)))
        print(f"  {'ref date, equal':24s} " + " ".join(f"{x:9.1f}" for x in ref_eq))
        print(f"  {'channel':26s} {'ref trace':>9s} {'ref log':>9s} {'ref trace ρ':>11s} {'in-sample':>9s}")
        rho = args.keep_share[-1]
        for j, ch in enumerate(problem.channels):
            print(f"  {ch:26s} {cand[('trace', 0.0, 0.0)][j]:9.3f} {cand[('log', 0.0, 0.0)][j]:9.3f} "
                  f"{cand[('trace', 0.0, rho)][j]:11.3f} {own[j]:9.3f}")
        ledger.close() if hasattr(ledger, "close") else None
    return 0


if __name__ == "__main__":
    sys.exit(main())
