"""The safety layer against the simulated tunnel on a pty: bounds, ramps, readback checks,
keep-alive, start from the current speed, and fault injection (link lost, readback never there)."""

from __future__ import annotations

import dataclasses
import threading
import time

import pytest

from flagtrack.daemon.errors import DriverError
from flagtrack.drivers.tunnel.ascii import AsciiTunnel
from flagtrack.drivers.tunnel.base import TunnelLink
from flagtrack.drivers.tunnel.modbus import ModbusTunnel
from flagtrack.drivers.tunnel.safe import SafeTunnel, SafetyParams, TunnelAborted
from flagtrack.drivers.tunnel.setup import TunnelConfig, open_tunnel
from flagtrack.drivers.tunnel.sim_model import SimParams
from flagtrack.drivers.tunnel.simulated import SimulatedTunnel
from tests.fakes.helpers import wait_until

SIM = SimParams(tau_s=0.02, ramp_mps2=500.0, max_speed_mps=12.0, watchdog_s=0.6, tick_s=0.002)
SAFETY = SafetyParams(
    max_speed_mps=10.0, max_ramp_mps2=40.0, ramp_period_s=0.02, tolerance_mps=0.1,
    settle_timeout_s=0.5, poll_period_s=0.01, keepalive_s=0.1, watchdog_s=0.6,
)  # fmt: skip


class RecordingLink:
    """A real link that also records (monotonic time, set-point) of every set-point it sends."""

    def __init__(self, link: TunnelLink) -> None:
        self.link = link
        self.device = link.device
        self.setpoints: list[tuple[float, float]] = []

    def write_setpoint_mps(self, speed_mps: float) -> None:
        self.setpoints.append((time.monotonic(), speed_mps))
        self.link.write_setpoint_mps(speed_mps)

    def __getattr__(self, name: str):
        return getattr(self.link, name)


@pytest.fixture(params=["ascii", "modbus"])
def sim_params(request: pytest.FixtureRequest) -> SimParams:
    return SimParams(**{**SIM.__dict__, "protocol": request.param})


def make_tunnel(sim: SimulatedTunnel, params: SafetyParams = SAFETY) -> tuple[SafeTunnel, RecordingLink]:
    if sim.params.protocol == "modbus":
        raw: TunnelLink = ModbusTunnel.open(sim.port, timeout_s=0.2)
    else:
        raw = AsciiTunnel.open(sim.port, timeout_s=0.2)
    link = RecordingLink(raw)
    return SafeTunnel(link, params), link


def test_set_ramps_within_the_limit_and_verifies(sim: SimulatedTunnel) -> None:
    tunnel, link = make_tunnel(sim)
    with tunnel:
        called = time.monotonic()
        tunnel.set_speed_mps(8.0)
        done = time.monotonic()
        assert abs(sim.speed_mps - 8.0) <= SAFETY.tolerance_mps + 0.05
        values = [v for _, v in link.setpoints]
        assert values[-1] == 8.0 and len(values) >= 5
        assert all(b >= a for a, b in zip(values, values[1:]))
        # The ramp can be slower than the limit under load, never faster.
        assert all(v <= SAFETY.max_ramp_mps2 * (t - called) + 1e-9 for t, v in link.setpoints)
        assert done - called >= 8.0 / SAFETY.max_ramp_mps2
    assert sim.setpoint_mps == 0.0
    assert wait_until(lambda: sim.speed_mps < 0.05)


def test_out_of_bounds_setpoint_sends_nothing(sim: SimulatedTunnel) -> None:
    tunnel, link = make_tunnel(sim)
    with tunnel:
        for bad in (10.5, -1.0, float("nan")):
            with pytest.raises(DriverError, match="outside the bounds") as info:
                tunnel.set_speed_mps(bad)
            assert info.value.device == sim.port
        assert link.setpoints == []


def test_readback_never_reaching_the_setpoint_fails_and_stops(sim: SimulatedTunnel) -> None:
    sim.inject(stall_mps=3.0)
    tunnel, _ = make_tunnel(sim)
    with tunnel:
        with pytest.raises(DriverError) as info:
            tunnel.set_speed_mps(6.0)
        message = str(info.value)
        assert info.value.device == sim.port and message.startswith(sim.port)
        assert "did not reach the set-point 6.00" in message and "tunnel commanded to zero" in message
        assert sim.setpoint_mps == 0.0
        assert wait_until(lambda: sim.speed_mps < 0.05)


def test_link_lost_mid_operation_fails_and_watchdog_brings_it_to_zero(sim: SimulatedTunnel) -> None:
    tunnel, _ = make_tunnel(sim)
    try:
        tunnel.start()
        tunnel.set_speed_mps(4.0)
        sim.inject(mute=True)  # the cable is cut: the tunnel neither hears nor answers
        heard = sim.valid_commands
        with pytest.raises(DriverError) as info:
            tunnel.set_speed_mps(6.0)
        message = str(info.value)
        assert info.value.device == sim.port
        assert "commanding zero failed too" in message and "watchdog" in message
        assert sim.valid_commands == heard  # it heard nothing: its own watchdog stops it
        assert wait_until(lambda: sim.watchdog_trips == 1, timeout_s=3.0)
        assert wait_until(lambda: sim.speed_mps < 0.05)
        assert sim.fault == "WATCHDOG"
    finally:
        tunnel.close()


def test_keepalive_holds_the_speed_longer_than_the_watchdog(sim_params: SimParams) -> None:
    watchdog_s = 1.2  # a 1.1 s stall of a loaded host between keep-alives (0.1 s) would still trip it
    with SimulatedTunnel(dataclasses.replace(sim_params, watchdog_s=watchdog_s)) as sim:
        tunnel, _ = make_tunnel(sim, dataclasses.replace(SAFETY, watchdog_s=watchdog_s))
        with tunnel:
            tunnel.set_speed_mps(5.0)
            time.sleep(2 * watchdog_s)  # idle: only the keep-alive talks
            assert sim.watchdog_trips == 0
            assert tunnel.read_speed_mps() == pytest.approx(5.0, abs=SAFETY.tolerance_mps)
            assert tunnel.status().keepalive_failures == 0


def test_start_reads_the_current_speed_and_ramps_from_it() -> None:
    with SimulatedTunnel(SimParams(**{**SIM.__dict__, "initial_speed_mps": 6.0, "watchdog_s": 5.0})) as sim:
        tunnel, link = make_tunnel(sim)
        with tunnel:
            assert tunnel.setpoint_mps == pytest.approx(6.0, abs=0.01)
            tunnel.set_speed_mps(7.0)
            first = link.setpoints[0][1]
            assert 6.0 - 0.01 <= first <= 7.0  # no drop to zero first
        assert sim.setpoint_mps == 0.0


def test_exception_inside_the_with_block_ramps_to_zero(sim: SimulatedTunnel) -> None:
    tunnel, _ = make_tunnel(sim)
    with pytest.raises(RuntimeError, match="analysis crashed"), tunnel:
        tunnel.set_speed_mps(3.0)
        raise RuntimeError("analysis crashed")
    assert sim.setpoint_mps == 0.0
    assert wait_until(lambda: sim.speed_mps < 0.05)


def test_abort_interrupts_a_ramp_and_stops(sim: SimulatedTunnel) -> None:
    slow = SafetyParams(**{**SAFETY.__dict__, "max_ramp_mps2": 2.0, "settle_timeout_s": 5.0})
    tunnel, _ = make_tunnel(sim, slow)
    with tunnel:
        threading.Timer(0.3, tunnel.abort).start()  # what a SIGTERM handler does
        started = time.monotonic()
        with pytest.raises(TunnelAborted, match="aborted; tunnel commanded to zero"):
            tunnel.set_speed_mps(9.0)  # would take 4.5 s
        assert time.monotonic() - started < 4.0
        assert sim.setpoint_mps == 0.0


def test_status_reports_speed_setpoint_and_link(sim: SimulatedTunnel) -> None:
    tunnel, _ = make_tunnel(sim)
    with tunnel:
        tunnel.set_speed_mps(2.0)
        status = tunnel.status()
        assert status.device == sim.port and status.link_ok and status.fault is None
        assert status.setpoint_mps == 2.0 and abs(status.speed_mps - 2.0) <= SAFETY.tolerance_mps + 0.05
        sim.inject(mute=True)
        status = tunnel.status()
        assert not status.link_ok and "no" in (status.fault or "")
        sim.clear_faults()


@pytest.mark.parametrize("protocol", ["ascii", "modbus"])
def test_simulated_driver_from_config_exposes_the_simulator(protocol: str) -> None:
    if protocol == "modbus":
        pytest.importorskip("pymodbus")
    cfg = TunnelConfig(driver="simulated", safety=SAFETY, sim=SimParams(**{**SIM.__dict__, "protocol": protocol}))
    tunnel = open_tunnel(cfg)
    with tunnel:
        tunnel.set_speed_mps(3.0)
        assert tunnel.simulator.speed_mps == pytest.approx(3.0, abs=0.2)  # what the simulated camera reads
    assert tunnel.simulator.setpoint_mps == 0.0


def test_safety_params_reject_a_keepalive_slower_than_half_the_watchdog() -> None:
    with pytest.raises(ValueError, match="at most half"):
        SafetyParams(keepalive_s=3.0, watchdog_s=5.0)


def test_a_hung_owner_loop_lets_the_controllers_watchdog_stop_the_fan(sim: SimulatedTunnel) -> None:
    params = SafetyParams(**{**SAFETY.__dict__, "loop_timeout_s": 0.3})
    tunnel, _ = make_tunnel(sim, params)
    with tunnel:
        tunnel.heartbeat()  # the owner's loop reports ...
        tunnel.set_speed_mps(5.0)
        beat_until = time.monotonic() + 2 * SIM.watchdog_s
        while time.monotonic() < beat_until:  # ... and while it does, the keep-alive holds the speed
            tunnel.heartbeat()
            time.sleep(0.05)
        assert sim.watchdog_trips == 0 and sim.setpoint_mps == 5.0
        # then the loop hangs: no more heartbeats, the keep-alive stops, the controller's watchdog trips
        wait_until(lambda: sim.watchdog_trips == 1, params.loop_timeout_s + SIM.watchdog_s + 2, "the watchdog trip")
        assert tunnel.owner_silent
        wait_until(lambda: sim.speed_mps < 0.1, 2, "the fan stopped")
        assert tunnel.status().link_ok  # the link itself was fine all along
        # the loop comes back: its set-points are refused, said, and the tunnel stays at zero
        tunnel.heartbeat()
        for command in (lambda: tunnel.step_toward(5.0), lambda: tunnel.set_speed_mps(5.0)):
            with pytest.raises(DriverError, match="owner's loop was silent .* no set-point is taken"):
                command()
        assert sim.setpoint_mps == 0.0


def test_a_controller_fault_is_read_through_the_protocol_and_spoils_a_point(sim: SimulatedTunnel) -> None:
    from flagtrack.daemon.sweep.validity import TunnelWatch

    tunnel, _ = make_tunnel(sim)
    with tunnel:
        tunnel.set_speed_mps(5.0)
        watch = TunnelWatch(5.0, SAFETY.tolerance_mps, grace_s=1.0)
        status = tunnel.status()
        assert status.fault is None and watch.check(status.speed_mps, status.fault, status.link_ok, 0.0) is None
        sim.inject(fault="OVERCURRENT")
        status = tunnel.status()
        expected = "OVERCURRENT" if sim.params.protocol == "ascii" else "fault code 2"
        assert expected in (status.fault or "")
        assert "tunnel fault" in watch.check(status.speed_mps, status.fault, status.link_ok, 0.1)
