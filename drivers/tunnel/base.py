"""The wind-tunnel interfaces.

Two layers, so that safety is written once:

- :class:`TunnelLink` is what a protocol driver implements: it only turns requests into bytes and
  replies into numbers (ASCII fan controller, Modbus RTU drive). It does no ramping, no checks.
- :class:`WindTunnel` is what the rest of flagtrack calls: set-points are bounded, ramped and
  verified, and the link is kept alive. :class:`flagtrack.drivers.tunnel.safe.SafeTunnel` turns any
  link into a wind tunnel.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol


@dataclass(frozen=True)
class TunnelStatus:
    """A snapshot of a tunnel, for logs and the supervisor.

    Attributes:
        device: port or name of the controller (``/dev/ttyUSB0``).
        setpoint_mps: last set-point sent to the controller, m/s.
        speed_mps: speed read back from the controller, m/s (``nan`` when the read failed).
        fault: fault reported by the controller or by the link, ``None`` when healthy.
        link_ok: the last exchange with the controller succeeded.
        keepalive_failures: keep-alive exchanges that failed since the tunnel was opened.
    """

    device: str
    setpoint_mps: float
    speed_mps: float
    fault: str | None
    link_ok: bool
    keepalive_failures: int = 0


class WindTunnel(Protocol):
    """A wind tunnel whose speed flagtrack controls (ramped, bounded, verified)."""

    def set_speed_mps(self, speed_mps: float) -> None:
        """Ramp to ``speed_mps`` and return once the readback is there; DriverError otherwise."""
        ...

    def read_speed_mps(self) -> float:
        """Return the speed read back from the controller, m/s."""
        ...

    def safe_stop(self) -> None:
        """Ramp to zero and stop the fan; never leaves the tunnel running if it still answers."""
        ...

    def status(self) -> TunnelStatus:
        """Return the current status (reads the controller)."""
        ...

    def close(self) -> None:
        """Release the port (does not change the speed; call :meth:`safe_stop` first)."""
        ...


class TunnelLink(Protocol):
    """The bytes-level side of one controller: each method is one exchange, no ramping.

    Every method raises :class:`flagtrack.daemon.errors.DriverError` naming :attr:`device` when
    the controller does not answer, answers an error, or answers something unexpected.
    """

    device: str

    def write_setpoint_mps(self, speed_mps: float) -> None:
        """Send one set-point (and start the fan if it is stopped and ``speed_mps > 0``)."""
        ...

    def read_speed_mps(self) -> float:
        """Read the actual speed, m/s."""
        ...

    def stop(self) -> None:
        """Command the fan to stop (set-point zero, drive stopped)."""
        ...

    def keep_alive(self) -> None:
        """One harmless exchange that resets the controller's communication watchdog."""
        ...

    def read_fault(self) -> str | None:
        """Return the controller's fault text, ``None`` when there is none (or it cannot tell)."""
        ...

    def close(self) -> None:
        """Close the port."""
        ...
