"""``Tracker.skip_to``: a live tracker that sheds camera time leaves gaps, never shapes made of part of a window."""

from __future__ import annotations

import numpy as np
import pytest

from flagtrack.daemon.core.centreline import CentrelineBatch
from flagtrack.daemon.core.chain import ChainParams
from flagtrack.daemon.core.denoise import DenoiseParams
from flagtrack.daemon.core.tracker import Tracker, TrackerParams
from flagtrack.daemon.core.windows import WindowSchedule, WindowSegment
from flagtrack.drivers.sim.quickline import QuickLineParams, WavyFlag, line_events

FLAG = WavyFlag()
T0_US = 1_000_000


@pytest.fixture(scope="module")
def events() -> np.ndarray:
    params = QuickLineParams(events_per_px2=5, noise_rate_hz=2e5, drop_fraction=0.1)
    return np.concatenate(list(line_events(FLAG, T0_US, T0_US + 40_000, 640, 480, params, seed=3)))


def _params(schedule: WindowSchedule | None = None) -> TrackerParams:
    chain = ChainParams(root=FLAG.root, length=FLAG.length, min_events=5, refine_deg=10.0)
    return TrackerParams(chain=chain, schedule=schedule or WindowSchedule.uniform(2.5e-4), denoise=DenoiseParams())


def _shed(events: np.ndarray, params: TrackerParams, lo_us: int, hi_us: int) -> tuple[CentrelineBatch, int]:
    """Track ``events`` in 1 ms packets (with their horizons) but those of ``[lo_us, hi_us)``, skipped."""
    tracker, out, dropped = Tracker(params), [], 0
    for start in range(T0_US, T0_US + 40_000, 1000):
        packet = events[(events["t"] >= start) & (events["t"] < start + 1000)]
        if lo_us <= start < hi_us:
            dropped += tracker.skip_to(start + 1000)
        else:
            out.append(tracker.feed(packet, start + 999))
    return CentrelineBatch.concatenate([*out, tracker.finish()]), dropped


def _windows_us(batch: CentrelineBatch, tau_us: float) -> tuple[np.ndarray, np.ndarray]:
    t_us = batch.t_s * 1e6
    return np.ceil(t_us - tau_us / 2 - 1e-6), np.ceil(t_us + tau_us / 2 - 1e-6)


@pytest.mark.parametrize("tau_s", [2.5e-4, 3.3e-4])
def test_no_window_over_skipped_time_is_emitted_and_the_schedule_goes_on(events: np.ndarray, tau_s: float) -> None:
    params = _params(WindowSchedule.uniform(tau_s))
    full = Tracker(params)
    want = CentrelineBatch.concatenate([full.feed(events), full.finish()])
    lo_us, hi_us = T0_US + 10_000, T0_US + 17_000
    got, dropped = _shed(events, params, lo_us, hi_us)
    lo, hi = _windows_us(got, tau_s * 1e6)
    assert not np.any((lo < hi_us) & (hi > lo_us))  # a gap: no update made of part of the skipped time
    assert dropped > 0  # the windows pending at the skip, cut short, were dropped
    # every update is at a time of the offline schedule (the grid goes on after the gap) ...
    assert np.isin(np.round(got.t_s * 1e9), np.round(want.t_s * 1e9)).all()
    # ... before the gap it is the offline one, and after it every window of the schedule is back
    before = got.t_s < lo_us * 1e-6
    np.testing.assert_allclose(got.x[before], want.x[: before.sum()], rtol=0, atol=1e-9)
    after_offline = want.t_s[want.t_s * 1e6 - tau_s * 1e6 / 2 >= hi_us]
    np.testing.assert_array_equal(got.t_s[~before][-len(after_offline) :], after_offline)
    assert len(got) < len(want)


def test_skipping_before_the_first_event_changes_nothing(events: np.ndarray) -> None:
    params = _params()
    tracker = Tracker(params)
    assert tracker.skip_to(T0_US + 500) == 0
    got = CentrelineBatch.concatenate([tracker.feed(events), tracker.finish()])
    full = Tracker(params)
    want = CentrelineBatch.concatenate([full.feed(events), full.finish()])
    np.testing.assert_allclose(got.x, want.x, rtol=0, atol=1e-9)


def test_a_skip_across_a_schedule_segment_lands_on_the_new_grid(events: np.ndarray) -> None:
    schedule = WindowSchedule((WindowSegment(0.0, 2.5e-4, 2.5e-4), WindowSegment((T0_US + 12_000) * 1e-6, 5e-4, 5e-4)))
    params = _params(schedule)
    full = Tracker(params)
    want = CentrelineBatch.concatenate([full.feed(events), full.finish()])
    got, _ = _shed(events, params, T0_US + 10_000, T0_US + 15_000)
    assert np.isin(np.round(got.t_s * 1e9), np.round(want.t_s * 1e9)).all()
    lo, hi = _windows_us(got, 5e2)
    assert not np.any((got.t_s > (T0_US + 12_000) * 1e-6) & (lo < T0_US + 15_000))


def test_skip_after_finish_is_an_error(events: np.ndarray) -> None:
    tracker = Tracker(_params())
    tracker.feed(events[:100])
    tracker.finish()
    with pytest.raises(RuntimeError, match="finish"):
        tracker.skip_to(T0_US + 5000)
