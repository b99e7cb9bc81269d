"""Control laws for mode ``control``: a user's function ``FILE.py:FUNCTION`` or the built-in ``pi``,
what they may return, and the speed bounds every ask goes through.

A law is called with the newest :class:`~flagtrack.daemon.schema.FlagState` and returns a wind speed
in m/s, or None to hold. Anything else (an exception, NaN, a string) is a fault: the speed is held.
A law may say what it holds the flag at with a ``setpoint`` (a number: an attribute of the function,
or a name of its module; the run's record and figure show it).
"""

from __future__ import annotations

import ast
import importlib.util
import math
import numbers
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from flagtrack.daemon.errors import ConfigError
from flagtrack.daemon.schema import FlagState
from flagtrack.daemon.services.supervisor.feedback import ControllerState, control_step, measured_amplitude
from flagtrack.daemon.services.supervisor.section import FeedbackConfig

BUILT_IN = ("pi",)


@dataclass(frozen=True)
class Law:
    """A loaded law: its name (``FILE.py:FUNCTION`` or ``pi``), the callable and its module."""

    name: str
    function: Callable[[FlagState], Any]
    module: Any = None

    def setpoint(self) -> float:
        """What the law says it holds (its ``setpoint``), NaN when it says nothing."""
        value: object = getattr(self.function, "setpoint", getattr(self.module, "setpoint", math.nan))
        if isinstance(value, bool) or not isinstance(value, numbers.Real):
            return math.nan
        if math.isfinite(float(value)):
            return float(value)
        return math.nan


def law_file(spec: str, key: str, path: str | None = None) -> tuple[Path, str]:
    """The file and function of ``FILE.py:FUNCTION``, checked without running anything: the file
    is there, is Python, and defines the name (found before the rig starts, not once it is up).

    Raises:
        ConfigError: not of that form, no such file, a syntax error, no such name (naming ``key``).
    """
    file, sep, function = spec.rpartition(":")
    if not sep or not file.endswith(".py") or not function.isidentifier():
        raise ConfigError(
            f"{spec!r}: give the law as FILE.py:FUNCTION, or {', '.join(BUILT_IN)} (or none: speed requests only)",
            key=key,
            path=path,
        )
    law_path = Path(file).expanduser()
    if not law_path.is_file():
        raise ConfigError(f"no such file: {law_path}", key=key, path=path)
    try:
        tree = ast.parse(law_path.read_bytes(), filename=str(law_path))
    except SyntaxError as exc:
        raise ConfigError(f"{law_path}, line {exc.lineno}: {exc.msg}", key=key, path=path) from None
    except (OSError, ValueError) as exc:
        raise ConfigError(f"{law_path}: cannot be read as Python: {exc}", key=key, path=path) from None
    names = _top_level_names(tree)
    if names is not None and function not in names:
        defined = ", ".join(sorted(n for n in names if not n.startswith("_"))) or "nothing"
        raise ConfigError(f"{law_path} has no function {function!r} (it defines: {defined})", key=key, path=path)
    return law_path, function


def _top_level_names(tree: ast.Module) -> set[str] | None:
    """The names a module's top level binds; None when it cannot tell (``from x import *``)."""
    names: set[str] = set()
    for node in tree.body:
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
            names.add(node.name)
        elif isinstance(node, ast.Import | ast.ImportFrom):
            for alias in node.names:
                if alias.name == "*":
                    return None
                names.add(alias.asname or alias.name.split(".")[0])
        else:
            names.update(n.id for n in ast.walk(node) if isinstance(n, ast.Name) and isinstance(n.ctx, ast.Store))
    return names


def load_law(spec: str, feedback: FeedbackConfig, key: str = "supervisor.control.controller") -> Law:
    """The law ``spec`` names: ``pi`` (the ``feedback:`` section's PI) or ``FILE.py:FUNCTION``
    (the file is run as a module).

    Raises:
        ConfigError: the file is missing, cannot be run, or has no such function (naming ``key``).
    """
    if spec == "pi":
        return Law("pi", PiLaw(feedback))
    law_path, name = law_file(spec, key)
    module_spec = importlib.util.spec_from_file_location(f"flagtrack_law_{law_path.stem}", law_path)
    if module_spec is None or module_spec.loader is None:
        raise ConfigError(f"{law_path} cannot be loaded as a Python module", key=key)
    module = importlib.util.module_from_spec(module_spec)
    try:
        module_spec.loader.exec_module(module)
    except Exception as exc:  # noqa: BLE001 - a user's file: whatever it raises is one line
        raise ConfigError(f"{law_path} failed when loaded: {type(exc).__name__}: {exc}", key=key) from None
    function = getattr(module, name, None)
    if function is None:
        raise ConfigError(f"{law_path} has no function {name!r}", key=key)
    if not callable(function):
        raise ConfigError(f"{law_path}: {name!r} is not a function (type {type(function).__name__})", key=key)
    return Law(spec, function, module)


def checked_output(value: object) -> tuple[float | None, str]:
    """A law's return value as (speed, "") or (None, "") to hold, or (None, why it is a fault)."""
    if value is None:
        return None, ""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        return None, f"returned {type(value).__name__} {str(value)[:40]!r}, not a speed in m/s or None"
    speed = float(value)
    if not math.isfinite(speed):
        return None, f"returned {speed}, not a speed in m/s or None"
    return speed, ""


def bound_speed(asked_mps: float, min_speed_mps: float, max_speed_mps: float) -> tuple[float, str]:
    """The speed applied for ``asked_mps`` within the tunnel's bounds (``tunnel.safety``), and why it
    differs ("" when it does not): above the maximum, the maximum; below zero, zero; between zero and
    the smallest non-zero speed, that speed."""
    if asked_mps > max_speed_mps:
        return max_speed_mps, f"asked {asked_mps:g} m/s, above tunnel.safety.max_speed_mps {max_speed_mps:g} m/s"
    if asked_mps < 0:
        return 0.0, f"asked {asked_mps:g} m/s, below zero"
    if 0 < asked_mps < min_speed_mps:
        return min_speed_mps, f"asked {asked_mps:g} m/s, below tunnel.safety.min_speed_mps {min_speed_mps:g} m/s"
    return asked_mps, ""


class PiLaw:
    """The PI of the ``feedback:`` section as a law: the A/L of each new state to a speed (held while
    the flag is lost in more than ``max_lost_fraction`` of the cycle's updates). Its bounds and its
    largest step (``max_step_mps`` per ``period_s``, scaled to the time between states) are its own,
    inside the tunnel's."""

    def __init__(self, cfg: FeedbackConfig) -> None:
        self.cfg = cfg
        self.setpoint = cfg.target_amplitude_over_l
        self._state = ControllerState(0.0, cfg.start_speed_mps)
        self._last_t_s: float | None = None

    def __call__(self, state: FlagState) -> float | None:
        if self._last_t_s is not None and state.t_s <= self._last_t_s:
            return None  # nothing new measured
        dt_s = self.cfg.period_s if self._last_t_s is None else state.t_s - self._last_t_s
        self._last_t_s = state.t_s
        amplitude = state.amplitude_over_l if state.amplitude_over_l >= 0 else math.nan
        lost = state.lost_fraction if state.lost_fraction >= 0 else math.nan
        cfg = replace(self.cfg, max_step_mps=self.cfg.max_step_mps * dt_s / self.cfg.period_s)
        self._state = control_step(self._state, measured_amplitude(amplitude, lost, cfg), dt_s, cfg)
        return self._state.speed_mps
