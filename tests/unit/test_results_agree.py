"""One name, one unit, one statistic per number (issue 32), on a run made of point records (no rig): the
terminal lines (through the supervisor's progress fields), README.txt, run.json, run.jsonl, summary.csv,
the demo's report and --json, and the figures agree; a point's figure says what its excerpt is; records
written with the names before the tip error and the cloud distance were told apart still read."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from flagtrack.daemon.commands._progress import point_line
from flagtrack.daemon.commands.demo import demo_report
from flagtrack.daemon.core.pointsensor import SensorComparison
from flagtrack.daemon.core.sync import ClockSync
from flagtrack.daemon.schema import SupervisorState
from flagtrack.daemon.services.supervisor.busside import progress_fields
from flagtrack.daemon.sweep.figures import amplitude_figure, sweep_figure
from flagtrack.daemon.sweep.plan import SpeedRange, SweepConfig, plan_points
from flagtrack.daemon.sweep.progress import SweepProgress
from flagtrack.daemon.sweep.runlog import RUN_LOG, PointResult, RunLog, point_paths, read_run
from flagtrack.daemon.sweep.summary import figure_titles, summary_points, transition_speeds, write_summary
from flagtrack.daemon.typed_yaml import to_mapping
from flagtrack.daemon.validation.figures import point_figure
from flagtrack.daemon.validation.point import FlagFrame, PointValidation
from tests.results_agree import (
    check_demo_report,
    check_files,
    check_point_figure,
    check_sweep_figures,
    check_terminal,
    figure_texts,
)

CFG = SweepConfig(range=SpeedRange(4.0, 5.0, 0.5), settle_s=1, record_s=2)  # up 4, 4.5, 5; down 4.5, 4


def measured(point, index: int) -> PointResult:
    """Numbers as a sweep gives them: still points without f, one point without sensor, one failed."""
    flapping = point.speed_mps >= 4.5 and not (point.branch.value == "up" and point.speed_mps == 4.5)
    rng = np.random.default_rng(index)
    values = dict(
        state="flapping" if flapping else "still",
        amplitude_over_l=0.25 + 0.01 * index if flapping else 0.0004,
        amplitude_std_over_l=0.006 if flapping else math.nan,
        frequency_hz=11.0 + index if flapping else math.nan,
        event_rate_mev_s=0.3 if flapping else 0.007,
        cloud_distance_mean_over_l=0.004 + 0.0001 * index,
        cloud_distance_std_over_l=0.0012,
        lost_fraction=[0.0, 0.0004, 0.021, 0.0, 0.0][index],
        raw_file=point_paths(point.point_id)[0],
        sensor_status="ok",
        sensor_error_rms_over_l=float(0.003 + 0.002 * rng.random()),
        sensor_error_max_over_l=0.0271,
        sensor_error_mean_over_l=0.0025,
        sensor_error_std_over_l=0.0015,
    )
    if index == 3:  # no comparison at this point
        values.update(sensor_status="sensor samples all missing", sensor_error_rms_over_l=math.nan,
                      sensor_error_max_over_l=math.nan, sensor_error_mean_over_l=math.nan,
                      sensor_error_std_over_l=math.nan)  # fmt: skip
    return PointResult.planned(point, **values)


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[str]]:
    """A finished run of 5 points, written as the runner writes it; the terminal's lines of its points."""
    run_dir = tmp_path_factory.mktemp("runs") / "sweep"
    plan = plan_points(CFG)
    progress = SweepProgress(plan, set(), planned_point_s=3.0, now_s=0.0)
    lines = []
    with RunLog.create(run_dir, run_id="sweep", config={"sweep": to_mapping(CFG)}, plan=plan, t_unix=1.8e9) as log:
        for index, point in enumerate(plan):
            progress.start_point(point, float(index))
            result = measured(point, index)
            log.point(result)
            progress.finish_point(result, index + 0.9)
            state = SupervisorState("still", 0.0, mode="sweep", **progress_fields(progress, index + 0.9))
            lines.append(point_line(state))
        log.stop("finished", t_unix=1.8e9 + 60)
    write_summary(run_dir)
    return run_dir, lines


def test_the_files_the_terminal_and_the_report_agree(run: tuple[Path, list[str]]) -> None:
    run_dir, lines = run
    described = check_files(run_dir)
    assert check_terminal(lines, described) == 5
    summary, text = demo_report(run_dir, None, 0.5)
    check_demo_report(text, summary, described)
    readme = (run_dir / "README.txt").read_text()
    assert "e/L RMS (%)" in readme and "Delta_RMS/L mean (%)" in readme and "cloud_distance_mean_over_l" in readme


def test_the_sweep_figures_say_what_which_run_and_in_what_unit(run: tuple[Path, list[str]]) -> None:
    run_dir, _ = run
    record = read_run(run_dir)
    points = summary_points(record)
    amplitude_title, sweep_title = figure_titles(record, points)
    amplitude = amplitude_figure(points, amplitude_title, transition_speeds(points))
    sweep = sweep_figure(points, sweep_title)
    check_sweep_figures(json.loads((run_dir / "run.json").read_text()), amplitude, sweep)
    texts = figure_texts(sweep)
    assert any("no sensor comparison (1 points)" in t for t in texts)  # a marker where there is no number
    assert (run_dir / "validation.png").stat().st_size > 5000 and (run_dir / "amplitude.png").stat().st_size > 5000


def validation(still: bool, duration_s: float = 2.0) -> PointValidation:
    """A point's comparison as validate_point makes it: 1 kHz updates, a 1 kHz sensor; a still flag's
    updates have events (a finite Delta_RMS) only now and then."""
    t = np.arange(0.0, duration_s, 1e-3)
    length = 300.0
    y = np.zeros_like(t) if still else 30.0 * np.sin(2 * np.pi * 11.0 * t)
    error = 1.2 * np.sin(2 * np.pi * 0.7 * t) + 0.3 * np.cos(2 * np.pi * 37 * t)  # larger in some parts
    delta = np.full_like(t, np.nan)
    delta[:: 97 if still else 1] = 1.5 + 0.5 * np.abs(np.sin(2 * np.pi * 3 * t[:: 97 if still else 1]))
    comparison = SensorComparison(t, y - error, y, error, length, 0.0, len(t), len(t), len(t))
    sync = ClockSync("trigger", 3000.0, 0.2)
    return PointValidation("ok", sync, sync, ClockSync("none"), ClockSync("none"), comparison, t, y, delta,
                           FlagFrame(length, (150.0, 240.0), 0.0), "px", 0.73, len(t), 0,
                           np.zeros(len(t), dtype=bool))  # fmt: skip


@pytest.mark.parametrize("still", [False, True])
def test_a_points_figure_says_its_excerpt_and_gives_each_statistic_its_own_span(still: bool) -> None:
    v = validation(still)
    whole = {"sensor_error_rms_over_l": v.comparison.error_rms_over_l}  # type: ignore[union-attr]
    fig = point_figure(v, "run sweep, point 014-down-4.50: 4.50 m/s, flapping", window_s=0.3)
    check_point_figure(fig, whole)
    assert "an excerpt: 0.30 s of the point's 2.00 s" in fig.axes[0].get_title()
    excerpt_rms = float(fig.axes[1].texts[0].get_text().split("e/L RMS ")[1].split(" %")[0])
    assert abs(excerpt_rms - 100 * whole["sensor_error_rms_over_l"]) > 0.05  # the excerpt's own, not the point's
    if still:  # a few updates with events: drawn as markers, counted
        note = fig.axes[2].texts[0].get_text()  # one update in 97 had events: 3 or 4 of the 300 shown
        assert note.endswith(("3 of 300 updates had events", "4 of 300 updates had events")), note
    short = point_figure(validation(still, duration_s=0.2), "short", window_s=0.3)
    check_point_figure(short)
    assert "the whole point" in short.axes[0].get_title()


def test_records_written_before_the_cloud_distance_had_its_name_still_read(tmp_path: Path) -> None:
    plan = plan_points(CFG)
    with RunLog.create(tmp_path, run_id="old", config={}, plan=plan, t_unix=1.0) as log:
        log.point(PointResult.planned(plan[0], cloud_distance_mean_over_l=0.004, cloud_distance_std_over_l=0.001))
    record = json.loads((tmp_path / RUN_LOG).read_text().splitlines()[1])
    assert record["cloud_distance_mean_over_l"] == record["delta_rms_over_l"] == 0.004  # both names written
    old = {k: v for k, v in record.items() if not k.startswith("cloud_distance")}
    old.update(point_id=plan[1].point_id, index=1, delta_rms_over_l=0.005, delta_rms_std_over_l=0.002)
    with open(tmp_path / RUN_LOG, "a") as handle:
        handle.write(json.dumps(old) + "\n")
    got = read_run(tmp_path).points[1]
    assert (got.cloud_distance_mean_over_l, got.cloud_distance_std_over_l) == (0.005, 0.002)
