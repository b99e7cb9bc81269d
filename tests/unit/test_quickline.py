"""The quick line-event generator puts events on the true line, time-sorted, at the asked rate."""

from __future__ import annotations

import numpy as np

from flagtrack.drivers.sim.quickline import QuickLineParams, WavyFlag, line_events


def test_flag_is_inextensible() -> None:
    flag = WavyFlag(length=150.0, amp_rad=0.8)
    x, y = flag.positions(np.linspace(0, 0.05, 7), np.linspace(0, 150.0, 301))
    lengths = np.hypot(np.diff(x, axis=1), np.diff(y, axis=1)).sum(axis=1)
    np.testing.assert_allclose(lengths, 150.0, rtol=1e-4)
    assert np.allclose(x[:, 0], flag.root[0]) and np.allclose(y[:, 0], flag.root[1])


def test_events_lie_on_the_line_and_are_sorted() -> None:
    flag = WavyFlag()
    events = np.concatenate(list(line_events(flag, 0, 50_000, 640, 480, QuickLineParams(), seed=3)))
    assert len(events) > 10_000
    assert np.all(np.diff(events["t"]) >= 0) and events["t"][0] >= 0 and events["t"][-1] < 50_000
    sample = events[::50]
    s = np.linspace(0, flag.length, 2001)
    distances = []
    for ev in sample:
        x, y = flag.positions(np.array([ev["t"] * 1e-6]), s)
        distances.append(np.min(np.hypot(x[0] - ev["x"], y[0] - ev["y"])))
    assert np.percentile(distances, 95) < 2.5
    assert 0.4 < events["p"].mean() < 0.6


def test_noise_and_drops_change_counts_as_asked() -> None:
    flag = WavyFlag()
    clean = sum(len(e) for e in line_events(flag, 0, 100_000, 640, 480, QuickLineParams(), seed=1))
    dropped = sum(len(e) for e in line_events(flag, 0, 100_000, 640, 480, QuickLineParams(drop_fraction=0.5), seed=1))
    noisy = sum(len(e) for e in line_events(flag, 0, 100_000, 640, 480, QuickLineParams(noise_rate_hz=1e5), seed=1))
    assert abs(dropped / clean - 0.5) < 0.05
    assert abs((noisy - clean) - 10_000) < 500
