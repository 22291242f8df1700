"""Record, then compare, the results of small runs before and after a change of the optimisation loop.

Each case is a small version of a config the project reports on (the quickstart, the Table 1
analogue with its refinement, one seed of the methods study for every optimiser plugin, batch
EGO, asynchronous EGO on processes and on a dask LocalCluster, and a run resumed after SIGKILL).
It records what a change of the loop must not change: w_opt, J_max, the number of simulator
calls, the stop reasons and the anytime history (J and w of every evaluation, in order)::

    python benchmarks/check_loop_identity.py --record before.json      # on the old code
    python benchmarks/check_loop_identity.py --compare before.json     # on the new code: exit 1 on a difference

``--only NAME ...`` runs some cases. Every run is serial unless the case says otherwise.

Floats are compared to a relative tolerance (``--rtol``, default 1e-9: far above the last bits, far below
any change of a result); integers and strings exactly. The record names the machine that wrote it (processor,
BLAS kernel): on another processor the same code can differ beyond that, because the loop branches on J's
values (which EI maximum wins, which point is best) and another BLAS kernel gives them other last bits. A
comparison across machines says so: a difference there is machine-bound, not a change of the loop; record
both sides on one machine to test a change.
"""

from __future__ import annotations

import argparse
import copy
import json
import math
import os
import platform
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
KEYS = ("w_opt", "J_max", "n_simulator_calls", "n_initial", "n_iterations", "stop_reason", "refine_stop_reason",
        "anytime", "identifiable", "interval")

TINY = {"name": "tiny", "seed": 5,
        "simulator": {"plugin": "exudyn-train", "options": {"solver": "frequency"}},
        "parameters": {"k_sec_z": {}, "c_sec_z": {}, "c_sec_y": {}},
        "data": {"source": "experiment",
                 "track": {"spectrum": "german-low", "n_segments": 6, "length_m": 600.0, "speed_kmh": 300.0},
                 "w_ref": {"k_sec_z": 330.0e3, "c_sec_z": 27.0e3, "c_sec_y": 21.0e3}},
        "spectra": {"f_min_hz": 0.4, "f_max_hz": 20.0, "n_freqs": 60},
        "design": {"n_initial": 6},
        "ego": {"max_iter": 6, "tol": 0.0, "explore_tol": 0.0},
        "identifiability": {"n_redraws": 6}}


def _small(name: str, **track) -> dict:
    cfg = yaml.safe_load((ROOT / "configs" / f"{name}.yaml").read_text())
    cfg.pop("study", None)
    cfg["data"]["track"].update(track)
    cfg["spectra"]["n_freqs"] = 60
    cfg["identifiability"] = {"n_redraws": 6}
    return cfg


def cases() -> dict[str, dict]:
    """name -> config (dict, without ``output``)."""
    out: dict[str, dict] = {}
    q = _small("quickstart", n_segments=8)
    q["design"]["n_initial"], q["ego"]["max_iter"] = 12, 10
    out["quickstart"] = q
    t = _small("table1", n_segments=8)
    t["design"]["n_initial"], t["ego"]["max_iter"] = 20, 8
    t["ego"]["refine"] = {"enabled": True, "max_iter": 4}
    out["table1"] = t
    m = _small("methods", n_segments=6)
    m["seed"] = 1
    m["design"]["n_initial"], m["ego"]["max_iter"] = 10, 14
    m["optimizer"] = {"plugin": "ego", "budget": 24}
    m["executor"] = {"plugin": "serial"}
    for plugin in ("ego", "random", "lhs-only", "nelder-mead", "cma-es", "skopt-gp", "gauss-newton"):
        c = copy.deepcopy(m)
        c["optimizer"]["plugin"] = plugin
        out[f"methods-{plugin}"] = c
    r = copy.deepcopy(m)
    r["ego"]["max_iter"], r["ego"]["refine"] = 10, {"enabled": True, "max_iter": 4}
    out["methods-ego-refine"] = r
    out["batch"] = {**TINY, "ego": {**TINY["ego"], "batch": 2}}
    out["async-processes"] = {**TINY, "executor": {"plugin": "processes", "options": {"workers": 2}}}
    out["async-dask"] = {**TINY, "executor": {"plugin": "dask", "options": {"n_workers": 2,
                                                                           "threads_per_worker": 1}}}
    out["sigkill-resume"] = {**TINY, "executor": {"plugin": "processes", "options": {"workers": 2}}}
    return out


def _kill_midway(path: Path, out: Path, n_evaluations: int) -> int:
    """Start ``suspid run`` on ``path`` and SIGKILL it (and its workers) once the ledger holds
    ``n_evaluations`` evaluations; returns how many it held then."""
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    proc = subprocess.Popen([sys.executable, "-m", "suspid", "run", str(path)], env=env, start_new_session=True,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    import sqlite3
    t0 = time.time()
    n = 0
    try:
        while time.time() - t0 < 600 and proc.poll() is None:
            time.sleep(0.5)
            ledgers = list(out.rglob("ledger.sqlite"))
            if not ledgers:
                continue
            try:
                with sqlite3.connect(ledgers[0], timeout=1) as db:
                    n = db.execute("select count(*) from evaluations where status = 'ok'").fetchone()[0]
            except sqlite3.Error:
                continue
            if n >= n_evaluations:
                break
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    return n


def machine() -> dict:
    """The processor and BLAS kernel this process computes with."""
    model = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    kernel = None
    try:
        from threadpoolctl import threadpool_info
        kernel = next((i.get("architecture") for i in threadpool_info() if i.get("internal_api") == "openblas"), None)
    except ImportError:
        pass
    return {"processor": model, "machine": platform.machine(), "blas_kernel": kernel,
            "OPENBLAS_CORETYPE": os.environ.get("OPENBLAS_CORETYPE")}


def differs(a, b, rtol: float) -> bool:
    """Whether two recorded values differ: floats beyond ``rtol`` (relative, and absolute near 0), the rest exactly."""
    if isinstance(a, dict) and isinstance(b, dict):
        return set(a) != set(b) or any(differs(a[k], b[k], rtol) for k in a)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) != len(b) or any(differs(x, y, rtol) for x, y in zip(a, b))
    if isinstance(a, float) and isinstance(b, (int, float)) or isinstance(b, float) and isinstance(a, (int, float)):
        return not math.isclose(a, b, rel_tol=rtol, abs_tol=rtol)
    return a != b


def run_case(name: str, cfg: dict, tmp: Path) -> dict:
    import suspid
    out = tmp / name
    cfg = {**cfg, "output": {"dir": str(out)}}
    if name == "sigkill-resume":
        path = tmp / f"{name}.yaml"
        path.write_text(yaml.safe_dump(cfg, sort_keys=False))
        killed_at = _kill_midway(path, out, 8)   # mid-EGO: 6 design points, then EGO's
    t0 = time.perf_counter()
    res = suspid.identify(str(path) if name == "sigkill-resume" else cfg).to_dict()
    row = {k: res.get(k) for k in KEYS}
    row["seconds"] = round(time.perf_counter() - t0, 1)
    if name == "sigkill-resume":
        row["killed_after_evaluations"] = killed_at
        row["simulated_after_resume"] = res.get("n_simulator_calls_this_session")
    return row


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    g = ap.add_mutually_exclusive_group(required=True)
    g.add_argument("--record", type=Path)
    g.add_argument("--compare", type=Path)
    ap.add_argument("--only", nargs="*")
    ap.add_argument("--rtol", type=float, default=1e-9, help="relative tolerance of float comparisons (1e-9)")
    args = ap.parse_args()
    all_cases = cases()
    names = args.only or list(all_cases)
    rows: dict[str, dict] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name in names:
            rows[name] = run_case(name, all_cases[name], Path(tmp))
            if args.record:
                previous = json.loads(args.record.read_text()) if args.record.exists() else {}
                args.record.write_text(json.dumps({**previous, "_machine": machine(), name: rows[name]}, indent=1))
            print(f"{name}: J_max {rows[name]['J_max']:.10g}, {rows[name]['n_simulator_calls']} calls, "
                  f"{rows[name]['stop_reason']}, {rows[name]['seconds']} s"
                  + (f", killed after {rows[name]['killed_after_evaluations']} evaluations, "
                     f"{rows[name]['simulated_after_resume']} simulated after the resume"
                     if "killed_after_evaluations" in rows[name] else ""), flush=True)
    if args.record:
        return 0
    before = json.loads(args.compare.read_text())
    recorded, here = before.get("_machine"), machine()
    bad = 0
    for name, row in rows.items():
        diff = [k for k in KEYS if differs(row.get(k), before.get(name, {}).get(k), args.rtol)]
        print(f"{name}: {f'same (rtol {args.rtol:g})' if not diff else 'DIFFERS in ' + ', '.join(diff)}")
        bad += bool(diff)
    if recorded != here:
        print(f"note: recorded on {recorded or 'an unrecorded machine'}, compared on {here}: a difference can be "
              f"machine-bound (module docstring); record both sides on one machine to test a change")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
