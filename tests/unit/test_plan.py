"""Sweep plans: tested by listing what they yield."""

from __future__ import annotations

from pathlib import Path

import pytest

from flagtrack.daemon.errors import ConfigError
from flagtrack.daemon.sweep.plan import (
    Action,
    ActionSpec,
    Branch,
    EndPoint,
    Point,
    Record,
    SetSpeed,
    SpeedRange,
    SweepConfig,
    Wait,
    load_sweep_config,
    plan_points,
    sweep_plan,
)


@pytest.mark.parametrize(
    ("rng", "expected"),
    [
        (SpeedRange(3.0, 4.0, 0.25), (3.0, 3.25, 3.5, 3.75, 4.0)),
        (SpeedRange(0.1, 0.3, 0.1), (0.1, 0.2, 0.3)),  # 0.1 + 2 * 0.1 is 0.30000000000000004
        (SpeedRange(5.0, 5.9, 0.5), (5.0, 5.5)),
        (SpeedRange(2.0, 2.0, 1.0), (2.0,)),
    ],
)
def test_range_values_include_stop_without_float_noise(rng: SpeedRange, expected: tuple[float, ...]) -> None:
    assert rng.values() == expected


def test_one_point_yields_set_settle_record_end_then_zero() -> None:
    steps = list(sweep_plan(SweepConfig(speeds=(4.0,), branches=(Branch.UP,), settle_s=5, record_s=20)))
    assert steps == [
        Point("000-up-4.00", 0, Branch.UP, 4.0),
        SetSpeed(4.0),
        Wait(5.0),
        Record(20.0, "000-up-4.00"),
        EndPoint("000-up-4.00"),
        SetSpeed(0.0, reason="end of sweep"),
    ]


def test_up_and_down_branches_share_the_turning_point_unless_asked() -> None:
    cfg = SweepConfig(speeds=(5.0, 3.0, 4.0, 4.0))
    assert [(p.branch.value, p.speed_mps) for p in plan_points(cfg)] == [
        ("up", 3.0), ("up", 4.0), ("up", 5.0), ("down", 4.0), ("down", 3.0),
    ]  # fmt: skip
    repeated = plan_points(SweepConfig(speeds=(3.0, 4.0), repeat_turning_point=True))
    assert [p.point_id for p in repeated] == ["000-up-3.00", "001-up-4.00", "002-down-4.00", "003-down-3.00"]
    down_only = plan_points(SweepConfig(speeds=(3.0, 4.0), branches=(Branch.DOWN,)))
    assert [p.speed_mps for p in down_only] == [4.0, 3.0]


def test_actions_surround_the_record() -> None:
    cfg = SweepConfig(
        speeds=(3.0,), branches=(Branch.UP,), settle_s=1, record_s=2,
        actions=(ActionSpec("command", params={"argv": ["true"]}), ActionSpec("pause", when="before_record", params={"seconds": 3})),
    )  # fmt: skip
    kinds = [type(s).__name__ for s in sweep_plan(cfg)]
    assert kinds == ["Point", "SetSpeed", "Wait", "Action", "Record", "Action", "EndPoint", "SetSpeed"]
    actions = [s for s in sweep_plan(cfg) if isinstance(s, Action)]
    assert actions == [
        Action("pause", "000-up-3.00", {"seconds": 3}),
        Action("command", "000-up-3.00", {"argv": ["true"]}),
    ]


def test_resume_skips_done_points_and_reenters_the_down_branch_from_the_top() -> None:
    cfg = SweepConfig(range=SpeedRange(3.0, 6.0, 1.0), settle_s=7, record_s=1)
    ids = [p.point_id for p in plan_points(cfg)]
    assert ids == [
        "000-up-3.00",
        "001-up-4.00",
        "002-up-5.00",
        "003-up-6.00",
        "004-down-5.00",
        "005-down-4.00",
        "006-down-3.00",
    ]
    done = set(ids[:5])  # crashed while measuring 005-down-4.00
    steps = list(sweep_plan(cfg, done))
    assert [s.point_id for s in steps if isinstance(s, Record)] == ["005-down-4.00", "006-down-3.00"]
    assert steps[:3] == [
        SetSpeed(6.0, reason="re-enter the down branch from its top"),
        Wait(7.0, reason="re-enter the down branch from its top"),
        Point("005-down-4.00", 5, Branch.DOWN, 4.0),
    ]
    assert sum(isinstance(s, SetSpeed) and s.speed_mps == 6.0 for s in steps) == 1


def test_resume_on_the_up_branch_needs_no_reentry() -> None:
    cfg = SweepConfig(speeds=(3.0, 4.0, 5.0), settle_s=1, record_s=1)
    steps = list(sweep_plan(cfg, {"000-up-3.00"}))
    assert steps[0] == Point("001-up-4.00", 1, Branch.UP, 4.0)
    assert [s.point_id for s in steps if isinstance(s, Record)] == [
        "001-up-4.00",
        "002-up-5.00",
        "003-down-4.00",
        "004-down-3.00",
    ]


def test_resume_of_a_finished_sweep_only_returns_to_zero() -> None:
    cfg = SweepConfig(speeds=(3.0, 4.0))
    assert list(sweep_plan(cfg, {p.point_id for p in plan_points(cfg)})) == [SetSpeed(0.0, reason="end of sweep")]


def test_plan_from_yaml(tmp_path: Path) -> None:
    path = tmp_path / "run.yaml"
    path.write_text(
        "sweep:\n"
        "  range: {start: 3, stop: 4, step: 0.5}\n"
        "  branches: [up, down]\n"
        "  settle_s: 10\n"
        "  record_s: 20\n"
        "  actions:\n"
        "    - {name: command, when: after_record, params: {argv: [flagtrack, events, info, '{raw}']}}\n"
    )
    cfg = load_sweep_config(path)
    assert cfg.speed_values() == (3.0, 3.5, 4.0)
    assert cfg.branches == (Branch.UP, Branch.DOWN) and cfg.actions == (
        ActionSpec("command", params={"argv": ["flagtrack", "events", "info", "{raw}"]}),
    )
    assert len([s for s in sweep_plan(cfg) if isinstance(s, Record)]) == 5


@pytest.mark.parametrize(
    ("body", "key", "words"),
    [
        ("sweep:\n  speeds: [3]\n  range: {start: 3, stop: 4, step: 1}\n", "sweep", "exactly one of"),
        ("sweep:\n  record_s: 3\n", "sweep", "exactly one of"),
        ("sweep:\n  speeds: [3]\n  branches: [up, sideways]\n", "sweep.branches[1]", "one of"),
        ("sweep:\n  range: {start: 4, stop: 3, step: 1}\n", "sweep.range", "start <= stop"),
        ("sweep:\n  speeds: [3]\n  settle: 3\n", "sweep.settle", "unknown key"),
        ("sweep:\n  speeds: [3]\n  actions: [{name: x, when: during}]\n", "sweep.actions[0].when", "one of"),
        ("tunnel: {}\n", "sweep", "section is missing"),
    ],
)
def test_yaml_errors_name_key_and_file(tmp_path: Path, body: str, key: str, words: str) -> None:
    path = tmp_path / "run.yaml"
    path.write_text(body)
    with pytest.raises(ConfigError) as info:
        load_sweep_config(path)
    assert str(path) in str(info.value) and f"'{key}'" in str(info.value) and words in str(info.value)
