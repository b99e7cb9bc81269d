"""Property-based fuzzing of the serial protocol parsers: whatever a tunnel controller answers (line
protocol over pyserial's loop://; Modbus RTU frames replayed to the real pymodbus client), whatever
line a point sensor sends, whatever frame reaches the simulated drive: a value or the driver's own
error naming the port, never another exception."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from flagtrack.daemon.bench.fuzz_targets import check_rtu_frame, check_sensor_line, check_tunnel_reply
from flagtrack.daemon.errors import DriverError
from flagtrack.drivers.serial import modbus_rtu as rtu
from flagtrack.drivers.tunnel.modbus import ModbusMap, ModbusTunnel
from tests.fakes.serial_replay import SerialReplay


@settings(max_examples=80, deadline=None)
@given(reply=st.one_of(st.binary(max_size=80), st.builds(lambda v: f"SPD {v}".encode(), st.text(max_size=30))))
def test_any_tunnel_reply_is_a_value_or_a_driver_error(reply: bytes) -> None:
    check_tunnel_reply(reply)


@settings(max_examples=150, deadline=None)
@given(
    line=st.one_of(
        st.text(max_size=80),
        st.builds(lambda t, v: f"D {t} {v}", st.text("0123456789", max_size=30), st.text(max_size=12)),
    )
)
def test_any_sensor_line_is_sorted_into_a_kind(line: str) -> None:
    check_sensor_line(line)


@settings(max_examples=150, deadline=None)
@given(
    frame=st.one_of(st.binary(max_size=300), st.builds(lambda b: rtu.with_crc(b), st.binary(min_size=2, max_size=40)))
)
def test_any_rtu_frame_is_a_request_or_a_value_error(frame: bytes) -> None:
    check_rtu_frame(frame)


READ_SPEED = rtu.with_crc(bytes([1, 0x04, 0x00, 0x10, 0x00, 0x01]))  # the drive map's readback request


@pytest.mark.filterwarnings("ignore::DeprecationWarning")
@settings(max_examples=25, deadline=None)
@given(
    answer=st.one_of(
        st.binary(min_size=1, max_size=12), st.builds(lambda b: rtu.with_crc(b), st.binary(min_size=1, max_size=8))
    )
)
def test_any_drive_answer_is_a_speed_or_a_driver_error(answer: bytes) -> None:
    """The real pymodbus client reading the readback register gets any answer (twice: it retries once)."""
    replay = SerialReplay([(READ_SPEED, answer), (READ_SPEED, answer)])
    tunnel = ModbusTunnel.open(replay.url, ModbusMap(), timeout_s=0.02)
    try:
        speed = tunnel.read_speed_mps()
        assert isinstance(speed, float) and speed >= 0
    except DriverError as exc:
        assert replay.url in str(exc)
    finally:
        tunnel.close()
