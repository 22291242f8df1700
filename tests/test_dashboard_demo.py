"""Issue 47's acceptance on the demo fleet, in a real browser (Debian's headless Chromium through chromedriver).

The demo fleet (``suspid fleet demo configs/fleet-demo.yaml``: TS01's yaw damper and TS02's air spring wear
out, TS03 has a faulty sensor, TS04 is healthy) is monitored once (the ``demo_fleet`` fixture, about two
minutes) and served by ``suspid dashboard``'s application. The overview must show units, % of nominal, the date
and mileage of the latest measurement, the next crossing, TS01's EN 14363 state, a reason behind every "not
assessable", and "no trend" (no date) for the faulty sensor's flat elements. ``SUSPID_SCREENSHOTS=docs/fleet``
keeps the screenshots (``demo-*.png``) that docs/fleet.md and the README show.
"""

from __future__ import annotations

import datetime as dt
import os
import re
import shutil
import threading
from pathlib import Path

import pytest

pytest.importorskip("selenium")
from selenium import webdriver  # noqa: E402
from selenium.webdriver.chrome.service import Service  # noqa: E402
from selenium.webdriver.common.by import By  # noqa: E402
from selenium.webdriver.support import expected_conditions as EC  # noqa: E402
from selenium.webdriver.support.ui import WebDriverWait  # noqa: E402
from werkzeug.serving import make_server  # noqa: E402

from fleet_fixtures import demo_fleet  # noqa: E402,F401 - fixture
from suspid.dashboard.app import create_app  # noqa: E402
from suspid.fleet.db import open_database  # noqa: E402

pytestmark = pytest.mark.long      # the demo's monitors: about two minutes on 2 cores

CHROMIUM, CHROMEDRIVER = "/usr/bin/chromium", "/usr/bin/chromedriver"
TODAY = dt.date(2026, 12, 1)       # the demo's dates are January to June 2026
DATE = re.compile(r"\d{4}-\d\d-\d\d")


USERS = {"m.martin": "correct horse battery", "j.doe": "staple battery horse"}


def make_app(db):
    """The demo's dashboard with acknowledgements allowed for two users of its database."""
    from suspid.fleet.users import add_user, list_users

    known = {u.name for u in list_users(db)}
    for name, password in USERS.items():
        if name not in known:
            add_user(db, name, password)
    return create_app(db, allow_ack=True, today=lambda: TODAY)


@pytest.fixture(scope="module")
def served(demo_fleet):
    if not (Path(CHROMIUM).exists() and Path(CHROMEDRIVER).exists()):
        pytest.skip("chromium and chromium-driver are not installed (apt-get install chromium chromium-driver)")
    db = open_database(demo_fleet.database)
    server = make_server("127.0.0.1", 0, make_app(db), threaded=True)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for flag in ("--headless", "--no-sandbox", "--disable-gpu", "--no-first-run", "--window-size=1400,1100"):
        options.add_argument(flag)
    driver = webdriver.Chrome(service=Service(CHROMEDRIVER), options=options)
    yield f"http://127.0.0.1:{server.server_port}", driver
    driver.quit()
    server.shutdown()
    db.dispose()


def _shot(driver, name: str, tmp_path: Path) -> None:
    """A full-page screenshot, kept in $SUSPID_SCREENSHOTS when set."""
    height = driver.execute_script("return document.body.scrollHeight")
    driver.set_window_size(1400, min(max(height + 200, 700), 3200))
    path = tmp_path / f"{name}.png"
    driver.save_screenshot(str(path))
    if os.environ.get("SUSPID_SCREENSHOTS"):
        shutil.copy(path, Path(os.environ["SUSPID_SCREENSHOTS"]) / path.name)


def _rows(driver) -> dict[tuple[str, str], dict[str, str]]:
    out = {}
    for tr in driver.find_elements(By.CSS_SELECTOR, "#overview tr.row"):
        cells = {c.get_attribute("class").split()[0]: c for c in tr.find_elements(By.TAG_NAME, "td")}
        out[(tr.get_attribute("data-trainset"), tr.get_attribute("data-source"))] = {
            "state": tr.get_attribute("data-state"), **{k: c.text for k, c in cells.items()},
            "why": [s.get_attribute("title") for s in tr.find_elements(By.CSS_SELECTOR, "td.state .why")]}
    return out


def test_the_overview_answers_at_a_glance(served, tmp_path):
    base, driver = served
    driver.get(base + "/")
    table = driver.find_element(By.ID, "overview").text
    rows = _rows(driver)
    assert len(rows) == 16                                     # 4 trainsets x (2 element groups + 2 indicators)
    assert "?" not in table and not re.search(r"\de[+-]\d", table)   # no placeholder, no scientific notation
    yaw = rows[("TS01", "c_yaw")]
    assert yaw["state"] == "alarm" and "yaw damper rate per damper" in yaw["element"]
    assert "all bogies and sides" in yaw["element"]
    assert re.match(r"\d+\.\d % of nominal \[\d+\.\d %, \d+\.\d %\]\n\d+(\.\d)? kN s/m \[", yaw["value"]), yaw["value"]
    assert yaw["measured"] == "2026-06-14\n235\u202f000 km, 170 days ago"
    assert re.fullmatch(r"alarm level crossed on 2026-0[2-6]-\d\d", yaw["next"])
    assert " kN/m " in rows[("TS02", "k_sec_z")]["value"]
    instability = rows[("TS01", "en14363-instability")]      # the worn yaw damper's bogie instability
    assert instability["state"] in ("warning", "alarm") and instability["alarm"].startswith(instability["state"])
    assert re.match(r"\d+ % of the limit\n\d\.\d+ m/s², limit 5\.65 m/s²", instability["value"])
    for source in ("c_yaw", "k_sec_z"):                       # the faulty sensor: flat, no forecast date
        flat = rows[("TS03", source)]
        assert flat["next"].startswith("no trend") and not DATE.search(flat["next"]), flat
    for key, row in rows.items():
        assert row["next"], key
        if row["state"] == "not assessable":
            assert row["why"] and all(row["why"]), key        # the reason on hover
    counts = driver.find_element(By.ID, "counts").text
    assert re.match(r"\d+ alarms?, \d+ warnings?, \d+ not assessable, \d+ ok", counts), counts
    n = dict((s, int(k)) for k, s in re.findall(r"(\d+) (alarms?|warnings?|not assessable|ok)", counts))
    assert sum(n.values()) == 16 and n.get("alarms", 0) >= 2
    states = [r["state"] for r in rows.values()]
    rank = ["alarm", "warning", "not assessable", "ok"]
    assert states == sorted(states, key=rank.index)           # the most urgent first
    _shot(driver, "demo-overview", tmp_path)


def test_the_element_page_says_why_and_the_trend_shows_no_trend(served, tmp_path):
    base, driver = served
    driver.get(base + "/")
    row = next(tr for tr in driver.find_elements(By.CSS_SELECTOR, "#overview tr.row")
               if tr.get_attribute("data-state") == "not assessable")
    reason = row.find_element(By.CSS_SELECTOR, "td.state .why").get_attribute("title")
    row.find_element(By.CSS_SELECTOR, "td.element a").click()
    assert reason in driver.find_element(By.ID, "reason").text
    driver.get(base + "/trainset/TS03")
    assert "no trend" in driver.find_element(By.CSS_SELECTOR, "p.next").text
    images = driver.find_elements(By.CSS_SELECTOR, "img.trend")
    assert images and all(driver.execute_script("return arguments[0].naturalWidth", i) >= 1100 for i in images)
    _shot(driver, "demo-trainset-flat", tmp_path)
    driver.get(base + "/trainset/TS01")
    assert "per 1 000 km" in driver.find_element(By.CSS_SELECTOR, "p.slope").text
    _shot(driver, "demo-trainset", tmp_path)
    for user, comment in (("m.martin", "damper replacement booked"), ("j.doe", "damper replaced, to be re-measured")):
        driver.get(base + "/login")
        driver.find_element(By.ID, "name").send_keys(user)
        driver.find_element(By.ID, "password").send_keys(USERS[user])
        driver.find_element(By.ID, "login").click()
        WebDriverWait(driver, 20).until(EC.presence_of_element_located((By.ID, "who")))
        row = next(tr for tr in driver.find_elements(By.CSS_SELECTOR, "#alarms tr[data-alarm]")
                   if "TS01" in tr.text and "c_yaw" in tr.text)
        alarm = row.get_attribute("data-alarm")
        driver.find_element(By.ID, f"comment-{alarm}").send_keys(comment)
        driver.find_element(By.ID, f"ack-{alarm}").click()
        WebDriverWait(driver, 20).until(EC.presence_of_element_located((By.ID, "message")))
        assert f"acknowledged by {user} at " in driver.find_element(By.ID, "message").text
        driver.find_element(By.ID, "logout").click()
        WebDriverWait(driver, 20).until(EC.presence_of_element_located((By.ID, "login-link")))
    driver.get(base + "/alarms")
    acks = driver.find_element(By.ID, f"acks-{alarm}").text
    assert "m.martin at " in acks and "damper replacement booked" in acks and "j.doe at " in acks   # both kept
    _shot(driver, "demo-alarms", tmp_path)
    driver.get(base + "/trainset/TS01")
    driver.find_element(By.PARTIAL_LINK_TEXT, "run ").click()
    assert driver.find_element(By.CSS_SELECTOR, "#report h1").text.startswith("suspid run")
    _shot(driver, "demo-run", tmp_path)
    driver.get(base + "/trainset/NOPE")
    assert "no trainset 'NOPE' in the database" in driver.find_element(By.ID, "error").text
    assert driver.find_element(By.ID, "nav")
