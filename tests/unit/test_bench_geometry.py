"""The grid of `flagtrack bench geometry`: what it covers, that it is the same every run, its summary."""

from __future__ import annotations

import math

from flagtrack.daemon.bench.geometry import plan, summary


def test_the_grid_covers_sensors_directions_amplitudes_noise_and_defects() -> None:
    cases = plan(36, 0, 0.3)
    assert cases == plan(36, 0, 0.3) and cases != plan(36, 1, 0.3)
    assert {(c.width, c.height) for c in cases} == {(640, 480), (1280, 720)}
    assert {c.shot_noise_hz for c in cases} == {0.0, 1.0, 5.0}
    assert {c.peak_to_peak for c in cases} == {(0.085, 0.2), (0.2, 1.05)}
    assert any(c.tilted for c in cases) and any(c.tapped for c in cases) and any(c.hot_pixels for c in cases)
    plain = [c for c in cases if not c.tilted]
    quadrants = {int(c.direction_deg // 90) for c in plain}
    assert quadrants == {0, 1, 2, 3}  # right-down, left-down, left-up, right-up
    for c in plain:  # the flag and its motion (0.55 L either side) inside the sensor
        d = math.radians(c.direction_deg)
        for a in (0.0, 1.0):
            for b in (-0.55, 0.55):
                x = c.root[0] + c.length * (a * math.cos(d) - b * math.sin(d))
                y = c.root[1] + c.length * (a * math.sin(d) + b * math.cos(d))
                assert 0 <= x < c.width and 0 <= y < c.height


def test_summary_takes_magnitudes_and_counts_the_misses() -> None:
    rows = [
        {"root_error_over_l": -0.01, "direction_error_deg": -0.5, "length_error_pct": 1.0},
        {"root_error_over_l": 0.03, "direction_error_deg": 0.1, "length_error_pct": -4.0},
        {"error": "no flag"},
    ]
    figures = summary(rows)
    assert figures["recordings"] == 3 and figures["found"] == 2
    assert figures["root_error_over_l"]["max"] == 0.03
    assert figures["direction_error_deg"]["max"] == 0.5
    assert figures["length_error_pct"]["median"] == 2.5
