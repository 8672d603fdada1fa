"""The encoder driver against the simulator in a separate process (SLCAN on a TCP socket),
and the driver's side of the SLCAN link fuzzed with line noise."""

from __future__ import annotations

import json
import subprocess
import sys
import time
import uuid

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from drivers.encoder_canopen import CanBusConfig, CanopenEncoder, EncoderConfig, EncoderNetwork
from drivers.errors import DeviceDisconnected, DeviceProtocolError
from simulators.encoder_node import EncoderNode, SweepPlant
from simulators.slcan_adapter import SlcanAdapter
from tests.support.paths import REPO

pytestmark = pytest.mark.realtime  # measures on simulated devices in real time (tests/conftest.py)


@pytest.fixture
def simulator_process():
    proc = subprocess.Popen(
        [sys.executable, "-m", "simulators.encoder_node", "--node-id", "5",
         "--input-node-id", "6", "--heartbeat-ms", "100"],
        cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    try:
        line = proc.stdout.readline()
        assert line, f"simulator printed nothing; stderr: {proc.stderr.read()}"
        yield proc, json.loads(line)
    finally:
        if proc.poll() is None:
            proc.terminate()
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


def test_two_encoders_in_another_process_then_it_dies(simulator_process) -> None:
    proc, info = simulator_process
    assert info["encoder_slcan"].startswith("socket://127.0.0.1:")
    assert info["nodes"] == {"output": 5, "input": 6}
    network = EncoderNetwork(CanBusConfig(
        interface="slcan", channel=info["encoder_slcan"], sync_period_s=0.005,
        bus_options={"sleep_after_open": 0},
    ))
    out = CanopenEncoder(EncoderConfig(name="output encoder", node_id=5, heartbeat_ms=100,
                                       timeout_s=3.0, missed_periods=400), network)
    inp = CanopenEncoder(EncoderConfig(name="input encoder", node_id=6, heartbeat_ms=100,
                                       timeout_s=3.0, missed_periods=400), network)
    try:
        out.start()
        inp.start()
        deadline = time.monotonic() + 10
        while out.health().samples < 100 and time.monotonic() < deadline:
            time.sleep(0.01)
        samples = out.readings()
        assert len(samples) >= 100
        assert [s.seq for s in samples] == list(range(len(samples)))
        # the kinematic plant turns the input 81 times the output (SweepPlant, ratio 81);
        # both nodes answer the same SYNC, a few ms apart at most
        assert abs(inp.read().angle_deg - 81 * out.read().angle_deg) < 0.1
        assert max(abs(s.angle_deg) for s in samples) <= 0.05 + 1e-3  # the sweep amplitude
        proc.kill()
        proc.wait(timeout=10)
        t0 = time.monotonic()
        with pytest.raises(DeviceDisconnected):
            while time.monotonic() - t0 < 5:
                out.read()
                time.sleep(0.005)
        assert time.monotonic() - t0 < 1.0  # link loss or 2.5 heartbeat periods
    finally:
        out.close()
        inp.close()
        network.close()


def test_driver_survives_slcan_line_noise() -> None:
    channel = f"fuzz-{uuid.uuid4().hex[:8]}"
    face = EncoderNode(SweepPlant(), node_id=5, channel=channel)
    face.start()
    adapter = SlcanAdapter(channel=channel)
    adapter.start()
    bus = CanBusConfig(interface="slcan", channel=adapter.address, sync_period_s=0.005,
                       bus_options={"sleep_after_open": 0})
    enc = CanopenEncoder(EncoderConfig(node_id=5, heartbeat_ms=0, missed_periods=400, bus=bus))
    enc.start()

    @settings(max_examples=30, deadline=None, database=None)
    @given(noise=st.binary(min_size=1, max_size=80))
    def noise_gives_our_error_or_nothing(noise: bytes) -> None:
        seq = enc.read().seq
        assert adapter.backdoor.inject(noise + b"\r")
        deadline = time.monotonic() + 5
        while time.monotonic() < deadline:
            try:
                reading = enc.read()
            except DeviceProtocolError as exc:
                assert "node 5" in exc.device
                continue
            if reading.seq > seq + 2:
                return
            time.sleep(0.002)
        raise AssertionError(f"no samples after noise {noise!r}")

    try:
        noise_gives_our_error_or_nothing()
        assert enc.health().protocol_errors > 0
    finally:
        enc.close()
        adapter.stop()
        face.stop()
