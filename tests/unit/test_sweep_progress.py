"""Sweep progress: the ETA, the per-point facts (lost-fraction hook included), their line, the plain and quiet
views, and the new SupervisorState fields on the wire, for peers of this version and of the previous one."""

from __future__ import annotations

import dataclasses
import io
import math
from types import SimpleNamespace

import pytest

from flagtrack.daemon.commands._progress import SweepProgressView, bar_text, clock, point_line
from flagtrack.daemon.schema import SupervisorState, decode, encode
from flagtrack.daemon.schema.messages import MESSAGE_TYPES, MessageType
from flagtrack.daemon.sweep.plan import SpeedRange, SweepConfig, plan_points
from flagtrack.daemon.sweep.progress import PointFacts, SweepProgress, lost_fraction
from flagtrack.daemon.sweep.runlog import PointResult

PLAN = plan_points(SweepConfig(range=SpeedRange(4.0, 5.0, 0.5), settle_s=1, record_s=2))  # 3 up + 2 down


def test_eta_is_the_plan_estimate_then_the_measured_mean_less_the_point_in_progress() -> None:
    progress = SweepProgress(PLAN, done=(), planned_point_s=3.0, now_s=100.0)
    assert progress.total == 5 and progress.done == 0 and progress.eta_s(100.0) == 15.0  # 5 points x 3 s planned
    progress.start_point(PLAN[0], 100.0)
    assert progress.current_position == 1 and progress.eta_s(101.0) == 4 * 3.0 + 2.0
    facts = progress.finish_point(PointResult.planned(PLAN[0], state="still"), 110.0)  # it took 10 s, not 3
    assert facts.position == 1 and progress.done == 1 and progress.current_position == 0
    assert progress.eta_s(110.0) == 4 * 10.0
    progress.start_point(PLAN[1], 110.0)
    assert progress.eta_s(125.0) == 3 * 10.0  # past the expected duration: no negative time for this one
    progress.finish_point(PointResult.planned(PLAN[1]), 116.0)  # mean (10 + 6) / 2
    assert progress.eta_s(116.0) == 3 * 8.0 and progress.elapsed_s(116.0) == 16.0


def test_a_resumed_run_counts_the_points_done_before() -> None:
    progress = SweepProgress(
        PLAN, done={PLAN[0].point_id, PLAN[1].point_id, "not-in-plan"}, planned_point_s=2.0, now_s=0.0
    )
    assert progress.done == 2 and progress.eta_s(0.0) == 3 * 2.0
    for point in PLAN[2:]:
        progress.start_point(point, 0.0)
        progress.finish_point(PointResult.planned(point), 1.0)
    assert progress.done == progress.total == 5 and progress.eta_s(1.0) == 0.0


def test_a_redone_point_counts_once_in_done_and_twice_in_records() -> None:
    progress = SweepProgress(PLAN, done=(), planned_point_s=1.0, now_s=0.0)
    for point in PLAN[:-1]:
        progress.finish_point(PointResult.planned(point), 1.0)
    last = PLAN[-1]
    progress.finish_point(dataclasses.replace(PointResult.planned(last), status="lossy"), 2.0)
    assert progress.done == progress.total == 5 and progress.records == 5
    progress.finish_point(PointResult.planned(last), 3.0)  # the lossy last point redone
    assert progress.done == 5 and progress.records == 6 and progress.last is not None
    assert progress.last.status == "done"


def test_lost_fraction_is_nan_until_records_carry_one() -> None:
    assert math.isnan(lost_fraction(PointResult.planned(PLAN[0])))
    later_record = SimpleNamespace(lost_fraction=0.125)  # what a record with the tracker's lost flag will hold
    assert lost_fraction(later_record) == 0.125  # type: ignore[arg-type]
    facts = PointFacts.of(PointResult.planned(PLAN[2], state="flapping", amplitude_over_l=0.25, frequency_hz=11.0))
    assert facts.position == 3 and math.isnan(facts.lost_fraction) and math.isnan(facts.sensor_error_rms_over_l)
    assert math.isnan(facts.chain_reach) and not facts.suspect
    judged = PointFacts.of(PointResult.planned(PLAN[2], state="flapping", chain_reach=0.87, suspect=True))
    assert judged.chain_reach == 0.87 and judged.suspect


def state(**changes) -> SupervisorState:
    values = dict(
        flag_state="flapping",
        rate_hz=3e5,
        mode="sweep",
        point="003-up-5.00",
        branch="up",
        speed_mps=5.0,
        point_index=4,
        points_total=17,
        points_done=3,
        elapsed_s=42.0,
        eta_s=98.0,
        last_point="002-up-4.50",
        last_index=3,
        last_speed_mps=4.5,
        last_branch="up",
        last_state="flapping",
        last_status="done",
        amplitude_over_l=0.231,
        frequency_hz=12.4,
        sensor_error_rms_over_l=0.0043,
    )
    return SupervisorState(**{**values, **changes})


def test_the_line_of_a_point_shows_its_facts_and_dashes_for_what_is_not_known() -> None:
    line = point_line(state())
    for part in (
        " 3/17",
        "4.50 m/s",
        "up",
        "flapping",
        "A/L 0.231",
        "f  12.4 Hz",
        "lost -",
        "e/L RMS 0.43 %",
        "[0:42, ETA 1:38]",
    ):
        assert part in line, (part, line)
    still = point_line(
        state(last_state="still", amplitude_over_l=0.0004, frequency_hz=-1.0, sensor_error_rms_over_l=-1.0)
    )
    assert "f     - Hz" in still and "e/L" not in still and "A/L 0.000" in still
    assert "lost 5.0 %" in point_line(state(lost_fraction=0.05))
    assert "FAILED" in point_line(state(last_status="failed"))
    assert "SUSPECT" not in line
    assert "SUSPECT (reach 0.870)  [0:42" in point_line(state(last_suspect=True, chain_reach=0.87))
    lost = point_line(state(last_suspect=True, lost_fraction=0.4, chain_reach=1.002))
    assert "lost 40.0 %" in lost and "SUSPECT  [0:42" in lost  # suspect for its lost updates, not its reach
    assert bar_text(state()) == "0:42 elapsed, ETA 1:38 | point 4: 5.00 m/s up, flag flapping"
    assert clock(3725) == "1:02:05" and clock(-1.0) == "?"


def feed(view: SweepProgressView) -> None:
    view(state(points_total=0, points_done=0, last_point=""))  # before the sweep: nothing to show
    view(state(points_done=0, last_point="", last_index=0))  # the sweep begins
    for _ in range(3):
        view(state(points_done=0, last_point="", last_index=0))  # states between points: no new line
    view(state(points_done=1, last_point="000-up-4.00", last_index=1, last_speed_mps=4.0))
    view(state(points_done=1, last_point="000-up-4.00", last_index=1, last_speed_mps=4.0))
    view(state(points_done=2, last_point="001-up-4.25", last_index=2, last_speed_mps=4.25))


def test_plain_lines_one_per_finished_point_when_not_on_a_terminal() -> None:
    out = io.StringIO()
    with SweepProgressView(out) as view:
        assert not view.terminal
        feed(view)
    lines = out.getvalue().splitlines()
    assert lines[0] == "sweep: 17 points, ETA 1:38"
    assert [line.split()[1] for line in lines[1:]] == ["1/17", "2/17"] and "\r" not in out.getvalue()


def test_a_redone_last_point_gets_a_line_for_each_record() -> None:
    out = io.StringIO()
    last = dict(last_point="016-down-4.00", last_index=17, points_done=17)
    with SweepProgressView(out) as view:
        view(state(points_done=16, point_records=0, last_point="", last_index=0))
        view(state(**last, point_records=1, last_status="lossy"))
        view(state(**last, point_records=1, last_status="lossy"))  # the same record again: no line
        view(state(**last, point_records=2, last_status="done"))  # points_done unchanged: still a line
    lines = out.getvalue().splitlines()[1:]
    assert len(lines) == 2 and "LOSSY" in lines[0] and "A/L 0.231" in lines[1]
    joined = io.StringIO()  # a view that joins mid-sweep: no line for the records before it
    with SweepProgressView(joined) as view:
        view(state(**last, point_records=2))
        view(state(**last, point_records=2))
    assert [line for line in joined.getvalue().splitlines() if line.startswith("point")] == []


def test_quiet_shows_nothing_and_a_bar_is_drawn_when_asked() -> None:
    out = io.StringIO()
    with SweepProgressView(out, quiet=True) as view:
        feed(view)
    assert out.getvalue() == ""
    bar = io.StringIO()
    with SweepProgressView(bar, terminal=True) as view:
        feed(view)
    shown = bar.getvalue()
    assert "\r" in shown and "sweep 2/17 |" in shown and "ETA 1:38" in shown and shown.count("point  2/17") == 1


def test_new_state_fields_round_trip_and_default_to_no_sweep() -> None:
    message = state(lost_fraction=0.01, chain_reach=0.87, last_suspect=True)
    assert decode(encode(message), SupervisorState) == message
    plain = SupervisorState("still", 1e4, "monitor")
    assert plain.points_total == 0 and plain.amplitude_over_l == -1.0 and plain.eta_s == -1.0
    assert decode(encode(plain), SupervisorState) == plain


PREVIOUS_FIELDS = ("flag_state", "rate_hz", "mode", "point", "branch", "speed_mps", "message")


def test_peers_of_the_previous_version_and_this_one_understand_each_other(monkeypatch: pytest.MonkeyPatch) -> None:
    fields = {f.name: f for f in dataclasses.fields(SupervisorState)}
    assert list(fields)[: len(PREVIOUS_FIELDS)] == list(PREVIOUS_FIELDS)  # additions only at the end
    assert all(fields[name].default is not dataclasses.MISSING for name in list(fields)[len(PREVIOUS_FIELDS) :])
    previous = dataclasses.make_dataclass(
        "SupervisorState",
        [
            (name, fields[name].type, dataclasses.field(default=fields[name].default))
            if fields[name].default is not dataclasses.MISSING
            else (name, fields[name].type)
            for name in PREVIOUS_FIELDS
        ],
        frozen=True,
    )
    previous.TYPE = MessageType.SUPERVISOR_STATE
    old_message = previous("flapping", 3e5, "sweep", "003-up-5.00", "up", 5.0, "")
    from_old_peer = encode(old_message)
    assert decode(from_old_peer, SupervisorState) == SupervisorState("flapping", 3e5, "sweep", "003-up-5.00", "up", 5.0)
    monkeypatch.setitem(MESSAGE_TYPES, MessageType.SUPERVISOR_STATE, previous)  # this process is now an old peer
    assert decode(encode(state()), previous) == old_message
