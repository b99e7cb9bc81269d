"""The robust default (adaptive background-activity filter) keeps the tracker independent of chunking."""

from __future__ import annotations

import numpy as np
import pytest

from flagtrack.daemon.core.centreline import CentrelineBatch
from flagtrack.daemon.core.tracker import Tracker, track
from flagtrack.daemon.tracking.section import TrackingConfig
from flagtrack.drivers.sim.quickline import QuickLineParams, WavyFlag, line_events

FLAG = WavyFlag()


@pytest.mark.slow
def test_noisy_stream_gives_the_same_updates_however_it_is_cut() -> None:
    # noise dense enough that the filter asks for more than one neighbour part of the time
    params = QuickLineParams(events_per_px2=20, noise_rate_hz=2e7)
    events = np.concatenate(list(line_events(FLAG, 0, 15_000, 640, 480, params, seed=5)))
    config = TrackingConfig(root=FLAG.root, length=FLAG.length, tau_s=2.5e-4)
    tracker_params = config.tracker_params()
    whole = track(events, tracker_params)
    tracker = Tracker(tracker_params)
    cuts = np.sort(np.random.default_rng(1).integers(0, len(events), 300))
    parts = CentrelineBatch.concatenate([*(tracker.feed(c) for c in np.split(events, cuts)), tracker.finish()])
    assert len(whole) > 50 and len(parts) == len(whole)
    for name in ("t_s", "x", "y", "joints_x", "joints_y", "delta_rms"):
        np.testing.assert_allclose(getattr(parts, name), getattr(whole, name), rtol=0, atol=1e-9, err_msg=name)
    np.testing.assert_array_equal(parts.n_events, whole.n_events)
    assert tracker._filter.required_neighbours >= 2  # the adaptive rule was active
