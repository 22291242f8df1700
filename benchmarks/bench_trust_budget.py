"""Model-error checks within budget: the linearised checks against the full ones, on the independent train.

For every seed, measurement-date suspension w_ref and objective, the independent
train of ``tests/independent`` writes a reference date at w0 and a measurement
date at w_ref (as ``bench_model_form.py``); ``suspid run`` identifies w with
``identifiability.model_error.method: linearised`` (the model parameters of
``--nuisance`` as the checked ones, calibration off, so that both methods check
the same ranges). Then, on the same problem, ledger and w_opt, in this process:

- the **full** checks (:func:`suspid.workflows.analysis.model_error`, method
  ``full``: self-check splits, data groups and nuisance ends re-identified by
  simulation);
- the **linearised** checks again with the calibration of the model parameters
  at the reference date on (``calibrated``).

A component's flag is its trustworthiness under model error (the checks'
reasons, and the "too uncertain" verdict of the bias-aware half-width,
:func:`suspid.workflows.analysis.imprecise`). Printed per run: the flags of each
method, the simulations each check took, the identification's simulations;
then the agreement of linearised and full over all components (the target is
>= 90 %) and each method's total simulator calls against the identification's.

Usage (from the repository root)::

    python benchmarks/bench_trust_budget.py OUT_DIR [--seeds 7] [--w-refs quickstart w0]
        [--objectives overlap] [--segments 24] [--nuisance k_yaw_s=5e6:20e6 kalker_scale=0.6:1.0]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

import bench_model_form as MF  # noqa: E402

from suspid.config import load_config  # noqa: E402
from suspid.infra.ledger import Ledger  # noqa: E402
from suspid.method.identifiability import bias_aware_half_width  # noqa: E402
from suspid.workflows.analysis import imprecise, model_error  # noqa: E402
from suspid.workflows.problem import build_problem  # noqa: E402


def flags(problem, trust: dict, sd: np.ndarray, identifiable: np.ndarray, n_sigmas: float, max_half: float) -> dict:
    """name -> trustworthy, with the analysis's "too uncertain" verdict applied to ``trust``."""
    if trust["bias_bound"] is not None:
        half = bias_aware_half_width(sd, trust["bias_bound"], n_sigmas)
        imprecise(trust, problem.names, identifiable, half, n_sigmas * sd, max_half)
    return dict(trust["trustworthy"])


CHECKS = {"self-check": "self-check", "data groups": "disagree", "model parameters": "rests on",
          "too uncertain": "too uncertain", "adequacy bands": "inadequate",
          "no change": "do not tell it from its value at the reference date"}
"""Each check's flag, from the start of its reason (the same words in both methods)."""


def check_flags(reasons: dict[str, list[str]], names: list[str]) -> dict[str, dict[str, bool]]:
    """check -> name -> flagged by that check."""
    return {check: {n: any(word in r for r in reasons.get(n, [])) for n in names} for check, word in CHECKS.items()}


def check_costs(report: dict) -> dict[str, int]:
    """Simulations each check took (either method's report)."""
    if report.get("method") == "linearised":
        return {k: v for k, v in report["budget"].items() if isinstance(v, int) and k != "total"}
    out = {}
    for name, part in (("self_check", report.get("self_check", {})), ("nuisance", report.get("nuisance", {})),
                       ("no_change", report.get("no_change", {}))):
        if part.get("status") == "done":
            out[name] = int(part["n_simulations"])
    groups = report.get("adequacy", {}).get("groups")
    if groups:
        out["data_groups"] = int(groups["n_simulations"])
    return out


def compare(cfg_path: Path) -> dict:
    """Full and calibrated-linearised checks on the finished linearised run of ``cfg_path``."""
    run_dir = cfg_path.parent / "runs" / cfg_path.stem
    res = json.loads((run_dir / "result.json").read_text())
    config = load_config(cfg_path)
    ledger = Ledger(run_dir / "ledger.sqlite")
    problem = build_problem(config, ledger)
    opts = config.identifiability
    names = problem.names
    u_opt = np.array([res["w_opt_normalized"][n] for n in names])
    sd = np.sqrt(np.clip(np.diag(np.array(res["interval_method"]["covariance_normalized"])), 0, None))
    identifiable = np.array([res["identifiable"][n] for n in names])
    me = opts.model_error
    truth = json.loads((cfg_path.parent / "measurement" / "truth.json").read_text())["parameters"]
    u_true = problem.to_unit(np.array([truth[n] for n in names]))
    out = {"identification": int(res["n_simulator_calls"]), "identifiable": res["identifiable"],
           "linearised": {"flags": res["trustworthy"], "costs": check_costs(res["model_error"]),
                          "checks": check_flags(res["untrustworthy_reasons"], names),
                          "covered": {n: bool(res["interval"][n][0] <= truth[n] <= res["interval"][n][1])
                                      for n in names},
                          "wall_s": res["model_error"]["budget"]["wall_time_s"]}}
    for label, options in (("full", me.model_copy(update={"method": "full"})),
                           ("calibrated", me.model_copy(update={"calibration": me.calibration.model_copy(
                               update={"enabled": True})}))):
        t0 = time.perf_counter()
        trust = model_error(problem, ledger, u_opt, opts.step, options, False, sd, None)
        wall = time.perf_counter() - t0
        half = (bias_aware_half_width(sd, trust["bias_bound"], opts.n_sigmas) if trust["bias_bound"] is not None
                else opts.n_sigmas * sd)
        out[label] = {"covered": {n: bool(abs(u_opt[k] - u_true[k]) <= half[k]) for k, n in enumerate(names)},
                      "flags": flags(problem, trust, sd, identifiable, opts.n_sigmas, me.max_half_width),
                      "costs": check_costs(trust["report"]), "wall_s": round(wall, 1),
                      "checks": check_flags(trust["reasons"], names)}
        if label == "calibrated":
            out[label]["calibration"] = {n: (e["status"], e["value"], e["interval"])
                                         for n, e in trust["report"]["calibration"]["parameters"].items()}
    out["errors"] = {n: 100 * (res["w_opt"][n] - truth[n]) / (res["bounds"][n][1] - res["bounds"][n][0])
                     for n in names}
    return out


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("--seeds", type=int, nargs="+", default=[7])
    ap.add_argument("--w-refs", nargs="+", default=["quickstart", "w0"], choices=list(MF.W_REFS))
    ap.add_argument("--objectives", nargs="+", default=["overlap"])
    ap.add_argument("--segments", type=int, default=24)
    ap.add_argument("--nuisance", nargs="*", default=["k_yaw_s=5e6:20e6", "kalker_scale=0.6:1.0"],
                    metavar="NAME=LOW:HIGH")
    a = ap.parse_args(argv)
    a.out.mkdir(parents=True, exist_ok=True)
    nuisance = {text.split("=")[0]: [float(v) for v in text.split("=")[1].split(":")] for text in a.nuisance}
    rows = []
    for obj in a.objectives:
        for seed in a.seeds:
            for w_ref in a.w_refs:
                case = MF.prepare(a.out, seed, w_ref, a.segments)
                cfg_path = MF.write_config(case, seed, obj, nuisance)
                cfg = yaml.safe_load(cfg_path.read_text())
                cfg["identifiability"]["model_error"].update({"method": "linearised",
                                                              "calibration": {"enabled": False}})
                cfg_path.write_text(yaml.safe_dump(cfg, sort_keys=False))
                if not (case / "runs" / cfg_path.stem / "result.json").exists():
                    t0 = time.time()
                    proc = subprocess.run([sys.executable, "-m", "suspid", "run", str(cfg_path), "--quiet"],
                                          capture_output=True, text=True)
                    print(f"{case.name}/{obj}: run {time.time() - t0:.0f} s"
                          + (f" FAILED: {proc.stderr.strip()[-300:]}" if proc.returncode else ""), flush=True)
                    if proc.returncode:
                        continue
                r = compare(cfg_path)
                r["case"] = f"{case.name}/{obj}"
                rows.append(r)
                print(json.dumps(r), flush=True)
    print("\n| case | component | error % | identifiable | full | linearised | calibrated |")
    print("|---|---|---|---|---|---|---|")
    agree = total = agree_c = 0
    for r in rows:
        for n, f_full in r["full"]["flags"].items():
            f_lin, f_cal = r["linearised"]["flags"][n], r["calibrated"]["flags"][n]
            agree += f_lin == f_full
            agree_c += f_cal == f_full
            total += 1
            mark = lambda key: ("trusted" if r[key]["flags"][n] else "flagged") + ("" if r[key]["covered"][n] else "*")  # noqa: E731,B023
            print(f"| {r['case']} | {n} | {r['errors'][n]:+.1f} | {r['identifiable'][n]} | {mark('full')} | "
                  f"{mark('linearised')} | {mark('calibrated')} |")
    print("(* the truth outside the interval)")
    print("\n| case | identification | full checks | linearised checks | calibrated linearised |")
    print("|---|---|---|---|---|")
    for r in rows:
        cost = {k: sum(r[k]["costs"].values()) for k in ("full", "linearised", "calibrated")}
        print(f"| {r['case']} | {r['identification']} | {cost['full']} ({r['full']['wall_s']} s) | "
              f"{cost['linearised']} ({r['linearised']['wall_s']} s) | {cost['calibrated']} ({r['calibrated']['wall_s']} s) |")
    for key in ("full", "linearised", "calibrated"):
        rep = [(r, n) for r in rows for n in r["full"]["flags"] if r[key]["flags"][n] and r["identifiable"][n]]
        cov = sum(r[key]["covered"][n] for r, n in rep)
        within = sum(abs(r["errors"][n]) <= 5.0 for r, n in rep)
        print(f"{key}: reported (identifiable and trusted) {len(rep)}/{total}, interval holds the truth {cov}/"
              f"{len(rep)}, within 5 % {within}/{len(rep)}")
    if total:
        print(f"\nsame flags, linearised vs full: {agree}/{total} ({100 * agree / total:.0f} %); "
              f"calibrated linearised vs full: {agree_c}/{total} ({100 * agree_c / total:.0f} %)")
        for check in CHECKS:
            same = [r["linearised"]["checks"][check][n] == r["full"]["checks"][check][n]
                    for r in rows for n in r["full"]["flags"]]
            n_full = sum(r["full"]["checks"][check][n] for r in rows for n in r["full"]["flags"])
            n_lin = sum(r["linearised"]["checks"][check][n] for r in rows for n in r["full"]["flags"])
            print(f"  check '{check}': same verdict {sum(same)}/{len(same)}; flagged by full {n_full}, "
                  f"by linearised {n_lin}")
        for key in ("full", "linearised", "calibrated"):
            sims = [sum(r[key]["costs"].values()) for r in rows]
            ident = [r["identification"] for r in rows]
            print(f"{key}: simulator calls of the checks {np.mean(sims):.0f} (mean), identification "
                  f"{np.mean(ident):.0f}: ratio {np.mean(np.array(sims) / np.array(ident)):.2f}")


if __name__ == "__main__":
    main()
