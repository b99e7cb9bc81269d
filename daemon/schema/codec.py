"""The versioned wire encoding of the messages of :mod:`.messages`.

Wire format of every message (little-endian)::

    b"FT" | version u8 | type u8 | meta_len u32 | meta (UTF-8 JSON object) | payload

The JSON meta holds the scalar fields; array fields (numpy) and byte fields travel in the payload,
described in the meta under ``"_blobs"`` as ``[name, dtype, shape]`` (``dtype`` ``"bytes"`` for raw
bytes), in order. :func:`decode` rejects a wrong magic, an unknown version or type, bad JSON,
missing or mistyped fields, a payload whose size does not match and arrays of one message whose
shapes or types disagree (a centreline message's ``joints_x`` must be (n, N_j+1) for its n updates),
with a :class:`SchemaError` that names the key and the field. This module imports no transport: see
:mod:`flagtrack.daemon.transport` for Zenoh.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math
import struct
from dataclasses import field
from typing import Any, TypeVar

import numpy as np

from flagtrack.daemon.errors import SchemaError
from flagtrack.daemon.schema.messages import MESSAGE_TYPES, CentrelineMessage, MessageType, SensorSamples

MAGIC = b"FT"
VERSION = 3
"""Written in every message. 2 (2026-11-24) added optional fields (EventPacket.stream_id,
CentrelineMessage.stream, status counters); 3 (2026-11-27) the optional arrays
CentrelineMessage.stale and CentrelineMessage.shed (a build that reads only 1 and 2 would refuse an
unknown array by its name; it refuses the version instead). Messages of earlier versions decode with
their defaults, and scalar fields this build does not know are ignored, so scalar additions need no
new version."""
READABLE_VERSIONS = frozenset({1, 2, 3})
_HEADER = struct.Struct("<2sBBI")
M = TypeVar("M")


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
    message_type: type = type(message)
    for name in _field_names(message_type):
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

    Whatever the bytes, the only exception is :class:`SchemaError` (so that a subscriber that counts
    and skips those is never stopped by a message): JSON nested too deep to parse, integers beyond
    64 bits, a ``bytes`` blob for an array field or an array for a ``bytes`` one are refused by name,
    and anything else that goes wrong inside is turned into one.

    Args:
        data: the message bytes.
        expected: the message class wanted; another type raises SchemaError.
        key: the key expression it arrived on, for error messages.

    Raises:
        SchemaError: malformed bytes, unknown version or type, or not of ``expected`` type.
    """
    try:
        return _decode(data, expected, key)
    except SchemaError:
        raise
    except RecursionError:
        raise SchemaError("meta nested too deeply to decode", key=key) from None
    except Exception as exc:  # noqa: BLE001 - a message must never raise anything else (see above)
        raise SchemaError(f"cannot be decoded ({type(exc).__name__}: {str(exc)[:200]})", key=key) from None


def _decode(data: bytes | bytearray | memoryview, expected: type[M] | None, key: str | None) -> M:
    view = memoryview(data)
    if len(view) < _HEADER.size:
        raise SchemaError(f"{len(view)} bytes is shorter than the {_HEADER.size}-byte header", key=key)
    magic, version, type_id, meta_len = _HEADER.unpack_from(view)
    if magic != MAGIC:
        raise SchemaError(f"bad magic {bytes(magic)!r}, not a flagtrack message", key=key)
    if version not in READABLE_VERSIONS:
        raise SchemaError(
            f"unsupported schema version {version} (this build reads {', '.join(map(str, sorted(READABLE_VERSIONS)))})",
            key=key,
        )
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
        meta = json.loads(bytes(view[_HEADER.size : end]))
    except ValueError as exc:  # (~1000 nested brackets, a few kB, raise RecursionError: see decode)
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
    return cls(**_checked_scalars(cls, view_cls, meta, key), **blob_values)


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
                value: Any = bytes(payload[offset : offset + size])
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
        ("t_s", ("n",), _REAL),
        ("s", ("n_s",), _REAL),
        ("x", ("n", "n_s"), _REAL),
        ("y", ("n", "n_s"), _REAL),
        ("joints_x", ("n", "N_j+1"), _REAL),
        ("joints_y", ("n", "N_j+1"), _REAL),
        ("tip_x", ("n",), _REAL),
        ("tip_y", ("n",), _REAL),
        ("delta_rms", ("n",), _REAL),
        ("n_events", ("n",), _INT),
        ("source_ns", ("n",), _INT),
        ("lost", ("n",), _INT),
        ("stale", ("n",), _INT),
        ("shed", ("n",), _REAL),
    ),
    SensorSamples: (("t_us", ("n",), _INT), ("value", ("n",), _REAL), ("trigger_t_us", ("m",), _INT)),
}
_MIN_SIZE = {"n_s": 1, "N_j+1": 2}
_KIND_NAMES = {_REAL: "real numbers", _INT: "integers"}


def _check_shapes(
    cls: type, spec: tuple[tuple[str, tuple[str, ...], str], ...], values: dict[str, Any], key: str | None
) -> None:
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
            said = [
                f"{d} = {sizes[d]}" if d in sizes else f"{d} >= {_MIN_SIZE[d]}"
                for d in dims
                if d in sizes or d in _MIN_SIZE
            ]
            raise SchemaError(
                f"{cls.__name__}: field '{name}' has shape {shape}, expected ({', '.join(dims)}"
                f"{',' if len(dims) == 1 else ''}){' with ' + ', '.join(said) if said else ''}",
                key=key,
            )
        if array.dtype.kind not in kinds:
            raise SchemaError(
                f"{cls.__name__}: field '{name}' holds {array.dtype}, expected {_KIND_NAMES[kinds]}", key=key
            )


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
    if (dtype == "bytes") != (name in _bytes_fields(cls)):
        raise ValueError(f"{name}: {'bytes' if name in _bytes_fields(cls) else 'an array'} expected, got {dtype}")
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


@functools.cache
def _bytes_fields(cls: type) -> frozenset[str]:
    """Names of the fields of ``cls`` carried as raw bytes (the others of :func:`_blob_fields` are arrays)."""
    return frozenset(f.name for f in dataclasses.fields(cls) if f.type in ("bytes", bytes))


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
_I64_MIN, _I64_MAX = -(1 << 63), (1 << 63) - 1


def _fits_int64(value: Any) -> bool:
    """Whether an integer field's value fits numpy's int64 (what the services make of it)."""
    return bool(_I64_MIN <= value <= _I64_MAX)


@functools.cache
def _simple_types(cls: type) -> dict[str, type] | None:
    """Name -> exact Python type of each scalar field of ``cls``; ``None`` if one is not simple."""
    simple: dict[str, type] = {}
    for f in dataclasses.fields(cls):
        if not _is_blob(f):
            kind = _SIMPLE.get(f.type) if isinstance(f.type, str) else None
            if kind is None:
                return None
            simple[f.name] = kind
    return simple


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
        if expected is None or type(value) is not expected or (expected is int and not _fits_int64(value)):
            return False
    return True


def _checked_scalars(cls: type, view_cls: type, meta: dict[str, Any], key: str | None) -> dict[str, Any]:
    """The scalar fields of ``meta`` checked against ``cls``'s annotations (defaults where absent).

    Raises:
        SchemaError: a required field is missing or a value is not of its field's type.
    """
    values: dict[str, Any] = {}
    for f in dataclasses.fields(view_cls):
        if f.name not in meta:
            if _required(f):
                raise SchemaError(f"{cls.__name__}: required field '{f.name}' is missing", key=key)
            continue
        values[f.name] = _scalar(cls, f.name, f.type, meta[f.name], key)
    return values


def _scalar(cls: type, name: str, annotation: Any, value: Any, key: str | None) -> Any:
    kind = _SIMPLE.get(annotation) if isinstance(annotation, str) else annotation
    if annotation == "dict[str, Any]":
        kind = dict
    ok = isinstance(value, kind) if kind is not None else False
    if kind is int or kind is float:
        ok = isinstance(value, int | float if kind is float else int) and not isinstance(value, bool)
    if ok and kind is int and not _fits_int64(value):
        raise SchemaError(f"{cls.__name__}: field '{name}' is beyond 64 bits", key=key)
    if not ok:
        raise SchemaError(
            f"{cls.__name__}: field '{name}' expects {getattr(kind, '__name__', annotation)}, "
            f"got {type(value).__name__} {str(value)[:40]!r}",
            key=key,
        )
    if kind is float:
        try:
            return float(value)
        except OverflowError:
            raise SchemaError(f"{cls.__name__}: field '{name}' is out of range", key=key) from None
    return value
