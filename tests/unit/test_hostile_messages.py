"""Messages made to hurt: every decode error is a SchemaError, and what decodes but cannot be used is
told apart (onset detector, point analysis, packet header checks, the recording preamble) without an
exception, a hang or a huge allocation."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from flagtrack.daemon.core.centreline import CentrelineBatch
from flagtrack.daemon.core.onset import OnsetDetector
from flagtrack.daemon.errors import FormatError, SchemaError
from flagtrack.daemon.schema import (
    MESSAGE_TYPES,
    CentrelineMessage,
    EventPacket,
    EventRate,
    MessageType,
    RecorderCommand,
    SensorSamples,
    decode,
    encode,
)
from flagtrack.daemon.schema.codec import _HEADER, MAGIC
from flagtrack.daemon.services.sequence import MAX_JUMP_US, PacketSequence, packet_problem
from flagtrack.daemon.services.supervisor.analysis import point_metrics, usable_batches
from flagtrack.drivers.formats.packets import MAX_OFFSET_US, stream_preamble

RATE = '"camera_id":"c","t_us":1,"interval_s":0.1,"events":1,"on_fraction":0.5,"_blobs":[]'


def wire(type_id: int, meta: str, payload: bytes = b"") -> bytes:
    data = meta.encode()
    return _HEADER.pack(MAGIC, 2, type_id, len(data)) + data + payload


@pytest.mark.parametrize(
    ("data", "words"),
    [
        # JSON nested ~1000 deep (4 kB): RecursionError in json.loads before
        (wire(MessageType.EVENT_RATE, "{" + RATE + ',"rate_hz":' + "[" * 1000 + "]" * 1000 + "}"), "nested too deeply"),
        (
            wire(
                MessageType.CAMERA_STATUS,
                '{"camera_id":"c","state":"s","adapter":"a","width":1,"height":1,"encoding":'
                '"evt3","settings":' + '{"a":' * 1000 + "1" + "}" * 1000 + ',"_blobs":[]}',
            ),
            "nested too deeply",
        ),
        (wire(MessageType.EVENT_RATE, "{" + RATE + ',"unknown":' + "[" * 5000 + "]" * 5000 + "}"), "nested too deeply"),
        # a 400-digit integer in a float field, and in an integer field (numpy's int64 would overflow later)
        (wire(MessageType.EVENT_RATE, "{" + RATE + ',"rate_hz":' + "9" * 400 + "}"), "rate_hz' is out of range"),
        (
            wire(MessageType.EVENT_RATE, "{" + RATE.replace('"t_us":1', '"t_us":' + "9" * 400) + ',"rate_hz":1.0}'),
            "t_us' is beyond 64 bits",
        ),
        (
            wire(
                MessageType.EVENT_PACKET,
                '{"camera_id":"c","seq":' + str(1 << 63) + ',"t_first_us":0,"t_last_us":0,'
                '"n_events":0,"width":1,"height":1,"encoding":"evt3","sent_ns":0,"_blobs":[["data","bytes",[0]]]}',
            ),
            "seq' is beyond 64 bits",
        ),
        # a bytes blob for an array field (AttributeError before), an array for the bytes field
        (
            wire(
                MessageType.SENSOR_SAMPLES,
                '{"sensor_id":"s","seq":0,"units":"mm","_blobs":[["t_us","bytes",[8]],["value","<f8",[1]]]}',
                bytes(16),
            ),
            "an array expected, got bytes",
        ),
        (
            wire(
                MessageType.EVENT_PACKET,
                '{"camera_id":"c","seq":0,"t_first_us":0,"t_last_us":0,"n_events":0,"width":1,'
                '"height":1,"encoding":"evt3","sent_ns":0,"_blobs":[["data","<u2",[2]]]}',
                bytes(4),
            ),
            "bytes expected",
        ),
    ],
)
def test_hostile_bytes_are_schema_errors(data: bytes, words: str) -> None:
    with pytest.raises(SchemaError, match=words):
        decode(data, key="k")


def test_mutated_messages_raise_nothing_but_schema_errors() -> None:
    """20 000 random mutations of valid messages (bytes flipped, cut, repeated, meta values swapped
    for big numbers and nested lists): each decodes or raises SchemaError, in bounded time."""
    rng = np.random.default_rng(18)
    one = np.ones((2, 5))
    valid = [
        encode(EventRate("cam0", 10, 0.1, 5, 50.0, 0.5, 99)),
        encode(RecorderCommand("start", path="x", request_id="r")),
        encode(EventPacket("cam0", 3, 1, 2, 4, 640, 480, "evt3", 7, data=bytes(range(64)))),
        encode(SensorSamples("s", 1, "mm", np.arange(4, dtype=np.int64), np.ones(4))),
        encode(
            CentrelineMessage(
                "t",
                0,
                "px",
                np.arange(2.0),
                np.arange(5.0),
                one,
                one,
                np.ones((2, 3)),
                np.ones((2, 3)),
                np.ones(2),
                np.ones(2),
                np.ones(2),
                np.ones(2, np.int64),
                np.ones(2, np.int64),
            )
        ),
    ]
    swaps = [b"9" * 400, b"[" * 990 + b"]" * 990, b"-1", b"1e999", b"NaN", b'"x"', b"{}", b"null", b"true"]
    other = 0
    start = time.perf_counter()
    for i in range(20_000):
        data = bytearray(valid[i % len(valid)])
        kind = rng.integers(4)
        if kind == 0:
            for _ in range(rng.integers(1, 4)):
                data[rng.integers(len(data))] = rng.integers(256)
        elif kind == 1:
            data = data[: rng.integers(len(data))]
        elif kind == 2:
            colon = [k for k in range(len(data)) if data[k] == ord(":")]
            if colon:
                k = colon[rng.integers(len(colon))] + 1
                data = data[:k] + swaps[rng.integers(len(swaps))] + data[k:]
                data[4:8] = (int.from_bytes(data[4:8], "little") + len(data) - len(valid[i % len(valid)])).to_bytes(
                    4, "little"
                )
        else:
            data[1] = rng.integers(256)
        try:
            decode(bytes(data), key="k")
        except SchemaError:
            pass
        except Exception:  # noqa: BLE001 - what the test looks for
            other += 1
    assert other == 0
    assert time.perf_counter() - start < 30


def test_the_onset_detector_says_which_samples_it_cannot_take() -> None:
    detector = OnsetDetector()
    detector.update(1.0, 10.0)
    assert detector.sample_problem(0.5, 10.0).startswith("time went backwards")
    assert detector.sample_problem(2.0, -1.0).startswith("negative event rate")
    assert detector.sample_problem(2.0, math.inf).startswith("infinite event rate")
    assert "not a finite number" in detector.sample_problem(math.nan, 10.0)
    assert detector.sample_problem(2.0, math.nan) is None  # a missing rate is a sample
    with pytest.raises(ValueError, match="backwards"):
        detector.update(0.5, 10.0)
    assert detector.update(2.0, 10.0).t_s == 2.0  # refused samples changed nothing


def batch(t_s: list[float] | np.ndarray, n_s: int = 10, joints: int = 4) -> CentrelineBatch:
    t = np.asarray(t_s, dtype=float)
    n = len(t)
    x = np.tile(np.linspace(0, 200, n_s), (n, 1))
    y = 240 + 20 * np.sin(np.nan_to_num(t, posinf=0, neginf=0)[:, None] * 60) + np.zeros((n, n_s))
    return CentrelineBatch(
        t,
        np.linspace(0, 200, n_s),
        x,
        y,
        np.zeros((n, joints)),
        np.zeros((n, joints)),
        np.zeros(n),
        np.ones(n, np.int64),
    )


@pytest.mark.parametrize(
    "bad",
    [
        [batch([0.6], n_s=7)],  # another shape (ValueError in concatenate before)
        [batch([0.6], joints=3)],
        [batch(np.arange(100) * 1e-3)],  # back in time
        [batch([math.nan] * 20)],  # ValueError in arange before
        [batch([math.inf])],
        [batch([1e12])],  # far ahead: a 7 PiB resampling grid before
    ],
)
def test_point_analysis_leaves_out_centrelines_it_cannot_use(bad: list[CentrelineBatch]) -> None:
    good = [batch(np.arange(k * 100, (k + 1) * 100) * 1e-3) for k in range(5)]
    want = point_metrics(good, 200, (100, 240), 0)
    got = point_metrics([*good[:3], *bad, *good[3:]], 200, (100, 240), 0)
    assert got.updates == 500 and got.amplitude_over_l == want.amplitude_over_l
    assert [len(b) for b in usable_batches([batch([0.0, 0.2, 0.1, 0.3]), batch([0.25, 0.4, math.nan, 0.5, 99])])] == [
        3,
        2,
    ]


def test_a_time_offset_decades_away_is_refused_before_any_preamble() -> None:
    """An EVT 3.0 preamble is 4 bytes per 16.8 s loop: decades would be 7 GB (np.tile or MemoryError)."""
    decades = (30 * 365 * 86_400_000_000 >> 24) << 24
    start = time.perf_counter()
    with pytest.raises(FormatError, match="more than a year"):
        stream_preamble("evt3", decades)
    assert time.perf_counter() - start < 0.1
    assert len(stream_preamble("evt3", (MAX_OFFSET_US >> 24) << 24)) < 8 << 20  # a year: 7.5 MB at most
    far = EventPacket("cam0", 0, decades + 5, decades + 900, 10, 640, 480, "evt3", 0, decades)
    assert "more than a year" in packet_problem(far)


def test_a_packet_may_not_jump_past_its_streams_horizon() -> None:
    """The tracker walks its windows through the time a packet skips (a day: 19 s; decades: forever)."""
    sequence = PacketSequence()
    assert sequence.arrive(0, 5)[1] == 0 and sequence.horizon_us is None
    sequence.follow_horizon(2_000)
    loop = 1 << 24
    ahead = MAX_JUMP_US + 10_000
    offset = (ahead // loop) * loop
    jump = EventPacket("cam0", 1, ahead, ahead + 500, 10, 640, 480, "evt3", 0, offset)
    assert "more than an hour past the stream" in packet_problem(jump, sequence.horizon_us)
    assert packet_problem(jump) is None  # the first packet of a stream may start anywhere
    empty = EventPacket("cam0", 1, 2_000, 10**15, 0, 640, 480, "evt3", 0, 0)  # a horizon carried decades on
    assert "more than an hour past" in packet_problem(empty, sequence.horizon_us)
    wide = EventPacket("cam0", 0, 5, 10**15, 10, 640, 480, "evt3", 0, 0)  # one packet spanning decades
    assert "past its first event" in packet_problem(wide)
    assert sequence.arrive(0, 6)[0].value == "new stream" and sequence.horizon_us is None


def test_every_message_type_is_covered() -> None:
    assert set(MESSAGE_TYPES) == set(MessageType)
