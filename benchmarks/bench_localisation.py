"""Localisation of one degraded element group on the second independent generator's data (tests/independent2).

For each seed: a reference date at w0 and, per case, a measurement date with one
element group degraded (``independent2.protocol.ELEMENT_CASES``: one bogie's yaw
dampers at 50 %, one lateral damper at 40 %, one air spring at 70 %, one bogie's
primary vertical dampers at 50 %) or nothing degraded (the null), written by the
generator (its own model, integration and measurement chain; no suspid code).
suspid reads the files as a user would (``data.source: measured``,
``noise.reference``) and localises the change over the kinds c_yaw, c_sec_y,
k_sec_z and c_prim_z (``suspid.workflows.elements.localise_problem``: no
kind-level identification first, localisation on request).

Scored per run: the group named first is the expected one at the finest level
the default sensors separate (left and right elements of a mirror-symmetric car
are not separable with centreline sensors: a single lateral damper or air spring
is expected as its bogie's pair, reported together); the value against the
expected one (for a pair, the mean of its two elements: what a change of the
pair together must match to first order), "ok" when inside the interval or
within 5 %; nothing named in the nulls. The reference (ratio 1) is the
acceptance bar: >= 90 % right first, every null silent.

    PYTHONPATH=tests python benchmarks/bench_localisation.py [--seeds 1 2 3] [--segments 12] [--out DIR]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from independent2 import measure as MS  # noqa: E402
from independent2 import protocol as PR  # noqa: E402

from suspid import api  # noqa: E402
from suspid.infra.lock import open_run_dir  # noqa: E402
from suspid.workflows.elements import localise_problem  # noqa: E402
from suspid.workflows.problem import build_problem  # noqa: E402

KINDS = ["c_yaw", "c_sec_y", "k_sec_z", "c_prim_z"]
EXPECTED = {
    "yaw-bogie1-50": ("c_yaw[bogie1]", 150e3),
    "lateral-bogie2-left-40": ("c_sec_y[bogie2]", (12e3 + 30e3) / 2),
    "airspring-bogie1-right-70": ("k_sec_z[bogie1]", (245e3 + 350e3) / 2),
    "primary-dampers-bogie2-50": ("c_prim_z[bogie2]", 5e3),
    "null": (None, None),
}
"""Case -> (group expected first in suspid's names, its expected value in SI)."""

SPEED = 300.0 / 3.6
LINEAR = {"damper_asym": 0.0, "f_blow_z": 1e12, "f_blow_y": 1e12, "yaw_f_blow": 1e12, "f_blow_prim": 1e12,
          "mu": 1e9, "flange_gap": 1e3}
"""The generator's own parameters that make it linear (symmetric dampers, no blow-off, no creep saturation, no
flange contact), for ``--linear``: what is left of the value's error is then not the dampers' nonlinearity."""


def config_for(case_dir: Path, reference: Path, seed: int, segments: int) -> dict:
    path = PR.write_config(case_dir, seed=seed, identified=tuple(KINDS))
    cfg = yaml.safe_load(path.read_text(encoding="utf-8"))
    cfg["data"]["measurements"] = str(case_dir / "measurement" / "accelerations")
    cfg["data"]["track_file"] = str(case_dir / "measurement" / "track")
    cfg["noise"]["reference"] = {"measurements": str(reference / "accelerations"),
                                 "track_file": str(reference / "track")}
    cfg["localisation"] = {"kinds": KINDS, "enabled": True, "n_segments": min(8, segments)}
    cfg["output"] = {"dir": str(case_dir / "run")}
    return cfg


def run_case(cfg: dict) -> tuple[dict, float, dict]:
    """The localisation entry, its wall time (s) and the admissible interval's width (SI) of every kind."""
    t0 = time.perf_counter()
    config = api.load_config(cfg)
    with open_run_dir(config.run_dir(), config_name=config.name, config_file=None) as ledger:
        problem = build_problem(config, ledger)
        out = localise_problem(problem, config.localisation)
    widths = {p.name: p.upper - p.lower for p in problem.simulator.parameters()}
    return out, time.perf_counter() - t0, widths


def score(case: str, out: dict, width: float | None = None) -> dict:
    """Right group first; value: error in % of the kind's admissible interval ``width`` (SI; the project's
    "error %"), ok within 5 %; whether the truth lies in the reported interval."""
    group, truth = EXPECTED[case]
    row = out["rows"][0] if out["rows"] else None
    # the same hypotheses read with localisation.direction: decrease (a change must be a loss)
    losses = [h for h in out["hypotheses"] if h["value"] < h["nominal"]
              and h["evidence"] >= out["options"]["min_evidence"]]
    first_loss = losses[0]["group"] if losses else None
    right_decrease = first_loss == group
    if group is None:
        return {"right": row is None, "value_ok": None, "named": row["group"] if row else "-",
                "right_decrease": right_decrease}
    if row is None:
        return {"right": False, "value_ok": False, "named": "-", "right_decrease": right_decrease}
    lo, hi = row["interval"]
    error = 100.0 * (row["value"] - truth) / width if width else float("nan")
    return {"right": row["group"] == group, "value_ok": bool(abs(error) <= 5.0), "error_percent": error,
            "covered": bool(lo <= truth <= hi), "named": row["group"], "value": row["value"],
            "right_decrease": right_decrease,
            "interval": (lo, hi), "evidence": row["evidence"], "alternatives": [a["group"] for a in row["alternatives"]],
            "together": row["separable"] or len(row["members"]) > 1}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    ap.add_argument("--segments", type=int, default=12, help="segments per date (1000 m each)")
    ap.add_argument("--cases", nargs="+", default=list(EXPECTED))
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--linear", action="store_true", help="the generator's dampers and contact made linear (LINEAR) "
                    "on both dates")
    a = ap.parse_args(argv)
    base = a.out or Path(tempfile.mkdtemp(prefix="bench-localisation-"))
    print(f"load {os.getloadavg()[0]:.1f}; {len(a.seeds)} seed(s) x {len(a.cases)} case(s), {a.segments} segments "
          f"per date{', linear generator' if a.linear else ''}; files in {base}", flush=True)
    rows = []
    for seed in a.seeds:
        reference = base / f"seed{seed}" / "reference"
        if not (reference / "truth.json").exists():
            t0 = time.perf_counter()
            MS.generate_date(reference, dict(LINEAR) if a.linear else {}, seed=seed * 2 + 1, n_segments=a.segments, speed_mps=SPEED,
                             chainage_m=10_000.0, instrument_seed=seed)
            print(f"seed {seed}: reference date generated in {time.perf_counter() - t0:.0f} s", flush=True)
        for case in a.cases:
            case_dir = base / f"seed{seed}" / case
            if not (case_dir / "measurement" / "truth.json").exists():
                w = ({} if case == "null" else PR.ELEMENT_CASES[case]) | (LINEAR if a.linear else {})
                MS.generate_date(case_dir / "measurement", w, seed=seed * 2 + 2, n_segments=a.segments,
                                 speed_mps=SPEED, chainage_m=200_000.0, instrument_seed=seed)
            out, wall, widths = run_case(config_for(case_dir, reference, seed, a.segments))
            kind = (EXPECTED[case][0] or "").split("[")[0]
            s = score(case, out, widths.get(kind)) | {"case": case, "seed": seed, "wall_s": wall}
            rows.append(s)
            print(f"seed {seed} {case:<27} named {s['named']:<18} right {s['right']!s:<5} (as a loss "
                  f"{s['right_decrease']!s:<5}) value_ok "
                  f"{s['value_ok']!s:<5} " + (f"value {s['value']:.4g} [{s['interval'][0]:.4g}, "
                                             f"{s['interval'][1]:.4g}] error {s['error_percent']:+.1f} % evidence {s['evidence']:.0f} "
                                             f"alternatives {s['alternatives']}" if "value" in s else "")
                  + f" ({wall:.0f} s)", flush=True)
    degraded = [r for r in rows if r["case"] != "null"]
    nulls = [r for r in rows if r["case"] == "null"]
    right = np.mean([r["right"] for r in degraded]) if degraded else float("nan")
    value_ok = np.mean([bool(r["value_ok"]) for r in degraded]) if degraded else float("nan")
    silent = np.mean([r["right"] for r in nulls]) if nulls else float("nan")
    per_seed = [np.mean([r["right"] for r in degraded if r["seed"] == s]) for s in a.seeds] if degraded else []
    print(f"\nright group first: {100 * right:.0f} % of {len(degraded)} (per seed mean {100 * np.mean(per_seed):.0f} "
          f"± {100 * np.std(per_seed):.0f} %; ratio to the 90 % bar {right / 0.9:.2f})")
    errors = [abs(r["error_percent"]) for r in degraded if "error_percent" in r and r["right"]]
    covered = np.mean([bool(r.get("covered")) for r in degraded]) if degraded else float("nan")
    print(f"value within 5 % of the admissible interval: {100 * value_ok:.0f} % of {len(degraded)} (|error| of the "
          f"right ones {np.mean(errors) if errors else float('nan'):.1f} ± {np.std(errors) if errors else 0:.1f} % of the "
          f"interval); truth inside the reported interval: {100 * covered:.0f} %")
    print(f"nulls with nothing named: {100 * silent:.0f} % of {len(nulls)}")
    print(f"read as losses only (localisation.direction: decrease): right first "
          f"{100 * np.mean([r['right_decrease'] for r in degraded]):.0f} %, nulls silent "
          f"{100 * np.mean([r['right_decrease'] for r in nulls]):.0f} %")
    print(f"wall time per case (localisation only): {np.mean([r['wall_s'] for r in rows]):.0f} s; "
          f"load {os.getloadavg()[0]:.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
