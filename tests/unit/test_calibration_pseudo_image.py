"""Blink detection and pseudo-image on synthetic event streams (blink, flicker, leak, shot noise)."""

from __future__ import annotations

import numpy as np
import pytest

from flagtrack.calibration.errors import CalibrationError
from flagtrack.calibration.pseudo_image import BlinkSearch, detect_blink, pseudo_image, to_uint8
from flagtrack.daemon.core.events import EVENT_DTYPE

W, H = 64, 48
N_PER_SWITCH = 6


def _lit_mask() -> np.ndarray:
    yy, xx = np.mgrid[0:H, 0:W]
    board = ((xx // 8 + yy // 8) % 2 == 0) & (xx >= 8) & (xx < 56) & (yy >= 8) & (yy < 40)
    return board


def _events(t: np.ndarray, x: np.ndarray, y: np.ndarray, p: np.ndarray) -> np.ndarray:
    ev = np.zeros(len(t), dtype=EVENT_DTYPE)
    ev["t"], ev["x"], ev["y"], ev["p"] = t, x, y, p
    return ev


def blink_stream(
    period_us: int = 40_000,
    n_periods: float = 3.0,
    first_on_us: int = 7_000,
    ramp_us: int = 400,
    flicker_hz: float = 0.0,
    flicker_depth: int = 0,
    leak_hz: float = 0.0,
    noise_hz: float = 0.0,
    seed: int = 0,
) -> np.ndarray:
    """Events of a board blinking on a dark screen, with optional screen flicker, leak and noise.

    The board (lit mask) switches on at ``first_on_us + k period`` and off half a period later;
    each lit pixel fires N_PER_SWITCH events in the ramp. Flicker: the whole screen (board and
    dark squares) fires ``flicker_depth`` ON then OFF events each flicker period, all the time.
    """
    rng = np.random.default_rng(seed)
    t_end = int(n_periods * period_us)
    lit_y, lit_x = np.nonzero(_lit_mask())
    parts = []
    starts = np.arange(first_on_us - period_us, t_end, period_us)
    for start in starts:
        for t_switch, pol in ((start, 1), (start + period_us // 2, 0)):
            if not 0 <= t_switch < t_end:
                continue
            n = len(lit_x) * N_PER_SWITCH
            t = t_switch + rng.uniform(0, ramp_us, n)
            parts.append(_events(t, np.repeat(lit_x, N_PER_SWITCH), np.repeat(lit_y, N_PER_SWITCH), np.full(n, pol)))
    if flicker_hz:
        sy, sx = np.mgrid[4:44, 4:60]
        sx, sy = sx.ravel(), sy.ravel()
        for t0 in np.arange(0, t_end, 1e6 / flicker_hz):
            for offset, pol in ((0.0, 1), (0.5e6 / flicker_hz, 0)):
                n = len(sx) * flicker_depth
                t = t0 + offset + rng.uniform(0, 50, n)
                parts.append(_events(t, np.repeat(sx, flicker_depth), np.repeat(sy, flicker_depth), np.full(n, pol)))
    for rate, polarity in ((leak_hz, 1), (noise_hz, None)):
        n = rng.poisson(rate * W * H * t_end * 1e-6)
        if n:
            p = np.ones(n) if polarity else rng.integers(0, 2, n)
            parts.append(_events(rng.uniform(0, t_end, n), rng.integers(0, W, n), rng.integers(0, H, n), p))
    events = np.concatenate(parts)
    events = events[(events["t"] >= 0) & (events["t"] < t_end)]
    return events[np.argsort(events["t"], kind="stable")]


def _contrast(image: np.ndarray) -> tuple[float, float]:
    lit = _lit_mask()
    return float(np.median(image[lit])), float(np.abs(image[~lit]).mean())


@pytest.mark.parametrize(
    "period_us, first_on_us, min_period_us", [(40_000, 7_000, 40_000), (100_000, 60_000, 40_000), (25_000, 0, 20_000)]
)
def test_period_and_switch_times_are_found(period_us: int, first_on_us: int, min_period_us: int) -> None:
    events = blink_stream(period_us=period_us, n_periods=3.2, first_on_us=first_on_us)
    timing = detect_blink(events["t"], events["p"], BlinkSearch(min_period_us=min_period_us))
    assert timing.period_us == pytest.approx(period_us, rel=5e-3)
    assert timing.on_us and timing.off_us
    for t in timing.on_us:
        assert abs((t - first_on_us - 200) / period_us - round((t - first_on_us) / period_us)) < 0.02
    for t in timing.off_us:
        k = round((t - first_on_us - period_us / 2) / period_us)
        assert abs(t - (first_on_us + period_us / 2 + k * period_us) - 200) < 0.02 * period_us
    assert timing.half_window_us == pytest.approx(period_us / 4, rel=0.05)
    assert timing.strength > 0.8 and timing.step_snr > 20


def test_pseudo_image_shows_the_lit_pattern() -> None:
    events = blink_stream()
    image = pseudo_image(events, W, H, detect_blink(events["t"], events["p"]))
    lit, dark = _contrast(image)
    assert lit == pytest.approx(N_PER_SWITCH, abs=0.01)
    assert dark < 0.01
    scaled = to_uint8(image)
    assert scaled.dtype == np.uint8 and scaled[_lit_mask()].min() == 255 and scaled[~_lit_mask()].max() == 0


def test_flicker_leak_and_noise_do_not_fool_the_period_or_the_image() -> None:
    """A screen PWM at 300 Hz firing 2x as many events as the blink itself, plus leak and shot noise."""
    clean = blink_stream()
    events = blink_stream(flicker_hz=300.0, flicker_depth=2 * N_PER_SWITCH, leak_hz=2.0, noise_hz=5.0, seed=1)
    assert len(events) > 3 * len(clean)
    timing = detect_blink(events["t"], events["p"])
    assert timing.period_us == pytest.approx(40_000, rel=0.02)
    lit, dark = _contrast(pseudo_image(events, W, H, timing))
    assert lit == pytest.approx(N_PER_SWITCH, abs=1.0)
    assert dark < 0.1 * lit
    naive = np.zeros(W * H)  # plain |ON| + |OFF| counts drown the pattern in flicker
    np.add.at(naive, events["y"].astype(np.int64) * W + events["x"], 1.0)
    naive_lit, naive_dark = _contrast(naive.reshape(H, W))
    assert naive_dark > 0.5 * naive_lit


def test_a_given_period_is_used() -> None:
    events = blink_stream(period_us=50_000)
    timing = detect_blink(events["t"], events["p"], BlinkSearch(period_us=50_000))
    assert timing.period_us == pytest.approx(50_000, rel=2e-3)
    assert _contrast(pseudo_image(events, W, H, timing))[0] == pytest.approx(N_PER_SWITCH, abs=0.01)


@pytest.mark.parametrize("seed, duration_us", [(0, 300_000), (1, 1_000_000), (2, 300_000), (5, 1_000_000)])
def test_no_blinking_is_a_clear_error(seed: int, duration_us: int) -> None:
    """Random events (a random walk of the level) are not taken for a blink."""
    rng = np.random.default_rng(seed)
    n = 200_000
    events = _events(
        np.sort(rng.uniform(0, duration_us, n)), rng.integers(0, W, n), rng.integers(0, H, n), rng.integers(0, 2, n)
    )
    with pytest.raises(CalibrationError, match="no blinking pattern found"):
        detect_blink(events["t"], events["p"])


def test_too_short_and_empty_recordings_are_clear_errors() -> None:
    events = blink_stream(period_us=40_000, n_periods=0.6)
    with pytest.raises(CalibrationError, match="too short|no full blink period|no blinking"):
        detect_blink(events["t"], events["p"], BlinkSearch(min_period_us=30_000))
    with pytest.raises(CalibrationError, match="no blinking pattern recorded"):
        detect_blink(np.zeros(5, np.int64), np.ones(5, np.uint8))


def test_search_parameters_are_checked() -> None:
    with pytest.raises(ValueError):
        BlinkSearch(min_period_us=0)
    with pytest.raises(ValueError):
        BlinkSearch(period_us=-1.0)
