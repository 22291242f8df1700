"""The trend figure of one element group (the dashboard's trainset and element pages).

Drawn with matplotlib's object API (a :class:`~matplotlib.figure.Figure` of
its own per request, no pyplot state), so that the threaded server can draw
several at once. Every line has a legend entry; the axes hold the data, the
levels, the next crossing and today, and nothing past the forecast horizon.
"""

from __future__ import annotations

import datetime as dt
import io
from typing import Any

import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch
from matplotlib.ticker import FuncFormatter

from suspid.dashboard.present import number, quantity, scale_for, slope
from suspid.fleet.trends import Trend

COLOURS = {"ok": "tab:green", "warning": "tab:orange", "alarm": "tab:red", "not assessable": "0.55"}
LEVEL_COLOURS = {"warning": "tab:orange", "alarm": "tab:red"}


def _x_end(x: np.ndarray, trend: Trend) -> float:
    """The right edge: the data and the next forecast crossing, never past the forecast horizon."""
    end = float(x.max())
    ahead = [f for f in trend.forecasts if not f.crossed and f.x is not None]
    if ahead and ahead[0].x > end:
        end = ahead[0].x if trend.horizon is None else min(ahead[0].x, trend.horizon)
    return end


def trend_figure(info: dict[str, Any], trend: Trend, *, today: dt.date, label: str = "") -> bytes:
    """PNG of one element group's history (module docstring): values with their intervals coloured by verdict,
    points left out of the trend hollow, the acceptable domain, the warning and alarm levels, the trend with its
    90 % band, the next crossing with its interval, crossings already measured, and today.

    :param info: a :func:`suspid.fleet.queries.trends` info dict (points, abscissae ``x``, ``calendar``).
    """
    pts = info["points"]
    x = np.asarray(info["x"], dtype=float)
    unit = pts[-1]["unit"]
    factor, shown = scale_for(unit, [max(abs(p["value"]) for p in pts)])
    calendar = info.get("calendar")
    x_today = calendar.to_x(today) if calendar is not None else None
    x_end = _x_end(x, trend)
    x_start = float(x.min())
    pad = 0.03 * max(x_end - x_start, 1.0)

    fig = Figure(figsize=(11.5, 5.0), dpi=100, layout="constrained")
    ax = fig.add_subplot()
    handles: dict[str, Any] = {}
    ys: list[float] = []
    for p, xi in zip(pts, x):
        usable = p["identifiable"] and p["trust"] != "no"
        c = COLOURS[p["verdict"]]
        v, lo, hi = p["value"] / factor, p["interval_low"] / factor, p["interval_high"] / factor
        ax.errorbar([xi], [v], yerr=[[v - lo], [hi - v]], fmt="o", ms=7, color=c, mfc=c if usable else "white",
                    capsize=4, zorder=3)
        ys += [lo, hi]
        handles.setdefault(f"v-{p['verdict']}", Line2D([], [], marker="o", color=c, ls="-", ms=7,
                                                       label=f"identified value, 90 % interval: {p['verdict']}"))
        if not usable:
            handles.setdefault("left out", Line2D([], [], marker="o", color="0.3", mfc="white", ls="", ms=7,
                                                  label="left out of the trend (not identifiable or not trustworthy)"))
    if any(p["w_ref"] is not None for p in pts):
        ax.plot(x, [np.nan if p["w_ref"] is None else p["w_ref"] / factor for p in pts], "k--", lw=0.9)
        handles["w_ref"] = Line2D([], [], color="k", ls="--", lw=0.9, label="true value (numerical experiment)")
    for edge in (pts[-1]["acceptable_low"], pts[-1]["acceptable_high"]):
        if edge is not None:
            ax.axhline(edge / factor, color="tab:green", ls="--", lw=1.2)
            ys.append(edge / factor)
            handles["domain"] = Line2D([], [], color="tab:green", ls="--", lw=1.2, label="acceptable domain (edges)")
    if trend.slope is not None:
        grid = np.linspace(x_start, x_end, 200)
        yhat, lower, upper = (a / factor for a in trend.predict(grid))
        ax.plot(grid, yhat, color="tab:blue", lw=1.5)
        ax.fill_between(grid, lower, upper, color="tab:blue", alpha=0.14, lw=0)
        ys += [float(yhat[0]), float(yhat[-1])]
        words = (f"trend (Theil-Sen), {slope(trend, unit)}" if trend.significant else
                 "fitted line (Theil-Sen): no trend, the slope's 90 % interval contains 0")
        handles["trend"] = Line2D([], [], color="tab:blue", lw=1.5, label=words)
        handles["band"] = Patch(color="tab:blue", alpha=0.14, label="90 % band of the trend")
    next_shown = False
    for f in trend.forecasts:
        colour = LEVEL_COLOURS[f.level]
        level = f.value / factor
        ax.axhline(level, color=colour, lw=1.1, ls=":")
        ys.append(level)
        handles[f"level-{f.level}"] = Line2D([], [], color=colour, lw=1.1, ls=":",
                                             label=f"{f.level} level ({quantity(f.value, unit)})")
        if f.crossed and f.crossed_x is not None:
            ax.plot([f.crossed_x], [level], marker="X", ms=10, color=colour, ls="", zorder=4)
            when = f" on {f.crossed_on.isoformat()}" if f.crossed_on else ""
            handles[f"crossed-{f.level}"] = Line2D([], [], marker="X", ms=10, color=colour, ls="",
                                                   label=f"{f.level} level crossed (measured{when})")
        elif not next_shown and f.x is not None and f.x <= x_end:
            next_shown = True
            ax.plot([f.x], [level], marker="v", ms=10, color=colour, ls="", zorder=4)
            when = f", {f.date.isoformat()}" if f.date else ""
            handles[f"next-{f.level}"] = Line2D([], [], marker="v", ms=10, color=colour, ls="",
                                                label=f"next crossing: {f.level} level{when}")
            if f.x_low is not None:
                ax.axvspan(f.x_low, min(f.x_high if f.x_high is not None else x_end, x_end), color=colour,
                           alpha=0.10, lw=0)
                handles[f"span-{f.level}"] = Patch(color=colour, alpha=0.10,
                                                   label=f"90 % interval of the {f.level} crossing")
    if x_today is not None and x_start - pad <= x_today <= x_end + pad:
        ax.axvline(x_today, color="0.2", lw=1.2, ls="-.")
        handles["today"] = Line2D([], [], color="0.2", lw=1.2, ls="-.", label=f"today ({today.isoformat()})")
    elif x_today is not None:                  # today is off the axes: an arrow at the edge it lies beyond
        right = x_today > x_end
        ax.annotate("", xy=(1.0 if right else 0.0, 0.04), xytext=(0.93 if right else 0.07, 0.04),
                    xycoords="axes fraction", arrowprops={"arrowstyle": "-|>", "color": "0.2", "lw": 1.4})
        where = (f"{number(x_today, 12)} km" if trend.abscissa == "mileage_km" else f"day {x_today:.0f}")
        handles["today"] = Line2D([], [], color="0.2", lw=1.4, marker=">" if right else "<", ms=6,
                                  label=f"today ({today.isoformat()}, about {where}): "
                                        f"{'right' if right else 'left'} of the plot")
    lo, hi = min(ys), max(ys)
    margin = 0.08 * max(hi - lo, abs(hi) * 1e-3, 1e-12)
    ax.set_ylim(lo - margin, hi + margin)
    ax.set_xlim(x_start - pad, x_end + pad)
    ax.xaxis.set_major_formatter(FuncFormatter(lambda v, _: number(v, 12) if abs(v) >= 1000 else f"{v:g}"))
    if trend.abscissa == "mileage_km":
        ax.set_xlabel("mileage (km)")
    else:
        first = calendar.first.isoformat() if calendar is not None else "the first date"
        ax.set_xlabel(f"days since {first}")
    name = info["element_group"]
    ax.set_ylabel(f"{label or name} ({shown})" if shown else (label or name))
    ax.set_title(f"{info.get('trainset', '')} {info['vehicle']}: {label + ' ' if label else ''}({name})",
                 fontsize=11, loc="left")
    ax.grid(alpha=0.3)
    ax.legend(handles=list(handles.values()), fontsize=9, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    return buf.getvalue()
