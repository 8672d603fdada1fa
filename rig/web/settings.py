"""Settings of the control page: where it listens, the operator token, the store.

Security rules (docs/web.md, "Security"):

- the page binds to 127.0.0.1 unless told otherwise;
- every request that moves the rig or changes data carries the operator token
  (``Authorization: Bearer <token>``); without it a browser can only watch;
- the token comes from ``--token``, else ``$RIG_WEB_TOKEN``, else the token file of the store
  (``<store>/web/operator-token``), else it is generated on the first start, written to that
  file (mode 0600) and printed;
- binding to any other address than the loopback needs a token given explicitly
  (``--token`` or ``$RIG_WEB_TOKEN``): a generated token that nobody chose is refused there.
"""

from __future__ import annotations

import ipaddress
import os
import secrets
from dataclasses import dataclass
from pathlib import Path

from rig.core.errors import RigError

TOKEN_ENV = "RIG_WEB_TOKEN"
TOKEN_FILE = Path("web") / "operator-token"
DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 8765
MIN_TOKEN_LENGTH = 8


class WebSettingsError(RigError):
    """The page cannot start with these settings (says why and what to do)."""


@dataclass(frozen=True)
class WebSettings:
    """Resolved settings: ``token_source`` is "option", "environment", "file" or "generated"."""

    host: str
    port: int
    store_root: Path
    token: str
    token_source: str
    check_host: bool = False
    """Refuse requests whose Host is not the loopback (rig serve on 127.0.0.1: DNS
    rebinding); off for in-process test clients."""

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port}/"


def is_loopback(host: str) -> bool:
    """True for 127.0.0.0/8, ::1 and "localhost"."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def _checked_token(token: str, where: str) -> str:
    token = token.strip()
    if len(token) < MIN_TOKEN_LENGTH or any(c.isspace() for c in token):
        raise WebSettingsError(f"{where}: the operator token must be at least "
                               f"{MIN_TOKEN_LENGTH} characters without spaces")
    return token


def resolve_token(store_root: Path, token: str | None) -> tuple[str, str]:
    """The operator token and where it came from (see the module docstring)."""
    if token:
        return _checked_token(token, "--token"), "option"
    env = os.environ.get(TOKEN_ENV, "")
    if env:
        return _checked_token(env, f"${TOKEN_ENV}"), "environment"
    path = store_root / TOKEN_FILE
    if path.is_file():
        return _checked_token(path.read_text(encoding="utf-8"), str(path)), "file"
    new = secrets.token_urlsafe(18)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(new + "\n")
    except OSError as exc:
        raise WebSettingsError(f"cannot write the operator token to {path}: "
                               f"{exc.strerror or exc}") from exc
    return new, "generated"


def resolve_settings(host: str = DEFAULT_HOST, port: int = DEFAULT_PORT, *,
                     store_root: Path, token: str | None = None,
                     check_host: bool = False) -> WebSettings:
    """Check the address and resolve the token; WebSettingsError says what to change."""
    if not 0 <= port <= 65535:
        raise WebSettingsError(f"--port must be 0..65535, got {port}")
    explicit = bool(token) or bool(os.environ.get(TOKEN_ENV))
    if not is_loopback(host) and not explicit:
        raise WebSettingsError(
            f"refusing to bind to {host}: the control page moves the rig, and on an address "
            f"other than the loopback (127.0.0.1) it needs an operator token you chose. "
            f"Give --token TOKEN (or set ${TOKEN_ENV}), or bind to 127.0.0.1.")
    value, source = resolve_token(store_root, token)
    return WebSettings(host=host, port=port, store_root=store_root, token=value,
                       token_source=source, check_host=check_host and is_loopback(host))
