"""Fake ``dv_processing`` (tests only): the subset of dv-processing 2.0 the inivation adapter uses.

Real API mirrored: ``io.camera.open()`` / ``io.camera.open(serialNumber)`` (IndexError / RuntimeError
"Could not find device with given serial number" when absent), ``io.camera.discover()``; cameras of class
``DVXplorer`` or ``DAVIS`` with ``getNextEventBatch() -> EventStore | None`` (non-blocking),
``getNextTriggerBatch()``, ``isTriggerStreamAvailable()``, ``isRunning()``, ``getEventResolution()``,
``getTimestampOffset() -> timedelta``, ``getCameraName()``, ``getSerialNumber()``, ``getFirmwareVersion()``,
``getLogicVersion()``, ``getConnectionSpeed()``, ``setCropArea/getCropArea`` (x, y, w, h tuples), DVXplorer
``set/getContrastThresholdOn/Off``, ``ReadoutFPS``, ``set/getReadoutFPS``, detector ``setDetectorRunning``,
``setDetectorRisingEdges``, ``setDetectorFallingEdges``, ``isDetectorRunning``; DAVIS ``Davis346BiasCF``,
``set/getDavis346BiasCoarseFine``. ``EventStore`` gives ``timestamps()``, ``coordinates()``, ``polarities()``
as the real one does (int64, int16 N x 2, uint8); ``Trigger(timestamp, type)`` with ``TriggerType``.

Device behaviour: event batches of random sizes of a flapping line, timestamps in Unix µs (device time plus
the timestamp offset); the crop area drops events outside it (refused when outside the sensor), triggers
come only while the detector runs; can be absent, unplugged (``isRunning()`` turns False, or the next call
raises) or stall (no batches).
"""

from __future__ import annotations

import dataclasses
import enum
import types
from datetime import timedelta

import _fake_streams
import numpy as np


class TriggerType(enum.Enum):
    TIMESTAMP_RESET = 0
    EXTERNAL_SIGNAL_RISING_EDGE = 1
    EXTERNAL_SIGNAL_FALLING_EDGE = 2
    EXTERNAL_SIGNAL_PULSE = 3
    EXTERNAL_GENERATOR_RISING_EDGE = 4
    EXTERNAL_GENERATOR_FALLING_EDGE = 5
    APS_FRAME_START = 6


class Trigger:
    def __init__(self, timestamp: int = 0, type: TriggerType = TriggerType.TIMESTAMP_RESET) -> None:  # noqa: A002
        self.timestamp, self.type = int(timestamp), type


class EventStore:
    def __init__(self, t: np.ndarray | None = None, xy: np.ndarray | None = None, p: np.ndarray | None = None) -> None:
        self._t = np.zeros(0, np.int64) if t is None else t
        self._xy = np.zeros((0, 2), np.int16) if xy is None else xy
        self._p = np.zeros(0, np.uint8) if p is None else p

    def size(self) -> int:
        return len(self._t)

    def __len__(self) -> int:
        return len(self._t)

    def isEmpty(self) -> bool:  # noqa: N802 - the bindings' names
        return len(self._t) == 0

    def timestamps(self) -> np.ndarray:
        return self._t.copy()

    def coordinates(self) -> np.ndarray:
        return self._xy.copy()

    def polarities(self) -> np.ndarray:
        return self._p.copy()


class _Speed(enum.Enum):
    LIBUSB_SPEED_SUPER = 4


@dataclasses.dataclass
class FakeDvCamera:
    """One fake iniVation camera.

    Attributes:
        model: ``DVXplorer`` (640x480) or ``DAVIS`` (346x260).
        serial: serial number.
        duration_us, seed: the flapping-line source and batch sizes.
        timestamp_offset_us: Unix time of the camera's clock zero.
        unplug_after_batches: then isRunning() is False (or, with ``unplug_raises``, the next call raises).
        stall_after_batches: then no more batches.
    """

    model: str = "DVXplorer"
    serial: str = "DXA00093"
    duration_us: int = 150_000
    seed: int = 0
    timestamp_offset_us: int = 1_763_700_000_000_000
    unplug_after_batches: int | None = None
    unplug_raises: bool = False
    stall_after_batches: int | None = None
    events: np.ndarray | None = None
    triggers: np.ndarray | None = None
    sent_events: np.ndarray | None = None
    sent_triggers: np.ndarray | None = None


class _Controller:
    def __init__(self) -> None:
        self.cameras: list[FakeDvCamera] = []

    def reset(self) -> None:
        self.cameras = []

    def plug(self, camera: FakeDvCamera) -> FakeDvCamera:
        self.cameras.append(camera)
        return camera


_fake = _Controller()


class _Camera:
    WIDTH, HEIGHT = 0, 0

    def __init__(self, fake: FakeDvCamera) -> None:
        self.fake = fake
        self._crop = (0, 0, self.WIDTH, self.HEIGHT)
        self._detector = False
        self._rising = self._falling = False
        self._batches: list[tuple[np.ndarray, np.ndarray]] | None = None
        self._handed = 0
        self._unplugged = False

    def getCameraName(self) -> str:  # noqa: N802
        return f"{type(self).__name__}_{self.fake.serial}"

    def getSerialNumber(self) -> str:  # noqa: N802
        return self.fake.serial

    def getFirmwareVersion(self) -> int:  # noqa: N802
        return 7

    def getLogicVersion(self) -> int:  # noqa: N802
        return 18

    def getConnectionSpeed(self) -> _Speed:  # noqa: N802
        return _Speed.LIBUSB_SPEED_SUPER

    def getEventResolution(self) -> tuple[int, int]:  # noqa: N802
        return (self.WIDTH, self.HEIGHT)

    def getTimestampOffset(self) -> timedelta:  # noqa: N802
        return timedelta(microseconds=self.fake.timestamp_offset_us)

    def isTriggerStreamAvailable(self) -> bool:  # noqa: N802
        return True

    def isRunning(self) -> bool:  # noqa: N802
        return not self._unplugged

    def setCropArea(self, cropAreaEvents: tuple[int, int, int, int]) -> None:  # noqa: N802, N803
        x, y, w, h = cropAreaEvents
        if x < 0 or y < 0 or w < 1 or h < 1 or x + w > self.WIDTH or y + h > self.HEIGHT:
            raise ValueError("Crop area outside of the sensor")
        self._crop = (x, y, w, h)

    def getCropArea(self) -> tuple[int, int, int, int]:  # noqa: N802
        return self._crop

    def setDetectorRunning(self, run: bool) -> None:  # noqa: N802
        self._detector = bool(run)

    def isDetectorRunning(self) -> bool:  # noqa: N802
        return self._detector

    def setDetectorRisingEdges(self, detectRising: bool) -> None:  # noqa: N802, N803
        self._rising = bool(detectRising)

    def setDetectorFallingEdges(self, detectFalling: bool) -> None:  # noqa: N802, N803
        self._falling = bool(detectFalling)

    def getNextEventBatch(self) -> EventStore | None:  # noqa: N802
        batch = self._next()
        if batch is None or len(batch[0]) == 0:
            return None
        events = batch[0]
        xy = np.stack([events["x"], events["y"]], axis=1).astype(np.int16)
        return EventStore(events["t"] + self.fake.timestamp_offset_us, xy, events["p"].astype(np.uint8))

    def getNextTriggerBatch(self) -> list[Trigger] | None:  # noqa: N802
        if self._pending_triggers is None or not len(self._pending_triggers):
            return None
        triggers, self._pending_triggers = self._pending_triggers, None
        kinds = {1: TriggerType.EXTERNAL_SIGNAL_RISING_EDGE, 0: TriggerType.EXTERNAL_SIGNAL_FALLING_EDGE}
        return [Trigger(int(t["t"]) + self.fake.timestamp_offset_us, kinds[int(t["edge"])]) for t in triggers]

    _pending_triggers: np.ndarray | None = None

    def _next(self) -> tuple[np.ndarray, np.ndarray] | None:
        fake = self.fake
        if self._unplugged:
            if fake.unplug_raises:
                raise RuntimeError("libcaer: device disconnected")
            return None
        if self._batches is None:
            self._batches = self._make_batches()
        if fake.unplug_after_batches is not None and self._handed >= fake.unplug_after_batches:
            self._unplugged = True
            return self._next()
        limit = len(self._batches) if fake.stall_after_batches is None else fake.stall_after_batches
        if self._handed >= min(limit, len(self._batches)):
            return None
        batch = self._batches[self._handed]
        self._handed += 1
        self._pending_triggers = batch[1]
        return batch

    def _make_batches(self) -> list[tuple[np.ndarray, np.ndarray]]:
        fake = self.fake
        if fake.events is None:
            fake.events, fake.triggers = _fake_streams.flapping_source(
                self.WIDTH, self.HEIGHT, fake.duration_us, seed=fake.seed
            )
        x, y, w, h = self._crop
        ev = fake.events
        ev = ev[(ev["x"] >= x) & (ev["x"] < x + w) & (ev["y"] >= y) & (ev["y"] < y + h)]
        tr = fake.triggers
        if not self._detector:
            tr = tr[:0]
        else:
            tr = tr[((tr["edge"] == 1) & self._rising) | ((tr["edge"] == 0) & self._falling)]
        fake.sent_events, fake.sent_triggers = ev, tr
        rng = np.random.default_rng(fake.seed)
        cuts = np.cumsum(rng.integers(1, 3000, size=len(ev) + 1))
        cuts = np.concatenate([[0], cuts[cuts < len(ev)], [len(ev)]])
        ends = ev["t"][np.maximum(cuts[1:] - 1, 0)] if len(ev) else np.zeros(1, np.int64)
        owner = np.minimum(np.searchsorted(ends, tr["t"], side="left"), len(cuts) - 2)  # each trigger, one batch
        batches = [(ev[a:b], tr[owner == i]) for i, (a, b) in enumerate(zip(cuts[:-1], cuts[1:]))]
        return batches


class DVXplorer(_Camera):
    WIDTH, HEIGHT = 640, 480

    class ReadoutFPS(enum.Enum):
        CONSTANT_100 = 0
        VARIABLE_2000 = 7
        VARIABLE_15000 = 10

    def __init__(self, fake: FakeDvCamera) -> None:
        super().__init__(fake)
        self._thresholds = {"on": 9, "off": 9}
        self._fps = DVXplorer.ReadoutFPS.VARIABLE_2000

    def setContrastThresholdOn(self, contrastThresholdOn: int) -> None:  # noqa: N802, N803
        self._thresholds["on"] = min(max(int(contrastThresholdOn), 1), 31)  # the sensor register's range

    def getContrastThresholdOn(self) -> int:  # noqa: N802
        return self._thresholds["on"]

    def setContrastThresholdOff(self, contrastThresholdOff: int) -> None:  # noqa: N802, N803
        self._thresholds["off"] = min(max(int(contrastThresholdOff), 1), 31)

    def getContrastThresholdOff(self) -> int:  # noqa: N802
        return self._thresholds["off"]

    def setReadoutFPS(self, readoutFps: DVXplorer.ReadoutFPS) -> None:  # noqa: N802, N803
        if not isinstance(readoutFps, DVXplorer.ReadoutFPS):
            raise TypeError("incompatible function arguments")
        self._fps = readoutFps

    def getReadoutFPS(self) -> DVXplorer.ReadoutFPS:  # noqa: N802
        return self._fps


class DAVIS(_Camera):
    WIDTH, HEIGHT = 346, 260

    class Davis346BiasCF(enum.Enum):
        Diff = 2
        On = 3
        Off = 4
        Refractory = 8

    def __init__(self, fake: FakeDvCamera) -> None:
        super().__init__(fake)
        self._biases = {b: (4, 39) for b in DAVIS.Davis346BiasCF}

    def setDavis346BiasCoarseFine(self, bias: DAVIS.Davis346BiasCF, coarse: int, fine: int) -> None:  # noqa: N802
        if not (0 <= coarse <= 7 and 0 <= fine <= 255):
            raise ValueError("coarse must be 0..7 and fine 0..255")
        self._biases[bias] = (coarse, fine)

    def getDavis346BiasCoarseFine(self, bias: DAVIS.Davis346BiasCF) -> tuple[int, int]:  # noqa: N802
        return self._biases[bias]


@dataclasses.dataclass
class _Descriptor:
    serialNumber: str  # noqa: N815


def _open(serialNumber: str | None = None) -> _Camera:  # noqa: N803
    matches = [c for c in _fake.cameras if serialNumber is None or c.serial == serialNumber]
    if not matches:
        if serialNumber is None:
            raise IndexError("vector::_M_range_check: __n (which is 0) >= this->size() (which is 0)")
        raise RuntimeError("Could not find device with given serial number")
    fake = matches[0]
    return (DVXplorer if fake.model == "DVXplorer" else DAVIS)(fake)


io = types.SimpleNamespace(
    camera=types.SimpleNamespace(
        open=_open, discover=lambda: [_Descriptor(c.serial) for c in _fake.cameras], DVXplorer=DVXplorer, DAVIS=DAVIS
    )
)
