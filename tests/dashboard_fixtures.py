"""A small recorded fleet for the dashboard's fast tests: real runs of ``record_result`` into a real database
(SQLite or the suite's PostgreSQL server), real run folders (report.md, PNG figures), no identification.

- TS01 car1: ``c_yaw[bogie1]`` (yaw damper, bogie 1) loses a third over five dates: an alarm, the alarm level
  crossed on the fifth date (2026-05-01, 200 kN s/m against 215 kN s/m); ``c_sec_z`` flat at its nominal 20 kN s/m
  (a trend whose slope interval contains 0); EN 14363 instability rising to 4.75 m/s^2 of a 5.65 m/s^2 limit
  (a warning) and EN 12299 comfort at 1.3 (ok).
- TS02 car1: ``c_yaw[bogie1]`` drops to an alarm and is repaired (the alarm cleared); ``k_sec_z`` is not
  identifiable at its last date, with the run's own reason.
- A run folder of TS01 holds ``outside.png``, a symbolic link to a PNG outside every run folder, and a
  ``secret.txt`` beside the folders that no route may serve.
"""

from __future__ import annotations

import datetime as dt
import re
from pathlib import Path
from typing import Any

import numpy as np

from suspid.fleet.db import open_database
from suspid.fleet.record import VehicleKey, record_result
from suspid.indicators.standard import IndicatorValue

START = dt.date(2026, 1, 1)
TODAY = dt.date(2026, 12, 1)
DOMAIN = {"c_yaw[bogie1]": [225e3, 375e3], "c_sec_z": [15e3, 25e3], "k_sec_z": [262.5e3, 437.5e3]}
NOMINAL = {"c_yaw[bogie1]": 300e3, "c_sec_z": 20e3, "k_sec_z": 350e3}
UNITS = {"c_yaw[bogie1]": "N s/m", "c_sec_z": "N s/m", "k_sec_z": "N/m"}
LABELS = {"c_yaw[bogie1]": "bogie 1: yaw damper rate per damper", "c_sec_z": "secondary vertical damper",
          "k_sec_z": "secondary vertical stiffness per side"}
SECRET = "the content of a file outside every run folder"
PASSWORD = "correct horse battery"


def result(name: str, values: dict[str, float], hw: dict[str, float], *, not_identifiable: tuple[str, ...] = ()
           ) -> dict[str, Any]:
    """A result.json as ``suspid run`` writes it (the keys the fleet records)."""
    names = list(values)
    return {"name": name, "run_id": name, "parameters": names, "units": {n: UNITS[n] for n in names},
            "w_opt": values, "interval": {n: [values[n] - hw[n], values[n] + hw[n]] for n in names},
            "identifiable": {n: n not in not_identifiable for n in names},
            "non_identifiable_reasons": {n: "flat direction: the interval spans 100 % of the admissible one"
                                         for n in not_identifiable},
            "trustworthy": {n: None for n in names},
            "not_assessed_reasons": {n: ["reference-date self-check not run"] for n in names},
            "nominal": {n: NOMINAL[n] for n in names},
            "verdict": {"rows": [{"name": n, "label": LABELS[n]} for n in names]}}


def _png(path: Path) -> None:
    import matplotlib.image as mpimg

    mpimg.imsave(path, np.zeros((4, 4, 3)))


def _run_dir(root: Path, name: str) -> Path:
    d = root / "runs" / name
    d.mkdir(parents=True, exist_ok=True)
    (d / "report.md").write_text(f"# Run `{name}`\n\n| a | b |\n|---|---|\n| 1 | 2 |\n\n<script>alert(1)</script>\n\n"
                                 f"![figure 1](figure1_spectra.png)\n![elsewhere](../../secret.png)\n"
                                 f"[a local link](result.json)\n", encoding="utf-8")
    _png(d / "figure1_spectra.png")
    _png(d / "figure2_parameters.png")
    return d


def build_fleet(url: str, root: Path) -> dict[str, Any]:
    """Record the fleet of the module docstring into ``url``; returns the run ids and alarm ids by name."""
    (root / "secret.txt").write_text(SECRET)
    _png(root / "secret.png")
    db = open_database(url)
    ids: dict[str, Any] = {"runs": {}}
    try:
        c_yaw = [300e3, 290e3, 250e3, 220e3, 200e3]
        instability = [2.0, 3.0, 4.0, 4.6, 4.75]
        for i, v in enumerate(c_yaw):
            name = f"TS01-{i}"
            d = START + dt.timedelta(days=30 * i)
            rec = record_result(
                db, VehicleKey("demo", "TS01", "car1"), d,
                result(name, {"c_yaw[bogie1]": v, "c_sec_z": 20e3 + (300.0 if i % 2 else -300.0)},
                       {"c_yaw[bogie1]": 10e3, "c_sec_z": 1e3}),
                _run_dir(root, name), mileage_km=100_000.0 + 27_000.0 * i, acceptable=DOMAIN, kind="monitor-date",
                indicators=[IndicatorValue("en14363-instability", instability[i], "m/s^2",
                                           "warning" if instability[i] > 0.8 * 5.65 else "ok", None, "bogie", 5.65),
                            IndicatorValue("en12299-comfort", 1.3, "-", "ok", None, "carbody", None)])
            ids["runs"][name] = rec.run_id
        for i, (v, k) in enumerate([(300e3, 350e3), (205e3, 350e3), (300e3, 400e3)]):
            name = f"TS02-{i}"
            rec = record_result(db, VehicleKey("demo", "TS02", "car1"), START + dt.timedelta(days=30 * i),
                                result(name, {"c_yaw[bogie1]": v, "k_sec_z": k}, {"c_yaw[bogie1]": 10e3,
                                                                                   "k_sec_z": 200e3 if i == 2 else 20e3},
                                       not_identifiable=("k_sec_z",) if i == 2 else ()),
                                _run_dir(root, name), mileage_km=50_000.0 + 20_000.0 * i, acceptable=DOMAIN,
                                kind="monitor-date")
            ids["runs"][name] = rec.run_id
        outside = root / "runs" / "TS01-4" / "outside.png"
        outside.symlink_to(root / "secret.png")
        from suspid.fleet import queries
        from suspid.fleet.users import add_user

        ids["alarms"] = {(a["trainset"], a["source"]): a["id"] for a in queries.alarms(db)}
        add_user(db, "m.martin", PASSWORD)
        add_user(db, "j.doe", PASSWORD + "!")
    finally:
        db.dispose()
    return ids


def tampered_run(url: str, root: Path) -> int:
    """A run row whose recorded figure and report paths point outside its folder (a tampered database)."""
    from suspid.fleet.schema import Run

    db = open_database(url)
    try:
        with db.session() as s:
            run = Run(fleet="demo", trainset="TS09", vehicle="car1", date=START, mileage_km=None, kind="run",
                      name="tampered", config_hash="x", run_dir=str(root / "runs" / "TS01-0"),
                      report_path=str(root / "secret.txt"), figure1_path=str(root / "secret.png"),
                      figure2_path="/etc/passwd", recorded_at=dt.datetime(2026, 1, 1))
            s.add(run)
            s.flush()
            return run.id
    finally:
        db.dispose()


def form_value(html: str, name: str) -> str:
    """The value of the first hidden input ``name`` of a page."""
    found = re.search(rf'name="{name}" value="([^"]+)"', html)
    assert found, f"no {name} in the page"
    return found.group(1)


def log_in(client, name: str = "m.martin", password: str = PASSWORD):  # noqa: ANN001, ANN201
    """Log in through the login form (its CSRF token first); returns the response."""
    token = form_value(client.get("/login").get_data(as_text=True), "csrf_token")
    return client.post("/login", data={"name": name, "password": password, "csrf_token": token})
