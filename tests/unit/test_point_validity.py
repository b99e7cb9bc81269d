"""The checks that decide whether a sweep point was measured as planned, and the plan keys that say
what follows a bad one."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from flagtrack.daemon.errors import ConfigError
from flagtrack.daemon.schema import RecorderStatus
from flagtrack.daemon.sweep.plan import load_sweep_config
from flagtrack.daemon.sweep.validity import (
    TunnelWatch,
    expected_point_bytes,
    free_space_problem,
    recording_problem,
    tunnel_problem,
)


@pytest.mark.parametrize(
    ("speed", "fault", "link_ok", "words"),
    [
        (5.5, None, True, None),
        (5.64, None, True, None),
        (3.19, None, True, "left its tolerance: readback 3.19 m/s"),
        (math.nan, "no reply within 0.5 s", False, "tunnel silent (no reply within 0.5 s)"),
        (5.5, "OVERCURRENT", True, "tunnel fault: OVERCURRENT"),
    ],
)
def test_tunnel_problem(speed: float, fault: str | None, link_ok: bool, words: str | None) -> None:
    problem = tunnel_problem(speed, fault, link_ok, 5.5, 0.15)
    assert problem == words if words is None else words in problem


def test_the_watch_bears_drift_for_its_grace_but_not_a_fault() -> None:
    watch = TunnelWatch(5.5, 0.15, grace_s=1.0)
    assert watch.check(4.0, None, True, 10.0) is None
    assert watch.check(4.0, None, True, 10.9) is None
    assert watch.check(5.5, None, True, 11.0) is None  # back in tolerance: the grace starts again
    assert watch.check(4.0, None, True, 11.5) is None
    assert "left its tolerance" in watch.check(4.0, None, True, 12.6)
    assert "OVERCURRENT" in TunnelWatch(5.5, 0.15, grace_s=1.0).check(5.5, "OVERCURRENT", True, 0.0)


def test_recording_problem_counts_every_kind_of_loss() -> None:
    started = RecorderStatus("recording", dropped_packets=7)
    assert recording_problem(started, RecorderStatus("idle", packets=100, dropped_packets=7)) is None
    text = recording_problem(
        started, RecorderStatus("idle", missing_packets=3, malformed_packets=1, dropped_packets=10)
    )
    assert recording_problem(started, RecorderStatus("idle", missing_packets=2)) == (
        "recording lost packets (2 missing in sequence)"
    )
    assert text == (
        "recording lost packets (3 missing in sequence, 3 of them dropped by the recorder's full queue; 1 malformed)"
    )


def test_drops_the_camera_reported_make_a_recording_lossy_with_their_reason() -> None:
    skipped = "simulated camera: cannot keep up with real time; skipped ahead (events dropped) (0.5 s, 2 times)"
    stopped = RecorderStatus("idle", packets=100, device_drops=2, device_drop_reason=skipped)
    assert recording_problem(RecorderStatus("recording"), stopped) == (
        f"the camera dropped data 2 time(s) while recording: {skipped}"
    )
    both = recording_problem(None, RecorderStatus("idle", missing_packets=1, device_drops=1))
    assert both == (
        "recording lost packets (1 missing in sequence); the camera dropped data 1 time(s) while recording: "
        "no reason given"
    )


def test_free_space_uses_the_larger_of_the_configured_and_the_measured_rate() -> None:
    assert expected_point_bytes(20.0, 5.0, 2.0) == 200e6
    assert expected_point_bytes(20.0, 5.0, 2.0, measured_bytes_per_s=30e6) == 600e6
    assert free_space_problem(300_000_000, 200e6, 50e6, "/data") is None
    problem = free_space_problem(240_000_000, 200e6, 50e6, "/data")
    assert problem == "not enough free space on /data: 240.0 MB free, the point needs 200.0 MB plus a margin of 50 MB"


def test_plan_keys_for_a_bad_point(tmp_path: Path) -> None:
    plan = tmp_path / "plan.yaml"
    plan.write_text("sweep: {speeds: [3, 4]}\n")
    default = load_sweep_config(plan)
    assert (default.on_bad_point, default.retries) == ("retry", 1)
    plan.write_text("sweep: {speeds: [3, 4], on_bad_point: stop}\n")
    assert load_sweep_config(plan).on_bad_point == "stop"
    plan.write_text("sweep: {speeds: [3, 4], on_bad_point: ignore}\n")
    with pytest.raises(ConfigError, match="on_bad_point"):
        load_sweep_config(plan)
    plan.write_text("sweep: {speeds: [3, 4], retries: -1}\n")
    with pytest.raises(ConfigError, match="retries"):
        load_sweep_config(plan)
