"""Fake ``neuromorphic_drivers`` (tests only): the subset of neuromorphic-drivers 0.18 the prophesee adapter uses.

Real API mirrored: ``list_devices() -> [ListedDevice(name, connection, address, serial, error)]``,
``open(configuration=None, iterator_timeout=None, raw=False, serial=None, ...)`` returning a device with
``__next__ -> (RawStatus, bytes | None)`` (None when ``iterator_timeout`` passes without data),
``properties()``, ``serial()``, ``name()``, ``connection()``, ``biases_bounds()``,
``update_configuration(configuration)``, ``close()``, ``temperature_celsius()`` (EVK4), ``backlog()``,
``clear_backlog(until)``, ``overflow()``, and the model
modules ``prophesee_evk4`` and ``centuryarks_vga`` with ``Biases``, ``RateLimiter``, ``Configuration``,
``Properties``, ``BiasesBounds``.

Device behaviour: streams real EVT 3.0 bytes of a flapping line (``_fake_streams``) in buffers of random
sizes; applies the configuration as a sensor would (row/column masks drop events, the rate limiter keeps at
most N events per period, the trigger input on/off, biases clamped to the bounds it reports); can be absent,
refuse to open (``error``), be unplugged (the iterator raises) or stall (no data). The stream is encoded from
the configuration in force at the first read (the adapter configures before reading). The host's ring can
overflow (``ring_drops``: USB packets lost before a given one, counted in ``RawRingStatus.dropped_packets``,
which only grows, and marked by ``overflow_indices``) or fill up (``backlog_at``: packets waiting, which
``clear_backlog(until)`` consumes as the library does: one at a time until fewer than ``until`` wait or
none is left).

Tests drive it through ``_fake``: ``_fake.plug(FakeCamera(...))``, ``_fake.cameras``, ``_fake.reset()``.
"""

from __future__ import annotations

import dataclasses
import enum
import time
from typing import Any

import _fake_streams
import numpy as np

from . import centuryarks_vga, prophesee_evk4
from ._models import RingConfiguration, check_words  # noqa: F401


class Name(enum.Enum):
    INIVATION_DAVIS346 = "iniVation DAVIS 346"
    INIVATION_DVXPLORER = "iniVation DVXplorer"
    PROPHESEE_EVK3_HD = "Prophesee EVK3 HD"
    PROPHESEE_EVK4 = "Prophesee EVK4"
    CENTURYARKS_VGA = "CenturyArks VGA"
    LUCID_TRITON = "Lucid Triton"


class Connection(enum.Enum):
    USB_HIGH = "USB 2.0 High Speed (480 Mb/s)"
    USB_SUPER = "USB 3.0 SuperSpeed (5.0 Gb/s)"


@dataclasses.dataclass
class ListedDevice:
    name: Name
    connection: Connection
    address: str
    serial: str | None
    error: str | None


@dataclasses.dataclass
class RawRingStatus:
    system_time: float
    backlog: int
    raw_packets: int
    clutch_engaged: bool
    overflow_indices: list[int] | None
    dropped_packets: int


@dataclasses.dataclass
class RawStatus:
    system_time: float
    ring: RawRingStatus | None


MODELS = {Name.PROPHESEE_EVK4: prophesee_evk4, Name.CENTURYARKS_VGA: centuryarks_vga}


@dataclasses.dataclass
class FakeCamera:
    """One fake USB camera: what it streams and how it fails.

    Attributes:
        name: model.
        serial: serial number.
        duration_us: camera time of the flapping-line source.
        seed: seed of the source and of the buffer sizes.
        error: listed with this error (permissions) and refuses to open.
        unplug_after_bytes: the iterator raises after this many bytes.
        stall_after_bytes: stops delivering after this many bytes.
        events, triggers: the source (made from duration_us and seed when None).
        ring_drops: USB packet number -> how many packets the host's ring dropped just before it.
        backlog_at: USB packet number -> how many packets wait in the ring when it is delivered.
    """

    name: Name = Name.PROPHESEE_EVK4
    serial: str = "00050423"
    duration_us: int = 200_000
    seed: int = 0
    error: str | None = None
    unplug_after_bytes: int | None = None
    stall_after_bytes: int | None = None
    events: np.ndarray | None = None
    triggers: np.ndarray | None = None
    opened: int = 0
    closed: int = 0
    applied: Any = None  # the Configuration in force, biases as the device clamped them
    sent_events: np.ndarray | None = None  # what the sensor produced under that configuration
    sent_triggers: np.ndarray | None = None
    feed: _fake_streams.ByteFeed | None = None
    ring_drops: dict[int, int] = dataclasses.field(default_factory=dict)
    backlog_at: dict[int, int] = dataclasses.field(default_factory=dict)
    delivered_packets: int = 0  # USB packets handed to the host (dropped ones included)
    dropped_packets: int = 0
    lost: list[tuple[int, int]] = dataclasses.field(default_factory=list)  # byte ranges that never arrived
    cleared: list[int] = dataclasses.field(default_factory=list)  # packets each clear_backlog consumed
    backlog: int = 0

    def __post_init__(self) -> None:
        model = MODELS.get(self.name)
        if model is not None:  # else listed only (an iniVation camera, say): opening it is not faked
            self.applied = model.Configuration()

    def source(self) -> tuple[np.ndarray, np.ndarray]:
        """The scene in front of the sensor (made on first use)."""
        if self.events is None:
            model = MODELS[self.name]
            self.events, self.triggers = _fake_streams.flapping_source(
                model.WIDTH, model.HEIGHT, self.duration_us, seed=self.seed
            )
        return self.events, self.triggers


class _Controller:
    """Test-side control of the fake USB bus."""

    def __init__(self) -> None:
        self.cameras: list[FakeCamera] = []

    def reset(self) -> None:
        self.cameras = []

    def plug(self, camera: FakeCamera) -> FakeCamera:
        self.cameras.append(camera)
        return camera


_fake = _Controller()


def list_devices() -> list[ListedDevice]:
    return [ListedDevice(c.name, Connection.USB_SUPER, "", c.serial, c.error) for c in _fake.cameras]


def open(  # noqa: A001 - the real SDK's name
    configuration: Any = None,
    iterator_timeout: float | None = None,
    raw: bool = False,
    serial: str | None = None,
    address: str | None = None,
    ring_configuration: Any = None,
    iterator_maximum_raw_packets: int = 64,
) -> Device:
    for camera in _fake.cameras:
        if serial is None or camera.serial == serial:
            if camera.error:
                raise RuntimeError(camera.error)
            if configuration is not None and configuration.type() != camera.name.name.lower():
                raise RuntimeError(f"the configuration type {configuration.type()} does not match the device")
            return Device(camera, raw, iterator_timeout, configuration)
    raise RuntimeError(f'device with serial "{serial}" not found' if serial else "no device found")


class Device:
    def __init__(self, camera: FakeCamera, raw: bool, iterator_timeout: float | None, configuration: Any) -> None:
        if not raw:
            raise NotImplementedError("the fake only streams raw bytes (raw=True)")
        self.camera = camera
        self.model = MODELS[camera.name]
        self.iterator_timeout = iterator_timeout
        self._closed = False
        camera.opened += 1
        self.update_configuration(configuration or self.model.Configuration())

    def __enter__(self) -> Device:
        return self

    def __exit__(self, *exc: object) -> bool:
        if not self._closed:
            self._closed = True
            self.camera.closed += 1
        return False

    def close(self) -> None:
        self.__exit__(None, None, None)

    def __iter__(self) -> Device:
        return self

    def __next__(self) -> tuple[RawStatus, bytes | None]:
        if self._closed:
            raise RuntimeError("__next__ called after __exit__")
        camera = self.camera
        if camera.feed is None:
            camera.feed = self._start_stream()
        feed = camera.feed
        if camera.unplug_after_bytes is not None and feed.delivered >= camera.unplug_after_bytes:
            raise RuntimeError("LIBUSB_ERROR_NO_DEVICE: the device was disconnected")
        overflow = self._overflow(feed)
        camera.backlog = camera.backlog_at.get(camera.delivered_packets, max(camera.backlog - 1, 0))
        chunk = self._next_packet(feed)
        if chunk is None:
            if self.iterator_timeout is None:
                raise AssertionError("fake: a blocking iterator with no data would hang")
            time.sleep(self.iterator_timeout)
            return RawStatus(time.time(), None), None
        ring = RawRingStatus(time.time(), camera.backlog, 1, False, [0] if overflow else None, camera.dropped_packets)
        return RawStatus(time.time(), ring), chunk

    def _next_packet(self, feed: _fake_streams.ByteFeed) -> bytes | None:
        chunk = feed.next()
        if chunk is not None:
            self.camera.delivered_packets += 1
        return chunk

    def _overflow(self, feed: _fake_streams.ByteFeed) -> bool:
        """Lose the packets the ring drops before this one (counted); whether any were."""
        camera = self.camera
        n = camera.ring_drops.get(camera.delivered_packets, 0)
        start = feed.delivered
        for _ in range(n):
            if self._next_packet(feed) is None:
                break
            camera.dropped_packets += 1
        if feed.delivered > start:
            camera.lost.append((start, feed.delivered))
        return n > 0

    def backlog(self) -> int:
        return self.camera.backlog

    def clear_backlog(self, until: int) -> None:
        if self._closed:
            raise RuntimeError("__next__ called after __exit__")
        camera, feed = self.camera, self.camera.feed
        start, consumed = (feed.delivered if feed else 0), 0
        while feed is not None and camera.backlog > 0 and self._next_packet(feed) is not None:
            consumed += 1  # one of the packets waiting, taken and dropped
            camera.backlog -= 1
            if camera.backlog < until:
                break
        if consumed:
            camera.lost.append((start, feed.delivered))
        camera.cleared.append(consumed)

    def overflow(self) -> bool:
        return self.camera.dropped_packets > 0

    def name(self) -> Name:
        return self.camera.name

    def serial(self) -> str:
        return self.camera.serial

    def connection(self) -> Connection:
        return Connection.USB_SUPER

    def properties(self) -> Any:
        return self.model.Properties()

    def biases_bounds(self) -> Any:
        bounds = {k: self.model.Bounds(*v) for k, v in self.model.DEVICE_BOUNDS.items()}
        return self.model.BiasesBounds(**bounds)

    def temperature_celsius(self) -> float:
        if self.camera.name != Name.PROPHESEE_EVK4:
            raise AttributeError("temperature_celsius")
        return 36.5

    def update_configuration(self, configuration: Any) -> None:
        if configuration.type() != self.camera.name.name.lower():
            raise RuntimeError("configuration type mismatch")
        defaults = self.model.Configuration()
        check_words("x_mask", configuration.x_mask, len(defaults.x_mask))
        check_words("y_mask", configuration.y_mask, len(defaults.y_mask))
        bounds = self.model.DEVICE_BOUNDS
        clamped = {}
        for f in dataclasses.fields(configuration.biases):  # the DACs hold values within the bounds
            value = getattr(configuration.biases, f.name)
            low, high = bounds.get(f.name, (0, 0))
            clamped[f.name] = min(max(value, low), high)
        self.camera.applied = dataclasses.replace(configuration, biases=type(configuration.biases)(**clamped))

    def _start_stream(self) -> _fake_streams.ByteFeed:
        """Encode what the sensor produces under the applied configuration."""
        camera, cfg = self.camera, self.camera.applied
        events, triggers = camera.source()
        events = events[_unmasked(events, cfg)]
        if cfg.rate_limiter is not None:
            events = _rate_limited(
                events, cfg.rate_limiter.reference_period_us, cfg.rate_limiter.maximum_events_per_period
            )
        triggers = triggers if getattr(cfg, "enable_external_trigger", True) else triggers[:0]
        camera.sent_events, camera.sent_triggers = events, triggers
        data = _fake_streams.encode("evt3", events, triggers, self.model.WIDTH, self.model.HEIGHT)
        return _fake_streams.ByteFeed(data, seed=camera.seed, stall_after_bytes=camera.stall_after_bytes)


def _unmasked(events: np.ndarray, cfg: Any) -> np.ndarray:
    """Events whose column and row are both unmasked (mask_intersection_only False)."""
    x_bits = np.unpackbits(np.array(cfg.x_mask, dtype="<u8").view(np.uint8), bitorder="little").astype(bool)
    y_bits = np.unpackbits(np.array(cfg.y_mask, dtype="<u8").view(np.uint8), bitorder="little").astype(bool)
    return ~x_bits[events["x"]] & ~y_bits[events["y"]]


def _rate_limited(events: np.ndarray, period_us: int, maximum: int) -> np.ndarray:
    """Keep at most ``maximum`` events in each period of ``period_us``."""
    slot = events["t"] // period_us
    starts = np.searchsorted(slot, slot, side="left")
    return events[np.arange(len(events)) - starts < maximum]
