"""The discrepancy workflow on hidden-effect experiments: the table of benchmarks/RESULTS.md.

For each effect of the catalogue, the measurement-date data are simulated
with the effect (``data.measurement.simulator_options``) and the
identification model lacks it; the cases, data and checks are those of
``tests/test_diagnose.py`` (v = 32 segments of 600 m, v0 = 48 reference
segments, reference model error 1.5 dB systematic and 0.5 dB per segment;
the diagnosis at the nominal parameters, the gap after with the fitted effect
at the same parameters). Also the null case, the two confounders and,
with ``--demo``, ``configs/diagnose-hidden-bending.yaml`` (identification
before and after). With ``--independent``, the hidden-effect experiments on
the independent train (``tests/independent/effects.py``: data suspid's code
did not make; 40 measurement and 48 reference segments per speed; the
suspension fitted under D before and jointly with the effects after, its
errors in % of the admissible interval) instead.

    python benchmarks/bench_diagnose.py [--demo] [--seeds 3 4 5]
    python benchmarks/bench_diagnose.py --independent [--cases bending tilt ...] [--seeds 3 4 5] [--floor auto]
        [--keep DIR] [--from DIR]

``--floor`` sets ``noise.floor`` of the reference-date noise model of the independent experiments:
``none``, ``auto``, or ``spec=<density>`` (the sensors' noise density, (m/s²)²/Hz one-sided; the
independent train's sensors have 1e-8). ``--at nominal`` diagnoses at the nominal parameters (the truth of
the null cases) instead of the identified ones: the noise model's share of the flags, without the
identification's error. ``--keep DIR`` writes the experiments (data, configs, runs) under DIR instead of a
temporary folder, for a look at their ``diagnosis.json`` afterwards; ``--from DIR`` prints the table of experiments
already diagnosed under DIR (a ``--keep`` folder, or the ``--basetemp`` of the acceptance run
``pytest -m acceptance tests/test_diagnose_independent.py --basetemp DIR``) without running anything.
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("SUSPID_DISABLE_PLUGIN_AUTOLOAD", "1")
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from test_diagnose import CASES, KMH, _config, _main_error, _shrink  # noqa: E402

import suspid  # noqa: E402


def _run(path: Path) -> tuple[dict, float]:
    t0 = time.perf_counter()
    out = suspid.diagnose(path)
    return out.diagnosis, time.perf_counter() - t0


def _located(d: dict, frequency: float | None) -> str:
    if not d["flagged"]:
        return "nothing"
    rows = d["flagged"]
    if frequency is not None:
        rows = [r for r in rows if r["f_low_hz"] <= frequency <= r["f_high_hz"]] or rows
    best = max(rows, key=lambda r: abs(r["magnitude_db"]))
    return (f"{best['channel']} {best['f_low_hz']:.3g}-{best['f_high_hz']:.3g} Hz ({best['sign']}"
            f"{abs(best['magnitude_db']):.1f} dB); {len(d['flagged'])} cells")


def _row(label: str, d: dict, truth_name: str | None, truth: float | None, frequency: float | None,
         seconds: float) -> str:
    named = d["named"] or "(nothing)"
    if d["named"] and truth_name == d["named"]:
        from suspid import registry

        main = registry.get("effect", d["named"]).main_parameter
        est = d["named_parameters"][main]
        err = f"{main} {est:.4g} vs {truth:g}: {100 * _main_error(d, d['named'], truth):.2f} %"
    else:
        err = "-"
    gb, ga = d["gap_before"], d["gap_after"]
    if ga:
        share, integ = _shrink(d)
        gap = (f"{100 * gb['share_flagged']:.1f} % → {100 * ga['share_flagged']:.1f} % ({100 * share:.0f} %) | "
               f"{gb['integrated_db_hz']:.1f} → {ga['integrated_db_hz']:.1f} ({100 * integ:.0f} %)")
    else:
        gap = f"{100 * gb['share_flagged']:.1f} % → - | {gb['integrated_db_hz']:.1f} → -"
    return f"| {label} | {_located(d, frequency)} | {named} | {err} | {gap} | {seconds:.0f} |"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--demo", action="store_true", help="also run configs/diagnose-hidden-bending.yaml")
    ap.add_argument("--seeds", type=int, nargs="*", default=[3], help="experiment seeds (the tests use 3)")
    ap.add_argument("--independent", action="store_true", help="the experiments on the independent train")
    ap.add_argument("--cases", nargs="*", default=None, help="independent cases (default: all)")
    ap.add_argument("--at", default="identified", choices=["identified", "nominal"],
                    help="diagnose.at of the independent experiments")
    ap.add_argument("--floor", default="none", help="noise.floor of the independent experiments' noise model: "
                    "none, auto or spec=<density in (m/s²)²/Hz>")
    ap.add_argument("--keep", type=Path, default=None, help="keep the independent experiments under this folder")
    ap.add_argument("--from", dest="source", type=Path, default=None,
                    help="print the independent table from experiments already diagnosed in this folder (a --keep "
                         "folder, or pytest's --basetemp of the acceptance run)")
    args = ap.parse_args()
    if args.independent:
        return independent(args.seeds, args.cases, args.floor, args.at, args.keep, args.source)
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"# bench_diagnose  {datetime.date.today()}  python {platform.python_version()}  {platform.machine()}  "
          f"{os.cpu_count()} cpus  load average {load:.2f}")
    print("| hidden effect (seed) | located: strongest flagged cell at the effect's frequency | named | "
          "main parameter error | flagged cells before → after (shrink) | integrated dB·Hz before → after "
          "(shrink) | s |")
    print("|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for seed in args.seeds:
            for name, (hidden, truth, overrides, (_, _, frequency)) in CASES.items():
                path = _config(tmp, f"{name.replace('-', '_')}_{seed}", [{"name": name, **hidden}], **overrides)
                _reseed(path, seed)
                d, s = _run(path)
                print(_row(f"{name} {_describe(hidden)} ({seed})", d, name, truth, frequency, s), flush=True)
            for hidden, label in (({"name": "wheel-polygon", "order": 1, "amplitude_m": 1e-4, "wheelsets": [3]},
                                   "confounder: polygon k=1 at 120 km/h (11.5 Hz)"),
                                  ({"name": "carbody-bending", "frequency_hz": 11.5, "damping": 0.02},
                                   "confounder: bending 11.5 Hz at 120 km/h")):
                path = _config(tmp, f"conf_{hidden['name']}_{seed}", [hidden], speed_kmh=120.0)
                _reseed(path, seed)
                d, s = _run(path)
                truth = hidden.get("order", hidden.get("frequency_hz"))
                f = 120 * KMH / (math.pi * 0.92) if hidden["name"] == "wheel-polygon" else 11.5
                print(_row(f"{label} ({seed})", d, hidden["name"], truth, f, s), flush=True)
            path = _config(tmp, f"null_{seed}", [])
            _reseed(path, seed)
            d, s = _run(path)
            print(_row(f"null case: no hidden effect ({seed})", d, None, None, None, s), flush=True)
        if args.demo:
            d, s = _run(ROOT / "configs" / "diagnose-hidden-bending.yaml")
            print()
            print(_row("demo configs/diagnose-hidden-bending.yaml (identified before and after)", d,
                       "carbody-bending", 9.5, 9.5, s))
            gb, ga = d["gap_before"], d["gap_after"]
            print(f"# demo J {gb['J']:.5f} -> {ga['J']:.5f}; errors (% of interval) before "
                  f"{json.dumps({k: round(v, 2) for k, v in gb['errors_percent'].items()})} after "
                  f"{json.dumps({k: round(v, 2) for k, v in ga['errors_percent'].items()})}")


def independent(seeds: list[int], cases: list[str] | None, floor: str = "none", at: str = "identified",
                keep: Path | None = None, source: Path | None = None) -> None:
    """The table of the experiments on the independent train (docs/diagnose.md, "Measured accuracy").

    :param source: a folder of experiments already diagnosed (``--keep`` of an earlier run, or the
        ``--basetemp`` of ``pytest -m acceptance tests/test_diagnose_independent.py``): their rows are printed
        from their ``diagnosis.json`` (the s column: the diagnosis's own wall time), nothing is run.
    """
    import contextlib

    from independent import effects as HE

    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"# bench_diagnose --independent --floor {floor} --at {at}  {datetime.date.today()}  {os.cpu_count()} cpus  "
          f"load average {load:.2f}" + (f"  (rows read from {source})" if source is not None else ""))
    print("| case (seed) | named (steps) | effect parameters | flagged before → after each step | "
          "errors before → after (% of interval; n.i.: not identifiable under the data-group check) | "
          "unexplained (first) | channel-level gains | reported suspension (D joint fit / re-identified) | s |")
    print("|---|---|---|---|---|---|---|---|---|")
    folder = contextlib.nullcontext(str(keep)) if keep is not None else tempfile.TemporaryDirectory()
    with folder as tmp:
        for seed in seeds:
            for case in cases or list(HE.CASES):
                c = HE.CASES[case]
                t0 = time.perf_counter()
                if source is not None:
                    found = sorted(Path(source).glob(f"**/{case}-{seed}/config.yaml"))
                    if not found:
                        print(f"| {case} ({seed}) | not in {source} | | | | | | | |", flush=True)
                        continue
                    path = found[0]
                    d = json.loads((path.parent / "runs" / "config" / "diagnosis.json").read_text())
                    seconds = d["wall_time_s"]
                else:
                    path = HE.prepare(Path(tmp) / f"{case}-{seed}", c.hidden, seed=seed, speeds_kmh=c.speeds,
                                      w_ref=c.w_ref, noise_asd=c.noise_asd, noise=_noise_options(floor),
                                      diagnose={"at": at})
                    d = suspid.diagnose(path).diagnosis
                    seconds = time.perf_counter() - t0
                print(_independent_row(case, seed, path, d, seconds), flush=True)


def _independent_row(case: str, seed: int, path: Path, d: dict, seconds: float) -> str:
    """One row of the independent table: ``d`` the diagnosis of the experiment whose config is ``path``."""
    result_json = path.parent / "runs" / "config" / "before" / "result.json"
    res = json.loads(result_json.read_text()) if result_json.is_file() else None   # none at nominal
    truth = json.loads((path.parent / "measurement" / "truth.json").read_text())["parameters"]

    def err(gap):
        if res is None:
            return {}
        return {n: 100 * (v - truth[n]) / (res["bounds"][n][1] - res["bounds"][n][0])
                for n, v in (gap or {}).get("w", {}).items()}

    eb, ea = err(d["gap_before"]), err(d["gap_after"])
    params = "; ".join(f"{e['name']}: " + ", ".join(_value(k, v) for k, v in e["parameters"].items()
                                                   if k not in SKIP)
                       for e in d["effects"]) or "-"
    seq = " → ".join([f"{100 * d['gap_before']['share_flagged']:.1f} %"]
                     + [f"{100 * q['share_flagged_after']:.1f} %" for q in d["sequence"]
                        if q["share_flagged_after"] is not None])
    final = d["gap_after"] or d["gap_before"]
    ident = (final.get("suspension_fit") or {}).get("identifiable") or {}
    mark = {n: "" if ident.get(n, True) else " (n.i.)" for n in eb}    # not identifiable at the end
    errs = ", ".join(f"{n} {eb[n]:+.1f} → {ea[n]:+.1f}{mark[n]}" if n in ea else f"{n} {eb[n]:+.1f}{mark[n]}"
                     for n in eb)
    first = "-"
    if d["unexplained"]:
        u = d["unexplained"][0]
        first = (f"{u['channel']} {u['f_low_hz']:.3g}-{u['f_high_hz']:.3g} Hz {u['magnitude_db']:+.1f} dB"
                 + (f" ({u['kind']})" if u.get("kind") else ""))
    gains = ", ".join(f"{g['channel']} {100 * (g['gain'] - 1):+.1f} %"
                      for g in d.get("channel_gains") or [] if g["significant"]) or "-"
    sus = d.get("suspension") or {}
    reported = (f"{'joint fit' if sus['source'].startswith('joint') else 're-identification'} (D "
                f"{sus['D_joint_fit']:.0f} / " + (f"{sus['D_reidentified']:.0f})" if sus.get("D_reidentified")
                                                  is not None else "-)")) if sus else "-"
    return (f"| {case} ({seed}) | {', '.join(d['named_effects']) or 'nothing'} | {params} | {seq} | {errs} | "
            f"{first} | {gains} | {reported} | {seconds:.0f} |")


SKIP = {"length_m", "wheel_diameter_m", "phase_rad", "modal_mass_kg", "gravity_roll", "angles_deg", "applied", "weights"}
"""Effect parameters the table leaves out (fixed in the fits, or repeated)."""


def _value(key: str, value) -> str:
    return f"{key} {value:.4g}" if isinstance(value, float) else f"{key} {value}"


def _noise_options(floor: str) -> dict:
    """``noise:`` options of ``--floor``: none, auto, spec=<density>."""
    if floor.startswith("spec="):
        return {"floor": "spec", "sensor_noise_density": float(floor[5:])}
    return {"floor": floor}


def _describe(hidden: dict) -> str:
    keep = {k: v for k, v in hidden.items() if k not in ("channels", "wheelsets")}
    return "(" + ", ".join(f"{k} {v:g}" if isinstance(v, float) else f"{k} {v}" for k, v in keep.items()) + ")"


def _reseed(path: Path, seed: int) -> None:
    import yaml

    cfg = yaml.safe_load(path.read_text())
    cfg["seed"] = seed
    path.write_text(yaml.safe_dump(cfg, sort_keys=False))


if __name__ == "__main__":
    main()
