"""The ASCII line-protocol driver: against the simulated tunnel on a real pseudo-terminal, and
against pyserial's ``loop://`` for write-only commands and the no-reply path."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
import serial

from flagtrack.daemon.errors import ConfigError, DriverError
from flagtrack.daemon.typed_yaml import from_mapping
from flagtrack.drivers.serial.adapter import SerialAdapter
from flagtrack.drivers.tunnel.ascii import AsciiProtocol, AsciiTunnel
from flagtrack.drivers.tunnel.sim_model import SimParams
from flagtrack.drivers.tunnel.simulated import SimulatedTunnel
from tests.fakes.helpers import wait_until
from tests.fakes.tunnel import FAST_SIM


@pytest.fixture
def sim_params() -> SimParams:
    return FAST_SIM


@pytest.fixture
def link(sim: SimulatedTunnel) -> Iterator[AsciiTunnel]:
    driver = AsciiTunnel.open(sim.port, timeout_s=0.3)
    yield driver
    driver.close()


def test_default_protocol_round_trip_on_a_pty(sim: SimulatedTunnel, link: AsciiTunnel) -> None:
    assert link.device == sim.port and sim.port.startswith("/dev/")
    assert link.read_speed_mps() == pytest.approx(0.0, abs=1e-3)
    link.write_setpoint_mps(4.5)
    assert sim.setpoint_mps == pytest.approx(4.5)
    assert wait_until(lambda: abs(link.read_speed_mps() - 4.5) < 0.01)
    link.keep_alive()
    assert link.read_fault() is None
    link.stop()
    assert sim.setpoint_mps == 0.0
    assert wait_until(lambda: link.read_speed_mps() < 0.01)


def test_refused_command_names_device_and_reason(sim: SimulatedTunnel, link: AsciiTunnel) -> None:
    with pytest.raises(DriverError) as info:
        link.write_setpoint_mps(50.0)  # the simulated controller's max is 12 m/s
    assert info.value.device == sim.port
    assert "refused 'SET 50.00'" in str(info.value) and "bad set-point" in str(info.value)
    assert sim.setpoint_mps == 0.0


def test_garbage_reply_is_a_clear_error(sim: SimulatedTunnel, link: AsciiTunnel) -> None:
    sim.inject(garbage=True)
    with pytest.raises(DriverError, match=r"unexpected reply .* to 'GET\?'") as info:
        link.read_speed_mps()
    assert info.value.device == sim.port


def test_muted_controller_gives_no_reply_error(sim: SimulatedTunnel, link: AsciiTunnel) -> None:
    sim.inject(mute=True)
    with pytest.raises(DriverError, match="no reply within 0.3 s") as info:
        link.keep_alive()
    assert info.value.device == sim.port


def test_watchdog_reports_fault_then_clears_on_new_setpoint(sim: SimulatedTunnel, link: AsciiTunnel) -> None:
    link.write_setpoint_mps(3.0)
    assert wait_until(lambda: sim.fault == "WATCHDOG", timeout_s=3.0)
    assert link.read_fault() == "WATCHDOG"
    assert sim.setpoint_mps == 0.0 and sim.watchdog_trips == 1
    link.write_setpoint_mps(2.0)
    assert link.read_fault() is None


def loop_link(protocol: AsciiProtocol) -> tuple[AsciiTunnel, serial.SerialBase]:
    port = serial.serial_for_url("loop://", timeout=0.1)
    return AsciiTunnel(
        SerialAdapter("loop://", timeout_s=0.1, eol=protocol.eol.encode(), port_obj=port), protocol
    ), port


def test_write_only_commands_send_exact_bytes_on_loop() -> None:
    protocol = AsciiProtocol(
        eol="\r", units_per_mps=100 / 15, set_command="F{value:05.1f}", set_reply=None,
        stop_command="F000.0", stop_reply=None, ping_command="?", ping_reply=None,
    )  # fmt: skip
    link, port = loop_link(protocol)
    link.write_setpoint_mps(7.5)  # 50 % of 15 m/s
    assert port.read(port.in_waiting) == b"F050.0\r"
    link.stop()
    assert port.read(port.in_waiting) == b"F000.0\r"
    link.keep_alive()
    assert port.read(port.in_waiting) == b"?\r"


def test_echoing_link_without_reply_times_out_on_loop() -> None:
    link, _ = loop_link(AsciiProtocol(echo=True))
    with pytest.raises(DriverError) as info:
        link.write_setpoint_mps(5.0)  # the echo arrives, then nothing
    assert info.value.device == "loop://"
    assert "no reply within 0.1 s" in str(info.value)


def test_echo_taken_for_a_reply_is_reported_on_loop() -> None:
    link, _ = loop_link(AsciiProtocol())
    with pytest.raises(DriverError, match=r"unexpected reply 'SET 5\.00' to 'SET 5\.00' \(expected /OK/\)"):
        link.write_setpoint_mps(5.0)


def test_custom_reply_pattern_and_units_on_a_pty(sim: SimulatedTunnel) -> None:
    protocol = AsciiProtocol(query_reply=r"SPD\s+(?P<value>[0-9.]+)", units_per_mps=1.0, fault_command=None)
    link = AsciiTunnel.open(sim.port, protocol, timeout_s=0.3)
    try:
        link.write_setpoint_mps(2.0)
        assert wait_until(lambda: abs(link.read_speed_mps() - 2.0) < 0.01)
        assert link.read_fault() is None  # no fault query configured: nothing sent
    finally:
        link.close()


@pytest.mark.parametrize(
    ("section", "words"),
    [
        ({"query_reply": "SPD ([0-9.]+)"}, "named group (?P<value>"),
        ({"error_reply": "ERR ("}, "not a valid regular expression"),
        ({"set_command": "SET {speed}"}, "must format with {value}"),
        ({"units_per_mps": 0}, "units_per_mps must be positive"),
        ({"set_replly": "OK"}, "unknown key"),
    ],
)
def test_protocol_config_errors_name_the_key(section: dict, words: str) -> None:
    with pytest.raises(ConfigError) as info:
        from_mapping(AsciiProtocol, section, path="rig.yaml", key="tunnel.ascii")
    assert "rig.yaml" in str(info.value) and "tunnel.ascii" in str(info.value)
    assert words in str(info.value)


def test_unopenable_port_names_it() -> None:
    with pytest.raises(DriverError) as info:
        AsciiTunnel.open("/dev/does-not-exist-flagtrack")
    assert info.value.device == "/dev/does-not-exist-flagtrack"
