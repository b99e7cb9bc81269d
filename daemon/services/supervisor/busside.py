"""The supervisor's bus as a run's :class:`~flagtrack.daemon.sweep.ports.Outside`: the monitor's
subscriptions, the supervisor and tunnel state messages (and their observers), the recorder."""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Sequence
from typing import Any

from flagtrack.daemon.schema import RecorderCommand, RecorderStatus, SupervisorState, TunnelState
from flagtrack.daemon.services.sd_notify import beat
from flagtrack.daemon.services.supervisor.monitor import BusMonitor
from flagtrack.daemon.services.supervisor.requests import SpeedDesk
from flagtrack.daemon.services.supervisor.section import SupervisorConfig
from flagtrack.daemon.sweep.ports import Report
from flagtrack.daemon.sweep.progress import SweepProgress
from flagtrack.daemon.transport import Bus
from flagtrack.drivers.tunnel.base import TunnelStatus

log = logging.getLogger(__name__)


class BusSide:
    """Publishes the run's state and reads what the monitor gathered (see the module).

    Args:
        bus: the bus.
        name: the service's name (its liveliness token and watchdog beats).
        cfg: the supervisor section.
        monitor: the supervisor's subscriptions.
        observers: called with every state published, in the run's thread; an observer that
            raises is logged once and the states keep coming.
        refusing: speed requests to answer as refused while no control loop takes them, and why.
    """

    def __init__(
        self,
        bus: Bus,
        name: str,
        cfg: SupervisorConfig,
        monitor: BusMonitor,
        observers: Sequence[Callable[[SupervisorState], None]] = (),
        refusing: tuple[SpeedDesk, str] | None = None,
    ) -> None:
        keys = bus.keys
        self.name, self.cfg, self.monitor, self.observers = name, cfg, monitor, observers
        self.refusing = refusing
        self._state_pub = bus.publisher(keys.supervisor_state())
        self._tunnel_pub = bus.publisher(keys.tunnel_state())
        self._recorder_pub = bus.publisher(keys.recorder_command(), tag_source=True)  # the recorder logs who
        self._observer_failed = False

    def pump(self) -> None:
        self.monitor.pump()
        if self.refusing is not None and not self.refusing[0].taking:
            desk, why = self.refusing
            desk.refuse_all(why)

    def beat(self, mode: str) -> None:
        beat(self.name, f"{mode}, flag {self.monitor.state.value}")

    def publish(self, report: Report, tunnel: TunnelStatus) -> None:
        m = self.monitor
        state = SupervisorState(
            m.state.value,
            float(m.rate_hz) if math.isfinite(m.rate_hz) else 0.0,
            report.mode,
            report.point_id,
            report.branch,
            float(report.setpoint_mps) if math.isfinite(report.setpoint_mps) else 0.0,
            report.stop_reason,
            **progress_fields(report.progress, report.now_s),
        )
        self._state_pub.put(state)
        self._tunnel_pub.put(
            TunnelState(
                float(tunnel.speed_mps) if math.isfinite(tunnel.speed_mps) else -1.0,
                float(tunnel.setpoint_mps) if math.isfinite(tunnel.setpoint_mps) else 0.0,
                "fault" if tunnel.fault else report.mode,
                tunnel.fault or "",
                time.time(),
            )
        )
        for observer in self.observers:
            try:
                observer(state)
            except Exception as exc:  # noqa: BLE001 - a display never stops a sweep (or its safe state)
                if not self._observer_failed:
                    log.error("supervisor: a progress observer failed (%s: %s)", type(exc).__name__, exc)
                self._observer_failed = True

    def waiting_for(self) -> str | None:
        missing = self.monitor.missing()
        if missing:
            return f"services {', '.join(missing)} did not appear"
        if self.monitor.reading is None or not math.isfinite(self.monitor.thresholds_hz()[0]):
            return "no event-rate baseline"
        return None

    def watch_from_now(self) -> None:
        self.monitor.last_rate_s = time.monotonic()

    def problem(self) -> str | None:
        return self.monitor.problem(self.cfg.silence_timeout_s)

    def recorder_error(self) -> str:
        return self.monitor.recorder_error

    def send(self, command: RecorderCommand) -> None:
        self._recorder_pub.put(command)

    def reply(self, request_id: str) -> RecorderStatus | None:
        return self.monitor.recorder_replies.pop(request_id, None)


def progress_fields(progress: SweepProgress | None, now_s: float) -> dict[str, Any]:
    """The sweep-progress fields of :class:`SupervisorState` (none outside a sweep)."""
    if progress is None:
        return {}
    fields: dict[str, Any] = {
        "point_index": progress.current_position,
        "points_total": progress.total,
        "points_done": progress.done,
        "point_records": progress.records,
        "elapsed_s": progress.elapsed_s(now_s),
        "eta_s": _known(progress.eta_s(now_s)),
    }
    last = progress.last
    if last is not None:
        fields.update(
            last_point=last.point_id,
            last_index=last.position,
            last_speed_mps=_known(last.speed_mps),
            last_branch=last.branch,
            last_state=last.state,
            last_status=last.status,
            amplitude_over_l=_known(last.amplitude_over_l),
            frequency_hz=_known(last.frequency_hz),
            lost_fraction=_known(last.lost_fraction),
            stale_fraction=_known(last.stale_fraction),
            sensor_error_rms_over_l=_known(last.sensor_error_rms_over_l),
            chain_reach=_known(last.chain_reach),
            last_suspect=last.suspect,
        )
    return fields


def _known(value: float) -> float:
    """``value``, or -1.0 when it is not a finite number (the state messages' "not known")."""
    return float(value) if math.isfinite(value) else -1.0
