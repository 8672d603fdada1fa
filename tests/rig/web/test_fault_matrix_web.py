"""Outside fault matrix rows on the control page (issue 12), against a real ``rig serve
--simulated`` over HTTP: a cross-site E-stop and a foreign Host are refused (row 5), the
E-stop answers under 60 parallel plan previews (row 6), non-finite numbers are a 422 naming
the field (row 9), and large bodies a 413 before anything parses them (row 10)."""

from __future__ import annotations

import http.client
import json
import threading
import time
from collections.abc import Iterator
from typing import Any

import pytest

from tests.support.http import request, wait_until_idle
from tests.support.serve import TOKEN, rig_serve

pytestmark = pytest.mark.realtime  # measures on simulated devices in real time (tests/conftest.py)

BIG_PLAN = {"plan": {"rated_torque_Nm": 10.0, "steps_per_quarter": 50, "cycles": 20},
            "kind": "campaign", "axes": {"positions_deg": [0.0, 45.0, 90.0, 135.0, 180.0,
                                                           225.0, 270.0, 315.0]}}


@pytest.fixture(scope="module")
def page(tmp_path_factory) -> Iterator[tuple[str, int]]:
    root = tmp_path_factory.mktemp("web-faults")
    with rig_serve(root / "store") as (url, _link):
        yield wait_until_idle(url)


def test_cross_site_estop_and_foreign_host_are_refused(page, record_property: Any):
    host, port = page
    code, answer = request(host, port, "POST", "/api/control/estop", b"",
                           {"Origin": "http://evil.example", "Sec-Fetch-Site": "cross-site",
                            "Content-Type": "text/plain"})
    record_property("fault", "no-CORS POST /api/control/estop from another site")
    record_property("phase", "idle")
    record_property("outcome", f"HTTP {code}")
    record_property("safe_s", "")
    record_property("samples_kept", "")
    record_property("message", str(answer))
    assert code == 403 and "another site" in answer["detail"]
    status = request(host, port, "GET", "/api/status")[1]
    assert status["faults"] == [] and status["state"] == "idle"  # nothing was pressed
    code, answer = request(host, port, "POST", "/api/control/estop", b"",
                           {"Origin": f"http://127.0.0.1:{port}"})  # the page itself
    assert code == 200
    code, answer = request(host, port, "GET", "/api/status",
                           headers={"Host": f"rebind.example:{port}"})
    assert code == 421 and "127.0.0.1" in answer["detail"]
    auth = {"Authorization": f"Bearer {TOKEN}", "Content-Type": "application/json"}
    assert request(host, port, "POST", "/api/devices/reset-faults", b"{}", auth)[0] == 200


@pytest.mark.parametrize("text", ["NaN", "Infinity", "-Infinity", "1e999"])
def test_non_finite_numbers_are_422_naming_the_field(page, text, record_property: Any):
    host, port = page
    body = ('{"unit": {"kind": "internal_involute", "z_internal": 45, "z_external": 40}, '
            '"plan": {"rated_torque_Nm": ' + text + '}}').encode()
    code, answer = request(host, port, "POST", "/api/plan/preview", body,
                           {"Content-Type": "application/json"})
    record_property("fault", f"{text} in a JSON request body")
    record_property("phase", "POST /api/plan/preview")
    record_property("outcome", f"HTTP {code}")
    record_property("safe_s", "")
    record_property("samples_kept", "")
    record_property("message", json.dumps(answer)[:200])
    assert code == 422, answer
    assert answer["detail"][0]["loc"] == ["body", "plan", "rated_torque_Nm"]
    auth = {"Authorization": f"Bearer {TOKEN}", "Content-Type": "application/json"}
    code, answer = request(host, port, "POST", "/api/devices/input-lock",
                           b'{"angle_deg": %s, "confirm": true}' % text.encode(), auth)
    assert code == 422 and answer["detail"][0]["loc"] == ["body", "angle_deg"]


def test_large_bodies_are_refused_before_parsing(page, record_property: Any):
    host, port = page
    big = b"[" + b"1," * 600_000 + b"1]"
    code, answer = request(host, port, "POST", "/api/plan/preview", big,
                           {"Content-Type": "application/json"})
    record_property("fault", f"a {len(big) // 1000} kB request body")
    record_property("phase", "POST /api/plan/preview")
    record_property("outcome", f"HTTP {code}")
    record_property("safe_s", "")
    record_property("samples_kept", "")
    record_property("message", str(answer)[:200])
    assert code == 413 and "at most" in answer["detail"]
    # a body that lies about its length is cut off as it streams in
    conn = http.client.HTTPConnection(host, port, timeout=60)
    conn.putrequest("POST", "/api/plan/preview")
    conn.putheader("Content-Type", "application/json")
    conn.putheader("Transfer-Encoding", "chunked")
    conn.endheaders()
    chunk = b"1," * 50_000
    try:
        for _ in range(10):
            conn.send(b"%x\r\n%s\r\n" % (len(chunk), chunk))
        conn.send(b"0\r\n\r\n")
        r = conn.getresponse()
        assert r.status == 413
    except (BrokenPipeError, ConnectionResetError):
        pass  # refused and closed while we were still sending: refused all the same
    finally:
        conn.close()


def test_estop_answers_under_sixty_parallel_previews(page, record_property: Any):
    host, port = page
    unit = request(host, port, "GET", "/api/units")[1][0]["unit"]
    body = json.dumps({**BIG_PLAN, "unit": unit}).encode()
    code, answer = request(host, port, "POST", "/api/plan/preview", body,
                           {"Content-Type": "application/json"})
    assert code == 200 and answer["n_steps"] > 50_000, answer
    codes: list[int] = []

    def hammer() -> None:
        codes.append(request(host, port, "POST", "/api/plan/preview", body,
                             {"Content-Type": "application/json"})[0])

    threads = [threading.Thread(target=hammer) for _ in range(60)]
    for t in threads:
        t.start()
    time.sleep(0.5)
    latencies = []
    for _ in range(3):
        t0 = time.monotonic()
        code, _ = request(host, port, "POST", "/api/control/estop")
        latencies.append(time.monotonic() - t0)
        assert code == 200
        time.sleep(0.2)
    for t in threads:
        t.join(120)
    record_property("fault", "60 parallel plan previews (no token), E-stop pressed 3x")
    record_property("phase", "idle")
    record_property("outcome", f"E-stop answered in {max(latencies) * 1000:.0f} ms at most; "
                               f"previews {sorted(set(codes))}")
    record_property("safe_s", f"{max(latencies):.3f}")
    record_property("samples_kept", "")
    record_property("message", "")
    assert max(latencies) < 1.0, latencies  # the 100 ms target is measured, not asserted
    assert set(codes) <= {200, 429, 503} and 429 in codes  # bounded and rate-limited
    auth = {"Authorization": f"Bearer {TOKEN}", "Content-Type": "application/json"}
    assert request(host, port, "POST", "/api/devices/reset-faults", b"{}", auth)[0] == 200


def test_guard_paths_unit():
    from rig.web.guard import non_finite_paths

    assert non_finite_paths({"a": [1.0, float("nan")], "b": {"c": float("inf")}}) == [
        ("a", 1), ("b", "c")]
    assert non_finite_paths([1, 2.5, {"x": "NaN"}]) == []  # a string is not a number
