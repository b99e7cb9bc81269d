"""The simulated point sensor on the digital twin, through the real tracker: e/L and both clock syncs.

The twin is generated as fast as possible (no bus, no real time), so the numbers do not depend on
the machine's load: twin -> events -> core tracker, and the twin-reading sensor sampling the
true flag at x/L = 0.73 with 0.2 % L noise, 2 ms latency and an injected clock offset
(the harness of ``flagtrack bench sensor``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from flagtrack.daemon.bench.sensor import BEAM as BEAM_VALUES
from flagtrack.daemon.bench.sensor import twin_point
from flagtrack.daemon.core.centreline import CentrelineBatch
from flagtrack.daemon.core.pointsensor import BeamParams, beam_lateral, reading_to_lateral
from flagtrack.daemon.core.sync import SyncParams
from flagtrack.daemon.validation.point import FlagFrame, PointValidation, validate_point
from flagtrack.drivers.camera.simulated import SimulatedCamera
from flagtrack.drivers.sensor.record import SensorRecord
from flagtrack.drivers.sensor.twin import TwinSensor

L = 300.0
FRAME = FlagFrame(L, (150.0, 240.0), 0.0)
BEAM = BeamParams(**BEAM_VALUES)  # readings in mm, sensor on the +y side
TAU_S = 0.001
WARM_S, RECORD_S = 0.3, 1.0


@dataclass
class Run:
    camera: SimulatedCamera
    sensor: TwinSensor
    lines: CentrelineBatch
    record: SensorRecord
    triggers: np.ndarray
    validation: PointValidation


def twin_run(speed_mps: float, offset_ms: float, drift_ppm: float = 0.0, record_s: float = RECORD_S) -> Run:
    point = twin_point(
        speed_mps,
        tau_s=TAU_S,
        offset_ms=offset_ms,
        drift_ppm=drift_ppm,
        noise_over_l=0.002,
        warm_s=WARM_S,
        record_s=record_s,
    )
    validation = validate_point(point.lines, point.record, point.triggers, FRAME, BEAM, SyncParams(), "px")
    return Run(point.camera, point.sensor, point.lines, point.record, point.triggers, validation)


@pytest.fixture(scope="module")
def flapping() -> Run:
    return twin_run(5.5, offset_ms=3.0)


def test_the_sensor_reads_the_true_flag_with_its_noise_and_clock(flapping: Run) -> None:
    run = flapping
    t_cam_us = run.sensor.camera_us(run.record.t_us)
    x, y = run.camera.truth.positions(t_cam_us, np.linspace(0, L, 257))
    truth = beam_lateral(x, y, FRAME.root, 0.0, 0.73 * L, BEAM.side)
    measured = reading_to_lateral(run.record.value, BEAM)
    ok = np.isfinite(truth)
    assert ok.mean() > 0.99 and run.record.missing == 0
    noise = measured[ok] - truth[ok]
    assert abs(noise.mean()) < 0.1 and 0.0018 * L < noise.std() < 0.0022 * L
    assert np.ptp(truth[ok]) > 0.3 * L  # it flaps at the beam
    np.testing.assert_array_equal(np.diff(run.record.t_us), 1000)  # 1 kHz on its own clock
    rising = np.sort(run.triggers["t"][run.triggers["edge"] == 1])
    pulses = run.record.trigger_t_us
    assert len(pulses) >= len(rising) - 1
    nearest = rising[np.argmin(np.abs(pulses[:, None] - 3000 - rising[None, :]), axis=1)]
    assert np.all(np.abs(pulses - nearest - 3000) <= 5)  # the pulses on the sensor clock: +3 ms, ~1 us jitter


def test_flapping_error_is_under_one_percent_and_both_syncs_recover_the_offset(flapping: Run) -> None:
    v, f = flapping.validation, flapping.validation.fields()
    assert v.status == "ok" and v.sync.method == "trigger"
    assert f["sensor_error_rms_over_l"] < 0.01  # the paper: e/L within 0-1.5 %
    assert v.comparison is not None and v.comparison.n_compared > 0.9 * len(flapping.record.t_us)
    update_us = TAU_S * 1e6
    assert abs(f["sensor_offset_us"] - 3000.0) < 5.0 and f["sensor_offset_unc_us"] < 2.0
    assert abs(f["sensor_xcorr_offset_us"] - 3000.0) < update_us
    assert f["sensor_xcorr_unc_us"] < 0.2 * update_us
    assert v.xcorr.quality > 0.99 and v.trigger.n >= 15  # a pulse every 50 ms


def test_a_negative_offset_and_drift_are_recovered_too() -> None:
    run = twin_run(6.0, offset_ms=-4.5, drift_ppm=150.0, record_s=0.8)
    v = run.validation
    assert v.sync.method == "trigger" and v.sync.drift_ppm == pytest.approx(150.0, abs=30.0)
    t_mid = v.sync.t_ref_us
    true_offset_at_mid = -4500.0 + 150e-6 * t_mid  # sensor minus camera at the reference time
    assert abs(v.sync.offset_us - true_offset_at_mid) < 5.0
    assert abs(v.xcorr.offset_us - true_offset_at_mid) < TAU_S * 1e6
    assert v.fields()["sensor_error_rms_over_l"] < 0.01


def test_xcorr_takes_over_without_trigger_pulses(flapping: Run) -> None:
    no_pulses = SensorRecord(**{**flapping.record.__dict__, "trigger_t_us": np.zeros(0, dtype=np.int64)})
    v = validate_point(flapping.lines, no_pulses, flapping.triggers, FRAME, BEAM, SyncParams(), "px")
    assert v.sync.method == "xcorr" and v.trigger.method == "none"
    assert abs(v.sync.offset_us - 3000.0) < TAU_S * 1e6
    assert v.fields()["sensor_error_rms_over_l"] < 0.01


def test_a_still_flag_is_compared_without_a_correlation() -> None:
    run = twin_run(4.0, offset_ms=3.0, record_s=0.5)
    v = run.validation
    assert v.status == "ok" and v.sync.method == "trigger" and v.xcorr.method == "none"
    assert v.fields()["sensor_error_rms_over_l"] < 0.01


def test_updates_without_events_of_a_flapping_flag_are_not_compared(flapping: Run) -> None:
    lines = flapping.lines
    frozen = slice(300, 500)  # 0.2 s of lost camera data: the tracker repeats its last shape
    x, y, n_events = lines.x.copy(), lines.y.copy(), lines.n_events.copy()
    x[frozen], y[frozen], n_events[frozen] = x[frozen.start - 1], y[frozen.start - 1], 0
    lost = CentrelineBatch(lines.t_s, lines.s, x, y, lines.joints_x, lines.joints_y, lines.delta_rms, n_events)
    kept = validate_point(lost, flapping.record, flapping.triggers, FRAME, BEAM, SyncParams(), "px")
    assert kept.fields()["sensor_error_rms_over_l"] > 0.03  # the stale shape is far from the flapping flag
    skipped = validate_point(
        lost, flapping.record, flapping.triggers, FRAME, BEAM, SyncParams(), "px", compare_without_events=False
    )
    f = skipped.fields()
    assert skipped.n_stale == 200 and f["sensor_error_rms_over_l"] < 0.01
    assert f["sensor_compared"] < flapping.validation.fields()["sensor_compared"] - 150


def test_a_host_stamped_sensor_without_pulses_is_found_from_wall_stamps_then_correlation(flapping: Run) -> None:
    # samples stamped with the host's wall clock (µs since the epoch), no trigger wired: the wall-clock
    # stamps of both sides (a few ms apart) centre the correlation search, which finds the offset
    wall0_us = 1_763_000_000_000_000  # the camera clock's zero on the wall clock
    rec = flapping.record
    t_host = rec.t_us + wall0_us  # sensor clock = camera + 3 ms, so host = camera + wall0 + 3 ms
    batches = t_host[::50]
    camera_t = np.arange(300_000, 1_300_000, 4000)
    host = SensorRecord(
        "dist",
        "mm",
        "host",
        t_host,
        rec.value,
        np.zeros(0, dtype=np.int64),
        0,
        wall_t_us=batches,
        wall_ns=(batches + 2_500) * 1000,  # arrive 2.5 ms late
        camera_t_us=camera_t,
        camera_wall_ns=(camera_t + wall0_us + 4_000) * 1000,
    )
    v = validate_point(flapping.lines, host, flapping.triggers, FRAME, BEAM, SyncParams(), "px")
    assert v.coarse.method == "coarse" and abs(v.coarse.offset_us - (wall0_us + 3000)) < 3000
    assert v.sync.method == "xcorr" and abs(v.sync.offset_us - (wall0_us + 3000)) < TAU_S * 1e6
    assert v.fields()["sensor_error_rms_over_l"] < 0.01
