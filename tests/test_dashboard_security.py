"""The dashboard under hostile input and its safe acknowledgement, on SQLite and on a real PostgreSQL server.

Every route of the application is listed in :data:`ROUTES` (a test fails when a route is added without being
listed); :data:`HOSTILE` holds, per route, requests a careless or hostile client sends: unknown and malformed
ids, huge and odd query strings, SQL metacharacters, path segments that try to leave the run folder, wrong
methods. No answer may be a 500, an error page must be the dashboard's own (its navigation kept), every answer
carries the security headers, and no file outside the recorded runs is ever served. :data:`STATE_CHANGES`
holds acknowledgements without a valid session, token or origin, and replays: none may change the database.

The fleet is recorded for real (``record_result`` into the database, run folders with report.md and PNGs;
``dashboard_fixtures``); requests go through Flask's test client to the real application.
"""

from __future__ import annotations

import html
import re

import pytest

from dashboard_fixtures import PASSWORD, SECRET, TODAY, build_fleet, form_value, log_in, tampered_run
from fleet_fixtures import pg_server  # noqa: F401 - fixture
from suspid.dashboard.app import SECURITY_HEADERS, create_app
from suspid.fleet import queries
from suspid.fleet.db import open_database

pytest.importorskip("flask_wtf")


@pytest.fixture(scope="module", params=["sqlite", "postgresql"])
def fleet(request, tmp_path_factory):
    """The recorded fleet of ``dashboard_fixtures`` on each backend, and a tampered run row."""
    root = tmp_path_factory.mktemp(f"dash-{request.param}")
    if request.param == "sqlite":
        url = f"sqlite:///{root / 'fleet.sqlite'}"
    else:
        url = request.getfixturevalue("pg_server").fresh_database(f"dash_{root.name.replace('-', '_')}")
    ids = build_fleet(url, root)
    ids["tampered"] = tampered_run(url, root)
    db = open_database(url)
    yield {"url": url, "root": root, "db": db, **ids}
    db.dispose()


@pytest.fixture
def app(fleet):
    return create_app(fleet["db"], allow_ack=True, today=lambda: TODAY)


def _n_acks(db) -> int:
    return len(queries.acknowledgements(db))


ROUTES = {
    ("GET", "/"), ("GET", "/trainset/<name>"), ("GET", "/trainset/<name>/element/<vehicle>/<path:group>"),
    ("GET", "/trainset/<name>/trend/<vehicle>/<path:group>.png"), ("GET", "/run/<int:run_id>"),
    ("GET", "/run/<int:run_id>/figure/<int:which>"), ("GET", "/run/<int:run_id>/image/<name>"),
    ("GET", "/alarms"), ("GET", "/login"), ("POST", "/login"), ("POST", "/logout"),
    ("POST", "/alarms/<int:alarm_id>/ack"), ("GET", "/export.<fmt>"), ("GET", "/static/<path:filename>"),
}
"""Every route of the dashboard (method, rule)."""


def test_every_route_is_listed_and_hostile_requests_reach_each(app):
    found = {(m, r.rule) for r in app.url_map.iter_rules() for m in r.methods - {"HEAD", "OPTIONS"}}
    assert found == ROUTES
    adapter = app.url_map.bind("localhost")
    reached = set()
    for method, path, *_ in HOSTILE:
        try:
            rule, _ = adapter.match(path.split("?", 1)[0], method=method, return_rule=True)
            reached.add((method, rule.rule))
        except Exception:  # noqa: BLE001 - a path no route matches (404/405 by design)
            pass
    assert reached == ROUTES


HOSTILE = [
    # (method, path, expected status, text the page must say)
    ("GET", "/?trainset=TS01'%20OR%20'1'='1", 200, "nothing recorded with these filters"),
    ("GET", "/?fleet=demo%22;DROP%20TABLE%20runs;--", 200, "nothing recorded"),
    ("GET", "/?group=%25", 200, "nothing recorded"),                                # a LIKE wildcard is a name
    ("GET", "/?state=alarm'%20OR%201=1", 400, "give one of alarm, warning"),
    ("GET", "/?verdict=nope", 400, "give one of"),
    ("GET", "/?trainset=%00", 400, "no control characters"),
    ("GET", "/?trainset=" + "A" * 300, 400, "at most 200 characters"),
    ("GET", "/?" + "&".join(f"a{i}=1" for i in range(1500)), 400, "the query string has"),
    ("GET", "/?trainset=%F0%9F%9A%84&fleet=%ff%fe", 200, "nothing recorded"),
    ("GET", "/?trainset=TS01&trainset=TS02", 200, "TS01"),
    ("GET", "/trainset/NOPE", 404, "no trainset 'NOPE' in the database"),
    ("GET", "/trainset/TS01'%20OR%20'1'='1", 404, "no trainset"),
    ("GET", "/trainset/%00", 400, "no control characters"),
    ("GET", "/trainset/" + "B" * 5000, 400, "at most 200"),
    ("GET", "/trainset/TS01/element/car1/nope", 404, "has no element group 'nope'"),
    ("GET", "/trainset/TS01/element/car1/c_yaw[bogie1]/../../../secret.txt", 404, "has no element group"),
    ("GET", "/trainset/TS01/element/car9/c_sec_z", 404, "on vehicle 'car9'"),
    ("GET", "/trainset/TS01/trend/car1/nope.png", 404, "has no element group"),
    ("GET", "/trainset/TS01/trend/car1/..%2F..%2Fsecret.png", 404, "has no element group"),
    ("GET", "/run/0", 404, "no run 0 in the database"),
    ("GET", "/run/abc", 404, "nothing at /run/abc"),
    ("GET", "/run/-1", 404, "nothing at"),
    ("GET", "/run/1.5", 404, "nothing at"),
    ("GET", "/run/99999999999999999999999", 404, "ids go up to"),
    ("GET", "/run/2147483648", 404, "ids go up to"),
    ("GET", "/run/1/figure/3", 404, "has no Figure 3"),
    ("GET", "/run/1/figure/99999999999999999999", 404, "ids go up to"),
    ("GET", "/run/1/image/..%2F..%2Fsecret.png", 404, "nothing at"),
    ("GET", "/run/1/image/%2e%2e", 404, "has no image"),
    ("GET", "/run/1/image/report.md", 404, "has no image"),
    ("GET", "/run/1/image/.hidden.png", 404, "has no image"),
    ("GET", "/run/1/image/" + "c" * 300 + ".png", 400, "at most 200"),
    ("GET", "/alarms?message=%3Cscript%3Ealert(1)%3C/script%3E", 200, "Audit trail"),
    ("GET", "/export.xml", 404, "no export format 'xml'"),
    ("GET", "/export.csv?what=..%2F..%2Fetc%2Fpasswd", 400, "give one of overview, board"),
    ("GET", "/export.csv?what=history", 400, "needs trainset=NAME"),
    ("GET", "/export.json?what=history&trainset=%27%3B--", 200, "[]"),
    ("GET", "/static/..%2F..%2Fapp.py", 404, "nothing at"),
    ("GET", "/static/../app.py", 404, "nothing at"),
    ("PUT", "/", 405, "PUT is not allowed"),
    ("DELETE", "/alarms/1/ack", 405, "DELETE is not allowed"),
    ("GET", "/logout", 405, "GET is not allowed"),
    ("GET", "/nothing/here", 404, "nothing at /nothing/here"),
    ("GET", "/", 200, "Fleet overview"),
    ("GET", "/alarms", 200, "Log in"),
    ("GET", "/login?next=http://evil.example", 200, "Log in to acknowledge alarms"),
    ("GET", "/static/dashboard.css", 200, "font-family"),
    ("POST", "/login", 400, "security token"),
    ("POST", "/logout", 400, "security token"),
    ("POST", "/alarms/1/ack", 400, "security token"),
    ("POST", "/alarms/99999999999/ack", 404, "ids go up to"),
]


@pytest.mark.parametrize("method,path,status,says", HOSTILE, ids=[f"{m} {p[:60]}" for m, p, *_ in HOSTILE])
def test_hostile_requests_get_the_dashboards_own_answer(app, fleet, method, path, status, says):
    res = app.test_client().open(path, method=method)
    body = res.get_data(as_text=True)
    assert res.status_code == status, body[:500]
    assert says in html.unescape(body)
    assert SECRET not in body and "Traceback" not in body and "<script>alert" not in body
    for header, value in SECURITY_HEADERS.items():
        assert res.headers.get(header) == value
    if status >= 400:
        assert 'id="nav"' in body and f"({status})" in body       # the dashboard's own page, navigation kept


def test_no_route_serves_a_file_from_outside_the_recorded_runs(app, fleet):
    """A symbolic link in a run folder, paths of a tampered run row (outside its folder, /etc/passwd) and
    report images that climb out: none is served; the run's own PNGs are."""
    client = app.test_client()
    run, bad = fleet["runs"]["TS01-4"], fleet["tampered"]
    refused = [f"/run/{run}/image/outside.png", f"/run/{bad}/figure/1", f"/run/{bad}/figure/2",
               f"/run/{run}/image/secret.png"]
    for path in refused:
        res = client.get(path)
        assert res.status_code == 404 and SECRET.encode() not in res.data, path
    page = client.get(f"/run/{bad}").get_data(as_text=True)
    assert SECRET not in page and 'id="report-missing"' in page
    own = client.get(f"/run/{run}").get_data(as_text=True)
    images = re.findall(r'<img class="fig" src="([^"]+)"', own)
    assert images == [f"/run/{run}/image/figure1_spectra.png"]            # ../../secret.png left out
    assert "<em>[elsewhere]</em>" in own and "a local link" in own and 'href="result.json"' not in own
    assert "&lt;script&gt;alert(1)&lt;/script&gt;" in own                # raw HTML in a report shown as text
    assert "<table>" in own and "<code>TS01-4</code>" in own               # the Markdown rendered
    for path in images + [f"/run/{run}/figure/1", f"/run/{run}/figure/2"]:
        res = client.get(path)
        assert res.status_code == 200 and res.data[:8] == b"\x89PNG\r\n\x1a\n", path


def _logged_in(app):
    client = app.test_client()
    assert log_in(client).status_code == 302
    page = client.get("/alarms").get_data(as_text=True)
    return client, page


def _ack_form(page: str, alarm_id: int) -> dict[str, str]:
    form = page[page.index(f'action="/alarms/{alarm_id}/ack"'):]
    return {"csrf_token": form_value(form, "csrf_token"), "once": form_value(form, "once"), "comment": "x"}


def _case_no_session_no_token(app, fleet, alarm):
    return app.test_client().post(f"/alarms/{alarm}/ack", data={"comment": "by evil"})


def _case_no_session_valid_csrf(app, fleet, alarm):
    client = app.test_client()
    token = form_value(client.get("/login").get_data(as_text=True), "csrf_token")
    return client.post(f"/alarms/{alarm}/ack", data={"csrf_token": token, "comment": "by evil"})


def _logged_in_post(app, alarm, *, headers=None, drop=()):
    """Log in, load the alarms page, and post its acknowledgement form (less the fields ``drop``)."""
    client, page = _logged_in(app)
    form = {k: v for k, v in _ack_form(page, alarm).items() if k not in drop}
    return client.post(f"/alarms/{alarm}/ack", data=form, headers=headers or {})


def _case_session_without_token(app, fleet, alarm):
    return _logged_in_post(app, alarm, drop=("csrf_token",))


def _case_other_origin(app, fleet, alarm):
    return _logged_in_post(app, alarm, headers={"Origin": "http://evil.example"})


def _case_null_origin(app, fleet, alarm):
    return _logged_in_post(app, alarm, headers={"Origin": "null"})


def _case_other_referer(app, fleet, alarm):
    return _logged_in_post(app, alarm, headers={"Referer": "http://evil.example/page"})


def _case_cross_site_fetch(app, fleet, alarm):
    return _logged_in_post(app, alarm, headers={"Sec-Fetch-Site": "cross-site"})


def _case_token_of_another_session(app, fleet, alarm):
    _, page = _logged_in(app)
    other, _ = _logged_in(app)
    return other.post(f"/alarms/{alarm}/ack", data=_ack_form(page, alarm))


def _case_without_one_time_token(app, fleet, alarm):
    return _logged_in_post(app, alarm, drop=("once",))


def _case_replayed_after_logout(app, fleet, alarm):
    client, page = _logged_in(app)
    cookie = client.get_cookie("suspid_session").value
    form = _ack_form(page, alarm)
    client.post("/logout", data={"csrf_token": form["csrf_token"]})
    client.set_cookie("suspid_session", cookie)                   # the captured cookie and form, replayed
    return client.post(f"/alarms/{alarm}/ack", data=form)


def _case_forged_cookie(app, fleet, alarm):
    client, page = _logged_in(app)
    form = _ack_form(page, alarm)
    cookie = client.get_cookie("suspid_session").value
    client.set_cookie("suspid_session", cookie[:-4] + ("AAAA" if not cookie.endswith("AAAA") else "BBBB"))
    return client.post(f"/alarms/{alarm}/ack", data=form)


def _case_read_only(app, fleet, alarm):
    read_only = create_app(fleet["db"], allow_ack=False, today=lambda: TODAY)
    client, page = _logged_in(app)
    return read_only.test_client().post(f"/alarms/{alarm}/ack", data=_ack_form(page, alarm))


STATE_CHANGES = [
    (_case_no_session_no_token, 400, "security token"),
    (_case_no_session_valid_csrf, 401, "log in to acknowledge"),
    (_case_session_without_token, 400, "security token"),
    (_case_other_origin, 403, "another origin (http://evil.example)"),
    (_case_null_origin, 403, "another origin (null)"),
    (_case_other_referer, 403, "referred by another site"),
    (_case_cross_site_fetch, 403, "cross-site"),
    (_case_token_of_another_session, 400, "security token"),
    (_case_without_one_time_token, 400, "already sent or is not from this session"),
    (_case_replayed_after_logout, 401, "log in to acknowledge"),
    (_case_forged_cookie, 400, "security token"),
    (_case_read_only, 403, "read-only"),
]


@pytest.mark.parametrize("case,status,says", STATE_CHANGES, ids=[c.__name__[6:] for c, *_ in STATE_CHANGES])
def test_no_state_change_without_a_valid_session_token_and_origin(app, fleet, case, status, says):
    alarm = fleet["alarms"][("TS01", "c_yaw[bogie1]")]
    before = _n_acks(fleet["db"])
    res = case(app, fleet, alarm)
    assert res.status_code == status, res.get_data(as_text=True)[:400]
    assert says in html.unescape(res.get_data(as_text=True))
    assert _n_acks(fleet["db"]) == before


def test_a_replayed_acknowledgement_form_is_refused(app, fleet):
    alarm = fleet["alarms"][("TS01", "en14363-instability")]
    client, page = _logged_in(app)
    form = _ack_form(page, alarm)
    before = _n_acks(fleet["db"])
    assert client.post(f"/alarms/{alarm}/ack", data=form).status_code == 303
    again = client.post(f"/alarms/{alarm}/ack", data=form)
    assert again.status_code == 400 and "already sent" in again.get_data(as_text=True)
    assert _n_acks(fleet["db"]) == before + 1


@pytest.mark.parametrize("name,password", [("nobody", PASSWORD), ("m.martin", "wrong password"), ("m.martin", ""),
                                           ("", ""), ("m.martin' OR '1'='1", PASSWORD), ("j.doe", PASSWORD)])
def test_an_unknown_user_or_a_wrong_password_is_refused(app, name, password):
    client = app.test_client()
    res = log_in(client, name, password)
    assert res.status_code == 401 and "Unknown user or wrong password." in res.get_data(as_text=True)
    assert "logged in as" not in client.get("/alarms").get_data(as_text=True)


def test_login_rotates_the_session_and_logout_ends_it(app):
    client = app.test_client()
    before = form_value(client.get("/login").get_data(as_text=True), "csrf_token")
    assert log_in(client).status_code == 302
    page = client.get("/alarms").get_data(as_text=True)
    assert "logged in as m.martin" in page and "Acknowledge as m.martin" in page
    assert form_value(page, "csrf_token") != before
    client.post("/logout", data={"csrf_token": form_value(page, "csrf_token")})
    assert "logged in as" not in client.get("/alarms").get_data(as_text=True)


def test_a_cleared_alarm_cannot_be_acknowledged(app, fleet):
    from suspid.fleet.alarms import AcknowledgementError, acknowledge

    alarm = fleet["alarms"][("TS02", "c_yaw[bogie1]")]
    assert next(a for a in queries.alarms(fleet["db"]) if a["id"] == alarm)["state"] == "cleared"
    client, page = _logged_in(app)
    assert f'action="/alarms/{alarm}/ack"' not in page                  # no form offered
    form = _ack_form(page, fleet["alarms"][("TS01", "c_yaw[bogie1]")])  # a valid session, token and nonce
    before = _n_acks(fleet["db"])
    res = client.post(f"/alarms/{alarm}/ack", data=form, follow_redirects=True)
    assert "was cleared on 2026-03-02: only a raised alarm can be acknowledged" in html.unescape(res.get_data(as_text=True))
    assert _n_acks(fleet["db"]) == before
    with pytest.raises(AcknowledgementError, match="was cleared"), fleet["db"].session() as s:
        acknowledge(s, alarm, "m.martin")
    with pytest.raises(AcknowledgementError, match="not a user who may acknowledge"), fleet["db"].session() as s:
        acknowledge(s, fleet["alarms"][("TS01", "c_yaw[bogie1]")], "by evil")


def test_two_acknowledgements_both_show_with_who_and_when(fleet):
    app = create_app(fleet["db"], allow_ack=True, today=lambda: TODAY)
    alarm = fleet["alarms"][("TS01", "c_yaw[bogie1]")]
    for user, password, comment in (("m.martin", PASSWORD, "damper ordered"),
                                    ("j.doe", PASSWORD + "!", "fitted on Monday")):
        client = app.test_client()
        assert log_in(client, user, password).status_code == 302
        page = client.get("/alarms").get_data(as_text=True)
        form = _ack_form(page, alarm) | {"comment": comment}
        res = client.post(f"/alarms/{alarm}/ack", data=form, follow_redirects=True)
        assert f"alarm {alarm} acknowledged by {user} at " in res.get_data(as_text=True)
    page = app.test_client().get("/alarms").get_data(as_text=True)
    cell = page[page.index(f'id="acks-{alarm}"'):].split("</td>", 1)[0]
    found = re.findall(r">(\S+) at (\d{4}-\d\d-\d\d \d\d:\d\d:\d\d) UTC \(alarm of 2026-04-01\): ([^<]+)<", cell)
    assert [(u, c) for u, _, c in found][-2:] == [("m.martin", "damper ordered"), ("j.doe", "fitted on Monday")]
    element = app.test_client().get("/trainset/TS01/element/car1/c_yaw[bogie1]").get_data(as_text=True)
    assert "acknowledged by m.martin at" in element and "acknowledged by j.doe at" in element
    assert not re.search(r"\d\d:\d\d:\d\d\.\d", page + element)           # times without microseconds


def test_security_headers_and_cookie_flags(app):
    client = app.test_client()
    res = log_in(client)
    cookie = res.headers["Set-Cookie"]
    assert "HttpOnly" in cookie and "SameSite=Strict" in cookie
    page = client.get("/")
    assert page.headers["Cache-Control"] == "no-store"
    assert "script-src" not in page.headers["Content-Security-Policy"]        # default-src 'none': no script at all
    assert "<script" not in page.get_data(as_text=True)


def test_unknown_host_header_refused_when_bound_to_loopback(fleet):
    """DNS rebinding: a page of another site resolving to 127.0.0.1 sends its own Host: refused."""
    from suspid.dashboard.server import LOOPBACK_NAMES

    app = create_app(fleet["db"], trusted_hosts=LOOPBACK_NAMES, today=lambda: TODAY)
    res = app.test_client().get("/", headers={"Host": "evil.example:8050"})
    assert res.status_code == 400 and "answers to its own address only" in res.get_data(as_text=True)
    assert app.test_client().get("/", headers={"Host": "127.0.0.1:8050"}).status_code == 200
