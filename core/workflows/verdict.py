"""The maintenance verdict: per identified parameter or element group, is the suspension still acceptable?

For each identified parameter (a kind such as ``c_yaw``, or an element group such as ``c_yaw[bogie2]``)
and each group a localisation names, the verdict compares the identified value with its **nominal value**
and the acceptable domain of the config's ``limits:`` section (warning and alarm levels in % of nominal,
below and/or above it):

- the nominal value is the simulator's (:attr:`suspid.interfaces.Parameter.nominal`: exudyn-train's vehicle
  preset with its ``vehicle:`` overrides, the vampire plugin's ``parameters[].nominal``); an element group the
  simulator does not declare takes its kind's; ``limits.<name>.nominal`` replaces it;
- the levels of ``limits.<name>``, else of its kind's entry (``limits.c_yaw`` holds for ``c_yaw[bogie2]``).

The rules, in order (the first that applies gives the verdict, and its wording is kept as the ``rule``):

1. not identifiable -> **not assessable** (its value is not a finding);
2. not trustworthy under model error -> **not assessable**;
3. no nominal value, or no limits for it -> **not assessable**;
4. the interval reaches across two levels (from ok to alarm) -> **not assessable**: the data do not tell the
   three states apart;
5. the interval reaches across one level (its ends lie in two adjacent states) -> by the limits' ``decision``:
   ``precautionary`` (the default) gives the more severe of the two states, marked *borderline*, naming the
   level: acceptance must be shown, not presumed (the conformity decision rule of ISO 14253-1, where a
   measurement proves conformity only when its whole uncertainty interval lies inside the specification);
   ``strict`` gives **not assessable**;
6. otherwise the state of the whole interval: **ok**, **warning** (at or beyond a warning level) or **alarm**
   (at or beyond an alarm level). Where trust was *not assessed* (the model-error checks did not all run),
   the verdict stands on the sampling interval and the rule says so.

Rows are :class:`VerdictRow` (typed; ``to_dict``/``from_dict`` for ``result.json``'s ``verdict`` block,
:data:`VERSION`). The table functions here give the same cells to the terminal, ``report.md`` and a notebook.
"""

from __future__ import annotations

import math
import re
from dataclasses import asdict, dataclass, field, replace
from typing import Any, Mapping, Sequence

from suspid.config import kind_of
from suspid.interfaces import Parameter
from suspid.sections import Limits
from suspid.workflows.trust import trust_word

__all__ = ["VERSION", "STATES", "DECISIONS", "ACTIONS", "VerdictRow", "verdict_rows", "verdict_block", "rows_of",
           "zone", "judge", "format_value", "table", "terminal_table", "vertical_lines", "summary_line",
           "verdict_markdown"]

VERSION = 1
"""Version of ``result.json``'s ``verdict`` block (bumped when a field changes meaning or goes)."""

STATES = ("ok", "warning", "alarm", "not assessable")
DECISIONS = ("precautionary", "strict")
"""How an interval reaching across one level is decided (``limits.<name>.decision``; rule 5)."""
ACTIONS = {"ok": "no action", "warning": "inspect at the next maintenance", "alarm": "replace",
           "not assessable": "no verdict"}
"""What each state asks of the maintenance engineer, as the summary line words it."""


@dataclass(frozen=True)
class VerdictRow:
    """The verdict on one identified parameter or element group.

    :ivar name: ``c_yaw`` or ``c_yaw[bogie2]``; :ivar label: the element(s) in plain language.
    :ivar unit: SI unit of ``nominal``, ``value`` and ``interval``.
    :ivar nominal: the nominal value (SI), None when unknown.
    :ivar value: the identified value (SI); :ivar interval: ``(lower, upper)`` SI.
    :ivar change_percent: ``100 (value / nominal - 1)``; :ivar interval_percent: the interval likewise.
    :ivar identifiable: False where the value is not a finding.
    :ivar trust: trust under model error, ``"yes"``, ``"no"`` or ``"not assessed"``.
    :ivar warning, alarm: ``(lower, upper)`` levels in % of nominal (None: open side), None when not given.
    :ivar verdict: one of :data:`STATES`; :ivar rule: why (the rule of the module docstring that applied).
    :ivar source: ``"identification"`` or ``"localisation"``; :ivar w_ref: the known value of a numerical
        experiment, else None; :ivar error_percent: ``|value - w_ref|`` in % of the admissible interval (the
        paper's error), else None; :ivar alternatives: groups a localisation found nearly as likely.
    """

    name: str
    label: str
    unit: str
    nominal: float | None
    value: float
    interval: tuple[float, float]
    change_percent: float | None
    interval_percent: tuple[float, float] | None
    identifiable: bool
    trust: str
    warning: tuple[float | None, float | None] | None
    alarm: tuple[float | None, float | None] | None
    verdict: str
    rule: str
    source: str = "identification"
    w_ref: float | None = None
    error_percent: float | None = None
    alternatives: list[str] = field(default_factory=list)
    borderline: bool = False

    def to_dict(self) -> dict[str, Any]:
        """JSON-able (tuples as lists)."""
        return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> "VerdictRow":
        """From :meth:`to_dict`'s output (``result.json``)."""
        tup = lambda v: None if v is None else tuple(v)  # noqa: E731
        return cls(**{**data, "interval": tuple(data["interval"]), "interval_percent": tup(data["interval_percent"]),
                      "warning": tup(data["warning"]), "alarm": tup(data["alarm"]),
                      "alternatives": list(data.get("alternatives", [])),
                      "borderline": bool(data.get("borderline", False))})

    @property
    def summary(self) -> str:
        """One plain-language line: ``bogie 2 yaw dampers (c_yaw[bogie2]): -38 % (interval -44 to -32 %), alarm:
        replace``."""
        return summary_line(self)


# -- the rules -----------------------------------------------------------------------------------------
def _percent(value: float, nominal: float) -> float:
    return 100.0 * (value / nominal - 1.0)


def zone(change: float, warning: tuple | None, alarm: tuple | None) -> str:
    """The state of a change (% of nominal): ``alarm`` at or beyond an alarm level, else ``warning`` at or
    beyond a warning level, else ``ok``. Levels are ``(lower, upper)``, None an open side."""
    for state, levels in (("alarm", alarm), ("warning", warning)):
        if levels is None:
            continue
        lower, upper = levels
        if (lower is not None and change <= lower) or (upper is not None and change >= upper):
            return state
    return "ok"


def _levels_between(lo: float, hi: float, warning: tuple | None, alarm: tuple | None) -> list[str]:
    out = []
    for state, levels in (("warning", warning), ("alarm", alarm)):
        for level in (levels or (None, None)):
            if level is not None and lo <= level <= hi:
                out.append(f"the {state} level {level:+g} %")
    return out


def _across(lo: float, hi: float, warning: tuple | None, alarm: tuple | None) -> str:
    """``the interval -31.0 to -24.0 % reaches across the warning level -25 %``: the levels between lo and hi."""
    crossed = _levels_between(lo, hi, warning, alarm)
    return f"the interval {lo:+.1f} to {hi:+.1f} % reaches across {' and '.join(crossed) or 'a level'}"


BORDERLINE = "borderline: "
"""How the rule of a precautionary verdict on an interval across one level begins (rule 5)."""
SAMPLING = "; trust under model error not assessed: the verdict rests on the sampling interval"
MISFIT = ("; the interval holds the segments' spread and the misfit the localisation's fit leaves (model-form "
          "error the channels show)")


def judge(*, identifiable: bool, trust: str, change: float | None, interval: tuple[float, float] | None,
          warning: tuple | None, alarm: tuple | None, reasons: Sequence[str] = (),
          caveat: str = SAMPLING, decision: str = "precautionary") -> tuple[str, str]:
    """``(verdict, rule)`` by the rules of the module docstring.

    :param change: the identified change in % of nominal (None: no nominal value).
    :param interval: its interval in % of nominal.
    :param reasons: why the component is not identifiable or not trustworthy (quoted in the rule).
    :param caveat: what the interval holds, appended to a verdict whose trust is not "yes" (:data:`SAMPLING`, or
        :data:`MISFIT` for a localisation whose interval holds its fit's misfit).
    :param decision: one of :data:`DECISIONS`, for an interval reaching across one level.
    """
    why = f": {'; '.join(reasons)}" if reasons else ""
    if not identifiable:
        return "not assessable", f"not identifiable{why}"
    if trust == "no":
        return "not assessable", f"not trustworthy under model error{why}"
    if change is None or interval is None:
        return "not assessable", "no nominal value to measure the change from"
    if warning is None and alarm is None:
        return "not assessable", "no limits given for it (limits: in the config)"
    if decision not in DECISIONS:
        raise ValueError(f"decision must be one of {', '.join(DECISIONS)}, not {decision!r}")
    lo, hi = min(interval), max(interval)
    states = {zone(lo, warning, alarm), zone(change, warning, alarm), zone(hi, warning, alarm)}
    across = _across(lo, hi, warning, alarm)
    if len(states) > 2 or (len(states) > 1 and decision == "strict"):
        return "not assessable", across
    if len(states) == 2:
        state = max(states, key=("ok", "warning", "alarm").index)
        rule = (f"{BORDERLINE}{across}; precautionary decision: the more severe state, {state}, until a "
                f"measurement shows the milder one")
        return state, rule + (caveat if trust != "yes" else "")
    state = states.pop()
    levels = [f"{s} {', '.join(f'{v:+g} %' for v in lv if v is not None)}"
              for s, lv in (("warning", warning), ("alarm", alarm)) if lv is not None]
    rule = f"the whole interval {lo:+.1f} to {hi:+.1f} % is {state} ({'; '.join(levels)})"
    if trust != "yes":
        rule += caveat
    return state, rule


# -- nominal values, limits and labels -------------------------------------------------------------------
def limits_for(name: str, limits: Mapping[str, Limits]) -> Limits | None:
    """The limits of ``name``: its own entry, else its kind's (``c_yaw`` for ``c_yaw[bogie2]``)."""
    return limits.get(name) or limits.get(kind_of(name))


def nominal_of(name: str, parameters: Mapping[str, Parameter], limits: Mapping[str, Limits]) -> float | None:
    """The nominal value (SI) of a parameter or group: ``limits.<name>.nominal``, the simulator's nominal of the
    name, or of its kind; None when none is known."""
    own = limits.get(name)
    if own is not None and own.nominal is not None:
        return float(own.nominal)
    p = parameters.get(name) or parameters.get(kind_of(name))
    if p is None:
        kind = limits.get(kind_of(name))
        return float(kind.nominal) if kind is not None and kind.nominal is not None else None
    return float(p.nominal)


def short_description(description: str) -> str:
    """The head of a parameter description: up to its first ``;`` or ``(`` (the rest is its source)."""
    return re.split(r"[;(]", description, maxsplit=1)[0].strip()



def _qualifiers(name: str) -> str:
    """``c_yaw[bogie1,left]`` -> ``bogie 1, left``; a kind -> ``""``."""
    if "[" not in name:
        return ""
    inner = name.split("[", 1)[1].rstrip("]")
    return ", ".join(re.sub(r"(?<=[A-Za-z])(?=\d)", " ", part.strip()) for part in inner.split(","))


def label_of(name: str, parameters: Mapping[str, Parameter], limits: Mapping[str, Limits]) -> str:
    """The element(s) in plain language: ``limits.<name>.label``, the simulator's description of the name, or
    the group's qualifiers before its kind's (``bogie 2: yaw damper rate per damper``)."""
    own = limits.get(name)
    if own is not None and own.label:
        return own.label
    if name in parameters and parameters[name].description:
        return short_description(parameters[name].description)
    kind = limits.get(kind_of(name))
    base = kind.label if kind is not None and kind.label else (
        short_description(parameters[kind_of(name)].description) if kind_of(name) in parameters
        and parameters[kind_of(name)].description else kind_of(name))
    where = _qualifiers(name)
    return f"{where}: {base}" if where else base


# -- rows from a result ----------------------------------------------------------------------------------
def _row(name: str, value: float, interval: Sequence[float], identifiable: bool, trust: str, reasons: Sequence[str],
         unit: str, parameters: Mapping[str, Parameter], limits: Mapping[str, Limits], source: str,
         w_ref: float | None = None, error: float | None = None, alternatives: Sequence[str] = (),
         caveat: str = SAMPLING) -> VerdictRow:
    nominal = nominal_of(name, parameters, limits)
    lim = limits_for(name, limits)
    warning, alarm = (lim.warning, lim.alarm) if lim is not None else (None, None)
    decision = lim.decision if lim is not None else "precautionary"
    change = interval_pc = None
    if nominal is not None:
        change = _percent(value, nominal)
        a, b = (_percent(v, nominal) for v in interval)
        interval_pc = (min(a, b), max(a, b))
    verdict, rule = judge(identifiable=identifiable, trust=trust, change=change, interval=interval_pc,
                          warning=warning, alarm=alarm, reasons=reasons, caveat=caveat, decision=decision)
    return VerdictRow(name=name, label=label_of(name, parameters, limits), unit=unit, nominal=nominal,
                      value=float(value), interval=(float(interval[0]), float(interval[1])), change_percent=change,
                      interval_percent=interval_pc, identifiable=bool(identifiable), trust=trust,
                      warning=warning, alarm=alarm, verdict=verdict, rule=rule, source=source, w_ref=w_ref,
                      error_percent=error, alternatives=list(alternatives),
                      borderline=rule.startswith(BORDERLINE))


def _group_name(item: Any) -> str:
    return str(item.get("group", item)) if isinstance(item, Mapping) else str(item)


def localisation_items(localisation: Any) -> list[Mapping[str, Any]]:
    """The rows of a localisation: a list of rows, or a mapping holding them under ``rows`` (None: none)."""
    if isinstance(localisation, Mapping):
        localisation = localisation.get("rows")
    return list(localisation or [])


def verdict_rows(result: Mapping[str, Any], parameters: Sequence[Parameter], limits: Mapping[str, Limits],
                 localisation: Any = None) -> list[VerdictRow]:
    """One :class:`VerdictRow` per identified parameter (``result.json``'s keys), then one per group of a
    localisation: rows with ``group``, ``value`` SI, ``interval``, and optionally ``evidence``,
    ``alternatives``, ``identifiable``, ``trustworthy``, ``reasons``.

    A parameter's identified value is the bias-corrected one where the model-error checks gave it
    (``w_corrected``, the centre of its interval), else w_opt.

    :param parameters: the simulator's parameters (nominal values, units, descriptions).
    :param localisation: the localisation's rows (or a mapping with them under ``rows``); default
        ``result["localisation"]`` when the result has one.
    """
    params = {p.name: p for p in parameters}
    trust = result.get("trustworthy") or {}
    w_ref = result.get("w_ref") or {}
    errors = result.get("errors_percent") or {}
    rows = []
    for n in result["parameters"]:
        t = trust_word(trust.get(n))
        reasons = (result.get("non_identifiable_reasons", {}).get(n, []) if not result["identifiable"][n]
                   else result.get("untrustworthy_reasons", {}).get(n, []) if t == "no" else [])
        value = (result.get("w_corrected") or result["w_opt"])[n]   # the interval's centre: bias-corrected if it was
        rows.append(_row(n, value, result["interval"][n], result["identifiable"][n], t, reasons,
                         result.get("units", {}).get(n, ""), params, limits, "identification", w_ref.get(n), errors.get(n)))
    for item in localisation_items(localisation if localisation is not None else result.get("localisation")):
        name = str(item["group"])
        kind = kind_of(name)
        unit = params[name].unit if name in params else params[kind].unit if kind in params else \
            result.get("units", {}).get(kind, "")
        t = trust_word(item.get("trustworthy"))
        row = _row(name, float(item["value"]), item["interval"], bool(item.get("identifiable", True)), t,
                   list(item.get("reasons", [])), unit, params, limits, "localisation", None, None,
                   [_group_name(a) for a in item.get("alternatives") or []],
                   # the interval holds the fit's model-form misfit too
                   MISFIT if item.get("interval_statistical") is not None else SAMPLING)
        if item.get("not_separated"):   # a cluster of elements the sensors only see together (suspid.elements)
            row = replace(row, label=f"{row.label} ({item['not_separated']})")
        rows.append(row)
    return rows


def verdict_block(rows: Sequence[VerdictRow], limits: Mapping[str, Limits]) -> dict[str, Any]:
    """``result.json``'s ``verdict``: the version, the limits as given, the rows and the count per state."""
    return {"version": VERSION,
            "limits": {n: lim.model_dump(mode="json") for n, lim in limits.items()},
            "counts": {s: sum(r.verdict == s for r in rows) for s in STATES},
            "rows": [r.to_dict() for r in rows]}


def rows_of(result: Mapping[str, Any]) -> list[VerdictRow]:
    """The verdict rows of a ``result.json`` (none for a result written before the verdict existed)."""
    block = result.get("verdict") or {}
    return [VerdictRow.from_dict(r) for r in block.get("rows", [])]


# -- presentation ---------------------------------------------------------------------------------------
_PREFIXES = ((1e9, "G"), (1e6, "M"), (1e3, "k"))


def format_value(value: float | None, unit: str) -> str:
    """A value with its unit, force units with an SI prefix: ``300 kN s/m``, ``1.2 MN/m``, ``0.15``."""
    if value is None or not math.isfinite(value):
        return "-"
    if unit.split(" ")[0].split("/")[0] in ("N", "Pa", "W"):
        for scale, prefix in _PREFIXES:
            if abs(value) >= scale:
                return f"{value / scale:.4g} {prefix}{unit}"
    return f"{value:.4g} {unit}".strip() if unit not in ("", "1") else f"{value:.4g}"


def _pc(v: float | None) -> str:
    return "-" if v is None else f"{v:+.1f} %"


def _levels_text(row: VerdictRow) -> str:
    parts = [f"{s} {' / '.join(f'{v:+g}' for v in lv if v is not None)}"
             for s, lv in (("warning", row.warning), ("alarm", row.alarm)) if lv is not None]
    return "; ".join(parts) + " %" if parts else "none"


def table(rows: Sequence[VerdictRow], *, with_reference: bool = False, with_rule: bool = False
          ) -> tuple[list[str], list[list[str]]]:
    """The verdict table's header and cells (strings with units), as the terminal, report.md and a notebook show it.

    :param with_reference: add ``w_ref`` and its error (numerical experiments, where the truth is known).
    :param with_rule: add the levels and the rule that gave the verdict.
    """
    header = ["parameter", "nominal", "identified", "change", "interval"]
    header += ["w_ref", "error (% of interval)"] if with_reference else []
    header += ["identifiable", "trustworthy", "verdict"] + (["limits", "rule"] if with_rule else [])
    cells = []
    for r in rows:
        iv = "-" if r.interval_percent is None else f"{r.interval_percent[0]:+.1f} to {r.interval_percent[1]:+.1f} %"
        row = [r.name, format_value(r.nominal, r.unit), format_value(r.value, r.unit), _pc(r.change_percent), iv]
        if with_reference:
            ref = format_value(r.w_ref, r.unit)
            if r.w_ref is not None and r.nominal:
                ref += f" ({_percent(r.w_ref, r.nominal):+.1f} %)"
            row += [ref, "-" if r.error_percent is None else f"{r.error_percent:.2f}"]
        row += ["yes" if r.identifiable else "no", r.trust, r.verdict + (" (borderline)" if r.borderline else "")]
        row += [_levels_text(r), r.rule] if with_rule else []
        cells.append(row)
    return header, cells


TERMINAL_COLUMNS = ("verdict", "parameter", "identified", "change [interval]", "nominal", "trust", "w_ref", "error")
"""The terminal's verdict table, verdict first (:func:`terminal_table`); ``nominal`` is the first to go where the
terminal is narrow, ``w_ref`` and ``error`` are only for numerical experiments (where the truth is known)."""


def _verdict_text(r: VerdictRow) -> str:
    return r.verdict + (" (borderline)" if r.borderline else "")


def _change_text(r: VerdictRow) -> str:
    """``-28.7 % [-31.2, -26.1]``: the change and its interval, % of nominal."""
    if r.change_percent is None:
        return "-"
    lo, hi = r.interval_percent
    return f"{r.change_percent:+.1f} % [{lo:+.1f}, {hi:+.1f}]"


def terminal_table(rows: Sequence[VerdictRow], *, with_reference: bool = False, with_nominal: bool = True
                   ) -> tuple[list[str], list[list[str]]]:
    """The verdict table as the terminal shows it (:data:`TERMINAL_COLUMNS`): the verdict first, the change and
    its interval in one column, identifiability folded into the trust (``not identifiable``), so that the
    quickstart's table fits 100 columns; report.md keeps the full :func:`table`.

    :param with_reference: add ``w_ref`` (as % of nominal) and the error (% of the admissible interval).
    :param with_nominal: add the nominal value.
    """
    header = [c for c in TERMINAL_COLUMNS if (with_nominal or c != "nominal")
              and (with_reference or c not in ("w_ref", "error"))]
    cells = []
    for r in rows:
        cell = {"verdict": _verdict_text(r), "parameter": r.name, "identified": format_value(r.value, r.unit),
                "change [interval]": _change_text(r), "nominal": format_value(r.nominal, r.unit),
                "trust": r.trust if r.identifiable else "not identifiable",
                "w_ref": "-" if r.w_ref is None or not r.nominal else f"{_percent(r.w_ref, r.nominal):+.1f} %",
                "error": "-" if r.error_percent is None else f"{r.error_percent:.2f}"}
        cells.append([cell[h] for h in header])
    return header, cells


def vertical_lines(rows: Sequence[VerdictRow]) -> list[str]:
    """The verdict table for a terminal too narrow for :func:`terminal_table`: a few short lines per row."""
    out = []
    for r in rows:
        out.append(f"{r.name}: {_verdict_text(r)}")
        out.append(f"  identified {format_value(r.value, r.unit)}, {_change_text(r)} of nominal "
                   f"{format_value(r.nominal, r.unit)}")
        trust = r.trust if r.identifiable else "not identifiable"
        ref = "" if r.w_ref is None else (
            f"; w_ref {format_value(r.w_ref, r.unit)}"
            + (f" ({_percent(r.w_ref, r.nominal):+.1f} %)" if r.nominal else "")
            + ("" if r.error_percent is None else f", error {r.error_percent:.2f} % of the interval"))
        out.append(f"  trust {trust}{ref}")
    return out


def summary_line(row: VerdictRow, markdown: bool = True) -> str:
    """``bogie 2: yaw dampers (`c_yaw[bogie2]`): -38 % (interval -44 to -32 %), alarm: replace`` (the name as
    code where ``markdown``)."""
    head = f"{row.label} (`{row.name}`)" if markdown else f"{row.label} ({row.name})"
    if row.change_percent is None:
        return f"{head}: identified {format_value(row.value, row.unit)}, no nominal value: not assessable"
    lo, hi = row.interval_percent
    text = f"{head}: {row.change_percent:+.0f} % (interval {lo:+.0f} to {hi:+.0f} %)"
    if row.verdict == "not assessable":
        text += f", not assessable: {row.rule}"
    else:
        text += f", {row.verdict}{' (borderline)' if row.borderline else ''}: {ACTIONS[row.verdict]}"
        if row.borderline:
            text += f" ({_across(lo, hi, row.warning, row.alarm)})"
        if row.trust != "yes":
            text += f" (trust under model error {row.trust})"
    if row.alternatives:
        text += f"; nearly as likely: {', '.join(row.alternatives)}"
    return text


def verdict_markdown(rows: Sequence[VerdictRow], markdown_table, *, with_reference: bool = False) -> str:
    """``report.md``'s first section: a plain-language line per element, then the verdict table with units.

    :param markdown_table: the report's table formatter (header, rows) -> str.
    """
    if not rows:
        return ""
    header, cells = table(rows, with_reference=with_reference, with_rule=True)
    lines = ["## Maintenance verdict", "", *[f"- {summary_line(r)}" for r in rows], "",
             markdown_table(header, cells), "",
             "Change and interval in % of the nominal value (the simulator's, or `limits.<name>.nominal`); "
             "levels from the config's `limits:` (warning and alarm, % of nominal). *not assessable*: not "
             "identifiable, not trustworthy under model error, no limits, or an interval reaching across two "
             "levels (or one, with `decision: strict`); *borderline*: the interval reaches across one level and "
             "the verdict is the more severe state (`decision: precautionary`, the default); the rule column "
             "says which.", ""]
    return "\n".join(lines)
