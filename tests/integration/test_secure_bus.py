"""A secured bus on loopback (mutual TLS through a router, access control made from the rig): who
cannot join, and what an identity may not send. Each defence is shown failing where it is off."""

from __future__ import annotations

import json
import logging
import threading
from contextlib import ExitStack
from pathlib import Path

import numpy as np
import pytest
import zenoh

from flagtrack.daemon.core.onset import OnsetParams
from flagtrack.daemon.core.tracker import Tracker
from flagtrack.daemon.errors import ConfigError
from flagtrack.daemon.schema import CentrelineMessage, EventPacket, EventRate, RecorderCommand, RecorderStatus
from flagtrack.daemon.services.recorder import RecorderConfig, RecorderService
from flagtrack.daemon.services.supervisor.monitor import BusMonitor
from flagtrack.daemon.services.tracker import TrackerService, TrackerServiceConfig
from flagtrack.daemon.tracking.section import TrackingConfig
from flagtrack.daemon.transport import Bus
from flagtrack.drivers.formats.packets import Packetizer, PacketParams
from flagtrack.drivers.sim.quickline import WavyFlag, line_events
from tests.fakes.helpers import wait_subscribed, wait_until
from tests.fakes.secure import Pki, intruder_config, load, make_pki, rig_text, router_config
from tests.integration.test_transport import free_port

FLAG = WavyFlag(length=200.0, root=(100.0, 240.0), frequency_hz=20.0)
TRACKING = TrackingConfig(root=FLAG.root, length=FLAG.length, tau_s=2.5e-4)


@pytest.fixture(scope="module")
def pki(tmp_path_factory: pytest.TempPathFactory) -> Pki:
    return make_pki(tmp_path_factory.mktemp("pki"))


def rate(t_us: int, rate_hz: float) -> EventRate:
    return EventRate("cam0", t_us, 0.1, int(rate_hz * 0.1), rate_hz, 0.5)


def intruders(pki: Pki) -> dict[str, dict]:
    """How each intruder tries to join: trusting the rig's CA (so the router's certificate is taken)."""
    other = pki.other
    return {
        "no certificate": {"ca": pki.ca},
        "another CA's certificate": {"ca": pki.ca, "cert": other / "operator.pem", "key": other / "operator.key"},
        "an expired certificate": {"ca": pki.ca, "cert": pki.rig / "expired.pem", "key": pki.rig / "expired.key"},
        "plain TCP": {"ca": None, "scheme": "tcp"},
        "a valid operator certificate (control)": {
            "ca": pki.ca,
            "cert": pki.rig / "operator.pem",
            "key": pki.rig / "operator.key",
        },
    }


@pytest.mark.parametrize(
    "who",
    [
        "no certificate",
        "another CA's certificate",
        "an expired certificate",
        "plain TCP",
        "a valid operator certificate (control)",
    ],
)
def test_an_intruder_without_a_valid_certificate_cannot_join_a_secured_router(
    pki: Pki, tmp_path: Path, who: str
) -> None:
    """It has no link to the router, receives none of the rig's messages (a rig service gets them
    meanwhile), and its command does not reach the recorder's subscription, where a legitimate command
    sent after it arrives. The control, an operator's valid certificate, joins, hears and commands."""
    control = "control" in who
    port = free_port()
    rig = load(tmp_path / "rig.yaml", rig_text(port, pki))
    keys_ns = rig.bus_config.namespace
    with ExitStack() as stack:
        stack.enter_context(Bus(router_config(rig, port)))
        camera, supervisor, recorder = (
            stack.enter_context(Bus(rig.bus_config_for([n]))) for n in ("camera", "supervisor", "recorder")
        )
        keys = camera.keys
        rates = supervisor.subscribe(keys.event_rate("cam0"), EventRate)
        commands = recorder.subscribe(keys.recorder_command(), RecorderCommand)
        wait_subscribed(camera, keys.event_rate("cam0"))
        wait_subscribed(supervisor, keys.recorder_command())
        heard: list[str] = []
        try:
            session = zenoh.open(intruder_config(port, **intruders(pki)[who]))
        except zenoh.ZError:
            session = None  # (a peer that cannot connect still opens: this is a bonus)
        if session is not None:
            stack.callback(session.close)
            own = keys.recorder_command()  # (its own put is delivered to it locally)
            session.declare_subscriber(
                f"{keys_ns}/**", lambda s: heard.append(str(s.key_expr)) if str(s.key_expr) != own else None
            )
            evil = session.declare_publisher(keys.recorder_command())
            if control:
                wait_until(lambda: evil.matching_status.matching, 10, "the control's command to find the recorder")
            evil.put(_bytes(RecorderCommand("start", path="intruder", request_id="evil")))
        supervisor.publisher(keys.recorder_command()).put(RecorderCommand("stop", request_id="legit"))
        got = [wait_until(lambda: commands.recv(timeout_s=0.1), 10, "the legitimate command")]
        if control:  # the two sessions' commands come in either order: both, then nothing more
            got += [wait_until(lambda: commands.recv(timeout_s=0.1), 10, "the control's forged command")]
        got += [msg for msg in iter(lambda: commands.recv(timeout_s=0.2), None)]
        publisher, sent = camera.publisher(keys.event_rate("cam0")), 0

        def rig_traffic_seen() -> bool:  # a rate every 20 ms until the supervisor (and the control) hear them
            nonlocal sent
            sent += 1
            publisher.put(rate(sent * 100_000, 1e5))
            return rates.recv(timeout_s=0.02) is not None and (bool(heard) or not control)

        wait_until(rig_traffic_seen, 10, "the rig's rates")
        links = session.info.routers_zid() + session.info.peers_zid() if session is not None else []
    ids = sorted(msg.request_id for msg in got)
    if control:
        assert ids == ["evil", "legit"] and any(key.endswith("/rate") for key in heard) and links
    else:
        assert ids == ["legit"] and heard == [] and links == []


def _bytes(message: object) -> bytes:
    from flagtrack.daemon.schema import encode

    return encode(message)


def event_packets(stream_id: int, t0_us: int = 0, n: int = 40) -> list[EventPacket]:
    events = np.concatenate(list(line_events(FLAG, t0_us, t0_us + n * 1000, 640, 480)))
    packets = Packetizer("evt3", 640, 480, PacketParams(packet_us=1000)).push(events, None, t_until_us=t0_us + n * 1000)
    return [
        EventPacket(
            "cam0",
            seq,
            p.t_first_us,
            p.t_last_us,
            p.n_events,
            640,
            480,
            "evt3",
            1,
            p.t_offset_us,
            stream_id=stream_id,
            data=p.data,
        )
        for seq, p in enumerate(packets)
    ]


def forged_centrelines() -> CentrelineMessage:
    one = np.zeros((1, 5))
    return CentrelineMessage(
        "forged",
        0,
        "px",
        np.array([0.0]),
        np.linspace(0, 1, 5),
        one,
        one,
        np.zeros((1, 3)),
        np.zeros((1, 3)),
        np.zeros(1),
        np.zeros(1),
        np.zeros(1),
        np.ones(1, np.int64),
        np.ones(1, np.int64),
    )


def start(stack: ExitStack, service: object) -> None:
    """Run ``service`` in a thread until ``stack`` closes (before the buses opened earlier close)."""
    stop = threading.Event()
    thread = threading.Thread(target=service.run, args=(stop,), daemon=True)  # type: ignore[attr-defined]
    thread.start()

    def stop_service() -> None:
        stop.set()
        thread.join(20)
        assert not thread.is_alive()

    stack.callback(stop_service)


def send_forged(intruder: Bus, wait: bool) -> None:
    """What the intruder sends: a recorder command, 10 packets of another stream, an event rate of
    10^12/s and a centreline message (``wait``: until each key has a subscriber, which it can know)."""
    keys = intruder.keys
    forged = {
        key: intruder.publisher(key)
        for key in (keys.recorder_command(), keys.camera_events("cam0"), keys.event_rate("cam0"), keys.centrelines())
    }
    if wait:
        wait_subscribed(intruder, *forged)
    forged[keys.recorder_command()].put(RecorderCommand("start", path="intruder", request_id="evil"))
    for packet in event_packets(stream_id=999, t0_us=50_000_000, n=10):
        forged[keys.camera_events("cam0")].put(packet)
    forged[keys.event_rate("cam0")].put(rate(1, 1e12))
    forged[keys.centrelines()].put(forged_centrelines())


@pytest.mark.parametrize("secured", [True, False], ids=["secured", "unsecured (control)"])
def test_a_valid_identity_cannot_send_what_is_not_its_own(pki: Pki, tmp_path: Path, secured: bool) -> None:
    """An intruder holding the viewer's valid certificate sends a recorder command, event packets of
    another stream, an event rate and a centreline message. On the secured bus none reaches the
    recorder, the tracker or the supervisor's monitor, while the rig's own messages sent after them
    do; on an unsecured bus the same messages reach all three."""
    port = free_port()
    rig = load(tmp_path / "rig.yaml", rig_text(port, pki if secured else None))
    params = TRACKING.tracker_params()
    with ExitStack() as stack:
        stack.enter_context(Bus(router_config(rig, port)))
        bus = {
            name: stack.enter_context(Bus(rig.bus_config_for([name])))
            for name in ("camera", "tracker", "recorder", "supervisor", "viewer")
        }
        keys = bus["camera"].keys
        recorder = RecorderService(bus["recorder"], RecorderConfig(directory=tmp_path / "rec"))
        recorder.start()
        tracker = TrackerService(
            bus["tracker"], TrackerServiceConfig(status_interval_s=0.2), lambda: Tracker(params, sensor_size=(640, 480))
        )
        tracker.start()
        tracker.warm_up()
        monitor = BusMonitor(bus["supervisor"], "cam0", OnsetParams(), ())
        seen = bus["supervisor"].subscribe(keys.centrelines(), CentrelineMessage)  # all that reach the supervisor
        statuses = bus["supervisor"].subscribe(keys.recorder_status(), RecorderStatus)
        start(stack, recorder)
        start(stack, tracker)
        wait_subscribed(bus["camera"], keys.camera_events("cam0"), keys.event_rate("cam0"))
        wait_subscribed(bus["supervisor"], keys.recorder_command())
        wait_subscribed(bus["tracker"], keys.centrelines())
        monitor.start_collecting()

        send_forged(bus["viewer"], wait=not secured)  # (on the unsecured bus the control's are all delivered)

        # then the rig's own: the supervisor starts a recording, the camera sends its stream and rates
        bus["supervisor"].publisher(keys.recorder_command()).put(
            RecorderCommand("start", path="legit", request_id="ok")
        )
        wait_until(
            lambda: any(s.request_id == "ok" for s in iter(lambda: statuses.recv(timeout_s=0.05), None)),
            10,
            "the recorder's answer to the supervisor",
        )
        packets = event_packets(stream_id=1, n=40)
        camera_pub, rate_pub = (
            bus["camera"].publisher(keys.camera_events("cam0")),
            bus["camera"].publisher(keys.event_rate("cam0")),
        )
        for seq, packet in enumerate(packets):
            camera_pub.put(packet)
            if seq % 10 == 9:
                rate_pub.put(rate(packet.t_last_us, 2e6))
        wait_until(
            lambda: (
                tracker.packets >= len(packets) + (0 if secured else 10)  # (unsecured: the forged ones too)
                and recorder.current is not None
                and recorder.current.packets >= len(packets)
            ),
            20,
            "the camera's packets at tracker and recorder",
        )

        sources: set[str] = set()

        def legit_seen() -> bool:  # the camera's last rate at the monitor, the tracker's centrelines at the spy
            monitor.pump()
            sources.update(msg.source for msg in iter(lambda: seen.recv(timeout_s=0), None))
            c = monitor.collection
            return c is not None and 2e6 in c.rates_hz and "tracker" in sources

        wait_until(legit_seen, 20, "the camera's rates and the tracker's centrelines at the supervisor")
        collection = monitor.stop_collecting()
    rates_hz = set(collection.rates_hz)
    intruder_files = sorted(p.name for p in (tmp_path / "rec").glob("intruder*"))
    if secured:
        assert rates_hz == {2e6} and sources == {"tracker"} and intruder_files == []
        assert tracker.packets == len(packets) and tracker.restarts == 0
    else:
        assert 1e12 in rates_hz and "forged" in sources and "intruder.json" in intruder_files
        assert tracker.packets == len(packets) + 10 and tracker.restarts >= 1


@pytest.mark.parametrize("secured", [True, False], ids=["secured", "unsecured"])
def test_a_recorder_command_naming_a_path_outside_its_folder_is_refused(
    pki: Pki, tmp_path: Path, secured: bool, caplog: pytest.LogCaptureFixture
) -> None:
    """From the supervisor, which may command the recorder: an absolute path elsewhere, '..', a link
    out of the folder and '~nosuchuser' each get an error status and write nothing; a path inside is
    recorded, and the recorder logs the command with the session it came from."""
    port = free_port()
    rig = load(tmp_path / "rig.yaml", rig_text(port, pki if secured else None))
    rec, outside = tmp_path / "rec", tmp_path / "outside"
    rec.mkdir()
    outside.mkdir()
    (rec / "link").symlink_to(outside)
    bad = {"a": str(outside / "evil"), "b": "../outside/evil", "c": "link/evil", "d": "~nosuchuser/x"}
    with caplog.at_level(logging.INFO, logger="flagtrack.daemon.services.recorder"), ExitStack() as stack:
        stack.enter_context(Bus(router_config(rig, port)))
        recorder_bus, supervisor = (
            stack.enter_context(Bus(rig.bus_config_for([n]))) for n in ("recorder", "supervisor")
        )
        recorder = RecorderService(recorder_bus, RecorderConfig(directory=rec))
        recorder.start()
        start(stack, recorder)
        keys = supervisor.keys
        statuses = supervisor.subscribe(keys.recorder_status(), RecorderStatus)
        commands = supervisor.publisher(keys.recorder_command(), tag_source=True)
        wait_subscribed(supervisor, keys.recorder_command())
        wait_subscribed(recorder_bus, keys.recorder_status())
        for request, path in bad.items():
            commands.put(RecorderCommand("start", path=path, request_id=request))
        commands.put(RecorderCommand("start", path="inside", request_id="ok"))
        replies: dict[str, RecorderStatus] = {}

        def answered() -> bool:
            while (msg := statuses.recv(timeout_s=0.05)) is not None:
                replies[msg.request_id] = msg
            return "ok" in replies

        wait_until(answered, 10, "the answer to the command inside the folder")
        assert recorder.current is not None and recorder.current.base == rec / "inside"
    assert {r: replies[r].state for r in bad} == dict.fromkeys(bad, "error")
    assert all("refused" in replies[r].message for r in bad) and replies["ok"].state == "recording"
    assert list(outside.iterdir()) == [] and sorted(p.name for p in rec.iterdir()) == ["inside.json", "link"]
    assert recorder.refused_commands == 4
    accepted = [r.getMessage() for r in caplog.records if r.getMessage().startswith("recorder: start /")]
    assert (
        len(accepted) == 1 and "inside" in accepted[0] and f"on {keys.recorder_command()} from session" in accepted[0]
    )


def test_user_and_password_on_top_of_tls(pki: Pki, tmp_path: Path) -> None:
    """The router takes the users of its users_file: the rig's password joins, another is refused, and
    neither appears in the error or the records."""
    users = tmp_path / "users"
    users.write_text("rig:s3cret-pw\n")
    users.chmod(0o600)
    port = free_port()

    def rig(password: str):
        auth = f"    user: rig\n    password: {password}\n    users_file: {users}\n"
        return load(tmp_path / "rig.yaml", rig_text(port, pki) + auth)

    with Bus(router_config(rig("s3cret-pw"), port)):
        with Bus(rig("s3cret-pw").bus_config_for(["camera"])) as camera:
            assert camera.session.info.routers_zid()
        with pytest.raises(ConfigError) as refused:
            Bus(rig("not-it").bus_config_for(["camera"]))
    assert "not-it" not in str(refused.value) and "s3cret" not in str(refused.value)
    assert "s3cret" not in json.dumps(rig("s3cret-pw").snapshot())
