"""Did EGO converge? Compare a run's w_opt with a Nelder-Mead search on J itself.

For each finished run directory, the script rebuilds the run's problem (the
same measurements, noise paths and objective, from its ``config.yaml``), then
maximises the true J (not the metamodel) by Nelder-Mead in [0, 1]^q from
w_opt, and from w_ref when it is known. It prints, per component in % of the
admissible interval:

- ``EGO``: |w_opt - w_ref|, the run's error;
- ``J max``: |argmax J - w_ref|, the error of the maximiser of J itself, which
  no optimiser can beat: it is set by the data (segments, noise, model error);
- ``EGO to J max``: |w_opt - argmax J|, what the optimiser left on the table.

and J at each point. The run's ledger is copied first; the run is not changed.
About 150-300 evaluations of J per start (~0.1 s each with the frequency solver).

    python benchmarks/check_optimum.py RUN_DIR [RUN_DIR ...] [--maxfev 300]
"""

from __future__ import annotations

import argparse
import json
import shutil
import tempfile
from pathlib import Path

import numpy as np
from scipy.optimize import minimize


def check(run_dir: Path, maxfev: int) -> None:
    from suspid.config import load_config
    from suspid.workflows.evaluation import evaluate
    from suspid.workflows.problem import build_problem
    from suspid.infra.ledger import Ledger
    from suspid.infra.threads import single_blas_thread

    result = json.loads((run_dir / "result.json").read_text())
    with tempfile.TemporaryDirectory() as tmp, single_blas_thread():
        shutil.copy(run_dir / "ledger.sqlite", Path(tmp) / "ledger.sqlite")
        ledger = Ledger(Path(tmp) / "ledger.sqlite")
        problem = build_problem(load_config(run_dir / "config.yaml"), ledger)
        names = problem.names

        def J(u: np.ndarray) -> float:
            return evaluate(problem, ledger, problem.from_unit(np.clip(u, 0.0, 1.0))).J

        def climb(u0: np.ndarray) -> tuple[np.ndarray, float, int]:
            simplex = u0 + 0.03 * np.vstack([np.zeros(len(u0)), np.eye(len(u0))])
            res = minimize(lambda u: -J(u), u0, method="Nelder-Mead",
                           options=dict(maxfev=maxfev, xatol=1e-3, fatol=1e-6, initial_simplex=simplex))
            return np.clip(res.x, 0.0, 1.0), -float(res.fun), int(res.nfev)

        u_opt = np.array([result["w_opt_normalized"][n] for n in names])
        starts = {"w_opt": u_opt}
        u_ref = None
        if "w_ref_normalized" in result:
            u_ref = np.array([result["w_ref_normalized"][n] for n in names])
            starts["w_ref"] = u_ref
        print(f"\n{run_dir}  ({result['objective']}, {result['n_simulator_calls']} simulations)")
        print(f"  J(w_opt) = {J(u_opt):.8g}" + (f", J(w_ref) = {J(u_ref):.8g}" if u_ref is not None else ""))
        width = max(len(n) for n in names)
        for label, u0 in starts.items():
            u_max, j_max, nfev = climb(u0)
            print(f"  Nelder-Mead from {label}: J max = {j_max:.8g} after {nfev} evaluations")
            print(f"    {'component':{width}}  EGO   J max  EGO to J max   (% of interval; * = flagged n.i.)")
            for i, n in enumerate(names):
                flag = "" if result["identifiable"][n] else "*"
                ego_err = f"{100 * abs(u_opt[i] - u_ref[i]):5.2f}" if u_ref is not None else "   - "
                max_err = f"{100 * abs(u_max[i] - u_ref[i]):5.2f}" if u_ref is not None else "   - "
                print(f"    {n:{width}}  {ego_err}  {max_err}  {100 * abs(u_opt[i] - u_max[i]):5.2f}{flag}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run_dirs", nargs="+", type=Path)
    parser.add_argument("--maxfev", type=int, default=300, help="J evaluations per Nelder-Mead start")
    args = parser.parse_args()
    for run_dir in args.run_dirs:
        check(run_dir, args.maxfev)


if __name__ == "__main__":
    main()
