"""The incremental tracker: chunking does not matter, windows are where they should be, Delta_RMS."""

from __future__ import annotations

import numpy as np
import pytest

from flagtrack.daemon.core.buffer import SPARE
from flagtrack.daemon.core.centreline import CentrelineBatch
from flagtrack.daemon.core.chain import ChainParams, ChainState
from flagtrack.daemon.core.denoise import BackgroundActivityFilter, DenoiseParams
from flagtrack.daemon.core.mapping import AffineMapping
from flagtrack.daemon.core.tracker import Tracker, TrackerParams, track
from flagtrack.daemon.core.windows import WindowSchedule, WindowSegment
from flagtrack.drivers.sim.quickline import QuickLineParams, WavyFlag, line_events

FLAG = WavyFlag()


@pytest.fixture(scope="module")
def events() -> np.ndarray:
    params = QuickLineParams(events_per_px2=5, noise_rate_hz=2e5, drop_fraction=0.1)
    return np.concatenate(list(line_events(FLAG, 1_000_000, 1_060_000, 640, 480, params, seed=7)))


def _params(method: str = "robust", **schedule: float) -> TrackerParams:
    robust = method == "robust"
    chain = ChainParams(
        root=FLAG.root, length=FLAG.length, min_events=5 if robust else 1, refine_deg=10.0 if robust else None
    )
    return TrackerParams(
        chain=chain,
        schedule=WindowSchedule.uniform(schedule.pop("tau", 2.5e-4), **schedule),
        denoise=DenoiseParams() if robust else None,
    )


def _feed_in_chunks(events: np.ndarray, params: TrackerParams, cuts: np.ndarray) -> CentrelineBatch:
    tracker = Tracker(params)
    out = [tracker.feed(chunk) for chunk in np.split(events, cuts)]
    return CentrelineBatch.concatenate([*out, tracker.finish()])


def _assert_same(a: CentrelineBatch, b: CentrelineBatch) -> None:
    assert len(a) == len(b)
    for name in ("t_s", "x", "y", "joints_x", "joints_y", "delta_rms"):
        np.testing.assert_allclose(getattr(a, name), getattr(b, name), rtol=0, atol=1e-9, err_msg=name)
    np.testing.assert_array_equal(a.n_events, b.n_events)


@pytest.mark.parametrize("method", ["robust", "paper"])
@pytest.mark.parametrize("dt_over_tau", [1.0, 0.3, 2.5])
def test_results_do_not_depend_on_chunking(events: np.ndarray, method: str, dt_over_tau: float) -> None:
    params = _params(method, tau=2.5e-4, dt_s=2.5e-4 * dt_over_tau)
    whole = track(events, params)
    rng = np.random.default_rng(3)
    random_cuts = np.sort(rng.integers(0, len(events), 200))
    _assert_same(whole, _feed_in_chunks(events, params, random_cuts))
    # cuts between events of the same microsecond, and tiny packets as a live camera sends
    same_t = np.flatnonzero(np.diff(events["t"]) == 0)[::50] + 1
    _assert_same(whole, _feed_in_chunks(events, params, same_t))


def test_tiny_packets_give_the_same_updates(events: np.ndarray) -> None:
    params = _params()
    part = events[:40_000]
    _assert_same(track(part, params), _feed_in_chunks(part, params, np.arange(13, len(part), 13)))


def test_feed_returns_only_complete_windows(events: np.ndarray) -> None:
    tracker = Tracker(_params(tau=2.5e-4))
    seen = events[events["t"] < 1_010_000]
    batch = tracker.feed(seen)
    assert len(batch) > 0
    assert np.all(batch.t_s * 1e6 + 125 <= seen["t"][-1])
    # the next window ends after the last event seen: it comes with later events
    later = tracker.feed(events[(events["t"] >= 1_010_000) & (events["t"] < 1_010_400)])
    assert later.t_s[0] == pytest.approx(batch.t_s[-1] + 2.5e-4)


def test_update_times_are_window_centres(events: np.ndarray) -> None:
    batch = track(events, _params(tau=2.5e-4, dt_s=1e-4))
    t0 = events["t"][0] * 1e-6
    np.testing.assert_allclose(batch.t_s, t0 + 1.25e-4 + 1e-4 * np.arange(len(batch)), atol=1e-12)
    # finish() gave every window that starts at or before the last event, and no other
    t_last_us = int(events["t"][-1])
    assert np.ceil(batch.t_s[-1] * 1e6 - 125) <= t_last_us < np.ceil((batch.t_s[-1] + 1e-4) * 1e6 - 125)


def test_start_stop_and_schedule(events: np.ndarray) -> None:
    segments = (WindowSegment(0.0, 2e-4, 2e-4), WindowSegment(1.02, 5e-4, 1e-3))
    schedule = WindowSchedule(segments, t_start_s=1.005, t_stop_s=1.04)
    params = TrackerParams(chain=_params().chain, schedule=schedule, denoise=DenoiseParams())
    batch = track(events, params)
    assert batch.t_s[0] == pytest.approx(1.005)
    assert batch.t_s[-1] <= 1.04 + 1e-12
    steps = np.round(np.diff(batch.t_s) * 1e6).astype(int)
    assert set(steps[batch.t_s[1:] <= 1.02]) == {200}
    assert set(steps[batch.t_s[:-1] >= 1.02]) == {500}
    first_new = batch.t_s[batch.t_s >= 1.02][0]
    assert 1.02 <= first_new < 1.0202 + 1e-9  # the grid continues into the new segment
    rng = np.random.default_rng(5)
    _assert_same(batch, _feed_in_chunks(events, params, np.sort(rng.integers(0, len(events), 50))))


def test_a_calibration_mapping_is_applied_to_every_event(events: np.ndarray) -> None:
    scale, offset = 0.5, (10.0, -20.0)  # nearly exact in binary: the same decisions as in pixels
    mapping = AffineMapping(((scale, 0.0), (0.0, scale)), offset)
    px = _params("paper")
    chain_m = ChainParams(
        root=(FLAG.root[0] * scale + offset[0], FLAG.root[1] * scale + offset[1]),
        length=FLAG.length * scale,
        refine_deg=None,
    )
    pm = TrackerParams(chain=chain_m, schedule=px.schedule)
    in_px = track(events, px)
    tracker = Tracker(pm, mapping=mapping)
    in_m = CentrelineBatch.concatenate([tracker.feed(events), tracker.finish()])
    np.testing.assert_allclose(in_m.x, in_px.x * scale + offset[0], atol=1e-4)  # single-precision rounding
    np.testing.assert_allclose(in_m.y, in_px.y * scale + offset[1], atol=1e-4)
    np.testing.assert_allclose(in_m.delta_rms, in_px.delta_rms * scale, rtol=1e-4)


def test_delta_rms_is_the_rms_distance_of_the_area_events(events: np.ndarray) -> None:
    params = _params("paper")
    batch = track(events, params)
    for k in (5, 100, len(batch) - 3):
        lo, hi = np.ceil((batch.t_s[k] - 1.25e-4) * 1e6), np.ceil((batch.t_s[k] + 1.25e-4) * 1e6)
        win = events[(events["t"] >= lo) & (events["t"] < hi)]
        x, y = win["x"].astype(float), win["y"].astype(float)
        inside = _in_any_area(x, y, batch, k, params.chain)
        d2 = _polyline_d2(x[inside], y[inside], batch.x[k], batch.y[k])
        assert batch.n_events[k] == inside.sum()
        assert batch.delta_rms[k] == pytest.approx(np.sqrt(d2.mean()), rel=1e-5)


def _in_any_area(x: np.ndarray, y: np.ndarray, batch: CentrelineBatch, k: int, p: ChainParams) -> np.ndarray:
    """Events inside an area of update k: arcs around its joints, along the previous update's links."""
    prev = np.arctan2(np.diff(batch.joints_y[k - 1]), np.diff(batch.joints_x[k - 1]))
    inside = np.zeros(len(x), bool)
    for j, r in enumerate(p.lengths()):
        dx, dy = x - batch.joints_x[k, j], y - batch.joints_y[k, j]
        d = np.hypot(dx, dy)
        off = np.abs(np.angle(np.exp(1j * (np.arctan2(dy, dx) - prev[j]))))
        inside |= (d >= 0.4 * r) & (d <= 1.6 * r) & (off <= np.radians(p.angle_limit_deg))
    return inside


def _polyline_d2(x: np.ndarray, y: np.ndarray, px: np.ndarray, py: np.ndarray) -> np.ndarray:
    ax, ay = px[:-1], py[:-1]
    dx, dy = np.diff(px), np.diff(py)
    t = np.clip(((x[:, None] - ax) * dx + (y[:, None] - ay) * dy) / (dx * dx + dy * dy), 0, 1)
    return np.min((x[:, None] - ax - t * dx) ** 2 + (y[:, None] - ay - t * dy) ** 2, axis=1)


def test_state_and_stats(events: np.ndarray) -> None:
    params = _params()
    tracker = Tracker(params, state=ChainState.straight(10, 5.0))
    np.testing.assert_allclose(tracker.state.angles_rad, np.radians(5.0))
    n_updates = len(tracker.feed(events)) + len(tracker.finish())
    assert tracker.stats.events_in == len(events)
    kept = int(BackgroundActivityFilter(params.denoise).keep_mask(events).sum())
    assert tracker.stats.events_kept == kept and 0.5 * len(events) < kept < len(events)
    # 250 µs windows from the first event, every one that starts at or before the last event
    assert tracker.stats.updates == n_updates == int(events["t"][-1] - events["t"][0]) // 250 + 1
    assert not np.allclose(tracker.state.angles_rad, np.radians(5.0))
    with pytest.raises(RuntimeError):
        tracker.feed(events[:10])


def test_out_of_order_events_are_sorted_in_and_counted(events: np.ndarray) -> None:
    part = events[:20_000].copy()
    swapped = part.copy()
    swapped[[100, 101]] = part[[101, 100]]
    swapped["t"][100], swapped["t"][101] = part["t"][101] + 5, part["t"][100]
    tracker = Tracker(_params())
    tracker.feed(swapped)
    tracker.finish()
    assert tracker.stats.events_out_of_order >= 1


def test_no_events_no_updates() -> None:
    tracker = Tracker(_params())
    assert len(tracker.feed(np.zeros(0, dtype=[("t", "<i8"), ("x", "<u2"), ("y", "<u2"), ("p", "u1")]))) == 0
    assert len(tracker.finish()) == 0


def test_a_long_pause_gives_no_flood_of_empty_updates(events: np.ndarray) -> None:
    pause_us = 3_600_000_000  # an hour without a single event
    later = events.copy()
    later["t"] += pause_us
    both = np.concatenate([events, later])
    params = _params()
    batch = track(both, params)
    n_one = len(track(events, params))
    # the windows within 1 s (max_gap_s) after the last event are kept, the rest of the hour is not
    assert 2 * n_one <= len(batch) <= 2 * n_one + 1.0 / 2.5e-4 + 2
    gap = np.diff(batch.t_s)
    assert gap.max() > 3500 and np.sum(gap > 1e-3) == 1
    rng = np.random.default_rng(9)
    _assert_same(batch, _feed_in_chunks(both, params, np.sort(rng.integers(0, len(both), 30))))
    # without the rule every window of a (shorter) pause is written
    everything = TrackerParams(chain=params.chain, schedule=params.schedule, denoise=params.denoise, max_gap_s=None)
    later["t"] = events["t"] + 5_000_000
    assert len(track(np.concatenate([events, later]), everything)) >= 2 * n_one + 19_000


def test_a_still_start_gives_updates_for_max_gap_then_none() -> None:
    from flagtrack.daemon.core.events import make_events

    params = _params(tau=1e-3)
    lonely = make_events(np.array([0, 400_000]), np.array([10, 600]), np.array([10, 400]), np.array([1, 0]))
    later = make_events(np.array([3_000_000]), np.array([300]), np.array([100]), np.array([1]))
    tracker = Tracker(params)
    batch = CentrelineBatch.concatenate([tracker.feed(lonely), tracker.feed(later), tracker.finish()])
    # filtered noise only: the rest chain is reported during the first second, then nothing
    assert 990 <= len(batch) <= 1002 and batch.t_s[-1] < 1.002
    np.testing.assert_allclose(batch.y, FLAG.root[1])


def test_the_update_clock_gives_the_same_windows_however_often_it_is_asked() -> None:
    """Asked after every few µs (mostly nothing is complete: the early return) or once at the end,
    the clock gives the same windows, across a change of dt and tau and up to the stop time."""
    from flagtrack.daemon.core.windows import UpdateClock

    schedule = WindowSchedule((WindowSegment(0.0, 1.7e-4, 2.5e-4), WindowSegment(1.01, 4.1e-4, 3e-4)), t_stop_s=1.03)
    once = UpdateClock(schedule, 1_000_003).take(1_040_000)
    often = UpdateClock(schedule, 1_000_003)
    rng = np.random.default_rng(3)
    horizons = [*(np.cumsum(rng.integers(0, 40, 2000)) + 1_000_000), 1_040_000]
    parts = [often.take(int(horizon)) for horizon in horizons]
    assert len(once[0]) > 100
    for column, got in zip(once, (np.concatenate([p[i] for p in parts]) for i in range(3))):
        np.testing.assert_array_equal(got, column)
    hi = once[2]
    for before, horizon, part in zip([-1, *horizons], horizons, parts):  # each window as soon as it is complete
        np.testing.assert_array_equal(part[2], hi[(hi > before) & (hi <= horizon)])
    assert sum(len(p[0]) == 0 for p in parts) > 1000  # most calls completed no window


def test_a_source_horizon_completes_the_window_ending_there(events: np.ndarray) -> None:
    """A live packet says every event up to its end has come: the window ending there is taken with
    that packet, not with the next one, and packets fed with their horizons give the same updates."""
    params = _params(tau=2.5e-4)
    t0 = int(events["t"][0])
    end = t0 + 40 * 250  # a window end (windows start at the first event and last 250 µs)
    before = events[events["t"] < end]
    without = Tracker(params).feed(before)
    with_horizon = Tracker(params).feed(before, complete_through_us=end - 1)
    assert len(with_horizon) == len(without) + 1 == 40
    assert params.schedule.window_ends_us(with_horizon.t_s)[-1] == end
    cuts = np.searchsorted(events["t"], np.arange(t0 + 1000, int(events["t"][-1]), 1000))  # 1 ms packets
    tracker = Tracker(params)
    fed = [
        tracker.feed(packet, int(packet["t"][0]) // 1000 * 1000 + 999)
        for packet in np.split(events, cuts)
        if len(packet)
    ]
    _assert_same(track(events, params), CentrelineBatch.concatenate([*fed, tracker.finish()]))


def test_a_start_long_before_the_first_event_skips_the_empty_windows() -> None:
    """A start before the stream (``--t-start 0`` on a recording whose clock is Unix time) steps over
    the windows that end before its first event, at once, on the same grid, and across segments."""
    from flagtrack.daemon.core.windows import UpdateClock

    first_us = 1_605_537_493_718_345  # an aedat4 recording's first event
    schedule = WindowSchedule((WindowSegment(0.0, 2e-4, 2.5e-4),), t_start_s=0.0)
    t_us, lo, hi = UpdateClock(schedule, first_us).take(first_us + 10_000)
    assert 45 <= len(t_us) <= 51  # the windows from the first event on, not 8e12 of them
    assert hi[0] > first_us and hi[0] - 200 <= first_us  # the first that can hold it
    np.testing.assert_allclose(np.diff(t_us), 200.0)
    assert abs(t_us[0] / 200 - round(t_us[0] / 200)) < 1e-3  # on the grid from t = 0
    segments = (WindowSegment(0.0, 2e-4, 2e-4), WindowSegment(1.02, 5e-4, 1e-3))
    late = UpdateClock(WindowSchedule(segments, t_start_s=0.0), 1_030_000).take(1_040_000)[0]
    whole = UpdateClock(WindowSchedule(segments, t_start_s=0.0), 0).take(1_040_000)[0]
    np.testing.assert_array_equal(late, whole[whole + 500 > 1_030_000])  # the second segment's own grid


def test_window_ends_from_update_times_are_the_clocks() -> None:
    from flagtrack.daemon.core.windows import UpdateClock

    schedule = WindowSchedule((WindowSegment(0.0, 1.7e-4, 2.5e-4), WindowSegment(1.01, 4.1e-4, 3e-4)))
    t_us, _, hi = UpdateClock(schedule, 1_000_003).take(1_040_000)
    assert len(hi) > 100
    np.testing.assert_array_equal(schedule.window_ends_us(t_us * 1e-6), hi)


def test_a_horizon_waits_for_the_steps_back_a_jittery_sensor_makes(events: np.ndarray) -> None:
    """Times that step back by up to 5 µs: a packet (cut by the running maximum, as the packetizer
    cuts) can hold events before the previous packet's horizon. The horizon is trusted only up to
    the largest step back seen, so those events are still used: the same updates as offline."""
    jittery = events.copy()
    rng = np.random.default_rng(11)
    jittery["t"] -= rng.integers(0, 6, len(jittery))
    params = _params(tau=2.5e-4)
    slots = np.maximum.accumulate(jittery["t"]) // 1000
    cuts = np.flatnonzero(np.diff(slots)) + 1
    packets = np.split(jittery, cuts)
    horizons = [int(slot) * 1000 + 999 for slot in slots[np.concatenate([[0], cuts])]]
    assert any(int(p["t"].min()) <= h for p, h in zip(packets[1:], horizons))  # late events cross packets
    tracker = Tracker(params)
    fed = [tracker.feed(packet, horizon) for packet, horizon in zip(packets, horizons)]
    _assert_same(track(jittery, params), CentrelineBatch.concatenate([*fed, tracker.finish()]))


def test_a_horizon_past_the_last_event_adds_no_window_that_starts_after_it(events: np.ndarray) -> None:
    """A packet may reach past the last event (a trigger later, or time passing on a still flag):
    windows that start after the last event are not completed by it, so the end of a stream gives
    the offline updates, no more."""
    params = _params(tau=2.5e-4)
    part = events[:50_000]
    tracker = Tracker(params)
    live = CentrelineBatch.concatenate([tracker.feed(part, int(part["t"][-1]) + 3000), tracker.finish()])
    _assert_same(track(part, params), live)


def test_a_tracker_in_the_buffer_of_an_ended_stream_gives_the_same_updates(events: np.ndarray) -> None:
    """A fresh tracker taking the memory of one that tracked another stream (the live service after
    a camera restart) tracks as a new one; the old tracker keeps none of that memory."""
    params = _params()
    old = Tracker(params)
    old.preallocate(20e6)
    other = events[:60_000].copy()  # another stream: later, and mirrored
    other["t"] += 10_000_000
    other["y"] = other["y"].max() - other["y"]
    for chunk in np.array_split(other, 6):
        old.feed(chunk)
    memory = old._buffer.t
    tracker = Tracker(params)
    tracker.take_buffer_of(old)
    assert tracker._buffer.t is memory and not np.shares_memory(old._buffer.t, memory)
    cuts = np.arange(5_000, len(events), 5_000)
    out = CentrelineBatch.concatenate([tracker.feed(chunk) for chunk in np.split(events, cuts)] + [tracker.finish()])
    _assert_same(_feed_in_chunks(events, params, cuts), out)
    with pytest.raises(RuntimeError, match="after the first events"):
        tracker.take_buffer_of(Tracker(params))


def test_a_preallocated_tracker_gives_the_same_updates(events: np.ndarray) -> None:
    params = _params()
    tracker = Tracker(params)
    tracker.preallocate(20e6)  # 20 Mev/s: room for the look-back and the longest window, and the spare
    assert len(tracker._buffer.t) >= 20e6 * (params.stale_after_s or 0) * (1 + SPARE)
    cuts = np.arange(5_000, len(events), 5_000)
    out = CentrelineBatch.concatenate([tracker.feed(chunk) for chunk in np.split(events, cuts)] + [tracker.finish()])
    _assert_same(_feed_in_chunks(events, params, cuts), out)
