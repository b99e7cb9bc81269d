"""``flagtrack up``: run the rig's services in one process (Zenoh peer on loopback by default)."""

from __future__ import annotations

import argparse
import logging
import sys
from collections.abc import Callable
from pathlib import Path

from flagtrack.daemon.commands._tracking_args import add_tracking_arguments

COMMAND = "up"
HELP = "run the rig's services in one process (-c rig.yaml), or replay a file through them (--replay)"
DESCRIPTION = """\
Run camera, tracker, recorder and viewer (the `services:` of the rig config) in one process,
talking over Zenoh (peer mode, loopback, unless the config's `bus:` says otherwise).

  flagtrack up -c deploy/rig-sim.yaml
  flagtrack up --replay run.raw --exit-at-eof --centrelines run.h5 --rrd run.rrd --root 102 240 --length 200

With --replay, the file is played through camera adapter -> Zenoh -> tracker (same options and
results as `flagtrack reconstruct`). The first Ctrl-C stops gracefully; a second one forces.
"""

log = logging.getLogger(__name__)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``flagtrack up``."""
    parser.add_argument("-c", "--config", type=Path, help="rig config (YAML)")
    parser.add_argument("--replay", type=Path, metavar="FILE", help="replay this recording as the camera")
    parser.add_argument("--speed", type=float, default=1.0, help="replay speed factor (0: as fast as possible)")
    parser.add_argument("--loop", action="store_true", help="replay in a loop")
    parser.add_argument("--exit-at-eof", action="store_true", help="stop when the replayed file ends")
    parser.add_argument("--centrelines", type=Path, metavar="OUT.h5", help="write the centrelines to this file")
    parser.add_argument("--rrd", type=Path, metavar="OUT.rrd", help="write the Rerun view to this file (headless)")
    parser.add_argument("--record", type=Path, metavar="BASE", help="record the camera to BASE.raw (+ .json)")
    parser.add_argument("--shutdown-timeout", type=float, default=10.0, help="seconds to wait for services to stop")
    add_tracking_arguments(parser)


def run(args: argparse.Namespace) -> int:
    """Build the rig from the config and flags, run it, report."""
    rig, names = rig_from_args(args)
    return run_rig(rig, names, exit_at_end_of_stream=args.exit_at_eof, centrelines=args.centrelines,
                   shutdown_timeout_s=args.shutdown_timeout).code


def rig_from_args(args: argparse.Namespace):  # noqa: ANN201 - (RigConfig, list[str])
    """The rig config of ``-c`` with the command-line overrides applied; the services to run."""
    import dataclasses

    from flagtrack.daemon.commands._tracking_args import apply_tracking_arguments
    from flagtrack.daemon.errors import ConfigError
    from flagtrack.daemon.rig import CameraConfig, RigConfig, load_rig
    from flagtrack.drivers.camera.replay import ReplayConfig

    if args.config is None and args.replay is None:
        raise ConfigError("give a rig config (-c rig.yaml) or a recording to replay (--replay FILE)")
    # files and folders are checked by run_rig, once the flags below have changed the rig
    rig = load_rig(args.config, services=()) if args.config else RigConfig(services=("camera", "tracker"))
    names = list(rig.services)
    if args.replay is not None:
        if not args.replay.is_file():
            raise ConfigError(f"no such recording: {args.replay}", key="--replay")
        camera = CameraConfig(id=rig.camera.id, adapter="replay", packet_us=rig.camera.packet_us,
                              replay=ReplayConfig(args.replay, speed=args.speed, loop=args.loop))
        rig = dataclasses.replace(rig, camera=camera)
        for name in ("camera", "tracker"):
            if name not in names:
                names.append(name)
    rig = dataclasses.replace(rig, tracker=apply_tracking_arguments(rig.tracker, args))
    if args.rrd is not None:
        rig = dataclasses.replace(rig, viewer=dataclasses.replace(rig.viewer, sink="rrd", rrd_path=args.rrd))
        if "viewer" not in names:
            names.append("viewer")
    if args.record is not None:
        rig = dataclasses.replace(rig, recorder=dataclasses.replace(rig.recorder, path=str(args.record)))
        if "recorder" not in names:
            names.append("recorder")
    return rig, names


def run_rig(rig, names: list[str], *, exit_at_end_of_stream: bool = False, centrelines: Path | None = None,  # noqa: ANN001
            shutdown_timeout_s: float = 10.0, resume_dir: Path | None = None, quiet: bool = False,
            prepared: bool = False):  # noqa: ANN201
    """Open the bus, build and run the services until a signal, a failure or the end of the work.

    ``prepared``: the caller already ran :func:`prepare_services` (to time the run without it).

    Returns:
        A :class:`RigRun` (exit code, the services, the runner's report).
    """
    from flagtrack.daemon.config import require_output_file
    from flagtrack.daemon.rig import check_rig
    from flagtrack.daemon.services.build import build_services, open_hardware_camera, tracker_setup
    from flagtrack.daemon.services.centreline_file import CentrelineFileService
    from flagtrack.daemon.services.runner import run_services
    from flagtrack.daemon.transport import Bus

    def say(text: str) -> None:
        if not quiet:
            print(f"flagtrack up: {text}", file=sys.stderr)

    # bad config: one clear line, before anything opens (the tracker setup then serves every step)
    check_rig(rig, names)
    if centrelines is not None:
        require_output_file(centrelines, key="--centrelines", path=None)
    setup = tracker_setup(rig) if "tracker" in names else None
    if not prepared:
        prepare_services(rig, names, say, tracker=setup)
    finishers = []
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
        with Bus(rig.bus_config) as bus:
            services = build_services(rig, bus, names, exit_at_end_of_stream=exit_at_end_of_stream,
                                      resume_dir=resume_dir, tracker=setup, camera=camera)
            if centrelines is not None:
                attrs = {**rig.tracker.attrs(), "input_file": str(rig.camera.replay.path) if rig.camera.replay else ""}
                services.insert(0, CentrelineFileService(bus, centrelines, attrs,
                                                         exit_after_final=exit_at_end_of_stream))
            say(f"{', '.join(s.name for s in services)} on {rig.bus_config.namespace}")
            report = run_services(services, shutdown_timeout_s=shutdown_timeout_s, stop_when_any_finishes=finishers,
                                  on_service_end=bus.undeclare_alive)
    finally:
        if camera is not None and not camera.handed_over:
            camera.close()  # the rig failed before the camera service took it
    for name, exc in report.errors.items():
        print(f"flagtrack up: {name} failed: {exc}", file=sys.stderr)
    if report.abandoned:
        print(f"flagtrack up: did not stop in time: {', '.join(report.abandoned)}", file=sys.stderr)
    if centrelines is not None:
        say(f"centrelines in {centrelines}")
    for service in services:
        if getattr(service, "description", ""):
            say(f"viewer {service.description}")
    code = 1 if report.errors else (130 if report.signal_count else 0)
    return RigRun(code, services, report)


def prepare_services(rig, names: list[str], say: Callable[[str], None] = lambda text: None,  # noqa: ANN001
                     *, tracker=None) -> None:  # noqa: ANN001
    """Do the slow one-off work of the services before they start, while nothing runs in real time
    (``say`` tells the user when that includes loading or compiling kernels; ``tracker``: the rig's
    tracker setup, if the caller already made it).

    - Compile (first run after installing: about a minute) or load the compiled kernels of the twin
      camera, the packets and the tracker: services that share this process would otherwise compile
      together, and the supervisor would not see the tracker come up within its start-up timeout
      (hardware cameras are not opened here).
    - A supervisor imports matplotlib (about a second, holding the GIL): drawing the summary figure
      at the end of a sweep would otherwise stall the twin camera of the same process.
    """
    from flagtrack.daemon.errors import FlagtrackError
    from flagtrack.daemon.services.build import open_camera, tracker_setup
    from flagtrack.daemon.services.tracker import warm_up_kernels
    from flagtrack.daemon.sweep.summary import load_figure_modules
    from flagtrack.drivers.camera.simulated import fast_forward

    twin = "camera" in names and rig.camera.adapter == "simulated"
    if twin or "tracker" in names:
        say("loading the compiled kernels (the first run after installing compiles them: about a minute)")
    try:
        if twin:
            fast_forward(open_camera(rig.camera), 0.05)
        if "tracker" in names:
            warm_up_kernels((tracker or tracker_setup(rig)).factory)
        if "supervisor" in names:
            load_figure_modules()
    except FlagtrackError:
        raise
    except Exception as exc:  # a failed compile or import: one line, as the services' own failures are
        raise FlagtrackError(f"preparing the services failed ({type(exc).__name__}: {exc})") from exc


class RigRun:
    """How a run of the rig ended: exit code, the services (to read their results), the report."""

    def __init__(self, code: int, services: list, report) -> None:  # noqa: ANN001
        self.code, self.services, self.report = code, services, report

    def service(self, name: str):  # noqa: ANN201
        """The service called ``name`` (or None)."""
        return next((s for s in self.services if s.name == name), None)
