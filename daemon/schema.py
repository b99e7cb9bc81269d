"""The wire schema: every key expression and message type on the bus, with a versioned encoding.

Wire format of every message (little-endian)::

    b"FT" | version u8 | type u8 | meta_len u32 | meta (UTF-8 JSON object) | payload

The JSON meta holds the scalar fields; array fields (numpy) and byte fields travel in the payload,
described in the meta under ``"_blobs"`` as ``[name, dtype, shape]`` (``dtype`` ``"bytes"`` for raw
bytes), in order. :func:`decode` rejects a wrong magic, an unknown version or type, bad JSON,
missing or mistyped fields, a payload whose size does not match and arrays of one message whose
shapes or types disagree (a centreline message's ``joints_x`` must be (n, N_j+1) for its n updates),
with a :class:`SchemaError` that names the key and the field. :class:`ProblemLog` is how services
count what they drop and log it rarely. This module imports no transport: see
:mod:`flagtrack.daemon.transport` for Zenoh.
"""

from __future__ import annotations

import dataclasses
import enum
import functools
import json
import logging
import math
import struct
import time
from dataclasses import dataclass, field
from typing import Any, ClassVar, TypeVar

import numpy as np

from flagtrack.daemon.config import from_mapping
from flagtrack.daemon.core.centreline import CentrelineBatch
from flagtrack.daemon.errors import ConfigError, SchemaError

MAGIC = b"FT"
VERSION = 2
"""Written in every message. 2 (2026-11-24) added optional fields (EventPacket.stream_id,
CentrelineMessage.stream, status counters); version 1 messages decode with their defaults, and
scalar fields this build does not know are ignored, so later additions need no new version."""
READABLE_VERSIONS = frozenset({1, 2})
_HEADER = struct.Struct("<2sBBI")
M = TypeVar("M")


class MessageType(enum.IntEnum):
    """Type byte of each message on the wire."""

    EVENT_PACKET = 1
    CAMERA_STATUS = 2
    EVENT_RATE = 3
    CENTRELINES = 4
    TRACKER_STATUS = 5
    TUNNEL_STATE = 6
    TUNNEL_COMMAND = 7
    SUPERVISOR_STATE = 8
    RECORDER_COMMAND = 9
    RECORDER_STATUS = 10
    SENSOR_SAMPLES = 11


@dataclass(frozen=True)
class Keys:
    """Key expressions under one namespace (lowercase slash-separated words, default ``flagtrack/<rig>``)."""

    namespace: str = "flagtrack/default"

    def camera_events(self, camera_id: str) -> str:
        """Native event packets of one camera (:class:`EventPacket`)."""
        return f"{self.namespace}/camera/{camera_id}/events"

    def camera_status(self, camera_id: str) -> str:
        """Camera state and settings read back (:class:`CameraStatus`)."""
        return f"{self.namespace}/camera/{camera_id}/status"

    def event_rate(self, camera_id: str) -> str:
        """Event-rate statistics of one camera (:class:`EventRate`)."""
        return f"{self.namespace}/camera/{camera_id}/rate"

    def centrelines(self) -> str:
        """Batched tracker output (:class:`CentrelineMessage`)."""
        return f"{self.namespace}/tracker/centreline"

    def tracker_status(self) -> str:
        """Tracker health (:class:`TrackerStatus`)."""
        return f"{self.namespace}/tracker/status"

    def tunnel_state(self) -> str:
        """Wind-tunnel speed and state (:class:`TunnelState`)."""
        return f"{self.namespace}/tunnel/state"

    def tunnel_command(self) -> str:
        """Commands to the tunnel owner (:class:`TunnelCommand`)."""
        return f"{self.namespace}/tunnel/command"

    def supervisor_state(self) -> str:
        """Flag state, sweep progress (:class:`SupervisorState`)."""
        return f"{self.namespace}/supervisor/state"

    def recorder_command(self) -> str:
        """Start/stop/rotate recordings (:class:`RecorderCommand`)."""
        return f"{self.namespace}/recorder/command"

    def recorder_status(self) -> str:
        """What the recorder is writing (:class:`RecorderStatus`)."""
        return f"{self.namespace}/recorder/status"

    def sensor_samples(self, sensor_id: str) -> str:
        """Point-sensor samples (:class:`SensorSamples`)."""
        return f"{self.namespace}/sensor/{sensor_id}/samples"

    def alive(self, service: str) -> str:
        """Liveliness token of one service instance."""
        return f"{self.namespace}/alive/{service}"

    def alive_all(self) -> str:
        """Liveliness of every service in the namespace."""
        return f"{self.namespace}/alive/**"


@dataclass(frozen=True)
class EventPacket:
    """About 1 ms of one camera's events in its native encoding (EVT 3.0 / 2.0 bytes).

    Every packet decodes alone (it starts with the stream's time base), and the packets of a
    stream concatenate into one valid stream (what the recorder writes). ``t_offset_us`` is the
    stream's encoder offset (a whole number of the encoding's time loops) added back on decoding.
    ``sent_ns`` is the wall-clock time (ns) at which the adapter received the data, for latency.
    ``t_last_us`` is the completeness horizon: every event with ``t <= t_last_us`` is in this packet
    or an earlier one (an empty packet carries it forward while the scene is still).
    ``end_of_stream`` marks the last packet of a stream (end of a replayed file). ``stream_id``
    names the stream (drawn when the camera service starts; 0 from older peers): packets of
    another id are a restarted camera, a lower ``seq`` with the same id a duplicate or late packet.
    """

    TYPE: ClassVar[MessageType] = MessageType.EVENT_PACKET
    camera_id: str
    seq: int
    t_first_us: int
    t_last_us: int
    n_events: int
    width: int
    height: int
    encoding: str
    sent_ns: int
    t_offset_us: int = 0
    n_triggers: int = 0
    end_of_stream: bool = False
    stream_id: int = 0
    data: bytes = b""


@dataclass(frozen=True)
class CameraStatus:
    """State of a camera adapter and its settings as read back from the device."""

    TYPE: ClassVar[MessageType] = MessageType.CAMERA_STATUS
    camera_id: str
    state: str  # starting | streaming | stopped | eof | error
    adapter: str
    width: int
    height: int
    encoding: str
    settings: dict[str, Any] = field(default_factory=dict)
    message: str = ""
    packets: int = 0
    events: int = 0


@dataclass(frozen=True)
class EventRate:
    """Event-rate statistics over one interval of camera time."""

    TYPE: ClassVar[MessageType] = MessageType.EVENT_RATE
    camera_id: str
    t_us: int
    interval_s: float
    events: int
    rate_hz: float
    on_fraction: float
    bytes: int = 0


@dataclass(frozen=True)
class CentrelineMessage:
    """A batch of tracker updates: t, joints, smoothed centreline, tip, Δ_RMS, events used.

    Shapes (checked by :func:`decode`): ``t_s``, ``tip_x``, ``tip_y``, ``delta_rms``, ``n_events``,
    ``source_ns`` (n_t,); ``s`` (n_s,), n_s >= 1; ``x``, ``y`` (n_t, n_s); ``joints_x``, ``joints_y``
    (n_t, N_j+1), N_j >= 1. ``n_events`` and ``source_ns`` are integers, the rest real numbers.
    ``source_ns`` (n_t,) is the ``sent_ns`` of the newest packet each update used (for latency).
    ``final`` marks the last message of a stream (after the camera's end of stream).
    ``published_ns`` is the wall-clock time (ns) the tracker published the message (0: not said).
    ``stream`` numbers the camera streams the tracker has tracked (0 for the first; one more after
    each end of stream or camera restart), so a recorder knows which stream's file the updates go to.
    """

    TYPE: ClassVar[MessageType] = MessageType.CENTRELINES
    source: str
    seq: int
    units: str
    t_s: np.ndarray
    s: np.ndarray
    x: np.ndarray
    y: np.ndarray
    joints_x: np.ndarray
    joints_y: np.ndarray
    tip_x: np.ndarray
    tip_y: np.ndarray
    delta_rms: np.ndarray
    n_events: np.ndarray
    source_ns: np.ndarray
    final: bool = False
    published_ns: int = 0
    stream: int = 0

    @classmethod
    def from_batch(
        cls, batch: CentrelineBatch, *, source: str, seq: int, units: str, source_ns: np.ndarray, final: bool = False,
        published_ns: int = 0, stream: int = 0,
    ) -> CentrelineMessage:
        """Wrap a tracker batch for the wire."""
        return cls(
            final=final, published_ns=published_ns, stream=stream, source=source, seq=seq, units=units, t_s=batch.t_s,
            s=batch.s,
            x=batch.x, y=batch.y, joints_x=batch.joints_x, joints_y=batch.joints_y, tip_x=batch.tip_x,
            tip_y=batch.tip_y,
            delta_rms=batch.delta_rms, n_events=batch.n_events, source_ns=np.asarray(source_ns, np.int64),
        )

    def batch(self) -> CentrelineBatch:
        """The updates as a :class:`CentrelineBatch`."""
        return CentrelineBatch(
            t_s=self.t_s, s=self.s, x=self.x, y=self.y, joints_x=self.joints_x, joints_y=self.joints_y,
            delta_rms=self.delta_rms, n_events=self.n_events,
        )


@dataclass(frozen=True)
class TrackerStatus:
    """Tracker health, published about once a second.

    ``missing_packets``: sequence gaps; ``malformed_packets``: messages or EVT bytes that could not be
    used; ``dropped_packets``: packets its full queue turned away (they also show as gaps);
    ``restarts``: new camera streams that began without the end of the last one (a restarted camera);
    ``late_packets``: duplicates and late packets of the stream, dropped.
    """

    TYPE: ClassVar[MessageType] = MessageType.TRACKER_STATUS
    source: str
    state: str  # waiting | tracking | stopped
    events_per_s: float
    updates_per_s: float
    lag_s: float
    packets: int
    missing_packets: int
    malformed_packets: int
    t_s: float = 0.0
    dropped_packets: int = 0
    restarts: int = 0
    late_packets: int = 0


@dataclass(frozen=True)
class TunnelState:
    """Wind-tunnel speed as read back, its set-point and state."""

    TYPE: ClassVar[MessageType] = MessageType.TUNNEL_STATE
    speed_mps: float
    setpoint_mps: float
    state: str  # idle | ramping | steady | stopping | fault
    fault: str = ""
    t_wall_s: float = 0.0


@dataclass(frozen=True)
class TunnelCommand:
    """A request to the tunnel owner: ``set`` a speed or ``stop`` (ramp to zero)."""

    TYPE: ClassVar[MessageType] = MessageType.TUNNEL_COMMAND
    action: str
    speed_mps: float = 0.0


@dataclass(frozen=True)
class SupervisorState:
    """Flag state from event rates, and sweep progress."""

    TYPE: ClassVar[MessageType] = MessageType.SUPERVISOR_STATE
    flag_state: str  # still | flapping | unknown
    rate_hz: float
    mode: str = "idle"  # idle | sweep | feedback | safe
    point: str = ""
    branch: str = ""
    speed_mps: float = 0.0
    message: str = ""


@dataclass(frozen=True)
class RecorderCommand:
    """Start, stop or rotate a recording of one camera (``path`` without extension)."""

    TYPE: ClassVar[MessageType] = MessageType.RECORDER_COMMAND
    action: str  # start | stop | rotate
    path: str = ""
    camera_id: str = ""
    centrelines: bool = False
    request_id: str = ""


@dataclass(frozen=True)
class RecorderStatus:
    """What the recorder is writing (counts of the recording ``path``; ``dropped_packets``: turned
    away by the recorder's full queue since it started, whatever file was open)."""

    TYPE: ClassVar[MessageType] = MessageType.RECORDER_STATUS
    state: str  # idle | recording | error
    path: str = ""
    bytes: int = 0
    packets: int = 0
    missing_packets: int = 0
    request_id: str = ""
    message: str = ""
    malformed_packets: int = 0
    dropped_packets: int = 0


def _no_pulses() -> np.ndarray:
    return np.zeros(0, dtype=np.int64)


@dataclass(frozen=True)
class SensorSamples:
    """Point-sensor samples: times on the sensor clock (µs), values (sensor units), NaN = missing.

    ``t_us`` (n,) int64 and ``value`` (n,) float64. Fields after ``value`` were added later with
    defaults, so messages without them still decode: ``trigger_t_us`` (m,) int64 the trigger pulses
    the sensor drove or recorded, on its clock; ``missing`` samples lost in this message's span (its
    NaN values included); ``clock`` ``sensor`` (the device's own clock) or ``host`` (stamped by the
    host on arrival, wall-clock µs); ``wall_ns`` the wall time the newest sample arrived (with
    ``t_us[-1]``, a rough link to the camera clock).
    """

    TYPE: ClassVar[MessageType] = MessageType.SENSOR_SAMPLES
    sensor_id: str
    seq: int
    units: str
    t_us: np.ndarray
    value: np.ndarray
    trigger_t_us: np.ndarray = field(default_factory=_no_pulses)
    missing: int = 0
    clock: str = "sensor"
    wall_ns: int = 0


MESSAGE_TYPES: dict[MessageType, type] = {
    cls.TYPE: cls
    for cls in (
        EventPacket, CameraStatus, EventRate, CentrelineMessage, TrackerStatus, TunnelState,
        TunnelCommand, SupervisorState, RecorderCommand, RecorderStatus, SensorSamples,
    )
}


@functools.cache
def _field_names(cls: type) -> tuple[str, ...]:
    """The dataclass fields of a message class, in order (looked up once per class)."""
    return tuple(f.name for f in dataclasses.fields(cls))


_META_ENCODER = json.JSONEncoder(separators=(",", ":"))  # what json.dumps(..., separators=...) builds per call


@functools.lru_cache(maxsize=1024)
def _blob_descriptor(name: str, dtype: np.dtype, shape: tuple[int, ...]) -> str:
    """The JSON text of an array's ``[name, dtype, shape]`` descriptor (messages repeat a few shapes).

    Raises:
        TypeError: arrays of Python objects or variable-width strings (their bytes are pointers).
    """
    if dtype.hasobject or dtype.kind == "T":
        raise TypeError(f"{name}: {dtype} arrays cannot be sent (their bytes are not their values)")
    return f'["{name}","{dtype.str}",[{",".join(map(str, shape))}]]'


def encode(message: Any) -> bytes:
    """Serialise one message of this module to bytes (see the module docstring for the layout).

    The meta is ``{<scalar fields in order>, "_blobs": [[name, dtype, shape], ...]}``; the blob
    descriptors are written as text directly (names, dtype strings and shapes need no escaping),
    which is the same JSON ``json.dumps`` writes for them, at a fraction of the cost.
    """
    scalars: dict[str, Any] = {}
    blobs: list[str] = []
    chunks: list[Any] = []  # byte buffers: the arrays themselves (C order), joined without a copy each
    for name in _field_names(type(message)):
        value = getattr(message, name)
        if isinstance(value, np.ndarray):
            array = value if value.flags.c_contiguous else np.ascontiguousarray(value)
            blobs.append(_blob_descriptor(name, array.dtype, array.shape))
            chunks.append(array)
        elif isinstance(value, (bytes, bytearray, memoryview)):
            data = bytes(value)
            blobs.append(f'["{name}","bytes",[{len(data)}]]')
            chunks.append(data)
        else:
            scalars[name] = value
    head = _META_ENCODER.encode(scalars)[:-1] + ("," if scalars else "")
    meta_bytes = f'{head}"_blobs":[{",".join(blobs)}]}}'.encode()
    return b"".join([_HEADER.pack(MAGIC, VERSION, message.TYPE, len(meta_bytes)), meta_bytes, *chunks])


def decode(data: bytes | bytearray | memoryview, expected: type[M] | None = None, *, key: str | None = None) -> M:
    """Parse bytes made by :func:`encode`.

    Args:
        data: the message bytes.
        expected: the message class wanted; another type raises SchemaError.
        key: the key expression it arrived on, for error messages.

    Raises:
        SchemaError: malformed bytes, unknown version or type, or not of ``expected`` type.
    """
    view = memoryview(data)
    if len(view) < _HEADER.size:
        raise SchemaError(f"{len(view)} bytes is shorter than the {_HEADER.size}-byte header", key=key)
    magic, version, type_id, meta_len = _HEADER.unpack_from(view)
    if magic != MAGIC:
        raise SchemaError(f"bad magic {bytes(magic)!r}, not a flagtrack message", key=key)
    if version not in READABLE_VERSIONS:
        raise SchemaError(f"unsupported schema version {version} (this build reads "
                          f"{', '.join(map(str, sorted(READABLE_VERSIONS)))})", key=key)
    try:
        cls = MESSAGE_TYPES[MessageType(type_id)]
    except ValueError:
        raise SchemaError(f"unknown message type {type_id}", key=key) from None
    if expected is not None and cls is not expected:
        raise SchemaError(f"expected {expected.__name__}, got {cls.__name__}", key=key)
    end = _HEADER.size + meta_len
    if end > len(view):
        raise SchemaError(f"meta length {meta_len} runs past the end ({len(view)} bytes)", key=key)
    try:
        meta = json.loads(bytes(view[_HEADER.size:end]))
    except ValueError as exc:
        raise SchemaError(f"{cls.__name__}: meta is not valid JSON ({exc})", key=key) from None
    if not isinstance(meta, dict):
        raise SchemaError(f"{cls.__name__}: meta is not a JSON object", key=key)
    blob_values = _read_blobs(cls, meta.pop("_blobs", None), view[end:], key)
    missing = _required_blobs(cls).difference(blob_values)
    if missing:
        raise SchemaError(f"{cls.__name__}: missing payload field '{sorted(missing)[0]}'", key=key)
    spec = _SHAPES.get(cls)
    if spec is not None:
        _check_shapes(cls, spec, blob_values, key)
    if _fast_scalars_ok(cls, meta):
        return cls(**meta, **blob_values)
    view_cls = _scalar_view(cls)
    known = _scalar_names(view_cls)
    if not known.issuperset(meta):  # fields of a later version: ignored (additions are optional)
        meta = {name: value for name, value in meta.items() if name in known}
    try:
        scalars = from_mapping(view_cls, meta)
    except ConfigError as exc:
        raise SchemaError(f"{cls.__name__}: {exc}", key=key) from None
    return cls(**{f.name: getattr(scalars, f.name) for f in dataclasses.fields(scalars)}, **blob_values)


def _read_blobs(cls: type, blobs: Any, payload: memoryview, key: str | None) -> dict[str, Any]:
    if not isinstance(blobs, list):
        raise SchemaError(f"{cls.__name__}: meta has no '_blobs' list", key=key)
    values: dict[str, Any] = {}
    offset = 0
    for item in blobs:
        try:
            name, dtype, shape = item
            try:
                dims = tuple(shape)
                layout = _blob_layout if len(dims) <= _CACHED_DIMS else _blob_layout.__wrapped__
                np_dtype, shape, size = layout(cls, name, dtype, dims)
            except TypeError:  # a part that cannot be a cache key, or a bad one: checked without the cache
                np_dtype, shape, size = _blob_layout.__wrapped__(cls, name, dtype, shape)
            if name in values:
                raise ValueError(name)
        except (ValueError, TypeError, OverflowError, SyntaxError) as exc:  # (np.dtype(",") raises SyntaxError)
            raise SchemaError(f"{cls.__name__}: bad payload descriptor {item!r} ({exc})", key=key) from None
        if offset + size > len(payload):
            raise SchemaError(f"{cls.__name__}: payload '{name}' truncated", key=key)
        try:
            if np_dtype is None:
                value: Any = bytes(payload[offset:offset + size])
            else:  # a read-only view of the message, as np.frombuffer gives, in one call
                value = np.ndarray(shape, dtype=np_dtype, buffer=payload, offset=offset)
        except (ValueError, TypeError) as exc:  # e.g. more than 64 dimensions, or one too large for numpy
            raise SchemaError(f"{cls.__name__}: bad payload descriptor {item!r} ({exc})", key=key) from None
        values[name] = value
        offset += size
    if offset != len(payload):
        raise SchemaError(f"{cls.__name__}: {len(payload) - offset} unexpected trailing payload bytes", key=key)
    return values


# The arrays of a message must agree: (field, dimension names, numpy kinds). A name is bound by the
# first field that has it; every later one must match. Sizes with a minimum are in _MIN_SIZE.
_REAL, _INT = "fiu", "iu"
_SHAPES: dict[type, tuple[tuple[str, tuple[str, ...], str], ...]] = {
    CentrelineMessage: (
        ("t_s", ("n",), _REAL), ("s", ("n_s",), _REAL), ("x", ("n", "n_s"), _REAL), ("y", ("n", "n_s"), _REAL),
        ("joints_x", ("n", "N_j+1"), _REAL), ("joints_y", ("n", "N_j+1"), _REAL), ("tip_x", ("n",), _REAL),
        ("tip_y", ("n",), _REAL), ("delta_rms", ("n",), _REAL), ("n_events", ("n",), _INT),
        ("source_ns", ("n",), _INT),
    ),
    SensorSamples: (("t_us", ("n",), _INT), ("value", ("n",), _REAL), ("trigger_t_us", ("m",), _INT)),
}
_MIN_SIZE = {"n_s": 1, "N_j+1": 2}
_KIND_NAMES = {_REAL: "real numbers", _INT: "integers"}


def _check_shapes(cls: type, spec: tuple[tuple[str, tuple[str, ...], str], ...], values: dict[str, Any],
                  key: str | None) -> None:
    """Raise SchemaError naming the first field whose shape or type disagrees with ``spec`` (O(fields))."""
    sizes: dict[str, int] = {}
    for name, dims, kinds in spec:
        array = values.get(name)
        if array is None:  # an optional field left out
            continue
        shape = array.shape
        ok = len(shape) == len(dims)
        for dim, size in zip(dims, shape) if ok else ():
            bound = sizes.get(dim)
            if bound is None and size >= _MIN_SIZE.get(dim, 0):
                sizes[dim] = size
            elif bound != size:
                ok = False
                break
        if not ok:
            said = [f"{d} = {sizes[d]}" if d in sizes else f"{d} >= {_MIN_SIZE[d]}"
                    for d in dims if d in sizes or d in _MIN_SIZE]
            raise SchemaError(f"{cls.__name__}: field '{name}' has shape {shape}, expected ({', '.join(dims)}"
                              f"{',' if len(dims) == 1 else ''}){' with ' + ', '.join(said) if said else ''}",
                              key=key)
        if array.dtype.kind not in kinds:
            raise SchemaError(f"{cls.__name__}: field '{name}' holds {array.dtype}, expected {_KIND_NAMES[kinds]}",
                              key=key)


_CACHED_DIMS = 8  # descriptors with more dimensions are checked without the cache (bounds its memory)


@functools.lru_cache(maxsize=256)
def _blob_layout(cls: type, name: Any, dtype: Any, shape: Any) -> tuple[np.dtype | None, tuple[int, ...], int]:
    """Checked layout of one payload descriptor: (numpy dtype, or None for bytes; shape; size in bytes).

    Raises ValueError, TypeError, OverflowError or SyntaxError for a bad one. Cached: a stream
    repeats a few descriptors (bounded, as they come off the wire; errors are not cached).
    """
    if not isinstance(dtype, str):  # numpy would also take a dict or a list as a structured type
        raise TypeError(f"dtype {dtype!r} is not a string")
    shape = tuple(map(int, shape))
    if name not in _blob_fields(cls) or min(shape, default=0) < 0 or (dtype == "bytes" and len(shape) != 1):
        raise ValueError(name)
    np_dtype = None if dtype == "bytes" else np.dtype(dtype)
    if np_dtype is not None and (np_dtype.hasobject or np_dtype.itemsize == 0 or np_dtype.shape):
        raise ValueError(f"{name}: not a plain array type")
    size = shape[0] if np_dtype is None else math.prod(shape) * np_dtype.itemsize  # (np.prod: ~15 us)
    return np_dtype, shape, size


@functools.cache
def _required_blobs(cls: type) -> frozenset[str]:
    """Names of the payload fields of ``cls`` without a default."""
    return frozenset(f.name for f in dataclasses.fields(cls) if _is_blob(f) and _required(f))


@functools.cache
def _blob_fields(cls: type) -> frozenset[str]:
    """Names of the fields of ``cls`` carried as binary payloads (arrays, bytes)."""
    return frozenset(f.name for f in dataclasses.fields(cls) if _is_blob(f))


def _is_blob(f: dataclasses.Field) -> bool:
    return f.type in ("np.ndarray", "bytes", np.ndarray, bytes)


def _required(f: dataclasses.Field) -> bool:
    return f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING


@functools.cache
def _scalar_view(cls: type) -> type:
    """A dataclass with only the JSON (non-blob) fields of ``cls``, for checked decoding (made once per class)."""
    specs: list[tuple] = []
    for f in dataclasses.fields(cls):
        if _is_blob(f):
            continue
        if f.default is not dataclasses.MISSING:
            specs.append((f.name, f.type, field(default=f.default)))
        elif f.default_factory is not dataclasses.MISSING:
            specs.append((f.name, f.type, field(default_factory=f.default_factory)))
        else:
            specs.append((f.name, f.type))
    view = dataclasses.make_dataclass(f"{cls.__name__}Meta", specs, frozen=True)
    view.__module__ = __name__  # so string annotations resolve against this module
    return view


@functools.cache
def _scalar_names(view_cls: type) -> frozenset[str]:
    """The field names of a scalar view."""
    return frozenset(f.name for f in dataclasses.fields(view_cls))


_SIMPLE = {"str": str, "int": int, "float": float, "bool": bool}


@functools.cache
def _simple_types(cls: type) -> dict[str, type] | None:
    """Name -> exact Python type of each scalar field of ``cls``; ``None`` if one is not simple."""
    simple = {f.name: _SIMPLE.get(f.type) for f in dataclasses.fields(cls) if not _is_blob(f)}
    return simple if all(simple.values()) else None  # type: ignore[return-value]


def _fast_scalars_ok(cls: type, meta: dict[str, Any]) -> bool:
    """True when ``meta`` holds exactly the scalar fields of ``cls`` with exact simple types.

    The hot path (event packets at kHz): skips the general checked conversion, which still runs
    (and explains the problem) whenever this quick test fails.
    """
    types_ = _simple_types(cls)
    if types_ is None or len(meta) != len(types_):
        return False
    for name, value in meta.items():
        expected = types_.get(name)
        if expected is None or type(value) is not expected:
            return False
    return True


class ProblemLog:
    """Counts the repeated problems of one service by kind and logs them rarely (STYLE.md).

    The first problem of a kind is logged at once with its detail; later ones are only counted, and
    summed up in one line at most every ``interval_s`` (by :meth:`add` as they come, or by
    :meth:`flush`, which a service calls now and then and when it stops). O(1) per problem.

    Args:
        logger: where the lines go.
        service: prefix of every line.
        interval_s: at most one line per kind this often.
        level: logging level of the lines.
    """

    def __init__(self, logger: logging.Logger, service: str, interval_s: float = 5.0,
                 level: int = logging.WARNING) -> None:
        self.logger = logger
        self.service = service
        self.interval_s = interval_s
        self.level = level
        self.totals: dict[str, int] = {}
        self._unlogged: dict[str, int] = {}
        self._latest: dict[str, object] = {}
        self._logged_at: dict[str, float] = {}

    def add(self, kind: str, detail: object, count: int = 1) -> None:
        """Count ``count`` problems of ``kind`` (e.g. ``"malformed packets"``); ``detail`` (an exception,
        or text) describes the latest one and is formatted only when logged."""
        self.totals[kind] = self.totals.get(kind, 0) + count
        self._unlogged[kind] = self._unlogged.get(kind, 0) + count
        self._latest[kind] = detail
        now = time.monotonic()
        if now - self._logged_at.get(kind, -math.inf) >= self.interval_s:
            self._log(kind, now)

    def flush(self, force: bool = False) -> None:
        """Log the summary of every kind with unlogged problems whose interval has passed (all: ``force``)."""
        now = time.monotonic()
        for kind, unlogged in self._unlogged.items():
            if unlogged and (force or now - self._logged_at.get(kind, -math.inf) >= self.interval_s):
                self._log(kind, now)

    def _log(self, kind: str, now: float) -> None:
        unlogged, total = self._unlogged[kind], self.totals[kind]
        if unlogged == total:
            self.logger.log(self.level, "%s: %s [%s: %d]", self.service, self._latest[kind], kind, total)
        else:
            self.logger.log(self.level, "%s: %d more %s in the last %.0f s (%d in all); latest: %s", self.service,
                            unlogged, kind, now - self._logged_at[kind], total, self._latest[kind])
        self._unlogged[kind] = 0
        self._logged_at[kind] = now
