"""sd_notify: READY once every loop has beaten, pings only while all keep beating, over a real AF_UNIX
datagram socket standing in for systemd."""

from __future__ import annotations

import os
import socket
import threading
import uuid
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from flagtrack.daemon.services import sd_notify
from flagtrack.daemon.services.runner import run_services
from flagtrack.daemon.services.sd_notify import Notifier, Watchdog, notify_address, watchdog_interval_s
from tests.fakes.helpers import wait_until


class FakeClock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def test_ready_waits_for_every_service_and_pings_need_every_loop() -> None:
    sent: list[str] = []
    clock = FakeClock()
    dog = Watchdog(["camera/cam0", "tracker"], sent.append, interval_s=1.0, clock=clock)
    dog.beat("camera/cam0", "10 packets")
    assert sent == [] and not dog.ready  # the tracker has not reached its loop yet (warming up)
    dog.beat("tracker", "5 updates")
    assert sent == ["READY=1\nWATCHDOG=1\nSTATUS=camera/cam0: 10 packets; tracker: 5 updates"]
    clock.t = 2.0
    for _ in range(50):  # the tracker's loop hangs: the camera beats on, no ping
        dog.beat("camera/cam0", "11 packets")
    assert len(sent) == 1
    dog.beat("tracker")
    assert sent[-1] == "WATCHDOG=1\nSTATUS=camera/cam0: 11 packets; tracker: 5 updates"
    clock.t = 2.5  # both beat again, but within the period: no ping yet
    dog.beat("camera/cam0")
    dog.beat("tracker")
    assert len(sent) == 2 and dog.pings == 2
    dog.beat("someone-else")  # not a service of this group: ignored
    clock.t = 4.0
    dog.retire("camera/cam0")  # a replay that reached its end: the tracker alone keeps the pings going
    dog.beat("tracker")
    assert sent[-1] == "WATCHDOG=1\nSTATUS=tracker: 5 updates" and dog.pings == 3
    dog.stopping()
    clock.t = 10.0
    dog.beat("camera/cam0")
    dog.beat("tracker")
    assert sent[-1] == "STOPPING=1" and len(sent) == 4


def test_without_watchdog_usec_only_ready_and_status_are_sent() -> None:
    sent: list[str] = []
    clock = FakeClock()
    dog = Watchdog(["recorder"], sent.append, interval_s=None, clock=clock)
    dog.beat("recorder", "idle")
    clock.t = 1.0
    dog.beat("recorder", "idle")  # within STATUS_INTERVAL_S
    clock.t = sd_notify.STATUS_INTERVAL_S + 0.1
    dog.beat("recorder", "a.raw, 0 packets lost")
    assert sent == ["READY=1\nSTATUS=recorder: idle", "STATUS=recorder: a.raw, 0 packets lost"]


@pytest.mark.parametrize(
    ("env", "address"),
    [
        ({}, None),
        ({"NOTIFY_SOCKET": ""}, None),
        ({"NOTIFY_SOCKET": "/run/systemd/notify"}, "/run/systemd/notify"),
        ({"NOTIFY_SOCKET": "@/org/freedesktop/systemd1/notify/123"}, b"\0/org/freedesktop/systemd1/notify/123"),
        ({"NOTIFY_SOCKET": "vsock:2:1234"}, None),
    ],
)
def test_notify_address(env: dict[str, str], address: object) -> None:
    assert notify_address(env) == address


@pytest.mark.parametrize(
    ("env", "interval_s"),
    [
        ({}, None),
        ({"WATCHDOG_USEC": "20000000"}, 10.0),
        ({"WATCHDOG_USEC": "0"}, None),
        ({"WATCHDOG_USEC": "abc"}, None),
        ({"WATCHDOG_USEC": "2²"}, None),
        ({"WATCHDOG_USEC": "20000000", "WATCHDOG_PID": "1"}, None),  # meant for another process
        ({"WATCHDOG_USEC": "20000000", "WATCHDOG_PID": str(os.getpid())}, 10.0),
    ],
)
def test_watchdog_interval(env: dict[str, str], interval_s: float | None) -> None:
    assert watchdog_interval_s(env) == interval_s


@pytest.fixture
def systemd_socket(tmp_path: Path) -> Iterator[tuple[socket.socket, str]]:
    """A real AF_UNIX datagram socket where systemd's would be; yields (socket, $NOTIFY_SOCKET)."""
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    name = f"@flagtrack-test-{uuid.uuid4().hex}"  # the abstract namespace, as systemd's own
    sock.bind(b"\0" + name[1:].encode())
    sock.settimeout(5.0)
    try:
        yield sock, name
    finally:
        sock.close()


def test_notifier_reaches_a_path_and_an_abstract_socket(tmp_path: Path, systemd_socket) -> None:
    abstract, name = systemd_socket
    path = tmp_path / "notify"
    by_path = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    by_path.bind(str(path))
    by_path.settimeout(5.0)
    for sock, env in ((abstract, name), (by_path, str(path))):
        notifier = Notifier(notify_address({"NOTIFY_SOCKET": env}))
        assert notifier.send("READY=1")
        assert sock.recv(4096) == b"READY=1"
        notifier.close()
    by_path.close()
    path.unlink()
    gone = Notifier(str(path))  # systemd went away: the service goes on
    assert gone.send("WATCHDOG=1") is False
    gone.close()
    assert Notifier(None).send("READY=1") is False


@dataclass
class Beating:
    """A service whose loop beats; ``hang`` set makes the loop block (as a stuck device read would)."""

    name: str
    hang: threading.Event = field(default_factory=threading.Event)
    release: threading.Event = field(default_factory=threading.Event)
    done: threading.Event = field(default_factory=threading.Event)
    ticks: int = 0
    hanging: bool = False

    def start(self) -> None:
        pass

    def run(self, stop: threading.Event) -> None:
        while not stop.wait(0.002) and not self.done.is_set():
            sd_notify.beat(self.name, f"{self.ticks} ticks")
            self.ticks += 1
            if self.hang.is_set():
                self.hanging = True
                self.release.wait(30.0)
                self.hanging = False


def received(sock: socket.socket, timeout_s: float) -> list[str]:
    """Every datagram that arrives within ``timeout_s`` of the previous one."""
    got = []
    sock.settimeout(timeout_s)
    try:
        while True:
            got.append(sock.recv(4096).decode())
    except TimeoutError:
        return got


def test_a_hung_loop_stops_the_pings_while_the_process_lives(monkeypatch: pytest.MonkeyPatch, systemd_socket) -> None:
    sock, name = systemd_socket
    monkeypatch.setenv("NOTIFY_SOCKET", name)
    monkeypatch.setenv("WATCHDOG_USEC", "100000")  # WatchdogSec=0.1: a ping every 50 ms
    monkeypatch.delenv("WATCHDOG_PID", raising=False)
    camera, tracker = Beating("camera/cam0"), Beating("tracker")
    runner = threading.Thread(
        target=run_services,
        args=([camera, tracker],),
        kwargs={"handle_signals": False, "stop_when_any_finishes": ["camera/cam0"]},
    )
    runner.start()
    try:
        first = sock.recv(4096).decode()
        assert first.startswith("READY=1\nWATCHDOG=1\nSTATUS=camera/cam0: ")
        assert "tracker: " in first
        wait_until(lambda: sock.recv(4096).startswith(b"WATCHDOG=1"), what="a second ping")
        tracker.hang.set()
        wait_until(lambda: tracker.hanging, what="the tracker's loop to hang")
        # the ping owed to the tracker's last beat (sent on a camera beat, under the lock) is out
        wait_until(lambda: sd_notify._current is not None and sd_notify._current.awaits("tracker"))
        received(sock, 0.01)
        ticks = camera.ticks
        assert received(sock, 0.5) == []  # ten watchdog periods: systemd would have killed the process
        assert runner.is_alive() and camera.ticks > ticks + 10  # ... whose other loop still runs
        tracker.release.set()  # the loop comes back: the pings resume
        assert sock.recv(4096).startswith(b"WATCHDOG=1\nSTATUS=")
    finally:
        tracker.release.set()
        camera.done.set()  # the camera's end ends the group
        runner.join(10.0)
    assert not runner.is_alive()
    assert received(sock, 0.5)[-1] == "STOPPING=1"


def test_no_notify_socket_is_a_no_op(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("NOTIFY_SOCKET", raising=False)
    with sd_notify.watching(["tracker"]) as dog:
        assert dog is None
        sd_notify.beat("tracker", "nothing listens")
    assert sd_notify._current is None
