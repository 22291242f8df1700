"""Spectra with their derivatives: the Jacobian's accuracy and cost, and the gradient method against EGO.

Two parts, each measured in one run so that the ratios hold on a loaded machine:

1. ``jacobian``: on the presets of ``configs/quickstart.yaml`` (conventional-hs) and
   ``configs/table1.yaml`` (tgv-articulated), every parameter ``exudyn-train``
   differentiates, its analytic derivatives of the records against central finite
   differences (relative step 1e-3, the 2-norm over channels and samples); then the cost of
   the spectra's Jacobian (the records' derivatives carried through eq. 1-2, y included) for
   the identified q parameters and for all of them, each call against a plain solve of the
   same segments timed just before it (mean ± sd over ``--repeats``), and the first call of a
   fresh simulator (nothing kept between calls yet) against its own plain solve.
2. ``identify``: both problems over ``--seeds``, three methods from the same config:
   the paper's EGO (``ego.refine`` off; on the Table 1 analogue the paper's loop of the
   ``ego.refine`` run, which is the same run up to its stop), EGO + refinement, and ``gauss-newton``. For each run:
   the simulations after which the best-J point's worst identifiable error first is ≤ 2 %
   (the study's anytime curve), that run's wall time scaled to that point (wall × calls to
   reach / calls), the worst error at the end, the coverage of the intervals, and for the
   gradient method its Jacobians (count, and cost in plain-solve equivalents). Every method of
   a seed is judged on the components the paper's EGO flags identifiable in that seed (the
   study's rule); each run's own flags are printed too. ``--extra gauss-newton-8`` adds
   ``gauss-newton`` with J averaged over 8 draws of the noise paths (``objective.noise_draws``).
3. ``cost``: the cost ratios alone, for whichever suspid is installed, with the FFT floor of a
   forward Jacobian of all parameters (:func:`fft_floor`).
4. ``maximiser``: where J's maximiser lies on either problem for several draws of the noise
   paths, one draw's J or J averaged over ``--average`` draws.

Usage::

    python benchmarks/bench_gradient.py jacobian
    python benchmarks/bench_gradient.py identify --seeds 1 2 3 4 5 --out /tmp/bench_gradient
    python benchmarks/bench_gradient.py identify --problems quickstart --table1-m0 60
    python benchmarks/bench_gradient.py identify --seeds 1 2 --out /tmp/bench_gradient --reuse   # tables again
    python benchmarks/bench_gradient.py identify --problems table1 --extra gauss-newton-8 --reuse --out /tmp/bench_gradient
    python benchmarks/bench_gradient.py cost --repeats 3
    python benchmarks/bench_gradient.py maximiser --problem table1 --draws 1 --paths 1 --average 8

The Table 1 analogue's paper design has m0 = 500 (``configs/table1.yaml``); ``--table1-m0``
sets the EGO variants' design (default 60, the config's own small-design variant: the
m0 = 500 runs take minutes each on a shared 2-core machine).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
PROBLEMS = {"quickstart": ROOT / "configs" / "quickstart.yaml", "table1": ROOT / "configs" / "table1.yaml"}
TARGET = 2.0


def header(what: str) -> None:
    load = os.getloadavg()
    print(f"# bench_gradient {what}  {time.strftime('%Y-%m-%d %H:%M')}  python {platform.python_version()}  "
          f"numpy {np.__version__}  {os.cpu_count()} cpus  load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}")


# ------------------------------------------------------------------------------------------- jacobian
def jacobian_part(repeats: int, n_segments: int | None) -> None:
    from suspid.config import build_simulator, load_config
    from suspid.workflows.jacobian import spectra_jacobian
    from suspid.testing import check_differentiable
    from suspid.workflows.problem import synthetic_track
    from suspid.workflows.tasks import simulate_spectra

    header("jacobian")
    for problem, path in PROBLEMS.items():
        config = load_config(path)
        sim = build_simulator(config)
        names_all = sim.differentiable([p.name for p in sim.parameters()])
        identified = [n for n in config.parameters] if config.parameters else sim.default_parameters()
        segments = synthetic_track(config, "measurement")
        if n_segments:
            segments = segments[:n_segments]
        # accuracy: two segments of the run's own track
        t0 = time.perf_counter()
        errors = check_differentiable(type(sim), dict(sim.options), segments[:2], names=names_all, rtol=1e-4)
        worst = max(errors, key=errors.get)
        print(f"{problem} ({sim.opts.preset}): {len(names_all)} parameters differentiated; largest relative "
              f"difference to central FD {errors[worst]:.2e} ({worst}); median {statistics.median(errors.values()):.1e} "
              f"[{time.perf_counter() - t0:.0f} s]")
        print("  per parameter: " + ", ".join(f"{n} {e:.1e}" for n, e in errors.items()))
        # cost, on the run's segments; the first call of a fresh simulator (nothing kept: sparsity patterns, the
        # point-independent matrix derivatives, the compiled loops already compiled) apart from the later ones
        w = {n: float(v) for n, v in config.data.w_ref.items()}
        fresh = build_simulator(config)
        simulate_spectra(fresh, w, segments, config.spectra)
        t = time.perf_counter()
        simulate_spectra(fresh, {**w, identified[0]: w[identified[0]] * (1 + 1e-7)}, segments, config.spectra)
        cold_plain = time.perf_counter() - t
        t = time.perf_counter()
        spectra_jacobian(fresh, w, names_all, segments, config.spectra)
        cold = time.perf_counter() - t
        simulate_spectra(sim, w, segments, config.spectra)
        spectra_jacobian(sim, w, identified, segments, config.spectra)
        spectra_jacobian(sim, w, names_all, segments, config.spectra)
        plain, per_record, r_q, r_all, c_q, c_all = [], [], [], [], [], []

        def timed(fn, *args):
            t, c = time.perf_counter(), time.process_time()
            fn(*args)
            return time.perf_counter() - t, time.process_time() - c

        for k in range(repeats):
            wk = {**w, identified[0]: w.get(identified[0], sim.values({})[identified[0]]) * (1 + 1e-6 * (k + 1))}
            p, pc = timed(simulate_spectra, sim, wk, segments, config.spectra)
            plain.append(p)
            # again at the same w: the receptance is cached, the per-record work is left
            per_record.append(timed(simulate_spectra, sim, wk, segments, config.spectra)[0] / p)
            j, jc = timed(spectra_jacobian, sim, wk, identified, segments, config.spectra)
            r_q.append(j / p)
            c_q.append(jc / pc)
            wk = {**wk, identified[0]: wk[identified[0]] * (1 + 1e-7)}     # a new point for the plain solve too
            p, pc = timed(simulate_spectra, sim, wk, segments, config.spectra)
            plain.append(p)
            j, jc = timed(spectra_jacobian, sim, wk, names_all, segments, config.spectra)
            r_all.append(j / p)
            c_all.append(jc / pc)

        def ms(x):
            return f"{statistics.mean(x):.2f} ± {statistics.stdev(x) if len(x) > 1 else 0.0:.2f}"

        print(f"  cost on {len(segments)} segments, {repeats} repeats, each ratio against the plain solve timed just "
              f"before it (mean ± sd): plain solve {statistics.mean(plain):.3f} ± {statistics.stdev(plain):.3f} s; "
              f"y + Jacobian for the q = {len(identified)} identified {ms(r_q)} plain in wall time, {ms(c_q)} in CPU "
              f"time (central FD: {2 * len(identified) + 1}); for all {len(names_all)} {ms(r_all)} plain in wall time, "
              f"{ms(c_all)} in CPU time (central FD: {2 * len(names_all) + 1})")
        print(f"  first call of a fresh simulator for all {len(names_all)}: {cold:.3f} s = {cold / cold_plain:.2f} "
              f"plain (its own plain solve {cold_plain:.3f} s)")
        pr = statistics.mean(per_record)
        print(f"  per-record work of a plain solve (receptance cached: products, inverse FFTs, spectra) {ms(per_record)} "
              f"of it; n_p derivative records of every segment at that cost per record: "
              f"1 + n_p x {pr:.2f} = {1 + len(identified) * pr:.2f} plain for q = {len(identified)}, "
              f"{1 + len(names_all) * pr:.2f} for all {len(names_all)}")


def cost_part(problems: list[str], repeats: int) -> None:
    """The jacobian part's cost figures alone (no accuracy check), for whichever suspid is installed: one
    JSON line per problem and parameter set, wall and CPU ratios to a plain solve timed just before each
    Jacobian. Run with another checkout's interpreter to compare versions in the same conditions, e.g.
    ``/path/to/main/.venv/bin/python benchmarks/bench_gradient.py cost`` beside this checkout's."""
    import suspid
    from suspid.config import build_simulator, load_config
    from suspid.workflows.jacobian import spectra_jacobian
    from suspid.workflows.problem import synthetic_track
    from suspid.workflows.tasks import simulate_spectra

    header(f"cost  suspid from {Path(suspid.__file__).parent}")
    for problem in problems:
        config = load_config(PROBLEMS[problem])
        sim = build_simulator(config)
        names = sim.differentiable([p.name for p in sim.parameters()])
        ident = list(config.parameters)
        segments = synthetic_track(config, "measurement")
        w = {n: float(v) for n, v in config.data.w_ref.items()}
        simulate_spectra(sim, w, segments, config.spectra)
        for which in (names, ident):
            spectra_jacobian(sim, w, which, segments, config.spectra)
        rows = {"all": [], "q": []}
        for k in range(repeats):
            for which, asked in (("all", names), ("q", ident)):
                wk = {**w, ident[0]: w[ident[0]] * (1 + 1e-6 * (k + 1) + (1e-7 if which == "q" else 0.0))}
                t, c = time.perf_counter(), time.process_time()
                simulate_spectra(sim, wk, segments, config.spectra)
                p, pc = time.perf_counter() - t, time.process_time() - c
                t, c = time.perf_counter(), time.process_time()
                spectra_jacobian(sim, wk, asked, segments, config.spectra)
                rows[which].append(((time.perf_counter() - t) / p, (time.process_time() - c) / pc, pc))
        floor = [fft_floor(sim, w, segments, len(names), config.spectra, k) for k in range(repeats)]
        print(json.dumps({"problem": problem, "parameters": "all", "n_p": len(names),
                          "fft_floor_cpu_ratio": round(statistics.mean(f[0] for f in floor), 2),
                          "fft_floor_sd": round(statistics.stdev(f[0] for f in floor), 2) if repeats > 1 else 0.0,
                          "records": floor[0][1], "n_fft": floor[0][2], "n_t": floor[0][3],
                          "load": round(os.getloadavg()[0], 1)}), flush=True)
        for which, sel in rows.items():
            wall, cpu, plain = zip(*sel)
            print(json.dumps({"problem": problem, "parameters": which, "n_p": len(names if which == "all" else ident),
                              "wall_ratio": round(statistics.mean(wall), 2), "wall_sd": round(statistics.stdev(wall), 2),
                              "cpu_ratio": round(statistics.mean(cpu), 2), "cpu_sd": round(statistics.stdev(cpu), 2),
                              "plain_cpu_s": round(statistics.mean(plain), 3), "load": round(os.getloadavg()[0], 1)}),
                  flush=True)


def fft_floor(sim, w: dict, segments: list, n_p: int, spectra, k: int) -> tuple[float, int, int, int]:
    """The least a forward Jacobian of ``n_p`` parameters adds to a plain solve, in plain solves (CPU time).

    Each derivative record is the window [0, T) of a response the solver has on its FFT grid of n_fft lines:
    whatever computes ∂H/∂p U, every parameter, channel and segment then takes at least one inverse FFT of
    length n_fft, its truncation to the record's n_t samples and one forward FFT of length n_t (the windowed
    record's lines that the cells read; single precision, all of a segment's records in one batched call).
    Returns ``(1 + t_ffts / t_plain, records, n_fft, n_t)`` with t_plain the CPU time of a plain solve
    (``simulate_spectra`` at a point moved by a relative 1e-6 k, so that nothing of it is cached) timed just
    before; the derivatives' own products and cell sums are left out, so the true cost lies above this floor."""
    from scipy import fft as sfft

    from suspid.plugins.simulators.exudyn_train.solvers import FrequencyResponse, fft_plan
    from suspid.plugins.simulators.exudyn_train.model import TimeFeatures
    from suspid.workflows.tasks import simulate_spectra

    values = sim.values(w)
    speed = float(segments[0].mean_speed)
    response = FrequencyResponse(sim._model(values, speed, TimeFeatures()).linear_system())
    n_ts, n_fft = fft_plan(response, list(segments), sim.opts.fs_hz, sim.opts.settle_s)
    n_out = len(sim.channels())
    rng = np.random.default_rng(0)
    dY = (rng.standard_normal((n_p, n_out, n_fft // 2 + 1))
          + 1j * rng.standard_normal((n_p, n_out, n_fft // 2 + 1))).astype(np.complex64)
    c = time.process_time()
    first = next(iter(w))
    simulate_spectra(sim, {**w, first: w[first] * (1 + 1e-6 * (k + 1) + 3e-8)}, segments, spectra)
    plain = time.process_time() - c
    c = time.process_time()
    for n in n_ts:
        sfft.rfft(np.ascontiguousarray(sfft.irfft(dY, n=n_fft, axis=-1)[..., :n]), axis=-1)
    return 1.0 + (time.process_time() - c) / plain, n_p * n_out * len(n_ts), n_fft, max(n_ts)


# ------------------------------------------------------------------------------------------- identify
RUNS = {
    "ego": {"ego.refine.enabled": False},
    "ego+refine": {"ego.refine.enabled": True},
    "gauss-newton": {"optimizer.plugin": "gauss-newton"},
    # J averaged over 8 draws of the noise paths (objective.noise_draws): another J, so its J_max is not
    # compared with the others' (the seed's J maximiser is that of the one-draw J)
    "gauss-newton-8": {"optimizer.plugin": "gauss-newton", "objective.noise_draws": 8},
}
ONE_DRAW = ("ego", "ego+refine", "gauss-newton")


def one_run(problem: str, method: str, seed: int, out: Path, table1_m0: int, reuse: bool = False) -> dict:
    """One identification (or, with ``reuse``, the finished one already in its output folder)."""
    import suspid

    run_dir = out / problem / method / str(seed)
    if reuse and (run_dir / "result.json").exists():
        res = json.loads((run_dir / "result.json").read_text())
        return {"result": res, "ledger": str(run_dir / "ledger.sqlite"), "wall": float(res["wall_time_s"])}
    overrides = {"seed": seed, "output.dir": str(run_dir)} | RUNS[method]
    if problem == "table1" and method != "gauss-newton":
        overrides["design.n_initial"] = table1_m0
    t = time.perf_counter()
    r = suspid.identify(str(PROBLEMS[problem]), overrides, fresh=True)
    return {"result": r.to_dict(), "ledger": str(r.run_dir / "ledger.sqlite"), "wall": time.perf_counter() - t}


def row_of(problem: str, seed: int, method: str, run: dict, reference: dict, w_max: dict,
           paper_loop: bool = False) -> dict:
    """One run's figures on the ``reference`` identifiable components; ``paper_loop``: the EGO loop's prefix
    of an ``ego+refine`` run (its curve up to where the paper's loop stopped; no interval of its own).

    Besides the errors against w_ref, the same curve against ``w_max``, the maximiser of J (the best-J point
    of all the seed's runs: the same data and noise paths, so their J are comparable): how fast the method
    finds J's maximum, apart from how far that maximum lies from w_ref (the data's own error)."""
    from suspid.workflows.study_stats import anytime_errors

    res = dict(run["result"])
    own = res["identifiable"]
    res["identifiable"] = reference
    curve = anytime_errors(run["ledger"], res)
    to_max = anytime_errors(run["ledger"], {**res, "w_ref": w_max})
    n_total = int(res["n_simulator_calls"])
    n = int(res["paper_loop"]["n_simulator_calls"]) if paper_loop else n_total
    curve, to_max = curve[:n], to_max[:n]
    reached = float(np.flatnonzero(curve <= TARGET)[0] + 1) if np.any(curve <= TARGET) else math.nan
    reached_max = float(np.flatnonzero(to_max <= TARGET)[0] + 1) if np.any(to_max <= TARGET) else math.nan
    names = [k for k in res["parameters"] if reference[k]]
    inside = [res["interval"][k][0] <= res["w_ref"][k] <= res["interval"][k][1] for k in names]
    jac = res.get("jacobian") or {}
    wall = run["wall"] * n / n_total        # the run's wall time, pro rata of its simulations (a prefix)
    return {"problem": problem, "seed": seed, "method": method, "calls": n, "wall_s": wall,
            "calls_to_2pct": reached, "wall_to_2pct_s": wall * reached / n if math.isfinite(reached) else math.nan,
            "worst_final": float(curve[-1]) if curve.size else math.nan,
            "calls_to_2pct_of_max": reached_max, "to_max_final": float(to_max[-1]) if to_max.size else math.nan,
            "J_max": float(res["paper_loop"]["J_max"] if paper_loop else res["J_max"]),
            "coverage": math.nan if paper_loop else (float(np.mean(inside)) if inside else math.nan),
            "not_identifiable_own": [] if paper_loop else [k for k in res["parameters"] if not own[k]],
            "jacobians": jac.get("n_jacobians", 0), "jacobian_plain_equivalents": jac.get("plain_solve_equivalents_each")}


def identify_part(problems: list[str], seeds: list[int], out: Path, table1_m0: int, reuse: bool = False,
                  extra: list[str] = ()) -> None:
    header("identify")
    rows = []
    methods = ["ego", "ego+refine", "gauss-newton", *extra]
    for problem in problems:
        for seed in seeds:
            # Table 1: the paper's loop is the prefix of the ego+refine run (same design, same points)
            kinds = [m for m in methods if not (problem == "table1" and m == "ego")]
            runs = {m: one_run(problem, m, seed, out, table1_m0, reuse) for m in kinds}
            ref_run = runs.get("ego", runs["ego+refine"])
            reference = ref_run["result"]["identifiable"]
            w_max = max((r["result"] for m, r in runs.items() if m in ONE_DRAW), key=lambda r: r["J_max"])["w_opt"]
            if problem == "table1":
                new = [row_of(problem, seed, "ego", runs["ego+refine"], reference, w_max, paper_loop=True)]
            else:
                new = [row_of(problem, seed, "ego", runs["ego"], reference, w_max)]
            new += [row_of(problem, seed, m, runs[m], reference, w_max) for m in kinds if m != "ego"]
            for row in new:
                print(json.dumps(row), flush=True)
            rows += new
            out.mkdir(parents=True, exist_ok=True)
            (out / "rows.json").write_text(json.dumps(rows, indent=1))
    print()
    print("| problem | method | simulations (mean) | reached ≤ 2 % | simulations to ≤ 2 % (mean over those) | "
          "wall to ≤ 2 % (s) | worst final % (mean, max) | within 2 % of J's maximiser | simulations to it (mean) | "
          "coverage | Jacobians (mean) | Jacobian cost (plain solves) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for problem in problems:
        for method in methods:
            sel = [r for r in rows if r["problem"] == problem and r["method"] == method]
            if not sel:
                continue
            ok = [r for r in sel if math.isfinite(r["calls_to_2pct"])]
            ok_max = [r for r in sel if math.isfinite(r["calls_to_2pct_of_max"])]

            def mean(key, rs=sel):
                vals = [r[key] for r in rs if r[key] is not None and math.isfinite(r[key])]
                return float(np.mean(vals)) if vals else math.nan

            eq = [r["jacobian_plain_equivalents"] for r in sel if r["jacobian_plain_equivalents"]]
            print(f"| {problem} | {method} | {mean('calls'):.1f} | {len(ok)}/{len(sel)} | "
                  f"{mean('calls_to_2pct', ok):.1f} | {mean('wall_to_2pct_s', ok):.1f} | "
                  f"{mean('worst_final'):.2f}, {max(r['worst_final'] for r in sel):.2f} | "
                  f"{len(ok_max)}/{len(sel)} | {mean('calls_to_2pct_of_max', ok_max):.1f} | "
                  f"{mean('coverage'):.2f} | {mean('jacobians'):.1f} | "
                  f"{np.median(eq) if eq else float('nan'):.1f} |")


# ------------------------------------------------------------------------------------------- maximiser
def maximiser_part(seeds: list[int], draws: int, paths: list[int], out: Path, objectives: list[str],
                   overrides: list[str] = (), synthetic: bool = False, problem_name: str = "quickstart",
                   average: int = 1) -> None:
    """Where J's maximiser lies on the quickstart, per seed, for several draws of the noise paths b_i.

    The run's J uses one fixed path b_i per segment (common random numbers, eq. 4): its maximiser moves with
    the draw as well as with the measured spectra. For each seed (its measured spectra and noise model B as
    the run builds them) and each of ``draws`` draws (draw 0: the run's own paths), J's maximiser is found by
    Gauss-Newton steps from w_ref (the spectra linearised in log w with the analytic Jacobian, J kept exact,
    three re-linearisations), with K paths per segment for each K of ``paths`` (the v K modelled spectra
    y_sim_i + b_ik against the v measured ones: the same objective with less of the paths' own noise). Errors
    in % of each admissible interval against w_ref. The spread over draws is what the paths add; what stays
    as K grows is the measured spectra's own error and the objective's. ``objectives``: besides the config's
    (``config``), other objective plugins on the same data and paths (``mean-spectrum``: the mean spectra's
    weighted least squares). ``overrides``: ``key=value`` changes of the quickstart config (e.g. the
    measurement process without its sensor floor) to see what moves the maximiser. ``synthetic``: the
    measured spectra replaced by the model's own, y_sim_i(w_ref) + b*_i with b* a fresh draw of B: what the
    estimator itself does where the data follow its model exactly. ``problem_name``: the config (quickstart or
    table1). ``average``: J averaged over that many independent draws of the v paths (each draw's J as the run
    computes it; the first draw of the average is the row's own draw), the noise paths' share of the
    maximiser's scatter divided by about its square root."""
    from scipy.optimize import minimize

    from suspid import registry
    from suspid.config import load_config
    from suspid.infra.lock import open_run_dir
    from suspid.infra.seeds import rng as named_rng
    from suspid.method.objective import ObjectiveFunction
    from suspid.workflows.jacobian import spectra_jacobian
    from suspid.workflows.problem import build_problem, segment_speeds

    header(f"maximiser {problem_name} average {average} {' '.join(overrides)}{' synthetic' if synthetic else ''}")
    rows = []
    for seed in seeds:
        config = load_config(PROBLEMS[problem_name], [f"seed={seed}", *overrides])
        with open_run_dir(out / f"maximiser-{problem_name}-{seed}", config_name=config.name, config_file=config.source_file,
                          fresh=True, log=lambda s: None) as ledger:
            problem = build_problem(config, ledger)
        names, bounds = problem.names, np.asarray(problem.bounds, dtype=float)
        width = bounds[:, 1] - bounds[:, 0]
        w_ref = np.array([float(config.data.w_ref[n]) for n in names])
        v = len(problem.segments)
        speeds = segment_speeds(problem.segments)
        y_mes = problem.y_mes
        if synthetic:
            from suspid.method.noise import modelled_spectra
            from suspid.workflows.tasks import simulate_spectra

            y_ref = simulate_spectra(problem.simulator, dict(zip(names, w_ref)), problem.segments, config.spectra)[0]
            y_mes = modelled_spectra(y_ref, problem.noise_model.sample(v, named_rng(seed, "bench-synthetic"), speeds),
                                     problem.noise_model.floor_)
        cache: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}

        def linear_model(x):
            key = tuple(np.round(x, 9))
            if key not in cache:
                res = spectra_jacobian(problem.simulator, dict(zip(names, x)), names, problem.segments,
                                       config.spectra)
                cache[key] = (res.y, res.jacobian * x)             # dy / dlog w
            return cache[key]

        for k, K, objective in ((k, K, o) for o in objectives for k in range(draws) for K in paths):
            if k == 0 and K == 1:
                b = problem.b
            else:
                b = problem.noise_model.sample(K * v, named_rng(seed, f"bench-maximiser-{k}-{K}"), speeds * K)
            plugin = problem.objective if objective == "config" else registry.get("objective", objective)()
            bs = [b] + [problem.noise_model.sample(K * v, named_rng(seed, f"bench-maximiser-avg-{k}-{K}-{a}"),
                                                   speeds * K) for a in range(1, average)]
            fns = [ObjectiveFunction(plugin, y_mes, problem.freqs, bb, weights=problem.weights,
                                     channels=problem.channels, floor=problem.noise_model.floor_) for bb in bs]
            x = w_ref.copy()
            for _ in range(3):
                y, jac = linear_model(x)

                def negJ(u, y=y, jac=jac, x=x):
                    z = np.log(bounds[:, 0] + u * width) - np.log(x)
                    y_lin = np.tile(y + jac @ z, (K, 1, 1))
                    return -float(np.mean([fn.evaluate(y_lin)[0] for fn in fns]))

                u0 = (x - bounds[:, 0]) / width
                lo, hi = np.clip(u0 - 0.15, 0, 1), np.clip(u0 + 0.15, 0, 1)
                r = minimize(negJ, u0, method="L-BFGS-B", bounds=list(zip(lo, hi)),
                             options={"maxiter": 40, "eps": 1e-5})
                x = bounds[:, 0] + np.clip(r.x, lo, hi) * width
            err = 100 * (x - w_ref) / width
            row = {"problem": problem_name, "seed": seed, "objective": objective, "draw": k, "paths_per_segment": K,
                   "average": average,
                   "errors": dict(zip(names, np.round(err, 2).tolist())), "worst": float(np.max(np.abs(err)))}
            rows.append(row)
            print(json.dumps(row), flush=True)
    out.mkdir(parents=True, exist_ok=True)
    (out / "maximiser.json").write_text(json.dumps(rows, indent=1))
    print()
    print("| seed | objective | paths per segment | worst error of J's maximiser per draw (%) | mean over draws per component (%) | "
          "sd over draws per component (%) |")
    print("|---|---|---|---|---|---|")
    for seed, objective, K in ((s_, o, K) for s_ in seeds for o in objectives for K in paths):
        sel = [r for r in rows if r["seed"] == seed and r["paths_per_segment"] == K and r["objective"] == objective]
        E = np.array([[r["errors"][n] for n in sel[0]["errors"]] for r in sel])
        worst = ", ".join(f"{r['worst']:.2f}" for r in sel)
        means = ", ".join(f"{n} {m:+.2f}" for n, m in zip(sel[0]["errors"], E.mean(axis=0)))
        sds = ", ".join(f"{sd:.2f}" for sd in (E.std(axis=0, ddof=1) if len(E) > 1 else np.zeros(E.shape[1])))
        print(f"| {seed} | {objective} | {K} | {worst} | {means} | {sds} |")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("part", choices=["jacobian", "cost", "identify", "maximiser"])
    ap.add_argument("--draws", type=int, default=4, help="maximiser: draws of the noise paths per seed")
    ap.add_argument("--paths", type=int, nargs="+", default=[1, 8], help="maximiser: paths per segment K")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="maximiser: a change of the quickstart config (repeatable)")
    ap.add_argument("--synthetic", action="store_true",
                    help="maximiser: measured spectra replaced by y_sim(w_ref) plus a draw of B")
    ap.add_argument("--problem", choices=list(PROBLEMS), default="quickstart", help="maximiser: the config")
    ap.add_argument("--average", type=int, default=1,
                    help="maximiser: J averaged over this many draws of the noise paths")
    ap.add_argument("--objectives", nargs="+", default=["config"],
                    help="maximiser: 'config' (the config's objective) and/or objective plugins")
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3, 4, 5])
    ap.add_argument("--problems", nargs="+", choices=list(PROBLEMS), default=list(PROBLEMS))
    ap.add_argument("--out", type=Path, default=Path("/tmp/bench_gradient"))
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--segments", type=int, default=None, help="jacobian: first N segments only")
    ap.add_argument("--table1-m0", type=int, default=60)
    ap.add_argument("--reuse", action="store_true", help="identify: read the runs already finished in --out")
    ap.add_argument("--extra", nargs="*", default=[], choices=[m for m in RUNS if m not in ONE_DRAW],
                    help="identify: further methods (gauss-newton-8: J averaged over 8 draws of the noise paths)")
    args = ap.parse_args(argv)
    sys.path.insert(0, str(ROOT))
    if args.part == "jacobian":
        jacobian_part(args.repeats, args.segments)
    elif args.part == "cost":
        cost_part(args.problems, args.repeats)
    elif args.part == "maximiser":
        maximiser_part(args.seeds, args.draws, args.paths, args.out, args.objectives, args.set, args.synthetic,
                       args.problem, args.average)
    else:
        identify_part(args.problems, args.seeds, args.out, args.table1_m0, args.reuse, args.extra)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
