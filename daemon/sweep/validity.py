"""Whether a point is measured as planned: the tunnel throughout settle and record, the recording,
the free space before it starts. Pure checks (the sweep runner gathers what they look at)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from flagtrack.daemon.errors import FlagtrackError
from flagtrack.daemon.schema import RecorderStatus
from flagtrack.daemon.sweep.plan import Point
from flagtrack.daemon.sweep.runlog import PointResult
from flagtrack.drivers.tunnel.base import TunnelStatus


class BadPoint(FlagtrackError):
    """A point was not measured as planned; ``result`` is its record (status ``failed`` or ``lossy``);
    ``stop``: measuring it again is pointless (the disk is full), the sweep stops safe."""

    def __init__(self, result: PointResult, stop: bool = False) -> None:
        self.result = result
        self.stop = stop
        super().__init__(f"point {result.point_id} {result.status}: {result.reason}")


@dataclass
class TunnelWatch:
    """Watches the tunnel's status during one point; a problem must last ``grace_s`` to count.

    Args:
        setpoint_mps: the point's speed, m/s.
        tolerance_mps: the readback must stay within this of the set-point, m/s.
        grace_s: how long a readback out of tolerance or a silent link is borne, s (0: not at all);
            a fault reported by the controller counts at once.
    """

    setpoint_mps: float
    tolerance_mps: float
    grace_s: float
    since_s: float | None = None

    def check(self, speed_mps: float, fault: str | None, link_ok: bool, now_s: float) -> str | None:
        """The reason the point is bad given one status read at ``now_s`` (monotonic s), or None."""
        problem = tunnel_problem(speed_mps, fault, link_ok, self.setpoint_mps, self.tolerance_mps)
        if problem is None:
            self.since_s = None
            return None
        if not link_ok or speed_mps != speed_mps or fault is None:  # silence or drift: after the grace
            self.since_s = now_s if self.since_s is None else self.since_s
            if now_s - self.since_s < self.grace_s:
                return None
        return problem


class PointWatch:
    """The point under way: its tunnel watch (from its speed set to the end of its recording), the
    readbacks while it records, the first problem seen since the last :meth:`check`.

    Attributes:
        point: the point.
        tunnel: the tunnel watch, None outside the point's settle and record.
        readbacks: the tunnel's readbacks while the point records (None when it does not), m/s.
    """

    def __init__(self, point: Point) -> None:
        self.point = point
        self.tunnel: TunnelWatch | None = None
        self.readbacks: list[float] | None = None
        self._problem: str | None = None

    @property
    def recording(self) -> bool:
        """Whether the point's recording is under way."""
        return self.readbacks is not None

    def see(self, status: TunnelStatus, now_s: float) -> None:
        """Take one tunnel status read at ``now_s`` (monotonic s)."""
        if self.readbacks is not None:
            self.readbacks.append(status.speed_mps)
        if self.tunnel is not None and self._problem is None:
            self._problem = self.tunnel.check(status.speed_mps, status.fault, status.link_ok, now_s)

    def check(self, recorder_error: str) -> None:
        """Raise BadPoint if the point is spoilt: the recorder failed while it records (the sweep
        stops), or the tunnel went silent, faulted or left its tolerance."""
        if recorder_error and self.readbacks is not None:
            reason = f"recorder: {recorder_error}"
            raise BadPoint(PointResult.planned(self.point, status="failed", reason=reason), stop=True)
        if self._problem:
            reason, self._problem = self._problem, None
            raise BadPoint(PointResult.planned(self.point, status="failed", reason=reason))


def tunnel_problem(
    speed_mps: float, fault: str | None, link_ok: bool, setpoint_mps: float, tolerance_mps: float
) -> str | None:
    """Why one tunnel status spoils a point at ``setpoint_mps`` (silent, faulted, out of tolerance), or None."""
    if not link_ok or not math.isfinite(speed_mps):
        return f"tunnel silent ({fault or 'no readback'})"
    if fault:
        return f"tunnel fault: {fault}"
    if abs(speed_mps - setpoint_mps) > tolerance_mps:
        return (
            f"tunnel left its tolerance: readback {speed_mps:.2f} m/s, set-point {setpoint_mps:.2f} "
            f"± {tolerance_mps:g} m/s"
        )
    return None


def recording_problem(started: RecorderStatus | None, stopped: RecorderStatus | None) -> str | None:
    """Why a recording is lossy from the recorder's replies to start and stop, or None.

    Counts packets missing in the camera's sequence (those the recorder's full queue dropped are
    among them, and said apart), packets turned away as malformed, and what the camera itself
    reported lost while it recorded (a full host ring, a cleared backlog, a simulated camera's skip
    ahead), with the reason.
    """
    if stopped is None:
        return None
    dropped = max(0, stopped.dropped_packets - (started.dropped_packets if started is not None else 0))
    missing = max(stopped.missing_packets, dropped)
    parts = []
    if missing:
        queue = f", {dropped} of them dropped by the recorder's full queue" if dropped else ""
        parts.append(f"{missing} missing in sequence{queue}")
    if stopped.malformed_packets:
        parts.append(f"{stopped.malformed_packets} malformed")
    reasons = [f"recording lost packets ({'; '.join(parts)})"] if parts else []
    if stopped.device_drops:
        what = stopped.device_drop_reason or "no reason given"
        reasons.append(f"the camera dropped data {stopped.device_drops} time(s) while recording: {what}")
    return "; ".join(reasons) or None


def expected_point_bytes(
    record_s: float, rate_mev_s: float, bytes_per_event: float, measured_bytes_per_s: float = 0.0
) -> float:
    """Bytes a point of ``record_s`` seconds is expected to write: the larger of the configured rate
    (Mev/s x bytes per event) and the largest rate measured on this run's points (bytes/s)."""
    return record_s * max(rate_mev_s * 1e6 * bytes_per_event, measured_bytes_per_s)


def free_space_problem(free_bytes: int, need_bytes: float, margin_bytes: float, where: str) -> str | None:
    """Why a point cannot start for lack of disk space on ``where``, or None."""
    if free_bytes >= need_bytes + margin_bytes:
        return None
    return (
        f"not enough free space on {where}: {free_bytes / 1e6:.1f} MB free, the point needs "
        f"{need_bytes / 1e6:.1f} MB plus a margin of {margin_bytes / 1e6:.0f} MB"
    )
