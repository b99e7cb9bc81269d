"""Wire schema: exact round trips, and clear errors for malformed or wrong-version bytes."""

from __future__ import annotations

import dataclasses
import json
import logging
import struct

import numpy as np
import pytest

from flagtrack.daemon import schema
from flagtrack.daemon.core.centreline import CentrelineBatch
from flagtrack.daemon.errors import SchemaError
from flagtrack.daemon.problems import ProblemLog
from flagtrack.daemon.schema import (
    CameraStatus,
    CentrelineMessage,
    EventPacket,
    Keys,
    SensorSamples,
    TunnelCommand,
    decode,
    encode,
)


def centreline_message() -> CentrelineMessage:
    rng = np.random.default_rng(0)
    n_t, n_s = 4, 51
    batch = CentrelineBatch(
        t_s=np.arange(n_t) * 1e-3,
        s=np.linspace(0, 1, n_s),
        x=rng.normal(size=(n_t, n_s)),
        y=rng.normal(size=(n_t, n_s)),
        joints_x=rng.normal(size=(n_t, 11)),
        joints_y=rng.normal(size=(n_t, 11)),
        delta_rms=rng.random(n_t),
        n_events=np.arange(n_t, dtype=np.int64),
    )
    return CentrelineMessage.from_batch(batch, source="tracker", seq=7, units="px", source_ns=np.arange(n_t) + 10**18)


def packet() -> EventPacket:
    return EventPacket(
        "cam0",
        3,
        1000,
        1999,
        42,
        640,
        480,
        "evt3",
        1_700_000_000_000_000_000,
        t_offset_us=16_777_216,
        n_triggers=2,
        end_of_stream=True,
        data=bytes(range(256)),
    )


def test_event_packet_round_trip() -> None:
    assert decode(encode(packet()), EventPacket) == packet()


def test_centrelines_round_trip_exactly() -> None:
    msg = centreline_message()
    got = decode(encode(msg), CentrelineMessage)
    for f in dataclasses.fields(msg):
        a, b = getattr(msg, f.name), getattr(got, f.name)
        assert np.array_equal(a, b) if isinstance(a, np.ndarray) else a == b, f.name
    np.testing.assert_array_equal(got.batch().tip_x, msg.x[:, -1])


@pytest.mark.parametrize(
    "message",
    [
        CameraStatus("cam0", "streaming", "simulated", 640, 480, "evt3", {"biases": {"bias_fo": 3}}),
        TunnelCommand("set", 5.5),
        SensorSamples("om70", 1, "m", np.arange(5, dtype=np.int64), np.linspace(0, 1, 5)),
    ],
)
def test_other_messages_round_trip(message: object) -> None:
    got = decode(encode(message))
    assert type(got) is type(message)
    assert encode(got) == encode(message)


@pytest.mark.parametrize(
    "message",
    [
        packet(),
        centreline_message(),
        CameraStatus("cam0", "streaming", "simulated", 640, 480, "evt3", {"biases": {"bias_fo": 3}}, 'dé"jà'),
        TunnelCommand("set", 5.5),
        SensorSamples("om70", 1, "m", np.arange(5, dtype=np.int64)[::2], np.linspace(0, 1, 6).reshape(2, 3)[:, 1]),
        CentrelineMessage.from_batch(
            CentrelineBatch(
                t_s=np.zeros(0),
                s=np.linspace(0, 1, 3),
                x=np.zeros((0, 3)),
                y=np.zeros((0, 3)),
                joints_x=np.zeros((0, 2)),
                joints_y=np.zeros((0, 2)),
                delta_rms=np.zeros(0),
                n_events=np.zeros(0, dtype=np.int64),
            ),
            source="tracker",
            seq=0,
            units="m",
            source_ns=np.zeros(0, dtype=np.int64),
            final=True,
        ),
    ],
)
def test_meta_is_the_json_that_json_dumps_writes(message: object) -> None:
    """The encoder writes the blob descriptors as text: the meta must still be exactly ``json.dumps``
    of the scalar fields then ``_blobs`` (the wire format other tools parse), and the payload the
    arrays in C order (non-contiguous ones included)."""
    data = encode(message)
    meta_len = struct.unpack_from("<2sBBI", data)[3]
    meta_bytes = data[8 : 8 + meta_len]
    scalars, blobs, payload = {}, [], []
    for f in dataclasses.fields(message):
        value = getattr(message, f.name)
        if isinstance(value, np.ndarray):
            blobs.append([f.name, value.dtype.str, list(value.shape)])
            payload.append(np.ascontiguousarray(value).tobytes())
        elif isinstance(value, bytes):
            blobs.append([f.name, "bytes", [len(value)]])
            payload.append(value)
        else:
            scalars[f.name] = value
    assert meta_bytes == json.dumps({**scalars, "_blobs": blobs}, separators=(",", ":")).encode()
    assert data[8 + meta_len :] == b"".join(payload)


def with_meta(meta: dict, type_id: int = schema.MessageType.EVENT_PACKET, payload: bytes = b"") -> bytes:
    body = json.dumps(meta).encode()
    return struct.pack("<2sBBI", b"FT", schema.VERSION, type_id, len(body)) + body + payload


GOOD_META = {f.name: getattr(packet(), f.name) for f in dataclasses.fields(EventPacket) if f.name != "data"}


@pytest.mark.parametrize(
    ("data", "words"),
    [
        (b"FT\x01", "shorter than"),
        (b"XX" + encode(packet())[2:], "bad magic"),
        (encode(packet())[:2] + b"\x09" + encode(packet())[3:], "unsupported schema version 9"),
        (encode(packet())[:3] + b"\x63" + encode(packet())[4:], "unknown message type 99"),
        (encode(packet())[:-1], "truncated"),
        (encode(packet()) + b"\x00", "trailing"),
        (with_meta({**GOOD_META, "_blobs": []})[:-3], "runs past"),
        (struct.pack("<2sBBI", b"FT", 1, 1, 3) + b"{x}", "not valid JSON"),
        (with_meta({**GOOD_META, "seq": "three", "_blobs": []}), "seq"),
        (with_meta({**{k: v for k, v in GOOD_META.items() if k != "width"}, "_blobs": []}), "width"),
        (with_meta({**GOOD_META, "_blobs": [["data", "bytes", [4]]]}), "truncated"),
        (with_meta({**GOOD_META, "_blobs": [["nope", "bytes", [0]]]}), "bad payload descriptor"),
        (with_meta({**GOOD_META}), "_blobs"),
    ],
)
def test_malformed_bytes_raise_clear_errors(data: bytes, words: str) -> None:
    with pytest.raises(SchemaError, match=words) as info:
        decode(data, key="flagtrack/x/camera/cam0/events")
    assert "flagtrack/x/camera/cam0/events" in str(info.value)


def with_blobs(message: object, edit: object) -> bytes:
    """``message`` encoded, with its payload descriptors changed by ``edit(blobs)``."""
    data = encode(message)
    magic, version, type_id, meta_len = struct.unpack_from("<2sBBI", data)
    meta = json.loads(data[8 : 8 + meta_len])
    edit(meta["_blobs"])
    body = json.dumps(meta).encode()
    return struct.pack("<2sBBI", magic, version, type_id, len(body)) + body + data[8 + meta_len :]


def _set(index: int, part: int, value: object):
    def edit(blobs: list) -> None:
        blobs[index][part] = value

    return edit


@pytest.mark.parametrize(
    ("data", "words"),
    [
        (with_blobs(packet(), _set(0, 2, [])), "bad payload descriptor"),  # bytes without a length
        (with_blobs(centreline_message(), _set(0, 1, "|O")), "not a plain array type"),
        (with_blobs(centreline_message(), _set(0, 1, "<bogus")), "bad payload descriptor"),
        (with_blobs(centreline_message(), _set(0, 2, ["x"])), "bad payload descriptor"),
        (with_blobs(centreline_message(), _set(0, 2, [-4])), "bad payload descriptor"),
        (with_blobs(centreline_message(), _set(-1, 2, [10**6])), "truncated"),
        (with_blobs(centreline_message(), _set(0, 2, [0] * 65)), "bad payload descriptor"),  # numpy: 64 dims at most
        (with_blobs(centreline_message(), _set(0, 1, {"names": ["a"], "formats": ["<f8"]})), "bad payload descriptor"),
        (with_blobs(centreline_message(), _set(0, 2, [0, 10**20])), "bad payload descriptor"),
        (with_blobs(centreline_message(), _set(0, 2, [float("inf")])), "bad payload descriptor"),
        (with_blobs(centreline_message(), _set(0, 1, ",")), "bad payload descriptor"),
        (with_blobs(centreline_message(), _set(0, 1, "(2,3)<i4")), "not a plain array type"),
        (with_blobs(centreline_message(), _set(0, 1, "|S0")), "not a plain array type"),
        (with_blobs(centreline_message(), lambda blobs: blobs.append(list(blobs[0]))), "bad payload descriptor"),
        (  # the last four blobs: the optional shed (4 float32), stale and lost (4 uint8 each), and source_ns (4 int64)
            with_blobs(centreline_message(), lambda blobs: (blobs.pop(), blobs.pop(), blobs.pop(), blobs.pop()))[:-56],
            "missing payload field 'source_ns'",
        ),
    ],
)
def test_malformed_payload_descriptors_raise_clear_errors(data: bytes, words: str) -> None:
    with pytest.raises(SchemaError, match=words):
        decode(data, key="flagtrack/x/centrelines")


def test_decoded_arrays_are_read_only_views_of_the_message() -> None:
    got = decode(encode(centreline_message()), CentrelineMessage)
    assert not got.x.flags.writeable and got.x.shape == (4, 51) and got.x.dtype == np.float64


def test_wrong_type_is_refused() -> None:
    with pytest.raises(SchemaError, match="expected CentrelineMessage, got EventPacket"):
        decode(encode(packet()), CentrelineMessage)


def test_keys_are_lowercase_slash_words_under_namespace() -> None:
    keys = Keys("flagtrack/rig1")
    names = [
        keys.camera_events("cam0"),
        keys.camera_status("cam0"),
        keys.event_rate("cam0"),
        keys.centrelines(),
        keys.tracker_status(),
        keys.tunnel_state(),
        keys.tunnel_command(),
        keys.supervisor_state(),
        keys.recorder_command(),
        keys.recorder_status(),
        keys.sensor_samples("om70"),
        keys.alive("tracker"),
    ]
    assert len(set(names)) == len(names)
    for name in names:
        assert name.startswith("flagtrack/rig1/") and name == name.lower() and "//" not in name


def test_sensor_samples_carry_pulses_missing_counts_and_clock() -> None:
    msg = SensorSamples(
        "om70",
        4,
        "mm",
        np.array([10, 20, 30], dtype=np.int64),
        np.array([1.5, np.nan, 2.5]),
        trigger_t_us=np.array([15, 65], dtype=np.int64),
        missing=3,
        clock="host",
        wall_ns=1_700_000_000_123,
    )
    got = decode(encode(msg), SensorSamples)
    np.testing.assert_array_equal(got.value, msg.value)  # NaN = a missing sample, kept
    np.testing.assert_array_equal(got.trigger_t_us, [15, 65])
    assert (got.missing, got.clock, got.wall_ns) == (3, "host", 1_700_000_000_123)


def test_sensor_samples_of_the_first_layout_still_decode() -> None:
    t_us, value = np.arange(3, dtype=np.int64), np.ones(3)
    meta = {
        "sensor_id": "om70",
        "seq": 1,
        "units": "mm",
        "_blobs": [["t_us", t_us.dtype.str, [3]], ["value", value.dtype.str, [3]]],
    }
    got = decode(with_meta(meta, schema.MessageType.SENSOR_SAMPLES, t_us.tobytes() + value.tobytes()), SensorSamples)
    assert got.missing == 0 and got.clock == "sensor" and len(got.trigger_t_us) == 0
    with pytest.raises(SchemaError, match="missing"):
        decode(
            with_meta({**meta, "missing": "many"}, schema.MessageType.SENSOR_SAMPLES, t_us.tobytes() + value.tobytes())
        )


def test_descriptor_checks_cache_no_oversized_shape() -> None:
    """A shape of a million zero dimensions is refused without being kept in the descriptor cache
    (any publisher could otherwise make a service hold megabytes per message)."""
    before = schema.codec._blob_layout.cache_info().currsize
    data = with_blobs(centreline_message(), _set(0, 2, [0] * 1_000_000))
    with pytest.raises(SchemaError, match="bad payload descriptor"):
        decode(data)
    assert schema.codec._blob_layout.cache_info().currsize == before


def test_object_arrays_are_not_sent() -> None:
    """Their bytes are pointers: encoding refuses them (as before), naming the field."""
    with pytest.raises(TypeError, match="t_us"):
        encode(SensorSamples("om70", 1, "m", np.array([1, "x"], dtype=object), np.linspace(0, 1, 2)))


def _replaced(message: object, **fields: object) -> bytes:
    """``message`` with some fields replaced, encoded (encoding does not check shapes: a buggy or
    foreign publisher's bytes)."""
    return encode(dataclasses.replace(message, **fields))


_MSG = centreline_message()  # 4 updates, 51 samples, 10 links


@pytest.mark.parametrize(
    ("data", "words"),
    [
        (
            _replaced(_MSG, joints_x=_MSG.joints_x[:, 0]),
            r"'joints_x' has shape \(4,\), expected \(n, N_j\+1\) with n = 4",
        ),
        (_replaced(_MSG, joints_y=_MSG.joints_y[:, :5]), r"'joints_y' has shape \(4, 5\).*N_j\+1 = 11"),
        (_replaced(_MSG, joints_x=_MSG.joints_x[:, :1], joints_y=_MSG.joints_y[:, :1]), r"'joints_x'.*N_j\+1 >= 2"),
        (_replaced(_MSG, x=_MSG.x[:, :3]), r"'x' has shape \(4, 3\), expected \(n, n_s\) with n = 4, n_s = 51"),
        (_replaced(_MSG, y=_MSG.y[:3]), r"'y' has shape \(3, 51\)"),
        (_replaced(_MSG, t_s=_MSG.t_s.reshape(2, 2)), r"'t_s' has shape \(2, 2\), expected \(n,\)"),
        (_replaced(_MSG, s=np.zeros(0), x=np.zeros((4, 0)), y=np.zeros((4, 0))), r"'s' has shape \(0,\).*n_s >= 1"),
        (_replaced(_MSG, delta_rms=_MSG.delta_rms[:2]), r"'delta_rms' has shape \(2,\)"),
        (_replaced(_MSG, tip_x=_MSG.tip_x[:, None]), r"'tip_x'"),
        (_replaced(_MSG, source_ns=np.arange(5)), r"'source_ns' has shape \(5,\)"),
        (_replaced(_MSG, n_events=_MSG.n_events.astype(float)), r"'n_events' holds float64, expected integers"),
        (_replaced(_MSG, t_s=np.array(["a", "b", "c", "d"])), r"'t_s' holds <U1, expected real numbers"),
        (encode(SensorSamples("om70", 1, "m", np.arange(3, dtype=np.int64), np.ones(2))), r"'value' has shape \(2,\)"),
        (
            encode(SensorSamples("om70", 1, "m", np.arange(3, dtype=np.int64), np.ones(3), np.ones((2, 2), np.int64))),
            r"'trigger_t_us' has shape \(2, 2\), expected \(m,\)",
        ),
    ],
)
def test_arrays_that_disagree_are_refused_naming_key_and_field(data: bytes, words: str) -> None:
    """A message that decodes but whose arrays disagree (a 1-D ``joints_x`` crashed the viewer) is
    a SchemaError naming the key and the field, which services count and skip."""
    with pytest.raises(SchemaError, match=words) as info:
        decode(data, key="flagtrack/x/tracker/centreline")
    assert "flagtrack/x/tracker/centreline" in str(info.value)


def test_arrays_that_agree_decode_whatever_their_sizes() -> None:
    """No updates, one sample, one link, and integer coordinates are all consistent."""
    n_s, joints = 1, 2
    empty = CentrelineMessage.from_batch(
        CentrelineBatch(
            t_s=np.zeros(0),
            s=np.zeros(n_s),
            x=np.zeros((0, n_s)),
            y=np.zeros((0, n_s)),
            joints_x=np.zeros((0, joints)),
            joints_y=np.zeros((0, joints)),
            delta_rms=np.zeros(0),
            n_events=np.zeros(0, dtype=np.int64),
        ),
        source="tracker",
        seq=0,
        units="px",
        source_ns=np.zeros(0, dtype=np.int64),
        final=True,
        stream=3,
    )
    got = decode(encode(empty), CentrelineMessage)
    assert got.final and got.stream == 3 and got.joints_x.shape == (0, 2)
    ints = _replaced(_MSG, x=np.zeros((4, 51), dtype=np.int32), source_ns=np.arange(4, dtype=np.uint64))
    assert decode(ints, CentrelineMessage).x.dtype == np.int32


def test_problem_log_logs_the_first_at_once_then_rate_limited_summaries(caplog: pytest.LogCaptureFixture) -> None:
    logger = logging.getLogger("flagtrack.test.problems")
    problems = ProblemLog(logger, "svc", interval_s=3600.0)
    with caplog.at_level(logging.WARNING, logger="flagtrack.test.problems"):
        for k in range(1000):
            problems.add("gaps", f"gap {k}", 2)
        problems.add("malformed", "bad bytes")
        problems.flush()  # the interval has not passed: nothing more
        assert [r.getMessage() for r in caplog.records] == ["svc: gap 0 [gaps: 2]", "svc: bad bytes [malformed: 1]"]
        problems.flush(force=True)  # at the end: the summary of what was not logged
    assert caplog.records[-1].getMessage().startswith("svc: 1998 more gaps in the last")
    assert caplog.records[-1].getMessage().endswith("(2000 in all); latest: gap 999")
    assert len(caplog.records) == 3 and problems.totals == {"gaps": 2000, "malformed": 1}
