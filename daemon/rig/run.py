"""Run a rig: open the bus, build the services it asks for, start them all, run them until a signal,
a failure or the end of the work, and report how the run ended."""

from __future__ import annotations

import math
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any

from flagtrack.daemon.rig.build import build_services, open_hardware_camera
from flagtrack.daemon.rig.config import RigConfig, check_endpoints, check_rig
from flagtrack.daemon.rig.findings import Findings
from flagtrack.daemon.rig.prepare import prepare_services
from flagtrack.daemon.rig.table import in_table_order
from flagtrack.daemon.services.centreline_file import CentrelineFileService
from flagtrack.daemon.services.runner import (
    CLEAR_LINE,
    RunReport,
    Service,
    StopEvent,
    is_terminal,
    run_services,
    stop_on_signals,
)
from flagtrack.daemon.tracking.setup import processing_attrs, tracking_setup
from flagtrack.daemon.transport import Bus
from flagtrack.daemon.typed_yaml import require_output_file

__all__ = ["RigRun", "prepare_services", "run_rig"]

if TYPE_CHECKING:
    from flagtrack.daemon.schema import SupervisorState


def run_rig(
    rig: RigConfig,
    names: list[str],
    *,
    exit_at_end_of_stream: bool = False,
    centrelines: Path | None = None,
    shutdown_timeout_s: float = 10.0,
    resume_dir: Path | None = None,
    quiet: bool = False,
    prepared: bool = False,
    on_supervisor_state: Callable[[SupervisorState], None] | None = None,
    on_services: Callable[[Sequence[Service]], None] | None = None,
    command: str = "up",
) -> RigRun:
    """Open the bus, build the services, start them (in table order) and run them until a signal, a
    failure or the end of the work.

    ``prepared``: the caller already ran :func:`prepare_services` (to time the run without it).
    ``on_supervisor_state``: called with every state the supervisor publishes, in its thread (a
    command draws the sweep's progress with it; see ``SupervisorService.add_observer``).
    ``on_services``: called with the services once they are built, before they start (a command
    watches the recorder's file with it).
    ``command``: the command running the rig, named in the lines it prints (``flagtrack up: ...``).

    Returns:
        A :class:`RigRun` (exit code, the services, the runner's report).

    Raises:
        ConfigError: the rig, or a setting the hardware camera refuses (key and rig file named).
        StartError: a service could not start (those started before it were closed; none ran).
    """

    def say(text: str) -> None:
        if not quiet:  # (on a terminal, over the status line a command may draw in place)
            print(f"{CLEAR_LINE * is_terminal(sys.stderr)}flagtrack {command}: {text}", file=sys.stderr)

    # bad config: one clear line, before anything opens (the tracker setup then serves every step)
    check_rig(rig, names)
    check_endpoints(rig, Findings())
    if centrelines is not None:
        require_output_file(centrelines, key="--centrelines", path=None)
    setup = tracking_setup(rig.tracker, path=rig.path) if "tracker" in names else None
    if not prepared:  # a compile may take a while: Ctrl-C ends the run after it, never inside it
        with stop_on_signals(StopEvent()) as stop:
            prepare_services(rig, names, say, tracker=setup)
        if stop.is_set():
            say(f"{stop.reason} before the services started")
            return RigRun(130, [], RunReport(signal_count=1))
    finishers = [spec.name for spec in in_table_order(names) if spec.finishes is not None and spec.finishes(rig)]
    shutdown_timeout_s = _stop_time_s(rig, names, shutdown_timeout_s, say)
    # a hardware camera opens first: what only the device can refuse stops the rig before anything else opens
    camera = open_hardware_camera(rig) if "camera" in names else None
    try:
        with Bus(rig.bus_config_for(names)) as bus:
            services = build_services(
                rig,
                bus,
                names,
                exit_at_end_of_stream=exit_at_end_of_stream,
                resume_dir=resume_dir,
                tracker=setup,
                camera=camera,
            )
            if on_supervisor_state is not None:
                from flagtrack.daemon.services.supervisor.service import SupervisorService  # (SciPy: when asked)

                for service in services:
                    if isinstance(service, SupervisorService):
                        service.add_observer(on_supervisor_state)
            if centrelines is not None:
                made_by = setup.attrs if setup is not None else processing_attrs(rig.tracker)
                attrs = {**made_by, "input_file": str(rig.camera.replay.path) if rig.camera.replay else ""}
                if rig.camera.replay:  # the sensor's size, as the replayed file's header gives it
                    from flagtrack.drivers.formats import open_events

                    with open_events(rig.camera.replay.path) as reader:
                        attrs.update(sensor_width_px=reader.info.width, sensor_height_px=reader.info.height)
                services.insert(
                    0, CentrelineFileService(bus, centrelines, attrs, exit_after_final=exit_at_end_of_stream)
                )
            say(f"{', '.join(s.name for s in services)} on {rig.bus_config.namespace}")
            if on_services is not None:
                on_services(services)
            report = run_services(
                services,
                shutdown_timeout_s=shutdown_timeout_s,
                stop_when_any_finishes=finishers,
                on_force=partial(_tunnel_left_running, services),
                on_service_end=bus.undeclare_alive,
            )
    finally:
        if camera is not None and not camera.handed_over:
            camera.close()  # the rig failed before the camera service took it
    _report_end(report, services, centrelines, say, command)
    code = 1 if report.errors else (130 if report.signal_count else 0)
    return RigRun(code, services, report)


def _tunnel_left_running(services: Sequence[Service]) -> str:
    """On a forced exit: the line saying a tunnel was left running and what stops it ("" if none)."""
    for service in services:
        tunnel = getattr(service, "tunnel", None)
        setpoint_mps = getattr(tunnel, "setpoint_mps", 0.0)
        if tunnel is not None and setpoint_mps > 0:  # (NaN: never commanded by this run)
            watchdog_s = getattr(getattr(tunnel, "params", None), "watchdog_s", math.nan)
            return (
                f"flagtrack: the tunnel was not ramped down (last set-point {setpoint_mps:g} m/s): with the "
                f"keep-alive gone, the controller's watchdog ({watchdog_s:g} s) must stop the fan; check it"
            )
    return ""


def _stop_time_s(rig: RigConfig, names: Sequence[str], timeout_s: float, say: Callable[[str], None]) -> float:
    """The shutdown timeout: ``timeout_s``, or longer if a service's stop takes longer (the supervisor
    ramps the tunnel to zero in full)."""
    for spec in in_table_order(names):
        stop_s = spec.stop_s(rig) if spec.stop_s is not None else 0.0
        if stop_s > timeout_s:
            say(f"shutdown may take up to {stop_s:.0f} s (the time the {spec.name} takes to stop)")
            timeout_s = stop_s
    return timeout_s


def _report_end(
    report: RunReport, services: list[Service], centrelines: Path | None, say: Callable[[str], None], command: str
) -> None:
    """Failures and stragglers always, on stderr; where the outputs are unless quiet (``say``)."""
    for name, exc in report.errors.items():
        print(f"flagtrack {command}: {name} failed: {exc}", file=sys.stderr)
    if report.abandoned:
        print(f"flagtrack {command}: did not stop in time: {', '.join(report.abandoned)}", file=sys.stderr)
    if centrelines is not None:
        say(f"centrelines in {centrelines}")
    for service in services:
        end_line = getattr(service, "end_line", None)
        if end_line is not None and (line := end_line()):
            say(line)


@dataclass(frozen=True)
class RigRun:
    """How a run of the rig ended: exit code, the services (to read their results), the report."""

    code: int
    services: list[Service]
    report: RunReport

    def service(self, name: str) -> Any:
        """The service called ``name`` (or None)."""
        return next((s for s in self.services if s.name == name), None)
