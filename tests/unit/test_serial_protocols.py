"""The serial drivers byte for byte, pymeasure style: request/response pairs replayed over pyserial's
``loop://`` (tests/fakes/serial_replay.py), every pair used, nothing else written.

The drivers are the real classes, given their port the way they take it: the ASCII ones a
:class:`SerialAdapter` on a replay port (its ``port_obj`` seam), the Modbus ones a port *name*
(``replay://N``) that pymodbus opens through pyserial's URL handlers. Modbus frames and their CRCs
come from the project's RTU framing (drivers/tunnel/modbus_rtu.py), which pymodbus's own frames must
then match. The simulated tunnel and sensor (tests/integration) check behaviour over time; these
check the bytes, including the refusals, silences and garbage the simulators do not produce.
"""

from __future__ import annotations

import math
import struct
import time

import numpy as np
import pytest
import serial

from flagtrack.daemon.errors import DriverError
from flagtrack.drivers.sensor.ascii import AsciiSensor, AsciiSensorProtocol
from flagtrack.drivers.sensor.base import SensorReading
from flagtrack.drivers.sensor.modbus import ModbusSensor, ModbusSensorMap
from flagtrack.drivers.sensor.poll import PollParams
from flagtrack.drivers.serial import modbus_rtu as rtu
from flagtrack.drivers.serial.adapter import SerialAdapter
from flagtrack.drivers.tunnel.ascii import AsciiProtocol, AsciiTunnel
from flagtrack.drivers.tunnel.modbus import ModbusMap, ModbusTunnel
from flagtrack.drivers.tunnel.safe import SafeTunnel, SafetyParams
from tests.fakes.serial_replay import ReplayError, SerialReplay, expected_protocol

pytest.importorskip("pymodbus")

TIMEOUT_S = 0.1  # a reply that does not come: each such exchange waits this long


# -- the replay helper itself ---------------------------------------------------------------------


def test_each_request_gets_its_response_and_a_silent_pair_gets_none() -> None:
    with expected_protocol([(b"A?\n", b"A 1\n"), (b"B?\n", None), (b"C?\n", b"C 3\n")]) as replay:
        port = replay.open_port(TIMEOUT_S)
        port.write(b"A?\n")
        assert port.read_until(b"\n") == b"A 1\n"
        port.write(b"B")  # a request may come in pieces
        port.write(b"?\nC?\n")  # and two in one write
        assert port.read_until(b"\n") == b"C 3\n"
        assert port.read(1) == b""  # B? had no answer
    assert replay.used == 3


def test_a_wrong_byte_fails_at_once_naming_the_pair_and_both_byte_strings() -> None:
    """The driver's wrong set-point (5.00 where the script says 4.00) fails the test at that write:
    the error names the pair and both byte strings, and the driver does not turn it into its own."""
    with pytest.raises(ReplayError, match=r"pair 1: the driver wrote b'SET 5\.00\\n', expected b'SET 4\.00\\n'"):
        with expected_protocol([(b"GET?\n", b"SPD 0.00\n"), (b"SET 4.00\n", b"OK\n")]) as replay:
            tunnel = ascii_tunnel(replay)
            assert tunnel.read_speed_mps() == 0.0
            tunnel.write_setpoint_mps(5.0)


def test_a_mismatch_the_driver_swallows_still_fails_the_block() -> None:
    with pytest.raises(ReplayError, match=r"pair 0: the driver wrote b'PONG\\n', expected b'PING\\n'"):
        with expected_protocol([(b"PING\n", b"PONG\n")]) as replay:
            try:
                replay.open_port().write(b"PONG\n")
            except AssertionError:
                pass  # a driver catching everything


def test_unused_pairs_and_half_written_requests_fail_the_block() -> None:
    with pytest.raises(ReplayError, match=r"pair 1 of 2 not used: the driver never wrote b'FLT\?\\n'"):
        with expected_protocol([(b"GET?\n", b"SPD 1.00\n"), (b"FLT?\n", b"FLT NONE\n")]) as replay:
            assert ascii_tunnel(replay).read_speed_mps() == 1.0
    with pytest.raises(ReplayError, match=r"pair 0: the driver wrote only b'GE' of b'GET\?\\n'"):
        with expected_protocol([(b"GET?\n", b"SPD 1.00\n")]) as replay:
            replay.open_port().write(b"GE")


def test_writes_beyond_the_script_fail() -> None:
    with pytest.raises(ReplayError, match=r"after all 1 pairs, the driver wrote b'PING\\n'"):
        with expected_protocol([(b"PING\n", b"PONG\n")]) as replay:
            tunnel = ascii_tunnel(replay)
            tunnel.keep_alive()
            tunnel.keep_alive()


def test_replay_urls_open_through_pyserial_with_the_callers_settings() -> None:
    with expected_protocol([(b"\x01\x02", b"\x03")]) as replay:
        port = serial.serial_for_url(replay.url, baudrate=115200, parity="E", timeout=0.05)
        assert (port.baudrate, port.parity, port.timeout) == (115200, "E", 0.05)
        port.write(b"\x01\x02")
        assert port.read(1) == b"\x03"
        port.close()
    with pytest.raises(serial.SerialException, match="no open replay"):
        serial.serial_for_url(replay.url)  # closed with its block


# -- the ASCII tunnel driver (drivers/tunnel/ascii.py, docs/tunnel.md) ----------------------------


def ascii_tunnel(replay: SerialReplay, protocol: AsciiProtocol | None = None) -> AsciiTunnel:
    protocol = protocol or AsciiProtocol()
    adapter = SerialAdapter(
        replay.url, timeout_s=TIMEOUT_S, eol=protocol.eol.encode("ascii"), port_obj=replay.open_port(TIMEOUT_S)
    )
    return AsciiTunnel(adapter, protocol)


def test_ascii_set_read_stop_keep_alive_and_faults() -> None:
    with expected_protocol(
        [
            (b"SET 5.00\n", b"OK\n"),
            (b"GET?\n", b"SPD 4.98\n"),
            (b"PING\n", b"PONG\n"),
            (b"FLT?\n", b"FLT NONE\n"),
            (b"FLT?\n", b"FLT WATCHDOG\n"),
            (b"STOP\n", b"OK\n"),
        ]
    ) as replay:
        tunnel = ascii_tunnel(replay)
        tunnel.write_setpoint_mps(5.0)
        assert tunnel.read_speed_mps() == 4.98
        tunnel.keep_alive()
        assert tunnel.read_fault() is None
        assert tunnel.read_fault() == "WATCHDOG"
        tunnel.stop()
        tunnel.close()


@pytest.mark.parametrize(
    ("response", "words"),
    [
        (
            b"ERR bad set-point '50.00' (0..12 m/s)\n",
            "controller refused 'SET 50.00': bad set-point '50.00' (0..12 m/s)",
        ),
        (b"PONG\n", "unexpected reply 'PONG' to 'SET 50.00' (expected /OK/)"),
        (None, "no reply within 0.1 s"),
        (b"O", "no reply within 0.1 s (got b'O')"),  # the line's end never comes
        (b"\xcf\x8e\xce\x9a\n", "reply is not ASCII: b'\\xcf\\x8e\\xce\\x9a'"),
    ],
)
def test_ascii_refusals_garbage_and_silence_are_driver_errors_naming_the_port(
    response: bytes | None, words: str
) -> None:
    with expected_protocol([(b"SET 50.00\n", response)]) as replay, pytest.raises(DriverError) as info:
        ascii_tunnel(replay).write_setpoint_mps(50.0)
    assert words in str(info.value) and info.value.device == replay.url


def test_ascii_speed_that_is_no_number_is_a_driver_error() -> None:
    protocol = AsciiProtocol(query_reply=r"SPD (?P<value>\S+)")  # a looser pattern lets "fast" through
    with expected_protocol([(b"GET?\n", b"SPD fast\n")]) as replay:
        with pytest.raises(DriverError, match="speed 'fast' is not a number"):
            ascii_tunnel(replay, protocol).read_speed_mps()


def test_ascii_stale_reply_is_dropped_before_the_next_command() -> None:
    """A reply that came after its request timed out is not taken for the next command's reply
    (the adapter drops unread input before each command)."""
    with expected_protocol([(b"GET?\n", None), (b"FLT?\n", b"FLT NONE\n")]) as replay:
        tunnel = ascii_tunnel(replay)
        with pytest.raises(DriverError, match="no reply"):
            tunnel.read_speed_mps()
        replay.device_sends(b"SPD 4.98\n")  # ... which comes late
        assert tunnel.read_fault() is None


def test_ascii_ramp_up_and_down_is_one_exchange_per_command() -> None:
    """A controller ramping a set-point up, read back until there, then stopped: the link sends
    exactly one line per call and reads exactly one reply."""
    with expected_protocol(
        [
            (b"GET?\n", b"SPD 0.00\n"),
            (b"SET 2.00\n", b"OK\n"),
            (b"SET 4.00\n", b"OK\n"),
            (b"GET?\n", b"SPD 3.10\n"),
            (b"GET?\n", b"SPD 3.97\n"),
            (b"PING\n", b"PONG\n"),
            (b"SET 2.00\n", b"OK\n"),
            (b"STOP\n", b"OK\n"),
            (b"GET?\n", b"SPD 0.41\n"),
            (b"FLT?\n", b"FLT NONE\n"),
        ]
    ) as replay:
        tunnel = ascii_tunnel(replay)
        assert tunnel.read_speed_mps() == 0.0
        for speed in (2.0, 4.0):
            tunnel.write_setpoint_mps(speed)
        assert [tunnel.read_speed_mps() for _ in range(2)] == [3.1, 3.97]
        tunnel.keep_alive()
        tunnel.write_setpoint_mps(2.0)
        tunnel.stop()
        assert tunnel.read_speed_mps() == 0.41 and tunnel.read_fault() is None


def test_ascii_controller_in_percent_with_cr_echo_and_no_set_reply() -> None:
    """A controller configured in YAML: set-point in percent of 15 m/s, CR line ends, an RS-485
    adapter echoing every command, a set command it does not answer, no ping (the keep-alive is a
    speed query) and no fault query."""
    protocol = AsciiProtocol(
        eol="\r",
        units_per_mps=100 / 15,
        set_command="S{value:05.1f}",
        set_reply=None,
        query_command="R",
        query_reply=r"R=(?P<value>\d+\.\d)%",
        stop_command="S000.0",
        stop_reply=None,
        ping_command=None,
        fault_command=None,
        echo=True,
    )
    with expected_protocol(
        [
            (b"S033.3\r", b"S033.3\r"),
            (b"R\r", b"R\rR=32.8%\r"),
            (b"R\r", b"R\rR=33.3%\r"),
            (b"S000.0\r", b"S000.0\r"),
        ]
    ) as replay:
        tunnel = ascii_tunnel(replay, protocol)
        tunnel.write_setpoint_mps(5.0)
        assert tunnel.read_speed_mps() == pytest.approx(32.8 * 0.15)
        tunnel.keep_alive()
        assert tunnel.read_fault() is None  # nothing sent
        tunnel.stop()
    with expected_protocol([(b"R\r", b"X\rR=32.8%\r")]) as replay:
        with pytest.raises(DriverError, match=r"expected the echo of 'R', got 'X'"):
            ascii_tunnel(replay, protocol).read_speed_mps()


def test_a_safe_tunnel_session_on_the_ascii_driver() -> None:
    """``with SafeTunnel(link)``: read the speed and fault at start, set, wait for the readback, then
    ramp to zero, stop and wait for zero, in exactly these lines. (The ramp is so steep here that
    each change is one set-point: its timing is tested on the simulated tunnel.)"""
    params = SafetyParams(max_ramp_mps2=1e9, tolerance_mps=0.1, poll_period_s=0.001, keepalive_s=1800, watchdog_s=3600)
    with (
        expected_protocol(
            [
                (b"GET?\n", b"SPD 0.00\n"),
                (b"FLT?\n", b"FLT NONE\n"),
                (b"SET 3.00\n", b"OK\n"),
                (b"GET?\n", b"SPD 2.40\n"),
                (b"GET?\n", b"SPD 2.95\n"),
                (b"SET 0.00\n", b"OK\n"),
                (b"STOP\n", b"OK\n"),
                (b"GET?\n", b"SPD 0.05\n"),
            ]
        ) as replay,
        SafeTunnel(ascii_tunnel(replay), params) as tunnel,
    ):
        tunnel.set_speed_mps(3.0)
        assert tunnel.setpoint_mps == 3.0


# -- the Modbus RTU tunnel driver (drivers/tunnel/modbus.py; frames of modbus_rtu.py) -------------

# the register map of deploy/tunnel-modbus.yaml: reference in holding register 1 (0.01 Hz), control word in 0,
# output frequency in input register 16, fault code in input register 17
DRIVE = ModbusMap(fault_codes={1: "communication loss", 2: "overcurrent"}, mps_per_hz=0.2, max_hz=60.0)


def request(device_id: int, function: int, address: int, value: int) -> bytes:
    """A read (``value`` = count) or single-write request frame, CRC included."""
    return rtu.with_crc(bytes([device_id, function]) + struct.pack(">HH", address, value))


def write_register(address: int, value: int, device_id: int = 1) -> tuple[bytes, bytes]:
    """The request and its echo, the standard's reply to a single write."""
    frame = request(device_id, rtu.WRITE_REGISTER, address, value)
    assert rtu.write_response(rtu.parse_request(frame)) == frame
    return frame, frame


def read_input(address: int, values: list[int] | None, device_id: int = 1) -> tuple[bytes, bytes | None]:
    """Read ``len(values)`` input registers at ``address``, answered with ``values`` (None: silence)."""
    count = 1 if values is None else len(values)
    asked = request(device_id, rtu.READ_INPUT, address, count)
    if values is None:
        return asked, None
    return asked, rtu.read_response(rtu.Request(device_id, rtu.READ_INPUT, address, count), values)


def modbus_tunnel(replay: SerialReplay, modbus_map: ModbusMap = DRIVE) -> ModbusTunnel:
    return ModbusTunnel.open(replay.url, modbus_map, baudrate=19200, parity="E", timeout_s=TIMEOUT_S)


def test_the_framing_agrees_with_the_standards_example() -> None:
    """The Modbus specification's example: read holding registers 108-110 of device 17."""
    assert request(0x11, rtu.READ_HOLDING, 0x006B, 3) == bytes.fromhex("11 03 00 6B 00 03 76 87")


def test_modbus_set_read_stop_and_faults() -> None:
    """5 m/s is 25 Hz, 2500 counts of 0.01 Hz in holding register 1, then run (control word 1 in
    register 0); the readback is input register 16, the fault code input register 17."""
    with expected_protocol(
        [
            write_register(1, 2500),
            write_register(0, 1),
            read_input(16, [2490]),
            read_input(17, [0]),
            read_input(17, [2]),
            read_input(17, [9]),
            write_register(1, 0),
            write_register(0, 0),
        ]
    ) as replay:
        tunnel = modbus_tunnel(replay)
        tunnel.write_setpoint_mps(5.0)
        assert tunnel.read_speed_mps() == pytest.approx(4.98)
        assert tunnel.read_fault() is None
        assert tunnel.read_fault() == "overcurrent"
        assert tunnel.read_fault() == "fault code 9"
        tunnel.stop()
        tunnel.close()


def test_modbus_run_coil_and_holding_readback() -> None:
    coil_map = ModbusMap(
        control="coil",
        control_address=5,
        readback_register=3,
        readback_kind="holding",
        fault_register=None,
        mps_per_hz=0.2,
    )
    run = request(1, rtu.WRITE_COIL, 5, 0xFF00)
    stop = request(1, rtu.WRITE_COIL, 5, 0x0000)
    readback = request(1, rtu.READ_HOLDING, 3, 1)
    with expected_protocol(
        [
            write_register(1, 1500),
            (run, run),
            (readback, rtu.read_response(rtu.Request(1, rtu.READ_HOLDING, 3), [1499])),
            write_register(1, 0),
            (stop, stop),
        ]
    ) as replay:
        tunnel = modbus_tunnel(replay, coil_map)
        tunnel.write_setpoint_mps(3.0)
        tunnel.keep_alive()  # a readback
        assert tunnel.read_fault() is None  # no fault register: nothing sent
        tunnel.stop()


def test_modbus_exception_reply_is_a_driver_error_naming_port_and_code() -> None:
    asked, _ = read_input(16, [0])
    with expected_protocol([(asked, rtu.exception_response(1, rtu.READ_INPUT, rtu.ILLEGAL_ADDRESS))]) as replay:
        with pytest.raises(DriverError, match="read input register 16: drive 1 answered exception 2") as info:
            modbus_tunnel(replay).read_speed_mps()
    assert info.value.device == replay.url


def corrupt(frame: bytes) -> bytes:
    return frame[:-1] + bytes([frame[-1] ^ 0xFF])


@pytest.mark.parametrize("reply", ["silent", "bad CRC", "another drive", "truncated"])
def test_modbus_no_valid_reply_is_retried_once_then_a_driver_error(reply: str) -> None:
    """The driver asks twice (pymodbus, one retry), then gives up naming the drive and the port."""
    asked, good = read_input(16, [2490])
    assert good is not None
    answer = {
        "silent": None,
        "bad CRC": corrupt(good),
        "another drive": read_input(16, [2490], device_id=2)[1],
        "truncated": good[:4],
    }[reply]
    with expected_protocol([(asked, answer), (asked, answer)]) as replay:
        with pytest.raises(DriverError, match="read input register 16: no valid reply from drive 1") as info:
            modbus_tunnel(replay).read_speed_mps()
    assert info.value.device == replay.url


def test_modbus_set_point_beyond_the_drive_sends_nothing() -> None:
    with expected_protocol([]) as replay:
        with pytest.raises(DriverError, match="13 m/s is 65 Hz, outside the drive's 0..60 Hz"):
            modbus_tunnel(replay).write_setpoint_mps(13.0)


def test_modbus_a_failed_write_stops_the_sequence() -> None:
    """The drive refuses the reference (illegal value): the run command is not sent after it."""
    asked, _ = write_register(1, 2500)
    with expected_protocol([(asked, rtu.exception_response(1, rtu.WRITE_REGISTER, rtu.ILLEGAL_VALUE))]) as replay:
        with pytest.raises(DriverError, match="write set-point: drive 1 answered exception 3"):
            modbus_tunnel(replay).write_setpoint_mps(5.0)


# -- the ASCII point-sensor driver (drivers/sensor/ascii.py, docs/sensor.md) -----------------------

POLL = PollParams(rate_hz=50.0, retry_s=0.02, fail_after_s=2.0, batch_s=0.001)  # one exchange per read
# Declared silent after 0.5 s without a valid reply: a read comes 0.02 s after a good or refused
# exchange (within it, by a stall of a loaded host too), but an unanswered one takes SLOW_TIMEOUT_S
# (beyond it).
SILENCE = PollParams(rate_hz=50.0, retry_s=0.02, fail_after_s=0.5, batch_s=0.001)
SLOW_TIMEOUT_S = 0.7


def ascii_sensor(
    replay: SerialReplay,
    protocol: AsciiSensorProtocol | None = None,
    poll: PollParams = POLL,
    timeout_s: float = TIMEOUT_S,
) -> AsciiSensor:
    protocol = protocol or AsciiSensorProtocol()
    adapter = SerialAdapter(
        replay.url, timeout_s=timeout_s, eol=protocol.eol.encode("ascii"), port_obj=replay.open_port(timeout_s)
    )
    return AsciiSensor(adapter, protocol, poll)


def samples(sensor: AsciiSensor | ModbusSensor, n: int, timeout_s: float = 5.0) -> tuple[np.ndarray, np.ndarray, int]:
    """Read until ``n`` samples came (the rate is below 1/batch_s: one exchange per sample); return
    their times, values and the missing count."""
    got: list[SensorReading] = []
    deadline = time.monotonic() + timeout_s
    while sum(len(r) for r in got) < n:
        assert time.monotonic() < deadline, f"{sum(len(r) for r in got)} of {n} samples in {timeout_s} s"
        got.append(sensor.read(0.001))
    return (np.concatenate([r.t_us for r in got]), np.concatenate([r.value for r in got]), sum(r.missing for r in got))


def test_ascii_sensor_poll_readings_out_of_range_and_refusals() -> None:
    """``M?`` once per sample; ``D -----`` (out of range) and a refusal are missing samples (NaN),
    stamped by the host at the middle of the exchange."""
    with expected_protocol(
        [
            (b"M?\n", b"D 152.3070\n"),
            (b"M?\n", b"D -----\n"),
            (b"M?\n", b"D 151.9995\n"),
            (b"M?\n", b"ERR laser off\n"),
            (b"M?\n", b"D -0.5\n"),
        ]
    ) as replay:
        sensor = ascii_sensor(replay)
        info = sensor.open()  # poll mode: nothing sent
        before_us = time.time_ns() // 1000
        t_us, values, missing = samples(sensor, 5)
        sensor.close()
    assert (info.driver, info.clock, info.device) == ("ascii", "host", replay.url)
    np.testing.assert_array_equal(values, [152.307, np.nan, 151.9995, np.nan, -0.5])
    assert missing == 2 and np.all(np.diff(t_us) > 0) and before_us - 1000 <= t_us[0] <= time.time_ns() // 1000


def test_ascii_sensor_silence_becomes_a_driver_error_after_fail_after_s() -> None:
    """A sensor that stops answering: a NaN sample for the exchange that timed out, then (silent for
    longer than fail_after_s) a DriverError naming the port and the last failure, so the service
    reopens it."""
    with expected_protocol([(b"M?\n", b"D 152.3070\n"), (b"M?\n", None)]) as replay:
        sensor = ascii_sensor(replay, poll=SILENCE, timeout_s=SLOW_TIMEOUT_S)
        _, values, missing = samples(sensor, 2)
        with pytest.raises(DriverError, match=r"no valid reply for \d\.\d s \(.*no reply within 0\.7 s\)") as info:
            sensor.read(0.001)
        sensor.close()
    assert values[0] == 152.307 and math.isnan(values[1]) and missing >= 1 and info.value.device == replay.url


def test_ascii_sensor_stream_with_sensor_clock_triggers_and_stop() -> None:
    """Stream mode (the default protocol of docs/sensor.md): ``START`` -> ``OK``, then lines the sensor
    sends by itself, stamped by its clock; ``STOP`` at close."""
    stream = AsciiSensorProtocol(mode="stream")
    poll = PollParams(rate_hz=1000.0)
    with expected_protocol(
        [
            (b"START\n", b"OK\nD 1000 152.3070\nD 2000 152.4000\nT 2500\nD 3000 -----\nD 4000 152.5\n"),
            (b"STOP\n", b"OK\n"),
        ]
    ) as replay:
        sensor = ascii_sensor(replay, stream, poll)
        info = sensor.open()
        got = sensor.read(0.05)
        sensor.close()
    assert info.clock == "sensor" and info.settings == {"mode": "stream"}
    np.testing.assert_array_equal(got.t_us, [1000, 2000, 3000, 4000])
    np.testing.assert_array_equal(got.value, [152.307, 152.4, np.nan, 152.5])
    np.testing.assert_array_equal(got.trigger_t_us, [2500])
    assert got.missing == 1


@pytest.mark.parametrize(
    ("reply", "words"),
    [
        (b"ERR not ready\n", "'START' refused: 'ERR not ready'"),
        (None, "no reply within 0.1 s"),
    ],
)
def test_ascii_sensor_stream_start_refused_or_unanswered_is_a_driver_error(reply: bytes | None, words: str) -> None:
    with expected_protocol([(b"START\n", reply)]) as replay:
        sensor = ascii_sensor(replay, AsciiSensorProtocol(mode="stream"))
        with pytest.raises(DriverError) as info:
            sensor.open()
    assert words in str(info.value) and info.value.device == replay.url


# -- the Modbus point-sensor driver (drivers/sensor/modbus.py) -------------------------------------

DISTANCE = ModbusSensorMap(
    device_id=1,
    register=0,
    kind="input",
    words=2,
    word_order="big",
    signed=True,
    scale=0.001,
    invalid_counts=(2147483647,),
)  # deploy/rig-sensor-modbus.yaml


def modbus_sensor(
    replay: SerialReplay, modbus_map: ModbusSensorMap = DISTANCE, poll: PollParams = POLL, timeout_s: float = TIMEOUT_S
) -> ModbusSensor:
    return ModbusSensor.open_port(replay.url, modbus_map, baudrate=115200, parity="E", timeout_s=timeout_s, poll=poll)


def words(counts: int) -> list[int]:
    """A signed 32-bit reading as two registers, high word first."""
    raw = counts & 0xFFFFFFFF
    return [raw >> 16, raw & 0xFFFF]


def test_modbus_sensor_32_bit_signed_readings_and_no_target() -> None:
    """Input registers 0-1, high word first, signed, 0.001 mm per count; 0x7FFFFFFF is "no target"."""
    with expected_protocol(
        [
            read_input(0, words(152_307)),
            read_input(0, words(-1_500)),
            read_input(0, words(2147483647)),
            read_input(0, words(152_000)),
        ]
    ) as replay:
        sensor = modbus_sensor(replay)
        info = sensor.open()
        _, values, missing = samples(sensor, 4)
        sensor.close()
    assert (info.driver, info.clock, info.settings) == ("modbus", "host", {"device_id": 1, "register": 0})
    np.testing.assert_allclose(values, [152.307, -1.5, np.nan, 152.0], rtol=0, atol=1e-12)
    assert missing == 1


def test_modbus_sensor_16_bit_holding_register_of_another_address() -> None:
    holding = ModbusSensorMap(device_id=7, register=0x20, kind="holding", words=1, scale=0.01, offset=100.0)
    asked = request(7, rtu.READ_HOLDING, 0x20, 1)
    with expected_protocol([(asked, rtu.read_response(rtu.Request(7, rtu.READ_HOLDING, 0x20), [5230]))]) as replay:
        sensor = modbus_sensor(replay, holding)
        _, values, _ = samples(sensor, 1)
        sensor.close()
    assert values[0] == pytest.approx(152.3)


def test_modbus_sensor_failures_are_missing_samples_then_a_driver_error() -> None:
    """An exception reply and a silence (no retry: a late sample is a missing one) are NaN samples;
    silent past fail_after_s, the next read raises DriverError naming the port and the last failure."""
    asked, _ = read_input(0, [0, 0])
    with expected_protocol(
        [
            (asked, rtu.exception_response(1, rtu.READ_INPUT, rtu.ILLEGAL_ADDRESS)),
            (asked, None),
        ]
    ) as replay:
        sensor = modbus_sensor(replay, poll=SILENCE, timeout_s=SLOW_TIMEOUT_S)
        _, values, missing = samples(sensor, 2)
        with pytest.raises(DriverError, match=r"no valid reply for \d\.\d s \(.*sensor 1 .*after 0 retries") as info:
            sensor.read(0.001)
        sensor.close()
    assert np.isnan(values).all() and missing >= 2 and info.value.device == replay.url


@pytest.mark.parametrize(
    ("make", "words"),
    [
        (lambda tmp: tmp / "ttyUSB9", "no such device (is it plugged in?"),
        (lambda tmp: (tmp / "notes.txt").write_text("x") and tmp / "notes.txt", "not a serial port"),
        (lambda tmp: tmp, "is a directory"),
    ],
)
def test_a_port_that_does_not_open_says_why_in_a_few_words(tmp_path, make, words: str) -> None:
    """One line: the port, then why (pyserial's text named the port and the errno twice)."""
    port = str(make(tmp_path))
    with pytest.raises(DriverError) as caught:
        SerialAdapter(port)
    message = str(caught.value)
    assert message.startswith(f"{port}: cannot open serial port: {words}") and message.count("Errno") == 0
