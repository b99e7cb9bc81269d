"""A stream that starts with nothing but isolated noise (a still flag) must not break the tracker."""

from __future__ import annotations

import numpy as np

from flagtrack.daemon.core.centreline import CentrelineBatch
from flagtrack.daemon.core.events import make_events
from flagtrack.daemon.core.tracker import Tracker
from flagtrack.daemon.tracking.section import TrackingConfig


def _assert_at_rest_without_evidence(batch: CentrelineBatch, t_ms: list[float]) -> None:
    """Updates at ``t_ms`` (window centres), each the straight rest chain with no event in its areas."""
    np.testing.assert_allclose(batch.t_s, np.array(t_ms) * 1e-3, atol=1e-12)
    np.testing.assert_array_equal(batch.n_events, 0)
    assert np.all(np.isnan(batch.delta_rms))  # no event: no distance to average
    np.testing.assert_allclose(batch.joints_x, np.tile(np.linspace(150.0, 450.0, 11), (len(batch), 1)), atol=1e-9)
    np.testing.assert_allclose(batch.joints_y, 240.0, atol=1e-9)
    np.testing.assert_allclose(batch.x, np.tile(np.linspace(150.0, 450.0, 51), (len(batch), 1)), atol=1e-9)
    np.testing.assert_allclose(batch.y, 240.0, atol=1e-9)


def test_noise_only_start_then_time_passing() -> None:
    tracker = Tracker(TrackingConfig(root=(150.0, 240.0), length=300.0, tau_s=0.001).tracker_params())
    lonely = make_events(np.array([0, 5_000]), np.array([10, 600]), np.array([10, 400]), np.array([1, 0]))
    # both are filtered out by the denoiser: the buffer stays empty, but the 1 ms windows that end
    # by the last event (t = 5 ms) are complete, starting at the first event
    _assert_at_rest_without_evidence(tracker.feed(lonely), [0.5, 1.5, 2.5, 3.5, 4.5])
    later = make_events(np.array([9_000]), np.array([300]), np.array([100]), np.array([1]))
    _assert_at_rest_without_evidence(tracker.feed(later), [5.5, 6.5, 7.5, 8.5])  # the 4 windows ending by 9 ms
    _assert_at_rest_without_evidence(tracker.finish(), [9.5])  # the window that starts at the last event
    stats = tracker.stats
    assert (stats.events_in, stats.events_kept, stats.updates) == (3, 0, 10)
    assert (stats.first_t_us, stats.last_t_us) == (0, 9_000)
    np.testing.assert_allclose(tracker.state.angles_rad, 0.0)
