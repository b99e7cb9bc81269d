"""Loss of track live (issues 19 and 30): the tracker service publishes ``lost`` and ``stale`` with each
update, as offline, and counts lost stretches in its status."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from flagtrack.daemon.core.tracker import Tracker
from flagtrack.drivers.formats import write_events
from flagtrack.drivers.sim.disruptions import disrupted, occlusion
from flagtrack.drivers.sim.quickline import QuickLineParams, line_events
from tests.integration.test_tracker_service import CONFIG, FLAG, live, offline


def test_live_lost_equals_offline_and_stretches_are_counted(tmp_path: Path) -> None:
    """A chain resting 90 degrees off the flag, and an object crossing it: lost, then found, live as offline."""
    events = np.concatenate(list(line_events(FLAG, 0, 400_000, 640, 480, QuickLineParams(events_per_px2=20.0))))
    events = disrupted("crossing", events, FLAG.root, FLAG.length, seed=1).events
    path = tmp_path / "flag.raw"
    write_events(path, events, width=640, height=480, encoding="evt3")
    config = CONFIG.with_overrides(direction_deg=90.0)
    want = offline(path, config)
    got, statuses, service = live(path, config)
    assert len(got) == len(want) and want.lost.any() and not want.lost[-200:].any()
    np.testing.assert_array_equal(got.lost, want.lost)
    np.testing.assert_allclose(got.x, want.x, rtol=0, atol=1e-9)
    stretches = int(np.count_nonzero(np.diff(want.lost.astype(int), prepend=0) == 1))
    assert statuses[-1].lost_stretches == service.lost.stretches == stretches >= 1
    assert statuses[-1].lost_updates == int(want.lost.sum())
    tracker = Tracker(config.tracker_params(), sensor_size=(640, 480))
    tracker.feed(events)
    assert tracker.stats.lost_stretches >= 1


def test_live_stale_equals_offline(tmp_path: Path) -> None:
    """The laser blocked for 300 ms: the updates after 0.1 s of it say stale, live as offline."""
    events = np.concatenate(list(line_events(FLAG, 0, 500_000, 640, 480, QuickLineParams(events_per_px2=20.0))))
    events = occlusion(events, 100_000, 400_000)
    path = tmp_path / "blocked.raw"
    write_events(path, events, width=640, height=480, encoding="evt3")
    want = offline(path, CONFIG)
    got, _, _ = live(path, CONFIG)
    t = want.t_s
    assert want.stale[(t > 0.21) & (t < 0.39)].all() and not want.stale[(t > 0.02) & (t < 0.09)].any()
    assert not want.lost[want.stale == 1].any()  # a stale update is not lost
    np.testing.assert_array_equal(got.stale, want.stale)
    np.testing.assert_array_equal(got.lost, want.lost)
    np.testing.assert_allclose(got.x, want.x, rtol=0, atol=1e-9)
