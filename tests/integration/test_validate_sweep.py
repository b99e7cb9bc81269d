"""A sweep of the simulated rig with the simulated point sensor (pty tunnel, twin camera with its sync
generator, tracker, recorder, sensor, supervisor, real Zenoh in one process): every point carries the
sensor comparison; a sensor that goes silent only marks its samples missing; ``flagtrack validate``
recomputes the comparison from the run's files, by trigger pulses and by cross-correlation."""

from __future__ import annotations

import csv
import json
import shutil
import threading
import time
from pathlib import Path

import pytest

from flagtrack.daemon.cli import main
from flagtrack.daemon.rig.build import build_services
from flagtrack.daemon.rig.config import RigConfig
from flagtrack.daemon.services.runner import ServiceGroup
from flagtrack.daemon.sweep.runlog import read_run
from flagtrack.daemon.transport import Bus
from flagtrack.daemon.typed_yaml import from_mapping
from flagtrack.daemon.validation.run import validate_run
from tests.fakes.helpers import wait_until
from tests.fakes.rig import SENSOR, SWEEP, simulated_rig

OFFSET_US = 3000.0  # the sensor clock runs 3 ms ahead of the camera's
TAU_S = 0.001


def rig(tmp_path: Path) -> RigConfig:
    """The simulated rig with its point sensor; a light twin at half real time (the rig shares 2 cores
    with other tests) sending sync pulses."""
    sensor = {**SENSOR, "simulated": {**SENSOR["simulated"], "clock_offset_ms": OFFSET_US / 1000}}
    mapping = simulated_rig(
        tmp_path,
        f"val{time.monotonic_ns() % 10**9}",
        {**SWEEP, "record_s": 1.2},
        tau_s=TAU_S,
        twin={"time_scale": 0.5, "trigger_period_ms": 50},
        supervisor={"onset": {"learn_s": 0.5}, "silence_timeout_s": 3.0},
        sensor=sensor,
    )
    return from_mapping(RigConfig, mapping)


@pytest.fixture(scope="module")
def sweep(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, object]:
    tmp_path = tmp_path_factory.mktemp("validate")
    config = rig(tmp_path)
    with Bus(config.bus_config) as bus:
        services = build_services(config, bus, list(config.services))
        supervisor = services[0]
        sensor = next(s for s in services if s.name == "sensor/om70")
        group = ServiceGroup(services, stop_when_any_finishes=["supervisor"])

        def mute_during_the_last_point() -> None:
            wait_until(lambda: len(supervisor.points_done) >= 2, 90, "two points done", poll_s=0.02)
            sensor.driver.muted = True  # the sensor stops answering

        threading.Thread(target=mute_during_the_last_point, daemon=True).start()
        group.start()
        group.wait(120)
        report = group.shutdown(30)
    return tmp_path / "runs" / "run", (supervisor, report)


@pytest.mark.slow
def test_every_point_carries_the_sensor_comparison(sweep: tuple[Path, object]) -> None:
    run_dir, (supervisor, report) = sweep
    assert supervisor.stop_reason == "finished" and not report.errors  # the silent sensor stopped nothing
    record = read_run(run_dir)
    still, flapping, muted = record.latest_points().values()
    assert (still.state, flapping.state) == ("still", "flapping")
    for point in (still, flapping):
        assert point.sensor_status == "ok" and point.sensor_sync == "trigger"
        assert abs(point.sensor_offset_us - OFFSET_US) < 5.0 and point.sensor_offset_unc_us < 5.0
        assert point.sensor_samples > 300 and point.sensor_missing == 0
        assert (run_dir / point.sensor_file).stat().st_size > 0
        assert (run_dir / point.sensor_figure).read_bytes()[:4] == b"\x89PNG"
    assert flapping.sensor_error_rms_over_l < 0.01 and flapping.sensor_error_max_over_l < 0.05
    assert abs(flapping.sensor_xcorr_offset_us - OFFSET_US) < TAU_S * 1e6
    assert muted.sensor_status == "sensor samples all missing" and muted.sensor_missing > 300
    with open(run_dir / "summary.csv", newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert float(rows[1]["sensor_error_rms_over_l"]) == pytest.approx(flapping.sensor_error_rms_over_l)
    assert rows[2]["sensor_error_max_over_l"] == "NaN"
    assert (run_dir / "validation.png").stat().st_size > 5000


@pytest.mark.slow
def test_validate_recomputes_from_the_files_by_both_paths(
    sweep: tuple[Path, object], capsys: pytest.CaptureFixture[str]
) -> None:
    run_dir, _ = sweep
    live = list(read_run(run_dir).latest_points().values())
    log_before = (run_dir / "run.jsonl").read_bytes()
    again = validate_run(run_dir)
    flapping = again.points[1]
    assert flapping.sensor_sync == "trigger" and abs(flapping.sensor_offset_us - OFFSET_US) < 5.0
    assert flapping.sensor_error_rms_over_l == pytest.approx(live[1].sensor_error_rms_over_l, rel=0.25)
    assert set(again.point_figures) == {p.point_id for p in live}
    out = run_dir.parent / "xcorr"
    code = main(["validate", str(run_dir), "--sync", "xcorr", "-o", str(out), "--json"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    rows = {r["point_id"]: r for r in json.loads(captured.out)["points"]}
    flapping = rows["001-up-5.50"]
    assert flapping["sensor_sync"] == "xcorr" and abs(flapping["sensor_offset_us"] - OFFSET_US) < TAU_S * 1e6
    assert flapping["sensor_error_rms_over_l"] < 0.01
    assert rows["000-up-4.00"]["sensor_sync"] == "coarse"  # a still flag has nothing to correlate
    assert (out / "validation.csv").exists() and (out / "001-up-5.50.png").exists()
    assert (run_dir / "run.jsonl").read_bytes() == log_before  # the run log is never rewritten


def test_a_bad_reconstruct_option_is_named_by_its_option(
    sweep: tuple[Path, object], capsys: pytest.CaptureFixture[str]
) -> None:
    """--tau nan was blamed on "file RUN/run.jsonl, key 'tracker.tau_s'"."""
    run_dir, _ = sweep
    assert main(["validate", str(run_dir), "--reconstruct", "--tau", "nan", "-o", str(run_dir.parent / "t")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("flagtrack validate: error: --tau: ") and "run.jsonl" not in err[0], err


@pytest.mark.slow
def test_a_damaged_point_is_said_and_the_others_are_validated(
    sweep: tuple[Path, object], tmp_path: Path, capsys: pytest.CaptureFixture[str], caplog: pytest.LogCaptureFixture
) -> None:
    run_dir, _ = sweep
    copy = tmp_path / "run"
    shutil.copytree(run_dir, copy)
    still, flapping, _ = read_run(copy).latest_points().values()
    lines = copy / flapping.centreline_file
    lines.write_bytes(lines.read_bytes()[:300])  # cut short
    (copy / still.sensor_file).write_bytes(b"\x00garbage" * 10)
    code = main(["validate", str(copy), "--json"])
    captured = capsys.readouterr()
    assert code == 1, captured.err
    rows = {r["point_id"]: r for r in json.loads(captured.out)["points"]}
    assert rows[flapping.point_id]["sensor_status"].startswith(f"damaged: {lines}")
    assert rows[still.point_id]["sensor_status"].startswith(f"damaged: {copy / still.sensor_file}")
    assert rows[flapping.point_id]["sensor_error_rms_over_l"] is None  # not the live run's number
    assert rows[flapping.point_id]["cloud_distance_mean_over_l"] is None
    said = [r.getMessage() for r in caplog.records if "not validated" in r.getMessage()]
    assert [p in m for p, m in zip((still.point_id, flapping.point_id), said, strict=True)] == [True, True]
    assert f"{flapping.point_id} (the lines above" in captured.err.splitlines()[-1], captured.err
    assert "Traceback" not in captured.err
    assert len(rows) == 3 and (copy / "validation" / "validation.csv").exists()


@pytest.mark.slow
def test_a_point_whose_recording_is_gone_is_validated_coarsely_and_says_why(
    sweep: tuple[Path, object], tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """Its row said `ok, unsynchronised (coarse)` and nothing named the missing file."""
    run_dir, _ = sweep
    copy = tmp_path / "run"
    shutil.copytree(run_dir, copy)
    flapping = list(read_run(copy).latest_points().values())[1]
    (copy / flapping.raw_file).unlink()
    again = validate_run(copy)
    assert again.points[1].sensor_sync != "trigger"
    said = [r.getMessage() for r in caplog.records if f"{copy / flapping.raw_file} is missing" in r.getMessage()]
    assert len(said) == 1 and "without the camera's trigger events" in said[0], said
