"""The fleet dashboard in a real browser (Debian's headless Chromium through selenium and chromedriver).

The database is filled by real ``suspid monitor`` runs (frequency solver, a few
segments and dates) recording through their ``fleet:`` section into SQLite;
the same monitor folders are imported with ``suspid fleet import`` into a
PostgreSQL server, and every browser test runs against both. Screenshots of
the overview, a trainset page and a run page are checked (content in the page,
the verdict colours in the pixels); ``SUSPID_SCREENSHOTS=DIR`` keeps them
(docs/fleet/ holds one set). Acknowledging goes through the login form of a
user added to the database.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import threading
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("selenium")
from selenium import webdriver  # noqa: E402
from selenium.webdriver.chrome.service import Service  # noqa: E402
from selenium.webdriver.common.by import By  # noqa: E402
from selenium.webdriver.support import expected_conditions as EC  # noqa: E402
from selenium.webdriver.support.ui import Select, WebDriverWait  # noqa: E402
from werkzeug.serving import make_server  # noqa: E402

import suspid  # noqa: E402
from conftest import run_cli  # noqa: E402
from fleet_fixtures import pg_server  # noqa: E402,F401 - fixture
from suspid.dashboard.app import create_app  # noqa: E402
from suspid.fleet import queries  # noqa: E402
from suspid.fleet.db import open_database  # noqa: E402
from suspid.fleet.users import add_user, list_users  # noqa: E402

pytestmark = pytest.mark.slow   # the session's monitors: about a minute on 2 cores; each browser test a few s

CHROMIUM, CHROMEDRIVER = "/usr/bin/chromium", "/usr/bin/chromedriver"
FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
         "--disable-component-update", "--no-first-run", "--window-size=1280,1000"]

CONFIG = """\
name: {name}
seed: {seed}
simulator: {{plugin: exudyn-train, options: {{solver: frequency}}}}
parameters:
  c_sec_z: {{lower: 5.0e3, upper: 30.0e3}}
  k_sec_z: {{}}
data:
  source: experiment
  track: {{spectrum: german-low, n_segments: 6, length_m: 800.0, speed_kmh: 300.0}}
  measurement: {{errors: noise-model}}
spectra: {{f_min_hz: 0.4, f_max_hz: 20.0, n_freqs: 100}}
design: {{n_initial: 6}}
ego: {{max_iter: 2}}
monitor:
  acceptable: {{c_sec_z: [15.0e3, 25.0e3], k_sec_z: [262.5e3, 437.5e3]}}
  scenario: {{parameter: c_sec_z, loss: {loss}, dates: [2026-01-15, 2026-03-15, 2026-05-15]}}
fleet: {{database: fleet.sqlite, fleet: demo, trainset: {name}, mileage_km: 100000, km_per_day: 900}}
"""


@pytest.fixture(scope="session")
def monitored(tmp_path_factory):
    """Two trainsets monitored for real: TS01's secondary vertical damper wears 60 % (8 kN s/m at the last date,
    far below its acceptable 15 kN s/m), TS02's 5 %."""
    if not (Path(CHROMIUM).exists() and Path(CHROMEDRIVER).exists()):
        if os.environ.get("CI"):
            pytest.fail("chromium and chromium-driver are not installed (.ci/run installs them)")
        pytest.skip("chromium and chromium-driver are not installed (apt-get install chromium chromium-driver)")
    from suspid.infra.threads import single_blas_thread

    root = tmp_path_factory.mktemp("fleet")
    folders = {}
    for name, seed, loss in (("TS01", 5, 0.6), ("TS02", 6, 0.05)):
        path = root / f"{name}.yaml"
        path.write_text(CONFIG.format(name=name, seed=seed, loss=loss))
        with single_blas_thread():
            folders[name] = suspid.monitor(path).monitor_dir
    return root, folders


@pytest.fixture(scope="session", params=["sqlite", "postgresql"])
def dashboard(request, monitored):
    """A dashboard (acknowledgements allowed) served on a loopback port over each backend."""
    root, folders = monitored
    if request.param == "sqlite":
        url = f"sqlite:///{root / 'fleet.sqlite'}"
    else:
        url = request.getfixturevalue("pg_server").fresh_database("browser")
        for name, folder in folders.items():     # the command a depot runs on the run folders that exist
            res = run_cli("fleet", "import", str(folder), "--db", url, "--fleet", "demo", "--trainset", name,
                          "--mileage-km", "100000", "--km-per-day", "900", "--quiet")
            assert res.returncode == 0, res.stderr
    lines: list[str] = []
    db = open_database(url)
    if not any(u.name == "m.martin" for u in list_users(db)):
        add_user(db, "m.martin", "correct horse battery")
    server = make_server("127.0.0.1", 0, create_app(db, allow_ack=True, log=lines.append), threaded=True)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    yield f"http://127.0.0.1:{server.server_port}", db, lines, request.param
    server.shutdown()
    db.dispose()


@pytest.fixture(scope="session")
def browser():
    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for flag in FLAGS:
        options.add_argument(flag)
    driver = webdriver.Chrome(service=Service(CHROMEDRIVER), options=options)
    driver.set_page_load_timeout(60)
    yield driver
    driver.quit()


def _screenshot(driver, name: str, tmp_path: Path) -> np.ndarray:
    """Save a screenshot (and keep it in $SUSPID_SCREENSHOTS), return its RGB pixels."""
    import matplotlib.image as mpimg

    path = tmp_path / f"{name}.png"
    driver.save_screenshot(str(path))
    if os.environ.get("SUSPID_SCREENSHOTS"):
        shutil.copy(path, Path(os.environ["SUSPID_SCREENSHOTS"]) / path.name)
    return mpimg.imread(path)[..., :3]


def _has_colour(pixels: np.ndarray, hex_colour: str) -> bool:
    rgb = np.array([int(hex_colour[i:i + 2], 16) for i in (1, 3, 5)]) / 255.0
    return bool((np.abs(pixels - rgb).max(axis=-1) < 0.02).sum() > 200)


def test_overview_colours_verdicts_and_shows_trust(dashboard, browser, tmp_path):
    base, db, _, backend = dashboard
    browser.get(base + "/")
    table = browser.find_element(By.ID, "overview").text
    assert "TS01" in table and "TS02" in table and "c_sec_z" in table and "k_sec_z" in table
    cells = browser.find_elements(By.CSS_SELECTOR, "#overview td.v-alarm")
    assert any("alarm" in c.text for c in cells)          # TS01's worn damper, last date out of its domain
    assert browser.find_elements(By.CSS_SELECTOR, "#overview td.v-ok, #overview td.v-warning")
    assert "not assessed" in table and "?" not in table   # trust in words, no placeholder
    assert "kN s/m" in table and "% of nominal" in table
    assert re.match(r"\d+ alarms?, \d+ warnings?, \d+ not assessable, \d+ ok", browser.find_element(By.ID, "counts").text)
    pixels = _screenshot(browser, f"overview-{backend}" if backend != "sqlite" else "overview", tmp_path)
    assert _has_colour(pixels, "#f28b82")                                   # the alarm cell drawn in its colour
    assert _has_colour(pixels, "#b7e1b0") or _has_colour(pixels, "#ffd27f")  # and ok or warning ones


def test_drill_down_to_the_trainset_and_a_run(dashboard, browser, tmp_path):
    base, *_, backend = dashboard
    browser.get(base + "/")
    browser.find_element(By.LINK_TEXT, "TS01").click()
    WebDriverWait(browser, 20).until(EC.url_contains("/trainset/TS01"))
    assert "Trainset TS01" in browser.find_element(By.TAG_NAME, "h1").text
    images = browser.find_elements(By.CSS_SELECTOR, "img.trend")
    assert len(images) == 2 and all(browser.execute_script("return arguments[0].naturalWidth", i) > 1000
                                    for i in images)
    forecast = browser.find_element(By.CSS_SELECTOR, "table.forecast").text
    assert "warning" in forecast and "alarm" in forecast
    assert "en14363-instability" in browser.find_element(By.ID, "indicators").text
    _screenshot(browser, "trainset" if backend == "sqlite" else f"trainset-{backend}", tmp_path)
    browser.find_element(By.PARTIAL_LINK_TEXT, "run ").click()
    WebDriverWait(browser, 20).until(EC.url_contains("/run/"))
    assert "Run " in browser.find_element(By.TAG_NAME, "h1").text
    figures = browser.find_elements(By.CSS_SELECTOR, "#report img.fig")
    assert len(figures) == 3 and all(browser.execute_script("return arguments[0].naturalWidth", f) > 300
                                     for f in figures)            # Figures 1 and 2 and the convergence
    verdicts = browser.find_element(By.ID, "verdicts").text
    assert "c_sec_z" in verdicts and "not assessed" in verdicts
    assert browser.find_element(By.CSS_SELECTOR, "#report h1").text.startswith("suspid run")   # Markdown rendered
    assert browser.find_elements(By.CSS_SELECTOR, "#report table")
    _screenshot(browser, "run" if backend == "sqlite" else f"run-{backend}", tmp_path)


def test_filter_by_state(dashboard, browser):
    base, *_ = dashboard
    browser.get(base + "/")
    Select(browser.find_element(By.ID, "filter-state")).select_by_value("alarm")
    browser.find_element(By.ID, "apply-filters").click()
    WebDriverWait(browser, 20).until(EC.url_contains("state=alarm"))
    table = browser.find_element(By.ID, "overview").text
    assert "TS01" in table and "TS02" not in table
    assert not browser.find_elements(By.CSS_SELECTOR, "#overview td.v-ok, #overview td.v-warning")


def test_acknowledge_an_alarm_after_logging_in_is_stored_audited_and_logged(dashboard, browser):
    base, db, lines, _ = dashboard
    (alarm,) = [a for a in queries.alarms(db, state="raised") if a["trainset"] == "TS01" and a["source"] == "c_sec_z"]
    browser.get(base + "/alarms")
    assert not browser.find_elements(By.ID, f"ack-{alarm['id']}")          # no form before logging in
    browser.find_element(By.ID, "login-link").click()
    browser.find_element(By.ID, "name").send_keys("m.martin")
    browser.find_element(By.ID, "password").send_keys("correct horse battery")
    browser.find_element(By.ID, "login").click()
    WebDriverWait(browser, 20).until(EC.presence_of_element_located((By.ID, "who")))
    browser.find_element(By.ID, f"comment-{alarm['id']}").send_keys("damper replacement booked")
    browser.find_element(By.ID, f"ack-{alarm['id']}").click()
    WebDriverWait(browser, 20).until(EC.presence_of_element_located((By.ID, "message")))
    assert f"alarm {alarm['id']} acknowledged by m.martin at " in browser.find_element(By.ID, "message").text
    assert "damper replacement booked" in browser.find_element(By.ID, "alarms").text
    audit = browser.find_element(By.ID, "audit").text
    assert "m.martin acknowledged" in audit
    stored = next(a for a in queries.alarms(db) if a["id"] == alarm["id"])
    assert stored["acked_by"] == "m.martin" and stored["acked_at"]
    assert any("acknowledged by m.martin" in line for line in lines)
    browser.find_element(By.ID, "logout").click()
    WebDriverWait(browser, 20).until(EC.presence_of_element_located((By.ID, "login-link")))


def test_export_csv_and_json(dashboard, browser):
    """The exports as a maintenance system fetches them (over HTTP; the pages' Content-Security-Policy forbids
    scripts, so the browser's own fetch cannot be used), and the page that links them."""
    import urllib.request

    base, db, *_ = dashboard
    browser.get(base + "/")
    links = [a.get_attribute("href") for a in browser.find_elements(By.CSS_SELECTOR, "#nav a")]
    assert base + "/export.json?what=board" in links and base + "/export.csv?what=board" in links

    def fetch(path: str) -> str:
        with urllib.request.urlopen(base + path, timeout=30) as res:
            return res.read().decode()

    rows = json.loads(fetch("/export.json"))
    assert rows == queries.overview(db)
    assert {r["trainset"] for r in rows} == {"TS01", "TS02"} and {"verdict", "trust", "mileage_km"} <= set(rows[0])
    header, *lines = fetch("/export.csv?what=history&trainset=TS01").strip().splitlines()
    assert header.startswith("run_id,") and len(lines) == 6          # 3 dates x 2 element groups
    board = json.loads(fetch("/export.json?what=board"))
    assert {r["what"] for r in board} == {"element", "indicator"} and all(r["next"]["text"] for r in board)


def test_read_only_dashboard_refuses_acknowledgements(monitored):
    root, _ = monitored
    app = create_app(f"sqlite:///{root / 'fleet.sqlite'}")
    res = app.test_client().post("/alarms/1/ack", data={"comment": "x"})
    assert res.status_code == 403 and b"read-only" in res.data
