"""Secrets out of what the rig prints, serves and logs (issue 21 item 5).

A PostgreSQL store is named by a libpq connection string, which can carry its password in
every form libpq accepts (https://www.postgresql.org/docs/current/libpq-connect.html):

- URL userinfo: ``postgresql://rig2:SECRET@host/db``;
- the URL's query: ``postgresql://rig2@host/db?password=SECRET`` (also ``sslpassword``);
- keyword/value strings: ``host=db password=SECRET`` or ``password = 'se cret'`` (quoted,
  with ``\\'`` escapes);
- the environment: ``PGPASSWORD``, which is never shown or logged.

:func:`redact` gives a store URL as listings show it (``store`` of ``rig runs --json``, the
SPC page); :func:`redact_text` scrubs any text (error lines, log records, a crash log's
traceback); :func:`redact_argv` a command line (``--token VALUE`` too). The replacement is
``***``. Values of ``PGPASSWORD`` and ``RIG_WEB_TOKEN`` found in the environment are also
replaced wherever they occur verbatim.
"""

from __future__ import annotations

import os
import re
from collections.abc import Iterable, Mapping

__all__ = ["MASK", "SECRET_ENV", "redact", "redact_argv", "redact_environment", "redact_text",
           "without_paths"]

MASK = "***"
SECRET_ENV = ("PGPASSWORD", "RIG_WEB_TOKEN")
"""Environment variables whose value is a secret (never shown)."""
SECRET_OPTIONS = ("--token",)
"""Command-line options whose value is a secret."""
URL_VALUED_ENV = ("RIG_STORE",)
"""Environment variables that may hold a connection string."""

_URL = re.compile(r"\b[A-Za-z][A-Za-z0-9+.-]*://[^\s'\"<>`]+")
_KEYWORD = re.compile(
    r"(?i)(?<![A-Za-z0-9_])((?:ssl)?password|pgpassword)([\"']?\s*[=:]\s*)"
    r"('(?:[^'\\]|\\.)*'?|\"(?:[^\"\\]|\\.)*\"?|[^\s&#'\"]+)")
_QUERY_SECRET = re.compile(r"(?i)([?&;](?:ssl)?password=)([^&#]*)")
MIN_LITERAL = 4
"""An environment secret shorter than this is not searched for verbatim (it would mask
ordinary words)."""


def _redact_url(url: str) -> str:
    scheme, sep, rest = url.partition("://")
    if not sep:
        return url
    cut = min((i for i in (rest.find(c) for c in "/?#") if i >= 0), default=len(rest))
    netloc, tail = rest[:cut], rest[cut:]
    userinfo, at, hosts = netloc.rpartition("@")
    if at:
        user, colon, password = userinfo.partition(":")
        if colon and password:
            netloc = f"{user}:{MASK}@{hosts}"
    tail = _QUERY_SECRET.sub(lambda m: m.group(1) + MASK, tail)
    return f"{scheme}://{netloc}{tail}"


def _url_match(match: re.Match[str]) -> str:
    """A URL found in prose: its trailing punctuation (``...db?password=x:``) is not part
    of it."""
    url = match.group(0)
    core = url.rstrip(".,:;)]}!")
    return _redact_url(core) + url[len(core):]


def _keyword_match(match: re.Match[str]) -> str:
    """``password=VALUE`` as ``password=***`` (trailing punctuation of prose kept)."""
    value = match.group(3)
    core = value if value[:1] in "'\"" else value.rstrip(".,:;)]}!")
    return match.group(1) + match.group(2) + MASK + value[len(core):]


def redact(url: str) -> str:
    """The connection string (URL or keyword/value) without any password."""
    return redact_text(url)


def _env_secrets(environ: Mapping[str, str] | None = None) -> list[str]:
    env = os.environ if environ is None else environ
    values = [env.get(name, "") for name in SECRET_ENV]
    return sorted({v for v in values if len(v) >= MIN_LITERAL}, key=len, reverse=True)


def redact_text(text: str, environ: Mapping[str, str] | None = None) -> str:
    """``text`` with every password of a connection string replaced by ``***`` (see the
    module doc), and the environment's secrets wherever they appear verbatim."""
    if not text:
        return text
    out = _URL.sub(_url_match, text)
    out = _KEYWORD.sub(_keyword_match, out)
    for secret in _env_secrets(environ):
        out = out.replace(secret, MASK)
    return out


def redact_argv(argv: Iterable[str], environ: Mapping[str, str] | None = None) -> list[str]:
    """A command line with the value of every secret option (``--token X``,
    ``--token=X``) and every password in a connection string replaced by ``***``."""
    out: list[str] = []
    hide_next = False
    for arg in argv:
        if hide_next:
            out.append(MASK)
            hide_next = False
            continue
        name, eq, _value = arg.partition("=")
        if name in SECRET_OPTIONS:
            if eq:
                out.append(f"{name}={MASK}")
            else:
                out.append(arg)
                hide_next = True
            continue
        out.append(redact_text(arg, environ))
    return out


def redact_environment(environ: Mapping[str, str] | None = None,
                       prefixes: tuple[str, ...] = ("RIG_", "PG")) -> dict[str, str]:
    """The rig's and libpq's environment variables (names starting with ``prefixes``) with
    every secret value replaced: what a crash log may show of the environment."""
    env = os.environ if environ is None else environ
    shown = {}
    for name in sorted(env):
        if not name.startswith(prefixes):
            continue
        value = env[name]
        if name in SECRET_ENV or "PASSWORD" in name.upper() or "TOKEN" in name.upper():
            shown[name] = MASK
        else:
            shown[name] = redact_text(value, env)
    return shown


_ABS_PATH = re.compile(r"(?<![\w.:/~-])/(?:[^\s/'\"<>`]+/)+[^\s/'\"<>`]*")
_PATH_TAIL = ".,:;)]}!"


def _last_part(path: str) -> str:
    core = path.rstrip(_PATH_TAIL)
    name = core.rstrip("/").rsplit("/", 1)[-1]
    return (name or "a folder") + path[len(core):]


def without_paths(text: str, roots: Iterable[str] = ()) -> str:
    """``text`` without the server's folder paths (issue 33 item 13: an answer to a browser
    never shows where the server keeps its files): a path under one of ``roots`` (the
    store's folder, as given or resolved) and any absolute path become their last part
    (``/srv/rig-store/campaigns/c-1: no runs`` -> ``c-1: no runs``); a root itself becomes
    "the store". URLs are left as they are."""
    if not text:
        return text
    out = text
    for root in sorted({r.rstrip("/") for r in roots if r and r.rstrip("/")}, key=len,
                       reverse=True):
        pattern = re.compile(re.escape(root) + r"(/[^\s'\"<>`]*)?")
        out = pattern.sub(lambda m: _last_part(m.group(1)) if m.group(1) and
                          m.group(1).rstrip(_PATH_TAIL).strip("/") else
                          "the store" + (m.group(1) or ""), out)
    return _ABS_PATH.sub(lambda m: _last_part(m.group(0)), out)
