"""A store's password is never printed, whatever form the target takes (a URL with its
scheme in any case or misspelt, the password in the query, an unencoded '@' in it, a libpq
key=value string), by ``open_store`` nor by the command line; a wrong password is said as
such; and the text a store keeps from people (mapstore.text) is one line of UTF-8 within a
limit. Against a real PostgreSQL server whose two roles log in with a password (SCRAM)."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import pytest

from mapstore import StoreError, open_store
from mapstore.text import NAME_LIMIT, NOTE_LIMIT, check_text

import postgres_tools

ROOT = Path(__file__).resolve().parents[1]
SECRET = "s3cr3t-XYZ"
AT_SECRET = "s3cr3t@XYZ"          # a password holding an '@'
PARTS = ("s3cr3t", "XYZ")         # neither half may show: a leak of part of it is a leak


def password_login(srv, role: str, password: str) -> str:
    """Make ``role`` log in from 127.0.0.1 with ``password`` only (SCRAM, a line put first in
    the server's pg_hba.conf, read again) and own a database of its own; its name."""
    import psycopg
    name = f"{role}_maps"
    with psycopg.connect(srv.url(), autocommit=True) as conn:
        conn.execute(f"CREATE ROLE {role} LOGIN PASSWORD '{password}'")
        conn.execute(f"CREATE DATABASE {name} OWNER {role}")
        hba = srv.folder / "data" / "pg_hba.conf"
        hba.write_text(f"host all {role} 127.0.0.1/32 scram-sha-256\n" + hba.read_text())
        conn.execute("SELECT pg_reload_conf()")
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline:      # the reload is asynchronous
        try:
            psycopg.connect(f"postgresql://{role}@127.0.0.1:{srv.port}/{name}",
                            connect_timeout=2).close()
        except psycopg.OperationalError as e:
            if "password" in str(e):
                return name
        time.sleep(0.1)
    raise AssertionError("the server did not ask for the password")


@pytest.fixture(scope="module")
def server(postgres):
    """This file's PostgreSQL server (conftest.py), its two roles logging in with a password,
    and their databases."""
    return postgres, (password_login(postgres, "mapper", SECRET),
                      password_login(postgres, "mapper2", AT_SECRET))


def forms(srv, dbs) -> dict[str, bool]:
    """Targets holding a secret, each with whether it connects."""
    port, free = srv.port, postgres_tools.free_port()
    db, db2 = dbs
    here = f"127.0.0.1:{port}"
    return {
        f"postgresql://mapper:{SECRET}@{here}/{db}": True,
        f"postgres://mapper:{SECRET}@{here}/{db}": True,
        f"POSTGRESQL://mapper:{SECRET}@{here}/{db}": True,
        f"Postgres://mapper:{SECRET}@{here}/{db}": True,
        f"postgresql://mapper@{here}/{db}?password={SECRET}": True,
        f"postgresql://mapper@{here}/{db}?sslmode=disable&password={SECRET}": True,
        f"postgresql://mapper2:{AT_SECRET}@{here}/{db2}": True,          # unencoded '@'
        f"postgresql://mapper2:s3cr3t%40XYZ@{here}/{db2}": True,
        f"  postgresql://mapper:{SECRET}@{here}/{db}  ": True,
        f"postgresql://mapper:not-{SECRET}@{here}/{db}": False,          # wrong password
        f"postgresql://mapper2:{SECRET}@{here}/{db2}?password={SECRET}": False,
        f"postgressql://mapper:{SECRET}@{here}/{db}": False,             # misspelt schemes
        f"postgre://mapper:{SECRET}@{here}/{db}": False,
        f"pg://mapper:{SECRET}@{here}/{db}": False,
        f"postgresql:/mapper:{SECRET}@{here}/{db}": False,
        f"postgresql:mapper:{SECRET}@{here}/{db}": False,
        f"host=127.0.0.1 port={port} password={SECRET} dbname={db}": False,
        f"password='{SECRET}' host=127.0.0.1 user=mapper": False,
        f"postgresql://mapper:s3cr3t/XYZ@{here}/{db}": False,            # unencoded '/'
        f"postgresql://u:{SECRET}@127.0.0.1:{free}/maps": False,         # unreachable
        f"postgresql://nobody:{SECRET}@{here}/postgres": False,          # unknown role
        f"postgresql://postgres:{SECRET}@{here}/nodb": False,            # no database
        f"postgresql://u:{SECRET}@[::1:{free}/maps": False,              # libpq echoes the URL
        f"postgresql://u:s3cr3t%zzXYZ@127.0.0.1:{free}/maps": False,     # ... a bad %-token
        f"postgresql://u:{SECRET}@127.0.0.1:port/maps": False,
        f"postgresql://u@127.0.0.1:{free}/maps?PASSWORD={SECRET}": False,
    }


def secret_free(text: str) -> bool:
    return not any(part in text for part in PARTS)


def test_no_form_of_target_prints_its_password(server):
    srv, dbs = server
    cases = forms(srv, dbs)
    assert len(cases) >= 12
    for target, connects in cases.items():
        try:
            with open_store(target, create=True) as store:
                assert connects, target
                assert secret_free(str(store.name)), store.name
                assert "***" in str(store.name) and store.db.kind == "postgresql"
                store.log()
        except StoreError as e:
            assert not connects, (target, str(e))
            assert secret_free(str(e)) and "\n" not in str(e), str(e)


def test_the_command_line_prints_no_password(server):
    srv, dbs = server
    cases = forms(srv, dbs)
    for db in dbs:      # the stores the connecting forms name, made
        role = "mapper" if db == dbs[0] else "mapper2"
        with open_store(f"postgresql://{role}@127.0.0.1:{srv.port}/{db}?password="
                        f"{SECRET if role == 'mapper' else 's3cr3t%40XYZ'}", create=True):
            pass
    runs = {target: subprocess.Popen([sys.executable, "-m", "mapupdate", "store", "log",
                                      "--store", target], cwd=ROOT, stdout=subprocess.PIPE,
                                     stderr=subprocess.PIPE, text=True)
            for target in cases}
    for target, p in runs.items():
        out, err = p.communicate(timeout=120)
        assert secret_free(out) and secret_free(err), (target, out, err)
        if cases[target]:
            assert p.returncode == 0 and "***" in out, (target, out, err)
        else:
            assert p.returncode == 2 and err.startswith("mapupdate store: error: "), (target, err)
            assert err.count("\n") == 1, err


def test_errors_say_which_problem(server):
    srv, (db, _) = server
    here = f"127.0.0.1:{srv.port}"
    said = {f"postgresql://mapper:not-{SECRET}@{here}/{db}":
            r"authentication failed for user \"mapper\": wrong password",
            f"postgresql://mapper@{here}/{db}": "asks for a password and the URL gives none",
            f"postgressql://mapper:{SECRET}@{here}/{db}": r"unknown scheme 'postgressql'",
            f"pg://u:{SECRET}@h/db": r"unknown scheme 'pg'",
            f"host=h password={SECRET} dbname=d": r"give a postgresql:// URL",
            f"postgresql:/u:{SECRET}@h/db": r"not a URL; give postgresql://"}
    for target, message in said.items():
        with pytest.raises(StoreError, match=message) as e:
            open_store(target)
        assert secret_free(str(e.value))


# --- the text a store keeps from people ----------------------------------------------------------
def test_check_text_refuses_what_is_not_one_line_of_utf8():
    assert check_text("note", None, NOTE_LIMIT) is None
    for fine in ("box gone, approved", "🤖 amr-07 🗺️", "été à l'entrepôt", "x" * NAME_LIMIT,
                 "Lagerhalle Süd – Regal 12"):
        assert check_text("note", fine, NOTE_LIMIT) == fine
    assert check_text("note", "déjà".encode(), NOTE_LIMIT) == "déjà"
    refused = {"amr-07\nv9 approved": "control character .U.000A",
               "tab\there": "U.0009", "red \x1b[31m": "U.001B", "nul\x00": "U.0000",
               "del\x7f": "U.007F", "line\u2028sep": "U.2028", "bidi\u202eevil": "U.202E",
               "\udcff": "not valid UTF-8", "caf\udce9": "not valid UTF-8",
               b"caf\xe9": "not valid UTF-8", "x" * (NAME_LIMIT + 1): "65 characters, more than 64"}
    for value, message in refused.items():
        with pytest.raises(StoreError, match=message) as e:
            check_text("robot name", value, NAME_LIMIT)
        assert str(e.value).startswith("robot name: ") and "\n" not in str(e.value)
    with pytest.raises(StoreError, match="2001 characters, more than 2000"):
        check_text("note", "a" * 2001, NOTE_LIMIT)
    assert check_text("note", "a" * 2000, NOTE_LIMIT) == "a" * 2000


def test_check_text_takes_what_argparse_makes_of_invalid_bytes():
    # argparse gives the bytes of an argument that are not UTF-8 as lone surrogates
    # (surrogateescape): b'amr-\xff' arrives as 'amr-\udcff'
    given = b"amr-\xff".decode("utf-8", "surrogateescape")
    with pytest.raises(StoreError, match="robot name: not valid UTF-8"):
        check_text("robot name", given, NAME_LIMIT)
