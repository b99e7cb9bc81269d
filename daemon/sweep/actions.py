"""Per-point actions of a sweep: what they mean, checked when the plan is read, run by the supervisor.

Two built-in actions (config ``sweep.actions``)::

    actions:
      - name: command             # run a program for the point (e.g. an offline reconstruction)
        when: after_record        # or before_record
        params:
          argv: [flagtrack, reconstruct, "{raw}", -o, "{point_dir}/{point_id}.recon.h5", --length, "300"]
          timeout_s: 600          # default 600
          required: false         # true: a failure stops the sweep (tunnel to zero); default: noted, go on
      - name: pause               # an extra wait at the point (e.g. for a manual check)
        params: {seconds: 5}

Placeholders in ``argv`` (Python ``{name}``): ``point_id``, ``index``, ``branch``, ``speed_mps``,
``run_dir``, ``point_dir`` (``run_dir/points``), ``raw`` (the point's raw file; after recording) and
``centrelines`` (its centreline file). The command runs in ``run_dir``; its output goes to
``points/<point_id>.action<N>.log`` (N: the action's number at the point, from 0).
"""

from __future__ import annotations

import subprocess
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

BUILTIN_ACTIONS = ("command", "pause")
PLACEHOLDERS = ("point_id", "index", "branch", "speed_mps", "run_dir", "point_dir", "raw", "centrelines")


@dataclass(frozen=True)
class CommandAction:
    """Run ``argv`` (placeholders filled in) with a timeout; ``required``: a failure stops the sweep."""

    argv: tuple[str, ...]
    timeout_s: float = 600.0
    required: bool = False


@dataclass(frozen=True)
class PauseAction:
    """Wait ``seconds`` at the point."""

    seconds: float


@dataclass(frozen=True)
class ActionOutcome:
    """How an action went: ``ok``, a one-line ``message``, how long it took (s)."""

    name: str
    ok: bool
    message: str
    duration_s: float
    required: bool = False

    def summary(self) -> str:
        """``name ok`` or ``name failed: message``, for the run log."""
        return f"{self.name} ok" if self.ok else f"{self.name} failed: {self.message}"


def parse_action(name: str, params: dict[str, Any]) -> CommandAction | PauseAction:
    """The typed action for ``name`` and its ``params``.

    Raises:
        ValueError: unknown name, missing or wrong parameter, unknown placeholder.
    """
    if name == "command":
        unknown = set(params) - {"argv", "timeout_s", "required"}
        argv = params.get("argv")
        if unknown:
            raise ValueError(f"action 'command': unknown parameter(s) {', '.join(sorted(unknown))}")
        if not isinstance(argv, list | tuple) or not argv or not all(isinstance(a, str | int | float) for a in argv):
            raise ValueError("action 'command' needs params.argv, a non-empty list of strings")
        argv = tuple(str(a) for a in argv)
        for arg in argv:
            try:
                arg.format_map({key: "" for key in PLACEHOLDERS})
            except (KeyError, ValueError, IndexError) as exc:
                raise ValueError(
                    f"action 'command': bad placeholder in {arg!r} ({exc}); known: {', '.join(PLACEHOLDERS)}"
                ) from None
        timeout_s = float(params.get("timeout_s", 600.0))
        if not timeout_s > 0:
            raise ValueError("action 'command': timeout_s must be > 0")
        return CommandAction(argv, timeout_s, bool(params.get("required", False)))
    if name == "pause":
        if set(params) != {"seconds"} or not float(params["seconds"]) >= 0:
            raise ValueError("action 'pause' needs params.seconds >= 0 (and nothing else)")
        return PauseAction(float(params["seconds"]))
    raise ValueError(f"unknown action {name!r}; built-in actions: {', '.join(BUILTIN_ACTIONS)}")


def run_command(
    action: CommandAction,
    name: str,
    context: dict[str, Any],
    cwd: Path,
    log_path: Path,
    idle: Callable[[float], None] = time.sleep,
) -> ActionOutcome:
    """Run a command action for one point; the outcome says what went wrong.

    ``idle(seconds)`` is called while the command runs (the supervisor keeps watching the rig
    there); if it raises, the command is killed and the exception goes on.
    """
    start = time.monotonic()
    argv = [arg.format_map(context) for arg in action.argv]

    def outcome(ok: bool, message: str = "") -> ActionOutcome:
        return ActionOutcome(name, ok, message, time.monotonic() - start, action.required)

    with open(log_path, "wb") as out:
        out.write(("$ " + " ".join(argv) + "\n").encode())
        out.flush()
        try:
            proc = subprocess.Popen(argv, cwd=cwd, stdout=out, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
        except OSError as exc:
            return outcome(False, f"cannot run {argv[0]!r}: {exc.strerror or exc}")
        try:
            while proc.poll() is None:
                if time.monotonic() - start > action.timeout_s:
                    proc.kill()
                    proc.wait()
                    return outcome(False, f"timed out after {action.timeout_s:g} s (output: {log_path.name})")
                idle(0.05)
        except BaseException:
            proc.kill()
            proc.wait()
            raise
    if proc.returncode != 0:
        return outcome(False, f"exit code {proc.returncode} (output: {log_path.name})")
    return outcome(True)


__all__ = [
    "BUILTIN_ACTIONS",
    "PLACEHOLDERS",
    "ActionOutcome",
    "CommandAction",
    "PauseAction",
    "parse_action",
    "run_command",
]
