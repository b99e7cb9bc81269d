"""Event files: write then read back identical, stream in chunks, report bad input precisely."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from flagtrack.daemon.core.events import TRIGGER_DTYPE, make_events
from flagtrack.daemon.errors import FormatError
from flagtrack.drivers.formats import FormatWarning, open_events, read_events, write_events

W, H = 640, 480


def sample_events(n: int = 30_000, t0: int = 1_000, seed: int = 0) -> np.ndarray:
    """Events with small backward time steps and a gap of more than one 24-bit time loop."""
    rng = np.random.default_rng(seed)
    dt = rng.choice([0, 1, 3, -2], size=n, p=[0.4, 0.4, 0.15, 0.05])
    dt[n // 2] = 20_000_000
    return make_events(t0 + np.cumsum(dt), rng.integers(0, W, n), rng.integers(0, H, n), rng.integers(0, 2, n))


def sample_triggers(events: np.ndarray) -> np.ndarray:
    triggers = np.zeros(4, dtype=TRIGGER_DTYPE)
    triggers["t"] = np.sort(events["t"][[5, 100, len(events) // 2 + 10, len(events) - 3]])
    triggers["channel"], triggers["edge"] = [0, 1, 0, 1], [1, 0, 1, 0]
    return triggers


@pytest.mark.parametrize(("name", "encoding"), [("a.raw", "evt3"), ("a.raw", "evt2"), ("a.npy", None), ("a.csv", None)])
def test_round_trip_is_identical(tmp_path: Path, name: str, encoding: str | None) -> None:
    events = sample_events()
    triggers = sample_triggers(events)
    path = tmp_path / name
    write_events(path, events, width=W, height=H, encoding=encoding, triggers=triggers)
    rec = read_events(path, strict=True)
    np.testing.assert_array_equal(rec.events, events)
    np.testing.assert_array_equal(rec.triggers, triggers)
    assert rec.info.encoding == encoding
    assert (rec.info.width, rec.info.height) == ((None, None) if name.endswith(".npy") else (W, H))


def test_round_trip_of_epoch_times_through_evt3(tmp_path: Path) -> None:
    events = sample_events(t0=1_633_953_690_975_950)  # AEDAT4 clocks are Unix µs
    write_events(tmp_path / "e.raw", events, width=W, height=H)
    np.testing.assert_array_equal(read_events(tmp_path / "e.raw").events, events)


def test_dat_round_trip(tmp_path: Path) -> None:
    events = sample_events(t0=0)
    write_events(tmp_path / "a.dat", events, width=W, height=H)
    rec = read_events(tmp_path / "a.dat", strict=True)
    np.testing.assert_array_equal(rec.events, events)
    assert (rec.info.format, rec.info.width, rec.info.height) == ("dat", W, H)


@pytest.mark.parametrize("name", ["c.raw", "c.npy", "c.csv", "c.dat"])
def test_chunks_are_bounded_and_in_order(tmp_path: Path, name: str) -> None:
    events = sample_events(t0=0)
    write_events(tmp_path / name, events, width=W, height=H)
    with open_events(tmp_path / name, chunk_bytes=8192) as reader:
        chunks = list(reader)
    assert len(chunks) > 5
    assert max(len(c.events) for c in chunks) * 13 <= 4 * 8192
    offsets = [c.byte_offset for c in chunks]
    assert offsets == sorted(offsets) and offsets[0] > 0
    np.testing.assert_array_equal(np.concatenate([c.events for c in chunks]), events)


def write_raw(tmp_path: Path, events: np.ndarray) -> tuple[Path, int]:
    path = tmp_path / "f.raw"
    write_events(path, events, width=W, height=H, encoding="evt3")
    data = path.read_bytes()
    return path, data.index(b"% end\n") + 6


def test_truncated_raw(tmp_path: Path) -> None:
    events = sample_events(t0=0)
    path, body = write_raw(tmp_path, events)
    data = path.read_bytes()
    path.write_bytes(data[:-1])  # cut inside the last 16-bit word
    with pytest.raises(FormatError) as err:
        read_events(path, strict=True)
    assert err.value.path == str(path) and err.value.offset == len(data) - 2
    assert f"{path}, byte {len(data) - 2}" in str(err.value)
    with pytest.warns(FormatWarning, match="truncated"):
        rec = read_events(path)
    np.testing.assert_array_equal(rec.events, events[: len(rec.events)])
    assert len(rec.events) >= len(events) - 1


def test_corrupt_word_in_raw(tmp_path: Path) -> None:
    events = sample_events(t0=0)
    path, body = write_raw(tmp_path, events)
    data = bytearray(path.read_bytes())
    index = (len(data) - body) // 4  # a word in the middle of the stream
    data[body + 2 * index : body + 2 * index + 2] = (0x9ABC).to_bytes(2, "little")
    path.write_bytes(bytes(data))
    with pytest.raises(FormatError, match="reserved type 0x9") as err:
        read_events(path, strict=True)
    assert err.value.offset == body + 2 * index
    with pytest.warns(FormatWarning, match=f"bytes {body + 2 * index}-"), open_events(path) as reader:
        rec = reader.read()  # by default: skipped to the next valid time base, the rest kept
    assert [r.start for r in reader.skipped] == [body + 2 * index]
    assert 0 < len(events) - len(rec.events) <= reader.events_lost_at_most
    assert_prefix_and_suffix(rec.events, events)


def assert_prefix_and_suffix(kept: np.ndarray, events: np.ndarray) -> None:
    """``kept`` is ``events`` with one stretch left out: a prefix of it, then a suffix."""
    differs = np.flatnonzero(kept != events[: len(kept)])
    k = int(differs[0]) if len(differs) else len(kept)
    assert 0 < k < len(kept), "events on both sides of the damage are kept"
    np.testing.assert_array_equal(kept[:k], events[:k])
    np.testing.assert_array_equal(kept[k:], events[len(events) - (len(kept) - k) :])


@pytest.mark.parametrize(
    ("content", "message", "offset"),
    [
        (b"% date x\n% format EVT7;width=2;height=2\n% end\n\x00\x00", "unknown encoding", 9),
        (b"% evt 3.0\n%\xff\xfe\n\x00\x00", "garbage", 11),
        (b"\x00\x80\x12\x34random", "not a RAW file", 0),
    ],
)
def test_bad_raw_headers(tmp_path: Path, content: bytes, message: str, offset: int) -> None:
    path = tmp_path / "bad.raw"
    path.write_bytes(content)
    for strict in (True, False):
        with pytest.raises(FormatError, match=message) as err:
            read_events(path, strict=strict)
        assert err.value.offset == offset and err.value.path == str(path)


def test_truncated_npy_keeps_whole_events(tmp_path: Path) -> None:
    events = sample_events(1000, t0=0)
    write_events(tmp_path / "t.npy", events, width=None, height=None)
    data = (tmp_path / "t.npy").read_bytes()
    (tmp_path / "t.npy").write_bytes(data[:-20])
    with pytest.raises(FormatError, match="ends after 998 of 1000") as err:
        read_events(tmp_path / "t.npy", strict=True)
    assert err.value.offset == len(data) - 2 * 13
    with pytest.warns(FormatWarning):
        np.testing.assert_array_equal(read_events(tmp_path / "t.npy").events, events[:998])


def test_garbage_npy_header(tmp_path: Path) -> None:
    (tmp_path / "g.npy").write_bytes(b"\x93NUMPY\x01\x00\x10\x00{'descr': oops}\n")
    with pytest.raises(FormatError, match="garbage .npy header"):
        read_events(tmp_path / "g.npy")


def test_bad_csv_row_names_the_byte(tmp_path: Path) -> None:
    path = tmp_path / "b.csv"
    path.write_bytes(b"t,x,y,p\n1,2,3,1\n5,6,x,0\n7,8,9,1\n")
    with pytest.raises(FormatError, match="bad CSV row") as err:
        read_events(path, strict=True)
    assert err.value.offset == 20
    with pytest.warns(FormatWarning):
        rec = read_events(path)
    assert rec.events.tolist() == [(1, 2, 3, 1)]


def test_csv_columns_in_any_order_and_minus_one_polarity(tmp_path: Path) -> None:
    path = tmp_path / "o.csv"
    path.write_bytes(b"# width=10 height=20\nx,y,p,t\n1,2,-1,100\n3,4,1,101\r\n\n")
    rec = read_events(path, strict=True)
    assert rec.events.tolist() == [(100, 1, 2, 0), (101, 3, 4, 1)]
    assert (rec.info.width, rec.info.height) == (10, 20)


def test_truncated_dat(tmp_path: Path) -> None:
    events = sample_events(100, t0=0)
    write_events(tmp_path / "d.dat", events, width=W, height=H)
    data = (tmp_path / "d.dat").read_bytes()
    (tmp_path / "d.dat").write_bytes(data[:-3])
    with pytest.raises(FormatError, match="truncated") as err:
        read_events(tmp_path / "d.dat", strict=True)
    assert err.value.offset == len(data) - 8


def test_unknown_extension_and_missing_file(tmp_path: Path) -> None:
    (tmp_path / "x.bin").write_bytes(b"\x00" * 8)
    with pytest.raises(FormatError, match="unknown event file type"):
        open_events(tmp_path / "x.bin")
    with pytest.raises(FormatError, match="no such file"):
        open_events(tmp_path / "missing.raw")


def test_raw_writer_needs_the_sensor_size(tmp_path: Path) -> None:
    with pytest.raises(FormatError, match="width and height"):
        write_events(tmp_path / "n.raw", sample_events(10), width=None, height=None)
