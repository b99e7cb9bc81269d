"""The tracker's event buffer: its live events survive drops, compactions and growth."""

from __future__ import annotations

import numpy as np

from flagtrack.daemon.core.buffer import SPARE, EventBuffer


def _append(buf: EventBuffer, t: np.ndarray) -> None:
    buf.reserve(len(t))
    buf.t[buf.n : buf.n + len(t)] = t
    buf.x[buf.n : buf.n + len(t)] = t % 640
    buf.y[buf.n : buf.n + len(t)] = t % 480
    buf.n += len(t)


def test_live_events_survive_drops_compactions_and_growth() -> None:
    rng = np.random.default_rng(0)
    buf, t0 = EventBuffer(), 0
    look_back = 100_000
    for _ in range(400):
        t = np.sort(rng.integers(t0, t0 + 10_000, 60_000))
        _append(buf, t)
        t0 += 10_000
        buf.drop_before(t0 - look_back)
        live = buf.times
        assert live[0] >= t0 - look_back and np.all(np.diff(live) >= 0)
        assert np.array_equal(buf.x[buf.start : buf.n], live % 640)
    assert len(buf.times) == 10 * 60_000  # the 100 ms look-back: the last 10 chunks
    assert len(buf.t) < 4 * 10 * 60_000  # compacted, not only grown


def test_preallocated_room_keeps_the_live_events_and_is_not_grown_again() -> None:
    buf = EventBuffer()
    _append(buf, np.arange(0, 5_000, dtype=np.int64))
    buf.drop_before(1_000)
    buf.preallocate(200_000)
    assert len(buf.t) >= (1 + SPARE) * 200_000 and len(buf.cum_region) == len(buf.t) + 1
    assert np.array_equal(buf.times, np.arange(1_000, 5_000))  # (compacted to the front)
    assert np.array_equal(buf.x[buf.start : buf.n], buf.times % 640)
    arrays = buf.t, buf.x, buf.cum_region
    _append(buf, np.arange(5_000, 150_000, dtype=np.int64))
    assert all(a is b for a, b in zip(arrays, (buf.t, buf.x, buf.cum_region)))  # the same memory
    buf.preallocate(10)  # smaller than it has: nothing changes
    assert buf.t is arrays[0]


def test_preallocating_less_than_the_live_events_keeps_them_all() -> None:
    buf = EventBuffer()
    _append(buf, np.arange(0, 50_000, dtype=np.int64))
    buf.drop_before(10)
    buf.preallocate(1_000)
    assert np.array_equal(buf.times, np.arange(10, 50_000)) and len(buf.t) >= (1 + SPARE) * len(buf.times)


class _CountingBuffer(EventBuffer):
    moved = 0

    def _compact(self) -> None:
        self.moved += self.n - self.start
        super()._compact()


def _stream(buf: EventBuffer, chunks: int, per_chunk: int, look_back: int) -> int:
    """Append ``chunks`` chunks of 10 ms, keeping ``look_back`` µs; return the events appended."""
    rng = np.random.default_rng(1)
    for i in range(chunks):
        _append(buf, np.sort(rng.integers(i * 10_000, (i + 1) * 10_000, per_chunk)))
        buf.drop_before((i + 1) * 10_000 - look_back)
    return chunks * per_chunk


def test_an_event_is_moved_at_most_once_on_average_whatever_the_look_back() -> None:
    for look_back in (20_000, 100_000, 500_000):
        buf = _CountingBuffer()
        appended = _stream(buf, 300, 20_000, look_back)
        assert 0 < buf.moved <= 1.1 * appended, look_back


def test_a_buffer_preallocated_for_its_stream_moves_an_event_half_a_time() -> None:
    buf = _CountingBuffer()
    buf.preallocate(10 * 20_000 + 20_000)  # the 100 ms look-back and a chunk
    arrays = buf.t
    appended = _stream(buf, 300, 20_000, 100_000)
    assert buf.t is arrays  # never grown
    assert 0 < buf.moved <= (1 / SPARE + 0.05) * appended  # (without the spare room: ~10 moves an event)
