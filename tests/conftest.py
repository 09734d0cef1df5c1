"""Fixtures several test files share. The helpers these files import by name (synthetic_room,
postgres_tools, ros2_tools ...) are found through pytest's ``pythonpath`` (pyproject.toml),
which puts tests/ and the checkout's root on sys.path however the tests are started."""

from __future__ import annotations

import pytest

import postgres_tools


@pytest.fixture(scope="module")
def postgres():
    """A throwaway PostgreSQL server of the test file's own (postgres_tools.server()): its
    tests may restart, pause or reconfigure it without touching another file's. A test that
    asks for it is skipped, with the reason, where no server can be had."""
    srv, why = postgres_tools.server()
    if srv is None:
        pytest.skip(f"no PostgreSQL server: {why}")
    yield srv
    srv.stop()


@pytest.fixture(params=("sqlite", "postgresql"))
def target(request, tmp_path):
    """A map store's target, once on each backend: a new SQLite file, and a new database on
    the file's PostgreSQL server (skipped where there is none, the SQLite run still runs)."""
    if request.param == "sqlite":
        return str(tmp_path / "maps.db")
    return request.getfixturevalue("postgres").new_database()
