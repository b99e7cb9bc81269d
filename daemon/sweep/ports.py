"""What a sweep run needs from outside it, as Protocols: the tunnel, the bus side, a point's
measurement, a clock. The supervisor service gives the real ones (its bus, a
:class:`~flagtrack.drivers.tunnel.safe.SafeTunnel`); tests give small fakes fed facts."""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

from flagtrack.daemon.schema import RecorderCommand, RecorderStatus
from flagtrack.daemon.sweep.plan import Point
from flagtrack.daemon.sweep.progress import SweepProgress
from flagtrack.daemon.sweep.runlog import PointResult
from flagtrack.drivers.tunnel.base import TunnelStatus


class Tunnel(Protocol):
    """The wind tunnel as the run drives it (what :class:`~flagtrack.drivers.tunnel.safe.SafeTunnel`
    offers; a ``heartbeat()`` method, when it has one, is called from the run's loop)."""

    @property
    def setpoint_mps(self) -> float:
        """Last set-point sent, m/s (NaN before start)."""
        ...

    def start(self) -> object:
        """Read the current speed and start the keep-alive."""
        ...

    def set_speed_mps(self, speed_mps: float) -> None:
        """Ramp to ``speed_mps`` and return once the readback is there; DriverError otherwise."""
        ...

    def status(self) -> TunnelStatus:
        """The current status (link errors reported, not raised)."""
        ...

    def safe_stop(self) -> None:
        """Ramp to zero and stop the fan."""
        ...

    def abort(self) -> None:
        """Make a ramp under way (and any later one) stop with an error; from any thread."""
        ...

    def close(self) -> None:
        """Release the port (commands nothing)."""
        ...


@dataclass(frozen=True)
class Report:
    """What the run is doing, for its state messages.

    Attributes:
        mode: ``monitor``, ``sweep``, ``feedback``, ``done`` or ``safe``.
        point_id, branch: the point under way ("" when none) and the last branch.
        setpoint_mps: the tunnel's set-point, m/s (NaN before start).
        stop_reason: why the run stopped ("" while it runs).
        progress: the sweep's progress (None outside a sweep).
        now_s: when (monotonic s).
    """

    mode: str
    point_id: str
    branch: str
    setpoint_mps: float
    stop_reason: str
    progress: SweepProgress | None
    now_s: float


class Outside(Protocol):
    """The bus side of a run: what arrived, the services' health, the state messages, the recorder."""

    def pump(self) -> None:
        """Take in what arrived."""
        ...

    def beat(self, mode: str) -> None:
        """Tell the service manager the run's loop is alive (in ``mode``)."""
        ...

    def publish(self, report: Report, tunnel: TunnelStatus) -> None:
        """Publish the run's state and the tunnel's."""
        ...

    def waiting_for(self) -> str | None:
        """What the run still waits for before it starts (services, a rate baseline), None when ready."""
        ...

    def watch_from_now(self) -> None:
        """The run starts: silences count from now."""
        ...

    def problem(self) -> str | None:
        """Why the run cannot go on (a required service gone, the camera silent), or None."""
        ...

    def recorder_error(self) -> str:
        """The recorder's last unprompted error ("" when none)."""
        ...

    def send(self, command: RecorderCommand) -> None:
        """Send a command to the recorder."""
        ...

    def reply(self, request_id: str) -> RecorderStatus | None:
        """Take the recorder's answer to ``request_id`` if it came."""
        ...


class PointMeasure(Protocol):
    """What a point's recording found (the flag's state, its metrics, a sensor comparison)."""

    def begin(self) -> None:
        """The point's recording has started: gather from now."""
        ...

    def end(self) -> None:
        """Stop gathering (the recording is about to stop, or it failed)."""
        ...

    def result(self, point: Point, run_dir: Path, previous_state: str) -> PointResult:
        """The point's record with what the last gathering found (``previous_state``: the state of
        the point before it, for the hysteresis band)."""
        ...


class Clock(Protocol):
    """Time for the run (monotonic and wall seconds) and its waits."""

    def monotonic(self) -> float:
        """Monotonic seconds."""
        ...

    def time(self) -> float:
        """Unix seconds."""
        ...

    def wait(self, stop: threading.Event, timeout_s: float) -> bool:
        """Wait up to ``timeout_s`` or until ``stop`` is set; return whether it is set."""
        ...


class SystemClock:
    """The process's clocks."""

    def monotonic(self) -> float:
        return time.monotonic()

    def time(self) -> float:
        return time.time()

    def wait(self, stop: threading.Event, timeout_s: float) -> bool:
        return stop.wait(timeout_s)
