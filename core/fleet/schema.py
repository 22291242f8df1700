"""Tables of the monitoring database (SQLAlchemy 2 declarative models).

One row of :class:`Run` per identification (a ``suspid run``, or one date of a
``suspid monitor``), keyed by fleet, trainset, vehicle, date and mileage, with
the run's config hash (its run id) and the paths of its report and figures.
Each run has its identified element values (:class:`ElementValue`) and the
standard indicators computed from its recordings (:class:`Indicator`).
:class:`Alarm` holds the alarm state of one (trainset, vehicle, element group
or indicator) with its acknowledgement; :class:`AuditEntry` records every
change of an alarm (raised, cleared, acknowledged) with who and when;
:class:`Acknowledgement` keeps every acknowledgement (who, when, comment) and
:class:`User` who may acknowledge (a Werkzeug password hash).

Element groups are named as the identified parameters: the kind-level name
(``c_yaw``) or an element-group name (``c_yaw[bogie1]``); ``kind`` is the part
before ``[``. ``verdict`` is one of :data:`VERDICTS`, ``trust`` one of
:data:`TRUST`. The schema is created and upgraded by the Alembic migrations of
``suspid.fleet.migrations``, never by ``create_all``: a depot database keeps its
history across suspid versions.
"""

from __future__ import annotations

import datetime as dt

from sqlalchemy import (Boolean, Date, DateTime, Float, ForeignKey, Integer, String, Text, UniqueConstraint)
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column, relationship

VERDICTS = ("ok", "warning", "alarm", "not assessable")
"""Verdict of an element group or an indicator at one run."""
TRUST = ("yes", "no", "not assessed")
"""Whether a model-error check supports the value (``not assessed``: no check ran)."""
ALARM_STATES = ("raised", "cleared")


class Base(DeclarativeBase):
    pass


class Run(Base):
    """One identification (or one recording's indicators) at one date of one vehicle."""

    __tablename__ = "runs"
    __table_args__ = (UniqueConstraint("run_dir", "config_hash", name="uq_runs_dir_hash"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    fleet: Mapped[str] = mapped_column(String(100), index=True)
    trainset: Mapped[str] = mapped_column(String(100), index=True)
    vehicle: Mapped[str] = mapped_column(String(100))
    date: Mapped[dt.date] = mapped_column(Date, index=True)
    mileage_km: Mapped[float | None] = mapped_column(Float, nullable=True)
    kind: Mapped[str] = mapped_column(String(20))            # run | monitor-date | recording
    name: Mapped[str] = mapped_column(String(200))
    config_hash: Mapped[str] = mapped_column(String(64))
    run_dir: Mapped[str] = mapped_column(String(1000))
    report_path: Mapped[str | None] = mapped_column(String(1000), nullable=True)
    figure1_path: Mapped[str | None] = mapped_column(String(1000), nullable=True)
    figure2_path: Mapped[str | None] = mapped_column(String(1000), nullable=True)
    recorded_at: Mapped[dt.datetime] = mapped_column(DateTime)

    values: Mapped[list["ElementValue"]] = relationship(back_populates="run", cascade="all, delete-orphan")
    indicators: Mapped[list["Indicator"]] = relationship(back_populates="run", cascade="all, delete-orphan")


class ElementValue(Base):
    """An identified parameter (element group) of a run: value, interval (SI units), verdict and trust."""

    __tablename__ = "element_values"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    run_id: Mapped[int] = mapped_column(ForeignKey("runs.id", ondelete="CASCADE"), index=True)
    element_group: Mapped[str] = mapped_column(String(200), index=True)
    kind: Mapped[str] = mapped_column(String(100))
    unit: Mapped[str] = mapped_column(String(40), default="")
    value: Mapped[float] = mapped_column(Float)
    interval_low: Mapped[float] = mapped_column(Float)
    interval_high: Mapped[float] = mapped_column(Float)
    acceptable_low: Mapped[float | None] = mapped_column(Float, nullable=True)
    acceptable_high: Mapped[float | None] = mapped_column(Float, nullable=True)
    identifiable: Mapped[bool] = mapped_column(Boolean)
    trust: Mapped[str] = mapped_column(String(20))
    verdict: Mapped[str] = mapped_column(String(20))
    w_ref: Mapped[float | None] = mapped_column(Float, nullable=True)
    nominal: Mapped[float | None] = mapped_column(Float, nullable=True)          # SI, None when unknown
    label: Mapped[str | None] = mapped_column(String(300), nullable=True)        # the element in plain words
    reason: Mapped[str | None] = mapped_column(Text, nullable=True)              # why "not assessable"
    trust_reason: Mapped[str | None] = mapped_column(Text, nullable=True)        # why trust is "not assessed"

    run: Mapped[Run] = relationship(back_populates="values")


class Indicator(Base):
    """A standard indicator of a run's recordings, per segment (``segment`` set) or per run (``segment`` null)."""

    __tablename__ = "indicators"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    run_id: Mapped[int] = mapped_column(ForeignKey("runs.id", ondelete="CASCADE"), index=True)
    name: Mapped[str] = mapped_column(String(60))            # en14363-instability | en12299-comfort
    segment: Mapped[str | None] = mapped_column(String(200), nullable=True)
    channel: Mapped[str] = mapped_column(String(200), default="")
    value: Mapped[float] = mapped_column(Float)
    limit: Mapped[float | None] = mapped_column(Float, nullable=True)
    unit: Mapped[str] = mapped_column(String(40), default="")
    verdict: Mapped[str] = mapped_column(String(20))
    detail: Mapped[str] = mapped_column(Text, default="")

    run: Mapped[Run] = relationship(back_populates="indicators")


class Alarm(Base):
    """The alarm of one element group (or indicator) of one vehicle: its state, level and acknowledgement."""

    __tablename__ = "alarms"
    __table_args__ = (UniqueConstraint("fleet", "trainset", "vehicle", "source", name="uq_alarms_key"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    fleet: Mapped[str] = mapped_column(String(100))
    trainset: Mapped[str] = mapped_column(String(100), index=True)
    vehicle: Mapped[str] = mapped_column(String(100))
    source: Mapped[str] = mapped_column(String(200))         # an element group or an indicator name
    state: Mapped[str] = mapped_column(String(20))            # raised | cleared
    level: Mapped[str] = mapped_column(String(20))            # warning | alarm (the highest since raised)
    raised_on: Mapped[dt.date | None] = mapped_column(Date, nullable=True)
    raised_run_id: Mapped[int | None] = mapped_column(Integer, nullable=True)
    cleared_on: Mapped[dt.date | None] = mapped_column(Date, nullable=True)
    last_date: Mapped[dt.date | None] = mapped_column(Date, nullable=True)
    acked_by: Mapped[str | None] = mapped_column(String(100), nullable=True)
    acked_at: Mapped[dt.datetime | None] = mapped_column(DateTime, nullable=True)
    ack_comment: Mapped[str | None] = mapped_column(Text, nullable=True)


class Acknowledgement(Base):
    """One acknowledgement of an alarm: who (a user of :class:`User`), when (UTC), the comment, and the episode
    (``raised_on``) and level it acknowledged. Acknowledgements are only ever added."""

    __tablename__ = "acknowledgements"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    alarm_id: Mapped[int] = mapped_column(ForeignKey("alarms.id"), index=True)
    user_name: Mapped[str] = mapped_column(String(100))
    at: Mapped[dt.datetime] = mapped_column(DateTime)
    comment: Mapped[str] = mapped_column(Text, default="")
    raised_on: Mapped[dt.date | None] = mapped_column(Date, nullable=True)
    level: Mapped[str] = mapped_column(String(20))


class User(Base):
    """Someone who may acknowledge alarms on the dashboard: a name and a Werkzeug password hash (never the
    password). ``active`` False: removed, kept so that the acknowledgements they made still name them."""

    __tablename__ = "users"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    name: Mapped[str] = mapped_column(String(100), unique=True)
    password_hash: Mapped[str] = mapped_column(String(300))
    created_at: Mapped[dt.datetime] = mapped_column(DateTime)
    active: Mapped[bool] = mapped_column(Boolean, default=True)


class AuditEntry(Base):
    """One change of an alarm: raised, escalated, cleared, acknowledged (who, when, what)."""

    __tablename__ = "audit"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    at: Mapped[dt.datetime] = mapped_column(DateTime)
    actor: Mapped[str] = mapped_column(String(100))
    action: Mapped[str] = mapped_column(String(40))
    alarm_id: Mapped[int | None] = mapped_column(ForeignKey("alarms.id"), nullable=True)
    detail: Mapped[str] = mapped_column(Text, default="")
