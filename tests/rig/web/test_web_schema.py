"""schemathesis against the page's OpenAPI spec: no 5xx, responses as documented.

The app has a real store and no rig, so commands answer 409; requests are sent as the
operator (token) so the command paths are exercised past the auth check. The live stream (an
endless response) is left out. schemathesis' "positive data acceptance" heuristic is not run:
a few rules cross fields and cannot be written in JSON schema (z_internal must exceed
z_external; a plan must stay small enough to preview), and the right answer to those is the
422 naming the field, which the other checks verify is documented.
"""

from __future__ import annotations

import pytest
import schemathesis
from hypothesis import HealthCheck, settings
from schemathesis.checks import positive_data_acceptance

from rig.store import Store
from rig.web import create_app
from rig.web.settings import resolve_settings

TOKEN = "schemathesis-operator"


@pytest.fixture(scope="module")
def app(tmp_path_factory: pytest.TempPathFactory):
    root = tmp_path_factory.mktemp("schema-store")
    return create_app(resolve_settings(store_root=root, token=TOKEN), store=Store(root))


schema = schemathesis.pytest.from_fixture("web_schema").exclude(path="/api/live")


@pytest.fixture(scope="module")
def web_schema(app):
    return schemathesis.openapi.from_asgi("/openapi.json", app)


@schema.parametrize()
@settings(max_examples=25, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much,
                                 HealthCheck.function_scoped_fixture])
def test_api_conforms_to_its_schema(case):
    case.call_and_validate(headers={"Authorization": f"Bearer {TOKEN}"},
                           excluded_checks=[positive_data_acceptance])


def test_spec_documents_every_route(app):
    spec = app.openapi()
    paths = set(spec["paths"])
    for path in ("/api/status", "/api/plan/preview", "/api/control/start", "/api/control/estop",
                 "/api/runs/{run_id}/run.zip", "/api/runs/{run_id}/loop.png",
                 "/api/campaigns/{campaign_id}/diagnosis.html", "/api/live"):
        assert path in paths, path
    start = spec["paths"]["/api/control/start"]["post"]
    assert {"200", "401", "403", "409", "422"} <= set(start["responses"])
    assert spec["components"]["securitySchemes"]["operator token"]["scheme"] == "bearer"
