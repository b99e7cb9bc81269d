"""The simulated camera flaps above onset, stays still below, with hysteresis, and its events are on the flag."""

from __future__ import annotations

import numpy as np
import pytest

from flagtrack.drivers.camera.simulated import SKIP_REASON, SimulatedCamera, SimulatedCameraConfig, fast_forward
from flagtrack.drivers.sim.flutter import FlutterParams

FLUTTER = FlutterParams(onset_speed_mps=5.0, decay_speed_mps=4.5, tau_amp_s=0.05)


def rate_mev_s(camera: SimulatedCamera, duration_s: float) -> float:
    return sum(len(e) for e in fast_forward(camera, duration_s)) / duration_s / 1e6


def test_rate_jumps_at_onset_and_drops_below_decay_with_hysteresis() -> None:
    speed = {"mps": 4.0}
    camera = SimulatedCamera(SimulatedCameraConfig(flutter=FLUTTER), speed_source=lambda: speed["mps"])
    still = rate_mev_s(camera, 0.3)
    speed["mps"] = 6.0
    rate_mev_s(camera, 0.3)  # amplitude settles
    flapping = rate_mev_s(camera, 0.3)
    speed["mps"] = 4.8  # between decay and onset: stays flapping on the way down
    between_down = rate_mev_s(camera, 0.5)
    speed["mps"] = 4.0
    rate_mev_s(camera, 0.3)
    stopped = rate_mev_s(camera, 0.3)
    speed["mps"] = 4.8  # between decay and onset on the way up: stays still
    between_up = rate_mev_s(camera, 0.5)
    assert flapping > 10 * still and between_down > 10 * still
    assert stopped < 2 * still and between_up < 2 * still
    assert camera.state.flapping is False


def test_events_lie_on_the_twin_flag() -> None:
    camera = SimulatedCamera(SimulatedCameraConfig(flutter=FLUTTER, speed_mps=7.0, noise_rate_hz=0.0, slice_us=200))
    fast_forward(camera, 0.4)
    state_before = camera.state
    events = np.concatenate(fast_forward(camera, 0.0002))
    state_after = camera.state
    assert len(events) > 50
    s = np.linspace(0, camera.kinematics.length, 801)
    phase = 0.5 * (state_before.phase_rad + state_after.phase_rad)
    amp = 0.5 * (state_before.amp_over_l + state_after.amp_over_l) / 0.3
    x, y = camera.kinematics.positions_at_phase(np.array([phase]), s, amp_scale=amp)
    sample = events[:: max(1, len(events) // 300)]
    distance = np.min(np.hypot(x[0][None, :] - sample["x"][:, None], y[0][None, :] - sample["y"][:, None]), axis=1)
    # the tip moves up to ~2 px in the 0.2 ms window; the line spreads events by ~1 px
    assert np.median(distance) < 1.5 and np.percentile(distance, 90) < 3.0


def test_a_camera_that_falls_behind_skips_ahead_and_stays_in_step_with_the_wall_clock() -> None:
    import time

    camera = SimulatedCamera(SimulatedCameraConfig(flutter=FLUTTER, speed_mps=7.0, max_lag_s=0.1))
    camera.open()
    started_s = time.monotonic()
    first = camera.read(0.05)  # the camera's clock starts
    assert first is not None and camera.skipped_us == 0
    time.sleep(0.5)  # an overloaded machine: no reads for half a second
    data = camera.read(0.05)
    wall_s = time.monotonic() - started_s
    assert data is not None and camera.skipped_us >= 300_000
    assert 0.35 < data.t_until_us * 1e-6 <= wall_s + 0.05  # camera time caught up with the wall clock
    assert camera.state.t_s == pytest.approx(data.t_until_us * 1e-6)  # the flag moved on with it
    # the skip is reported with the data after it: the camera time skipped, where it lies
    (drop,) = data.drops
    assert (drop.reason, drop.count, drop.unit) == (SKIP_REASON, camera.skipped_us, "us")
    assert drop.t_to_us - drop.t_from_us == camera.skipped_us and drop.t_to_us <= data.events["t"].min()
    later = camera.read(0.05)  # a skip is reported once (a later one, on a loaded machine, lies after it)
    assert later is None or all(d.t_from_us >= drop.t_to_us for d in later.drops)


def test_bench_twin_reports_the_demo_twins_rate_and_its_scaling() -> None:
    from flagtrack.daemon.bench.twin import measure

    demo = measure(events_per_px2=2.0, speed_mps=6.0, seconds=0.5)
    dense = measure(events_per_px2=6.0, speed_mps=6.0, seconds=0.5)
    assert demo["flapping"] and dense["flapping"]
    assert 0.8 < demo["camera_mev_s"] < 2.0  # the demo's twin: about 1 Mev/s of camera data
    assert dense["events"] / demo["events"] == pytest.approx(3.0, rel=0.1)  # events scale with the density
    assert demo["real_time_margin"] > 0 and demo["generated_mev_s"] > 0


def test_opening_renders_once_before_the_clock_starts_and_changes_nothing(monkeypatch: pytest.MonkeyPatch) -> None:
    import flagtrack.drivers.camera.simulated as simulated

    cfg = SimulatedCameraConfig(flutter=FLUTTER, speed_mps=7.0, seed=3)
    with monkeypatch.context() as patch:
        patch.setattr(SimulatedCamera, "_warm_up", lambda self: None)
        unwarmed = np.concatenate(fast_forward(SimulatedCamera(cfg), 0.05))
    clock_at_render: list[float | None] = []
    render = simulated.line_events

    def spy(*args: object, **kwargs: object) -> object:
        clock_at_render.append(camera._wall0)
        return render(*args, **kwargs)

    monkeypatch.setattr(simulated, "line_events", spy)
    camera = SimulatedCamera(cfg)
    camera.open()
    assert clock_at_render == [None]  # one slice rendered (the kernels loaded) before the clock started
    events = np.concatenate(fast_forward(camera, 0.05))
    np.testing.assert_array_equal(events, unwarmed)  # the stream is the one without the warm-up


def test_the_clock_starts_at_the_first_read_so_a_services_set_up_is_no_lag() -> None:
    import time

    camera = SimulatedCamera(SimulatedCameraConfig(flutter=FLUTTER, speed_mps=7.0, max_lag_s=0.1))
    camera.open()
    time.sleep(0.3)  # the camera service loading its own kernels between the open and the first read
    data = camera.read(0.05)
    assert data is not None and camera.skipped_us == 0 and not data.drops
    assert data.t_until_us == camera.cfg.slice_us  # the stream starts at its beginning
