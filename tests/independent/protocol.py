"""The two-date protocol on the independent train's files, as a suspid user would run it.

This module is the *consumer* side: it uses suspid (its readers, the
``exudyn-train`` simulator, spectra and noise model) on files written by
:mod:`.train`, which itself uses none of them.

Steps (:func:`prepare`):

1. :func:`.train.generate_two_dates`: a reference date at w0 and a
   measurement date at w_ref, other track segments, the same instrumented train;
2. the noise model of the reference date (paper eq. 3): spectra of the
   reference records minus spectra that suspid's simulator computes at w0 on
   the reference date's *measured* track, fitted by
   :func:`suspid.method.noise.fit_noise_model` and saved as ``noise.npz``;
3. a config (``config.yaml``) with ``data.source: measured`` on the
   measurement date's files and ``noise.path: noise.npz``.

Then ``suspid validate config.yaml`` and ``suspid run config.yaml``;
:func:`errors` compares a run's ``result.json`` with the truth.

Command line (``tests`` on ``PYTHONPATH``)::

    python -m independent.protocol OUT_DIR [--seed 7] [--segments 24] [--nominal]
        [--objective overlap|likelihood] [--n-initial 30] [--max-iter 40] [--physics NAME=VALUE ...]
        [--table1]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Mapping

import yaml

from . import train as TR

QUICKSTART_W_REF = {"k_sec_z": 340.0e3, "c_sec_z": 14.0e3, "k_prim_z": 1.30e6, "c_sec_y": 11.0e3,
                    "c_yaw": 560.0e3}
"""The damaged suspension of suspid's quickstart (SI)."""

TABLE1_W_REF = {"k_sec_z": 340.0e3, "k_prim_z": 1.00e6, "c_sec_z": 14.0e3, "k_sec_y": 130.0e3,
                "c_sec_y": 11.0e3, "c_yaw": 560.0e3, "k_prim_y": 3.2e6}
"""The damaged suspension of suspid's Table 1 config (q = 7, SI)."""

VEHICLE = {"preset": "manchester-coach", "k_prim_x": 14.68e6, "c_sec_y": 16.0e3, "c_yaw": 800.0e3, "conicity": 0.25}
"""suspid's car for the independent train's data: the Manchester coach preset with the values where the
independent train's nominal (w0) differs (its ``SHARED`` parameters), so that w0 is the same vehicle."""

SPECTRA = {"f_min_hz": 0.4, "f_max_hz": 20.0, "n_freqs": 200}
"""The quickstart's ``spectra:`` section."""


def fit_reference_noise(reference_dir: Path, out_path: Path, simulator_options: Mapping | None = None,
                        spectra: Mapping | None = None, noise: Mapping | None = None) -> Path:
    """Noise model of a reference date measured at w0 (suspid's model at its nominal values)."""
    from suspid import registry
    from suspid.method.noise import fit_noise_model
    from suspid.workflows.problem import read_measurements
    from suspid.method.spectra import compute_spectra

    sim = registry.get("simulator", "exudyn-train")(**dict(simulator_options or {"solver": "frequency",
                                                                                 "fs_hz": 100.0,
                                                                                 "vehicle": VEHICLE}))
    channels = sim.channels()
    segments, records = read_measurements(reference_dir / "accelerations", reference_dir / "track", channels)
    y_mes0, freqs = compute_spectra(records, spectra or SPECTRA)
    y_sim0, _ = compute_spectra(sim.simulate({}, segments), spectra or SPECTRA)
    model = fit_noise_model(y_mes0, y_sim0, noise or {}, freqs=freqs, channels=channels,
                            speeds=[s.mean_speed for s in segments])
    return model.save(out_path)


def write_config(path: Path, measurement_dir: Path, noise_path: Path, *, seed: int = 7,
                 objective: str = "overlap", n_initial: int = 30, max_iter: int = 40,
                 identified: tuple[str, ...] = tuple(QUICKSTART_W_REF)) -> Path:
    """A quickstart-sized identification config on measured files (paths relative to ``path``)."""
    base = path.parent
    cfg = {
        "name": path.stem,
        "seed": seed,
        "simulator": {"plugin": "exudyn-train", "options": {"solver": "frequency", "fs_hz": 100.0, "vehicle": VEHICLE}},
        "parameters": {n: {} for n in identified},
        "data": {"source": "measured",
                 "measurements": str(Path(measurement_dir, "accelerations").relative_to(base)),
                 "track_file": str(Path(measurement_dir, "track").relative_to(base))},
        "noise": {"path": str(Path(noise_path).relative_to(base))},
        "spectra": dict(SPECTRA),
        "objective": {"plugin": objective},
        "surrogate": {"plugin": "gpy-kriging"},
        "design": {"method": "maximin-lhs", "n_initial": n_initial},
        "ego": {"max_iter": max_iter, "tol": 1.0e-4},
    }
    path.write_text(yaml.safe_dump(cfg, sort_keys=False), encoding="utf-8")
    return path


def prepare(out_dir: Path, *, seed: int = 7, n_segments: int = 24, w_ref: Mapping[str, float] | None = None,
            objective: str = "overlap", n_initial: int = 30, max_iter: int = 40,
            physics: Mapping[str, float] | None = None,
            identified: tuple[str, ...] = tuple(QUICKSTART_W_REF)) -> Path:
    """Generate both dates, fit the reference noise model, write ``config.yaml``; returns its path.

    :param w_ref: the measurement date's parameters (default: the quickstart's damaged set).
    :param identified: the parameters the config identifies (default bounds).
    :param physics: values of the independent train's parameters on both dates (e.g.
        ``{"k_yaw_series": 1e9}``); ``w_ref`` overrides them on the measurement date.
    """
    out_dir = Path(out_dir).resolve()
    base = dict(physics or {})
    w_mes = base | dict(QUICKSTART_W_REF if w_ref is None else w_ref)
    ref, mes = TR.generate_two_dates(out_dir, base, w_mes, seed=seed, n_segments=n_segments,
                                     speed_mps=300.0 / 3.6)
    noise = fit_reference_noise(ref, out_dir / "noise.npz")
    return write_config(out_dir / "config.yaml", mes, noise, seed=seed, objective=objective,
                        n_initial=n_initial, max_iter=max_iter, identified=tuple(identified))


def errors(result_json: Path, truth_json: Path) -> dict[str, dict[str, float]]:
    """Per identified parameter: truth, identified value, error in % of its interval, |error| / truth %."""
    res = json.loads(Path(result_json).read_text())
    truth = json.loads(Path(truth_json).read_text())["parameters"]
    out = {}
    for n in res["parameters"]:
        lo, hi = res["bounds"][n]
        w = res["w_opt"][n]
        out[n] = {"truth": truth[n], "identified": w, "error_pct_interval": 100.0 * (w - truth[n]) / (hi - lo),
                  "error_pct_value": 100.0 * (w - truth[n]) / truth[n]}
    return out


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out_dir", type=Path)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--segments", type=int, default=24)
    ap.add_argument("--nominal", action="store_true", help="measurement date at w0 (no damage)")
    ap.add_argument("--table1", action="store_true", help="identify Table 1's q = 7 (its damaged w_ref)")
    ap.add_argument("--objective", default="overlap")
    ap.add_argument("--n-initial", type=int, default=30)
    ap.add_argument("--max-iter", type=int, default=40)
    ap.add_argument("--physics", nargs="*", default=[], metavar="NAME=VALUE",
                    help="independent-train parameters on both dates, e.g. k_yaw_series=1e9")
    a = ap.parse_args(argv)
    physics = {k: float(v) for k, v in (item.split("=", 1) for item in a.physics)}
    damaged = TABLE1_W_REF if a.table1 else QUICKSTART_W_REF
    cfg = prepare(a.out_dir, seed=a.seed, n_segments=a.segments, w_ref={} if a.nominal else damaged,
                  objective=a.objective, n_initial=a.n_initial, max_iter=a.max_iter, physics=physics,
                  identified=tuple(damaged))
    print(cfg)


if __name__ == "__main__":
    main()
