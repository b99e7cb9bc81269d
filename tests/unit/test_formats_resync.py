"""Damaged RAW files keep what is readable: after a corrupt stretch the reader skips to the next valid
time base (EVT 3.0, 2.0, 2.1), keeps the rest with the right times, and lists what it skipped;
``strict`` refuses."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

from flagtrack.daemon.core.events import make_events
from flagtrack.daemon.errors import FormatError
from flagtrack.drivers.formats import FormatWarning, open_events, read_events, write_events
from flagtrack.drivers.formats.codec import Decoder, unwrap_units
from tests.unit.test_formats_files import assert_prefix_and_suffix

W, H = 640, 480


def steady_events(n: int = 60_000, seed: int = 1, t0: int = 16_700_000) -> np.ndarray:
    """About 30 ms of events per TIME_HIGH unit of EVT 3.0, across a 24-bit time wrap (at 16.78 s)."""
    rng = np.random.default_rng(seed)
    t = t0 + np.sort(rng.integers(0, 400_000, n))
    return make_events(t, rng.integers(0, W, n), rng.integers(0, H, n), rng.integers(0, 2, n))


def body_start(path: Path) -> int:
    return path.read_bytes().index(b"% end\n") + 6


def read_kept(path: Path, **options: object) -> tuple[np.ndarray, list, int]:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with open_events(path, **options) as reader:  # type: ignore[arg-type]
            events = reader.read().events
    assert all(issubclass(w.category, FormatWarning) for w in caught)
    assert len(caught) == len(reader.skipped)  # one warning per skipped range
    return events, reader.skipped, reader.events_lost_at_most


@pytest.mark.parametrize("encoding", ["evt3", "evt2"])
@pytest.mark.parametrize("chunk_bytes", [4096, 8 << 20])
@pytest.mark.parametrize("where", [0.3, 0.5, 0.93])
def test_a_reserved_word_loses_only_its_stretch(tmp_path: Path, encoding: str, chunk_bytes: int, where: float) -> None:
    events = steady_events()
    path = tmp_path / "a.raw"
    write_events(path, events, width=W, height=H, encoding=encoding)
    data, body = bytearray(path.read_bytes()), body_start(path)
    size = 2 if encoding == "evt3" else 4
    at = body + (int(where * (len(data) - body)) // size) * size
    data[at : at + size] = (0x9 << (8 * size - 4)).to_bytes(size, "little")  # a reserved type
    path.write_bytes(bytes(data))
    with pytest.raises(FormatError, match="reserved type 0x9") as err:
        read_events(path, strict=True)
    assert err.value.offset == at
    kept, skipped, at_most = read_kept(path, chunk_bytes=chunk_bytes)
    assert [r.start for r in skipped] == [at] and skipped[0].end > at
    assert 0 < len(events) - len(kept) <= at_most
    assert len(kept) > 0.9 * len(events)
    assert_prefix_and_suffix(kept, events)  # the times after the stretch are the true ones (wrap included)


def test_a_garbage_block_is_skipped_and_the_rest_kept(tmp_path: Path) -> None:
    events = steady_events()
    path = tmp_path / "g.raw"
    write_events(path, events, width=W, height=H, encoding="evt3")
    data, body = bytearray(path.read_bytes()), body_start(path)
    at = body + (len(data) - body) // 2
    data[at : at + 2000] = np.random.default_rng(3).integers(0, 256, 2000, dtype=np.uint8).tobytes()
    path.write_bytes(bytes(data))
    kept, skipped, at_most = read_kept(path)
    assert skipped and skipped[0].start >= at and skipped[-1].end > at + 2000
    tail = events[events["t"] > kept["t"][-1] - 100_000]  # the last 100 ms, well past the damage
    np.testing.assert_array_equal(kept[-len(tail) :], tail)
    np.testing.assert_array_equal(kept[: len(kept) // 4], events[: len(kept) // 4])
    assert abs(len(events) - len(kept)) <= at_most + 2000  # garbage may also decode as a few events


def test_a_decoder_fed_in_small_pieces_resynchronises(tmp_path: Path) -> None:
    events = steady_events(20_000)
    path = tmp_path / "a.raw"
    write_events(path, events, width=W, height=H, encoding="evt2")
    stream = path.read_bytes()[body_start(path) :]
    decoder = Decoder("evt2", width=W, height=H, strict=False, resync=True)
    bad = bytearray(stream)
    bad[len(bad) // 2 // 4 * 4 : len(bad) // 2 // 4 * 4 + 4] = (0x9 << 28).to_bytes(4, "little")
    with pytest.warns(FormatWarning, match="skipped to the next valid time base"):
        got = np.concatenate([decoder.decode(bytes(bad[i : i + 1000]))[0] for i in range(0, len(bad), 1000)])
        decoder.finish()
    assert len(decoder.skipped) == 1 and 0 < len(events) - len(got) <= decoder.events_lost_at_most
    assert_prefix_and_suffix(got, events)


def test_the_strict_reader_refuses_what_the_default_one_skips(tmp_path: Path) -> None:
    events = steady_events(5_000)
    path = tmp_path / "a.raw"
    write_events(path, events, width=W, height=H, encoding="evt3")
    data, body = bytearray(path.read_bytes()), body_start(path)
    data[body + 200 : body + 202] = (0xB000).to_bytes(2, "little")
    path.write_bytes(bytes(data))
    with open_events(path, strict=True) as reader, pytest.raises(FormatError):
        reader.read()
    assert reader.skipped == []


@pytest.mark.parametrize(
    ("prev", "raw", "want"),
    [
        (5, 6, 6),
        (4095, 0, 4096),
        (4090, 3, 4099),
        (4000, 100, 100),
        (4096 + 7, 2, 4096 + 2),
        (4096 * 3 + 4095, 1, 4096 * 4 + 1),
    ],
)
def test_unwrap_follows_the_decoders_threshold_rule(prev: int, raw: int, want: int) -> None:
    assert unwrap_units(prev, raw, 12) == want
