"""The Modbus RTU drive: RTU framing, and the pymodbus driver against the simulated drive on a pty."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import replace

import pytest

from flagtrack.daemon.errors import DriverError
from flagtrack.drivers.serial import modbus_rtu as rtu
from flagtrack.drivers.tunnel.modbus import ModbusMap, ModbusTunnel
from flagtrack.drivers.tunnel.sim_model import SimParams
from flagtrack.drivers.tunnel.simulated import SimulatedTunnel
from tests.fakes.helpers import wait_until
from tests.fakes.tunnel import FAST_SIM

pytest.importorskip("pymodbus")

MAP = ModbusMap(fault_codes={1: "communication loss"}, mps_per_hz=0.2, max_hz=50.0)


@pytest.fixture(params=["register", "coil"])
def modbus_map(request: pytest.FixtureRequest) -> ModbusMap:
    if request.param == "coil":
        return ModbusMap(control="coil", control_address=5, fault_codes=MAP.fault_codes, mps_per_hz=0.2, max_hz=50.0)
    return MAP


@pytest.fixture
def sim_params() -> SimParams:
    return replace(FAST_SIM, protocol="modbus")


@pytest.fixture
def sim_modbus_map(modbus_map: ModbusMap) -> ModbusMap:
    return modbus_map


@pytest.fixture
def link(sim: SimulatedTunnel, modbus_map: ModbusMap) -> Iterator[ModbusTunnel]:
    driver = ModbusTunnel.open(sim.port, modbus_map, timeout_s=0.3)
    yield driver
    driver.close()


def test_crc_matches_the_modbus_reference_vector() -> None:
    frame = rtu.with_crc(bytes.fromhex("01 03 00 00 00 0A"))
    assert frame[-2:] == bytes.fromhex("C5 CD")  # the standard's example request
    assert rtu.parse_request(frame) == rtu.Request(1, rtu.READ_HOLDING, 0, count=10)


@pytest.mark.parametrize(
    "request_",
    [
        rtu.Request(7, rtu.WRITE_REGISTER, 0x2001, values=(1234,)),
        rtu.Request(1, rtu.WRITE_COIL, 5, values=(1,)),
        rtu.Request(1, rtu.WRITE_REGISTERS, 10, count=3, values=(1, 2, 65535)),
    ],
)
def test_write_requests_round_trip_through_the_framer(request_: rtu.Request) -> None:
    # A write response is the request's header; rebuild a request frame from it and parse it back.
    frame = rtu.write_response(request_)
    if request_.function == rtu.WRITE_REGISTERS:
        body = frame[:-2] + bytes([2 * request_.count]) + b"".join(v.to_bytes(2, "big") for v in request_.values)
        frame = rtu.with_crc(body)
    assert rtu.frame_length(frame) == len(frame)
    assert rtu.parse_request(frame) == request_


def test_corrupted_frame_is_rejected() -> None:
    frame = bytearray(rtu.with_crc(bytes.fromhex("01 06 00 01 01 F4")))
    frame[4] ^= 0x01
    with pytest.raises(ValueError, match="bad CRC"):
        rtu.parse_request(bytes(frame))


def test_drive_set_readback_stop_on_a_pty(sim: SimulatedTunnel, link: ModbusTunnel) -> None:
    assert link.read_speed_mps() == 0.0
    link.write_setpoint_mps(6.0)  # 30 Hz at 0.2 m/s per Hz
    assert sim.setpoint_mps == pytest.approx(6.0)
    assert wait_until(lambda: abs(link.read_speed_mps() - 6.0) < 0.01)
    link.keep_alive()
    assert link.read_fault() is None
    link.stop()
    assert sim.setpoint_mps == 0.0
    assert wait_until(lambda: link.read_speed_mps() == 0.0)


def test_watchdog_trip_shows_in_the_fault_register(sim: SimulatedTunnel, link: ModbusTunnel) -> None:
    link.write_setpoint_mps(2.0)
    assert wait_until(lambda: sim.watchdog_trips == 1)
    assert link.read_fault() == "communication loss"
    assert wait_until(lambda: sim.speed_mps < 0.01)


def test_setpoint_beyond_the_drive_limit_is_refused_before_sending(sim: SimulatedTunnel, link: ModbusTunnel) -> None:
    before = sim.valid_commands
    with pytest.raises(DriverError, match="outside the drive's 0..50 Hz") as info:
        link.write_setpoint_mps(11.0)  # 55 Hz
    assert info.value.device == sim.port
    assert sim.valid_commands == before


def test_exception_reply_is_a_driver_error(sim: SimulatedTunnel) -> None:
    # The client believes the readback is a holding register at 99: the drive answers "illegal address".
    wrong = ModbusMap(readback_register=99, readback_kind="holding", mps_per_hz=0.2, max_hz=50.0)
    link = ModbusTunnel.open(sim.port, wrong, timeout_s=0.3)
    try:
        with pytest.raises(DriverError, match="answered exception 2") as info:
            link.read_speed_mps()
        assert info.value.device == sim.port
    finally:
        link.close()


def test_silent_drive_is_a_driver_error(sim: SimulatedTunnel, link: ModbusTunnel) -> None:
    sim.inject(mute=True)
    with pytest.raises(DriverError, match="no valid reply from drive 1") as info:
        link.read_speed_mps()
    assert info.value.device == sim.port


def test_garbled_reply_is_a_driver_error(sim: SimulatedTunnel, link: ModbusTunnel) -> None:
    sim.inject(garbage=True)
    with pytest.raises(DriverError) as info:
        link.read_speed_mps()
    assert info.value.device == sim.port
