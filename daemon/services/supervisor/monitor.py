"""What the supervisor watches on the bus: event rates (flag state), centrelines, liveliness, recorder."""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import numpy as np

from flagtrack.daemon.core.centreline import CentrelineBatch
from flagtrack.daemon.core.onset import FlagState, OnsetDetector, OnsetParams, OnsetReading
from flagtrack.daemon.problems import ProblemLog
from flagtrack.daemon.schema import CentrelineMessage, EventRate, RecorderStatus, SensorSamples
from flagtrack.daemon.services.supervisor.analysis import MAX_GAP_S
from flagtrack.daemon.transport import Bus

log = logging.getLogger(__name__)

SERVICE_KEYS = {
    "camera": "camera/{camera_id}",
    "tracker": "tracker",
    "recorder": "recorder",
    "viewer": "viewer",
    "flagstate": "flagstate",
}
MAX_REPLIES = 256
"""Recorder answers kept for the supervisor to pick up (the oldest go: others' request ids, forged ones)."""


@dataclass
class Collection:
    """Centrelines, rates and point-sensor samples gathered while a point records.

    ``camera_wall`` holds (camera time µs, wall time ns) of the newest update of each centreline
    message: with the sensor messages' own wall stamps, a rough link between the two clocks.
    """

    batches: list[CentrelineBatch] = field(default_factory=list)
    rates_hz: list[float] = field(default_factory=list)
    units: str = "px"
    sensor: list[SensorSamples] = field(default_factory=list)
    camera_wall: list[tuple[int, int]] = field(default_factory=list)


class BusMonitor:
    """Drains the supervisor's subscriptions (call :meth:`pump` often) and keeps the flag state.

    A message it cannot use is counted (``unusable``), logged rarely and skipped, never raised: an
    event rate whose time is not finite or goes back, or whose rate is negative or infinite; a
    centreline message whose times are not finite and increasing after those already gathered, or
    whose samples or joints differ from the first one's. Every queue is bounded in bytes.

    Args:
        bus: the bus.
        camera_id: the camera watched.
        onset: detector parameters.
        required: services that must stay alive (``camera``, ``tracker``, ``recorder``).
        sensor_id: a point sensor whose samples are gathered with each point (None: no sensor).
    """

    def __init__(
        self, bus: Bus, camera_id: str, onset: OnsetParams, required: tuple[str, ...], sensor_id: str | None = None
    ) -> None:
        keys = bus.keys
        self.rates = bus.subscribe(keys.event_rate(camera_id), EventRate, capacity=100_000, max_bytes=16 << 20)
        self.lines = bus.subscribe(keys.centrelines(), CentrelineMessage, capacity=1_000_000, max_bytes=256 << 20)
        self.recorder = bus.subscribe(keys.recorder_status(), RecorderStatus, capacity=1000, max_bytes=4 << 20)
        self.sensor = (
            None
            if sensor_id is None
            else bus.subscribe(keys.sensor_samples(sensor_id), SensorSamples, capacity=100_000, max_bytes=64 << 20)
        )
        self.unusable = 0
        self.problems = ProblemLog(log, "supervisor")
        self.liveliness = bus.watch_liveliness()
        self.alive_keys = {name: keys.alive(SERVICE_KEYS[name].format(camera_id=camera_id)) for name in required}
        self.detector = OnsetDetector(onset)
        self.reading: OnsetReading | None = None
        self.last_rate_s = time.monotonic()
        self.rate_hz = float("nan")
        self.collection: Collection | None = None
        self.recorder_replies: dict[str, RecorderStatus] = {}
        self.recorder_error = ""  # the recorder's last unprompted error (a full disk), "" when none
        self.seen: set[str] = set()

    @property
    def state(self) -> FlagState:
        """The flag state from the event rate (unknown before a baseline exists)."""
        return FlagState.UNKNOWN if self.reading is None else self.reading.state

    def pump(self) -> None:
        """Take in everything that arrived (what cannot be used is counted and skipped)."""
        while (rate := self.rates.recv(timeout_s=0)) is not None:
            t_s = rate.t_us * 1e-6
            problem = self.detector.sample_problem(t_s, rate.rate_hz)
            if problem is not None:
                self._unusable("event rates that cannot be used", problem)
                continue
            self.reading = self.detector.update(t_s, rate.rate_hz)
            self.rate_hz = rate.rate_hz
            self.last_rate_s = time.monotonic()
            if self.collection is not None:
                self.collection.rates_hz.append(rate.rate_hz)
        while (msg := self.lines.recv(timeout_s=0)) is not None:
            if self.collection is not None and len(msg.t_s):
                problem = centreline_problem(msg, self.collection)
                if problem is not None:
                    self._unusable("centreline messages that cannot be used", problem)
                    continue
                self.collection.batches.append(msg.batch())
                self.collection.units = msg.units
                if len(msg.source_ns) and msg.source_ns[-1] > 0:
                    self.collection.camera_wall.append((round(float(msg.t_s[-1]) * 1e6), int(msg.source_ns[-1])))
        while self.sensor is not None and (samples := self.sensor.recv(timeout_s=0)) is not None:
            if self.collection is not None:
                self.collection.sensor.append(samples)
        while (status := self.recorder.recv(timeout_s=0)) is not None:
            self._recorder_status(status)
        self.problems.flush()

    def _recorder_status(self, status: RecorderStatus) -> None:
        """Keep a reply for whoever asked; note an unprompted error (a full disk)."""
        if status.state == "error" and not status.request_id:
            self.recorder_error = status.message or "error"
        elif status.state == "recording":
            self.recorder_error = ""
        if status.request_id:
            self.recorder_replies[status.request_id] = status
            while len(self.recorder_replies) > MAX_REPLIES:
                del self.recorder_replies[next(iter(self.recorder_replies))]

    def _unusable(self, kind: str, detail: str) -> None:
        self.unusable += 1
        self.problems.add(kind, detail)

    def start_collecting(self) -> None:
        """Start gathering centrelines and rates (for one point)."""
        self.pump()
        self.collection = Collection()

    def stop_collecting(self) -> Collection:
        """Stop gathering; return what was gathered."""
        self.pump()
        collection, self.collection = self.collection or Collection(), None
        return collection

    def problem(self, silence_timeout_s: float) -> str | None:
        """Why the run cannot go on (a required service gone, or no event rate), or None."""
        for name, key in self.alive_keys.items():
            if self.liveliness.is_alive(key):
                self.seen.add(name)
            elif name in self.seen:
                return f"the {name} service went away (liveliness lost)"
        silent_s = time.monotonic() - self.last_rate_s
        if silent_s > silence_timeout_s:
            return f"no event rate from the camera for {silent_s:.1f} s (camera silent)"
        return None

    def missing(self) -> list[str]:
        """Required services not (yet) alive."""
        return [name for name, key in self.alive_keys.items() if not self.liveliness.is_alive(key)]

    def thresholds_hz(self) -> tuple[float, float]:
        """(on, off) event-rate thresholds in force (nan before a baseline)."""
        if self.reading is None:
            return float("nan"), float("nan")
        return self.reading.on_rate_hz, self.reading.off_rate_hz


def centreline_problem(msg: CentrelineMessage, collection: Collection) -> str | None:
    """Why a centreline message cannot join what ``collection`` gathered, or None: its times are not
    finite and increasing (steps up to :data:`~.analysis.MAX_GAP_S`), do not follow the gathered
    ones within that, or its samples or joints differ from the first message's (another tracker
    set-up). O(updates)."""
    t_s = np.asarray(msg.t_s, dtype=float)
    steps = np.diff(t_s)
    if not np.all(np.isfinite(t_s)) or np.any(steps <= 0) or np.any(steps > MAX_GAP_S):
        return f"centreline message {msg.seq}: times not finite and increasing in steps up to {MAX_GAP_S:g} s"
    if collection.batches:
        first, last = collection.batches[0], collection.batches[-1]
        if not 0 < t_s[0] - last.t_s[-1] <= MAX_GAP_S:
            return f"centreline message {msg.seq} at {t_s[0]:.6f} s does not follow {last.t_s[-1]:.6f} s"
        if msg.x.shape[1] != first.x.shape[1] or msg.joints_x.shape[1] != first.joints_x.shape[1]:
            return (
                f"centreline message {msg.seq} has {msg.x.shape[1]} samples and {msg.joints_x.shape[1]} joints, "
                f"the point's first {first.x.shape[1]} and {first.joints_x.shape[1]}"
            )
    return None


def point_state(rates_hz: list[float], on_hz: float, off_hz: float, previous: str) -> str:
    """The flag state over a recording from its median rate, with the detector's hysteresis band.

    Above ``on_hz``: flapping; below ``off_hz``: still; in between: as the previous point.
    """
    if not rates_hz or not np.isfinite(on_hz):
        return FlagState.UNKNOWN.value
    median = float(np.median(rates_hz))
    if median >= on_hz:
        return FlagState.FLAPPING.value
    if median <= off_hz:
        return FlagState.STILL.value
    return previous if previous in (FlagState.FLAPPING.value, FlagState.STILL.value) else FlagState.UNKNOWN.value
