"""The sensor-noise floor (``noise.floor``) on equal data: both dates made the same physical way.

In the numerical experiment of ``configs/quickstart.yaml`` the measurement date
is y_sim(w_ref) + b (eq. 10), drawn from the noise model itself, so a run
with a floor and a run without one identify on different data. Here both
dates are accelerations: the model at w0 (reference date) and at w_ref
(measurement date) through the same model-error process
(:func:`suspid.data.experiment.apply_model_error`: one systematic gain for
both dates, a per-segment gain, white sensor noise), written as measured
files; ``suspid run`` then runs the two-date protocol on measured data
(``noise.reference``) with ``noise.floor`` none, auto and spec (the true
density), on the same files.

    python benchmarks/bench_floor.py [--seeds 7 8] [--set data.track.n_segments=12 ...]

``--set`` overrides the config for both dates and the runs (smaller sizes for
a quick check).
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import yaml

os.environ.setdefault("SUSPID_DISABLE_PLUGIN_AUTOLOAD", "1")
ROOT = Path(__file__).resolve().parents[1]

import suspid  # noqa: E402
from suspid.config import build_simulator, load_config  # noqa: E402
from suspid.data.experiment import apply_model_error, smooth_gain_db, systematic_grid  # noqa: E402
from suspid.data.files import write_accelerations_csv, write_track_csv  # noqa: E402
from suspid.infra.seeds import rng as named_rng  # noqa: E402
from suspid.workflows.problem import synthetic_track  # noqa: E402


def write_dates(config_path: Path, seed: int, out: Path, sets: list[str] = ()) -> tuple[dict, float]:
    """Both dates' files under ``out`` (``reference/``, ``measurement/``); returns w_ref and the one-sided
    sensor noise density (m/s²)²/Hz. ``sets``: config overrides ``KEY=VALUE``."""
    config = load_config(config_path, [f"seed={seed}", *sets])
    sim = build_simulator(config)
    opt = config.data.reference
    rng = named_rng(seed, "bench-floor")
    names = [p.name for p in sim.parameters()]
    w_ref = {n: v for n, v in config.data.w_ref.items() if n in names}
    dates = {"reference": ({}, synthetic_track(config, "reference", len(synthetic_track(config, "measurement")))),
             "measurement": (w_ref, synthetic_track(config, "measurement"))}
    systematic = None
    for date, (w, segments) in dates.items():
        responses = sim.simulate(w, segments)
        if systematic is None:
            systematic = smooth_gain_db(rng, systematic_grid(responses[0].fs), len(sim.channels()),
                                        opt.model_error_db, opt.correlation_octaves)
        for seg, r in zip(segments, apply_model_error(responses, opt, rng, systematic)):
            write_track_csv(seg, out / date / "track" / f"{seg.name}.csv")
            write_accelerations_csv(r, out / date / "accelerations" / f"{seg.name}.csv")
    fs = responses[0].fs
    return w_ref, 2 * opt.sensor_noise_rms ** 2 / fs


def run_case(config_path: Path, out: Path, seed: int, floor: dict, label: str, sets: list[str] = ()) -> dict:
    cfg = yaml.safe_load(config_path.read_text())
    cfg["name"] = f"floor-{label}-{seed}"
    cfg["seed"] = seed
    cfg["data"] = {"source": "measured", "measurements": str(out / "measurement" / "accelerations"),
                   "track_file": str(out / "measurement" / "track")}
    cfg["noise"] = {"reference": {"measurements": str(out / "reference" / "accelerations"),
                                  "track_file": str(out / "reference" / "track")}, **floor}
    cfg["output"] = {"dir": str(out / "runs" / cfg["name"])}
    path = out / f"{cfg['name']}.yaml"
    path.write_text(yaml.safe_dump(cfg, sort_keys=False))
    keep = [s for s in sets if not s.startswith("data.")]  # the data section is the files written above
    return suspid.identify(path, keep or None, fresh=True).result


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="*", default=[7])
    ap.add_argument("--config", type=Path, default=ROOT / "configs" / "quickstart.yaml")
    ap.add_argument("--set", dest="sets", action="append", default=[], metavar="KEY=VALUE",
                    help="config override (repeatable)")
    args = ap.parse_args()
    print(f"# bench_floor  {args.config.name} {' '.join(args.sets)}  load average {os.getloadavg()[0]:.2f}")
    print("| seed | noise.floor | worst error % (component) | errors % | s |")
    print("|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for seed in args.seeds:
            out = Path(tmp) / f"seed{seed}"
            w_ref, density = write_dates(args.config, seed, out, args.sets)
            cases = {"none": {}, "auto": {"floor": "auto"},
                     "spec": {"floor": "spec", "sensor_noise_density": density}}
            for label, floor in cases.items():
                t0 = time.perf_counter()
                r = run_case(args.config, out, seed, floor, label, args.sets)
                err = {n: abs(100 * (r["w_opt"][n] - w_ref[n]) / (r["bounds"][n][1] - r["bounds"][n][0]))
                       for n in r["w_opt"] if n in w_ref}
                worst = max(err, key=err.get)
                print(f"| {seed} | {label} | {err[worst]:.2f} ({worst}) | "
                      + ", ".join(f"{n} {e:.2f}" for n, e in err.items())
                      + f" | {time.perf_counter() - t0:.0f} |", flush=True)


if __name__ == "__main__":
    main()
