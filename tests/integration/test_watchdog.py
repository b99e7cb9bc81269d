"""Service watchdogs with a real AF_UNIX datagram socket standing in for systemd: a service process says
READY, pings and STOPPING; a real recorder whose loop hangs in a disk write stops the pings while the
process lives, and they resume when the write returns."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import threading
import uuid
from collections.abc import Iterator
from pathlib import Path

import pytest

from flagtrack.daemon.schema import EventPacket
from flagtrack.daemon.services import sd_notify
from flagtrack.daemon.services.recorder import RecorderConfig, RecorderService
from flagtrack.daemon.services.runner import run_services
from flagtrack.daemon.services.sd_notify import beat
from flagtrack.daemon.transport import Bus, BusConfig
from tests.fakes.helpers import wait_subscribed, wait_until
from tests.integration.test_transport import free_port


@pytest.fixture
def systemd_socket() -> Iterator[tuple[socket.socket, str]]:
    """A datagram socket in the abstract namespace, as systemd's; yields (socket, $NOTIFY_SOCKET)."""
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    name = f"@flagtrack-test-{uuid.uuid4().hex}"
    sock.bind(b"\0" + name[1:].encode())
    try:
        yield sock, name
    finally:
        sock.close()


def messages(sock: socket.socket, quiet_s: float) -> list[str]:
    """Datagrams until none comes for ``quiet_s``."""
    got = []
    sock.settimeout(quiet_s)
    try:
        while True:
            got.append(sock.recv(4096).decode())
    except TimeoutError:
        return got


def test_a_service_process_is_ready_pings_and_says_stopping(systemd_socket, tmp_path: Path) -> None:
    sock, name = systemd_socket
    rig = tmp_path / "rig.yaml"
    port = free_port()
    rig.write_text(f"""
rig: notify
bus: {{mode: peer, listen: ["tcp/127.0.0.1:{port}"]}}
recorder: {{directory: {tmp_path / "rec"}}}
""")
    env = {**os.environ, "NOTIFY_SOCKET": name, "WATCHDOG_USEC": "1000000"}  # WatchdogSec=1
    proc = subprocess.Popen(
        [sys.executable, "-m", "flagtrack.daemon", "recorder", "-c", str(rig)],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        sock.settimeout(60.0)
        assert sock.recv(4096).decode() == "READY=1\nWATCHDOG=1\nSTATUS=recorder: idle, 0 packets lost"
        sock.settimeout(5.0)
        assert sock.recv(4096).decode().startswith("WATCHDOG=1\n")  # within half of WatchdogSec
    finally:
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=30)
    assert proc.returncode == 130, err
    assert messages(sock, 0.2)[-1] == "STOPPING=1"


def test_a_hung_recorder_loop_stops_the_pings_while_the_process_lives(
    systemd_socket, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    sock, name = systemd_socket
    monkeypatch.setenv("NOTIFY_SOCKET", name)
    monkeypatch.setenv("WATCHDOG_USEC", "200000")  # a ping every 100 ms
    monkeypatch.delenv("WATCHDOG_PID", raising=False)
    release, hanging = threading.Event(), threading.Event()
    real_write = RecorderService._write_raw_packet

    def stuck_disk(self: RecorderService, *item: object) -> None:  # a write that never returns (dead NFS)
        hanging.set()
        release.wait(30.0)
        real_write(self, *item)

    monkeypatch.setattr(RecorderService, "_write_raw_packet", stuck_disk)
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with Bus(BusConfig(namespace="flagtrack/dog", listen=(endpoint,))) as bus:
        recorder = RecorderService(bus, RecorderConfig(directory=tmp_path, path="m"))
        stop_runner = threading.Event()

        class Ender:  # another service of the process, beating on; its end ends the group
            name = "test"

            def start(self) -> None:
                pass

            def run(self, stop: threading.Event) -> None:
                while not stop_runner.wait(0.01):
                    beat(self.name)

        runner = threading.Thread(
            target=run_services,
            args=([recorder, Ender()],),
            kwargs={"handle_signals": False, "stop_when_any_finishes": ["test"]},
        )
        runner.start()
        try:
            sock.settimeout(30.0)
            assert sock.recv(4096).startswith(b"READY=1\nWATCHDOG=1\nSTATUS=recorder: m.raw, 0 packets lost")
            wait_subscribed(bus, bus.keys.camera_events("cam0"))
            bus.publisher(bus.keys.camera_events("cam0")).put(
                EventPacket("cam0", 0, 0, 999, 0, 640, 480, "evt3", 0, data=b"")
            )
            wait_until(hanging.is_set, 10.0, "the recorder's write to hang")
            # the ping owed to the recorder's last beat (sent on the other service's beat) is out
            wait_until(lambda: sd_notify._current is not None and sd_notify._current.awaits("recorder"), 10.0)
            messages(sock, 0.01)
            assert messages(sock, 1.0) == []  # five watchdog periods without a ping: systemd kills here
            assert runner.is_alive()
            release.set()  # the write returns: the loop beats again
            sock.settimeout(5.0)
            assert sock.recv(4096).startswith(b"WATCHDOG=1\n")
        finally:
            release.set()
            stop_runner.set()
            runner.join(15.0)
    assert not runner.is_alive()
    assert recorder.current is None and (tmp_path / "m.raw").exists()
