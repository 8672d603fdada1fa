"""Issue 21 item 9: every request body of the control API goes through one strict parser,
whatever its ``Content-Type`` says. Against the page's app served by uvicorn over HTTP on the
shared simulated rig (tests/support/simulated_page.py; ``rig serve`` runs the same app): every
numeric field of every request body in the OpenAPI schema, with NaN, Infinity or 1e999, under
``application/JSON``, ``Application/Json; charset=UTF-8``, ``text/plain`` and no content type,
is a 422 naming the field (415 for the non-JSON media type), never a 500. A valid body without a
content type is 415 (a browser sends one from any site without asking)."""

from __future__ import annotations

import json
from collections.abc import Iterator
from typing import Any

import pytest

from tests.support.http import request, wait_until_idle
from tests.support.serve import TOKEN

pytestmark = pytest.mark.realtime  # measures on simulated devices in real time (tests/conftest.py)

BAD_NUMBERS = ["NaN", "Infinity", "-Infinity", "1e999"]
MEDIA_TYPES = ["application/JSON", "Application/Json; charset=UTF-8", "text/plain", None]
MARK = "__number__"


@pytest.fixture(scope="module")
def page(simulated_rig, tmp_path_factory) -> Iterator[tuple[str, int]]:
    from rig.store import Store
    from rig.web import create_app
    from rig.web.controller import RigController
    from rig.web.live import LiveHub
    from rig.web.server import BackgroundServer
    from rig.web.settings import resolve_settings

    root = tmp_path_factory.mktemp("web-body") / "store"
    controller = RigController(Store(root), LiveHub(), simulated_rig.factory(), simulated=True)
    app = create_app(resolve_settings(store_root=root, token=TOKEN), controller)
    with BackgroundServer(app) as server:
        yield wait_until_idle(server.url)


def _resolve(schema: dict[str, Any], spec: dict[str, Any]) -> dict[str, Any]:
    while "$ref" in schema:
        schema = spec["components"]["schemas"][schema["$ref"].rsplit("/", 1)[-1]]
    return schema


def numeric_paths(schema: dict[str, Any], spec: dict[str, Any],
                  path: tuple[str | int, ...] = ()) -> list[tuple[str | int, ...]]:
    """Every number or integer field reachable in a request-body schema (arrays as index 0)."""
    schema = _resolve(schema, spec)
    out: list[tuple[str | int, ...]] = []
    for alt in schema.get("anyOf", []) + schema.get("oneOf", []) + schema.get("allOf", []):
        out += numeric_paths(alt, spec, path)
    kind = schema.get("type")
    if kind in ("number", "integer"):
        out.append(path)
    elif kind == "array" and "items" in schema:
        out += numeric_paths(schema["items"], spec, (*path, 0))
    for name, sub in (schema.get("properties") or {}).items():
        out += numeric_paths(sub, spec, (*path, name))
    return sorted(set(out), key=str)


def body_with(path: tuple[str | int, ...], literal: str) -> bytes:
    """A JSON body holding ``literal`` (written as is: NaN is not JSON) at ``path``."""
    value: Any = MARK
    for key in reversed(path):
        value = [value] if isinstance(key, int) else {key: value}
    return json.dumps(value).replace(f'"{MARK}"', literal).encode()


def cases(spec: dict[str, Any]) -> list[tuple[str, tuple[str | int, ...]]]:
    out = []
    for route, ops in spec["paths"].items():
        for method, op in ops.items():
            if method != "post" or "requestBody" not in op:
                continue
            schema = op["requestBody"]["content"]["application/json"]["schema"]
            out += [(route, p) for p in numeric_paths(schema, spec)]
    return out


def test_every_numeric_field_under_every_media_type_is_refused_never_500(page):
    host, port = page
    spec = request(host, port, "GET", "/openapi.json")[1]
    fields = cases(spec)
    routes = {route for route, _ in fields}
    assert {"/api/plan/preview", "/api/control/start", "/api/devices/input-lock"} <= routes
    assert len(fields) >= 20, fields  # plan, limits, axes, unit, input lock ...
    seen: dict[tuple[str | None, int], int] = {}
    for route, path in fields:
        for literal in BAD_NUMBERS:
            body = body_with(path, literal)
            for media in MEDIA_TYPES:
                headers = {"Authorization": f"Bearer {TOKEN}"}
                if media is not None:
                    headers["Content-Type"] = media
                code, answer = request(host, port, "POST", route, body, headers)
                where = f"{route} {path} = {literal} as {media}: HTTP {code} {answer}"
                seen[(media, code)] = seen.get((media, code), 0) + 1
                if media == "text/plain":
                    assert code == 415, where
                    assert "must be JSON" in answer["detail"], where
                    continue
                assert code == 422, where
                assert answer["detail"][0]["loc"] == ["body", *path], where
                assert answer["detail"][0]["type"] == "finite_number", where
    assert all(code != 500 for _, code in seen), seen
    status = request(host, port, "GET", "/api/status")[1]
    assert status["state"] == "idle"  # nothing was started by any of them


def test_the_parsed_body_is_what_the_route_reads(page):
    """A valid body under an upper-case media type or none works as with application/json;
    a key given twice, broken JSON and non-UTF-8 bytes are refused; the E-stop answers
    whatever its body is."""
    host, port = page
    unit = request(host, port, "GET", "/api/units")[1][0]["unit"]
    body = json.dumps({"unit": unit, "plan": {"rated_torque_Nm": 10.0}}).encode()
    answers = []
    for media in ["application/json", "APPLICATION/JSON", "Application/Json; Charset=utf-8",
                  "application/problem+json"]:
        code, answer = request(host, port, "POST", "/api/plan/preview", body,
                               {"Content-Type": media})
        assert code == 200, (media, answer)
        answers.append(answer["n_steps"])
    assert len(set(answers)) == 1
    code, answer = request(host, port, "POST", "/api/plan/preview", body)  # no media type
    assert code == 415 and "Content-Type: application/json" in answer["detail"], answer
    code, answer = request(host, port, "POST", "/api/plan/preview",
                           b'{"plan": {"rated_torque_Nm": 10}, "plan": {"rated_torque_Nm": 1}}',
                           {"Content-Type": "application/json"})
    assert code == 422 and "twice" in answer["detail"][0]["msg"], answer
    code, answer = request(host, port, "POST", "/api/plan/preview", b'{"plan": ',
                           {"Content-Type": "Application/JSON"})
    assert code == 422 and answer["detail"][0]["type"] == "json_invalid", answer
    code, answer = request(host, port, "POST", "/api/plan/preview", b'{"a": "\xff"}',
                           {"Content-Type": "application/json"})
    assert code == 400 and "not UTF-8" in answer["detail"], answer
    code, answer = request(host, port, "POST", "/api/plan/preview", body,
                           {"Content-Type": "application/json; charset=latin-1"})
    assert code == 415, answer
    code, answer = request(host, port, "POST", "/api/control/estop", b"NaN",
                           {"Content-Type": "text/plain"})
    assert code == 200, answer
    auth = {"Authorization": f"Bearer {TOKEN}", "Content-Type": "application/json"}
    assert request(host, port, "POST", "/api/devices/reset-faults", b"{}", auth)[0] == 200
