"""Localisation of one degraded element group, and its maintenance verdict, on the independent generators' data.

For each seed: a reference date at the generator's nominal values and, per case,
a measurement date with one element group degraded (:data:`CASES`: one bogie's
yaw dampers at 50 %, one lateral damper at 40 %, one air spring at 70 %, one
bogie's primary vertical dampers at 50 %) or nothing degraded (the null),
written by an independent generator (``--generator``: ``independent2``, a
time-domain model with nonlinear dampers, or ``independent``, a linear
frequency-domain model with Maxwell dampers and longitudinal dynamics; both
with one parameter per element, neither imports suspid). suspid reads the files
as a user would (``data.source: measured``, ``noise.reference``) and localises
the change over the kinds c_yaw, c_sec_y, k_sec_z and c_prim_z
(``suspid.workflows.elements.localise_problem``: no kind-level identification
first, localisation on request).

Scored per run: the group named first is the expected one at the finest level
the default sensors separate (left and right elements of a mirror-symmetric car
are not separable with centreline sensors: a single lateral damper or air spring
is expected as its bogie's pair, reported together); the value against the
expected one (for a pair, the mean of its two elements: what a change of the
pair together must match to first order) in % of the kind's admissible
interval (the paper's error measure), "ok" within 5 %; nothing named in the
nulls; the verdict (ok / warning / alarm / not assessable) of the named group
under the config's ``limits:`` (:data:`LIMITS`, the default precautionary
decision: an interval across one level gives the more severe state, counted as
borderline) against the state of the expected value under the same limits, and
in the nulls no warning or alarm; verdicts milder and more severe than the
truth's are counted apart.
The reference (ratio 1) is the acceptance bar: >= 90 % right first, every
null silent, every verdict right.

    PYTHONPATH=tests python benchmarks/bench_localisation.py [--generator independent2] [--seeds 1 2 3]
        [--segments 40] [--out DIR] [--floor auto] [--no-calibrate] [--gain-octaves none|OCTAVES]
        [--model-form-octaves none|OCTAVES] [--all-channels] [--physics NAME=VALUE ...]
        [--effect none|NAME:KEY=VALUE,... ...] [--creep-at axle|contact]

The last three switch this session's parts of the method off or change them, for the ablations of
``benchmarks/RESULTS.md``: the smooth gain estimated with the calibration, the interval's model-form part, the
value from the channels that agree. ``--physics`` sets the generator's own parameters on both dates (a feature
switched off: ``k_yaw_series=1e12``, ``f_bend=300``, ...) and ``--effect`` the effects of suspid's model, for the
ablations of the values' biases. "Covered" counts the truth inside the reported interval (and inside the
segments' interval alone): whether the intervals are as wide as the errors they must hold.
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

from independent import protocol as PR1  # noqa: E402
from independent import train as TR1  # noqa: E402
from independent2 import measure as MS  # noqa: E402
from independent2 import protocol as PR  # noqa: E402
from independent2 import vehicle as VH2  # noqa: E402

from bench_model_form import written_with  # noqa: E402  (benchmarks/, the script's own folder)
from suspid import api  # noqa: E402
from suspid.infra.lock import open_run_dir  # noqa: E402
from suspid.workflows.elements import localise_problem  # noqa: E402
from suspid.workflows.problem import build_problem  # noqa: E402
from suspid.workflows.verdict import limits_for, verdict_rows, zone  # noqa: E402

KINDS = ["c_yaw", "c_sec_y", "k_sec_z", "c_prim_z"]
CASES: dict[str, tuple[str, tuple[tuple[str, str], ...], float, str] | None] = {
    "yaw-bogie1-50": ("c_yaw", (("bogie1", "left"), ("bogie1", "right")), 0.5, "c_yaw[bogie1]"),
    "lateral-bogie2-left-40": ("c_sec_y", (("bogie2", "left"),), 0.4, "c_sec_y[bogie2]"),
    "airspring-bogie1-right-70": ("k_sec_z", (("bogie1", "right"),), 0.7, "k_sec_z[bogie1]"),
    "primary-dampers-bogie2-50": ("c_prim_z", tuple((j, s) for j in ("ws3", "ws4") for s in ("left", "right")),
                                  0.5, "c_prim_z[bogie2]"),
    "null": None,
}
"""Case -> (kind, degraded elements' tags, their fraction of nominal, the group expected first in suspid's
names: the finest level the default sensors separate), None for the null."""

GENERATORS = {
    "independent2": {"nominal": VH2.KINDS, "generate": MS.generate_date, "vehicle": PR.VEHICLE, "effects": [],
                     "contact_point": False},
    "independent": {"nominal": TR1.SHARED, "generate": TR1.generate_date, "vehicle": PR1.VEHICLE,
                    "effects": [{"name": "carbody-bending", "frequency_hz": 10.0}], "contact_point": True},
}
"""Generator -> its kind-level nominal values (SI), its date writer, suspid's vehicle for its car, the effects of
suspid's model for it (``simulator.options.effects``) and whether its lateral creep forces act at the contact
points (``contact.creep_at_contact_point``). The first generator's car has a flexible carbody and wheelsets that
roll on an elastic contact with the creep force at the contact points: suspid's model has the carbody-bending
effect at the effect's default guess (10 Hz; its frequency and damping calibrated on the reference date with the
other calibratable model parameters, the generator's own value stays hidden) and the contact-point creep. The
second generator's carbody is rigid and its wheelsets have no roll. ``--effect none`` and ``--creep-at axle``
leave them out (the ablations)."""

LIMITS = {"c_yaw": {"warning": -25, "alarm": -40}, "c_sec_y": {"warning": -25, "alarm": -40},
          "c_prim_z": {"warning": -25, "alarm": -40},
          "k_sec_z": {"warning": [-10, 10], "alarm": [-25, 25]}}
"""The config's ``limits:``: dampers warn at 25 % below nominal and alarm at 40 % (docs/verdict.md's
example); air springs both ways, a stiffness change of 10 % warns and 25 % alarms."""


def degraded(generator: str, case: str) -> dict[str, float]:
    """The generator's element values of ``case`` (SI)."""
    spec = CASES[case]
    if spec is None:
        return {}
    kind, tags, fraction, _ = spec
    nominal = GENERATORS[generator]["nominal"][kind]
    return {f"{kind}[{','.join(t)}]": fraction * nominal for t in tags}


def expected(generator: str, case: str) -> tuple[str | None, float | None]:
    """(group expected first, its expected value in SI: the mean over the group's elements)."""
    spec = CASES[case]
    if spec is None:
        return None, None
    kind, tags, fraction, group = spec
    nominal = GENERATORS[generator]["nominal"][kind]
    n_members = 4 if kind == "c_prim_z" else 2              # a bogie's primary dampers; a bogie's pair
    return group, nominal * (1.0 - (1.0 - fraction) * len(tags) / n_members)

SPEED = 300.0 / 3.6
LINEAR = {"damper_asym": 0.0, "f_blow_z": 1e12, "f_blow_y": 1e12, "yaw_f_blow": 1e12, "f_blow_prim": 1e12,
          "mu": 1e9, "flange_gap": 1e3}
"""The generator's own parameters that make it linear (symmetric dampers, no blow-off, no creep saturation, no
flange contact), for ``--linear``: what is left of the value's error is then not the dampers' nonlinearity."""


def config_for(generator: str, case_dir: Path, reference: Path, seed: int, segments: int,
               floor: str = "none", calibrate: bool = True, localisation: dict | None = None,
               effects: list[dict] | None = None, contact_point: bool | None = None) -> dict:
    """The config of one case: the generator's vehicle, ``effects`` and ``contact_point`` in suspid's model (None:
    the generator's entry in :data:`GENERATORS`), the localisation over :data:`KINDS`, the limits :data:`LIMITS`."""
    effects = GENERATORS[generator]["effects"] if effects is None else effects
    contact_point = GENERATORS[generator]["contact_point"] if contact_point is None else contact_point
    if generator == "independent2":
        path = PR.write_config(case_dir, seed=seed, identified=tuple(KINDS))
        cfg = yaml.safe_load(path.read_text(encoding="utf-8"))
    else:
        cfg = {"name": "config", "seed": seed,
               "simulator": {"plugin": "exudyn-train", "options": {"solver": "frequency", "fs_hz": 100.0,
                                                                   "vehicle": dict(PR1.VEHICLE)}},
               "parameters": {n: {} for n in KINDS}, "data": {"source": "measured"}, "noise": {},
               "spectra": dict(PR1.SPECTRA)}
    cfg["data"]["measurements"] = str(case_dir / "measurement" / "accelerations")
    cfg["data"]["track_file"] = str(case_dir / "measurement" / "track")
    cfg["noise"]["reference"] = {"measurements": str(reference / "accelerations"),
                                 "track_file": str(reference / "track")}
    cfg["noise"]["floor"] = floor
    if effects:
        cfg["simulator"]["options"]["effects"] = [dict(e) for e in effects]
    if contact_point:
        cfg["simulator"]["options"].setdefault("contact", {})["creep_at_contact_point"] = True
    cfg["localisation"] = {"kinds": KINDS, "enabled": True, "n_segments": min(8, segments), "calibrate": calibrate,
                          **(localisation or {})}
    cfg["limits"] = LIMITS
    cfg["output"] = {"dir": str(case_dir / "run")}
    return cfg


def run_case(cfg: dict) -> tuple[dict, float, dict, list, dict]:
    """The localisation entry, its wall time (s), the admissible interval's width (SI) of every kind, the
    verdict rows of the named group(s) and the config's limits."""
    t0 = time.perf_counter()
    config = api.load_config(cfg)
    with open_run_dir(config.run_dir(), config_name=config.name, config_file=None) as ledger:
        problem = build_problem(config, ledger)
        out = localise_problem(problem, config.localisation, ledger=ledger)
    parameters = problem.simulator.parameters()
    widths = {p.name: p.upper - p.lower for p in parameters}
    empty = {"parameters": [], "w_opt": {}, "interval": {}, "identifiable": {}}
    rows = verdict_rows(empty, parameters, config.limits, localisation=out)
    return out, time.perf_counter() - t0, widths, rows, config.limits


def expected_state(group: str, value: float, nominal: float, limits) -> str:
    lim = limits_for(group, limits)
    return zone(100.0 * (value / nominal - 1.0), lim.warning, lim.alarm)


def score(generator: str, case: str, out: dict, width: float | None, verdicts: list, limits) -> dict:
    """Right group first; value: error in % of the kind's admissible interval ``width`` (SI; the paper's
    error measure), ok within 5 %; whether the truth lies in the reported interval; the verdict against the
    expected value's state under the same ``limits`` (nulls: no warning or alarm)."""
    group, truth = expected(generator, case)
    row = out["rows"][0] if out["rows"] else None
    # the same hypotheses read with localisation.direction: decrease (a change must be a loss)
    losses = [h for h in out["hypotheses"] if h["value"] < h["nominal"]
              and h["evidence"] >= out["options"]["min_evidence"]]
    first_loss = losses[0]["group"] if losses else None
    right_decrease = first_loss == group
    states = [v.verdict for v in verdicts]
    if group is None:
        return {"right": row is None, "value_ok": None, "named": row["group"] if row else "-",
                "right_decrease": right_decrease, "verdict": ", ".join(states) or "-", "expected_verdict": "-",
                "verdict_ok": not any(s in ("warning", "alarm") for s in states)}
    nominal = GENERATORS[generator]["nominal"][kind_of(group)]
    want = expected_state(group, truth, nominal, limits)
    if row is None:
        return {"right": False, "value_ok": False, "named": "-", "right_decrease": right_decrease,
                "verdict": "-", "expected_verdict": want, "verdict_ok": False}
    lo, hi = row["interval"]
    error = 100.0 * (row["value"] - truth) / width if width else float("nan")
    named = next((v for v in verdicts if v.name == row["group"]), None)
    mine = named.verdict if named is not None else "-"
    return {"right": row["group"] == group, "value_ok": bool(abs(error) <= 5.0), "error_percent": error,
            "covered": bool(lo <= truth <= hi), "named": row["group"], "value": row["value"],
            "covered_statistical": bool(min(row.get("interval_statistical", (lo, hi))) <= truth
                                        <= max(row.get("interval_statistical", (lo, hi)))),
            "change_percent": 100.0 * (row["value"] / row["nominal"] - 1.0),
            "right_decrease": right_decrease,
            "interval": (lo, hi), "evidence": row["evidence"], "alternatives": [a["group"] for a in row["alternatives"]],
            "dropped": row.get("dropped_channels", []),
            "together": row["separable"] or len(row["members"]) > 1,
            "verdict": mine, "borderline": bool(named is not None and named.borderline),
            "expected_verdict": want, "verdict_ok": row["group"] == group and mine == want}


SEVERITY = {"ok": 0, "warning": 1, "alarm": 2}


def milder(row: dict) -> bool:
    """A degraded case whose verdict is a milder state than its truth's (the unsafe error: no action, or an
    inspection where a replacement is due); "not assessable" is not milder, it asks for no trust."""
    want, got = row["expected_verdict"], row["verdict"]
    if want not in SEVERITY:
        return False
    return got == "-" or (got in SEVERITY and SEVERITY[got] < SEVERITY[want])


def harsher(row: dict) -> bool:
    """A degraded case whose verdict is a more severe state than its truth's (the costly error: an inspection
    or a replacement that was not due), which the precautionary decision on a borderline interval risks."""
    want, got = row["expected_verdict"], row["verdict"]
    return want in SEVERITY and got in SEVERITY and SEVERITY[got] > SEVERITY[want]


def kind_of(name: str) -> str:
    return name.split("[", 1)[0]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--generator", choices=list(GENERATORS), default="independent2")
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    ap.add_argument("--segments", type=int, default=12, help="segments per date (1000 m each); the acceptance "
                    "figures of benchmarks/RESULTS.md are measured at 100, the paper's data size (about one hundred "
                    "segments of a few km per date), and at 40 as the small-data sensitivity; the default 12 is a "
                    "quick look")
    ap.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES))
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--floor", choices=["none", "auto"], default="none", help="noise.floor of the config")
    ap.add_argument("--no-calibrate", action="store_true", help="localisation.calibrate: false (linearise at the "
                    "model parameters' nominal values)")
    ap.add_argument("--linear", action="store_true", help="independent2 only: its dampers and contact made linear "
                    "(LINEAR) on both dates")
    ap.add_argument("--physics", nargs="*", default=[], metavar="NAME=VALUE",
                    help="the generator's own parameters on both dates (e.g. k_bush_sec_y=1e12: a lateral damper "
                    "without its series bush), for the ablations of the generator's features")
    ap.add_argument("--effect", nargs="*", default=[], metavar="NAME:KEY=VALUE,...",
                    help="the effects in suspid's model (simulator.options.effects) instead of the generator's entry in "
                    "GENERATORS, e.g. carbody-bending:frequency_hz=9.5,damping=0.02; 'none': no effect")
    ap.add_argument("--creep-at", choices=["axle", "contact"], default=None, help="suspid's lateral creep force "
                    "at the axle or at the contact points (contact.creep_at_contact_point) instead of the "
                    "generator's entry in GENERATORS")
    ap.add_argument("--gain-octaves", default="1.0", help="localisation.calibration_gain_octaves ('none': a flat "
                    "gain per channel only)")
    ap.add_argument("--model-form-octaves", default="1.0", help="localisation.model_form_octaves ('none': the "
                    "segments' spread only)")
    ap.add_argument("--all-channels", action="store_true", help="localisation.consistent_channels: false (the "
                    "named group's value from every channel)")
    a = ap.parse_args(argv)
    octaves = {"calibration_gain_octaves": None if a.gain_octaves == "none" else float(a.gain_octaves),
               "model_form_octaves": None if a.model_form_octaves == "none" else float(a.model_form_octaves),
               "consistent_channels": not a.all_channels}
    if a.linear and a.generator != "independent2":
        ap.error("--linear is for --generator independent2")
    effects = [dict(e) for e in GENERATORS[a.generator]["effects"]] if not a.effect else []
    for item in ([] if a.effect == ["none"] else a.effect):
        name, _, rest = item.partition(":")
        try:
            effects.append({"name": name} | {k: float(v) for k, v in (kv.split("=", 1) for kv in rest.split(",")
                                                                      if kv)})
        except ValueError:
            ap.error(f"--effect takes NAME:KEY=VALUE,... with numbers, got {item}")
    contact_point = GENERATORS[a.generator]["contact_point"] if a.creep_at is None else a.creep_at == "contact"
    generate = GENERATORS[a.generator]["generate"]
    linear = dict(LINEAR) if a.linear else {}
    try:
        linear |= {k: float(v) for k, v in (item.split("=", 1) for item in a.physics)}
    except ValueError:
        ap.error(f"--physics takes NAME=VALUE with a number, got {a.physics}")
    base = a.out or Path(tempfile.mkdtemp(prefix="bench-localisation-"))
    print(f"load {os.getloadavg()[0]:.1f}; generator {a.generator}; {len(a.seeds)} seed(s) x {len(a.cases)} case(s), "
          f"{a.segments} segments per date{', linear generator' if a.linear else ''}"
          f"{'; generator physics ' + str(a.physics) if a.physics else ''}"
          f"{'; suspid effects ' + str(effects) if effects else ''}"
          f"{'; creep at the contact points' if contact_point else ''}; noise.floor {a.floor}; "
          f"localisation.calibrate {not a.no_calibrate}; {octaves}; files in {base}", flush=True)
    rows = []
    for seed in a.seeds:
        reference = base / f"seed{seed}" / "reference"
        if not written_with(reference / "truth.json", a.segments):
            t0 = time.perf_counter()
            generate(reference, linear, seed=seed * 2 + 1, n_segments=a.segments, speed_mps=SPEED,
                     chainage_m=10_000.0, instrument_seed=seed)
            print(f"seed {seed}: reference date generated in {time.perf_counter() - t0:.0f} s", flush=True)
        for case in a.cases:
            case_dir = base / f"seed{seed}" / case
            if not written_with(case_dir / "measurement" / "truth.json", a.segments):
                generate(case_dir / "measurement", degraded(a.generator, case) | linear, seed=seed * 2 + 2,
                         n_segments=a.segments, speed_mps=SPEED, chainage_m=200_000.0, instrument_seed=seed)
            out, wall, widths, verdicts, limits = run_case(config_for(a.generator, case_dir, reference, seed, a.segments,
                                                              a.floor, not a.no_calibrate, octaves, effects,
                                                              contact_point))
            kind = kind_of(expected(a.generator, case)[0] or "")
            s = score(a.generator, case, out, widths.get(kind), verdicts, limits) | {"case": case, "seed": seed,
                                                                                     "wall_s": wall}
            rows.append(s)
            print(f"seed {seed} {case:<27} named {s['named']:<18} right {s['right']!s:<5} (as a loss "
                  f"{s['right_decrease']!s:<5}) value_ok {s['value_ok']!s:<5} "
                  + (f"value {s['value']:.4g} ({s['change_percent']:+.0f} %) [{s['interval'][0]:.4g}, "
                     f"{s['interval'][1]:.4g}] error {s['error_percent']:+.1f} % evidence {s['evidence']:.0f} "
                     f"alternatives {s['alternatives']} dropped {s['dropped']} " if "value" in s else "")
                  + f"verdict {s['verdict']} (expected {s['expected_verdict']}: {'ok' if s['verdict_ok'] else 'WRONG'})"
                  + f" ({wall:.0f} s)", flush=True)
    degraded_rows = [r for r in rows if r["case"] != "null"]
    nulls = [r for r in rows if r["case"] == "null"]
    right = np.mean([r["right"] for r in degraded_rows]) if degraded_rows else float("nan")
    value_ok = np.mean([bool(r["value_ok"]) for r in degraded_rows]) if degraded_rows else float("nan")
    silent = np.mean([r["right"] for r in nulls]) if nulls else float("nan")
    per_seed = [np.mean([r["right"] for r in degraded_rows if r["seed"] == s]) for s in a.seeds] \
        if degraded_rows else []
    print(f"\nright group first: {100 * right:.0f} % of {len(degraded_rows)} (per seed mean "
          f"{100 * np.mean(per_seed):.0f} ± {100 * np.std(per_seed):.0f} %; ratio to the 90 % bar {right / 0.9:.2f})")
    errors = [abs(r["error_percent"]) for r in degraded_rows if "error_percent" in r and r["right"]]
    covered = np.mean([bool(r.get("covered")) for r in degraded_rows]) if degraded_rows else float("nan")
    covered_stat = np.mean([bool(r.get("covered_statistical")) for r in degraded_rows]) if degraded_rows \
        else float("nan")
    print(f"value within 5 % of the admissible interval: {100 * value_ok:.0f} % of {len(degraded_rows)} (|error| of "
          f"the right ones {np.mean(errors) if errors else float('nan'):.1f} ± {np.std(errors) if errors else 0:.1f} % "
          f"of the interval); truth inside the reported interval: {100 * covered:.0f} % (inside the segments' "
          f"statistical interval alone: {100 * covered_stat:.0f} %)")
    print(f"nulls with nothing named: {100 * silent:.0f} % of {len(nulls)}")
    print(f"verdict right: {sum(r['verdict_ok'] for r in rows)} of {len(rows)} (degraded "
          f"{sum(r['verdict_ok'] for r in degraded_rows)} of {len(degraded_rows)}, nulls "
          f"{sum(r['verdict_ok'] for r in nulls)} of {len(nulls)}); milder than the truth's state (ok or "
          f"warning for a worse one, nothing named for a degradation): "
          f"{sum(milder(r) for r in degraded_rows)}; more severe than the truth's: "
          f"{sum(harsher(r) for r in degraded_rows)}; borderline (the interval across one level, the more severe "
          f"state given): {sum(bool(r.get('borderline')) for r in degraded_rows)}; not assessable: "
          f"{sum(r['verdict'] == 'not assessable' for r in degraded_rows)}")
    print(f"read as losses only (localisation.direction: decrease): right first "
          f"{100 * np.mean([r['right_decrease'] for r in degraded_rows]):.0f} %, nulls silent "
          f"{100 * np.mean([r['right_decrease'] for r in nulls]):.0f} %")
    print(f"wall time per case (localisation only): {np.mean([r['wall_s'] for r in rows]):.0f} s; "
          f"load {os.getloadavg()[0]:.1f}")
    print("\n| case | " + " | ".join(f"seed {s}" for s in a.seeds) + " |\n|---|" + "---|" * len(a.seeds))
    for case in a.cases:
        cells = []
        for seed in a.seeds:
            r = next(r for r in rows if r["case"] == case and r["seed"] == seed)
            v = f"{r['value']:.3g} ({r['change_percent']:+.0f} %), error {r['error_percent']:+.1f} %, " \
                if "value" in r else ""
            cells.append(f"{r['named']} {v}verdict {r['verdict']}{' (borderline)' if r.get('borderline') else ''}"
                         f"{'' if r['verdict_ok'] else ' (WRONG: expected ' + r['expected_verdict'] + ')'}")
        print(f"| {case} | " + " | ".join(cells) + " |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
