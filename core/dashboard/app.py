"""The fleet dashboard: a server-rendered Flask application over the monitoring database.

Pages: the fleet overview (one row per trainset, vehicle and element group or
standard indicator, sorted by urgency, :mod:`suspid.fleet.board`), a trainset
page and an element page (history, trend, levels and forecast, the reason
behind each "not assessable"), a run page (verdicts, indicators, Figures 1
and 2, the report rendered from its Markdown), the alarms with every
acknowledgement and the audit trail. ``/export.csv`` and ``/export.json``
give the overview's rows (``?what=board``, ``?what=history&trainset=..``,
``?what=alarms``, ``?what=indicators``) to a maintenance information system.

**Read-only by default.** With ``allow_ack`` the users of the database
(:mod:`suspid.fleet.users`) may log in and acknowledge raised alarms. Every
state-changing request (log in, log out, acknowledge) is a POST that must come
from the dashboard's own origin (``Origin``, ``Referer`` and
``Sec-Fetch-Site`` checked) and carry a valid CSRF token (Flask-WTF's
:class:`~flask_wtf.csrf.CSRFProtect`, tied to the session); an acknowledgement
also needs a logged-in session and a one-time form token, so a replayed form
is refused. Sessions live in the server (:class:`Sessions`): logging out ends
the session for any copy of its cookie, and a restart ends every session (the
signing key is drawn anew at each start). Responses carry a strict
Content-Security-Policy and the usual protective headers; errors are the
dashboard's own pages (navigation kept, what was not found said).
"""

from __future__ import annotations

import csv
import datetime as dt
import io
import json
import re
import secrets
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable
from urllib.parse import urlsplit

from flask import Flask, Response, abort, flash, redirect, render_template, request, send_file, session, url_for
from flask_wtf.csrf import CSRFError, CSRFProtect
from markdown_it import MarkdownIt
from markupsafe import Markup
from sqlalchemy.engine import make_url
from werkzeug.exceptions import HTTPException, SecurityError

from suspid.dashboard import present
from suspid.dashboard.figures import trend_figure
from suspid.fleet import board as fleet_board
from suspid.fleet import queries
from suspid.fleet.alarms import MAX_COMMENT, AcknowledgementError, acknowledge
from suspid.fleet.db import Database, open_database
from suspid.fleet.users import authenticate

Log = Callable[[str], None]
MAX_ID = 2**31 - 1
"""Largest row id either backend stores (PostgreSQL's ``integer``); a larger id in a URL is no such row."""
MAX_PARAM = 200
"""Longest query value or path segment accepted (names are at most 100 characters in the database)."""
MAX_QUERY = 4096
"""Longest query string accepted."""
SESSION_HOURS = 8.0
"""A login lasts this long at most."""
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_CONTROL = re.compile(r"[\x00-\x1f\x7f]")
_IMAGE_NAME = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_.\-]{0,120}\.png$")
EXPORTS = ("overview", "board", "history", "alarms", "indicators")
SECURITY_HEADERS = {
    "Content-Security-Policy": ("default-src 'none'; img-src 'self'; style-src 'self'; form-action 'self'; "
                                "frame-ancestors 'none'; base-uri 'none'"),
    "X-Content-Type-Options": "nosniff",
    "X-Frame-Options": "DENY",
    "Referrer-Policy": "same-origin",
    "Cross-Origin-Opener-Policy": "same-origin",
    "Cross-Origin-Resource-Policy": "same-origin",
    "Permissions-Policy": "camera=(), microphone=(), geolocation=()",
}


MAX_NONCES = 500
"""One-time form tokens kept per session (the oldest are dropped: a page that old must be reloaded)."""


@dataclass
class _Session:
    user: str
    started: float
    nonces: dict[str, None] = field(default_factory=dict)     # insertion-ordered: the oldest first


class Sessions:
    """Logged-in sessions kept by the server: a random id per login (in the signed session cookie), the user,
    when it started, and the one-time tokens of the acknowledgement forms it was shown."""

    def __init__(self, hours: float = SESSION_HOURS) -> None:
        self._lock = threading.Lock()
        self._live: dict[str, _Session] = {}
        self.seconds = hours * 3600.0

    def start(self, user: str) -> str:
        sid = secrets.token_urlsafe(32)
        with self._lock:
            self._live[sid] = _Session(user, time.monotonic())
        return sid

    def user(self, sid: str | None) -> str | None:
        """The user of a live session, None when it ended, expired or never existed."""
        with self._lock:
            s = self._live.get(sid or "")
            if s is not None and time.monotonic() - s.started > self.seconds:
                del self._live[sid]
                s = None
            return None if s is None else s.user

    def end(self, sid: str | None) -> None:
        with self._lock:
            self._live.pop(sid or "", None)

    def nonce(self, sid: str) -> str:
        """A one-time token for a form of this session."""
        token = secrets.token_urlsafe(16)
        with self._lock:
            s = self._live.get(sid)
            if s is not None:
                s.nonces[token] = None
                while len(s.nonces) > MAX_NONCES:
                    del s.nonces[next(iter(s.nonces))]
        return token

    def use(self, sid: str | None, token: str) -> bool:
        """Spend a one-time token: True the first time it is given back, False after (or when unknown)."""
        with self._lock:
            s = self._live.get(sid or "")
            if s is None or token not in s.nonces:
                return False
            del s.nonces[token]
            return True


def markdown_html(text: str, image_url: Callable[[str], str | None]) -> Markup:
    """A report's Markdown as HTML (markdown-it-py, CommonMark with tables; raw HTML in the source is shown as
    text, never passed through). Images point to ``image_url(src)`` (None: the image is left out, its alt text
    kept); links other than http(s) become their text."""
    md = MarkdownIt("commonmark", {"html": False}).enable("table")

    def image(renderer, tokens, idx, options, env):  # noqa: ANN001 - markdown-it's render-rule signature
        token = tokens[idx]
        url = image_url(token.attrGet("src") or "")
        alt = md.renderer.renderInlineAsText(token.children or [], options, env)
        if url is None:
            return f"<em>[{Markup.escape(alt)}]</em>"
        return f'<img class="fig" src="{Markup.escape(url)}" alt="{Markup.escape(alt)}">'

    def link_open(renderer, tokens, idx, options, env):  # noqa: ANN001
        href = tokens[idx].attrGet("href") or ""
        if urlsplit(href).scheme in ("http", "https"):
            tokens[idx].attrSet("rel", "noopener noreferrer")
            return md.renderer.renderToken(tokens, idx, options, env)
        tokens[idx].meta["dropped"] = True
        return ""

    def link_close(renderer, tokens, idx, options, env):  # noqa: ANN001
        opening = next((t for t in reversed(tokens[:idx]) if t.type == "link_open"), None)
        if opening is not None and opening.meta.get("dropped"):
            return ""
        return md.renderer.renderToken(tokens, idx, options, env)

    md.add_render_rule("image", image)
    md.add_render_rule("link_open", link_open)
    md.add_render_rule("link_close", link_close)
    return Markup(md.render(text))


def _inside(path: str | None, run_dir: str) -> Path | None:
    """``path`` resolved (symbolic links followed) when it is a file inside the resolved ``run_dir``."""
    if not path or not run_dir:
        return None
    try:
        resolved, root = Path(path).resolve(), Path(run_dir).resolve()
    except (OSError, RuntimeError, ValueError):
        return None
    if resolved == root or not resolved.is_relative_to(root) or not resolved.is_file():
        return None
    return resolved


def _png(path: Path | None) -> Path | None:
    """``path`` when it is a PNG file (by its signature, not its name)."""
    if path is None or path.suffix.lower() != ".png":
        return None
    try:
        with open(path, "rb") as fh:
            return path if fh.read(8) == PNG_SIGNATURE else None
    except OSError:
        return None


def _csv_cell(v: Any) -> Any:
    """A CSV cell that a spreadsheet will not run as a formula (OWASP's CSV injection rule)."""
    if isinstance(v, str) and v[:1] in ("=", "+", "-", "@", "\t", "\r"):
        return "'" + v
    if isinstance(v, (dict, list)):
        return json.dumps(v)
    return v


def _origin_of(url: str) -> str | None:
    parts = urlsplit(url)
    return f"{parts.scheme}://{parts.netloc}" if parts.scheme and parts.netloc else None


def create_app(db: Database | str | Path, *, allow_ack: bool = False, log: Log = lambda s: None,
               today: Callable[[], dt.date] = dt.date.today, secret_key: bytes | None = None,
               trusted_hosts: list[str] | None = None) -> Flask:
    """The dashboard's Flask application over ``db`` (an open database, a URL or an SQLite path).

    :param allow_ack: let the database's users log in and acknowledge raised alarms (module docstring).
    :param today: the date the overview's ages and past forecasts are judged against.
    :param secret_key: the key signing the session cookie and the CSRF tokens (default: drawn at random, so a
        restart ends every session).
    :param trusted_hosts: the ``Host`` names served (others get 400); None: any.
    """
    database = db if isinstance(db, Database) else open_database(db)
    app = Flask(__name__)
    app.config.update(
        SECRET_KEY=secret_key or secrets.token_bytes(32), SESSION_COOKIE_HTTPONLY=True,
        SESSION_COOKIE_SAMESITE="Strict", SESSION_COOKIE_NAME="suspid_session", MAX_CONTENT_LENGTH=64 * 1024,
        MAX_FORM_MEMORY_SIZE=16 * 1024, WTF_CSRF_TIME_LIMIT=3600, TRUSTED_HOSTS=trusted_hosts)
    label = make_url(database.url).render_as_string(hide_password=True)
    sessions = Sessions()
    app.extensions["suspid_sessions"] = sessions

    def current_user() -> str | None:
        return sessions.user(session.get("sid"))

    @app.context_processor
    def _common() -> dict[str, Any]:
        return {"db_label": label, "p": present, "user": current_user(), "allow_ack": allow_ack, "today": today()}

    # -- what every request is checked for, before any view runs -------------------------------------------
    @app.before_request
    def _check_request() -> None:
        if len(request.query_string) > MAX_QUERY:
            abort(400, f"the query string has {len(request.query_string)} bytes; at most {MAX_QUERY}")
        for where, values in (("query parameter", request.args.items(multi=True)),
                              ("path segment", (request.view_args or {}).items())):
            for key, value in values:
                if isinstance(value, str) and (len(value) > MAX_PARAM or _CONTROL.search(value)):
                    abort(400, f"{where} '{key[:40]}': at most {MAX_PARAM} characters, no control characters")
        for value in (request.view_args or {}).values():
            if isinstance(value, int) and value > MAX_ID:
                abort(404, f"no row with id {value} (ids go up to {MAX_ID})")
        if request.method == "POST":
            _check_state_change()

    def _check_state_change() -> None:
        own = request.host_url.rstrip("/")
        origin = request.headers.get("Origin")
        referer = request.headers.get("Referer")
        fetch_site = request.headers.get("Sec-Fetch-Site")
        if origin is not None and origin != own:
            abort(403, f"a state-changing request from another origin ({origin[:80]}) is refused")
        if origin is None and referer and _origin_of(referer) != own:
            abort(403, "a state-changing request referred by another site is refused")
        if fetch_site is not None and fetch_site not in ("same-origin", "none"):
            abort(403, f"a {fetch_site} state-changing request is refused")
        if not allow_ack:
            abort(403, "this dashboard is read-only: start it with --allow-ack to let users acknowledge alarms")

    csrf = CSRFProtect(app)   # after the checks above: a read-only or cross-origin POST is refused first

    @app.after_request
    def _headers(response: Response) -> Response:
        for k, v in SECURITY_HEADERS.items():
            response.headers.setdefault(k, v)
        if response.mimetype == "text/html":
            response.headers["Cache-Control"] = "no-store"
        return response

    # -- errors: the dashboard's own pages --------------------------------------------------------------
    @app.errorhandler(CSRFError)
    def _csrf_error(exc: CSRFError):  # noqa: ANN202
        return render_template("error.html", code=400, title="Refused",
                               message=f"the form's security token is not valid ({exc.description.rstrip('.')}): "
                                       f"reload the page and try again"), 400

    @app.errorhandler(SecurityError)
    def _untrusted_host(exc: SecurityError):  # noqa: ANN202 - no page: its links would name the untrusted host
        return Response("400 Bad Request: this dashboard answers to its own address only (a Host header it does "
                        "not serve)\n", status=400, mimetype="text/plain")

    @app.errorhandler(HTTPException)
    def _http_error(exc: HTTPException):  # noqa: ANN202
        titles = {400: "Bad request", 401: "Not logged in", 403: "Refused", 404: "Not found",
                  405: "Method not allowed", 413: "Request too large"}
        message = exc.description if exc.code != 405 else f"{request.method} is not allowed on {request.path[:200]}"
        if exc.code == 404 and exc.description == getattr(type(exc), "description", None):
            message = f"nothing at {request.path[:200]}"
        response = Response(render_template("error.html", code=exc.code, title=titles.get(exc.code, exc.name),
                                            message=message), status=exc.code, mimetype="text/html")
        if exc.code == 405 and hasattr(exc, "valid_methods") and exc.valid_methods:
            response.headers["Allow"] = ", ".join(exc.valid_methods)
        return response

    @app.errorhandler(Exception)
    def _internal_error(exc: Exception):  # noqa: ANN202
        app.logger.exception("internal error on %s", request.path)
        return render_template("error.html", code=500, title="Internal error",
                               message="the dashboard could not answer this request; the server's log says why"), 500

    # -- pages --------------------------------------------------------------------------------------------
    def _filters() -> dict[str, str | None]:
        f = {k: request.args.get(k) or None for k in ("fleet", "trainset", "group", "state")}
        f["state"] = f["state"] or request.args.get("verdict") or None       # the name of the first dashboard
        if f["state"] is not None and f["state"] not in fleet_board.STATES:
            abort(400, f"state '{f['state']}': give one of {', '.join(fleet_board.STATES)}")
        return f

    @app.get("/")
    def overview() -> str:
        filters = _filters()
        result = fleet_board.board(database, today=today(), **filters)
        everything = queries.overview(database)
        return render_template("overview.html", board=result, filters=filters, states=fleet_board.STATES,
                               fleets=sorted({r["fleet"] for r in everything}),
                               all_trainsets=sorted({r["trainset"] for r in everything}))

    def _trainset_trends(name: str) -> list[tuple[dict[str, Any], Any]]:
        found = queries.trends(database, name)
        if not found:
            abort(404, f"no trainset '{name}' in the database")
        return found

    def _element_view(info: dict[str, Any], trend: Any) -> dict[str, Any]:
        pts = info["points"]
        last = pts[-1]
        return {"info": info, "trend": trend, "last": last, "label": last.get("label") or info["element_group"],
                "location": fleet_board.location(info["element_group"]),
                "reasons": [fleet_board.element_reason(p) for p in pts],
                "next": fleet_board.next_crossing(trend, info["calendar"], today())}

    @app.get("/trainset/<name>")
    def trainset_page(name: str) -> str:
        views = [_element_view(info, trend) for info, trend in _trainset_trends(name)]
        return render_template("trainset.html", name=name, views=views,
                               indicators=queries.indicators(database, name))

    def _find(name: str, vehicle: str, group: str) -> tuple[dict[str, Any], Any]:
        for info, trend in _trainset_trends(name):
            if info["vehicle"] == vehicle and info["element_group"] == group:
                return info, trend
        abort(404, f"trainset '{name}' has no element group '{group}' on vehicle '{vehicle}'")

    @app.get("/trainset/<name>/element/<vehicle>/<path:group>")
    def element_page(name: str, vehicle: str, group: str) -> str:
        view = _element_view(*_find(name, vehicle, group))
        alarm = next((a for a in queries.alarms(database, trainset=name)
                      if a["vehicle"] == vehicle and a["source"] == group), None)
        return render_template("element.html", name=name, view=view, alarm=alarm,
                               acks=[] if alarm is None else queries.acknowledgements(database, alarm["id"]))

    @app.get("/trainset/<name>/trend/<vehicle>/<path:group>.png")
    def trend_png(name: str, vehicle: str, group: str) -> Response:
        info, trend = _find(name, vehicle, group)
        label = info["points"][-1].get("label") or ""
        return Response(trend_figure(info, trend, today=today(), label=label), mimetype="image/png")

    def _run(run_id: int) -> dict[str, Any]:
        run = queries.run_info(database, run_id)
        if run is None:
            abort(404, f"no run {run_id} in the database")
        return run

    def _run_image(run: dict[str, Any], name: str) -> Path | None:
        if not _IMAGE_NAME.match(name):
            return None
        return _png(_inside(str(Path(run["run_dir"]) / name), run["run_dir"]))

    @app.get("/run/<int:run_id>")
    def run_page(run_id: int) -> str:
        run = _run(run_id)
        report_path = _inside(run["report_path"], run["run_dir"])
        report = None
        if report_path is not None and report_path.suffix == ".md" and report_path.stat().st_size < 2_000_000:
            text = report_path.read_text(encoding="utf-8", errors="replace")
            report = markdown_html(text, lambda src: url_for("run_image", run_id=run_id, name=src)
                                   if _run_image(run, src) is not None else None)
        figures = [w for w in (1, 2) if _png(_inside(run.get(f"figure{w}_path"), run["run_dir"])) is not None]
        return render_template("run.html", run=run, report=report, figures=figures,
                               indicators=queries.indicators(database, run_id=run_id),
                               reasons={v["element_group"]: fleet_board.element_reason(v) for v in run["values"]})

    @app.get("/run/<int:run_id>/figure/<int:which>")
    def run_figure(run_id: int, which: int) -> Response:
        run = _run(run_id)
        path = _png(_inside(run.get(f"figure{which}_path") if which in (1, 2) else None, run["run_dir"]))
        if path is None:
            abort(404, f"run {run_id} has no Figure {which} in its folder")
        return send_file(path, mimetype="image/png")

    @app.get("/run/<int:run_id>/image/<name>")
    def run_image(run_id: int, name: str) -> Response:
        path = _run_image(_run(run_id), name)
        if path is None:
            abort(404, f"run {run_id} has no image '{name}' in its folder")
        return send_file(path, mimetype="image/png")

    # -- alarms, logging in, acknowledging -----------------------------------------------------------------
    @app.get("/alarms")
    def alarm_list() -> str:
        user = current_user()
        acks: dict[int, list[dict[str, Any]]] = {}
        for a in queries.acknowledgements(database):
            acks.setdefault(a["alarm_id"], []).append(a)
        alarms = queries.alarms(database)
        nonces = {a["id"]: sessions.nonce(session["sid"]) for a in alarms
                  if user and allow_ack and a["state"] == "raised"}
        return render_template("alarms.html", alarms=alarms, acks=acks, audit=queries.audit(database),
                               nonces=nonces, max_comment=MAX_COMMENT)

    @app.get("/login")
    def login_form() -> str:
        if not allow_ack:
            abort(404, "this dashboard is read-only: there is nothing to log in for")
        return render_template("login.html")

    @app.post("/login")
    def login() -> Any:
        name, password = request.form.get("name", ""), request.form.get("password", "")
        user = authenticate(database, name, password)
        if user is None:
            log(f"{_now()} {request.remote_addr}: refused login as '{name[:100]}'")
            return render_template("login.html", refused=True), 401
        sessions.end(session.get("sid"))
        session.clear()                                     # a new session (and CSRF token) for the login
        session["sid"] = sessions.start(user)
        log(f"{_now()} {request.remote_addr}: {user} logged in")
        return redirect(url_for("alarm_list"))

    @app.post("/logout")
    def logout() -> Any:
        user = current_user()
        sessions.end(session.get("sid"))
        session.clear()
        if user:
            log(f"{_now()} {request.remote_addr}: {user} logged out")
        return redirect(url_for("overview"))

    @app.post("/alarms/<int:alarm_id>/ack")
    def acknowledge_alarm(alarm_id: int) -> Any:
        user = current_user()
        if user is None:
            abort(401, "log in to acknowledge alarms")
        if not sessions.use(session.get("sid"), request.form.get("once", "")):
            abort(400, "this form was already sent or is not from this session: reload the alarms page")
        comment = request.form.get("comment", "").strip()
        try:
            with database.session() as s:
                ack = acknowledge(s, alarm_id, user, comment)
                text = f"alarm {alarm_id} acknowledged by {user} at {ack.at.isoformat(sep=' ')} UTC"
        except AcknowledgementError as exc:
            flash(str(exc), "error")
            return redirect(url_for("alarm_list"), code=303)
        log(f"{_now()} {request.remote_addr}: {text}: {comment}")
        flash(text, "info")
        return redirect(url_for("alarm_list"), code=303)

    # -- exports ------------------------------------------------------------------------------------------
    @app.get("/export.<fmt>")
    def export(fmt: str) -> Response:
        if fmt not in ("csv", "json"):
            abort(404, f"no export format '{fmt}': export.csv or export.json")
        what = request.args.get("what", "overview")
        if what not in EXPORTS:
            abort(400, f"what='{what}': give one of {', '.join(EXPORTS)}")
        if what == "history":
            if not request.args.get("trainset"):
                abort(400, "what=history needs trainset=NAME")
            rows = queries.history(database, request.args["trainset"])
        elif what == "alarms":
            rows = queries.alarms(database)
        elif what == "indicators":
            rows = queries.indicators(database, request.args.get("trainset"))
        elif what == "board":
            rows = fleet_board.board(database, today=today(), **_filters())["rows"]
        else:
            f = _filters()
            rows = queries.overview(database, fleet=f["fleet"], trainset=f["trainset"], group=f["group"],
                                    verdict=request.args.get("verdict") or None)
        if fmt == "json":
            return Response(json.dumps(rows, indent=1), mimetype="application/json",
                            headers={"Content-Disposition": f"attachment; filename=suspid-{what}.json"})
        buf = io.StringIO()
        if rows:
            writer = csv.DictWriter(buf, fieldnames=list(dict.fromkeys(k for r in rows for k in r)), restval="")
            writer.writeheader()
            writer.writerows({k: _csv_cell(v) for k, v in r.items()} for r in rows)
        return Response(buf.getvalue(), mimetype="text/csv",
                        headers={"Content-Disposition": f"attachment; filename=suspid-{what}.csv"})

    app.extensions["suspid_csrf"] = csrf
    return app


def _now() -> str:
    return dt.datetime.now(dt.timezone.utc).strftime("%Y-%m-%d %H:%M:%S UTC")
