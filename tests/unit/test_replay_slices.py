"""The paced replay hands a file over in slices of camera time that partition the stream."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from flagtrack.daemon.core.events import TRIGGER_DTYPE, make_events
from flagtrack.drivers.camera.base import EndOfStream
from flagtrack.drivers.camera.replay import ReplayCamera, ReplayConfig
from flagtrack.drivers.formats import read_events, write_events


def slices(path: Path, slice_us: int) -> list[tuple[np.ndarray, np.ndarray, int]]:
    camera = ReplayCamera(ReplayConfig(path, speed=1e9, slice_us=slice_us, native=False))  # paced, no waiting
    camera.open()
    out = []
    while True:
        try:
            data = camera.read(1.0)
        except EndOfStream:
            return out
        if data is not None:
            out.append((data.events, data.triggers, data.t_until_us))


@pytest.mark.parametrize("slice_us", [250, 1000, 7000])
def test_slices_partition_the_stream_in_slots_of_the_running_time(tmp_path: Path, slice_us: int) -> None:
    rng = np.random.default_rng(5)
    n = 400_000  # several of the replay's reads (256 KB), so slices continue across them
    t = np.cumsum(rng.integers(0, 3, n)).astype(np.int64) + 1_000
    t[rng.choice(n, 300, replace=False)] -= 2  # small steps back in time, as real sensors make
    t[n // 2 :] += 30_000  # a pause: empty slots are skipped, not handed over
    events = make_events(t, rng.integers(0, 640, n), rng.integers(0, 480, n), rng.integers(0, 2, n))
    triggers = np.zeros(40, dtype=TRIGGER_DTYPE)
    triggers["t"] = np.sort(rng.integers(1_000, int(t.max()), 40))
    triggers["edge"] = np.arange(40) % 2
    path = tmp_path / "steps.raw"
    write_events(path, events, width=640, height=480, encoding="evt3", triggers=triggers)
    want = read_events(path)

    got = slices(path, slice_us)

    np.testing.assert_array_equal(np.concatenate([s[0] for s in got]), want.events)
    np.testing.assert_array_equal(np.concatenate([s[1] for s in got]), want.triggers)
    until = [s[2] for s in got]
    assert until == sorted(set(until))  # one slice per slot, in order
    running_max = np.maximum.accumulate(want.events["t"])
    starts = np.cumsum([0] + [len(s[0]) for s in got])
    for (events, slice_triggers, t_until), start in zip(got[:-1], starts):  # the last ends the file
        assert t_until % slice_us == 0
        assert np.all(slice_triggers["t"] < t_until)
        slots = running_max[start : start + len(events)] // slice_us  # each slice: one slot of the running time
        assert np.all(slots == t_until // slice_us - 1)


def test_a_looped_replay_repeats_the_file_later_in_time(tmp_path: Path) -> None:
    rng = np.random.default_rng(6)
    n = 100_000
    t = np.cumsum(rng.integers(0, 3, n)).astype(np.int64) + 500
    events = make_events(t, rng.integers(0, 640, n), rng.integers(0, 480, n), rng.integers(0, 2, n))
    path = tmp_path / "loop.raw"
    write_events(path, events, width=640, height=480, encoding="evt3")
    want = read_events(path).events
    camera = ReplayCamera(ReplayConfig(path, speed=1e9, loop=True))
    camera.open()
    got = []
    while sum(len(e) for e in got) < 3 * n:
        data = camera.read(1.0)
        if data is not None:
            got.append(data.events)
    stream = np.concatenate(got)[: 3 * n]
    assert camera.loops >= 2
    assert np.all(np.diff(stream["t"]) >= 0)  # time goes on increasing across the loops
    for k in range(3):
        part = stream[k * n : (k + 1) * n]
        np.testing.assert_array_equal(part[["x", "y", "p"]], want[["x", "y", "p"]])
        shift = int(part["t"][0] - want["t"][0])
        np.testing.assert_array_equal(part["t"], want["t"] + shift)
        assert (shift > 0) == (k > 0)
