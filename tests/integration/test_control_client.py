"""``flagtrack.client`` against a running rig: flag states, centrelines and rates as they come (iterated
and called back), speed requests bounded, answered and logged by the supervisor; on a secured bus only
an operator's requests reach it (an identity forging the operator's key gets through only where the
access control is off)."""

from __future__ import annotations

import dataclasses
import itertools
import json
import logging
import signal
import textwrap
import threading
from contextlib import ExitStack
from pathlib import Path

import pytest

from flagtrack.client import FlagState, NoAnswer, Rig, client_bus, rig_bus
from flagtrack.daemon.errors import ConfigError
from flagtrack.daemon.rig.build import build_services
from flagtrack.daemon.schema import EventRate, SpeedReply, SpeedRequest
from flagtrack.daemon.transport import Bus
from tests.fakes.helpers import wait_until
from tests.fakes.secure import Pki, load, make_pki, rig_text, router_config
from tests.integration.test_transport import free_port
from tests.integration.test_up import start

SAFETY = (
    "{max_speed_mps: 8, max_ramp_mps2: 4.0, ramp_period_s: 0.05, tolerance_mps: 0.15, settle_timeout_s: 5.0, "
    "poll_period_s: 0.05, keepalive_s: 0.25, watchdog_s: 1.0}"
)


def plain_rig(tmp_path: Path, port: int, mode: str) -> Path:
    path = tmp_path / "rig.yaml"
    path.write_text(
        textwrap.dedent(f"""
        rig: cli{port}
        bus: {{listen: ["tcp/127.0.0.1:{port}"]}}
        camera:
          adapter: simulated
          packet_us: 4000
          simulated: {{events_per_px2: 0.5, noise_rate_hz: 5000, max_lag_s: 1.0, speed_mps: 6.0,
                      flutter: {{onset_speed_mps: 4.9, decay_speed_mps: 4.4, tau_amp_s: 0.15}}}}
        tracker: {{root: [150, 240], length: 300, tau_s: 0.002}}
        tunnel: {{driver: simulated, timeout_s: 2.0, safety: {SAFETY}, sim: {{tau_s: 0.1, ramp_mps2: 6.0, watchdog_s: 1.0}}}}
        supervisor:
          mode: {mode}
          runs_dir: {tmp_path / "runs"}
          run_name: requests
          onset: {{learn_s: 1.0}}
          required: [camera, tracker]
          startup_timeout_s: 60
          control: {{duration_s: 0, record: false}}
        services: [camera, tracker, flagstate, supervisor]
        """)
    )
    return path


@pytest.mark.slow
@pytest.mark.timeout(240)
def test_a_script_reads_the_flag_and_asks_for_speeds(tmp_path: Path) -> None:
    port = free_port()
    path = plain_rig(tmp_path, port, "control")
    proc = start("-v", "up", "-c", str(path))
    try:
        with Rig.connect(path) as rig:
            called: list[FlagState] = []
            watch = rig.on_state(called.append)
            state = rig.next_state(timeout_s=120)
            assert isinstance(state, FlagState) and state.source == "cam0" and state.units == "px"
            rate = next(rig.rates("cam0", timeout_s=10))
            assert isinstance(rate, EventRate) and rate.rate_hz > 0
            lines = next(rig.centrelines(timeout_s=10))
            assert lines.x.shape[1] == len(lines.s)
            reply = wait_until(
                lambda: _asked(rig, 99.0, loop_running=True), 60, "the control loop's answer (once the rig is up)"
            )
            assert reply.accepted and reply.applied_mps == 8.0 and "tunnel.safety.max_speed_mps" in reply.reason
            reply = rig.request_speed(6.0)
            assert reply.accepted and reply.applied_mps == 6.0 and reply.reason == "" and reply.requester == "client"
            refused = rig.request_speed(float("nan"))
            assert not refused.accepted and "not a speed" in refused.reason
            speeds = [s.speed_mps for s in itertools.islice(rig.states(timeout_s=5), 20) if s.speed_mps >= 0]
            wait_until(lambda: len(called) >= 3, 30, "three states at the callback")
            watch.stop()
            assert watch.error is None and all(isinstance(s, FlagState) for s in called)
            assert speeds and max(speeds) <= 8.15  # the tunnel's readback, carried by the states
    finally:
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=90)
    assert "speed request" in err and "from client (not authenticated: plain bus): 99 m/s" in err
    assert "applied 8 m/s (asked 99 m/s, above tunnel.safety.max_speed_mps 8 m/s)" in err
    steps = [json.loads(line) for line in (tmp_path / "runs" / "requests" / "control.jsonl").read_text().splitlines()]
    refusals = [r for r in steps if r.get("reason", "").startswith("refused: ")]
    assert (
        len(refusals) == 1 and refusals[0]["requester"].startswith("client") and "not a speed" in refusals[0]["reason"]
    )
    assert refusals[0]["asked_mps"] is None and refusals[0]["request_id"] == refused.request_id


def _asked(rig: Rig, speed_mps: float, loop_running: bool = False) -> SpeedReply | None:
    """The supervisor's reply (None: none yet; with ``loop_running``, also while its loop has not started)."""
    try:
        reply = rig.request_speed(speed_mps, timeout_s=2.0)
    except NoAnswer:
        return None
    return None if loop_running and "has not started" in reply.reason else reply


@pytest.mark.slow
@pytest.mark.timeout(240)
def test_a_sweep_or_monitor_refuses_requests_and_says_why(tmp_path: Path) -> None:
    port = free_port()
    path = plain_rig(tmp_path, port, "monitor")
    proc = start("up", "-c", str(path))
    try:
        with Rig.connect(path, identity="alice") as rig:
            reply = wait_until(lambda: _asked(rig, 5.0), 120, "the supervisor's answer")
    finally:
        proc.send_signal(signal.SIGINT)
        proc.communicate(timeout=90)
    assert not reply.accepted and reply.requester == "alice" and "mode monitor" in reply.reason


def test_a_client_needs_somewhere_to_connect_and_a_secured_one_an_identity(tmp_path: Path) -> None:
    lone = tmp_path / "lone.yaml"
    lone.write_text("rig: lone\n")
    with pytest.raises(ConfigError, match="bus.listen"):
        client_bus(rig_bus(lone))
    pki = make_pki(tmp_path / "pki")
    secured = tmp_path / "sec.yaml"
    secured.write_text(rig_text(7447, pki))
    with pytest.raises(ConfigError, match="name the identity"):
        client_bus(rig_bus(secured))
    bus = client_bus(rig_bus(secured), identity="operator")
    assert bus.connect == ("tls/127.0.0.1:7447",) and bus.listen == () and bus.security.identity == "operator"
    with pytest.raises(ConfigError, match="tls/ endpoint needs"):
        Rig.at("tls/127.0.0.1:7447", "flagtrack/sec")
    # no rig there: a plain bus lets anyone ask, so the hint is the rig, not the identity
    with Rig.at(f"tcp/127.0.0.1:{free_port()}", "flagtrack/nobody") as nobody, pytest.raises(NoAnswer) as silence:
        nobody.request_speed(4.0, timeout_s=0.3)
    assert "is the rig running" in str(silence.value) and "operators" not in str(silence.value)


# -- a secured bus --------------------------------------------------------------------------------

SECURE_BODY = f"""
camera: {{id: cam0}}
tunnel: {{driver: simulated, timeout_s: 2.0, safety: {SAFETY}, sim: {{tau_s: 0.1, ramp_mps2: 6.0, watchdog_s: 1.0}}}}
supervisor:
  mode: control
  onset: {{learn_s: 0.2, window_s: 0.1}}
  required: [camera]
  control: {{duration_s: 0, record: false}}
services: [supervisor]
"""


@pytest.fixture(scope="module")
def pki(tmp_path_factory: pytest.TempPathFactory) -> Pki:
    return make_pki(tmp_path_factory.mktemp("pki"))


@pytest.mark.slow
@pytest.mark.timeout(240)
@pytest.mark.parametrize("acl", [True, False], ids=["access control", "no access control (the attack works)"])
def test_only_an_operator_may_ask_for_a_speed(
    pki: Pki, tmp_path: Path, acl: bool, caplog: pytest.LogCaptureFixture
) -> None:
    """The viewer holds a valid certificate and publishes a request on the operator's key. With the
    rig's access control the router drops it and only the operator's request is taken; without it,
    the forged request moves the tunnel (the attack the access control stops)."""
    caplog.set_level(logging.INFO, logger="flagtrack.daemon.services.supervisor.requests")
    port = free_port()
    rig = load(tmp_path / "rig.yaml", rig_text(port, pki, acl=acl, body=SECURE_BODY))
    rig = dataclasses.replace(rig, supervisor=dataclasses.replace(rig.supervisor, runs_dir=tmp_path))
    stop = threading.Event()
    with ExitStack() as stack:
        stack.enter_context(Bus(router_config(rig, port)))
        camera = stack.enter_context(Bus(rig.bus_config_for(["camera"])))
        (supervisor,) = build_services(
            rig, stack.enter_context(Bus(rig.bus_config_for(["supervisor"]))), ["supervisor"]
        )
        supervisor.start()
        runner = threading.Thread(target=supervisor.run, args=(stop,), daemon=True)
        runner.start()
        stack.callback(runner.join, 60)
        stack.callback(stop.set)
        _camera_alive(stack, camera, stop)
        viewer = stack.enter_context(Bus(rig.bus_config_for(["viewer"])))
        forged = viewer.publisher(viewer.keys.speed_request("operator"))
        operator = stack.enter_context(Rig.at(f"tls/127.0.0.1:{port}", rig.bus_config.namespace, identity="operator",
                                              ca=pki.ca, cert=pki.rig / "operator.pem", key=pki.rig / "operator.key"))  # fmt: skip
        wait_until(lambda: supervisor.desk.taking, 60, "the control loop")
        forged.put(SpeedRequest(7.0, "forged", "operator"))
        reply = operator.request_speed(3.0, timeout_s=20)
        assert reply.accepted and reply.applied_mps == 3.0 and reply.requester == "operator"
        if not acl:
            wait_until(lambda: supervisor.desk.answered >= 2, 20, "the forged request's answer")
        taken = [r.getMessage() for r in caplog.records if "speed request" in r.getMessage() and ": " in r.getMessage()]
    asked = [m for m in taken if "applied" not in m and "refused" not in m]  # the requests as they came
    if acl:
        assert supervisor.desk.answered == 1 and not any("forged" in m for m in taken)
        assert asked == ["speed request " + reply.request_id + " from operator: 3 m/s"]
    else:  # the same request, without the access control: taken as the operator's
        assert any(
            m.startswith("speed request forged from operator (not authenticated: no access control)") for m in taken
        )
        assert supervisor.desk.answered == 2


def _camera_alive(stack: ExitStack, camera: Bus, stop: threading.Event) -> None:
    """The camera's liveliness and event rates (the supervisor waits for them), until ``stop``."""
    camera.declare_alive("camera/cam0")
    publisher = camera.publisher(camera.keys.event_rate("cam0"))

    def rates() -> None:
        t_us = 0
        while not stop.wait(0.02):
            t_us += 20_000
            publisher.put(EventRate("cam0", t_us, 0.02, 1000, 50_000.0, 0.5))

    thread = threading.Thread(target=rates, daemon=True)
    thread.start()
    stack.callback(thread.join, 5)
