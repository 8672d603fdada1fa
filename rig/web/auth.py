"""The operator token check: a FastAPI dependency for everything that moves the rig or
changes data. Viewers (no token) may only read and watch; the E-stop needs no token."""

from __future__ import annotations

import secrets
from typing import Annotated

from fastapi import Depends, HTTPException, Request, status
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer

bearer = HTTPBearer(auto_error=False, scheme_name="operator token",
                    description="The operator token printed by `rig serve` "
                                "(Authorization: Bearer <token>).")

NEEDS_TOKEN = ("this needs the operator token (Authorization: Bearer <token>); "
               "without it the page can only watch")


def require_operator(request: Request,
                     credentials: Annotated[HTTPAuthorizationCredentials | None,
                                            Depends(bearer)]) -> str:
    """Return the token if it is the operator's; else 401 (none given) or 403 (wrong one)."""
    expected: str = request.app.state.settings.token
    if credentials is None or not credentials.credentials:
        raise HTTPException(status.HTTP_401_UNAUTHORIZED, NEEDS_TOKEN,
                            headers={"WWW-Authenticate": "Bearer"})
    if not secrets.compare_digest(credentials.credentials.encode(), expected.encode()):
        raise HTTPException(status.HTTP_403_FORBIDDEN,
                            "wrong operator token: this page can only watch")
    return credentials.credentials


def is_operator(request: Request) -> bool:
    """Whether the request carries the operator token (no error either way)."""
    header = request.headers.get("authorization", "")
    scheme, _, value = header.partition(" ")
    if scheme.lower() != "bearer" or not value:
        return False
    return secrets.compare_digest(value.strip().encode(),
                                  request.app.state.settings.token.encode())


Operator = Annotated[str, Depends(require_operator)]
"""A path-operation parameter type: the request must carry the operator token."""
