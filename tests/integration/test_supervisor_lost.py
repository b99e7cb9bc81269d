"""A sweep point whose tracker did not find the flag (issue 19), or whose chain is longer than the flag,
is marked suspect, on the simulated rig."""

from __future__ import annotations

import csv
import dataclasses
from pathlib import Path

import pytest

from flagtrack.daemon.commands._progress import point_line
from flagtrack.daemon.schema import SupervisorState
from flagtrack.daemon.sweep.runlog import read_run
from flagtrack.daemon.tracking.section import LostSection
from tests.integration.test_supervisor import rig, run


@pytest.mark.slow
def test_a_point_tracked_off_the_flag_is_suspect(tmp_path: Path) -> None:
    """The chain rests 90 degrees off the flag and may not search (re-acquisition off): the flapping
    point's updates are lost and the point is suspect in the run log and the summary CSV."""
    config = rig(tmp_path, sweep={"speeds": [5.5], "branches": ["up"], "settle_s": 0.5, "record_s": 1.0})
    tracker = config.tracker.with_overrides(direction_deg=90.0, lost=LostSection(reacquire=False))
    supervisor, report, _ = run(dataclasses.replace(config, tracker=tracker))
    assert supervisor.stop_reason == "finished" and not report.errors
    (point,) = read_run(tmp_path / "runs" / "run").latest_points().values()
    assert point.state == "flapping" and point.lost_fraction > 0.5 and point.suspect
    assert 0 <= point.stale_fraction <= 1  # measured, not left unknown
    with open(tmp_path / "runs" / "run" / "summary.csv") as handle:
        (row,) = csv.DictReader(handle)
    assert row["suspect"] == "True" and float(row["lost_fraction"]) == pytest.approx(point.lost_fraction)


@pytest.mark.slow
def test_a_point_tracked_with_a_chain_longer_than_the_flag_is_suspect(tmp_path: Path) -> None:
    """A chain 15 % longer than the flag finds it at every update (no loss to see) while its tail has
    no events: the point's chain reach says so, and the point is suspect."""
    config = rig(tmp_path, sweep={"speeds": [5.5], "branches": ["up"], "settle_s": 0.5, "record_s": 1.0})
    length = config.tracker.length
    assert length is not None
    tracker = config.tracker.with_overrides(length=1.15 * length)
    states: list[SupervisorState] = []
    supervisor, report, _ = run(
        dataclasses.replace(config, tracker=tracker), during=lambda services, _: services[0].add_observer(states.append)
    )
    assert supervisor.stop_reason == "finished" and not report.errors
    (point,) = read_run(tmp_path / "runs" / "run").latest_points().values()
    assert point.state == "flapping" and point.lost_fraction < 0.05 and point.suspect
    assert point.chain_reach == pytest.approx(1 / 1.15, abs=0.02)
    # what `flagtrack sweep` prints for the point, from the state the supervisor published
    last = [s for s in states if s.last_point == point.point_id][-1]
    assert last.last_suspect and last.chain_reach == pytest.approx(point.chain_reach)
    assert f"SUSPECT (reach {point.chain_reach:.3f})" in point_line(last)
    with open(tmp_path / "runs" / "run" / "summary.csv") as handle:
        (row,) = csv.DictReader(handle)
    assert row["suspect"] == "True" and float(row["chain_reach"]) == pytest.approx(point.chain_reach)
