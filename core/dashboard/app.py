"""The fleet dashboard: a server-rendered Flask application over the monitoring database.

Pages: the fleet overview (trainsets x element groups coloured by verdict,
trust shown, filters by fleet, trainset, element group and verdict), a
trainset page (each element group's history with its trend, levels and
forecast, and the indicators), a run page (verdict table, indicators, Figure 1
and 2, the report), the alarms with the audit trail. ``/export.csv`` and
``/export.json`` give the overview's rows (``?what=history&trainset=..``,
``?what=alarms``) to a maintenance information system.

Read-only unless created with ``allow_ack``: acknowledging an alarm is then a
POST that stores who, when and the comment, writes an audit entry and is
logged. :func:`serve` binds 127.0.0.1 by default, through werkzeug's threaded
WSGI server.
"""

from __future__ import annotations

import csv
import datetime as dt
import io
import json
from pathlib import Path
from typing import Any, Callable

import numpy as np
from flask import Flask, Response, abort, redirect, render_template, request, send_file, url_for
from sqlalchemy.engine import make_url
from werkzeug.serving import make_server

from suspid.errors import SuspidError
from suspid.fleet import queries
from suspid.fleet.alarms import acknowledge
from suspid.fleet.db import Database, open_database
from suspid.fleet.schema import VERDICTS
from suspid.fleet.trends import Trend
from suspid.infra.files import pyplot

Log = Callable[[str], None]
_COLOURS = {"ok": "tab:green", "warning": "tab:orange", "alarm": "tab:red", "not assessable": "0.55"}


def _fmt(v: Any) -> str:
    if v is None:
        return "-"
    if isinstance(v, float):
        return f"{v:.6g}" if abs(v) < 1e6 else f"{v:.0f}"
    return str(v)


def trend_figure(info: dict[str, Any], trend: Trend) -> bytes:
    """PNG of one element group's history: values with intervals coloured by verdict, not-usable points hollow,
    the acceptable domain's edges, the warning and alarm levels, the trend with its 90 % band and the forecast
    crossings with their intervals."""
    plt = pyplot()
    pts = info["points"]
    x = np.asarray(info["x"], dtype=float)
    fig, ax = plt.subplots(figsize=(8, 3.6))
    for p, xi in zip(pts, x):
        usable = p["identifiable"] and p["trust"] != "no"
        c = _COLOURS[p["verdict"]]
        ax.errorbar([xi], [p["value"]], yerr=[[p["value"] - p["interval_low"]], [p["interval_high"] - p["value"]]],
                    fmt="o", color=c, mfc=c if usable else "white", capsize=3, zorder=3)
    if any(p["w_ref"] is not None for p in pts):
        ax.plot(x, [np.nan if p["w_ref"] is None else p["w_ref"] for p in pts], "k--", lw=0.8,
                label="true value (numerical experiment)")
    for edge in (pts[-1]["acceptable_low"], pts[-1]["acceptable_high"]):
        if edge is not None:
            ax.axhline(edge, color="tab:green", ls="--", lw=1)
    if trend.slope is not None:
        ends = [f.x_high for f in trend.forecasts if f.x_high is not None] + \
               [f.x for f in trend.forecasts if f.x is not None]
        x_end = max([x.max(), *[e for e in ends if e < x.max() + 3 * np.ptp(x) + 1]])
        grid = np.linspace(x.min(), x_end, 200)
        yhat, lower, upper = trend.predict(grid)
        ax.plot(grid, yhat, color="tab:blue", lw=1.2, label="trend (Theil-Sen)")
        ax.fill_between(grid, lower, upper, color="tab:blue", alpha=0.15, lw=0, label="90 % band")
        for f in trend.forecasts:
            colour = "tab:orange" if f.level == "warning" else "tab:red"
            ax.axhline(f.value, color=colour, lw=1, ls=":", label=f"{f.level} level")
            if f.x_low is not None:
                ax.axvspan(f.x_low, f.x_high if f.x_high is not None else x_end, color=colour, alpha=0.08, lw=0)
    ax.set_xlabel("mileage (km)" if trend.abscissa == "mileage_km" else "days since the first date")
    ax.set_ylabel(f"{info['element_group']} ({pts[-1]['unit']})")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="best")
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)
    plt.close(fig)
    return buf.getvalue()


def create_app(db: Database | str | Path, *, allow_ack: bool = False, log: Log = lambda s: None) -> Flask:
    """The dashboard's Flask application over ``db`` (an open database, a URL or an SQLite path)."""
    database = db if isinstance(db, Database) else open_database(db)
    app = Flask(__name__)
    label = make_url(database.url).render_as_string(hide_password=True)

    @app.context_processor
    def _common() -> dict[str, Any]:
        return {"db_label": label, "fmt": _fmt}

    def _filters() -> dict[str, str | None]:
        return {k: request.args.get(k) or None for k in ("fleet", "trainset", "verdict", "group")}

    @app.get("/")
    def overview() -> str:
        filters = _filters()
        rows = queries.overview(database, **filters)
        everything = queries.overview(database)
        groups = sorted({r["element_group"] for r in rows})
        grid: dict[tuple[str, str], dict[str, Any]] = {}
        for r in rows:
            grid.setdefault((r["trainset"], r["vehicle"]), {})[r["element_group"]] = r
        return render_template("overview.html", grid=sorted(grid.items()), groups=groups, filters=filters,
                               fleets=sorted({r["fleet"] for r in everything}),
                               all_trainsets=sorted({r["trainset"] for r in everything}), verdicts=VERDICTS,
                               n_rows=len(rows))

    @app.get("/trainset/<name>")
    def trainset_page(name: str) -> str:
        trends = queries.trends(database, name)
        if not trends:
            abort(404)
        return render_template("trainset.html", name=name, trends=trends,
                               indicators=queries.indicators(database, name))

    @app.get("/trainset/<name>/trend/<vehicle>/<path:group>.png")
    def trend_png(name: str, vehicle: str, group: str) -> Response:
        for info, trend in queries.trends(database, name):
            if info["vehicle"] == vehicle and info["element_group"] == group:
                return Response(trend_figure(info, trend), mimetype="image/png")
        abort(404)

    @app.get("/run/<int:run_id>")
    def run_page(run_id: int) -> str:
        run = queries.run_info(database, run_id)
        if run is None:
            abort(404)
        report = ""
        if run["report_path"] and Path(run["report_path"]).is_file():
            report = Path(run["report_path"]).read_text(encoding="utf-8")
        return render_template("run.html", run=run, report=report,
                               indicators=queries.indicators(database, run_id=run_id))

    @app.get("/run/<int:run_id>/figure/<int:which>")
    def run_figure(run_id: int, which: int) -> Response:
        run = queries.run_info(database, run_id)
        path = None if run is None else run.get(f"figure{which}_path")
        if not path or not Path(path).is_file():
            abort(404)
        return send_file(path, mimetype="image/png")

    @app.get("/alarms")
    def alarm_list() -> str:
        return render_template("alarms.html", alarms=queries.alarms(database), audit=queries.audit(database),
                               allow_ack=allow_ack, message=request.args.get("message"))

    @app.post("/alarms/<int:alarm_id>/ack")
    def acknowledge_alarm(alarm_id: int) -> Response:
        if not allow_ack:
            abort(403, "this dashboard is read-only: start it with --allow-ack to acknowledge alarms")
        who, comment = request.form.get("who", ""), request.form.get("comment", "")
        try:
            with database.session() as s:
                alarm = acknowledge(s, alarm_id, who, comment)
                text = f"alarm {alarm_id} ({alarm.trainset}/{alarm.vehicle} {alarm.source}) acknowledged by {who}"
        except SuspidError as exc:
            return redirect(url_for("alarm_list", message=str(exc)))
        log(f"{dt.datetime.now(dt.timezone.utc).isoformat(timespec='seconds')} {request.remote_addr}: {text}: "
            f"{comment}")
        return redirect(url_for("alarm_list", message=text))

    @app.get("/export.<fmt>")
    def export(fmt: str) -> Response:
        what = request.args.get("what", "overview")
        if what == "history":
            if not request.args.get("trainset"):
                abort(400, "what=history needs trainset=")
            rows = queries.history(database, request.args["trainset"])
        elif what == "alarms":
            rows = queries.alarms(database)
        elif what == "indicators":
            rows = queries.indicators(database, request.args.get("trainset"))
        else:
            rows = queries.overview(database, **_filters())
        if fmt == "json":
            return Response(json.dumps(rows, indent=1), mimetype="application/json",
                            headers={"Content-Disposition": f"attachment; filename=suspid-{what}.json"})
        if fmt != "csv":
            abort(404)
        buf = io.StringIO()
        if rows:
            writer = csv.DictWriter(buf, fieldnames=list(rows[0]))
            writer.writeheader()
            writer.writerows(rows)
        return Response(buf.getvalue(), mimetype="text/csv",
                        headers={"Content-Disposition": f"attachment; filename=suspid-{what}.csv"})

    return app


def serve(db: str | Path, *, host: str = "127.0.0.1", port: int = 8050, allow_ack: bool = False,
          log: Log = lambda s: None) -> None:
    """Serve the dashboard until interrupted (werkzeug's threaded WSGI server)."""
    app = create_app(db, allow_ack=allow_ack, log=log)
    server = make_server(host, port, app, threaded=True)
    log(f"dashboard on http://{host}:{server.server_port}/ ({'acknowledgements allowed' if allow_ack else 'read-only'})"
        f"; Ctrl-C stops it")
    server.serve_forever()
