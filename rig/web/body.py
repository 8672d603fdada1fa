"""The one parser of every request body of the control API (issue 21 item 9).

A body is JSON, whatever the ``Content-Type`` header says about it: media types are compared
case-insensitively (``application/JSON``, ``Application/Json; charset=UTF-8``); any other media
type (``text/plain``, a form) is refused with 415. A body without a ``Content-Type`` is parsed
too (so that NaN in it is a 422 naming the field), then refused with 415 if it was valid: a
browser sends such a body from any site without asking (FastAPI's strict content type). The
parse is strict:

- UTF-8 only (another ``charset`` is 415; bytes that are not UTF-8 are 400);
- no ``NaN``, ``Infinity`` or a number beyond the float range such as ``1e999`` (422 naming
  every such field, in FastAPI's validation-error shape);
- no key twice in one object (422; Python's ``json`` would silently keep the last).

What the app then reads is the body re-written from the parsed value with
``Content-Type: application/json``, so the route's own JSON decoding sees exactly what this
parser accepted (:class:`rig.web.guard.GuardMiddleware` does that before any route runs).
"""

from __future__ import annotations

import json
import math
from typing import Any

from rig.core.json_files import DuplicateKey, no_duplicate_keys

__all__ = ["BodyRejected", "canonical_json_body", "is_json_media_type", "media_type",
           "non_finite_paths"]

JSON_CHARSETS = ("utf-8", "utf8", "us-ascii", "ascii")
FINITE_MSG = ("a number must be finite (NaN, Infinity or a value beyond the float range is "
              "not a measurement)")


class BodyRejected(Exception):
    """A request body the control API does not take: ``status`` and ``detail`` of the
    answer (``detail`` a message, or a list of FastAPI-style validation errors)."""

    def __init__(self, status: int, detail: Any) -> None:
        super().__init__(detail)
        self.status = status
        self.detail = detail


def media_type(content_type: str | None) -> tuple[str, dict[str, str]]:
    """``Content-Type`` as (type/subtype in lower case, {parameter: value}); ("", {}) when
    the header is missing or empty. Media types are case-insensitive (RFC 9110 8.3.1)."""
    if not content_type:
        return "", {}
    main, *rest = content_type.split(";")
    params = {}
    for item in rest:
        key, sep, value = item.partition("=")
        if sep:
            params[key.strip().lower()] = value.strip().strip('"').lower()
    return main.strip().lower(), params


def is_json_media_type(kind: str) -> bool:
    """``application/json``, ``application/<anything>+json``, or no media type at all."""
    return kind in ("", "application/json") or (
        kind.startswith("application/") and kind.endswith("+json"))


def non_finite_paths(value: Any, path: tuple[str | int, ...] = ()) -> list[tuple]:
    """Paths of every NaN or infinite number in a parsed JSON value."""
    if isinstance(value, float) and not math.isfinite(value):
        return [path]
    if isinstance(value, dict):
        return [p for k, v in value.items() for p in non_finite_paths(v, (*path, k))]
    if isinstance(value, list):
        return [p for i, v in enumerate(value) for p in non_finite_paths(v, (*path, i))]
    return []


def _invalid(msg: str, loc: list[Any], error: str) -> BodyRejected:
    return BodyRejected(422, [{"loc": ["body", *loc], "msg": msg, "type": "json_invalid",
                               "input": None, "ctx": {"error": error}}])


def parse_json_body(body: bytes, content_type: str | None) -> Any:
    """The body's JSON value, parsed strictly (see the module doc); BodyRejected if not."""
    kind, params = media_type(content_type)
    if not is_json_media_type(kind):
        raise BodyRejected(415, f"a request body must be JSON (Content-Type: application/json),"
                                f" not {kind[:80]!r}")
    charset = params.get("charset", "utf-8")
    if charset not in JSON_CHARSETS:
        raise BodyRejected(415, f"a JSON body must be UTF-8, not charset {charset[:40]!r}")
    try:
        text = body.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise BodyRejected(400, f"the body is not UTF-8 (byte {exc.start})") from exc
    try:
        value = json.loads(text, parse_constant=float, object_pairs_hook=no_duplicate_keys)
    except DuplicateKey as exc:
        raise _invalid("JSON object with a key given twice", [], f"duplicate key {exc}") \
            from exc
    except json.JSONDecodeError as exc:
        raise _invalid("JSON decode error", [exc.pos], exc.msg) from exc
    except RecursionError as exc:
        raise _invalid("JSON nested too deep", [], "too deep") from exc
    paths = non_finite_paths(value)
    if paths:
        raise BodyRejected(422, [{"loc": ["body", *p], "msg": FINITE_MSG,
                                  "type": "finite_number", "input": None} for p in paths])
    return value


def canonical_json_body(body: bytes, content_type: str | None) -> bytes:
    """The body as the app will read it: re-written from its strictly parsed value."""
    value = parse_json_body(body, content_type)
    if not media_type(content_type)[0]:
        raise BodyRejected(415, "a JSON body needs the header Content-Type: application/json")
    return json.dumps(value, ensure_ascii=False, allow_nan=False,
                      separators=(",", ":")).encode("utf-8")
