"""Model-form error: the two-date protocol on an independent train, with suspid's trust flags.

For every seed and measurement-date suspension w_ref (the quickstart's damaged
one, another one, and w0 itself) an independent train (``--generator``:
``independent``, the frequency-domain linear model of ``tests/independent`` on
the Manchester coach, or ``independent2``, the time-domain nonlinear model of
``tests/independent2`` on the quickstart's conventional-hs car) writes a reference date at w0 and a measurement date at w_ref; a config with
``noise.reference`` is run by ``suspid run`` for each objective (in parallel
subprocesses). Printed per run and component: the signed error in % of the
admissible interval, identifiable / trustworthy, whether the reported
interval contains the truth; then the acceptance summary:

- every component reported identifiable AND trustworthy within 5 % of its interval;
- its interval containing the truth in >= 90 % of cases;
- the flagged components;
- with w_ref = w0, no trustworthy component moving by more than 3 %;

then where the identifiable components' interval widths come from (sampling, self-check, data groups,
model parameters), and the model-error checks' simulator calls against the identification's.

Usage (from the repository root)::

    python benchmarks/bench_model_form.py OUT_DIR [--generator independent|independent2]
        [--seeds 7 8 11] [--w-refs quickstart other w0]
        [--objectives overlap likelihood] [--jobs 2] [--segments 100] [--summary]
        [--nuisance k_yaw_s=5e6:20e6 kalker_scale=0.6:1.0] [--weights efficient|equal|reference] [--limits 5]
        [--method full|linearised]

The acceptance grid runs at 100 segments of 1 km per date (the default): the paper ("Inverse identification
of mechanical parameters of high-speed train suspensions submitted to random track irregularities", section 2)
works with "about one hundred" known track geometry realisations per date. ``--segments 40`` is the small-data
sensitivity (the sampling half-width is then the largest part of the interval, and fewer components are
reported).

A finished run (its result.json) is kept: running again completes a cut grid;
``--summary`` prints the table of the runs finished so far.

``--compare-methods`` then runs both model-error methods (``linearised`` and ``full``) in this process on each
finished run's problem, ledger, w_opt and sampling spread, and prints per component both methods' flags (trust
under model error, with the "too uncertain" verdict of the bias-aware half-width), whether each interval holds the
truth, each source of bias as each method measured it (self-check, half the groups' spread, the model parameters'
shift and spread), the simulator calls of each check, and the agreement of the flags (the target is >= 90 %).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from independent import protocol  # noqa: E402
from independent import train as TR  # noqa: E402
from independent2 import measure as MS2  # noqa: E402
from independent2 import protocol as protocol2  # noqa: E402

W_REFS = {
    "quickstart": {"k_sec_z": 340.0e3, "c_sec_z": 14.0e3, "k_prim_z": 1.30e6, "c_sec_y": 11.0e3, "c_yaw": 560.0e3},
    "other": {"k_sec_z": 500.0e3, "c_sec_z": 26.0e3, "k_prim_z": 1.00e6, "c_sec_y": 20.0e3, "c_yaw": 1000.0e3},
    "w0": {},
}
"""Measurement-date suspensions (SI): the quickstart's damaged one, a stiffer/more damped one, and w0."""


BOUNDS = {n: {"lower": 0.5 * protocol.VEHICLE[n], "upper": 1.5 * protocol.VEHICLE[n]} for n in ("c_sec_y", "c_yaw")}
"""The preset's bounds of c_sec_y and c_yaw (16-48 kN s/m, 150-800 kN s/m) put the shared nominal values of the
independent train (16 and 800 kN s/m) on a bound: the interval is centred on them instead, as the preset's is."""


GENERATORS = {
    "independent": {"vehicle": protocol.VEHICLE, "bounds": BOUNDS, "w_refs": W_REFS,
                    "generate": TR.generate_two_dates},
    "independent2": {"vehicle": protocol2.VEHICLE, "bounds": protocol2.BOUNDS,
                     "w_refs": protocol2.W_REFS | protocol2.ELEMENT_CASES,
                     "generate": MS2.generate_two_dates},
}
"""Per generator: suspid's car for its data, bounds overriding the preset's, the w_ref cases and the function
writing both dates (the same interface). independent2 adds the localisation benchmark's element cases (one degraded element group
each, identified here per kind: the truth of a kind is the mean of its elements)."""
GEN = GENERATORS["independent"]


def write_config(case: Path, seed: int, objective: str, nuisance: dict[str, list[float]] | None = None,
                 weights: str | None = None, method: str | None = None) -> Path:
    name = objective + (f"-{weights}-weights" if weights else "") + (f"-{method}" if method else "")
    cfg = {"name": name, "seed": seed,
           "simulator": {"plugin": "exudyn-train", "options": {"solver": "frequency", "fs_hz": 100.0,
                                                               "vehicle": GEN["vehicle"]}},
           "parameters": {n: GEN["bounds"].get(n, {}) for n in GEN["w_refs"]["quickstart"]},
           "data": {"source": "measured", "measurements": "measurement/accelerations",
                    "track_file": "measurement/track"},
           "noise": {"reference": {"measurements": "reference/accelerations", "track_file": "reference/track"}},
           "spectra": {"f_min_hz": 0.4, "f_max_hz": 20.0, "n_freqs": 200},
           "objective": {"plugin": objective, **({"weights": weights} if weights else {})}, "surrogate": {"plugin": "gpy-kriging"},
           "design": {"method": "maximin-lhs", "n_initial": 30}, "ego": {"max_iter": 40, "tol": 1.0e-4}}
    model_error: dict = {}
    if nuisance:
        model_error["nuisance"] = {"parameters": nuisance}
    if method:
        model_error["method"] = method
    if model_error:
        cfg["identifiability"] = {"model_error": model_error}
    path = case / f"{name}.yaml"
    path.write_text(yaml.safe_dump(cfg, sort_keys=False), encoding="utf-8")
    return path


def prepare(out: Path, seed: int, w_ref: str, segments: int) -> Path:
    case = out / f"seed{seed}-{w_ref}"
    if not written_with(case / "measurement" / "truth.json", segments):
        GEN["generate"](case, {}, GEN["w_refs"][w_ref], seed=seed, n_segments=segments, speed_mps=300.0 / 3.6)
    return case


def written_with(truth: Path, segments: int) -> bool:
    """Whether a date's files (their ``truth.json``) are already written, with ``segments`` segments; exit 2 with
    one line if they were written with another count (figures over a mix of data sizes would be mixed)."""
    if not truth.exists():
        return False
    written = len(json.loads(truth.read_text())["segments"])
    if written != segments:
        print(f"error: {truth.parent} holds {written} segments, not {segments}: use another output folder or "
              f"--segments {written}", file=sys.stderr)
        raise SystemExit(2)
    return True


def run_one(cfg: Path) -> tuple[Path, float, str]:
    t0 = time.time()
    if (cfg.parent / "runs" / cfg.stem / "result.json").exists():   # a finished run: kept (delete to redo)
        return cfg, 0.0, ""
    proc = subprocess.run([sys.executable, "-m", "suspid", "run", str(cfg), "--quiet"], capture_output=True,
                          text=True)
    return cfg, time.time() - t0, proc.stderr.strip()[-300:] if proc.returncode else ""


def summarise(cfg: Path) -> dict:
    case = cfg.parent
    res = json.loads((case / "runs" / cfg.stem / "result.json").read_text())
    truth = json.loads((case / "measurement" / "truth.json").read_text())["parameters"]
    nc = (res.get("model_error") or {}).get("no_change") or {}
    w_reported = res.get("w_corrected", res["w_opt"])   # the reported value: bias-corrected where the checks correct it
    intervals = res["interval"]
    if "reported" not in nc and nc.get("status") == "done" and not nc.get("rejected") \
            and (res.get("interval_method") or {}).get("widened_by_model_error"):
        # a run written before the no-change report (suspid.workflows.no_change.reported_correction): the values
        # reported are w0's and the same intervals are centred there
        w0 = json.loads((case / "reference" / "truth.json").read_text())["parameters"]
        intervals = {n: [a + w0[n] - w_reported[n], b + w0[n] - w_reported[n]] for n, (a, b) in intervals.items()}
        w_reported = {n: w0[n] for n in res["parameters"]}
    estimate = (((res.get("model_error") or {}).get("correction") or {}).get("w_corrected")
                or res.get("w_corrected", res["w_opt"]))   # the (corrected) estimate, before any no-change report
    rows = {}
    for n in res["parameters"]:
        lo, hi = res["bounds"][n]
        t = truth[n]
        iv = intervals[n]
        rows[n] = {"error": 100 * (w_reported[n] - t) / (hi - lo), "estimate_error": 100 * (estimate[n] - t) / (hi - lo),
                   "unchanged": nc.get("status") == "done" and not nc.get("rejected", True),
                   "identifiable": res["identifiable"][n],
                   "trustworthy": res.get("trustworthy", {}).get(n, True), "in_interval": iv[0] <= t <= iv[1],
                   "in_sampling_interval": res["interval_sampling"][n][0] <= t <= res["interval_sampling"][n][1],
                   "half_width": 50 * (iv[1] - iv[0]) / (hi - lo),
                   "bias_aware_half_width": res.get("model_error", {}).get("half_width_percent", {}).get(n),
                   "reasons": res["non_identifiable_reasons"].get(n, []) + res.get("untrustworthy_reasons", {}).get(n, [])}
    return rows


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("--generator", choices=list(GENERATORS), default="independent",
                    help="the independent train that writes the data (tests/independent or tests/independent2)")
    ap.add_argument("--seeds", type=int, nargs="+", default=[7, 8, 11])
    ap.add_argument("--w-refs", nargs="+", default=["w0", "other", "quickstart"],
                    choices=list(dict.fromkeys(n for g in GENERATORS.values() for n in g["w_refs"])))
    ap.add_argument("--objectives", nargs="+", default=["overlap", "likelihood"])
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--segments", type=int, default=100,
                    help="segments of 1 km per date (default 100, the acceptance setting: the paper's 'about one "
                         "hundred' track realisations; 40, as the quickstart, is the small-data sensitivity; with 24 "
                         "the sampling scatter alone moves k_sec_z by 3-5 %% of its interval)")
    ap.add_argument("--summary", action="store_true", help="only summarise the runs already finished")
    ap.add_argument("--nuisance", nargs="*", default=[], metavar="NAME=LOW:HIGH",
                    help="nuisance parameters of the model-error check, e.g. k_yaw_s=5e6:20e6")
    ap.add_argument("--weights", choices=["equal", "reference", "efficient"], default="efficient",
                    help="objective.weights of the runs (their run directories get the suffix -WEIGHTS-weights; "
                         "'equal' leaves the key out, suspid's default, with no suffix). Default 'efficient': on "
                         "the 100-segment grid it reports more components with fewer misses (benchmarks/RESULTS.md)")
    ap.add_argument("--limits", type=float, nargs="*", default=[],
                    help="also score the acceptance with the 'too uncertain' limit (max_half_width) at these %% "
                         "post hoc: a reported component whose stored bias-aware half-width exceeds it is counted "
                         "as not reported")
    ap.add_argument("--compare-methods", action="store_true",
                    help="after the runs, the linearised and full model-error checks on each run's w_opt, compared")
    ap.add_argument("--method", choices=["full", "linearised"], default=None,
                    help="identifiability.model_error.method of the runs (default: the config's default; the run "
                         "directories get the suffix -METHOD)")
    a = ap.parse_args(argv)
    global GEN
    GEN = GENERATORS[a.generator]
    unknown = [w for w in a.w_refs if w not in GEN["w_refs"]]
    if unknown:
        ap.error(f"--w-refs {' '.join(unknown)}: not a case of --generator {a.generator} "
                 f"(its cases: {', '.join(GEN['w_refs'])})")
    a.out.mkdir(parents=True, exist_ok=True)
    nuisance = {text.split("=")[0]: [float(v) for v in text.split("=")[1].split(":")] for text in a.nuisance}
    cfgs = []
    for obj in a.objectives:       # the runs most needed first: a cut grid still covers every w_ref
        for seed in a.seeds:
            for w_ref in a.w_refs:
                cfgs.append(write_config(prepare(a.out, seed, w_ref, a.segments), seed, obj, nuisance,
                                         None if a.weights == "equal" else a.weights,
                                         a.method))
    with ThreadPoolExecutor(a.jobs) as pool:
        for cfg, wall, err in ([] if a.summary else pool.map(run_one, cfgs)):
            print(f"{cfg.parent.name}/{cfg.stem}: {wall:.0f} s{' FAILED: ' + err if err else ''}", flush=True)
    names = list(GEN["w_refs"]["quickstart"])
    print("\n| case | objective | " + " | ".join(names) + " | in interval |")
    print("|---|---|" + "---|" * (len(names) + 1))
    all_rows = []
    for cfg in cfgs:
        try:
            rows = summarise(cfg)
        except FileNotFoundError:
            continue
        w_ref = cfg.parent.name.split("-", 1)[1]
        cells = []
        for n in names:
            r = rows[n]
            mark = "" if r["identifiable"] and r["trustworthy"] else (" n.i." if not r["identifiable"] else " n.t.")
            cells.append(f"{r['error']:+.1f}{'' if r['in_interval'] else '*'}{mark}")
            all_rows.append((w_ref, cfg.parent.name, cfg.stem, n, r))
        n_in = sum(rows[n]["in_interval"] for n in names)
        print(f"| {cfg.parent.name} | {cfg.stem} | " + " | ".join(cells) + f" | {n_in}/{len(names)} |")
    print("\n(* truth outside the reported interval; n.i. not identifiable; n.t. not trustworthy under model error)")
    reported = [x for x in all_rows if x[4]["identifiable"] and x[4]["trustworthy"]]
    within = [x for x in reported if abs(x[4]["error"]) <= 5.0]
    covered = [x for x in reported if x[4]["in_interval"]]
    flagged = [x for x in all_rows if not (x[4]["identifiable"] and x[4]["trustworthy"])]
    w0_moves = [x for x in reported if x[0] == "w0" and abs(x[4]["error"]) > 3.0]
    print(f"\nreported (identifiable and trustworthy): {len(reported)} of {len(all_rows)} components")
    print(f"  within 5 % of the interval: {len(within)}/{len(reported)}"
          f"{' (all)' if len(within) == len(reported) else ''}; worst "
          + (f"{max(abs(x[4]['error']) for x in reported):.1f} %" if reported else "-"))
    print(f"  interval contains the truth: {len(covered)}/{len(reported)} "
          f"({100 * len(covered) / max(len(reported), 1):.0f} %)")
    print(f"  with w_ref = w0, trustworthy components moving > 3 %: {len(w0_moves)} "
          + ", ".join(f"{c}/{o} {n} {r['error']:+.1f}" for _, c, o, n, r in w0_moves))
    own = [x for x in reported if x[0] == "w0" and abs(x[4]["estimate_error"]) > 3.0]
    unchanged = sum(1 for x in all_rows if x[4]["unchanged"] and x[3] == names[0])
    print(f"    (runs reported as unchanged, w0 not rejected: {unchanged}; the estimates themselves, before that "
          f"report, moving > 3 %: {len(own)} "
          + ", ".join(f"{c}/{o} {n} {r['estimate_error']:+.1f}" for _, c, o, n, r in own) + ")")
    print(f"flagged: {len(flagged)}")
    for _, c, o, n, r in flagged:
        print(f"  {c}/{o} {n}: error {r['error']:+.1f} %; " + "; ".join(x[:140] for x in r["reasons"]))
    missed = [x for x in reported if abs(x[4]["error"]) > 5.0]
    print("reported but off by > 5 %: " + (", ".join(f"{c}/{o} {n} {r['error']:+.1f}" for _, c, o, n, r in missed)
                                         or "none"))
    print("\nper objective and component: reported / runs (worst |error| of the reported, %; mean half-width "
          "of their intervals, %)")
    for obj in objectives_in(all_rows):
        cells = []
        for n in names:
            rows_n = [r for _, _, o, m, r in all_rows if o == obj and m == n]
            rep = [r for r in rows_n if r["identifiable"] and r["trustworthy"]]
            cells.append(f"{n} {len(rep)}/{len(rows_n)}" + (f" ({max(abs(r['error']) for r in rep):.1f}; "
                                                             f"{np.mean([r['half_width'] for r in rep]):.1f})"
                                                             if rep else ""))
        print(f"  {obj}: " + ", ".join(cells))
    for limit in [None, *a.limits]:
        acceptance_at(all_rows, limit)
    width_table(cfgs)
    budget_table(cfgs)
    if a.compare_methods:
        compare_table([c for c in cfgs if (c.parent / "runs" / c.stem / "result.json").exists()])


METHOD_CHECKS = {"self-check": "self-check", "data groups": "disagree", "model parameters": "rests on",
                 "too uncertain": "too uncertain", "adequacy bands": "inadequate",
                 "no change": "do not tell it from its value at the reference date"}
"""Each check's flag, from the start of its reason (the same words in both methods)."""


def compare_methods(cfg: Path) -> dict:
    """Both model-error methods on the finished run of ``cfg``: flags, intervals, sources and costs per method."""
    from suspid.config import load_config
    from suspid.infra.ledger import Ledger
    from suspid.method.identifiability import bias_aware_half_width
    from suspid.workflows.analysis import imprecise, model_error
    from suspid.workflows.problem import build_problem

    run_dir = cfg.parent / "runs" / cfg.stem
    res = json.loads((run_dir / "result.json").read_text())
    config = load_config(cfg)
    ledger = Ledger(run_dir / "ledger.sqlite")
    problem = build_problem(config, ledger)
    opts, names = config.identifiability, problem.names
    u_opt = np.array([res["w_opt_normalized"][n] for n in names])
    sd = np.sqrt(np.clip(np.diag(np.array(res["interval_method"]["covariance_normalized"])), 0, None))
    identifiable = np.array([res["identifiable"][n] for n in names])
    truth = json.loads((cfg.parent / "measurement" / "truth.json").read_text())["parameters"]
    u_true = problem.to_unit(np.array([truth[n] for n in names]))
    out: dict = {"case": f"{cfg.parent.name}/{cfg.stem}", "identification": int(res["n_simulator_calls"]),
                 "identifiable": res["identifiable"], "names": names}
    for method in ("linearised", "full"):
        t0 = time.perf_counter()
        trust = model_error(problem, ledger, u_opt, opts.step, opts.model_error.model_copy(update={"method": method}),
                            False, sd, None)
        wall = time.perf_counter() - t0
        corr = trust.get("correction")
        u_est = u_opt if corr is None else np.clip(u_opt + corr, 0, 1)
        half = (bias_aware_half_width(sd, trust["bias_bound"], opts.n_sigmas) if trust["bias_bound"] is not None
                else opts.n_sigmas * sd)
        imprecise(trust, names, identifiable, half, opts.n_sigmas * sd, opts.model_error.max_half_width)
        rep = trust["report"]
        out[method] = {
            "flags": {n: trust["trustworthy"][n] is True for n in names},
            "error": {n: float(100 * (u_est[k] - u_true[k])) for k, n in enumerate(names)},
            "covered": {n: bool(abs(u_est[k] - u_true[k]) <= half[k]) for k, n in enumerate(names)},
            "half": {n: float(100 * half[k]) for k, n in enumerate(names)},
            "checks": {c: {n: any(w in r for r in trust["reasons"].get(n, [])) for n in names}
                       for c, w in METHOD_CHECKS.items()},
            "sources": {n: {"self_check": rep.get("self_check", {}).get("bias_percent", {}).get(n, 0.0),
                            "groups_half": 0.5 * rep.get("adequacy", {}).get("groups", {}).get(
                                "spread_percent", {}).get(n, 0.0),
                            "model_shift": rep.get("nuisance", {}).get("shift_percent", {}).get(n, 0.0),
                            "model_spread": rep.get("nuisance", {}).get("spread_percent", {}).get(n, 0.0)}
                        for n in names},
            "costs": {k: v for k, v in rep.get("budget", {}).items() if isinstance(v, int) and k != "total"},
            "wall_s": round(wall, 1)}
    return out


def self_check_why(cfg: Path) -> dict:
    """Why the two methods' self-checks differ, on the finished run of ``cfg``: the linearised self-check on the
    reference spectra extrapolated linearly from the nominal model to the calibrated θ̂ (the former rule), the same
    on the calibrated model's spectra simulated (one Jacobian at w0 and θ̂, the rule now), and the full self-check (re-identified by
    simulation on the calibrated model, from the run's ledger). ``name -> [extrapolated, simulated, full]`` (% of
    the interval): where "simulated" is near "full", the difference is the extrapolation's, not the searches'."""
    from suspid.config import load_config
    from suspid.infra.ledger import Ledger
    from suspid.workflows.linearised import date_jacobian, linear_self_check, model_parameters
    from suspid.workflows.linearised import calibrate_at_reference
    from suspid.workflows.problem import build_problem
    from suspid.workflows.reference import self_check

    run_dir = cfg.parent / "runs" / cfg.stem
    config = load_config(cfg)
    ledger = Ledger(run_dir / "ledger.sqlite")
    problem = build_problem(config, ledger)
    opts = config.identifiability.model_error
    theta = model_parameters(problem, opts)
    cal = calibrate_at_reference(problem, ledger, theta, opts, None)
    jac0 = date_jacobian(problem, ledger, problem.reference_segments, dict(problem.w0), problem.names, theta, None)
    extrapolated = linear_self_check(problem, dataclasses.replace(jac0, y=jac0.y + jac0.dt @ cal.t_hat),
                                     opts).mean(axis=0)
    w_hat = theta.w(cal.t_hat)
    jac_hat = date_jacobian(problem, ledger, problem.reference_segments, dict(problem.w0) | w_hat, problem.names,
                            theta, None)
    simulated = linear_self_check(problem, jac_hat, opts).mean(axis=0)
    full = self_check(problem, ledger, opts.self_check, extra=w_hat if np.any(cal.t_hat != 0) else None).bias
    return {n: [float(100 * extrapolated[k]), float(100 * simulated[k]), float(100 * full[k])]
            for k, n in enumerate(problem.names)}


def compare_table(cfgs: list[Path]) -> None:
    """The linearised and full methods on every finished run (:func:`compare_methods`): tables and agreement."""
    rows = []
    for cfg in cfgs:
        t0 = time.time()
        kept = cfg.parent / "runs" / cfg.stem / "compare_methods.json"   # a finished comparison (delete to redo)
        if kept.exists():
            r = json.loads(kept.read_text())
        else:
            r = compare_methods(cfg)
            kept.write_text(json.dumps(r))
        r["case"] = f"{cfg.parent.parent.name}:{r['case']}"     # the generator's folder too
        rows.append(r)
        print(f"compared {r['case']} ({time.time() - t0:.0f} s)", flush=True)
    print("\n| case | component | identifiable | error % (lin / full) | linearised | full | self-check % (lin / full) "
          "| groups ½ spread % | model shift % | model spread % |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        lin, full = r["linearised"], r["full"]
        for n in r["names"]:
            mark = lambda m: ("trusted" if m["flags"][n] else "flagged") + ("" if m["covered"][n] else "*")  # noqa: E731,B023
            pair = lambda key: f"{lin['sources'][n][key]:+.1f} / {full['sources'][n][key]:+.1f}"  # noqa: E731,B023
            print(f"| {r['case']} | {n} | {'yes' if r['identifiable'][n] else 'no'} | {lin['error'][n]:+.1f} / "
                  f"{full['error'][n]:+.1f} | {mark(lin)} | {mark(full)} | {pair('self_check')} | "
                  f"{pair('groups_half')} | {pair('model_shift')} | {pair('model_spread')} |")
    print("(error: the reported (corrected) value minus the truth, % of the interval; * the truth outside that "
          "method's interval)")
    comps = [(r, n) for r in rows for n in r["names"]]
    if not comps:
        return
    same = sum(r["linearised"]["flags"][n] == r["full"]["flags"][n] for r, n in comps)
    print(f"\nsame flags, linearised vs full: {same}/{len(comps)} ({100 * same / len(comps):.0f} %)")
    ident = [(r, n) for r, n in comps if r["identifiable"][n]]
    same_i = sum(r["linearised"]["flags"][n] == r["full"]["flags"][n] for r, n in ident)
    print(f"  identifiable components: {same_i}/{len(ident)}")
    for check in METHOD_CHECKS:
        agree = sum(r["linearised"]["checks"][check][n] == r["full"]["checks"][check][n] for r, n in comps)
        print(f"  check '{check}': same verdict {agree}/{len(comps)}; flagged by linearised "
              f"{sum(r['linearised']['checks'][check][n] for r, n in comps)}, by full "
              f"{sum(r['full']['checks'][check][n] for r, n in comps)}")
    print("  each source, linearised against full over the identifiable components (% of the interval): median "
          "|difference|, largest |difference| (where)")
    for key in ("self_check", "groups_half", "model_shift", "model_spread"):
        diffs = [(abs(r["linearised"]["sources"][n][key] - r["full"]["sources"][n][key]), r["case"], n)
                 for r, n in ident]
        if diffs:
            worst = max(diffs)
            print(f"    {key}: {np.median([d for d, _, _ in diffs]):.1f}, {worst[0]:.1f} ({worst[1]} {worst[2]})")
    half = [(abs(r["linearised"]["half"][n] - r["full"]["half"][n]), r["case"], n) for r, n in ident]
    if half:
        print(f"    bias-aware half-width: {np.median([d for d, _, _ in half]):.1f}, {max(half)[0]:.1f} "
              f"({max(half)[1]} {max(half)[2]})")
    print("  where the flags differ: the checks that differ, and each method's half-width (%)")
    for r, n in comps:
        if r["linearised"]["flags"][n] != r["full"]["flags"][n]:
            checks = [c for c in METHOD_CHECKS if r["linearised"]["checks"][c][n] != r["full"]["checks"][c][n]]
            print(f"    {r['case']} {n}: {', '.join(checks) or 'none'}; half-width {r['linearised']['half'][n]:.1f} "
                  f"/ {r['full']['half'][n]:.1f}; groups' ½ spread {r['linearised']['sources'][n]['groups_half']:.1f}"
                  f" / {r['full']['sources'][n]['groups_half']:.1f}")
    for m in ("linearised", "full"):
        rep = [(r, n) for r, n in ident if r[m]["flags"][n]]
        print(f"{m}: reported (identifiable and trusted) {len(rep)}/{len(ident)}, interval holds the truth "
              f"{sum(r[m]['covered'][n] for r, n in rep)}/{len(rep)}, within 5 % "
              f"{sum(abs(r[m]['error'][n]) <= 5 for r, n in rep)}/{len(rep)}")
    print("\nsimulator calls of the checks per run (an analytic Jacobian counts one): linearised | full | "
          "identification")
    for r in rows:
        cost = lambda m: f"{sum(r[m]['costs'].values())} ({', '.join(f'{k} {v}' for k, v in r[m]['costs'].items())}; {r[m]['wall_s']} s)"  # noqa: E731,B023,E501
        print(f"  {r['case']}: {cost('linearised')} | {cost('full')} | {r['identification']}")


def finished(cfgs: list[Path]) -> list[tuple[Path, dict]]:
    """The runs of ``cfgs`` that have a result.json, with it."""
    paths = [(cfg, cfg.parent / "runs" / cfg.stem / "result.json") for cfg in cfgs]
    return [(cfg, json.loads(path.read_text())) for cfg, path in paths if path.exists()]


def width_table(cfgs: list[Path]) -> None:
    """Where the identifiable components' interval widths come from, per objective (means over runs, % of the
    admissible interval): the sampling half-width (n σ), the self-check's mean shift (|b|) and what of it stays a
    bound (not corrected), half the data groups' spread, the model parameters' posterior spread, the reported
    bias-aware half-width; and how many are reported."""
    rows: dict[str, list[list[float]]] = {}
    for cfg, res in finished(cfgs):
        me = res.get("model_error", {})
        if me.get("method") != "linearised" or "correction" not in me:
            continue
        fixed = me["correction"].get("self_check_percent", {})
        for n in res["parameters"]:
            if not res["identifiable"][n]:
                continue
            lo, hi = res["bounds"][n]
            samp = 50 * (res["interval_sampling"][n][1] - res["interval_sampling"][n][0]) / (hi - lo)
            sc = me.get("self_check", {}).get("bias_percent", {}).get(n, 0.0)
            rows.setdefault(cfg.stem, []).append([
                samp, abs(sc), abs(sc + fixed.get(n, 0.0)),
                me.get("adequacy", {}).get("groups", {}).get("spread_percent", {}).get(n, 0.0) / 2,
                me.get("nuisance", {}).get("spread_percent", {}).get(n, 0.0),
                me["half_width_percent"][n], 100.0 * (res["trustworthy"].get(n) is True)])
    if not rows:
        return
    print("\nwhere the width comes from (identifiable components, means in % of the admissible interval): sampling "
          "half-width | self-check |shift| | of it left a bound | half the groups' spread | model parameters' spread "
          "| bias-aware half-width | % reported")
    for obj, r in rows.items():
        a = np.array(r)
        print(f"  {obj} ({len(a)} components): " + " | ".join(f"{v:.1f}" for v in a[:, :6].mean(axis=0))
              + f" | {a[:, 6].mean():.0f} %")


def budget_table(cfgs: list[Path]) -> None:
    """The simulator calls of each run's model-error checks against its identification's (the design and EGO)."""
    print("\nsimulator calls: model-error checks / identification (method)")
    ratios = []
    for cfg, res in finished(cfgs):
        me = res.get("model_error", {})
        if "total" in me.get("budget", {}):
            checks = int(me["budget"]["total"])
        else:
            checks = sum(int(me.get(k, {}).get("n_simulations", 0)) for k in ("self_check", "nuisance")) \
                + int(me.get("adequacy", {}).get("groups", {}).get("n_simulations", 0)) \
                + int(me.get("no_change", {}).get("n_simulations", 0))
        weights = int((res.get("objective_weights") or {}).get("n_simulations", 0))  # α at the reference date
        ident = int(res["n_simulator_calls"]) + weights
        ratios.append(checks / max(ident, 1))
        print(f"  {cfg.parent.name}/{cfg.stem}: {checks} / {ident} ({me.get('method', 'full')}"
              + (f"; identification incl. {weights} for the channel weights" if weights else "") + ")")
    if ratios:
        print(f"  checks within the identification's calls in {sum(r <= 1 for r in ratios)}/{len(ratios)} runs; "
              f"largest ratio {max(ratios):.2f}")


def acceptance_at(all_rows: list, limit: float | None) -> None:
    """The acceptance figures per objective, as the runs reported (``limit`` None) or with the "too uncertain"
    limit at ``limit`` % instead of the runs' own, post hoc: a reported component whose stored bias-aware
    half-width (``model_error.half_width_percent``) exceeds it counts as not reported (a rule on the stored
    half-widths; nothing is identified again)."""
    print("\nacceptance as the runs reported" if limit is None else
          f"\nacceptance with the 'too uncertain' limit at {limit:g} % (post hoc, on the stored half-widths)")
    limit = float("inf") if limit is None else limit
    for obj in [None, *objectives_in(all_rows)]:
        rows = [x for x in all_rows if obj is None or x[2] == obj]
        ident = [x for x in rows if x[4]["identifiable"]]
        rep = [x for x in ident if x[4]["trustworthy"]
               and (x[4]["bias_aware_half_width"] is None or x[4]["bias_aware_half_width"] <= limit)]
        within = sum(abs(x[4]["error"]) <= 5.0 for x in rep)
        held = sum(x[4]["in_interval"] for x in rep)
        moves = [x for x in rep if x[0] == "w0" and abs(x[4]["error"]) > 3.0]
        print(f"  {obj or 'all'}: reported {len(rep)}/{len(ident)} ({100 * len(rep) / max(len(ident), 1):.0f} %), "
              f"within 5 % {within}/{len(rep)}, intervals hold {held}/{len(rep)} "
              f"({100 * held / max(len(rep), 1):.0f} %), w_ref = w0 moving > 3 %: {len(moves)}"
              + (" (" + ", ".join(f"{c}/{o} {n} {r['error']:+.1f}" for _, c, o, n, r in moves) + ")" if moves else ""))


def objectives_in(all_rows: list) -> list[str]:
    """The objectives of the rows, in their order."""
    return list(dict.fromkeys(o for _, _, o, _, _ in all_rows))


if __name__ == "__main__":
    main()
