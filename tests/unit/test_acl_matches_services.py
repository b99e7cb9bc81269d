"""The access-control rules give each service what it really subscribes to, publishes and declares (read
off the services themselves on a bus that records the calls), so a service that starts using another
key is not silently denied on a secured bus."""

from __future__ import annotations

import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest

from flagtrack.daemon.core.onset import OnsetParams
from flagtrack.daemon.rig.access import role_rights
from flagtrack.daemon.rig.build import BusSpeedSource
from flagtrack.daemon.schema import Keys
from flagtrack.daemon.security.acl import Rights
from flagtrack.daemon.services.recorder import RecorderConfig, RecorderService
from flagtrack.daemon.services.supervisor.monitor import BusMonitor
from flagtrack.daemon.services.tracker import TrackerService, TrackerServiceConfig
from flagtrack.daemon.services.viewer import ViewerConfig, ViewerService


class _Sink:
    def __init__(self, used: set[str], key: str) -> None:
        self.key = key
        used.add(key)
        self.channel = _Channel()
        self.malformed = 0
        self.origin = ""

    def put(self, message: Any) -> None:
        pass

    def recv(self, timeout_s: float | None = None) -> None:
        return None

    def recv_raw(self, timeout_s: float | None = None) -> None:
        return None


class _Channel:
    dropped = 0

    def drain(self) -> list:
        return []

    def __len__(self) -> int:
        return 0


@dataclass
class RecordingBus:
    """A bus that records which keys a service subscribes to, publishes on and declares alive."""

    keys: Keys = field(default_factory=lambda: Keys("flagtrack/lab1"))
    subscribed: set[str] = field(default_factory=set)
    published: set[str] = field(default_factory=set)
    tokens: set[str] = field(default_factory=set)
    watches: bool = False

    def subscribe(self, key: str, *args: Any, **kwargs: Any) -> _Sink:
        return _Sink(self.subscribed, key)

    def publisher(self, key: str, **kwargs: Any) -> _Sink:
        return _Sink(self.published, key)

    def declare_alive(self, service: str) -> None:
        self.tokens.add(self.keys.alive(service))

    def undeclare_alive(self, service: str) -> int:
        return 0

    def watch_liveliness(self) -> Any:
        self.watches = True
        return type("Watch", (), {"is_alive": lambda self, key: False})()


def stopped() -> threading.Event:
    stop = threading.Event()
    stop.set()
    return stop


def covered(bus: RecordingBus, rights: Rights) -> None:
    assert bus.subscribed <= set(rights.subscribe), bus.subscribed - set(rights.subscribe)
    assert bus.published <= set(rights.publish), bus.published - set(rights.publish)
    assert bus.tokens <= set(rights.tokens), bus.tokens - set(rights.tokens)
    assert rights.watch or not bus.watches


def rights(bus: RecordingBus, role: str) -> Rights:
    return role_rights(bus.keys, role, ["cam0"], ["om70"])


def test_the_trackers_keys() -> None:
    bus = RecordingBus()
    service = TrackerService(bus, TrackerServiceConfig(), lambda: None)
    service.warm_up = lambda: None  # type: ignore[method-assign]
    service.start()
    service.run(stopped())
    covered(bus, rights(bus, "tracker"))
    assert bus.published == {bus.keys.centrelines(), bus.keys.tracker_status()}


def test_the_recorders_keys(tmp_path: Path) -> None:
    bus = RecordingBus()
    recorder = RecorderService(bus, RecorderConfig(directory=tmp_path))
    recorder.start()
    recorder.run(stopped())
    covered(bus, rights(bus, "recorder"))
    assert bus.keys.recorder_command() in bus.subscribed and bus.tokens == {bus.keys.alive("recorder")}


def test_the_viewers_keys() -> None:
    bus = RecordingBus()
    viewer = ViewerService(bus, ViewerConfig(sink="none"))
    viewer.start()
    viewer.run(stopped())
    covered(bus, rights(bus, "viewer"))
    assert bus.published == set()


@pytest.mark.parametrize("sensor", [None, "om70"])
def test_the_supervisors_watch(sensor: str | None) -> None:
    bus = RecordingBus()
    BusMonitor(bus, "cam0", OnsetParams(), ("camera", "tracker", "recorder"), sensor)
    covered(bus, rights(bus, "supervisor"))
    assert bus.watches


def test_a_simulated_camera_follows_the_tunnel_state() -> None:
    bus = RecordingBus()
    BusSpeedSource(bus)()  # type: ignore[arg-type]  # (it subscribes at its first call, in the camera's loop)
    covered(bus, rights(bus, "camera"))


def test_the_flag_state_services_keys() -> None:
    from flagtrack.daemon.core.flagstate import StateParams
    from flagtrack.daemon.services.flagstate import FlagStateService

    bus = RecordingBus()
    service = FlagStateService(bus, StateParams(300.0), "cam0")  # type: ignore[arg-type]
    service.start()
    service.run(stopped())
    covered(bus, rights(bus, "flagstate"))
    assert bus.published == {bus.keys.flag_state()} and bus.tokens == {bus.keys.alive("flagstate")}


def test_the_supervisors_speed_requests_and_states() -> None:
    from flagtrack.daemon.schema import FlagState
    from flagtrack.daemon.services.supervisor.requests import SpeedDesk
    from flagtrack.daemon.transport import BusConfig

    bus = RecordingBus()
    bus.cfg = BusConfig(namespace="flagtrack/lab1")  # type: ignore[attr-defined]
    SpeedDesk(bus).start()  # type: ignore[arg-type]
    bus.subscribe(bus.keys.flag_state(), FlagState)  # (mode control's)
    covered(bus, rights(bus, "supervisor"))
    assert bus.keys.speed_reply() in bus.published and bus.keys.speed_requests() in bus.subscribed
