"""Stale updates in sweeps (issue 30): each point's stale fraction in the run log, the summary CSV,
run.json and the progress line; a flapping point stale too often is suspect, a still point is not."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest

from flagtrack.daemon.commands._progress import point_line
from flagtrack.daemon.schema import SupervisorState
from flagtrack.daemon.services.supervisor.analysis import point_metrics
from flagtrack.daemon.sweep.plan import SpeedRange, SweepConfig, plan_points
from flagtrack.daemon.sweep.progress import PointFacts, is_suspect
from flagtrack.daemon.sweep.runlog import PointResult, RunLog, read_run
from flagtrack.daemon.sweep.summary import write_summary
from tests.fakes.helpers import rigid_flapping


def test_point_metrics_count_the_stale_updates() -> None:
    stale = np.zeros(1000, dtype=np.uint8)
    stale[:120] = 1  # a chain that had seen no event yet
    assert point_metrics(
        [rigid_flapping(np.arange(1000) * 1e-3, stale=stale)], 100.0, (0.0, 0.0), 0.0
    ).stale_fraction == pytest.approx(0.12)
    assert (
        point_metrics([rigid_flapping(np.arange(5) * 1e-3, stale=stale[:5])], 100.0, (0.0, 0.0), 0.0).stale_fraction
        == 1.0
    )
    assert math.isnan(point_metrics([], 100.0, (0.0, 0.0), 0.0).stale_fraction)


@pytest.mark.parametrize(
    ("lost", "stale", "state", "suspect"),
    [
        (0.0, 0.3, "flapping", True),  # remembered, not measured, while it flaps
        (0.0, 0.3, "still", False),  # a still flag gives few events: its A/L of 0 stands
        (0.0, 0.05, "flapping", False),  # at the bound, not above
        (0.3, 0.0, "still", True),  # lost is suspect whatever the state
        (0.0, math.nan, "flapping", False),  # an older record: not known
    ],
)
def test_a_flapping_point_stale_too_often_is_suspect(lost: float, stale: float, state: str, suspect: bool) -> None:
    assert is_suspect(lost, 0.05, stale, state) is suspect


def test_run_log_summary_and_run_json_carry_the_stale_fraction(tmp_path: Path) -> None:
    points = plan_points(SweepConfig(range=SpeedRange(4.0, 5.0, 1.0), settle_s=1, record_s=1))
    with RunLog.create(tmp_path, run_id="r", config={}, plan=points, t_unix=1.0) as log:
        log.point(PointResult.planned(points[0], state="still", stale_fraction=0.4, event_rate_mev_s=0.1))
        log.point(PointResult.planned(points[1], state="flapping", stale_fraction=0.0, event_rate_mev_s=2))
    latest = list(read_run(tmp_path).latest_points().values())
    assert [p.stale_fraction for p in latest] == [0.4, 0.0]
    csv_path, _ = write_summary(tmp_path)
    with open(csv_path) as handle:
        assert [row["stale_fraction"] for row in csv.DictReader(handle)] == ["0.4", "0.0"]
    run = json.loads((tmp_path / "run.json").read_text())
    assert [p["stale_fraction"] for p in run["points"]] == [0.4, 0.0]


def test_a_point_of_an_older_run_has_no_stale_fraction(tmp_path: Path) -> None:
    points = plan_points(SweepConfig(range=SpeedRange(4.0, 4.0, 1.0), settle_s=1, record_s=1))
    with RunLog.create(tmp_path, run_id="r", config={}, plan=points, t_unix=1.0) as log:
        log.point(PointResult.planned(points[0], state="still"))
    records = [json.loads(line) for line in (tmp_path / "run.jsonl").read_text().splitlines()]
    for record in records:
        record.pop("stale_fraction", None)  # as written before the field existed
    (tmp_path / "run.jsonl").write_text("".join(json.dumps(r) + "\n" for r in records))
    (point,) = read_run(tmp_path).latest_points().values()
    assert math.isnan(point.stale_fraction) and math.isnan(PointFacts.of(point).stale_fraction)


def test_the_progress_line_shows_the_stale_share_when_known() -> None:
    state = SupervisorState(
        "flapping", 1e6, mode="sweep", points_total=17, last_index=3, last_speed_mps=4.5, last_branch="up",
        last_state="flapping", last_status="done", amplitude_over_l=0.231, frequency_hz=12.4, lost_fraction=0.0,
        stale_fraction=0.125,
    )  # fmt: skip
    assert "lost 0.0 %  stale 12.5 %" in point_line(state)
    older = SupervisorState(**{**state.__dict__, "stale_fraction": -1.0})
    assert "stale" not in point_line(older)
