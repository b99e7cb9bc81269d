"""Stale updates and quiet windows (issue 30): a shape without recent evidence says so, and a still flag
that moves a little is re-seated where it is (the digital twin's flag after it stops flapping)."""

from __future__ import annotations

import dataclasses
import functools

import numpy as np
import pytest

from flagtrack.daemon.core.centreline import CentrelineBatch
from flagtrack.daemon.core.events import EVENT_DTYPE
from flagtrack.daemon.core.evidence import LOOK_BACK_EVENTS
from flagtrack.daemon.core.pointsensor import beam_lateral
from flagtrack.daemon.core.tracker import Tracker
from flagtrack.daemon.tracking.section import Method, TrackingConfig
from flagtrack.drivers.camera.simulated import SimulatedCamera, SimulatedCameraConfig
from flagtrack.drivers.sim.flutter import FlutterParams

ROOT, LENGTH = (150.0, 240.0), 300.0
CONFIG = TrackingConfig(root=ROOT, length=LENGTH, tau_s=0.001)
STILL_S, FLAP_S = 1.5, 1.0  # still (going up), flapping, still again (coming down)


@functools.cache
def _twin() -> tuple[list[tuple[np.ndarray, int]], SimulatedCamera]:
    """The demo's twin: still at 4.0 m/s, flapping at 5.5, then 4.0 again (the flag stops)."""
    clock = {"t": 0.0}

    def speed() -> float:
        return 5.5 if STILL_S <= clock["t"] < STILL_S + FLAP_S else 4.0

    cfg = SimulatedCameraConfig(
        events_per_px2=0.6,
        noise_rate_hz=5000,
        slice_us=4000,
        truth_keep_s=100.0,
        flutter=FlutterParams(onset_speed_mps=4.9, decay_speed_mps=4.4, tau_amp_s=0.3),
    )
    camera = SimulatedCamera(cfg, speed)
    camera.open()
    chunks = []
    while camera._t_us < (2 * STILL_S + FLAP_S + 1.5) * 1e6:
        clock["t"] = camera._t_us * 1e-6
        data = camera._generate(camera._t_us + cfg.slice_us)
        chunks.append((data.events, data.t_until_us))
    return chunks, camera


def _track(config: TrackingConfig, chunks: list[tuple[np.ndarray, int]]) -> CentrelineBatch:
    tracker = Tracker(config.tracker_params(), sensor_size=(640, 480))
    batches = [tracker.feed(events, horizon) for events, horizon in chunks] + [tracker.finish()]
    return CentrelineBatch.concatenate([b for b in batches if len(b)])


def _beam_error(batch: CentrelineBatch, camera: SimulatedCamera, rows: np.ndarray) -> float:
    """e/L RMS at the paper's sensor position x/L = 0.73 against the twin's true flag."""
    tx, ty = camera.truth.positions(batch.t_s[rows] * 1e6, batch.s)
    beam = 0.73 * LENGTH
    e = beam_lateral(batch.x[rows], batch.y[rows], ROOT, 0.0, beam) - beam_lateral(tx, ty, ROOT, 0.0, beam)
    return float(np.sqrt(np.nanmean(e**2)) / LENGTH)


@pytest.mark.slow  # ~15 s: 5.5 s of the twin
def test_a_still_flag_after_flapping_is_tracked_like_one_before() -> None:
    chunks, camera = _twin()
    batch = _track(CONFIG, chunks)
    t = batch.t_s
    up = (t > 0.5) & (t < STILL_S)
    down = t > 2 * STILL_S + FLAP_S  # the flapping has died out
    e_up, e_down = _beam_error(batch, camera, up), _beam_error(batch, camera, down)
    assert abs(e_down - e_up) <= 0.0005, (e_up, e_down)  # within 0.05 % of L
    assert batch.y[down, -1].std() > 0  # the chain moves with the flag: not frozen
    assert not batch.lost[up | down].any() and not batch.stale[up | down].any()


@pytest.mark.slow
def test_without_the_twins_few_events_the_still_flag_is_stale_not_frozen_and_found() -> None:
    """The classic filter (a 500 us window) drops the still flag's events: the shape is then said stale."""
    chunks, _ = _twin()
    classic = dataclasses.replace(CONFIG.denoise, max_window_us=0)
    batch = _track(CONFIG.with_overrides(denoise=classic), chunks)
    down = batch.t_s > 2 * STILL_S + FLAP_S + 0.5
    assert batch.stale[down].mean() > 0.9 and not batch.lost[down].any()


def _noise_only(n: int = 50) -> np.ndarray:
    chunks, _ = _twin()
    rng = np.random.default_rng(5)
    events = np.zeros(n, dtype=chunks[0][0].dtype)
    events["t"] = np.sort(rng.integers(0, 200_000, n))
    events["x"], events["y"] = rng.integers(0, 640, n), rng.integers(0, 480, n)
    return events


@pytest.mark.parametrize("method", [Method.ROBUST, Method.PAPER])
def test_a_chain_that_never_saw_the_flag_is_stale_from_the_start(method: Method) -> None:
    tracker = Tracker(CONFIG.with_overrides(method=method).tracker_params())
    batch = CentrelineBatch.concatenate([tracker.feed(_noise_only()), tracker.finish()])
    assert len(batch) > 100 and batch.stale.all() and not batch.lost.any()
    assert tracker.stats.stale_updates == len(batch)


def test_the_paper_update_is_untouched_by_the_stale_verdict() -> None:
    chunks, _ = _twin()
    events = np.concatenate([e for e, _ in chunks[: int(3.0e6 // 4000)]])
    paper = CONFIG.with_overrides(method=Method.PAPER).tracker_params()
    watched = Tracker(paper).feed(events)
    plain = Tracker(dataclasses.replace(paper, stale_after_s=None)).feed(events)
    for name in ("x", "y", "joints_x", "delta_rms", "n_events", "lost"):
        np.testing.assert_array_equal(getattr(watched, name), getattr(plain, name), err_msg=name)
    assert watched.stale.any() and not plain.stale.any()


def test_gathering_and_stale_do_not_depend_on_the_chunking() -> None:
    chunks, _ = _twin()
    events = np.concatenate([e for e, _ in chunks[: int(4.5e6 // 4000)]])[::3]  # sparse: windows gather
    params = CONFIG.tracker_params()
    whole = Tracker(params)
    ref = CentrelineBatch.concatenate([whole.feed(events), whole.finish()])
    cuts = np.sort(np.random.default_rng(7).integers(0, len(events), 60))
    chunked = Tracker(params)
    parts = [chunked.feed(part) for part in np.split(events, cuts)] + [chunked.finish()]
    got = CentrelineBatch.concatenate([p for p in parts if len(p)])
    assert ref.stale.any() and (ref.n_events >= 100).any()
    np.testing.assert_array_equal(got.stale, ref.stale)
    np.testing.assert_array_equal(got.lost, ref.lost)
    np.testing.assert_array_equal(got.x, ref.x)


def _busy_elsewhere() -> np.ndarray:
    """The flag along its rest line for 60 ms, then silent while a patch 1.8 L from the root (beyond
    its region and the noise ring) fires 2 Mev/s for 90 ms."""
    rng = np.random.default_rng(3)
    n_flag, n_busy = 20_000, 180_000
    flag = np.zeros(n_flag, EVENT_DTYPE)
    flag["t"] = np.sort(rng.integers(0, 60_000, n_flag))
    flag["x"] = rng.integers(int(ROOT[0]), int(ROOT[0] + LENGTH), n_flag)
    flag["y"] = int(ROOT[1]) + rng.integers(-1, 2, n_flag)
    busy = np.zeros(n_busy, EVENT_DTYPE)
    busy["t"] = np.sort(rng.integers(60_000, 150_000, n_busy))
    busy["x"], busy["y"] = rng.integers(620, 636, n_busy), rng.integers(4, 20, n_busy)
    return np.concatenate([flag, busy])


def test_the_look_back_holds_a_bounded_number_of_events_and_says_stale_beyond_it(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    events = _busy_elsewhere()
    params = CONFIG.tracker_params()
    params = dataclasses.replace(params, denoise=None)
    cap_s = LOOK_BACK_EVENTS / 2e6  # the look-back's events at 2 Mev/s: 33 ms

    def track(chunk_us: int) -> tuple[CentrelineBatch, int]:
        tracker, parts, most = Tracker(params, sensor_size=(640, 480)), [], 0
        for t0 in range(0, 150_000, chunk_us):
            parts.append(tracker.feed(events[(events["t"] >= t0) & (events["t"] < t0 + chunk_us)]))
            most = max(most, tracker._buffer.n - tracker._buffer.start)
        parts.append(tracker.finish())
        return CentrelineBatch.concatenate([p for p in parts if len(p)]), most

    capped, most = track(10_000)
    quiet = capped.t_s > 0.062
    late = capped.t_s > 0.060 + cap_s + 0.003
    assert capped.stale[late].all() and not capped.stale[capped.t_s < 0.058].any()
    assert most <= LOOK_BACK_EVENTS + 25_000  # the look-back, a window and a chunk
    chunked, _ = track(3_000)
    np.testing.assert_array_equal(chunked.stale, capped.stale)
    np.testing.assert_array_equal(chunked.x, capped.x)
    # without the bound, 0.1 s of events is kept, and the quiet windows gather the flag's old events
    monkeypatch.setattr("flagtrack.daemon.core.tracker.LOOK_BACK_EVENTS", 1 << 40)
    unbounded, most = track(10_000)
    assert most > 150_000 and not unbounded.stale[quiet & (unbounded.t_s < 0.155)].any()
