"""The supervisor's work against the tunnel that does it: every speed it asks for within the tunnel's
bounds, and how long a sweep takes and how much disk it needs.

Checked before the tunnel is opened (the supervisor's check of the service table), so a plan the
tunnel would refuse halfway through stops the rig before it starts.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

from flagtrack.daemon.errors import ConfigError
from flagtrack.daemon.rig.findings import Findings
from flagtrack.daemon.rig.host import free_bytes, size_text
from flagtrack.daemon.rig.sections import RigSections
from flagtrack.daemon.sweep.plan import SweepConfig, plan_duration_s, plan_points
from flagtrack.daemon.sweep.validity import expected_point_bytes, free_space_problem
from flagtrack.drivers.tunnel.setup import TunnelConfig


@dataclass(frozen=True)
class PlanEstimate:
    """What a sweep plan amounts to.

    Attributes:
        points: measurement points.
        lowest_mps, highest_mps: the plan's speed range, m/s.
        branches: the branches in order (``up``, ``down``).
        duration_s: ramps (at ``tunnel.safety.max_ramp_mps2``), settles, recordings and pauses, s;
            not the readback waits, the per-point commands or any retry.
        point_bytes: one point's recording at the expected rate, bytes.
        disk_bytes: every point's recording, bytes.
    """

    points: int
    lowest_mps: float
    highest_mps: float
    branches: tuple[str, ...]
    duration_s: float
    point_bytes: float
    disk_bytes: float


def estimate_plan(rig: RigSections) -> PlanEstimate | None:
    """The estimate of the rig's sweep plan (None without one)."""
    sweep = rig.supervisor.sweep
    if sweep is None:
        return None
    ramp_mps2 = rig.tunnel.safety.max_ramp_mps2 if rig.tunnel is not None else None
    duration_s = plan_duration_s(sweep, ramp_mps2)
    speeds = sweep.speed_values()
    supervisor = rig.supervisor
    point_bytes = expected_point_bytes(sweep.record_s, supervisor.expected_rate_mev_s, supervisor.bytes_per_event)
    points = len(plan_points(sweep))
    branches = tuple(branch.value for branch in sweep.branches)
    return PlanEstimate(points, speeds[0], speeds[-1], branches, duration_s, point_bytes, points * point_bytes)


def tunnel_refusal(tunnel: TunnelConfig, speed_mps: float) -> str | None:
    """Why the tunnel of ``tunnel`` would refuse to be set to ``speed_mps`` (None: it takes it).

    The safety layer's bounds (0 is always taken), a Modbus drive's frequency limit (its driver's own
    conversion), a simulated fan's top speed.
    """
    safety = tunnel.safety
    if speed_mps > safety.max_speed_mps:
        return f"{speed_mps:g} m/s is above tunnel.safety.max_speed_mps ({safety.max_speed_mps:g} m/s)"
    if 0 < speed_mps < safety.min_speed_mps:
        return f"{speed_mps:g} m/s is below tunnel.safety.min_speed_mps ({safety.min_speed_mps:g} m/s)"
    protocol = tunnel.sim.protocol if tunnel.driver == "simulated" else tunnel.driver
    if protocol == "modbus":
        try:
            tunnel.modbus.speed_to_counts(speed_mps)
        except ValueError as exc:
            return f"the drive refuses it: {exc} (tunnel.modbus.max_hz, mps_per_hz)"
    if tunnel.driver == "simulated" and speed_mps > tunnel.sim.max_speed_mps:
        return f"{speed_mps:g} m/s is above the simulated fan's tunnel.sim.max_speed_mps ({tunnel.sim.max_speed_mps:g} m/s)"
    return None


def check_speeds(rig: RigSections) -> None:
    """Every speed the supervisor would ask for is one the tunnel takes: the sweep plan's, and the
    feedback loop's bounds and start speed.

    Raises:
        ConfigError: naming the plan's (or loop's) key, the speed and the tunnel's bound.
    """
    tunnel, supervisor = rig.tunnel, rig.supervisor
    if tunnel is None:
        return
    if supervisor.sweep is not None:
        _refuse_any(tunnel, supervisor.sweep.speed_values(), key=_plan_key(supervisor.sweep), path=rig.path)
    if supervisor.mode == "feedback":
        feedback = supervisor.feedback
        for name in ("min_speed_mps", "start_speed_mps", "max_speed_mps"):
            _refuse_any(tunnel, [getattr(feedback, name)], key=f"supervisor.feedback.{name}", path=rig.path)


def check_disk(rig: RigSections, findings: Findings) -> None:
    """Note a run folder's disk that cannot hold one point (the sweep would stop safe before its first),
    and warn when it cannot hold them all (it would stop safe when the disk is full)."""
    estimate = estimate_plan(rig)
    free = free_bytes(rig.supervisor.runs_dir) if findings.files and estimate is not None else None
    if estimate is None or free is None:
        return
    runs_dir, margin_bytes = rig.supervisor.runs_dir, rig.supervisor.free_space_margin_mb * 1e6
    problem = free_space_problem(free, estimate.point_bytes, margin_bytes, str(runs_dir))
    if problem is not None:
        findings.later(f"no point could start: {problem}", key="supervisor.runs_dir")
    elif estimate.disk_bytes + margin_bytes > free:
        fits = int((free - margin_bytes) // estimate.point_bytes)
        findings.warn(
            f"the sweep needs about {size_text(estimate.disk_bytes)} and {runs_dir} has {size_text(free)} free: "
            f"it would stop safe after about {fits} of {estimate.points} points",
            key="supervisor.runs_dir",
        )


def _plan_key(sweep: SweepConfig) -> str:
    return "supervisor.sweep.speeds" if sweep.speeds is not None else "supervisor.sweep.range"


def _refuse_any(tunnel: TunnelConfig, speeds: Iterable[float], *, key: str, path: str | None) -> None:
    for speed_mps in speeds:
        why = tunnel_refusal(tunnel, speed_mps)
        if why is not None:
            raise ConfigError(f"the tunnel cannot run this: {why}", key=key, path=path)
