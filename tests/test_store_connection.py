"""A PostgreSQL store over a connection that fails (mapstore.backends): what stops a
connection is said as what it is (no server, no such user, no such database, a wrong
password). Against a real PostgreSQL server."""

from __future__ import annotations

import time

import pytest

from mapstore import StoreError, open_store
from mapstore.backends import connect_problem

try:
    import postgres_tools
except ImportError:  # tests collected as a package
    from tests import postgres_tools


@pytest.fixture(scope="module")
def server():
    srv, why = postgres_tools.server()
    if srv is None:
        pytest.skip(f"no PostgreSQL server: {why}")
    yield srv
    srv.stop()


def one_line(e: pytest.ExceptionInfo) -> str:
    text = str(e.value)
    assert "\n" not in text and text.startswith("postgresql://"), text
    return text


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
