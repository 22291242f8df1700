"""Re-run the benchmarks and write their printed tables into ``benchmarks/RESULTS.md``.

One command re-measures what a model or method change affects::

    python benchmarks/run_all.py            # every benchmark, full size (hours)
    python benchmarks/run_all.py --quick    # every benchmark at reduced sizes (about 20 minutes)
    python benchmarks/run_all.py --only objectives startup
    python benchmarks/run_all.py --list     # the table below: full and quick command lines
    python benchmarks/run_all.py --quick --results /tmp/RESULTS.md   # write into a copy

Each benchmark of :data:`BENCHMARKS` runs as its own process (the same Python,
from the repository root, one at a time: the figures of one never share the
machine with another), its output is echoed line by line as it comes (the
progress), and what it printed is written into RESULTS.md between the markers
``<!-- run_all:NAME begin -->`` and ``<!-- run_all:NAME end -->`` with the
command, the date, the commit and the load average. A block with no markers
yet is appended at the end of the file. RESULTS.md is rewritten atomically
after each benchmark, so an interrupt (Ctrl-C) keeps every table finished so
far. A benchmark that fails (non-zero exit) is reported and its old block is
kept unchanged; the exit status is then 1. At the end a summary prints each
benchmark's wall time and the total.

``--quick`` runs the same benchmarks with fewer seeds, segments, repeats and
evaluations and writes the same blocks (their command line shows the quick
sizes): after a model change every table is re-measured within about 20
minutes, with the wider scatter of the smaller sizes, until a full run (or
``--only NAME`` at full size) replaces it.
"""

from __future__ import annotations

import argparse
import datetime
import os
import re
import resource
import shlex
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "RESULTS.md"
WORK = "runs/run_all"  # output folders of the benchmarks that write runs (relative to ROOT)


@dataclass(frozen=True)
class Benchmark:
    """One entry of the table: ``argv`` after the interpreter, for a full and a quick run.

    ``quick`` is None for a benchmark too heavy for ``--quick`` (it is skipped there, with a note).
    """

    name: str
    argv: tuple[str, ...]
    quick: tuple[str, ...] | None
    measures: str


def _b(name: str, argv: str, quick: str | None, measures: str) -> Benchmark:
    """A :class:`Benchmark` from command lines split as a POSIX shell would (quotes group words)."""
    return Benchmark(name, tuple(shlex.split(argv)), None if quick is None else tuple(shlex.split(quick)), measures)


Q = "--set data.track.n_segments=12 --set design.n_initial=15 --set ego.max_iter=10"
"""The quick sizes of a quickstart-like identification: 12 segments, m0 = 15, at most 10 EGO steps."""

BENCHMARKS: tuple[Benchmark, ...] = (
    _b("startup", "benchmarks/bench_startup.py --runs 15", "benchmarks/bench_startup.py --runs 5",
       "wall time of `suspid --help` against a bare interpreter"),
    _b("objectives", "benchmarks/bench_objectives.py --repeat 5",
       "benchmarks/bench_objectives.py --repeat 2 --subset 10",
       "one evaluation of J, likelihood (numba kernel vs numpy) and overlap"),
    _b("baseline_objectives", "benchmarks/bench_baseline_objectives.py --repeat 5",
       "benchmarks/bench_baseline_objectives.py --repeat 2", "one evaluation of J, mean-spectrum and wasserstein"),
    _b("exudyn_train", "benchmarks/bench_exudyn_train.py --repeat 7 --vectors 30",
       "benchmarks/bench_exudyn_train.py --repeat 2 --vectors 5",
       "speed of the time and frequency solvers (conventional-hs), and their agreement"),
    _b("exudyn_train_articulated",
       "benchmarks/bench_exudyn_train.py --frequency-only --vehicle tgv-articulated --vectors 20",
       "benchmarks/bench_exudyn_train.py --frequency-only --vehicle tgv-articulated --vectors 5",
       "speed of the frequency solver on the articulated section"),
    _b("exudyn_physics", "benchmarks/bench_exudyn_train.py --physics",
       "benchmarks/bench_exudyn_train.py --physics",
       "modes, critical speed, ride, solver agreement and creep saturation of conventional-hs (docs/model.md)"),
    _b("exudyn_physics_articulated", "benchmarks/bench_exudyn_train.py --physics --vehicle tgv-articulated",
       "benchmarks/bench_exudyn_train.py --physics --vehicle tgv-articulated",
       "the same for tgv-articulated"),
    _b("variable_speed", "benchmarks/bench_variable_speed.py --seeds 3", "benchmarks/bench_variable_speed.py --seeds 1",
       "frequency solver on a speed record against the time solver"),
    _b("curve_spectra", "benchmarks/bench_curve_spectra.py --seed 3", "benchmarks/bench_curve_spectra.py --seed 3",
       "what a curve does to the spectra"),
    _b("ego", "benchmarks/bench_ego.py --seeds 5 --jobs 1",
       "benchmarks/bench_ego.py --seeds 2 --functions branin,hartmann3 --jobs 1",
       "EGO against peer Bayesian optimisers: evaluations to reach 1 %"),
    _b("ego_sklearn", "benchmarks/bench_ego.py --functions branin --tools suspid,suspid-sklearn --seeds 5 --jobs 1",
       "benchmarks/bench_ego.py --functions branin --tools suspid,suspid-sklearn --seeds 2 --jobs 1",
       "EGO with the sklearn-gp surrogate against gpy-kriging"),
    _b("executors", "benchmarks/bench_executors.py --points 8", "benchmarks/bench_executors.py --quick --points 4",
       "design evaluation by serial, processes and dask; batch EGO"),
    _b("executors_whole_run", "benchmarks/bench_executors.py --whole-run",
       "benchmarks/bench_executors.py --whole-run --segments 2 --m0 8 --m1 4",
       "a whole run per executor, asynchronous EGO"),
    _b("dask_scheduler_memory", "benchmarks/bench_executors.py --scheduler-memory --tasks 500 --tasks-before 30",
       "benchmarks/bench_executors.py --scheduler-memory --tasks 100 --tasks-before 10",
       "dask scheduler memory, track sent once per worker"),
    _b("ingest", "benchmarks/bench_ingest.py", "benchmarks/bench_ingest.py --hours 0.5",
       "speed and memory of `suspid ingest` on a one-hour recording"),
    _b("ingest_identify", "-m pytest tests/test_ingest_identify.py -m long -q -s -p no:cacheprovider",
       "-m pytest tests/test_ingest_identify.py -m long -q -s -p no:cacheprovider",
       "identification on ingested segments against segments simulated directly (a long test)"),
    _b("quickstart", f"-m suspid run configs/quickstart.yaml --fresh --set output.dir={WORK}/quickstart",
       f"-m suspid run configs/quickstart.yaml --fresh --set output.dir={WORK}/quickstart-quick {Q}",
       "the README's quickstart identification"),
    _b("table1", f"-m suspid study configs/table1.yaml --fresh --set output.dir={WORK}/table1",
       f"-m suspid study configs/table1.yaml --fresh --set output.dir={WORK}/table1-quick "
       "--set 'study.variants=[{name: overlap-m0-60, set: {design.n_initial: 60}}]' "
       "--set data.track.n_segments=20 --set ego.max_iter=20 --set ego.refine.max_iter=10",
       "the Table 1 analogue (tgv-articulated)"),
    _b("methods", f"-m suspid study configs/methods.yaml --fresh --set output.dir={WORK}/methods "
       "--set 'study.seeds=[1, 2, 3]'",
       f"-m suspid study configs/methods.yaml --fresh --set output.dir={WORK}/methods-quick "
       "--set study.seeds=[1] --set optimizer.budget=60 --set design.n_initial=30 --set ego.max_iter=30 "
       "--set data.track.n_segments=12 --set 'study.variants=[{name: ego, set: {}}, "
       "{name: nelder-mead, set: {optimizer.plugin: nelder-mead}}, "
       "{name: ego-likelihood, set: {objective.plugin: likelihood}}]' --set 'study.compare=[ego, nelder-mead]'",
       "six optimisers and three objectives on the Table 1 problem"),
    _b("independent", f"benchmarks/bench_independent.py --seeds 7 --out {WORK}/independent",
       f"benchmarks/bench_independent.py --seeds 7 --dates damaged --objectives overlap --segments 12 "
       f"--n-initial 15 --max-iter 10 --out {WORK}/independent-quick",
       "the two-date protocol on the independent train's data (tests/independent)"),
    _b("fleet_demo", "-m suspid fleet demo configs/fleet-demo.yaml --no-serve",
       "-m suspid fleet demo configs/fleet-demo.yaml --no-serve",
       "the demo fleet: degrading elements' verdicts and forecasts (serial, frequency solver)"),
    _b("coverage", f"benchmarks/bench_coverage.py --seeds 20 --out {WORK}/coverage",
       f"benchmarks/bench_coverage.py --seeds 2 --out {WORK}/coverage-quick {Q}",
       "interval coverage over seeds (quickstart)"),
    _b("gradient_jacobian", "benchmarks/bench_gradient.py jacobian",
       "benchmarks/bench_gradient.py jacobian --segments 5 --repeats 1",
       "analytic Jacobian against finite differences, and its cost"),
    _b("gradient_identify", f"benchmarks/bench_gradient.py identify --out {WORK}/gradient",
       f"benchmarks/bench_gradient.py identify --seeds 1 --problems quickstart --out {WORK}/gradient-quick",
       "gauss-newton against the paper's EGO"),
    _b("diagnose", "benchmarks/bench_diagnose.py", "benchmarks/bench_diagnose.py --seeds 3",
       "discrepancy workflow on hidden-effect experiments"),
    _b("diagnose_independent", "benchmarks/bench_diagnose.py --independent",
       "benchmarks/bench_diagnose.py --independent --cases tilt",
       "discrepancy workflow on the independent train"),
    _b("floor", "benchmarks/bench_floor.py --seeds 7 8", f"benchmarks/bench_floor.py {Q}",
       "sensor-noise floor on equal data"),
    _b("objective_bias", "benchmarks/bench_objective_bias.py",
       "benchmarks/bench_objective_bias.py --seeds 3 --segments 12",
       "where each objective puts the suspension on the independent train"),
    _b("model_form", f"benchmarks/bench_model_form.py {WORK}/model_form",
       f"benchmarks/bench_model_form.py {WORK}/model_form-quick --seeds 7 --w-refs quickstart --objectives overlap "
       "--segments 12 --jobs 1",
       "trust flags on the independent train"),
    _b("model_form_independent2",
       f"benchmarks/bench_model_form.py {WORK}/model_form2 --generator independent2",
       f"benchmarks/bench_model_form.py {WORK}/model_form2-quick --generator independent2 --seeds 7 "
       "--w-refs quickstart --objectives overlap --segments 12 --jobs 1",
       "trust flags on the second independent train"),
    _b("trust_budget", f"benchmarks/bench_trust_budget.py {WORK}/trust_budget",
       f"benchmarks/bench_trust_budget.py {WORK}/trust_budget-quick --w-refs quickstart --objectives overlap "
       "--segments 12",
       "linearised against full model-error checks"),
    _b("localisation", f"benchmarks/bench_localisation.py --seeds 1 2 3 --segments 100 --out {WORK}/localisation",
       f"benchmarks/bench_localisation.py --seeds 1 --cases yaw-bogie1-50 null --segments 6 "
       f"--out {WORK}/localisation-quick",
       "localisation of one degraded element group (tests/independent2)"),
)

MARK = "<!-- run_all:{name} {end} -->"


@dataclass(frozen=True)
class Timing:
    """What one benchmark of an invocation cost: wall time, CPU time of its processes (s), and its status."""

    name: str
    wall_s: float
    cpu_s: float
    status: str  # "ok" | "failed" | "skipped"


def children_cpu() -> float:
    """User + system CPU seconds of the terminated child processes (and theirs, once waited for) so far."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


PROGRESS = re.compile(r"━.* eta \d|^(variant \S+|executor \S+, \d+ task\(s\) at once|"
                      r"(reference|measurement) date: simulating .*)$")
"""A progress line (a rich progress bar, suspid's phase lines): echoed while a benchmark runs, left out of its
block."""


def strip_progress(output: str) -> str:
    """``output`` without its progress-bar lines."""
    return "".join(line for line in output.splitlines(keepends=True) if not PROGRESS.search(line))


def markers(name: str) -> tuple[str, str]:
    """The begin and end marker lines of benchmark ``name``'s block in RESULTS.md."""
    return MARK.format(name=name, end="begin"), MARK.format(name=name, end="end")


def render_block(bench: Benchmark, argv: tuple[str, ...], output: str, *, date: str, commit: str,
                 load: str) -> str:
    """The block written into RESULTS.md (markers included): command, date, commit, load, then the output."""
    begin, end = markers(bench.name)
    command = shlex.join(("python", *argv))
    fence = "````" if "```" in output else "```"
    return (f"{begin}\n"
            f"Command: `{command}` · date {date} · commit {commit} · load average {load} "
            f"(written by `benchmarks/run_all.py`)\n\n"
            f"{fence}text\n{output.rstrip()}\n{fence}\n{end}")


def replace_block(text: str, name: str, block: str) -> str:
    """``text`` with benchmark ``name``'s block replaced by ``block``, or ``block`` appended under a heading."""
    begin, end = markers(name)
    pattern = re.compile(re.escape(begin) + r".*?" + re.escape(end), re.S)
    if pattern.search(text):
        return pattern.sub(lambda _m: block, text, count=1)
    return f"{text.rstrip()}\n\n## {name} (benchmarks/run_all.py)\n\n{block}\n"


def git_commit() -> str:
    """The short hash of HEAD, ``+dirty`` when tracked files other than RESULTS.md differ from it; ``unknown``
    outside git (RESULTS.md itself is what this script rewrites, so its changes do not count)."""
    try:
        head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True,
                              text=True, check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no", "--", ".",
                                ":(exclude)benchmarks/RESULTS.md"], cwd=ROOT,
                               capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"
    return head + ("+dirty" if dirty else "")


def load_average() -> str:
    try:
        return " ".join(f"{x:.2f}" for x in os.getloadavg())
    except OSError:
        return "n/a"


def run_one(argv: tuple[str, ...], *, python: str = sys.executable, prefix: str = "") -> tuple[int, str]:
    """Run ``python *argv`` from the repository root, echoing its lines; returns (exit status, stdout).

    Its stderr goes to ours (progress bars and warnings are not part of the table). On Ctrl-C (or a
    SIGINT to this process alone) the child is sent SIGINT too, given 10 s to stop, then killed, and the
    interrupt re-raised.
    """
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    proc = subprocess.Popen([python, *argv], cwd=ROOT, stdout=subprocess.PIPE, text=True, env=env)
    lines = []
    try:
        assert proc.stdout is not None
        for line in proc.stdout:
            lines.append(line)
            print(prefix + line, end="", flush=True)
        return proc.wait(), "".join(lines)
    except KeyboardInterrupt:
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        raise


def update_results(results: Path, benches: list[Benchmark], *, quick: bool,
                   python: str = sys.executable, timings: list[Timing] | None = None) -> list[str]:
    """Run ``benches`` one by one, rewriting ``results`` after each success; returns the names that failed.

    ``timings``, if given, receives a :class:`Timing` per benchmark.
    """
    failed = []
    timings = [] if timings is None else timings
    commit = git_commit()
    for i, bench in enumerate(benches, 1):
        argv = bench.quick if quick else bench.argv
        if argv is None:
            print(f"[{i}/{len(benches)}] {bench.name}: skipped in --quick (run it without --quick)", flush=True)
            timings.append(Timing(bench.name, 0.0, 0.0, "skipped"))
            continue
        print(f"[{i}/{len(benches)}] {bench.name}: {shlex.join(('python', *argv))}", flush=True)
        load = load_average()
        t0, cpu0 = time.perf_counter(), children_cpu()
        status, output = run_one(argv, python=python, prefix=f"  {bench.name}| ")
        wall, cpu = time.perf_counter() - t0, children_cpu() - cpu0
        if status != 0 or not output.strip():
            why = f"exit status {status}" if status != 0 else "no output"
            print(f"[{i}/{len(benches)}] {bench.name}: FAILED ({why}, {wall:.0f} s); its old block is kept",
                  flush=True)
            failed.append(bench.name)
            timings.append(Timing(bench.name, wall, cpu, "failed"))
            continue
        date = datetime.date.today().isoformat()
        block = render_block(bench, argv, strip_progress(output), date=date, commit=commit, load=load)
        from suspid.infra.files import write_text  # atomic: an interrupt leaves the previous file

        write_text(results, replace_block(results.read_text(encoding="utf-8"), bench.name, block))
        print(f"[{i}/{len(benches)}] {bench.name}: done in {wall:.0f} s, written to {results.name}", flush=True)
        timings.append(Timing(bench.name, wall, cpu, "ok"))
    return failed


def timing_summary(timings: list[Timing], *, quick: bool, load_before: str, load_after: str) -> str:
    """The wall and CPU time of every benchmark of this invocation and their totals, as a text table.

    The CPU time (user + system of the benchmark's processes) hardly depends on the machine's load: on an
    idle 2-core machine a serial benchmark's wall time is about its CPU time, a parallel one's less.
    """
    width = max([len(t.name) for t in timings] + [9])
    lines = [f"run_all timing ({'quick' if quick else 'full'} sizes; load average before {load_before}, "
             f"after {load_after}):", f"  {'benchmark':<{width}}  wall (s)  CPU (s)  status"]
    lines += [f"  {t.name:<{width}}  {t.wall_s:8.0f}  {t.cpu_s:7.0f}  {t.status}" for t in timings]
    wall, cpu = sum(t.wall_s for t in timings), sum(t.cpu_s for t in timings)
    lines.append(f"  {'total':<{width}}  {wall:8.0f}  {cpu:7.0f}  (wall {wall / 60:.1f} min, CPU {cpu / 60:.1f} min)")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="every benchmark at reduced sizes (see --list)")
    ap.add_argument("--only", nargs="+", metavar="NAME", help="these benchmarks only (see --list)")
    ap.add_argument("--list", action="store_true", help="print the benchmarks and exit")
    ap.add_argument("--results", type=Path, default=RESULTS, help="the file to update (default: RESULTS.md)")
    args = ap.parse_args(argv)
    if args.list:
        for b in BENCHMARKS:
            quick = "skipped" if b.quick is None else shlex.join(("python", *b.quick))
            print(f"{b.name}: {b.measures}\n  full:  {shlex.join(('python', *b.argv))}\n  quick: {quick}")
        return 0
    by_name = {b.name: b for b in BENCHMARKS}
    unknown = [n for n in args.only or [] if n not in by_name]
    if unknown:
        print(f"run_all: unknown benchmark {', '.join(unknown)}; expected one of {', '.join(by_name)}",
              file=sys.stderr)
        return 2
    if not args.results.is_file():
        print(f"run_all: {args.results}: no such file (expected RESULTS.md)", file=sys.stderr)
        return 2
    benches = [by_name[n] for n in args.only] if args.only else list(BENCHMARKS)
    timings: list[Timing] = []
    load_before = load_average()
    try:
        failed = update_results(args.results, benches, quick=args.quick, timings=timings)
    except KeyboardInterrupt:
        print("run_all: interrupted; the tables finished so far are written", file=sys.stderr)
        return 130
    print(timing_summary(timings, quick=args.quick, load_before=load_before, load_after=load_average()),
          flush=True)
    if failed:
        print(f"run_all: failed: {', '.join(failed)} (their old blocks kept)", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
