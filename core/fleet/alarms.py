"""Alarms with hysteresis, acknowledgement and an audit trail.

An alarm follows one *source* of one vehicle: an element group (``c_yaw``,
``c_yaw[bogie1]``) or an indicator (``en14363-instability``). Each assessed
point of its history gives a *margin* m, a number that grows as the element
degrades (:func:`element_margin`, :func:`indicator_margin`), and the alarm
moves with hysteresis (EN 13848-5 names alert and intervention levels; a
condition-monitoring alarm must not chatter when a value hovers at a level):

- no alarm -> ``warning`` when m rises above ``warning_above``;
- -> ``alarm`` when m rises above ``alarm_above`` (an escalation);
- back to ``cleared`` only when m falls below ``clear_below``, a level lower
  than the warning level: a value between the two keeps the state it has.

Points that are not assessable (not identifiable, not trustworthy, no
acceptable domain or limit) leave the state unchanged: a value no check
supports neither raises nor clears an alarm.

The state is replayed from the whole history in date order whenever a run is
recorded (:func:`update_alarms`), so runs imported out of order or by writers
finishing together give the same alarms. A new episode (raised after a clear)
or an escalation resets the acknowledgement of the alarm's current episode.
Acknowledging (:func:`acknowledge`) is for a raised alarm only and for a user
of the database (:mod:`suspid.fleet.users`); each acknowledgement is a row of
its own (:class:`~suspid.fleet.schema.Acknowledgement`: who, when, the comment,
the episode and level), so a second one never replaces the first. Every change
is one :class:`AuditEntry`.
"""

from __future__ import annotations

import datetime as dt
import math
from dataclasses import dataclass
from typing import Sequence

from sqlalchemy import select
from sqlalchemy.orm import Session

from suspid.errors import SuspidError
from suspid.fleet.schema import Acknowledgement, Alarm, AuditEntry, Indicator, Run, User
from suspid.indicators.standard import COMFORT, COMFORT_ALARM, COMFORT_WARNING

SYSTEM_ACTOR = "suspid"
MAX_COMMENT = 2000
"""Longest acknowledgement comment (characters)."""


class AcknowledgementError(SuspidError):
    """An acknowledgement that cannot be made: no such alarm, a cleared alarm, an unknown user, a long comment."""


@dataclass(frozen=True)
class Hysteresis:
    """Margins at which an alarm is raised (warning, alarm) and cleared; ``clear_below < warning_above <= alarm_above``."""

    warning_above: float
    alarm_above: float
    clear_below: float


ELEMENT_LEVELS = Hysteresis(warning_above=-1.0, alarm_above=1.0, clear_below=-2.0)
"""Element margins are in half-widths h of the uncertainty interval past the acceptable domain's edge
(:func:`element_margin`): m > -1 is the monitor's ``warning`` (the interval overlaps the edge), m > 1 its
``out-of-domain`` (the whole interval outside); the alarm clears once the value is back inside by more than
two half-widths (one half-width deeper than where the warning was raised)."""
INDICATOR_LEVELS = Hysteresis(warning_above=0.8, alarm_above=1.0, clear_below=0.7)
"""Indicator margins are value / limit: warning above 80 % of the standard's limit, alarm above it, cleared
below 70 %."""
COMFORT_LEVELS = Hysteresis(warning_above=COMFORT_WARNING, alarm_above=COMFORT_ALARM,
                            clear_below=0.875 * COMFORT_WARNING)
"""EN 12299 mean comfort has no single limit: its margin is N_MV itself, warning from 2 (medium), alarm from 4
(uncomfortable), the verdict's levels; cleared below 1.75, the same 7/8 of the warning level as the instability's
70 % against 80 %."""


def element_margin(value: float, low: float, high: float, acceptable_low: float | None,
                   acceptable_high: float | None) -> float | None:
    """How far an identified value is past its acceptable domain, in half-widths of its interval [low, high].

    ``max((lo - value) / h, (value - hi) / h)`` with h = (high - low) / 2 (open sides ignored); None without
    a domain. Negative inside the domain.
    """
    if acceptable_low is None and acceptable_high is None:
        return None
    h = max((high - low) / 2.0, 1e-12 * max(abs(value), 1.0))
    sides = []
    if acceptable_low is not None:
        sides.append((acceptable_low - value) / h)
    if acceptable_high is not None:
        sides.append((value - acceptable_high) / h)
    return max(sides)


def indicator_margin(value: float, limit: float | None, name: str = "") -> float | None:
    """Indicator value / limit (EN 12299 comfort: N_MV itself, see :data:`COMFORT_LEVELS`); None without a limit."""
    if name == COMFORT:
        return float(value)
    if limit is None or not limit > 0:
        return None
    return value / limit


def indicator_levels(name: str) -> Hysteresis:
    """The hysteresis of an indicator's alarm."""
    return COMFORT_LEVELS if name == COMFORT else INDICATOR_LEVELS


@dataclass
class AlarmState:
    """The replayed state of one source: ``raised`` or ``cleared``, its level, the dates it changed."""

    state: str
    level: str
    raised_on: dt.date | None
    raised_run_id: int | None
    cleared_on: dt.date | None
    last_date: dt.date | None


def replay(points: Sequence[tuple[dt.date, int, float | None]], levels: Hysteresis) -> AlarmState | None:
    """The alarm state after ``points`` = (date, run id, margin or None) in date order; None if never raised."""
    state: AlarmState | None = None
    for date, run_id, m in points:
        if m is None or not math.isfinite(m):
            continue
        raised = state is not None and state.state == "raised"
        if not raised and m > levels.warning_above:
            state = AlarmState("raised", "alarm" if m > levels.alarm_above else "warning", date, run_id, None, date)
        elif raised and m > levels.alarm_above and state.level == "warning":
            state.level = "alarm"
        elif raised and m < levels.clear_below:
            state.state, state.cleared_on = "cleared", date
        if state is not None:
            state.last_date = date
    return state


def _audit(session: Session, action: str, alarm: Alarm | None, detail: str, actor: str = SYSTEM_ACTOR) -> None:
    now = dt.datetime.now(dt.timezone.utc).replace(tzinfo=None, microsecond=0)
    session.add(AuditEntry(at=now, actor=actor, action=action,
                           alarm_id=None if alarm is None else alarm.id, detail=detail))


def _apply(session: Session, key: tuple[str, str, str], source: str, new: AlarmState | None) -> None:
    fleet, trainset, vehicle = key
    alarm = session.scalar(select(Alarm).where(Alarm.fleet == fleet, Alarm.trainset == trainset,
                                               Alarm.vehicle == vehicle, Alarm.source == source))
    if new is None:
        if alarm is not None and alarm.state == "raised":   # history changed under it: nothing raises any more
            alarm.state, alarm.cleared_on = "cleared", alarm.last_date
            _audit(session, "cleared", alarm, f"{trainset}/{vehicle} {source}: no point raises it any more")
        return
    where = f"{trainset}/{vehicle} {source}"
    if alarm is None:
        alarm = Alarm(fleet=fleet, trainset=trainset, vehicle=vehicle, source=source, state=new.state,
                      level=new.level, raised_on=new.raised_on, raised_run_id=new.raised_run_id,
                      cleared_on=new.cleared_on, last_date=new.last_date)
        session.add(alarm)
        session.flush()
        _audit(session, "raised", alarm, f"{where}: {new.level} on {new.raised_on}")
        if new.state == "cleared":
            _audit(session, "cleared", alarm, f"{where}: cleared on {new.cleared_on}")
        return
    if alarm.raised_on != new.raised_on:   # another episode
        alarm.acked_by = alarm.acked_at = alarm.ack_comment = None
        _audit(session, "raised", alarm, f"{where}: {new.level} on {new.raised_on}")
    elif new.level == "alarm" and alarm.level == "warning":
        alarm.acked_by = alarm.acked_at = alarm.ack_comment = None
        _audit(session, "escalated", alarm, f"{where}: warning -> alarm by {new.last_date}")
    if new.state == "cleared" and (alarm.state != "cleared" or alarm.cleared_on != new.cleared_on):
        _audit(session, "cleared", alarm, f"{where}: cleared on {new.cleared_on}")
    alarm.state, alarm.level, alarm.raised_on, alarm.raised_run_id = new.state, new.level, new.raised_on, \
        new.raised_run_id
    alarm.cleared_on, alarm.last_date = new.cleared_on, new.last_date


def update_alarms(session: Session, fleet: str, trainset: str, vehicle: str) -> None:
    """Replay every source of one vehicle from its history and store the changes (with audit entries)."""
    runs = session.scalars(select(Run).where(Run.fleet == fleet, Run.trainset == trainset, Run.vehicle == vehicle)
                           .order_by(Run.date, Run.id)).all()
    by_source: dict[tuple[str, str], list[tuple[dt.date, int, float | None]]] = {}
    for run in runs:
        for v in run.values:
            m = None
            if v.identifiable and v.trust != "no" and v.verdict != "not assessable":
                m = element_margin(v.value, v.interval_low, v.interval_high, v.acceptable_low, v.acceptable_high)
            by_source.setdefault(("element", v.element_group), []).append((run.date, run.id, m))
        for ind in run.indicators:
            if ind.segment is None:   # the run's value, not each segment's
                m = None if ind.verdict == "not assessable" else indicator_margin(ind.value, ind.limit, ind.name)
                by_source.setdefault(("indicator", ind.name), []).append((run.date, run.id, m))
    for (what, source), points in sorted(by_source.items()):
        levels = ELEMENT_LEVELS if what == "element" else indicator_levels(source)
        _apply(session, (fleet, trainset, vehicle), source, replay(points, levels))


def acknowledge(session: Session, alarm_id: int, user: str, comment: str = "") -> Acknowledgement:
    """Acknowledge a raised alarm as ``user``: a new :class:`Acknowledgement` (who, when in UTC, the comment, the
    episode and level), the alarm's current acknowledgement, and an audit entry.

    ``user`` must be an active user of the database; the dashboard has checked the password before.

    :raises AcknowledgementError: no such alarm, a cleared alarm, an unknown or removed user, a comment longer
        than :data:`MAX_COMMENT`.
    """
    found = session.scalar(select(User).where(User.name == user))
    if found is None or not found.active:
        raise AcknowledgementError(f"acknowledgement: '{user}' is not a user who may acknowledge "
                                   f"(suspid fleet user add NAME)")
    if len(comment) > MAX_COMMENT:
        raise AcknowledgementError(f"acknowledgement: the comment has {len(comment)} characters; at most "
                                   f"{MAX_COMMENT}")
    alarm = session.get(Alarm, alarm_id)
    if alarm is None:
        raise AcknowledgementError(f"acknowledgement: no alarm with id {alarm_id}")
    where = f"{alarm.trainset}/{alarm.vehicle} {alarm.source}"
    if alarm.state != "raised":
        raise AcknowledgementError(f"acknowledgement: alarm {alarm_id} ({where}) was cleared on {alarm.cleared_on}: "
                                   f"only a raised alarm can be acknowledged")
    now = dt.datetime.now(dt.timezone.utc).replace(tzinfo=None, microsecond=0)
    ack = Acknowledgement(alarm_id=alarm.id, user_name=found.name, at=now, comment=comment,
                          raised_on=alarm.raised_on, level=alarm.level)
    session.add(ack)
    alarm.acked_by, alarm.ack_comment, alarm.acked_at = found.name, comment, now
    _audit(session, "acknowledged", alarm, f"{where} ({alarm.level}): {comment}", actor=found.name)
    session.flush()
    return ack
