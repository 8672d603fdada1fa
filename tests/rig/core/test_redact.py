"""Issue 21 item 5: the database password is never printed, served or logged.

Every form libpq accepts is redacted (URL userinfo, ``password=`` in the URL's query,
keyword/value strings with quoted values, ``PGPASSWORD``); against a real PostgreSQL server:
``rig runs`` (its errors and ``--json``'s ``store``), the token-free ``/spc`` and
``/api/spc``; the log file and the crash log are 0600 and hold no secret."""

from __future__ import annotations

import json
import os
import stat
import subprocess
import sys
from pathlib import Path

import pytest

from rig.core.redact import redact, redact_argv, redact_environment, redact_text

SECRET = "S3cr3t-pw"
TOKEN = "op-token-77aa"


@pytest.mark.parametrize(("text", "kept"), [
    (f"postgresql://rig2@db.lab:5432/rig?password={SECRET}",
     "postgresql://rig2@db.lab:5432/rig?password=***"),
    (f"postgresql://rig2:{SECRET}@db.lab:5432/rig", "postgresql://rig2:***@db.lab:5432/rig"),
    (f"postgres://rig2:{SECRET}@h1:5432,h2:5433/rig?sslmode=require&sslpassword={SECRET}#x",
     "postgres://rig2:***@h1:5432,h2:5433/rig?sslmode=require&sslpassword=***#x"),
    (f"postgresql://rig2:p@{SECRET}@db.lab/rig", "postgresql://rig2:***@db.lab/rig"),
    (f"postgresql://rig2@db.lab/rig?application_name=x&PASSWORD={SECRET}&sslmode=verify-full",
     "postgresql://rig2@db.lab/rig?application_name=x&PASSWORD=***&sslmode=verify-full"),
    (f"host=db.lab port=5432 user=rig2 password={SECRET} dbname=rig",
     "host=db.lab port=5432 user=rig2 password=*** dbname=rig"),
    (f"host=db.lab password = '{SECRET} with \\' quote' dbname=rig",
     "host=db.lab password = *** dbname=rig"),
    (f'dbname=rig password="{SECRET}"', "dbname=rig password=***"),
    (f"PGPASSWORD={SECRET} rig runs", "PGPASSWORD=*** rig runs"),
    (f"cannot open the store database postgresql://rig2@h/db?password={SECRET}: refused",
     "cannot open the store database postgresql://rig2@h/db?password=***: refused"),
    ('FATAL:  password authentication failed for user "rig2"',
     'FATAL:  password authentication failed for user "rig2"'),
    ("/srv/rig-store", "/srv/rig-store"),
])
def test_every_libpq_form_is_redacted(text, kept):
    assert redact(text) == kept
    assert SECRET not in redact_text(text)


def test_environment_secrets_and_the_token_option():
    env = {"PGPASSWORD": SECRET, "RIG_WEB_TOKEN": TOKEN, "HOME": "/root",
           "RIG_STORE": f"postgresql://rig2:{SECRET}@h/db", "PGHOST": "db.lab"}
    assert redact_text(f"connecting with {SECRET} and {TOKEN}", env) == \
        "connecting with *** and ***"
    assert redact_argv(["serve", "--token", TOKEN, f"--token={TOKEN}", "--store",
                        f"postgresql://u:{SECRET}@h/db"], env) == [
        "serve", "--token", "***", "--token=***", "--store", "postgresql://u:***@h/db"]
    assert redact_environment(env) == {"PGHOST": "db.lab", "PGPASSWORD": "***",
                                       "RIG_STORE": "postgresql://rig2:***@h/db",
                                       "RIG_WEB_TOKEN": "***"}


def _rig(*args: str, env: dict[str, str], cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", "from rig.cli import main; main()", *args],
                          cwd=cwd, env=env, capture_output=True, text=True, timeout=120)


def _env(tmp_path: Path, **extra: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items()
           if k not in ("RIG_STORE", "RIG_SAMPLES_DIR", "PGPASSWORD")}
    env.update(RIG_LOG_DIR=str(tmp_path / "logs"), **extra)
    return env


@pytest.fixture
def pg_store(pg_server, tmp_path):
    """A PostgreSQL store with one campaign, named by a URL with ``?password=``."""
    from rig.store import Store
    from rig.store.synthetic_runs import write_campaign

    url = f"{pg_server.create_schema()}&password={SECRET}"
    st = Store(url, samples=tmp_path / "samples")
    write_campaign(st, "PW-1", n_quarter=50)
    st.close()
    return url


def test_rig_runs_never_prints_the_password(pg_store, tmp_path):
    env = _env(tmp_path, RIG_SAMPLES_DIR=str(tmp_path / "samples"))
    out = _rig("runs", "--store", pg_store, "--json", "-", env=env, cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    doc = json.loads(out.stdout)
    assert len(doc["runs"]) == 2
    assert SECRET not in out.stdout + out.stderr and doc["store"].endswith("password=***")
    table = _rig("runs", "--store", pg_store, env=env, cwd=tmp_path)
    assert table.returncode == 0 and SECRET not in table.stdout + table.stderr
    # errors: no samples folder; a server that does not answer; a keyword string
    errors = [
        _rig("runs", "--store", pg_store, env=_env(tmp_path), cwd=tmp_path),
        _rig("runs", "--store", f"postgresql://rig2@127.0.0.1:9/rig?connect_timeout=2&"
             f"password={SECRET}", env=env, cwd=tmp_path),
        _rig("runs", "--store", f"host=127.0.0.1 password={SECRET}", env=env, cwd=tmp_path),
        _rig("runs", "--store", pg_store, "--limit", "0", env=env, cwd=tmp_path),
    ]
    for out in errors:
        assert out.returncode == 2, out.stderr
        assert SECRET not in out.stdout + out.stderr, out.stderr
    assert "password=***" in errors[0].stderr and "password=***" in errors[1].stderr
    for log in (tmp_path / "logs").iterdir():
        assert stat.S_IMODE(log.stat().st_mode) == 0o600, log
        assert SECRET not in log.read_text(), log


def test_spc_page_and_json_never_show_the_password(pg_store, tmp_path):
    from fastapi.testclient import TestClient

    from rig.store import Store
    from rig.web.app import create_app
    from rig.web.settings import resolve_settings

    st = Store(pg_store, samples=tmp_path / "samples")
    app = create_app(resolve_settings(store_root=st.root, token=TOKEN), store=st)
    with TestClient(app) as client:
        doc = client.get("/api/spc")
        page = client.get("/spc")
        bad = client.get("/api/runs/no-such-run/certificate.html")
    assert doc.status_code == 200 and page.status_code == 200
    assert doc.json()["store"].endswith("password=***")
    for text in (doc.text, page.text, bad.text):
        assert SECRET not in text
    assert "password=***" in page.text
    st.close()


CRASH = """
import sys
sys.argv = ["rig", "runs", "--store", URL, "--token", TOKEN]
from rig.cli import _write_crash_log
try:
    raise RuntimeError("could not open " + URL)
except RuntimeError:
    print(_write_crash_log())
"""

LOGGING = """
import logging
from rig.core.logs import configure_cli_logging
path = configure_cli_logging()
logging.getLogger("rig.store").warning("store database %s unreachable", URL)
logging.getLogger("rig.store").info("PGPASSWORD=%s set", PW)
print(path)
"""


def test_crash_log_and_log_file_are_private_and_hold_no_secret(tmp_path):
    url = f"postgresql://rig2@db.lab:5432/rig?password={SECRET}"
    env = _env(tmp_path, PGPASSWORD=SECRET + "-env", RIG_STORE=url, RIG_WEB_TOKEN=TOKEN)
    (tmp_path / "logs").mkdir()
    prelude = f"URL = {url!r}\nTOKEN = {TOKEN!r}\nPW = {SECRET + '-env'!r}\n"
    old = os.umask(0o022)  # the usual umask: a plain file would be 0644
    try:
        crash = subprocess.run([sys.executable, "-c", prelude + CRASH], env=env,
                               capture_output=True, text=True, timeout=60, cwd=tmp_path)
        assert crash.returncode == 0, crash.stderr
        crash_log = Path(crash.stdout.strip())
        text = crash_log.read_text()
        assert stat.S_IMODE(crash_log.stat().st_mode) == 0o600
        assert "rig runs --store postgresql://rig2@db.lab:5432/rig?password=*** --token ***" \
            in text
        assert "PGPASSWORD=***" in text and "RIG_WEB_TOKEN=***" in text
        assert "RuntimeError: could not open" in text
        assert SECRET not in text and TOKEN not in text
        logged = subprocess.run([sys.executable, "-c", prelude + LOGGING], env=env,
                                capture_output=True, text=True, timeout=60, cwd=tmp_path)
        assert logged.returncode == 0, logged.stderr
        daily = Path(logged.stdout.strip())
        assert stat.S_IMODE(daily.stat().st_mode) == 0o600
        text = daily.read_text()
        assert "unreachable" in text and "PGPASSWORD=*** set" in text
        assert SECRET not in text and SECRET not in logged.stderr
        assert "rig: warning: store database postgresql://rig2@db.lab:5432/rig?password=***" \
            in logged.stderr
        daily.chmod(0o644)  # a log file left readable by an older version is made private
        again = subprocess.run([sys.executable, "-c", prelude + LOGGING], env=env,
                               capture_output=True, text=True, timeout=60, cwd=tmp_path)
        assert again.returncode == 0 and stat.S_IMODE(daily.stat().st_mode) == 0o600
    finally:
        os.umask(old)
