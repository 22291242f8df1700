"""Fleet condition monitoring: the monitoring database, trends with a forecast, alarms (``suspid fleet``).

:mod:`suspid.fleet.options` (the config's ``fleet:`` section) needs nothing
beyond suspid's own dependencies; the rest needs the ``fleet`` extra
(SQLAlchemy, Alembic, psycopg, Flask): :mod:`~suspid.fleet.db` opens the database,
:mod:`~suspid.fleet.record` writes runs into it, :mod:`~suspid.fleet.trends`
fits the degradation trends and :mod:`~suspid.fleet.alarms` keeps the alarms.
"""
