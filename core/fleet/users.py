"""Who may acknowledge alarms: users of the monitoring database with hashed passwords (``suspid fleet user``).

A user is a name and a password hash made by Werkzeug's
:func:`~werkzeug.security.generate_password_hash` (scrypt with a random salt,
the method and salt stored in the hash); the password itself is never stored
nor logged. :func:`authenticate` checks a name and a password with
:func:`~werkzeug.security.check_password_hash`, which compares in constant
time; an unknown name costs the same hash computation as a known one, so the
time of a refusal does not tell which names exist. A removed user is kept
(inactive) so that the acknowledgements they made still name them.
"""

from __future__ import annotations

import datetime as dt
import re
from dataclasses import dataclass

from sqlalchemy import select
from werkzeug.security import check_password_hash, generate_password_hash

from suspid.errors import ConfigError
from suspid.fleet.db import Database
from suspid.fleet.schema import User

NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.@\-]{0,99}$")
"""A user name: letters, digits, ``_ . @ -``, at most 100 characters, not starting with a sign."""
MIN_PASSWORD = 8
"""Shortest accepted password (characters)."""
_DUMMY_HASH = generate_password_hash("suspid: a password no user has")


@dataclass(frozen=True)
class UserInfo:
    """A user as listed: name, when added (UTC), whether they may still acknowledge."""

    name: str
    created_at: dt.datetime
    active: bool


def check_name(name: str) -> str:
    """``name`` if it is a usable user name, else :class:`ConfigError` saying what a name may hold."""
    if not NAME.match(name or ""):
        raise ConfigError(f"user name '{name}': use 1 to 100 letters, digits or _ . @ - (starting with a letter or "
                          f"digit)")
    return name


def add_user(db: Database, name: str, password: str) -> UserInfo:
    """Add a user who may acknowledge alarms (or re-activate a removed one with a new password).

    :raises ConfigError: a bad name, a password shorter than :data:`MIN_PASSWORD`, a name already in use.
    """
    check_name(name)
    if len(password) < MIN_PASSWORD:
        raise ConfigError(f"user {name}: the password has {len(password)} characters; give at least {MIN_PASSWORD}")
    hashed = generate_password_hash(password)
    now = dt.datetime.now(dt.timezone.utc).replace(tzinfo=None, microsecond=0)

    def work(session) -> UserInfo:  # noqa: ANN001 - a SQLAlchemy session
        user = session.scalar(select(User).where(User.name == name))
        if user is not None and user.active:
            raise ConfigError(f"user {name} already exists (suspid fleet user remove {name} first)")
        if user is None:
            user = User(name=name, password_hash=hashed, created_at=now, active=True)
            session.add(user)
        else:
            user.password_hash, user.active, user.created_at = hashed, True, now
        return UserInfo(user.name, user.created_at, True)

    return db.write(work)


def remove_user(db: Database, name: str) -> None:
    """Take away a user's right to acknowledge (the user stays, inactive, for the record).

    :raises ConfigError: no such active user.
    """
    def work(session) -> None:  # noqa: ANN001
        user = session.scalar(select(User).where(User.name == name))
        if user is None or not user.active:
            raise ConfigError(f"user {name}: no such user (suspid fleet user list)")
        user.active = False

    db.write(work)


def list_users(db: Database) -> list[UserInfo]:
    """Every user, active or removed, by name."""
    with db.read() as s:
        return [UserInfo(u.name, u.created_at, u.active) for u in s.scalars(select(User).order_by(User.name))]


def has_users(db: Database) -> bool:
    """Whether anyone may acknowledge."""
    with db.read() as s:
        return s.scalar(select(User.id).where(User.active.is_(True)).limit(1)) is not None


def authenticate(db: Database, name: str, password: str) -> str | None:
    """The user's name when ``name`` is an active user and ``password`` is theirs, else None."""
    with db.read() as s:
        user = s.scalar(select(User).where(User.name == name)) if NAME.match(name or "") else None
        stored = user.password_hash if user is not None and user.active else _DUMMY_HASH
    ok = check_password_hash(stored, password or "")
    return user.name if ok and user is not None and user.active else None
