"""The tracker's event buffer: its live events survive drops, compactions and growth."""

from __future__ import annotations

import numpy as np

from flagtrack.daemon.core.buffer import EventBuffer


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
