"""Background-activity filter: neighbours' recent activity lets an event through, its own does not."""

from __future__ import annotations

import numpy as np
import pytest

from flagtrack.daemon.core.denoise import BackgroundActivityFilter, DenoiseParams
from flagtrack.daemon.core.events import make_events
from flagtrack.drivers.sim.quickline import QuickLineParams, WavyFlag, line_events


def _ev(rows: list[tuple[int, int, int]]) -> np.ndarray:
    t, x, y = np.array(rows).T
    return make_events(t, x, y, np.ones(len(t)))


def test_neighbour_within_window_passes() -> None:
    f = BackgroundActivityFilter(DenoiseParams(window_us=100), 10, 10)
    mask = f.keep_mask(_ev([(0, 5, 5), (50, 6, 5), (200, 7, 5), (210, 0, 0), (215, 9, 9)]))
    # first: no history; second: neighbour 50 us before; third: 150 us after its neighbour;
    # corners: nothing around
    assert mask.tolist() == [False, True, False, False, False]


def test_own_pixel_does_not_count_so_hot_pixels_are_removed() -> None:
    f = BackgroundActivityFilter(DenoiseParams(window_us=1000), 20, 20)
    hot = _ev([(t, 3, 4) for t in range(0, 100_000, 250)])  # 4 kHz
    assert not f.keep_mask(hot).any()


def test_all_eight_neighbours_count_and_sensor_edges_are_safe() -> None:
    for dx in (-1, 0, 1):
        for dy in (-1, 0, 1):
            if dx == dy == 0:
                continue
            f = BackgroundActivityFilter(DenoiseParams(window_us=10), 3, 3)
            assert f.keep_mask(_ev([(0, 1 + dx, 1 + dy), (5, 1, 1)])).tolist() == [False, True]
    f = BackgroundActivityFilter(DenoiseParams(window_us=10), 4, 3)
    assert f.keep_mask(_ev([(0, 0, 0), (1, 3, 2), (2, 0, 1)])).tolist() == [False, False, True]


def test_unknown_sensor_size_grows_and_keeps_history() -> None:
    f = BackgroundActivityFilter(DenoiseParams(window_us=100))
    assert f.keep_mask(_ev([(0, 5, 5)])).tolist() == [False]
    assert f.keep_mask(_ev([(10, 300, 200), (20, 6, 6), (30, 301, 201)])).tolist() == [False, True, True]


def test_no_params_keeps_everything() -> None:
    events = _ev([(0, 1, 1), (1, 50, 50)])
    assert BackgroundActivityFilter(None).keep_mask(events).all()


def test_chunking_does_not_change_the_result() -> None:
    flag = WavyFlag()
    events = np.concatenate(list(line_events(flag, 0, 30_000, 640, 480, QuickLineParams(noise_rate_hz=2e5), seed=4)))
    whole = BackgroundActivityFilter(DenoiseParams(300), 640, 480).keep_mask(events)
    f = BackgroundActivityFilter(DenoiseParams(300))
    cuts = np.sort(np.random.default_rng(0).integers(0, len(events), 20))
    parts = [f.keep_mask(chunk) for chunk in np.split(events, cuts)]
    np.testing.assert_array_equal(np.concatenate(parts), whole)


def test_line_events_pass_and_background_does_not() -> None:
    flag = WavyFlag()
    clean = np.concatenate(list(line_events(flag, 0, 50_000, 640, 480, QuickLineParams(events_per_px2=20), seed=1)))
    noise_params = QuickLineParams(events_per_px2=0.0, noise_rate_hz=len(clean) / 0.05)
    noise = np.concatenate(list(line_events(flag, 0, 50_000, 640, 480, noise_params, seed=2)))
    both = np.concatenate([clean, noise])
    is_line = np.r_[np.ones(len(clean), bool), np.zeros(len(noise), bool)]
    order = np.argsort(both["t"], kind="stable")
    both, is_line = both[order], is_line[order]
    kept = BackgroundActivityFilter(DenoiseParams(), 640, 480).keep_mask(both)
    assert kept[is_line].mean() > 0.98
    assert kept[~is_line].mean() < 0.25  # most of these few are next to the line


@pytest.mark.parametrize("window_us", [0, -5])
def test_window_must_be_positive(window_us: int) -> None:
    with pytest.raises(ValueError, match="window_us"):
        DenoiseParams(window_us)


def test_hours_long_recordings_and_gaps_keep_working() -> None:
    hour = 3_600_000_000
    rows = [(0, 5, 5), (50, 6, 5), (hour, 5, 5), (hour + 40, 6, 5), (3 * hour, 7, 7), (3 * hour + 10, 8, 7)]
    expected = [False, True, False, True, False, True]
    assert BackgroundActivityFilter(DenoiseParams(100), 10, 10).keep_mask(_ev(rows)).tolist() == expected
    f = BackgroundActivityFilter(DenoiseParams(100), 10, 10)
    n = 3
    out_t, out_x, out_y = np.empty(6, np.int64), np.empty(6, np.float32), np.empty(6, np.float32)
    end, ordered, latest = f.filter_into(_ev(rows[:n]), out_t, out_x, out_y, 0)
    end, ordered, latest = f.filter_into(_ev(rows[n:]), out_t, out_x, out_y, end, latest)
    assert end == 3 and ordered and latest == 3 * hour + 10
    assert out_t[:end].tolist() == [50, hour + 40, 3 * hour + 10]
