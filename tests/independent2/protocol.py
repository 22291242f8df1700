"""The two-date protocol on the second independent generator's files, as a suspid user would run it.

The car is suspid's ``conventional-hs`` preset (the quickstart's car) at its
nominal values, so a config names only the preset; the measurement date's
suspension is given per kind (:data:`W_REFS`) or per element
(:data:`ELEMENT_CASES`, one degraded element group each, issue 34's cases).

Command line (``tests`` on ``PYTHONPATH``)::

    python -m independent2.protocol OUT_DIR [--seed 7] [--segments 40] [--case quickstart]
        [--objective overlap|likelihood]

writes ``OUT_DIR/reference``, ``OUT_DIR/measurement`` and ``OUT_DIR/config.yaml``
(``data.source: measured`` with ``noise.reference`` on the reference date);
then ``suspid run OUT_DIR/config.yaml``.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Mapping

import yaml

from . import measure as MS

VEHICLE = {"preset": "conventional-hs"}
"""suspid's car for this generator's data: the preset whose nominal values the generator's kinds take."""

BOUNDS: dict[str, dict[str, float]] = {}
"""Bounds overriding the preset's (none: every nominal value and W_REFS lies inside the preset's bounds)."""

W_REFS: dict[str, dict[str, float]] = {
    "quickstart": {"k_sec_z": 280.0e3, "c_sec_z": 14.0e3, "k_prim_z": 1.28e6, "c_sec_y": 21.0e3, "c_yaw": 210.0e3},
    "other": {"k_sec_z": 420.0e3, "c_sec_z": 26.0e3, "k_prim_z": 1.0e6, "c_sec_y": 39.0e3, "c_yaw": 390.0e3},
    "w0": {},
}
"""Kind-level measurement-date suspensions (SI): the quickstart's damaged one, a stiffer/more damped one, w0."""

ELEMENT_CASES: dict[str, dict[str, float]] = {
    "yaw-bogie1-50": {"c_yaw[bogie1,left]": 150e3, "c_yaw[bogie1,right]": 150e3},
    "lateral-bogie2-left-40": {"c_sec_y[bogie2,left]": 12e3},
    "airspring-bogie1-right-70": {"k_sec_z[bogie1,right]": 245e3},
    "primary-dampers-bogie2-50": {f"c_prim_z[{j},{s}]": 5e3 for j in ("ws3", "ws4") for s in ("left", "right")},
}
"""One degraded element group each (issue 34): one bogie's yaw dampers at 50 %, one lateral damper at 40 %, one
air spring at 70 %, one bogie's primary vertical dampers at 50 %."""

SPECTRA = {"f_min_hz": 0.4, "f_max_hz": 20.0, "n_freqs": 200}
IDENTIFIED = tuple(W_REFS["quickstart"])


def write_config(case_dir: Path, *, seed: int = 7, objective: str = "overlap", n_initial: int = 30,
                 max_iter: int = 40, identified: tuple[str, ...] = IDENTIFIED, name: str = "config") -> Path:
    """A quickstart-sized two-date config in ``case_dir`` on ``measurement/`` with ``noise.reference`` on
    ``reference/`` (relative paths); returns its path."""
    cfg = {"name": name, "seed": seed,
           "simulator": {"plugin": "exudyn-train", "options": {"solver": "frequency", "fs_hz": 100.0,
                                                               "vehicle": dict(VEHICLE)}},
           "parameters": {n: dict(BOUNDS.get(n, {})) for n in identified},
           "data": {"source": "measured", "measurements": "measurement/accelerations",
                    "track_file": "measurement/track"},
           "noise": {"reference": {"measurements": "reference/accelerations", "track_file": "reference/track"}},
           "spectra": dict(SPECTRA), "objective": {"plugin": objective}, "surrogate": {"plugin": "gpy-kriging"},
           "design": {"method": "maximin-lhs", "n_initial": n_initial}, "ego": {"max_iter": max_iter, "tol": 1.0e-4}}
    path = Path(case_dir) / f"{name}.yaml"
    path.write_text(yaml.safe_dump(cfg, sort_keys=False), encoding="utf-8")
    return path


def prepare(out_dir: Path, *, seed: int = 7, n_segments: int = 40, w_ref: Mapping[str, float] | None = None,
            objective: str = "overlap", progress: bool = False) -> Path:
    """Both dates (reference at w0, measurement at ``w_ref``, default the quickstart's) and ``config.yaml``."""
    out = Path(out_dir).resolve()
    MS.generate_two_dates(out, {}, W_REFS["quickstart"] if w_ref is None else w_ref, seed=seed,
                          n_segments=n_segments, speed_mps=300.0 / 3.6, progress=progress)
    return write_config(out, seed=seed, objective=objective)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out_dir", type=Path)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--segments", type=int, default=40)
    ap.add_argument("--case", default="quickstart", choices=list(W_REFS) + list(ELEMENT_CASES))
    ap.add_argument("--objective", default="overlap")
    a = ap.parse_args(argv)
    w_ref = W_REFS.get(a.case, ELEMENT_CASES.get(a.case))
    print(prepare(a.out_dir, seed=a.seed, n_segments=a.segments, w_ref=w_ref, objective=a.objective,
                  progress=True))


if __name__ == "__main__":
    main()
