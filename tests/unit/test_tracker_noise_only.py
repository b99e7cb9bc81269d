"""A stream that starts with nothing but isolated noise (a still flag) must not break the tracker."""

from __future__ import annotations

import numpy as np

from flagtrack.daemon.core.events import make_events
from flagtrack.daemon.core.tracker import Tracker
from flagtrack.daemon.tracking_config import TrackingConfig


def test_noise_only_start_then_time_passing() -> None:
    tracker = Tracker(TrackingConfig(root=(150.0, 240.0), length=300.0, tau_s=0.001).tracker_params())
    lonely = make_events(np.array([0, 5_000]), np.array([10, 600]), np.array([10, 400]), np.array([1, 0]))
    tracker.feed(lonely)  # both are filtered out by the denoiser: the buffer is empty
    later = make_events(np.array([9_000]), np.array([300]), np.array([100]), np.array([1]))
    batch = tracker.feed(later)
    assert np.all(np.isfinite(batch.x)) and np.all(np.diff(batch.t_s) > 0)
    np.testing.assert_allclose(batch.y, 240.0)  # no evidence: the chain stays at rest
