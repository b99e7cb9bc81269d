"""Run a rig: open the bus, build the services it asks for, run them until a signal, a failure
or the end of the work, and report how the run ended."""

from __future__ import annotations

import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from flagtrack.daemon.errors import FlagtrackError
from flagtrack.daemon.rig.build import build_services, open_camera, open_hardware_camera
from flagtrack.daemon.rig.config import RigConfig, check_rig
from flagtrack.daemon.services.centreline_file import CentrelineFileService
from flagtrack.daemon.services.runner import RunReport, Service, run_services
from flagtrack.daemon.services.tracker import warm_up_kernels
from flagtrack.daemon.sweep import figures
from flagtrack.daemon.tracking.setup import TrackingSetup, processing_attrs, tracking_setup
from flagtrack.daemon.transport import Bus
from flagtrack.daemon.typed_yaml import require_output_file
from flagtrack.drivers.camera.simulated import fast_forward

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
) -> RigRun:
    """Open the bus, build and run the services until a signal, a failure or the end of the work.

    ``prepared``: the caller already ran :func:`prepare_services` (to time the run without it).
    ``on_supervisor_state``: called with every state the supervisor publishes, in its thread (a
    command draws the sweep's progress with it; see ``SupervisorService.add_observer``).

    Returns:
        A :class:`RigRun` (exit code, the services, the runner's report).
    """

    def say(text: str) -> None:
        if not quiet:
            print(f"flagtrack up: {text}", file=sys.stderr)

    # bad config: one clear line, before anything opens (the tracker setup then serves every step)
    check_rig(rig, names)
    if centrelines is not None:
        require_output_file(centrelines, key="--centrelines", path=None)
    setup = tracking_setup(rig.tracker, path=rig.path) if "tracker" in names else None
    if not prepared:
        prepare_services(rig, names, say, tracker=setup)
    finishers: list[str] = []
    if "supervisor" in names and rig.supervisor.mode != "monitor" and rig.supervisor.exit_when_done:
        finishers.append("supervisor")
    if "supervisor" in names and rig.tunnel is not None:  # let a stop ramp the tunnel to zero in full
        safety = rig.tunnel.safety
        ramp_s = safety.max_speed_mps / safety.max_ramp_mps2 + safety.settle_timeout_s + 5.0
        if ramp_s > shutdown_timeout_s:
            say(f"shutdown may take up to {ramp_s:.0f} s (the tunnel ramps down first)")
            shutdown_timeout_s = ramp_s
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
            report = run_services(
                services,
                shutdown_timeout_s=shutdown_timeout_s,
                stop_when_any_finishes=finishers,
                on_service_end=bus.undeclare_alive,
            )
    finally:
        if camera is not None and not camera.handed_over:
            camera.close()  # the rig failed before the camera service took it
    _report_end(report, services, centrelines, say)
    code = 1 if report.errors else (130 if report.signal_count else 0)
    return RigRun(code, services, report)


def _report_end(
    report: RunReport, services: list[Service], centrelines: Path | None, say: Callable[[str], None]
) -> None:
    """Failures and stragglers always, on stderr; where the outputs are unless quiet (``say``)."""
    for name, exc in report.errors.items():
        print(f"flagtrack up: {name} failed: {exc}", file=sys.stderr)
    if report.abandoned:
        print(f"flagtrack up: did not stop in time: {', '.join(report.abandoned)}", file=sys.stderr)
    if centrelines is not None:
        say(f"centrelines in {centrelines}")
    for service in services:
        if getattr(service, "description", ""):
            say(f"viewer {service.description}")


def prepare_services(
    rig: RigConfig,
    names: list[str],
    say: Callable[[str], None] = lambda text: None,
    *,
    tracker: TrackingSetup | None = None,
) -> None:
    """Do the slow one-off work of the services before they start, while nothing runs in real time
    (``say`` tells the user when that includes loading or compiling kernels; ``tracker``: the rig's
    tracker setup, if the caller already made it).

    - Compile (first run after installing: about a minute) or load the compiled kernels of the twin
      camera, the packets and the tracker: services that share this process would otherwise compile
      together, and the supervisor would not see the tracker come up within its start-up timeout
      (hardware cameras are not opened here).
    - A supervisor imports matplotlib (about a second, holding the GIL): drawing the summary figure
      at the end of a sweep would otherwise stall the twin camera of the same process.
    - Trigger events (a twin with a sync generator, a point sensor that reads the raw files' pulses)
      take kernels of their own: encoding them into packets and reading them back from a file
      (compiling those on a first run took 2 s, which the twin could not make up in real time).
    """
    twin = "camera" in names and rig.camera.adapter == "simulated"
    triggers = (twin and rig.camera.simulated.trigger_period_ms > 0) or "sensor" in names
    if twin or "tracker" in names:
        say("loading the compiled kernels (the first run after installing compiles them: about a minute)")
    try:
        if twin:
            fast_forward(open_camera(rig.camera), 0.05)
        if "tracker" in names:
            warm_up_kernels((tracker or tracking_setup(rig.tracker, path=rig.path)).factory)
        if "supervisor" in names:
            figures.load_figure_modules()
        if triggers:
            _warm_up_triggers()
    except FlagtrackError:
        raise
    except Exception as exc:  # a failed compile or import: one line, as the services' own failures are
        raise FlagtrackError(f"preparing the services failed ({type(exc).__name__}: {exc})") from exc


def _warm_up_triggers() -> None:
    """Packetize a few events with trigger pulses (EVT 3.0 and 2.0), write them to a file and read the
    pulses back as a point's sensor check does, to load (or compile) the kernels of that path."""
    import tempfile

    import numpy as np

    from flagtrack.daemon.core.events import empty_triggers, make_events
    from flagtrack.daemon.validation.collect import raw_triggers
    from flagtrack.drivers.formats import write_events
    from flagtrack.drivers.formats.packets import Packetizer

    n = 200
    events = make_events(np.arange(n, dtype=np.int64) * 10, np.arange(n) % 20, np.arange(n) // 20, np.arange(n) % 2)
    triggers = empty_triggers(4)
    triggers["t"], triggers["edge"] = [100, 110, 1100, 1110], [1, 0, 1, 0]
    for encoding in ("evt3", "evt2"):
        packetizer = Packetizer(encoding, 64, 64)
        packetizer.push(events, triggers, t_until_us=5000)
        packetizer.flush()
    with tempfile.TemporaryDirectory(prefix="flagtrack-warm-up-") as folder:
        path = Path(folder) / "triggers.raw"
        write_events(path, events, width=64, height=64, encoding="evt3", triggers=triggers)
        raw_triggers(path)


@dataclass(frozen=True)
class RigRun:
    """How a run of the rig ended: exit code, the services (to read their results), the report."""

    code: int
    services: list[Service]
    report: RunReport

    def service(self, name: str) -> Any:
        """The service called ``name`` (or None)."""
        return next((s for s in self.services if s.name == name), None)
