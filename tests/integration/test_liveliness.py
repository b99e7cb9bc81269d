"""A service's liveliness token lives exactly as long as the service runs: a real camera service that
reaches the end of its file, or fails, is seen gone by a real Zenoh liveliness subscriber in another
session while the session that ran it stays open and its other services stay alive."""

from __future__ import annotations

import threading
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from flagtrack.daemon.errors import DriverError
from flagtrack.daemon.services.camera import CameraService, CameraStreamConfig
from flagtrack.daemon.services.runner import ServiceGroup
from flagtrack.daemon.transport import Bus, BusConfig
from flagtrack.drivers.camera.replay import ReplayCamera, ReplayConfig
from flagtrack.drivers.formats import write_events
from flagtrack.drivers.sim.quickline import QuickLineParams, WavyFlag, line_events
from tests.integration.test_transport import free_port, wait_for


class Heartbeat:
    """A service that is alive until stopped (as a tracker waiting for packets is)."""

    name = "heartbeat"

    def __init__(self, bus: Bus) -> None:
        self.bus = bus

    def start(self) -> None:
        pass

    def run(self, stop: threading.Event) -> None:
        self.bus.declare_alive(self.name)
        stop.wait()


@pytest.fixture()
def buses() -> Iterator[tuple[Bus, Bus]]:
    """The services' session (listening) and an observer's session (connecting)."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with (
        Bus(BusConfig(namespace="flagtrack/alive", listen=(endpoint,))) as services,
        Bus(BusConfig(namespace="flagtrack/alive", connect=(endpoint,))) as observer,
    ):
        yield services, observer


def recording(path: Path) -> Path:
    flag = WavyFlag(length=200.0, root=(100.0, 240.0))
    events = np.concatenate(list(line_events(flag, 0, 50_000, 640, 480, QuickLineParams(noise_rate_hz=1e4))))
    write_events(path, events, width=640, height=480, encoding="evt3")
    return path


@pytest.mark.parametrize("source", ["end_of_file", "failure"])
def test_a_camera_that_ends_or_fails_is_seen_gone_while_the_session_stays(
    buses: tuple[Bus, Bus], tmp_path: Path, source: str
) -> None:
    bus, observer = buses
    if source == "end_of_file":
        path = recording(tmp_path / "flag.raw")
    else:  # opens after the token is declared, then fails: a CSV file that does not give the sensor size
        path = tmp_path / "nosize.csv"
        path.write_text("0,1,1,1\n10,2,2,0\n")
    watch = observer.watch_liveliness()
    bus.declare_alive("probe")  # (seen by the observer: its subscription is in place before a camera comes and goes)
    assert wait_for(lambda: watch.is_alive(bus.keys.alive("probe")), timeout_s=20.0)
    camera = CameraService(bus, CameraStreamConfig(id="cam0"), ReplayCamera(ReplayConfig(path, speed=0.0)))
    group = ServiceGroup([Heartbeat(bus), camera], on_service_end=bus.undeclare_alive)
    camera_key, heartbeat_key = bus.keys.alive("camera/cam0"), bus.keys.alive("heartbeat")
    group.start()
    try:
        assert wait_for(lambda: camera_key in watch.gone, timeout_s=20.0), watch.alive
        assert watch.gone[0] == camera_key and not watch.is_alive(camera_key) and not bus.session.is_closed()
        if source == "failure":  # the failure then stops the others, which go too
            # (the token goes in the service's `finally`, before its error is stored)
            assert wait_for(lambda: "camera/cam0" in group.report.errors)
            assert isinstance(group.report.errors["camera/cam0"], DriverError)
        else:  # the other service carries on, alive, in the same session
            assert camera.events > 1000 and "camera/cam0" not in group.report.errors
            assert wait_for(lambda: watch.is_alive(heartbeat_key)) and heartbeat_key not in watch.gone
    finally:
        group.shutdown(timeout_s=10.0)
    assert wait_for(lambda: heartbeat_key in watch.gone)  # ended by the stop: gone too, before the session closes
    assert watch.gone == [camera_key, heartbeat_key] and not bus.session.is_closed()
