"""Degradation trends of an element group and the forecast of its warning and alarm crossings.

**Model.** Wear of a damper or an air spring is slow and, over the months a
maintenance interval spans, close to linear in the distance run: the model is
``value = a + b * x`` with x the mileage (km), or the days since the first date
when the mileage is not recorded. It is fitted by the Theil-Sen estimator (the
median of the pairwise slopes; breakdown point 29 %), so that one bad
identification among a handful does not tilt the trend, and only on points
that are findings: not-identifiable values and values a model-error check
calls not trustworthy are left out (counted in ``n_excluded``).

**Uncertainty.** Two parts, both distribution-free where they can be: the
slope's 90 % confidence interval of Sen (1968) from the pairwise slopes
(``scipy.stats.theilslopes``), and the level of the line at its pivot (the
median mileage), ``t(0.95, n-1) sigma / sqrt(n)`` with sigma = max(1.4826 MAD
of the residuals, median interval half-width / 1.96): a robust residual scale,
never below the identification uncertainty each value carries. The band at x
is the envelope of the lines through the pivot with the slopes of the
interval, widened by the pivot's level uncertainty: narrow where the data
are, opening like the slope's uncertainty beyond them.

**Levels** follow the verdict rule of the monitor (an interval [v - h, v + h]
against the acceptable domain [lo, hi], h the median half-width): the
warning starts when the interval reaches the edge (v = lo + h) and the alarm
when it is wholly outside (v = lo - h); the side is the one the trend heads
to. **Forecast**: the trend's crossing of each level, with the interval of
mileages where the confidence band crosses it (inverse regression: the
earliest where the pessimistic edge of the band reaches the level, the latest
where the optimistic edge does; None when that is beyond ten times the
observed span). Mileages become dates through the vehicle's mileage rate
(a least-squares line of mileage against date, :class:`Calendar`).

**No trend, no forecast.** When the slope's 90 % interval contains 0 the data
do not show a degradation: the trend is kept (its line and band are what the
data say) but no crossing is forecast, whatever the central slope; the note
says "no trend". The levels are then those of the domain edge the values are
closest to. **Crossed levels.** A level the latest usable value is already
past is *crossed*, with the abscissa of the first point of the last unbroken
run of points past it (``crossed_x``): a measured fact, not a forecast.
"""

from __future__ import annotations

import datetime as dt
from dataclasses import asdict, dataclass, field
from typing import Any, Sequence

import numpy as np
from scipy import stats

MIN_POINTS = 3
HORIZON_SPANS = 10.0
BAND_LEVEL = 0.90


@dataclass
class Forecast:
    """When the trend crosses one level: abscissa (km or days) and date, each with its interval."""

    level: str
    value: float
    x: float | None
    x_low: float | None
    x_high: float | None
    date: dt.date | None = None
    date_low: dt.date | None = None
    date_high: dt.date | None = None
    crossed: bool = False           # the latest usable value is past the level (measured, not forecast)
    crossed_x: float | None = None  # abscissa of the first point of the last run of points past the level
    crossed_on: dt.date | None = None


@dataclass
class Trend:
    """A fitted degradation trend of one element group of one vehicle (module docstring)."""

    element_group: str
    abscissa: str                   # "mileage_km" or "days"
    n_points: int
    n_excluded: int
    slope: float | None = None      # value unit per km (or per day)
    slope_low: float | None = None
    slope_high: float | None = None
    intercept: float | None = None
    sigma: float | None = None
    x_pivot: float | None = None
    y_pivot: float | None = None
    level_se: float | None = None
    side: str | None = None         # "low" or "high": the edge of the domain the trend heads to
    forecasts: list[Forecast] = field(default_factory=list)
    note: str = ""
    x_first: float | None = None    # the usable points' abscissae: first and last
    x_last: float | None = None

    @property
    def horizon(self) -> float | None:
        """The farthest abscissa a crossing is forecast to: the last point plus ten observed spans."""
        if self.x_first is None:
            return None
        return self.x_last + HORIZON_SPANS * (self.x_last - self.x_first)

    @property
    def significant(self) -> bool:
        """Whether the slope's 90 % interval excludes 0 (a trend the data show, and crossings are forecast)."""
        return self.slope_low is not None and not self.slope_low <= 0.0 <= self.slope_high

    def predict(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The line and its 90 % band at ``x``: (yhat, lower, upper)."""
        x = np.asarray(x, dtype=float)
        yhat = self.intercept + self.slope * x
        lines = [self.y_pivot + s * (x - self.x_pivot) for s in (self.slope_low, self.slope_high)]
        return yhat, np.minimum(*lines) - self.level_se, np.maximum(*lines) + self.level_se

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def levels_for(acceptable_low: float | None, acceptable_high: float | None, half_width: float, side: str
               ) -> dict[str, float] | None:
    """Warning and alarm levels (value units) on ``side`` of the domain (module docstring), None without that edge."""
    edge = acceptable_low if side == "low" else acceptable_high
    if edge is None:
        return None
    sign = 1.0 if side == "low" else -1.0
    return {"warning": edge + sign * half_width, "alarm": edge - sign * half_width}


def _crossing(xs: np.ndarray, ys: np.ndarray, level: float, below: bool) -> float | None:
    """First x of the grid where ys passes ``level`` (downwards when ``below``), linearly interpolated."""
    past = ys <= level if below else ys >= level
    if not past.any():
        return None
    i = int(np.argmax(past))
    if i == 0:
        return float(xs[0])
    x0, x1, y0, y1 = xs[i - 1], xs[i], ys[i - 1], ys[i]
    return float(x0 + (level - y0) * (x1 - x0) / (y1 - y0)) if y1 != y0 else float(x1)


def fit_trend(element_group: str, x: Sequence[float], y: Sequence[float], half_width: Sequence[float],
              usable: Sequence[bool], *, acceptable_low: float | None, acceptable_high: float | None,
              abscissa: str = "mileage_km") -> Trend:
    """Fit the trend of one element group and forecast its level crossings (module docstring).

    :param x: mileage (km) or days of each point, ``(n,)``.
    :param y: identified values (SI units), ``(n,)``.
    :param half_width: half-width of each value's uncertainty interval, ``(n,)``.
    :param usable: False for not-identifiable or not-trustworthy points (left out).
    """
    x, y, hw = (np.asarray(v, dtype=float) for v in (x, y, half_width))
    keep = np.asarray(usable, dtype=bool) & np.isfinite(x) & np.isfinite(y)
    trend = Trend(element_group, abscissa, int(keep.sum()), int((~keep).sum()))
    if keep.sum() < MIN_POINTS or np.ptp(x[keep]) <= 0:
        trend.note = f"fewer than {MIN_POINTS} usable points at distinct {abscissa}: no trend"
        return trend
    xk, yk, hk = x[keep], y[keep], hw[keep]
    trend.x_first, trend.x_last = float(xk.min()), float(xk.max())
    slope, _, lo, hi = stats.theilslopes(yk, xk, alpha=BAND_LEVEL)
    intercept = float(np.median(yk - slope * xk))   # median of the points' intercepts (scipy's median(y) -
    # slope * median(x) is biased when the abscissae are not symmetric about their median)
    resid = yk - (intercept + slope * xk)
    mad = 1.4826 * float(np.median(np.abs(resid - np.median(resid))))
    h = float(np.median(hk))
    trend.slope, trend.intercept, trend.slope_low, trend.slope_high = map(float, (slope, intercept, lo, hi))
    trend.sigma = max(mad, h / 1.96, 1e-12 * max(abs(float(np.median(yk))), 1.0))
    trend.x_pivot = float(np.median(xk))
    trend.y_pivot = float(intercept + slope * trend.x_pivot)
    trend.level_se = float(stats.t.ppf(0.5 + BAND_LEVEL / 2, xk.size - 1) * trend.sigma / np.sqrt(xk.size))
    trend.side = "low" if slope < 0 else "high"
    if not trend.significant:
        trend.note = "no trend: the slope's 90 % interval contains 0, so no crossing is forecast"
        trend.side = _nearest_side(float(yk[np.argmax(xk)]), acceptable_low, acceptable_high) or trend.side
    levels = levels_for(acceptable_low, acceptable_high, h, trend.side)
    if levels is None:
        trend.note = trend.note or "no acceptable domain on the side the trend heads to: no forecast"
        return trend
    span = float(np.ptp(xk))
    grid = np.linspace(float(xk.min()), float(xk.max()) + HORIZON_SPANS * span, 4001)
    yhat, lower, upper = trend.predict(grid)
    below = trend.side == "low"
    pessimistic, optimistic = (lower, upper) if below else (upper, lower)
    order = np.argsort(xk, kind="stable")
    for name in ("warning", "alarm"):
        level = levels[name]
        past = (yk[order] <= level) if below else (yk[order] >= level)
        crossed_x = None
        if past[-1]:
            first = len(past) - int(np.argmin(past[::-1])) if not past.all() else 0
            crossed_x = float(xk[order][first])
        if not trend.significant:
            trend.forecasts.append(Forecast(name, level, None, None, None, crossed=bool(past[-1]),
                                            crossed_x=crossed_x))
            continue
        central = (level - trend.intercept) / trend.slope if trend.slope != 0 else None
        if central is not None and central < xk.min() - HORIZON_SPANS * span:
            central = None
        trend.forecasts.append(Forecast(name, level, central, _crossing(grid, pessimistic, level, below),
                                        _crossing(grid, optimistic, level, below), crossed=bool(past[-1]),
                                        crossed_x=crossed_x))
    return trend


def _nearest_side(value: float, low: float | None, high: float | None) -> str | None:
    """The domain edge ``value`` is closest to (past it counts as closest): "low", "high", or None."""
    if low is None and high is None:
        return None
    if low is None or high is None:
        return "low" if high is None else "high"
    return "low" if value - low <= high - value else "high"


@dataclass(frozen=True)
class Calendar:
    """Abscissa <-> date of one vehicle: days since ``first``, or mileage through a line of mileage against date
    (``km0`` at ``first``, ``rate`` km per day; None when the mileage does not grow with the dates)."""

    abscissa: str
    first: dt.date
    rate: float | None = None
    km0: float | None = None

    @classmethod
    def of(cls, abscissa: str, dates: Sequence[dt.date], mileages: Sequence[float | None]) -> "Calendar":
        first = min(dates)
        if abscissa == "days":
            return cls(abscissa, first)
        pairs = [((d - first).days, m) for d, m in zip(dates, mileages) if m is not None]
        if len(pairs) < 2 or np.ptp([p[0] for p in pairs]) == 0:
            return cls(abscissa, first)
        rate, km0 = np.polyfit([p[0] for p in pairs], [p[1] for p in pairs], 1)
        return cls(abscissa, first, float(rate), float(km0)) if rate > 0 else cls(abscissa, first)

    @property
    def usable(self) -> bool:
        return self.abscissa == "days" or self.rate is not None

    def to_date(self, x: float | None) -> dt.date | None:
        """The date at abscissa ``x`` (None when unknown or beyond the calendar)."""
        if x is None or not self.usable:
            return None
        days = float(x) if self.abscissa == "days" else (float(x) - self.km0) / self.rate
        try:
            return self.first + dt.timedelta(days=days)
        except OverflowError:
            return None

    def to_x(self, date: dt.date) -> float | None:
        """The abscissa at ``date`` (None when the calendar cannot tell)."""
        if not self.usable:
            return None
        days = float((date - self.first).days)
        return days if self.abscissa == "days" else self.km0 + self.rate * days


def dates_from_mileage(trend: Trend, dates: Sequence[dt.date], mileages: Sequence[float | None]) -> Calendar | None:
    """Fill each forecast's dates (directly from days, or through the mileage rate) and the date of each crossed
    level (the measurement's own date); returns the vehicle's :class:`Calendar` (None without dates)."""
    if not dates:
        return None
    calendar = Calendar.of(trend.abscissa, dates, mileages)
    on_x = {}
    for d, m in zip(dates, mileages):
        x = float((d - calendar.first).days) if trend.abscissa == "days" else m
        if x is not None:
            on_x.setdefault(float(x), d)
    for f in trend.forecasts:
        f.date, f.date_low, f.date_high = (calendar.to_date(v) for v in (f.x, f.x_low, f.x_high))
        f.crossed_on = None if f.crossed_x is None else on_x.get(float(f.crossed_x))
    return calendar
