"""Control laws (daemon/services/supervisor/laws.py): what a law may return, the tunnel's bounds, a
user's file loaded (or refused in one line), the built-in PI as a law; the new messages on the wire."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import pytest

from flagtrack.daemon.errors import ConfigError
from flagtrack.daemon.schema import FlagState, Keys, SpeedReply, SpeedRequest, decode, encode
from flagtrack.daemon.services.supervisor.laws import PiLaw, bound_speed, checked_output, load_law
from flagtrack.daemon.services.supervisor.section import ControlConfig, FeedbackConfig


def state(t_s: float = 1.0, amplitude_over_l: float = 0.25, lost_fraction: float = 0.0) -> FlagState:
    return FlagState("cam0", 1, t_s, 450.0, 240.0, 0.0, True, amplitude_over_l, 11.0, 0.1, 0.3,
                     lost_fraction, 0.0, 5.0, t_s - 0.09, t_s, 90, True, "px", 10, 20)  # fmt: skip


@pytest.mark.parametrize(
    ("value", "speed", "fault"),
    [
        (None, None, ""),
        (4.5, 4.5, ""),
        (3, 3.0, ""),
        (float("nan"), None, "returned nan, not a speed"),
        (float("inf"), None, "returned inf, not a speed"),
        ("fast", None, "returned str 'fast', not a speed"),
        (True, None, "returned bool"),
        ([4.0], None, "returned list"),
    ],
)
def test_what_a_law_may_return(value: object, speed: float | None, fault: str) -> None:
    got_speed, got_fault = checked_output(value)
    assert got_speed == speed and got_fault.startswith(fault) and bool(got_fault) == bool(fault)


@pytest.mark.parametrize(
    ("asked", "applied", "why"),
    [
        (5.0, 5.0, ""),
        (99.0, 10.0, "above tunnel.safety.max_speed_mps 10 m/s"),
        (-1.0, 0.0, "below zero"),
        (0.5, 2.0, "below tunnel.safety.min_speed_mps 2 m/s"),
        (0.0, 0.0, ""),
    ],
)
def test_every_ask_is_bounded_by_the_tunnel_and_says_why(asked: float, applied: float, why: str) -> None:
    got, reason = bound_speed(asked, 2.0, 10.0)
    assert got == applied and (why in reason if why else reason == "")


def test_a_users_law_is_loaded_with_its_setpoint(tmp_path: Path) -> None:
    path = tmp_path / "mine.py"
    path.write_text("setpoint = 0.3\n\ndef law(state):\n    return 4.0 + state.amplitude_over_l\n")
    law = load_law(f"{path}:law", FeedbackConfig())
    assert law.function(state()) == 4.25 and law.setpoint() == 0.3 and law.name == f"{path}:law"


@pytest.mark.parametrize(
    ("text", "spec", "words"),
    [
        ("def law(state):\n    return 1.0\n", "{path}:other", r"has no function 'other' \(it defines: law\)"),
        (
            "raise RuntimeError('no gain')\ndef law(state):\n    return 1.0\n",
            "{path}:law",
            "failed when loaded: RuntimeError: no gain",
        ),
        ("law = 3\n", "{path}:law", r"'law' is not a function \(type int\)"),
        ("def law(state:\n    return 1.0\n", "{path}:law", r"law.py, line 1: '\(' was never closed"),
        ("from math import *\n", "{path}:law", "has no function 'law'"),  # (found once it is run)
        ("", "{path}", "give the law as FILE.py:FUNCTION"),
        ("", "{missing}:law", "no such file"),
    ],
)
def test_a_bad_law_is_one_line_naming_the_key(tmp_path: Path, text: str, spec: str, words: str) -> None:
    path = tmp_path / "law.py"
    path.write_text(text)
    with pytest.raises(ConfigError, match=words) as caught:
        load_law(spec.format(path=path, missing=tmp_path / "none.py"), FeedbackConfig(), key="--controller")
    assert caught.value.key == "--controller" and "\n" not in str(caught.value)


def test_the_built_in_pi_is_a_law_of_the_cycles_amplitude() -> None:
    cfg = FeedbackConfig(target_amplitude_over_l=0.25, start_speed_mps=5.0, max_step_mps=0.2, period_s=1.0)
    pi = load_law("pi", cfg)
    assert isinstance(pi.function, PiLaw) and pi.setpoint() == 0.25
    first = pi.function(state(1.0, amplitude_over_l=0.35))  # too much flapping: slow the wind
    assert first is not None and 4.8 - 1e-9 <= first < 5.0  # at most max_step_mps per period_s
    assert pi.function(state(1.0, amplitude_over_l=0.35)) is None  # the same state again: nothing new
    second = pi.function(state(1.1, amplitude_over_l=0.35))
    assert second is not None and first - 0.02 - 1e-9 <= second < first  # a tenth of a period: a tenth of the step
    held = pi.function(state(1.2, amplitude_over_l=0.1, lost_fraction=0.5))  # lost: held
    assert held == second
    assert pi.function(state(1.3, amplitude_over_l=-1.0)) == second  # not known: held


def test_the_control_section_checks_itself() -> None:
    with pytest.raises(ValueError, match="period_s"):
        ControlConfig(period_s=0.0)
    with pytest.raises(ValueError, match="max_faults"):
        ControlConfig(max_faults=0)
    for timeout_s in (0.0, -1.0, math.nan, math.inf):
        with pytest.raises(ValueError, match="law_timeout_s"):
            ControlConfig(law_timeout_s=timeout_s)


def test_the_new_messages_round_trip_and_their_keys_are_words() -> None:
    for message in (
        state(),
        SpeedRequest(4.5, "id1", "operator", "note", 123),
        SpeedReply("id1", "operator", True, 99.0, 10.0, "why"),
    ):
        assert decode(encode(message)) == message
    keys = Keys("flagtrack/rig1")
    names = [keys.flag_state(), keys.speed_request("operator"), keys.speed_reply()]
    assert names == [
        "flagtrack/rig1/flag/state",
        "flagtrack/rig1/tunnel/request/operator",
        "flagtrack/rig1/tunnel/reply",
    ]
    assert keys.speed_requests() == "flagtrack/rig1/tunnel/request/*"
    unknown = dataclasses.replace(state(), frequency_hz=-1.0)
    assert not math.isnan(decode(encode(unknown)).frequency_hz)  # "not known" is -1.0, no NaN on the wire


def test_controller_none_runs_on_requests_only_and_needs_them(tmp_path: Path) -> None:
    from flagtrack.daemon.rig.config import load_rig
    from flagtrack.daemon.rig.control import control_rig

    deploy = Path(__file__).parents[2] / "deploy" / "rig-control-sim.yaml"
    rig, services = control_rig(load_rig(deploy, services=()), "none", out=tmp_path / "run")
    assert rig.supervisor.control.controller is None and rig.supervisor.mode == "control"
    assert "supervisor" in services
    with pytest.raises(ConfigError, match="no control law: .* or none"):
        control_rig(load_rig(deploy, services=()), None)
    quiet = load_rig(deploy, services=())
    quiet = dataclasses.replace(
        quiet,
        supervisor=dataclasses.replace(
            quiet.supervisor, control=dataclasses.replace(quiet.supervisor.control, requests=False)
        ),
    )
    with pytest.raises(ConfigError, match="nothing would move the speed") as refused:
        control_rig(quiet, "none")
    assert refused.value.key == "--controller"


def test_the_law_timeout_must_leave_the_tunnels_keep_alive_time() -> None:
    from flagtrack.daemon.rig.config import RigConfig
    from flagtrack.daemon.typed_yaml import from_mapping

    tunnel = {"driver": "simulated", "safety": {"loop_timeout_s": 3.0}}
    ok = from_mapping(RigConfig, {"tunnel": tunnel, "supervisor": {"control": {"law_timeout_s": 1.5}}})
    assert ok.supervisor.control.law_timeout_s == 1.5
    with pytest.raises(ConfigError, match="at most half of tunnel.safety.loop_timeout_s") as refused:
        from_mapping(RigConfig, {"tunnel": tunnel, "supervisor": {"control": {"law_timeout_s": 2.0}}})
    assert refused.value.key == "supervisor.control.law_timeout_s"
