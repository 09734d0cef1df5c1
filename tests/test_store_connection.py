"""A PostgreSQL store over a connection that fails (mapstore.backends): what stops a
connection is said as what it is (no server, no such user, no such database, a wrong
password); a store held open goes on after its server restarted; a connection lost inside a
write is ``ConnectionLost``; a server down longer than the reconnect window, or stopped while
a statement runs, is a one-line error within its bound, never a wait for ever. Against a real
PostgreSQL server the tests restart, stop (SIGSTOP) and resume; always resumed."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from gridmap import FREE, OCCUPIED, UNKNOWN, OccupancyGrid
from mapstore import StoreError, backends, open_store
from mapstore.backends import ConnectionLost, connect_problem

import postgres_tools


@pytest.fixture
def server(postgres):
    """This file's PostgreSQL server (conftest.py), which its tests restart and pause."""
    return postgres


def grid(seed: int) -> OccupancyGrid:
    rng = np.random.default_rng(seed)
    data = rng.choice(np.array([FREE, OCCUPIED, UNKNOWN], np.int8), size=(40, 50),
                      p=[.7, .1, .2])
    return OccupancyGrid(data, 0.05, (0.0, 0.0))


def one_line(e: pytest.ExceptionInfo) -> str:
    text = str(e.value)
    assert "\n" not in text and text.startswith("postgresql://"), text
    return text


def wait_until_down(srv, limit: float = 30) -> None:
    import psycopg
    deadline = time.monotonic() + limit
    while time.monotonic() < deadline:
        try:
            psycopg.connect(srv.url(), connect_timeout=1).close()
        except psycopg.OperationalError:
            return
        time.sleep(0.05)
    raise AssertionError("the server did not stop")


# --- what stops a connection -----------------------------------------------------------------
def test_no_user_no_database_and_no_server_are_said_apart(server):
    here = f"127.0.0.1:{server.port}"
    with pytest.raises(StoreError) as e:
        open_store(f"postgresql://nobody@{here}/postgres")
    assert 'no user (role) "nobody" on the server' in one_line(e)
    with pytest.raises(StoreError) as e:
        open_store(f"postgresql://postgres@{here}/nodb")
    assert 'no database "nodb" on the server; create it or check the URL' in one_line(e)
    t0 = time.monotonic()
    with pytest.raises(StoreError) as e:
        open_store(f"postgresql://postgres@127.0.0.1:{postgres_tools.free_port()}/maps")
    assert "cannot reach the database within 5 s (connection refused)" in one_line(e)
    assert time.monotonic() - t0 < 8


def test_psycopg_texts_are_sorted_by_what_they_say():
    # psycopg 3.3 with libpq 18's texts (a failed connection carries no SQLSTATE)
    at = 'connection failed: connection to server at "127.0.0.1", port 5432 failed: '
    texts = {
        at + 'FATAL:  password authentication failed for user "mapper"':
            ("auth", 'authentication failed for user "mapper": wrong password'),
        at + "fe_sendauth: no password supplied": ("auth", "the server asks for a password"),
        at + 'FATAL:  role "nobody" does not exist': ("role", 'no user (role) "nobody"'),
        at + 'FATAL:  database "nodb" does not exist': ("database", 'no database "nodb"'),
        at + 'FATAL:  no pg_hba.conf entry for host "10.0.0.7", user "u", database "d", no '
             "encryption": ("refused", "lets in no connection"),
        at + "FATAL:  the database system is starting up": ("starting", "is starting up"),
        at + "FATAL:  sorry, too many clients already": ("busy", "too many connections"),
        at + "Connection refused\n\tIs the server running on that host and accepting TCP/IP "
             "connections?": ("unreachable", "connection refused"),
        "connection timeout expired": ("unreachable", "no answer"),
        "failed to resolve host 'db.site': [Errno -2] Name or service not known":
            ("unreachable", "unknown host"),
        at + "No route to host": ("unreachable", "no route to host"),
        'invalid integer value "port" for connection option "port"\n':
            ("other", 'invalid integer value "port"'),
    }
    for text, (kind, say) in texts.items():
        found = connect_problem(text)
        assert found[0] == kind and say in found[1], (text, found)


def test_a_wrong_statement_timeout_setting_is_said(monkeypatch, server):
    monkeypatch.setenv("MAPSTORE_STATEMENT_TIMEOUT", "soon")
    with pytest.raises(StoreError, match="MAPSTORE_STATEMENT_TIMEOUT='soon': not a number"):
        open_store(server.new_database(), create=True)
    monkeypatch.setenv("MAPSTORE_STATEMENT_TIMEOUT", "3")
    with open_store(server.new_database(), create=True) as store:
        assert store.db.rows("SHOW statement_timeout") == [("3s",)]
        assert store.db.rows("SHOW lock_timeout") == [("1min",)]
    # the default leaves a writer waiting for the lock to the lock's own timeout
    assert backends.STATEMENT_TIMEOUT > backends.LOCK_TIMEOUT


# --- a server restarted, down, stopped ---------------------------------------------------------
def test_a_store_held_open_goes_on_after_its_server_restarted(server):
    with open_store(server.new_database(), create=True) as store:
        assert store.commit(grid(1), None, {}) == 1
        server.restart(1.0)
        assert [v.number for v in store.log()] == [1] and store.latest() == 1
        server.restart(1.0)             # this time a write is the first statement after
        assert store.commit(grid(2), 1, {}) == 2
        assert store.latest() == 2
        assert np.array_equal(store.get(1).data, grid(1).data)
        server.restart(0.5)
        assert np.array_equal(store.get(2).data, grid(2).data)


def test_a_connection_lost_inside_a_write_is_connection_lost(server):
    db = backends.connect(server.new_database())
    try:
        db.run("CREATE TABLE t (x BIGINT)")
        with pytest.raises(ConnectionLost) as e:
            with db.write():
                db.run("INSERT INTO t VALUES (1)")
                server.restart(0.2)
                db.run("INSERT INTO t VALUES (2)")
        assert "during a write, which was not committed" in one_line(e)
        assert not e.value.at_commit
        with db.write():                # made again at the write's start
            db.run("INSERT INTO t VALUES (3)")
        assert db.rows("SELECT x FROM t") == [(3,)]
    finally:
        db.close()


def test_a_commit_whose_connection_is_lost_inside_its_write_is_written_once(server):
    """The server restarts while a commit writes its rows (and, the second time, just after
    its transaction committed, before the answer is read): the store writes the commit again
    on a new connection, and its id keeps it from being written twice."""
    with open_store(server.new_database(), create=True) as store:
        store.commit(grid(1), None, {})
        for step, expect in (("version row", 2), ("committed", 3)):
            fired = []

            def hook(at, step=step, fired=fired):
                if at == step and not fired:
                    fired.append(at)
                    server.restart(0.3)
            store.hook = hook
            if step == "committed":
                # the answer lost after the commit: as a lost answer looks to the store
                def hook(at, fired=fired):
                    if at == "committed" and not fired:
                        fired.append(at)
                        raise ConnectionLost("lost", at_commit=True)
                store.hook = hook
            assert store.commit(grid(expect), expect - 1, {"k": expect}) == expect
            assert fired
            store.hook = None
        assert [v.number for v in store.log()] == [1, 2, 3]
        assert np.array_equal(store.get(3).data, grid(3).data)


def test_a_server_down_longer_than_the_window_is_said_within_it(monkeypatch, server):
    monkeypatch.setattr(backends, "RECONNECT_WINDOW", 3.0)
    store = open_store(server.new_database(), create=True)
    down = threading.Thread(target=server.restart, args=(7.0,))
    try:
        down.start()
        wait_until_down(server)
        t0 = time.monotonic()
        with pytest.raises(StoreError) as e:
            store.log()
        took = time.monotonic() - t0
        assert ("lost the connection to the server and could not connect again within 3 s "
                "(connection refused)") in one_line(e)
        assert 3.0 <= took < 3.0 + 3, took
    finally:
        down.join(60)
    assert store.log() == []            # the server back: the store goes on
    store.close()


def test_a_stopped_server_is_said_within_the_client_bound(monkeypatch, server):
    monkeypatch.setattr(backends, "STATEMENT_TIMEOUT", 2.0)
    monkeypatch.setattr(backends, "ANSWER_MARGIN", 0.5)
    url = server.new_database()
    store = open_store(url, create=True)
    store.commit(grid(1), None, {})
    try:
        # stopped while a statement runs: the server's own timeout cannot act
        threading.Timer(0.3, server.pause).start()
        t0 = time.monotonic()
        with pytest.raises(StoreError) as e:
            store.db.rows("SELECT pg_sleep(1)")
        took = time.monotonic() - t0
        assert one_line(e).endswith(": the server did not answer within 2.5 s")
        assert 2.5 <= took < 2.5 + 2, took
        server.resume()
        # stopped inside a write: the write is lost whole, the caller may write it again
        with pytest.raises(ConnectionLost) as e:
            with store.db.write():
                server.pause()
                t0 = time.monotonic()
                store.db.run("UPDATE mapstore_info SET value = '1' WHERE key = "
                             "'require_approval'")
        took = time.monotonic() - t0
        assert "the server did not answer within 2.5 s during a write" in one_line(e)
        assert took < 2.5 + 2, took
    finally:
        server.resume()
    with open_store(url) as again:      # a new open works, and so does the old store
        assert again.latest() == 1 and not again.require_approval
    assert store.latest() == 1 and not store.require_approval
    store.close()
