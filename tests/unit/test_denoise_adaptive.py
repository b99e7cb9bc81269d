"""Coincidence and adaptive support of the background-activity filter (the robust method's default)."""

from __future__ import annotations

import numpy as np
import pytest

from flagtrack.daemon.core.denoise import BackgroundActivityFilter, DenoiseParams
from flagtrack.daemon.core.events import make_events
from flagtrack.drivers.sim.quickline import QuickLineParams, WavyFlag, line_events

ADAPTIVE = DenoiseParams(window_us=500, min_neighbours=1, max_neighbours=3)


def _ev(rows: list[tuple[int, int, int]]) -> np.ndarray:
    t, x, y = np.array(rows).T
    return make_events(t, x, y, np.ones(len(t)))


def _mixed(noise_over_line: float, duration_us: int = 50_000, seed: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """A flapping line plus uniform noise ``noise_over_line`` times as many events; (events, is_line)."""
    flag = WavyFlag()
    clean = np.concatenate(
        list(line_events(flag, 0, duration_us, 640, 480, QuickLineParams(events_per_px2=20), seed=seed))
    )
    if noise_over_line == 0:
        return clean, np.ones(len(clean), bool)
    rate = noise_over_line * len(clean) / (duration_us * 1e-6)
    noise = np.concatenate(
        list(
            line_events(
                flag, 0, duration_us, 640, 480, QuickLineParams(events_per_px2=0.0, noise_rate_hz=rate), seed=seed + 1
            )
        )
    )
    both = np.concatenate([clean, noise])
    is_line = np.r_[np.ones(len(clean), bool), np.zeros(len(noise), bool)]
    order = np.argsort(both["t"], kind="stable")
    return both[order], is_line[order]


def test_fixed_support_needs_that_many_neighbours() -> None:
    f = BackgroundActivityFilter(DenoiseParams(window_us=100, min_neighbours=2, max_neighbours=2), 10, 10)
    mask = f.keep_mask(_ev([(0, 5, 5), (10, 6, 5), (20, 5, 6), (30, 4, 4), (300, 6, 6)]))
    # (5, 6) sees one neighbour (5, 5 and 6, 5 are both neighbours: two); (4, 4) sees (5, 5) only;
    # (6, 6) comes after the window
    assert mask.tolist() == [False, False, True, False, False]


def test_sparse_clean_stream_keeps_the_classic_rule() -> None:
    events, _ = _mixed(0.0)
    classic = BackgroundActivityFilter(DenoiseParams(window_us=500), 640, 480).keep_mask(events)
    adaptive = BackgroundActivityFilter(ADAPTIVE, 640, 480)
    np.testing.assert_array_equal(adaptive.keep_mask(events), classic)
    assert adaptive.required_neighbours == 1


def test_dense_noise_raises_the_support_and_rejects_far_more_noise() -> None:
    events, is_line = _mixed(6.0)
    classic = BackgroundActivityFilter(DenoiseParams(window_us=500), 640, 480).keep_mask(events)
    f = BackgroundActivityFilter(ADAPTIVE, 640, 480)
    adaptive = f.keep_mask(events)
    assert f.required_neighbours >= 2
    assert adaptive[~is_line].mean() < 0.3 * classic[~is_line].mean()
    assert adaptive[is_line].mean() > 0.9


def test_adaptive_result_does_not_depend_on_chunking_or_on_the_sensor_size_given() -> None:
    events, _ = _mixed(4.0, duration_us=30_000)
    whole = BackgroundActivityFilter(ADAPTIVE, 640, 480).keep_mask(events)
    f = BackgroundActivityFilter(ADAPTIVE)
    cuts = np.sort(np.random.default_rng(0).integers(0, len(events), 50))
    parts = np.concatenate([f.keep_mask(chunk) for chunk in np.split(events, cuts)])
    g = BackgroundActivityFilter(ADAPTIVE)
    single = np.concatenate([g.keep_mask(events[i : i + 1]) for i in range(0, 20_000)])
    np.testing.assert_array_equal(parts, BackgroundActivityFilter(ADAPTIVE).keep_mask(events))
    np.testing.assert_array_equal(single, parts[:20_000])
    np.testing.assert_array_equal(whole, parts)  # the noise rate is per pixel of the area seen so far


@pytest.mark.parametrize(
    "kwargs",
    [
        dict(min_neighbours=0),
        dict(min_neighbours=3, max_neighbours=2),
        dict(max_neighbours=9),
        dict(noise_pass=0.0),
        dict(block_us=0),
    ],
)
def test_bad_settings_are_refused(kwargs: dict) -> None:
    with pytest.raises(ValueError):
        DenoiseParams(**kwargs)
