"""Shedding in sweeps (issue 33): each point's share of camera time the live tracker shed, from the
updates' ``shed``, in the run log, the summary CSV and run.json; points of older runs read as unknown."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest

from flagtrack.daemon.services.supervisor.analysis import point_metrics
from flagtrack.daemon.sweep.plan import SpeedRange, SweepConfig, plan_points
from flagtrack.daemon.sweep.runlog import PointResult, RunLog, read_run
from flagtrack.daemon.sweep.summary import write_summary
from tests.fakes.helpers import rigid_flapping


def test_the_share_shed_is_weighted_by_the_time_each_update_stands_for() -> None:
    t = np.arange(1000) * 1e-3  # updates every ms ...
    keep = np.ones(1000, bool)
    keep[100:200] = False  # ... but 100 ms of them skipped: the update after the gap says 100 of its 101 ms
    shed = np.zeros(1000, np.float32)
    shed[200] = 100 / 101
    metrics = point_metrics([rigid_flapping(t[keep], shed=shed[keep])], 100.0, (0.0, 0.0), 0.0)
    assert metrics.shed_fraction == pytest.approx(0.1 / 0.999, rel=1e-6)
    untouched = point_metrics([rigid_flapping(t, shed=np.zeros(1000, np.float32))], 100.0, (0.0, 0.0), 0.0)
    assert untouched.shed_fraction == 0.0
    assert math.isnan(point_metrics([], 100.0, (0.0, 0.0), 0.0).shed_fraction)


def test_run_log_summary_and_run_json_carry_the_share_shed(tmp_path: Path) -> None:
    points = plan_points(SweepConfig(range=SpeedRange(4.0, 5.0, 1.0), settle_s=1, record_s=1))
    with RunLog.create(tmp_path, run_id="r", config={}, plan=points, t_unix=1.0) as log:
        log.point(PointResult.planned(points[0], state="still", shed_fraction=0.0, event_rate_mev_s=0.1))
        log.point(PointResult.planned(points[1], state="flapping", shed_fraction=0.25, event_rate_mev_s=2))
    latest = list(read_run(tmp_path).latest_points().values())
    assert [p.shed_fraction for p in latest] == [0.0, 0.25]
    csv_path, _ = write_summary(tmp_path)
    with open(csv_path) as handle:
        assert [row["shed_fraction"] for row in csv.DictReader(handle)] == ["0.0", "0.25"]
    run = json.loads((tmp_path / "run.json").read_text())
    assert [p["shed_fraction"] for p in run["points"]] == [0.0, 0.25]


def test_a_point_of_an_older_run_has_no_share_shed(tmp_path: Path) -> None:
    points = plan_points(SweepConfig(range=SpeedRange(4.0, 4.0, 1.0), settle_s=1, record_s=1))
    with RunLog.create(tmp_path, run_id="r", config={}, plan=points, t_unix=1.0) as log:
        log.point(PointResult.planned(points[0], state="still"))
    lines = (tmp_path / "run.jsonl").read_text().splitlines()
    records = [json.loads(line) for line in lines]
    for record in records:
        record.pop("shed_fraction", None)  # as written before the field existed
    (tmp_path / "run.jsonl").write_text("".join(json.dumps(r) + "\n" for r in records))
    (point,) = read_run(tmp_path).latest_points().values()
    assert math.isnan(point.shed_fraction)
