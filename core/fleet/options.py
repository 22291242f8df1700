"""The ``fleet:`` section of a config: where ``suspid run`` and ``suspid monitor`` record, and for which vehicle.

::

    fleet:
      database: fleet.sqlite        # a path (SQLite, relative to the config) or postgresql://user@host:port/db
      fleet: demo                   # the fleet's name
      trainset: TS01                # the trainset the recordings come from
      vehicle: car1                 # the vehicle of the trainset
      date: 2026-03-01              # date of a `suspid run` (default: today); monitor dates come from monitor:
      mileage_km: 120000            # mileage at that date (at the first date of a monitor)
      km_per_day: 1500              # mileage run per day, for the monitor's later dates
      indicators: true              # compute and store the EN 14363 / EN 12299 indicators of the recordings
      hunting_hz: null              # EN 14363 band centre; default: the spectral peak of the bogie frame
      acceptable:                   # acceptable domains of a `suspid run`'s verdicts (a monitor uses its own)
        c_yaw: [225.0e3, 375.0e3]   # SI units, null for an open side
      wait_s: 60                    # how long a finished run waits for a database server that cannot be reached

Without a ``fleet:`` section (or without ``database``) nothing is recorded.
``wait_s`` says how a run records, not what it computes: it is left out of
the resolved config, hence of the run id (changing it is the same run).
"""

from __future__ import annotations

import datetime as dt

from pydantic import Field

from suspid.options import Section

NAME = r"^[A-Za-z0-9_.\-]+$"
DEFAULT_WAIT_S = 60.0
"""How long a writer waits for a database server that cannot be reached, s: a server's restart fits in it,
a wrong address is not waited for much longer than the run's own last step."""


class FleetSection(Section):
    """The validated ``fleet:`` section (module docstring)."""

    database: str | None = Field(default=None, min_length=1, description="SQLite path or database URL")
    fleet: str = Field(default="fleet", pattern=NAME)
    trainset: str = Field(default="trainset", pattern=NAME)
    vehicle: str = Field(default="car1", pattern=NAME)
    date: dt.date | None = None
    mileage_km: float | None = Field(default=None, ge=0.0)
    km_per_day: float | None = Field(default=None, ge=0.0)
    indicators: bool = True
    hunting_hz: float | None = Field(default=None, gt=0.0)
    acceptable: dict[str, tuple[float | None, float | None]] = Field(default_factory=dict)
    wait_s: float = Field(default=DEFAULT_WAIT_S, ge=0.0, exclude=True,
                          description="how long to wait for a database server that cannot be reached, s")
