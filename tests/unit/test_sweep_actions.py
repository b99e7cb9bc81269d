"""Per-point actions: checked when the plan is read; commands run with a timeout and can be stopped."""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import pytest

from flagtrack.daemon.errors import ConfigError
from flagtrack.daemon.sweep.actions import CommandAction, PauseAction, parse_action, run_command
from flagtrack.daemon.sweep.plan import Action, SweepConfig, sweep_plan
from flagtrack.daemon.typed_yaml import from_mapping


@pytest.mark.parametrize(
    ("name", "params", "words"),
    [
        ("reconstruct", {}, "unknown action 'reconstruct'"),
        ("command", {}, "needs params.argv"),
        ("command", {"argv": ["x"], "shell": True}, "unknown parameter(s) shell"),
        ("command", {"argv": ["x", "{raw_file}"]}, "bad placeholder"),
        ("command", {"argv": ["x"], "timeout_s": 0}, "timeout_s must be > 0"),
        ("pause", {"seconds": -1}, "seconds >= 0"),
    ],
)
def test_bad_actions_are_refused_with_the_reason(name: str, params: dict, words: str) -> None:
    with pytest.raises(ValueError, match=words.replace("(", r"\(").replace(")", r"\)")):
        parse_action(name, params)


def test_a_bad_action_in_a_sweep_config_names_the_key() -> None:
    with pytest.raises(ConfigError, match="actions") as info:
        from_mapping(SweepConfig, {"speeds": [1.0], "actions": [{"name": "reconstrut"}]}, path="run.yaml")
    assert "run.yaml" in str(info.value) and "unknown action 'reconstrut'" in str(info.value)


def test_the_plan_carries_the_actions_around_the_record() -> None:
    cfg = from_mapping(
        SweepConfig,
        {
            "speeds": [1.0],
            "branches": ["up"],
            "actions": [
                {"name": "pause", "when": "before_record", "params": {"seconds": 2}},
                {"name": "command", "params": {"argv": ["true"]}},
            ],
        },
    )
    names = [type(s).__name__ + (f":{s.name}" if isinstance(s, Action) else "") for s in sweep_plan(cfg)]
    assert names == ["Point", "SetSpeed", "Wait", "Action:pause", "Record", "Action:command", "EndPoint", "SetSpeed"]
    assert parse_action("pause", {"seconds": 2}) == PauseAction(2.0)


def test_commands_report_exit_codes_timeouts_and_missing_programs(tmp_path: Path) -> None:
    ok = run_command(
        CommandAction(("{run_dir}/../none",)), "command", {"run_dir": "/nonexistent"}, tmp_path, tmp_path / "a.log"
    )
    assert not ok.ok and "cannot run '/nonexistent/../none'" in ok.message
    slow = run_command(
        CommandAction((sys.executable, "-c", "import time; time.sleep(30)"), timeout_s=0.3),
        "command",
        {},
        tmp_path,
        tmp_path / "b.log",
    )
    assert not slow.ok and "timed out after 0.3 s" in slow.message and slow.duration_s < 5
    fine = run_command(
        CommandAction((sys.executable, "-c", "print('{point_id}')")),
        "command",
        {"point_id": "007-up-4.00"},
        tmp_path,
        tmp_path / "c.log",
    )
    assert fine.ok and fine.summary() == "command ok" and "007-up-4.00" in (tmp_path / "c.log").read_text()


def test_a_stop_request_while_a_command_runs_kills_it(tmp_path: Path) -> None:
    started = time.monotonic()
    pid_file, marker = tmp_path / "pid", tmp_path / "finished"

    def idle(seconds: float) -> None:
        time.sleep(seconds)  # as the supervisor's idle does
        if pid_file.exists() and pid_file.read_text():  # the command runs: the stop request comes now
            raise KeyboardInterrupt("stop requested")

    script = (
        f"import os, time; open({str(pid_file)!r}, 'w').write(str(os.getpid())); time.sleep(2); "
        f"open({str(marker)!r}, 'w')"
    )
    with pytest.raises(KeyboardInterrupt):
        run_command(
            CommandAction((sys.executable, "-c", script)), "command", {}, tmp_path, tmp_path / "d.log", idle=idle
        )
    with pytest.raises(ProcessLookupError):  # killed and reaped, not even a zombie: it never writes its marker
        os.kill(int(pid_file.read_text()), 0)
    assert not marker.exists() and time.monotonic() - started < 10
