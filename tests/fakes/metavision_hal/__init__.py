"""Fake ``metavision_hal`` (tests only): the part of OpenEB's HAL Python bindings the metavision adapter uses.

Mirrors OpenEB 5.1 (its names and method names are checked against the real module where it
imports, tests/integration/test_camera_metavision_openeb.py); ``_fake.use_api("4.6")`` or ``("4.4")``
gives the older bindings instead. Real API mirrored: ``DeviceDiscovery.open(serial[, config])`` (None
when no such camera), ``DeviceDiscovery.list()``, ``DeviceConfig().set_format(...)``; a device's
facilities ``get_i_geometry()``, ``get_i_hw_identification()`` (serial, sensor info, integrator,
current and available data encoding formats, system info; the system id in 4.x only),
``get_i_ll_biases()`` (set/get/get_all_biases/get_bias_info with allowed ranges), ``get_i_roi()``
(``I_ROI.Window``, set_window, enable), ``get_i_erc_module()`` (set_cd_event_rate / get_cd_event_rate,
enable / is_enabled), ``get_i_trigger_in()`` (``I_TriggerIn.Channel``, enable / disable / is_enabled),
``get_i_events_stream()``, ``get_i_events_stream_decoder()``, ``get_i_event_cd_decoder()``,
``get_i_event_ext_trigger_decoder()`` (types and callbacks in :mod:`._events_stream`). A facility the
sensor lacks is None, as in the bindings.

Device behaviour: streams real EVT bytes (EVT 3.0, 2.0 or 2.1) of a flapping line in buffers of random sizes,
built at ``start()`` from the settings in force: biases out of their allowed range and unknown bias names
raise (as the HAL does), the ROI window drops events outside it, the ERC keeps at most N events per 200 µs
(the rate is quantised to that step, so reading it back differs from the request), the trigger input
passes triggers only when enabled. Simulates a missing camera, an unplug (``poll_buffer`` returns -1)
and a stall (no buffers).
"""

from __future__ import annotations

import dataclasses
import enum

import _fake_streams
import numpy as np

from flagtrack.drivers.formats import make_decoder

from . import _events_stream
from ._events_stream import (
    I_Decoder,
    I_EventDecoder_EventCD,
    I_EventDecoder_EventExtTrigger,
    I_EventsStream,
)

ERC_PERIOD_US = 200
API_VERSIONS = ("5.1", "4.6", "4.4")
"""5.1: RawBuffer (size() only); 4.6: RawDataBuffer (a vector of ints); 4.4: numpy bytes."""
TEST_CONTROLS = ("FakeHalCamera", "Sensor")
"""The fake's own classes (the test's controls), not the bindings'."""


@dataclasses.dataclass(frozen=True)
class Sensor:
    name: str
    width: int
    height: int
    formats: tuple[str, ...]
    biases: dict[str, tuple[int, int, int]]  # name -> (default, allowed min, allowed max)
    erc: bool
    system_id: int


SENSORS = {
    "IMX636": Sensor(
        "IMX636",
        1280,
        720,
        ("EVT3", "EVT21"),
        {
            "bias_diff_on": (0, -85, 140),
            "bias_diff_off": (0, -35, 190),
            "bias_fo": (0, -35, 55),
            "bias_hpf": (0, 0, 120),
            "bias_refr": (0, -20, 235),
        },
        True,
        0x31,
    ),
    "Gen3.1": Sensor(
        "Gen3.1",
        640,
        480,
        ("EVT2",),
        {
            "bias_diff": (299, 200, 400),
            "bias_diff_off": (221, 0, 298),
            "bias_diff_on": (384, 300, 1800),
            "bias_fo": (1477, 1250, 1800),
            "bias_hpf": (1499, 900, 1800),
            "bias_pr": (1250, 0, 1800),
            "bias_refr": (1500, 1300, 1800),
        },
        False,
        0x1C,
    ),
}


@dataclasses.dataclass
class FakeHalCamera:
    """One fake camera on the HAL.

    Attributes:
        serial: serial number.
        sensor: ``IMX636`` (EVK4: EVT 3.0 or 2.1, ERC) or ``Gen3.1`` (VGA: EVT 2.0, no ERC).
        format: data format at open (None: the sensor's first); a DeviceConfig format overrides it.
        format_options: options the HAL appends to the format string (``endianness=legacy``).
        duration_us, seed: the flapping-line source and buffer sizes.
        unplug_after_bytes: poll_buffer returns -1 after this many bytes.
        stall_after_bytes: no more buffers after this many bytes.
        corrupt_words: (OpenEB 4.x bindings, EVT 2.1) indices of 64-bit words of the stream the camera
            garbles into a reserved type (a corrupt transfer); their events are lost.
    """

    serial: str = "00ca0009"
    sensor: str = "IMX636"
    format: str | None = None
    format_options: str = ""
    duration_us: int = 200_000
    seed: int = 0
    unplug_after_bytes: int | None = None
    stall_after_bytes: int | None = None
    corrupt_words: tuple[int, ...] = ()
    events: np.ndarray | None = None
    triggers: np.ndarray | None = None
    sent_events: np.ndarray | None = None
    sent_triggers: np.ndarray | None = None
    started: int = 0
    stopped: int = 0

    @property
    def spec(self) -> Sensor:
        return SENSORS[self.sensor]


class _Controller:
    def __init__(self) -> None:
        self.cameras: list[FakeHalCamera] = []
        self.api = API_VERSIONS[0]

    def reset(self) -> None:
        self.cameras = []

    def use_api(self, version: str) -> None:
        """Be the bindings of this OpenEB version: its buffer type (module names included)."""
        if version not in API_VERSIONS:
            raise ValueError(f"fake bindings are {API_VERSIONS}, not {version}")
        self.api = version
        module = globals()
        module.pop("RawBuffer", None)
        module.pop("RawDataBuffer", None)
        if version.startswith("5"):
            module["RawBuffer"] = _events_stream.RawBuffer
        elif version == "4.6":
            module["RawDataBuffer"] = _events_stream.RawDataBuffer

    def plug(self, camera: FakeHalCamera) -> FakeHalCamera:
        self.cameras.append(camera)
        return camera


_fake = _Controller()
RawBuffer = _events_stream.RawBuffer  # OpenEB 5.1 until _fake.use_api says otherwise


class DeviceConfig:
    def __init__(self) -> None:
        self._format = ""

    def format(self) -> str:
        return self._format

    def set_format(self, format: str) -> None:  # noqa: A002 - the bindings' argument name
        self._format = format


class DeviceDiscovery:
    @staticmethod
    def list() -> list[str]:
        return [c.serial for c in _fake.cameras]

    @staticmethod
    def open(serial: str, config: DeviceConfig | None = None) -> Device | None:
        for camera in _fake.cameras:
            if not serial or camera.serial == serial:
                fmt = (config.format() if config is not None else "") or camera.format or camera.spec.formats[0]
                if fmt not in camera.spec.formats:
                    raise RuntimeError(f"HalException: format {fmt} is not supported by {camera.sensor}")
                return Device(camera, fmt)
        return None


class LL_Bias_Info:  # noqa: N801 - the bindings' name
    def __init__(self, low: int, high: int) -> None:
        self._range = (low, high)

    def get_bias_allowed_range(self) -> tuple[int, int]:
        return self._range

    def get_bias_range(self) -> tuple[int, int]:
        return self._range

    def is_modifiable(self) -> bool:
        return True


class I_LL_Biases:  # noqa: N801
    def __init__(self, sensor: Sensor) -> None:
        self._spec = sensor.biases
        self._values = {name: v[0] for name, v in sensor.biases.items()}

    def set(self, bias_name: str, bias_value: int) -> bool:
        if bias_name not in self._spec:
            raise RuntimeError(f"HalException: Unavailable bias: {bias_name}")
        _, low, high = self._spec[bias_name]
        if not low <= bias_value <= high:
            raise RuntimeError(f"HalException: Bias value {bias_value} out of range for {bias_name}")
        self._values[bias_name] = int(bias_value)
        return True

    def get(self, bias_name: str) -> int:
        return self._values[bias_name]

    def get_all_biases(self) -> dict[str, int]:
        return dict(self._values)

    def get_bias_info(self, bias_name: str) -> LL_Bias_Info:
        if bias_name not in self._spec:
            raise RuntimeError(f"HalException: Unavailable bias: {bias_name}")
        return LL_Bias_Info(*self._spec[bias_name][1:])


class I_ROI:  # noqa: N801
    class Mode(enum.Enum):
        ROI = 0
        RONI = 1

    class Window:
        def __init__(self, x: int, y: int, width: int, height: int) -> None:
            self.x, self.y, self.width, self.height = x, y, width, height

    def __init__(self, sensor: Sensor) -> None:
        self._sensor = sensor
        self.window: I_ROI.Window | None = None
        self.enabled = False
        self.mode = I_ROI.Mode.ROI

    def set_window(self, roi: I_ROI.Window) -> None:
        if roi.x < 0 or roi.y < 0 or roi.x + roi.width > self._sensor.width or roi.y + roi.height > self._sensor.height:
            raise RuntimeError("HalException: ROI window outside the sensor")
        self.window = roi

    def set_mode(self, mode: I_ROI.Mode) -> None:
        self.mode = mode

    def enable(self, enable: bool) -> bool:
        self.enabled = bool(enable)
        return True

    def get_max_supported_windows_count(self) -> int:
        return 1


class I_ErcModule:  # noqa: N801
    _MAX_RATE = 1_000_000_000

    def __init__(self) -> None:
        self._enabled = False
        self._count = 0

    def enable(self, b: bool) -> bool:
        self._enabled = bool(b)
        return True

    def is_enabled(self) -> bool:
        return self._enabled

    def set_cd_event_rate(self, events_per_sec: int) -> bool:
        if not 0 <= events_per_sec <= self._MAX_RATE:
            raise RuntimeError(f"HalException: ERC rate {events_per_sec} out of range")
        self._count = int(events_per_sec * ERC_PERIOD_US // 1_000_000)  # events per reference period
        return True

    def get_cd_event_rate(self) -> int:
        return self._count * 1_000_000 // ERC_PERIOD_US

    def get_min_supported_cd_event_rate(self) -> int:
        return 0

    def get_max_supported_cd_event_rate(self) -> int:
        return self._MAX_RATE

    @property
    def _count_per_period(self) -> int:
        return self._count


class I_TriggerIn:  # noqa: N801
    class Channel(enum.Enum):  # a pybind11 enum: not an int, but int() gives its value
        MAIN = 0
        AUX = 1
        LOOPBACK = 2

        def __int__(self) -> int:
            return int(self.value)

    def __init__(self) -> None:
        self._enabled: set[int] = set()

    def enable(self, channel: int) -> bool:
        self._enabled.add(int(channel))
        return True

    def disable(self, channel: int) -> bool:
        self._enabled.discard(int(channel))
        return True

    def is_enabled(self, channel: int) -> bool:
        return int(channel) in self._enabled

    def get_available_channels(self) -> dict:
        return {I_TriggerIn.Channel.MAIN: 0}


class I_Geometry:  # noqa: N801
    def __init__(self, sensor: Sensor) -> None:
        self._sensor = sensor

    def get_width(self) -> int:
        return self._sensor.width

    def get_height(self) -> int:
        return self._sensor.height


@dataclasses.dataclass
class SensorInfo:
    major_version: int
    minor_version: int
    name: str


class I_HW_Identification:  # noqa: N801
    def __init__(self, camera: FakeHalCamera, fmt: str) -> None:
        self._camera, self._format = camera, fmt

    def get_serial(self) -> str:
        return self._camera.serial

    def get_integrator(self) -> str:
        return "Prophesee"

    def get_sensor_info(self) -> SensorInfo:
        return SensorInfo(4, 2, self._camera.sensor)

    def get_available_data_encoding_formats(self) -> list[str]:
        return list(self._camera.spec.formats)

    def get_current_data_encoding_format(self) -> str:
        options = f";{self._camera.format_options}" if self._camera.format_options else ""
        return f"{self._format}{options}"

    def get_system_info(self) -> dict[str, str]:
        return {"Connection": "USB", "Release Version": "3.9.0", "Sensor Name": self._camera.sensor}


class _HwIdentification4(I_HW_Identification):
    """OpenEB 4.x's, which also has the system id."""

    def get_system_id(self) -> int:
        return self._camera.spec.system_id


class Device:
    def __init__(self, camera: FakeHalCamera, fmt: str) -> None:
        self.camera = camera
        self.format = fmt
        sensor = camera.spec
        self._biases = I_LL_Biases(sensor)
        self._roi = I_ROI(sensor)
        self._erc = I_ErcModule() if sensor.erc else None
        self._trigger = I_TriggerIn()
        self._stream = I_EventsStream(self)
        self._decoder = I_Decoder(self._api)
        self._geometry = I_Geometry(sensor)
        self._hw = (I_HW_Identification if self._api().startswith("5") else _HwIdentification4)(camera, fmt)

    @staticmethod
    def _api() -> str:
        return _fake.api

    def get_i_ll_biases(self) -> I_LL_Biases:
        return self._biases

    def get_i_roi(self) -> I_ROI:
        return self._roi

    def get_i_erc_module(self) -> I_ErcModule | None:
        return self._erc

    def get_i_trigger_in(self) -> I_TriggerIn:
        return self._trigger

    def get_i_events_stream(self) -> I_EventsStream:
        return self._stream

    def get_i_events_stream_decoder(self) -> I_Decoder:
        return self._decoder

    def get_i_event_cd_decoder(self) -> I_EventDecoder_EventCD:
        return self._decoder.cd

    def get_i_event_ext_trigger_decoder(self) -> I_EventDecoder_EventExtTrigger:
        return self._decoder.trigger

    def get_i_geometry(self) -> I_Geometry:
        return self._geometry

    def get_i_hw_identification(self) -> I_HW_Identification:
        return self._hw

    def _header(self) -> str:
        """The RAW header the HAL writes (``log_raw_data``)."""
        sensor = self.camera.spec
        fmt = f"{self.format};height={sensor.height};width={sensor.width}"
        return f"% camera_integrator_name Prophesee\n% format {fmt}\n% serial_number {self.camera.serial}\n% end\n"

    def _make_feed(self) -> _fake_streams.ByteFeed:
        """The sensor's output under the settings in force, as the format's bytes (and the decoder for them)."""
        camera, sensor = self.camera, self.camera.spec
        if camera.events is None:
            camera.events, camera.triggers = _fake_streams.flapping_source(
                sensor.width, sensor.height, camera.duration_us, seed=camera.seed
            )
        events = camera.events
        window = self._roi.window
        if self._roi.enabled and window is not None:
            inside = (
                (events["x"] >= window.x)
                & (events["x"] < window.x + window.width)
                & (events["y"] >= window.y)
                & (events["y"] < window.y + window.height)
            )
            events = events[inside]
        if self._erc is not None and self._erc.is_enabled():
            slot = events["t"] // ERC_PERIOD_US
            rank = np.arange(len(events)) - np.searchsorted(slot, slot, side="left")
            events = events[rank < self._erc._count_per_period]
        triggers = camera.triggers if self._trigger.is_enabled(0) else camera.triggers[:0]
        camera.sent_events, camera.sent_triggers = events, triggers
        encoding = {"EVT3": "evt3", "EVT2": "evt2", "EVT21": "evt21"}[self.format]
        legacy = "endianness=legacy" in camera.format_options or (
            encoding == "evt21" and "endianness" not in camera.format_options and sensor.system_id < 0x37
        )
        data = _fake_streams.encode(encoding, events, triggers, sensor.width, sensor.height, legacy=legacy)
        if camera.corrupt_words:
            words = np.frombuffer(data, dtype="<u8").copy()
            words[list(camera.corrupt_words)] = 0x3 << 60 if not legacy else 0x3 << 28  # reserved type 0x3
            data = words.tobytes()
        self._decoder.words = make_decoder(
            encoding, width=sensor.width, height=sensor.height, strict=True, endianness="legacy" if legacy else "little"
        )
        return _fake_streams.ByteFeed(data, seed=camera.seed, stall_after_bytes=camera.stall_after_bytes)
