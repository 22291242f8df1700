"""How the dashboard writes numbers: engineering units, % of nominal, mileage, ages and slopes, in words.

Values are stored in SI units (N s/m, N/m, m/s^2); a force-based unit gets the
SI prefix that puts the largest number shown between 1 and 1000 (``118.5 kN
s/m``, ``1.2 MN/m``), every number has at most four significant digits and
is never in scientific notation, thousands are grouped with a narrow space
(``235 000 km``). Functions return plain strings for the templates.
"""

from __future__ import annotations

import math
from typing import Any, Iterable

_PREFIXES = ((1e9, "G"), (1e6, "M"), (1e3, "k"))
_PREFIXABLE = ("N", "Pa", "W")
_UNIT_TEXT = {"m/s^2": "m/s²", "m s^-2": "m/s²", "-": "", "1": ""}
GROUP = "\u202f"
"""The thousands separator (a narrow no-break space, as SI writes it)."""


def unit_text(unit: str) -> str:
    """A unit as written for people: ``m/s^2`` -> ``m/s²``, dimensionless -> ``""``."""
    return _UNIT_TEXT.get(unit, unit)


def scale_for(unit: str, values: Iterable[float | None]) -> tuple[float, str]:
    """(factor, prefixed unit) for showing ``values`` in ``unit``: ``('N s/m', [118e3])`` -> ``(1e3, 'kN s/m')``."""
    shown = unit_text(unit)
    finite = [abs(v) for v in values if v is not None and math.isfinite(v)]
    if unit.split(" ")[0].split("/")[0] in _PREFIXABLE and finite:
        for factor, prefix in _PREFIXES:
            if max(finite) >= factor:
                return factor, prefix + shown
    return 1.0, shown


def number(v: float | None, digits: int = 4) -> str:
    """``v`` with at most ``digits`` significant digits, without exponent, thousands grouped: ``1 134 737``."""
    if v is None or not math.isfinite(v):
        return "not known"
    if v == 0:
        return "0"
    decimals = max(0, digits - 1 - int(math.floor(math.log10(abs(v)))))
    text = f"{v:,.{decimals}f}"
    if "." in text:
        text = text.rstrip("0").rstrip(".")
    return text.replace(",", GROUP)


def quantity(v: float | None, unit: str) -> str:
    """``118.5 kN s/m``."""
    if v is None:
        return "not known"
    factor, shown = scale_for(unit, [v])
    return f"{number(v / factor)} {shown}".strip()


def interval(lo: float | None, hi: float | None, unit: str, value: float | None = None) -> str:
    """``[105.9, 131.1] kN s/m`` (the prefix chosen with ``value`` when given, so it matches the value's)."""
    if lo is None or hi is None:
        return ""
    factor, shown = scale_for(unit, [value if value is not None else max(abs(lo), abs(hi))])
    return f"[{number(lo / factor)}, {number(hi / factor)}] {shown}".strip()


def percent(v: float | None, digits: int = 1) -> str:
    """``39.5 %``."""
    return "not known" if v is None else f"{v:.{digits}f} %"


def mileage(km: float | None) -> str:
    """``235 000 km`` (or "mileage not recorded")."""
    return "mileage not recorded" if km is None else f"{number(round(km), 12)} km"


def abscissa(x: float | None, kind: str) -> str:
    """A trend abscissa: mileage (``134 315 km``) or days since the first date (``day 74``)."""
    if x is None:
        return "not known"
    return mileage(x) if kind == "mileage_km" else f"day {x:.0f}"


def age(days: int) -> str:
    """``170 days ago``, ``today``, ``1 day ago``, ``in 3 days`` (a date after today)."""
    if days == 0:
        return "today"
    if days < 0:
        return f"in {-days} day{'s' if days != -1 else ''}"
    return f"{days} day{'s' if days != 1 else ''} ago"


def slope(trend: Any, unit: str) -> str:
    """The trend's slope with its unit and 90 % interval: per 1 000 km on mileage, per 100 days on dates."""
    if trend.slope is None:
        return "no slope (too few usable points)"
    per, span = ("1 000 km", 1000.0) if trend.abscissa == "mileage_km" else ("100 days", 100.0)
    factor, shown = scale_for(unit, [trend.slope * span, trend.slope_low * span, trend.slope_high * span])
    return (f"{number(trend.slope * span / factor, 3)} {shown} per {per} (90 % interval "
            f"{number(trend.slope_low * span / factor, 3)} to {number(trend.slope_high * span / factor, 3)})")


def row_value(row: dict[str, Any]) -> dict[str, str]:
    """The overview's value cell of a board row: its headline (``39.5 % of nominal``), the interval in %, and
    the value in units with its interval (indicators: the value against its limit or levels)."""
    if row["what"] == "indicator":
        value = quantity(row["value"], row["unit"]) if row["unit"] else f"N_MV {number(row['value'], 3)}"
        if row["limit"]:
            head = f"{percent(row['percent'], 0)} of the limit"
            detail = f"{value}, limit {quantity(row['limit'], row['unit'])}"
        elif row.get("levels"):
            head = value
            detail = f"warning from {number(row['levels']['warning'])}, alarm from {number(row['levels']['alarm'])}"
        else:
            head, detail = value, "no limit"
        return {"head": head, "interval": "", "detail": detail}
    span = interval(row["interval_low"], row["interval_high"], row["unit"], row["value"])
    if row["percent"] is None:
        return {"head": quantity(row["value"], row["unit"]), "interval": span,
                "detail": "% of nominal not known (no nominal value recorded)"}
    return {"head": f"{percent(row['percent'])} of nominal",
            "interval": f"[{percent(row['percent_low'])}, {percent(row['percent_high'])}]",
            "detail": f"{quantity(row['value'], row['unit'])} {span}"}
