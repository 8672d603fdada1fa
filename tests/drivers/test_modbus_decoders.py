"""Register map and decoders: layout checks, closed-form round trips and hypothesis fuzzing.

Fuzzing contract: any register words (including out-of-range integers and wrong lengths)
decode to a value or raise a :class:`drivers.errors.DeviceError`; never anything else.
"""

from __future__ import annotations

import math
import struct
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from drivers.errors import DeviceError, DeviceProtocolError
from drivers.loading_drive import decode_drive_block
from drivers.modbus.map import (
    LOADING_DRIVE_MAP,
    TORQUE_SENSOR_MAP,
    DriveFaultCode,
    DriveStatusBits,
    SensorStatus,
    decode_flags,
    decode_float32,
    decode_uint32,
    encode_float32,
    encode_uint32,
    table_span,
)
from drivers.modbus.torque_sensor import decode_torque_block
from simulators.modbus.devices import register_image

DEV = "test device"
words16 = st.integers(min_value=0, max_value=0xFFFF)
any_ints = st.integers(min_value=-(2**20), max_value=2**20)


@pytest.mark.parametrize("register_map", [TORQUE_SENSOR_MAP, LOADING_DRIVE_MAP])
def test_register_map_has_no_overlaps(register_map):
    for table in ("input", "holding"):
        taken: set[int] = set()
        for reg in register_map.values():
            if reg.table != table:
                continue
            span = set(range(reg.address, reg.end))
            assert not span & taken, f"{reg.name} overlaps in {table}"
            taken |= span
        first, count = table_span(register_map, table)
        assert first == 0 and count == len(taken)  # contiguous from 0: one request reads all


def test_docs_describe_every_register(repo_root: Path):
    text = (repo_root / "docs" / "modbus.md").read_text(encoding="utf-8")
    for register_map in (TORQUE_SENSOR_MAP, LOADING_DRIVE_MAP):
        for reg in register_map.values():
            assert f"`{reg.name}`" in text, f"docs/modbus.md does not describe {reg.name}"


def test_float32_words_are_ieee754_high_word_first():
    # 3.25 = 0x40500000: high word 0x4050 first (ABCD order, mbpoll -B)
    assert encode_float32(3.25) == [0x4050, 0x0000]
    assert decode_float32([0x4050, 0x0000], DEV, "x") == 3.25
    assert decode_float32([0xC120, 0x0000], DEV, "x") == -10.0
    assert decode_uint32([0x0001, 0x0002], DEV, "x") == 65538
    assert encode_uint32(65538) == [1, 2]


def test_nan_and_infinity_are_protocol_errors():
    for words in ([0x7FC0, 0], [0x7F80, 0], [0xFF80, 0]):
        with pytest.raises(DeviceProtocolError, match="finite float32"):
            decode_float32(words, DEV, "torque")


def test_undefined_status_bits_are_protocol_errors():
    with pytest.raises(DeviceProtocolError, match="got 0x0101") as info:
        decode_flags(0x0101, SensorStatus, DEV, "status")
    assert info.value.device == DEV


@given(st.floats(width=32, allow_nan=False, allow_infinity=False))
@settings(deadline=None)
def test_float32_round_trip(value):
    assert decode_float32(encode_float32(value), DEV, "x") == value


@given(st.lists(any_ints, max_size=4))
@settings(max_examples=300, deadline=None)
def test_scalar_decoders_only_raise_device_errors(words):
    for decode in (decode_float32, decode_uint32):
        try:
            decode(words, DEV, "x")
        except DeviceError as exc:
            assert exc.device == DEV


@given(st.lists(words16, min_size=7, max_size=7))
@settings(max_examples=500, deadline=None)
def test_torque_block_decoder_never_crashes(words):
    try:
        torque, status, counter, full_scale = decode_torque_block(words, DEV)
    except DeviceError as exc:
        assert DEV in str(exc)
        return
    assert math.isfinite(torque) and abs(torque) <= full_scale * (1 + 1e-6)
    assert SensorStatus.VALID in status and 0 <= counter < 2**32


@given(st.lists(any_ints, max_size=9))
@settings(max_examples=300, deadline=None)
def test_block_decoders_reject_wrong_shapes_with_device_errors(words):
    for decode, count in ((decode_torque_block, 7), (decode_drive_block, 6)):
        try:
            decode(words, DEV)
        except DeviceError as exc:
            assert exc.device == DEV
        else:
            assert len(words) == count


@given(st.lists(words16, min_size=6, max_size=6))
@settings(max_examples=500, deadline=None)
def test_drive_block_decoder_never_crashes(words):
    try:
        status = decode_drive_block(words, DEV)
    except DeviceError:
        return
    assert isinstance(status.fault_code, DriveFaultCode)
    assert status.faulted == (DriveStatusBits.FAULT & words[0] != 0)


def test_register_image_matches_the_map():
    """The simulator's image and the driver's decoder agree on a hand-computed block."""
    words = register_image(TORQUE_SENSOR_MAP, "input", {
        "torque": -1.5, "status": int(SensorStatus.VALID | SensorStatus.TARED),
        "sample_counter": 70000, "full_scale": 30.0})
    assert words[:2] == list(struct.unpack(">HH", struct.pack(">f", -1.5)))
    assert words[2] == 0x0005 and words[3:5] == [1, 70000 - 65536]
    torque, status, counter, full_scale = decode_torque_block(words, DEV)
    assert (torque, counter, full_scale) == (-1.5, 70000, 30.0)
    assert status == SensorStatus.VALID | SensorStatus.TARED
