"""When the viewer sends an entity's queued rows: at a size, at a row count, or when the oldest has waited;
which tracker updates it shows."""

from __future__ import annotations

import numpy as np
import pytest

from flagtrack.daemon.errors import ConfigError
from flagtrack.daemon.services.viewer import ViewerConfig
from flagtrack.daemon.services.viewer.batching import FlushPolicy, RowQueue, UpdateSlots, changes


def test_a_queue_is_due_when_its_oldest_row_has_waited_the_interval() -> None:
    policy = FlushPolicy(interval_s=0.25)
    queue = RowQueue()
    assert not policy.due(queue, 100.0)  # empty: never
    queue.add("a", 1, 16)
    assert not policy.due(queue, 100.0)  # the age is not known yet: the logger notes it at its next frame
    queue.since_s = 10.0
    queue.add("b", 1, 16)
    assert not policy.due(queue, 10.2)
    assert policy.due(queue, 10.25)
    assert queue.take() == ["a", "b"] and (queue.n_rows, queue.n_bytes, queue.since_s) == (0, 0, None)
    assert not policy.due(queue, 1e9)


def test_a_queue_is_due_at_a_size_or_a_row_count_whatever_its_age() -> None:
    policy = FlushPolicy(interval_s=30.0, chunk_bytes=1000, chunk_rows=10)
    by_size, by_rows = RowQueue(since_s=0.0), RowQueue(since_s=0.0)
    by_size.add("big", 2, 999)
    by_rows.add("many", 9, 90)
    assert not policy.due(by_size, 1.0) and not policy.due(by_rows, 1.0)
    by_size.add("more", 1, 1)
    by_rows.add("one more", 1, 10)
    assert policy.due(by_size, 1.0) and policy.due(by_rows, 1.0)


@pytest.mark.parametrize("key", ["flush_s", "rrd_flush_s", "geometry_rate_hz", "amplitude_window_s", "chunk_bytes"])
def test_the_viewer_section_refuses_a_rate_or_interval_that_is_not_positive(key: str) -> None:
    with pytest.raises(ConfigError, match=f"key 'viewer.{key}': must be a positive number"):
        ViewerConfig(**{key: 0})


def test_a_queue_of_its_own_row_limit_is_due_at_it() -> None:
    """Centrelines (LineStrips2D) go in chunks of at most 2 048 rows: Rerun reads a row of such a chunk
    back in a time that grows with the chunk."""
    from flagtrack.daemon.services.viewer.logger import MAX_ROWS

    policy = FlushPolicy(interval_s=30.0, chunk_bytes=1 << 30, chunk_rows=32_768)
    strips = RowQueue(since_s=0.0, max_rows=MAX_ROWS["tracker/centreline"])
    scalars = RowQueue(since_s=0.0)
    strips.add("lines", 2047, 2047 * 416)
    scalars.add("values", 2048, 2048 * 16)
    assert not policy.due(strips, 1.0) and not policy.due(scalars, 1.0)
    strips.add("one more", 1, 416)
    assert policy.due(strips, 1.0) and not policy.due(scalars, 1.0)


def test_the_view_shows_the_first_update_of_each_slot_whatever_the_batching() -> None:
    """1 kHz updates over 0.1 s, shown at 200 Hz: one update in five, the same ones in one batch or in
    uneven ones; None shows every update."""
    t = 2.0 + np.arange(100) * 1e-3
    whole = UpdateSlots(200.0).keep(t)
    slots = UpdateSlots(200.0)
    pieces = np.concatenate([slots.keep(part) for part in np.split(t, [3, 4, 37, 90])])
    np.testing.assert_array_equal(whole, pieces)
    assert whole.sum() == 20 and whole[0] and np.all(np.diff(t[whole]) > 0.004)
    assert UpdateSlots(None).keep(t).all()
    assert not UpdateSlots(200.0).keep(np.array([np.nan])).any()
    np.testing.assert_array_equal(changes([0, 0, 1, 1, 0], 0.0), [False, False, True, False, True])
