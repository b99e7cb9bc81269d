"""EVT 2.0 / 2.1 / 3.0 codecs against hand-decoded streams and slow reference codecs.

The reference encoders and decoders below are plain Python, one word at a time, written from
Prophesee's format pages and OpenEB's standalone decoders (not from flagtrack's kernels).
"""

from __future__ import annotations

import numpy as np
import pytest

from flagtrack.daemon.core.events import EVENT_DTYPE, TRIGGER_DTYPE, make_events
from flagtrack.daemon.errors import FormatError
from flagtrack.drivers.formats import FormatWarning, make_decoder, make_encoder

MAX_EVT3 = 4095 << 12
MAX_EVT2 = ((1 << 28) - 1) << 6


# ----------------------------------------------------------------- slow reference codecs


def evt3_word(kind: str, *a: int) -> int:
    """One EVT 3.0 word from the format table (type in the top 4 bits)."""
    if kind == "y":
        return (0x0 << 12) | a[0]
    if kind == "em_y":
        return (0x1 << 12) | a[0]
    if kind == "x":
        return (0x2 << 12) | (a[1] << 11) | a[0]
    if kind == "vbase":
        return (0x3 << 12) | (a[1] << 11) | a[0]
    if kind == "v12":
        return (0x4 << 12) | a[0]
    if kind == "v8":
        return (0x5 << 12) | a[0]
    if kind == "tlow":
        return (0x6 << 12) | a[0]
    if kind == "thigh":
        return (0x8 << 12) | a[0]
    if kind == "trigger":
        return (0xA << 12) | (a[0] << 8) | a[1]
    return {"cont4": 0x7, "others": 0xE, "cont12": 0xF}[kind] << 12 | (a[0] if a else 0)


def ref_decode_evt3(words: list[int]) -> tuple[list[tuple], list[tuple]]:  # noqa: PLR0912 - one branch per word type
    """OpenEB standalone EVT 3.0 semantics, word by word."""
    events, triggers = [], []
    base = time = y = xb = pol = loops = 0
    started, cd = False, True
    for w in words:
        typ, v = w >> 12, w & 0xFFF
        if not started and typ != 0x8:
            continue
        if typ == 0x8:
            started = True
            new = (v << 12) + loops * (1 << 24)
            if base > new and base - new >= MAX_EVT3 - (10 << 12):
                new += 1 << 24
                loops += 1
            base = time = new
        elif typ == 0x6:
            time = base + v
        elif typ == 0x0:
            y, cd = v & 0x7FF, True
        elif typ == 0x1:
            cd = False
        elif typ == 0x2 and cd:
            events.append((time, v & 0x7FF, y, v >> 11))
        elif typ == 0x3:
            xb, pol = v & 0x7FF, v >> 11
        elif typ in (0x4, 0x5):
            bits = 12 if typ == 0x4 else 8
            for b in range(bits):
                if cd and v >> b & 1:
                    events.append((time, xb + b, y, pol))
            xb += bits
        elif typ == 0xA:
            triggers.append((time, (v >> 8) & 0xF, v & 1))
    return events, triggers


def evt2_word(kind: str, *a: int) -> int:
    """One EVT 2.0 word: ("cd", p, t_low, x, y), ("thigh", t >> 6), ("trigger", t_low, ch, edge)."""
    if kind == "cd":
        p, low, x, y = a
        return (p << 28) | (low << 22) | (x << 11) | y
    if kind == "thigh":
        return (0x8 << 28) | a[0]
    if kind == "trigger":
        low, ch, edge = a
        return (0xA << 28) | (low << 22) | (ch << 8) | edge
    return {"others": 0xE, "continued": 0xF}[kind] << 28


def ref_decode_evt2(words: list[int]) -> tuple[list[tuple], list[tuple]]:
    """OpenEB standalone EVT 2.0 semantics, word by word."""
    events, triggers = [], []
    base, loops, started = 0, 0, False
    for w in words:
        typ = w >> 28
        if not started and typ != 0x8:
            continue
        if typ == 0x8:
            started = True
            new = ((w & 0xFFFFFFF) << 6) + loops * (1 << 34)
            if base > new and base - new >= MAX_EVT2 - (10 << 6):
                new += 1 << 34
                loops += 1
            base = new
        elif typ in (0, 1):
            events.append((base + (w >> 22 & 63), w >> 11 & 0x7FF, w & 0x7FF, typ))
        elif typ == 0xA:
            triggers.append((base + (w >> 22 & 63), w >> 8 & 0x1F, w & 1))
    return events, triggers


def evt21_bytes(words: list[tuple[int, int]], legacy: bool) -> bytes:
    """EVT 2.1 64-bit words given as (high half, validity half), in file byte order."""
    out = bytearray()
    for high, low in words:
        halves = (high, low) if legacy else (low, high)
        out += halves[0].to_bytes(4, "little") + halves[1].to_bytes(4, "little")
    return bytes(out)


def ref_decode_evt21(words: list[tuple[int, int]]) -> tuple[list[tuple], list[tuple]]:
    """OpenEB EVT21 decoder semantics: vectors of 32 pixels, wrap only from the maximum."""
    events, triggers = [], []
    base, loops, started = 0, 0, False
    for high, valid in words:
        typ = high >> 28
        if not started and typ != 0x8:
            continue
        if typ == 0x8:
            started = True
            new = (high & 0xFFFFFFF) << 6
            last = base - loops * (1 << 34)
            if new < last and last - new >= MAX_EVT2:
                loops += 1
            base = new + loops * (1 << 34)
        elif typ in (0, 1):
            t, x, y = base + (high >> 22 & 63), high >> 11 & 0x7FF, high & 0x7FF
            events += [(t, x + b, y, typ) for b in range(32) if valid >> b & 1]
        elif typ == 0xA:
            triggers.append((base + (high >> 22 & 63), high >> 8 & 0x1F, high & 1))
    return events, triggers


def as_tuples(events: np.ndarray, triggers: np.ndarray) -> tuple[list[tuple], list[tuple]]:
    return ([tuple(int(v) for v in e) for e in events], [tuple(int(v) for v in t) for t in triggers])


def u16(words: list[int]) -> bytes:
    return np.array(words, dtype="<u2").tobytes()


def u32(words: list[int]) -> bytes:
    return np.array(words, dtype="<u4").tobytes()


def decode_all(encoding: str, data: bytes, **options: object) -> tuple[list[tuple], list[tuple]]:
    decoder = make_decoder(encoding, **options)
    events, triggers = decoder.decode(data)
    decoder.finish()
    return as_tuples(events, triggers)


# ----------------------------------------------------------------- hand-decoded streams


def test_evt3_every_word_type_decodes_as_the_format_says() -> None:
    w = evt3_word
    words = [
        w("y", 9),
        w("x", 5, 1),  # before the first TIME_HIGH: skipped
        w("thigh", 1),
        w("tlow", 5),
        w("y", 10),
        w("x", 3, 1),
        w("vbase", 100, 0),
        w("v12", 0b101),
        w("v8", 0b1),  # x 100, 102, then 112
        w("tlow", 3),
        w("x", 7, 0),  # time steps back: kept as sent
        w("em_y", 5),
        w("x", 9, 1),
        w("vbase", 20, 1),
        w("v12", 1),  # EM: no CD events
        w("y", 11),
        w("trigger", 2, 1),
        w("others", 0x123),
        w("cont4", 1),
        w("cont12", 7),
        w("thigh", 4095),
        w("tlow", 4095),
        w("x", 4, 1),
        w("thigh", 2),
        w("x", 1, 0),  # 24-bit wrap: unwrapped to the next loop
        w("thigh", 4094),  # a small step back across a TIME_HIGH: kept
        w("x", 2, 0),
    ]
    events, triggers = decode_all("evt3", u16(words))
    assert events == [
        (4101, 3, 10, 1),
        (4101, 100, 10, 0),
        (4101, 102, 10, 0),
        (4101, 112, 10, 0),
        (4099, 7, 10, 0),
        (MAX_EVT3 + 4095, 4, 11, 1),
        ((1 << 24) + 8192, 1, 11, 0),
        ((1 << 24) + 4094 * 4096, 2, 11, 0),
    ]
    assert triggers == [(4099, 2, 1)]


def test_evt2_time_high_low_bits_and_wrap() -> None:
    w = evt2_word
    words = [
        w("cd", 1, 0, 1, 1),
        w("thigh", 100),
        w("cd", 1, 5, 639, 479),
        w("cd", 0, 63, 0, 0),
        w("trigger", 7, 3, 1),
        w("others"),
        w("continued"),
        w("cd", 0, 2, 10, 20),
        w("thigh", (1 << 28) - 1),
        w("cd", 1, 1, 2, 3),
        w("thigh", 0),
        w("cd", 0, 0, 4, 5),
    ]
    events, triggers = decode_all("evt2", u32(words))
    assert events == [
        (6405, 639, 479, 1),
        (6463, 0, 0, 0),
        (6402, 10, 20, 0),
        (MAX_EVT2 + 1, 2, 3, 1),
        (1 << 34, 4, 5, 0),
    ]
    assert triggers == [(6407, 3, 1)]


@pytest.mark.parametrize("legacy", [False, True])
def test_evt21_vectors_in_both_layouts(legacy: bool) -> None:
    words = [
        ((0x8 << 28) | 2, 0),  # TIME_HIGH: base 128 µs
        ((1 << 28) | (3 << 22) | (64 << 11) | 7, 0b1011),  # ON at x 64, 65, 67
        ((0 << 28) | (9 << 22) | (96 << 11) | 8, 1 << 31),  # OFF at x 127
        ((0xA << 28) | (4 << 22) | (5 << 8) | 1, 0),  # trigger
    ]
    events, triggers = decode_all("evt21", evt21_bytes(words, legacy), endianness="legacy" if legacy else "little")
    assert events == [(131, 64, 7, 1), (131, 65, 7, 1), (131, 67, 7, 1), (137, 127, 8, 0)]
    assert triggers == [(132, 5, 1)]


# ----------------------------------------------------------------- random streams vs reference


def random_evt3_words(rng: np.random.Generator, n: int) -> list[int]:
    """A random valid EVT 3.0 stream: time that mostly advances, wraps, steps back a little."""
    words, high = [evt3_word("thigh", int(rng.integers(0, 4096)))], 0
    for _ in range(n):
        r = rng.random()
        if r < 0.04:
            high = (high + int(rng.integers(0, 3000)) if rng.random() < 0.9 else high - int(rng.integers(0, 3))) % 4096
            words.append(evt3_word("thigh", high))
        elif r < 0.2:
            words.append(evt3_word("tlow", int(rng.integers(0, 4096))))
        elif r < 0.4:
            words.append(evt3_word("y", int(rng.integers(0, 720))))
        elif r < 0.75:
            words.append(evt3_word("x", int(rng.integers(0, 1280)), int(rng.integers(0, 2))))
        elif r < 0.82:
            words.append(evt3_word("vbase", int(rng.integers(0, 1248)), int(rng.integers(0, 2))))
        elif r < 0.88:
            words.append(evt3_word("v12", int(rng.integers(0, 4096))))
        elif r < 0.91:
            words.append(evt3_word("v8", int(rng.integers(0, 256))))
        elif r < 0.93:
            words.append(evt3_word("trigger", int(rng.integers(0, 16)), int(rng.integers(0, 2))))
        elif r < 0.95:
            words.append(evt3_word("em_y", int(rng.integers(0, 720))))
        else:
            words.append(evt3_word(str(rng.choice(["others", "cont4", "cont12"])), int(rng.integers(0, 4096))))
    return words


@pytest.mark.parametrize("seed", range(3))
def test_evt3_random_streams_match_the_reference_in_any_pieces(seed: int) -> None:
    rng = np.random.default_rng(seed)
    words = random_evt3_words(rng, 20_000)
    data = u16(words)
    expected = ref_decode_evt3(words)
    assert len(expected[0]) > 5000
    assert decode_all("evt3", data) == expected
    decoder = make_decoder("evt3", max_events=100)
    parts, pos = [], 0
    while pos < len(data):
        step = int(rng.integers(1, 300))
        parts.append(decoder.decode(data[pos : pos + step]))
        pos += step
    decoder.finish()
    events = np.concatenate([p[0] for p in parts])
    triggers = np.concatenate([p[1] for p in parts])
    assert as_tuples(events, triggers) == expected


@pytest.mark.parametrize("seed", range(2))
def test_evt2_random_streams_match_the_reference(seed: int) -> None:
    rng = np.random.default_rng(seed)
    words, high = [evt2_word("thigh", 5)], 5
    for _ in range(5000):
        r = rng.random()
        if r < 0.05:
            high = (high + int(rng.integers(-2, 1 << 26))) % (1 << 28)
            words.append(evt2_word("thigh", high))
        elif r < 0.93:
            words.append(
                evt2_word(
                    "cd",
                    int(rng.integers(0, 2)),
                    int(rng.integers(0, 64)),
                    int(rng.integers(0, 640)),
                    int(rng.integers(0, 480)),
                )
            )
        else:
            words.append(
                evt2_word("trigger", int(rng.integers(0, 64)), int(rng.integers(0, 32)), int(rng.integers(0, 2)))
            )
    data = u32(words)
    expected = ref_decode_evt2(words)
    assert decode_all("evt2", data, width=640, height=480) == expected
    decoder, parts = make_decoder("evt2"), []
    for cut in np.array_split(np.arange(len(data)), 37):
        parts.append(decoder.decode(data[cut[0] : cut[-1] + 1]))
    assert as_tuples(np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])) == expected


@pytest.mark.parametrize("legacy", [False, True])
def test_evt21_random_streams_match_the_reference(legacy: bool) -> None:
    rng = np.random.default_rng(7)
    words, high = [((0x8 << 28) | 9, 0)], 9
    for _ in range(3000):
        r = rng.random()
        if r < 0.05:
            high = (high + int(rng.integers(0, 1 << 20))) % (1 << 28)
            words.append(((0x8 << 28) | high, 0))
        elif r < 0.95:
            head = (int(rng.integers(0, 2)) << 28) | (int(rng.integers(0, 64)) << 22)
            head |= (int(rng.integers(0, 40)) * 32 << 11) | int(rng.integers(0, 720))
            words.append((head, int(rng.integers(0, 1 << 32))))
        else:
            words.append(((0xA << 28) | (int(rng.integers(0, 64)) << 22) | (3 << 8) | 1, 0))
    words += [((0x8 << 28) | ((1 << 28) - 1), 0), ((1 << 28) | 5, 1), ((0x8 << 28), 0), ((1 << 28) | 6, 1)]
    data = evt21_bytes(words, legacy)
    expected = ref_decode_evt21(words)
    options = {"endianness": "legacy" if legacy else "little"}
    assert decode_all("evt21", data, **options) == expected
    assert expected[0][-1] == (1 << 34, 0, 6, 1)  # the wrap from the maximum to 0
    decoder, parts = make_decoder("evt21", max_events=64, **options), []
    for start in range(0, len(data), 1001):
        parts.append(decoder.decode(data[start : start + 1001]))
    assert as_tuples(np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])) == expected


# ----------------------------------------------------------------- encoders


def tricky_events(rng: np.random.Generator, n: int, t0: int = 0) -> np.ndarray:
    """Events with vector-friendly runs, small backward steps, and gaps of several EVT 3.0 loops."""
    dt = rng.choice([0, 0, 0, 1, 2, 50, 5000, -3], size=n, p=[0.3, 0.1, 0.1, 0.2, 0.1, 0.1, 0.05, 0.05])
    dt[rng.random(n) < 0.002] = 40_000_000  # more than two loops of 2**24 µs
    events = make_events(
        t0 + 10 + np.cumsum(dt), rng.integers(0, 640, n), rng.integers(0, 480, n), rng.integers(0, 2, n)
    )
    run = rng.random(n) < 0.6  # event i continues a run of consecutive x at the same t, y, p
    for i in np.flatnonzero(run[1:]) + 1:
        if events["x"][i - 1] < 639:
            events[i] = (events["t"][i - 1], events["x"][i - 1] + 1, events["y"][i - 1], events["p"][i - 1])
    return events


def test_evt3_encoder_output_decodes_with_the_reference() -> None:
    rng = np.random.default_rng(1)
    events = tricky_events(rng, 5000)
    triggers = np.zeros(20, dtype=TRIGGER_DTYPE)
    triggers["t"] = np.sort(rng.choice(events["t"], 20))
    triggers["channel"], triggers["edge"] = rng.integers(0, 16, 20), rng.integers(0, 2, 20)
    data = make_encoder("evt3", t_offset_us=0).encode(events, triggers)
    words = np.frombuffer(data, dtype="<u2")
    assert np.any(words >> 12 == 4)  # vectors were used
    assert as_tuples(events, triggers) == ref_decode_evt3(words.tolist())


def test_evt2_encoder_output_decodes_with_the_reference() -> None:
    rng = np.random.default_rng(2)
    events = tricky_events(rng, 3000)
    events["t"] += 3 << 34  # several EVT 2.0 loops: the offset is the loop of the first event
    encoder = make_encoder("evt2")
    data = encoder.encode(events[:1000]) + encoder.encode(events[1000:])
    assert encoder.t_offset_us == 3 << 34
    decoded = ref_decode_evt2(np.frombuffer(data, dtype="<u4").tolist())[0]
    assert [(t + encoder.t_offset_us, x, y, p) for t, x, y, p in decoded] == as_tuples(events, events[:0])[0]


@pytest.mark.parametrize("encoding", ["evt2", "evt3"])
def test_packets_concatenate_and_decode_in_any_pieces(encoding: str) -> None:
    rng = np.random.default_rng(3)
    events = tricky_events(rng, 20_000, t0=1_605_537_493_718_345)  # epoch µs, as in AEDAT4 files
    at = np.array([10, 5000, 9000, 15000, 19990])
    triggers = np.zeros(len(at), dtype=TRIGGER_DTYPE)
    triggers["t"], triggers["channel"], triggers["edge"] = events["t"][at], np.arange(len(at)), 1
    encoder = make_encoder(encoding, width=640, height=480)
    bounds = [0, *np.sort(rng.choice(np.arange(1, len(events)), 30, replace=False)), len(events)]
    stream = b"".join(
        encoder.encode(events[a:b], triggers[(at >= a) & (at < b)]) for a, b in zip(bounds[:-1], bounds[1:])
    )
    decoder = make_decoder(encoding, width=640, height=480, t_offset_us=encoder.t_offset_us)
    pieces, pos = [], 0
    while pos < len(stream):
        step = int(rng.integers(1, 5000))
        pieces.append(decoder.decode(stream[pos : pos + step]))
        pos += step
    decoder.finish()
    np.testing.assert_array_equal(np.concatenate([p[0] for p in pieces]), events)
    np.testing.assert_array_equal(np.concatenate([p[1] for p in pieces]), triggers)


def test_evt3_encoder_agrees_with_the_evt3_library() -> None:
    evt3 = pytest.importorskip("evt3")
    events = tricky_events(np.random.default_rng(4), 20_000)
    data = make_encoder("evt3", t_offset_us=0, width=640, height=480).encode(events)
    theirs = evt3.decode_bytes(data, sensor_width=640, sensor_height=480)
    np.testing.assert_array_equal(np.asarray(theirs.timestamp, dtype=np.int64), events["t"])
    np.testing.assert_array_equal(theirs.x, events["x"])
    np.testing.assert_array_equal(theirs.y, events["y"])
    np.testing.assert_array_equal(np.asarray(theirs.polarity, dtype=np.uint8), events["p"])


# ----------------------------------------------------------------- faults


@pytest.mark.parametrize(
    ("encoding", "data", "index", "width"),
    [
        ("evt3", u16([evt3_word("thigh", 1), evt3_word("y", 3), 0x9000, evt3_word("x", 1, 1)]), 2, None),
        ("evt3", u16([evt3_word("thigh", 1), evt3_word("y", 3), evt3_word("x", 700, 1)]), 2, 640),
        ("evt2", u32([evt2_word("thigh", 1), evt2_word("cd", 1, 0, 3, 4), 0x3000_0000]), 2, None),
        ("evt2", u32([evt2_word("thigh", 1), evt2_word("cd", 1, 0, 650, 4)]), 1, 640),
    ],
)
def test_a_corrupt_word_is_reported_with_its_offset(encoding: str, data: bytes, index: int, width: int | None) -> None:
    size = {"evt3": 2, "evt2": 4}[encoding]
    with pytest.raises(FormatError) as err:
        make_decoder(encoding, width=width, height=480 if width else None, source="cam", base_offset=100).decode(data)
    assert err.value.offset == 100 + index * size and err.value.path == "cam"
    assert "cam, byte" in str(err.value) and "corrupt" in str(err.value)
    lenient = make_decoder(encoding, width=width, height=480 if width else None, strict=False)
    with pytest.warns(FormatWarning, match="corrupt"):
        lenient.decode(data)
    assert lenient.faults == 1


def test_corrupt_word_non_strict_keeps_events_before_and_after() -> None:
    words = [evt3_word("thigh", 1), evt3_word("y", 3), evt3_word("x", 1, 1), 0xB000, evt3_word("x", 2, 0)]
    decoder = make_decoder("evt3", strict=False)
    with pytest.warns(FormatWarning):
        events, _ = decoder.decode(u16(words))
    assert as_tuples(events, events[:0])[0] == [(4096, 1, 3, 1), (4096, 2, 3, 0)]


def test_stream_cut_inside_a_word_is_reported_at_finish() -> None:
    decoder = make_decoder("evt2", source="f.raw", base_offset=10)
    decoder.decode(u32([evt2_word("thigh", 1), evt2_word("cd", 1, 0, 1, 1)]) + b"\x01\x02")
    with pytest.raises(FormatError) as err:
        decoder.finish()
    assert err.value.offset == 18 and "f.raw" in str(err.value)


@pytest.mark.parametrize(
    ("encoding", "times", "message"),
    [
        ("evt3", [(1 << 24) + 5, 3], "steps back"),  # back across a loop
        ("evt2", [-1], "before"),  # before the stream's offset 0
    ],
)
def test_encoder_refuses_what_the_format_cannot_carry(encoding: str, times: list[int], message: str) -> None:
    events = make_events(np.array(times), np.zeros(len(times)), np.zeros(len(times)), np.ones(len(times)))
    with pytest.raises(FormatError, match=message):
        make_encoder(encoding, t_offset_us=0).encode(events)


def test_encoder_refuses_events_outside_the_sensor() -> None:
    events = make_events(np.array([5]), np.array([640]), np.array([0]), np.array([1]))
    with pytest.raises(FormatError, match="out of range"):
        make_encoder("evt3", width=640, height=480).encode(events)


def test_unknown_encoding_is_refused() -> None:
    with pytest.raises(FormatError, match="unknown encoding"):
        make_decoder("evt4")
    assert EVENT_DTYPE.itemsize == 13
