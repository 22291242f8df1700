"""Fixtures of the monitoring-database tests: the same tests on SQLite and on a real PostgreSQL server.

The PostgreSQL server (``pg_server.PostgresServer``) starts once per session.
Where its binaries are missing the PostgreSQL cases are skipped, except in CI
(``CI`` set), where ``.ci/run`` installs them and a missing server fails.
"""

from __future__ import annotations

import itertools
import os

import pytest

from pg_server import PostgresServer

_counter = itertools.count()


@pytest.fixture(scope="session")
def pg_server():
    server = PostgresServer()
    if not server.available:
        if os.environ.get("CI"):
            pytest.fail("PostgreSQL's initdb is not installed (.ci/run installs the postgresql package)")
        pytest.skip("PostgreSQL's initdb is not installed (apt-get install postgresql)")
    server.start()
    yield server
    server.stop()


@pytest.fixture(params=["sqlite", "postgresql"])
def db_url(request, tmp_path):
    """A fresh, empty database URL on each backend."""
    if request.param == "sqlite":
        return f"sqlite:///{tmp_path / 'fleet.sqlite'}"
    return request.getfixturevalue("pg_server").fresh_database(f"t{os.getpid()}_{next(_counter)}")


@pytest.fixture(scope="session")
def demo_fleet(tmp_path_factory):
    """The demo fleet (``configs/fleet-demo.yaml``: 4 trainsets x 6 dates) monitored once per session into an
    SQLite database of its own (about two minutes on 2 cores): a :class:`suspid.fleet.demo.DemoResult`."""
    import shutil
    from pathlib import Path

    from suspid.fleet.demo import run_demo
    from suspid.infra.threads import single_blas_thread

    plan = tmp_path_factory.mktemp("demo") / "fleet-demo.yaml"
    shutil.copy(Path(__file__).resolve().parents[1] / "configs" / "fleet-demo.yaml", plan)
    with single_blas_thread():
        return run_demo(plan)
