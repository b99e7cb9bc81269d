"""Run log (append-only JSON lines), resume bookkeeping, summary CSV and figure, on real files."""

from __future__ import annotations

import csv
import json
import math
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from flagtrack.daemon.errors import FormatError
from flagtrack.daemon.sweep.plan import Branch, EndPoint, Record, SpeedRange, SweepConfig, plan_points, sweep_plan
from flagtrack.daemon.sweep.runlog import (
    RUN_LOG,
    PointResult,
    RunLog,
    completed_points,
    point_paths,
    read_run,
    stored_sweep,
)
from flagtrack.daemon.sweep.summary import SUMMARY_COLUMNS, transition_speeds, write_summary
from tests.fakes.helpers import wait_until

CFG = SweepConfig(range=SpeedRange(3.0, 6.0, 0.5), settle_s=1, record_s=1)
ONSET_MPS, DECAY_MPS = 5.0, 4.0


def measured(point, **changes) -> PointResult:
    """A plausible result: flapping above the onset going up, above the decay going down."""
    flapping = point.speed_mps >= (ONSET_MPS if point.branch.value == "up" else DECAY_MPS + 0.5)
    raw, h5 = point_paths(point.point_id)
    values = dict(
        state="flapping" if flapping else "still", amplitude_over_l=0.25 if flapping else 0.002,
        amplitude_std_over_l=0.02 if flapping else math.nan, frequency_hz=20.0 if flapping else math.nan,
        event_rate_mev_s=2.0 if flapping else 0.03, raw_bytes=10_000, raw_file=raw, centreline_file=h5,
    )  # fmt: skip
    return PointResult.planned(point, **{**values, **changes})


def run_points(run_dir: Path, upto: int) -> list:
    points = plan_points(CFG)
    with RunLog.create(run_dir, run_id="test-run", config={"sweep": {"speeds": [3.0]}}, plan=points, t_unix=1.0) as log:
        for point in points[:upto]:
            log.point(measured(point))
    return points


def test_records_are_json_lines_with_version_and_nulls_for_nan(tmp_path: Path) -> None:
    points = run_points(tmp_path, upto=2)
    lines = (tmp_path / RUN_LOG).read_text().splitlines()
    records = [json.loads(line) for line in lines]  # strict JSON: no NaN tokens
    assert [r["type"] for r in records] == ["start", "point", "point"]
    assert all(r["v"] == 1 for r in records)
    assert records[0]["run_id"] == "test-run" and len(records[0]["plan"]) == len(points)
    assert records[1]["point_id"] == points[0].point_id and records[1]["frequency_hz"] is None
    assert records[1]["raw_file"] == f"points/{points[0].point_id}.raw"
    assert (tmp_path / "points").is_dir()


def test_reader_round_trips_points_and_stop(tmp_path: Path) -> None:
    points = run_points(tmp_path, upto=3)
    log, _ = RunLog.resume(tmp_path, t_unix=2.0)
    with log:
        log.stop("SIGTERM")
    record = read_run(tmp_path)
    assert [p.point_id for p in record.points] == [p.point_id for p in points[:3]]
    assert record.points[0] == measured(points[0])  # NaN comes back as NaN (compared field by field)
    assert record.stop is not None and record.stop["reason"] == "SIGTERM"
    assert len(record.resumes) == 1 and not record.torn_tail


def test_create_refuses_an_existing_run(tmp_path: Path) -> None:
    run_points(tmp_path, upto=1)
    with pytest.raises(FormatError, match="resume the run instead"):
        RunLog.create(tmp_path, run_id="again", config={}, plan=[])


def test_torn_last_line_is_ignored_then_cut_on_resume(tmp_path: Path) -> None:
    points = run_points(tmp_path, upto=4)
    path = tmp_path / RUN_LOG
    intact = path.stat().st_size
    with open(path, "ab") as handle:  # power lost in the middle of the fifth point record
        handle.write(b'{"type": "point", "v": 1, "point_id": "004-up-5.00", "ind')
    assert completed_points(tmp_path) == {p.point_id for p in points[:4]}
    assert read_run(tmp_path).torn_tail and read_run(tmp_path).valid_bytes == intact
    log, before = RunLog.resume(tmp_path)
    with log:
        log.point(measured(points[4]))
    after = read_run(tmp_path)
    assert before.torn_tail and not after.torn_tail
    assert [p.point_id for p in after.points] == [p.point_id for p in points[:5]]
    assert after.resumes[0]["cut_torn_tail"] is True


def test_nul_filled_tail_counts_as_torn(tmp_path: Path) -> None:
    run_points(tmp_path, upto=2)
    with open(tmp_path / RUN_LOG, "ab") as handle:
        handle.write(b"\x00" * 64)
    record = read_run(tmp_path)
    assert record.torn_tail and len(record.points) == 2


@pytest.mark.parametrize(
    ("damage", "words"),
    [
        (lambda text: text.replace('"type": "point"', '"type": "pint"', 1), "unexpected record type 'pint'"),
        (lambda text: text.replace('"v": 1', '"v": 9', 2), "unknown run-log version 9"),
        (lambda text: text.split("\n", 1)[1], "does not begin with a start record"),
        (lambda text: text.replace("}\n", "\n", 2), "malformed record"),
    ],
)
def test_damage_before_the_last_line_is_a_format_error_with_offset(tmp_path: Path, damage, words: str) -> None:
    run_points(tmp_path, upto=3)
    path = tmp_path / RUN_LOG
    path.write_text(damage(path.read_text()))
    with pytest.raises(FormatError, match=words) as info:
        read_run(tmp_path)
    assert info.value.path == str(path) and info.value.offset is not None


def test_failed_point_is_not_completed_and_a_redo_wins(tmp_path: Path) -> None:
    points = plan_points(CFG)
    with RunLog.create(tmp_path, run_id="r", config={}, plan=points) as log:
        log.point(measured(points[0]))
        log.point(PointResult.planned(points[1], status="failed", error="tunnel readback mismatch"))
    assert completed_points(tmp_path) == {points[0].point_id}
    log, _ = RunLog.resume(tmp_path)
    with log:
        log.point(measured(points[1]))
    assert completed_points(tmp_path) == {points[0].point_id, points[1].point_id}
    assert read_run(tmp_path).latest_points()[points[1].point_id].status == "done"


def test_interrupted_sweep_resumes_without_redoing_points(tmp_path: Path) -> None:
    points = run_points(tmp_path, upto=9)  # crashed during the 10th point (on the down branch)
    remaining = [s.point_id for s in sweep_plan(CFG, completed_points(tmp_path)) if isinstance(s, Record)]
    assert remaining == [p.point_id for p in points[9:]]
    log, record = RunLog.resume(tmp_path)
    with log:  # a runner executing the resumed plan
        for step in sweep_plan(CFG, completed_points(tmp_path)):
            if isinstance(step, EndPoint):
                log.point(measured(next(p for p in points if p.point_id == step.point_id)))
        log.stop("finished")
    final = read_run(tmp_path)
    ids = [p.point_id for p in final.points]
    assert sorted(ids) == sorted(p.point_id for p in points) and len(ids) == len(set(ids))
    assert final.resumes[0]["done"] == sorted(p.point_id for p in points[:9])


def test_killed_writer_leaves_a_readable_log(tmp_path: Path) -> None:
    script = (
        "import sys, itertools\n"
        "from flagtrack.daemon.sweep.plan import SweepConfig, plan_points\n"
        "from flagtrack.daemon.sweep.runlog import RunLog, PointResult\n"
        "points = plan_points(SweepConfig(speeds=(3.0,)))\n"
        "log = RunLog.create(sys.argv[1], run_id='k', config={}, plan=points)\n"
        "print('started', flush=True)\n"
        "for i in itertools.count():\n"
        "    log.point(PointResult.planned(points[0], raw_bytes=i, error='x' * 2000))\n"
    )  # fmt: skip
    with subprocess.Popen([sys.executable, "-c", script, str(tmp_path)], stdout=subprocess.PIPE, text=True) as proc:
        assert proc.stdout is not None and proc.stdout.readline() == "started\n"
        wait_until(lambda: (tmp_path / RUN_LOG).read_bytes().count(b"\n") > 20, what="20 point records written")
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=5)
    record = read_run(tmp_path)
    assert len(record.points) > 0
    assert [p.raw_bytes for p in record.points] == list(range(len(record.points)))


def test_summary_csv_and_figure(tmp_path: Path) -> None:
    points = run_points(tmp_path, upto=len(plan_points(CFG)))
    csv_path, fig_path = write_summary(tmp_path)
    with open(csv_path, newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert tuple(rows[0])[:9] == (
        "speed_mps", "branch", "state", "amplitude_over_l", "frequency_hz", "twi", "cloud_distance_mean_over_l",
        "event_rate_mev_s", "raw_bytes",
    )  # fmt: skip
    assert tuple(rows[0]) == SUMMARY_COLUMNS and len(rows) == len(points)
    assert [float(r["speed_mps"]) for r in rows] == [p.speed_mps for p in points]
    assert rows[0]["frequency_hz"] == "NaN" and rows[0]["error"] == ""
    assert fig_path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and fig_path.stat().st_size > 10_000
    assert transition_speeds(list(read_run(tmp_path).latest_points().values())) == (ONSET_MPS, DECAY_MPS)


@pytest.mark.parametrize(
    ("states", "expected"),
    [
        ({"up": "ssfff", "down": "fffss"}, (5.0, 4.0)),
        ({"up": "fffff", "down": "fffff"}, (None, None)),  # flapping over the whole range
        ({"up": "sssss", "down": "sssss"}, (None, None)),
        ({"up": "sufff", "down": "ffuss"}, (5.0, 4.0)),  # an unknown point in between
    ],
)
def test_transition_speeds(states: dict[str, str], expected: tuple) -> None:
    speeds = [3.0, 4.0, 5.0, 6.0, 7.0]
    names = {"s": "still", "f": "flapping", "u": "unknown"}
    points = [PointResult(f"{b}{i}", i, b, v, state=names[c])
              for b, order in (("up", speeds), ("down", speeds[::-1]))
              for i, (v, c) in enumerate(zip(order, states[b]))]  # fmt: skip
    assert transition_speeds(points) == expected


def test_resume_uses_the_sweep_stored_in_the_start_record(tmp_path: Path) -> None:
    with RunLog.create(tmp_path, run_id="r", config={"sweep": CFG, "note": Path("/x")}, plan=plan_points(CFG)):
        pass
    record = read_run(tmp_path)
    assert record.start["config"]["sweep"]["branches"] == ["up", "down"]  # dataclasses and enums as plain JSON
    assert stored_sweep(record) == CFG


def test_stored_plan_mismatch_is_refused(tmp_path: Path) -> None:
    other = SweepConfig(speeds=(3.0, 4.0), branches=(Branch.UP,))
    with RunLog.create(tmp_path, run_id="r", config={"sweep": other}, plan=plan_points(CFG)):
        pass
    with pytest.raises(FormatError, match="stored plan differs"):
        stored_sweep(read_run(tmp_path))
    with pytest.raises(FormatError, match="no 'tunnel' config"):
        stored_sweep(read_run(tmp_path), section="tunnel")


def test_sensor_fields_round_trip_and_older_records_load(tmp_path: Path) -> None:
    points = plan_points(CFG)
    with RunLog.create(tmp_path, run_id="s", config={}, plan=points, t_unix=1.0) as log:
        log.point(
            measured(
                points[0],
                sensor_status="ok",
                sensor_error_rms_over_l=0.004,
                sensor_error_max_over_l=0.012,
                sensor_error_mean_over_l=0.003,
                sensor_error_std_over_l=0.002,
                sensor_sync="trigger",
                sensor_offset_us=3000.2,
                sensor_offset_unc_us=0.2,
                sensor_samples=1000,
                sensor_missing=2,
                sensor_file="points/x_sensor.h5",
                cloud_distance_std_over_l=0.001,
            )
        )
        log.point(measured(points[1]))  # no sensor
    with open(tmp_path / RUN_LOG, "a") as handle:  # a record written before the sensor fields existed
        old = {
            k: v
            for k, v in json.loads((tmp_path / RUN_LOG).read_text().splitlines()[2]).items()
            if not k.startswith("sensor") and k not in ("delta_rms_std_over_l", "cloud_distance_std_over_l")
        }
        handle.write(json.dumps({**old, "point_id": points[2].point_id, "index": points[2].index}) + "\n")
    got = read_run(tmp_path).points
    assert got[0].sensor_error_rms_over_l == 0.004 and got[0].sensor_sync == "trigger" and got[0].sensor_missing == 2
    assert got[1].sensor_status is None and math.isnan(got[1].sensor_error_rms_over_l)
    assert got[2].sensor_status is None and got[2].sensor_samples == 0
    csv_path, _ = write_summary(tmp_path)
    with open(csv_path, newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert rows[0]["sensor_error_rms_over_l"] == "0.004" and rows[1]["sensor_error_max_over_l"] == "NaN"
    assert (tmp_path / "validation.png").stat().st_size > 5000  # the sweep figure, as a point has sensor data
