"""The service table: every service a rig can run, each described once.

An entry (:class:`ServiceSpec`) says, for one service: its name (the ``services:`` entry of a rig,
the ``flagtrack <name>`` command, the identity the access-control rules give its rights to), the
rig sections it reads, the bus keys it publishes and subscribes to and the liveliness token it
declares (the access-control rules are made from these, :mod:`.access`), how it is checked (before
anything opens), prepared (slow one-off work, before anything runs) and built (constructed, opening
nothing). The runner then starts every service in table order (``start()``) before any runs, so
the listeners come before the camera: every subscription exists before the first packet.

Adding a service: its module under ``daemon/services/`` (a class with ``start`` and ``run``, see
:class:`~flagtrack.daemon.services.runner.Service`), its section in ``RigSections``, its keys in
:class:`~flagtrack.daemon.schema.Keys`, and one entry here with its build function.

This module imports only the standard library at load time (the command line lists the services
without loading them): each step imports its service's module when it runs.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from pathlib import Path

    from flagtrack.daemon.rig.context import Build, Preparation
    from flagtrack.daemon.rig.findings import Findings
    from flagtrack.daemon.rig.sections import RigSections
    from flagtrack.daemon.services.runner import Service


@dataclass(frozen=True)
class ServiceSpec:
    """One service of the table.

    Attributes:
        name: the ``services:`` entry, the command ``flagtrack <name>``, the access-control identity.
        help: the one line of that command's help.
        sections: the ``RigSections`` fields it reads (its own first).
        needs: sections that must be given for it to run (each is ``None`` when absent).
        publishes, subscribes: the :class:`~flagtrack.daemon.schema.Keys` methods of the keys it
            publishes and subscribes to, as ``name()``, ``name(camera)`` (one key per camera) or
            ``name(sensor)`` (one per point sensor).
        alive: its liveliness token's service part (``{camera}``, ``{sensor}``: one per id).
        watches: it watches every service's liveliness.
        build: constructs it (opening nothing) from :class:`~flagtrack.daemon.rig.context.Build`.
        check: what it needs of the rig that a file or a setting can say, opening and creating nothing
            (raises ``ConfigError`` naming the key and the rig file; what this host lacks goes to the
            :class:`~flagtrack.daemon.rig.findings.Findings`, which raises it when strict).
        prepare: its slow one-off work before the rig runs (kernels, imports), with
            :class:`~flagtrack.daemon.rig.context.Preparation`.
        finishes: whether its normal end ends the rig (otherwise the rig runs until stopped).
        stop_s: how long its stop may take at most (the rig waits that long before abandoning it).
    """

    name: str
    help: str
    sections: tuple[str, ...]
    build: Callable[[Build], Service]
    publishes: tuple[str, ...] = ()
    subscribes: tuple[str, ...] = ()
    alive: str = ""
    watches: bool = False
    needs: tuple[str, ...] = ()
    check: Callable[[RigSections, Findings], None] | None = None
    prepare: Callable[[Preparation], None] | None = None
    finishes: Callable[[RigSections], bool] | None = None
    stop_s: Callable[[RigSections], float] | None = None


# -- supervisor ---------------------------------------------------------------------------------


def _build_supervisor(b: Build) -> Service:
    from flagtrack.daemon.services.supervisor.service import FlagGeometry, SupervisorService  # SciPy: here only
    from flagtrack.drivers.tunnel.setup import open_tunnel

    rig, tunnel = b.rig, b.rig.tunnel
    assert tunnel is not None  # a needed section (RigConfig checks it)
    tracker = rig.tracker
    root_x, root_y = tracker.root or (0.0, 0.0)
    flag = FlagGeometry(float(tracker.length or 1.0), (float(root_x), float(root_y)), float(tracker.direction_deg))
    opener = lambda: open_tunnel(tunnel)  # noqa: E731
    tracking = b.tracking() if tracker.root is not None and tracker.length is not None else None
    return SupervisorService(
        b.bus, rig.supervisor, opener, rig.camera.id, flag, rig.snapshot(), b.resume_dir, rig.sensor, tracking
    )


def _check_supervisor(rig: RigSections, findings: Findings) -> None:
    """The tunnel it drives, every speed it would ask for, the services it waits for, its run folder."""
    from flagtrack.daemon.errors import ConfigError
    from flagtrack.daemon.rig.host import check_port
    from flagtrack.daemon.rig.plan import check_disk, check_speeds
    from flagtrack.daemon.typed_yaml import require_folder

    if rig.tunnel is None:  # `flagtrack sweep -c` adds the supervisor to a rig's services
        raise ConfigError("the supervisor needs a 'tunnel:' section (driver: simulated for no hardware)", path=rig.path)
    from flagtrack.daemon.services.supervisor.monitor import SERVICE_KEYS

    unknown = [name for name in rig.supervisor.required if name not in SERVICE_KEYS]
    if unknown:
        known = ", ".join(SERVICE_KEYS)
        raise ConfigError(f"unknown service {unknown[0]!r} (known: {known})", key="supervisor.required", path=rig.path)
    check_speeds(rig)
    if rig.tunnel.driver != "simulated":
        check_port(rig.tunnel.port, key="tunnel.port", what="the tunnel's controller", findings=findings)
    if findings.files:
        require_folder(rig.supervisor.runs_dir, key="supervisor.runs_dir", path=rig.path)
        check_disk(rig, findings)
    controller = rig.supervisor.control.controller
    if rig.supervisor.mode == "control" and controller is not None and controller != "pi" and findings.files:
        from flagtrack.daemon.services.supervisor.laws import law_file

        law_file(controller, key="supervisor.control.controller", path=rig.path)


def _prepare_supervisor(_p: Preparation) -> None:
    from flagtrack.daemon.sweep import figures

    figures.load_figure_modules()  # the summary figure would otherwise stall a twin camera at the end


def _supervisor_finishes(rig: RigSections) -> bool:
    return rig.supervisor.mode != "monitor" and rig.supervisor.exit_when_done


def _supervisor_stop_s(rig: RigSections) -> float:
    """The tunnel ramps to zero before the supervisor ends: its whole ramp and settling."""
    if rig.tunnel is None:
        return 0.0
    safety = rig.tunnel.safety
    return safety.max_speed_mps / safety.max_ramp_mps2 + safety.settle_timeout_s + 5.0


# -- recorder ------------------------------------------------------------------------------------


def _build_recorder(b: Build) -> Service:
    from dataclasses import replace

    from flagtrack.daemon.services.recorder import RecorderService

    rig = b.rig
    cfg = replace(  # commands may name recordings in its folder and where the sweep's points go
        rig.recorder,
        camera_id=rig.camera.id,
        allowed_dirs=(*rig.recorder.allowed_dirs, rig.supervisor.runs_dir, *([b.resume_dir] if b.resume_dir else [])),
    )
    return RecorderService(
        b.bus,
        cfg,
        rig.snapshot(),
        centreline_attrs=b.centreline_attrs(),
        exit_at_end_of_stream=b.exit_at_end_of_stream,
    )


def _check_recorder(rig: RigSections, findings: Findings) -> None:
    from flagtrack.daemon.services.recorder import recording_base
    from flagtrack.daemon.typed_yaml import require_folder

    _check_calibration(rig, findings)  # its files name the calibration
    if not findings.files:
        return
    require_folder(rig.recorder.directory, key="recorder.directory", path=rig.path)
    if rig.recorder.path:
        base = recording_base(rig.recorder.directory, rig.recorder.path)
        require_folder(base.parent, key="recorder.path", path=rig.path)


# -- tracker -------------------------------------------------------------------------------------


def _build_tracker(b: Build) -> Service:
    from dataclasses import replace

    from flagtrack.daemon.services.tracker import TrackerService

    rig, setup = b.rig, b.tracking()
    exit_at_end = b.exit_at_end_of_stream or rig.tracker_service.exit_at_end_of_stream
    cfg = replace(rig.tracker_service, camera_id=rig.camera.id, exit_at_end_of_stream=exit_at_end)
    replay = rig.camera.replay if rig.camera.adapter == "replay" else None
    as_fast_as_possible = replay is not None and replay.speed == 0  # no camera's real time to keep up with
    max_lag_ms = None if as_fast_as_possible else rig.tracker.max_lag_ms
    return TrackerService(b.bus, cfg, setup.factory, setup.units, max_lag_ms=max_lag_ms)


def _check_calibration(rig: RigSections, findings: Findings) -> None:
    """The calibration file: the first day makes it (``flagtrack calibrate -o``), so one not made yet is
    pending; one that is there must be a calibration."""
    from flagtrack.daemon.typed_yaml import require_file

    calibration = rig.tracker.calibration
    if calibration is None or not findings.files:
        return
    try:
        missing = not calibration.exists()
    except OSError:  # a folder on the way that may not be searched: require_file says so
        missing = False
    if missing:
        findings.note(
            f"{calibration} is not made yet: flagtrack calibrate BOARD.raw --board NxM --square-mm S -o "
            f"{calibration} (docs/calibration.md); the rig's commands refuse to start without it",
            key="tracker.calibration",
            path=rig.path,
            error=f"no such file: {calibration}",
        )
        return
    require_file(calibration, key="tracker.calibration", path=rig.path)
    if findings.strict:  # the tracker loads it itself, right after the checks
        return
    from flagtrack.calibration.calfile import load_mapping
    from flagtrack.daemon.errors import ConfigError, FormatError

    try:
        load_mapping(calibration)
    except FormatError as exc:
        raise ConfigError(str(exc), key="tracker.calibration", path=rig.path) from None


def _check_tracker(rig: RigSections, findings: Findings) -> None:
    """Its calibration, and (config check: strict, the rig sets the tracker up itself right after the
    checks) the ``tracker:`` section as the tracker will build it: root, length, ranges."""
    _check_calibration(rig, findings)
    if not findings.strict:
        rig.tracker.tracker_params(path=rig.path)
    sensor = _known_sensor(rig) if findings.files else None
    if sensor is not None:  # (a hardware camera's: when up opens it)
        from flagtrack.daemon.tracking.setup import refuse_tracker_off_sensor

        width, height, whose = sensor
        refuse_tracker_off_sensor(rig.tracker, width, height, sensor=whose, path=rig.path)


def _known_sensor(rig: RigSections) -> tuple[int, int, str] | None:
    """(width, height, whose) of the sensor a simulated or replay camera has, None where unknown."""
    camera = rig.camera
    if camera.adapter == "simulated":
        return camera.simulated.width, camera.simulated.height, "the simulated camera (camera.simulated)"
    if camera.adapter == "replay" and camera.replay is not None and Path(camera.replay.path).is_file():
        from flagtrack.daemon.errors import FlagtrackError
        from flagtrack.drivers.formats.files import open_events

        try:
            with open_events(camera.replay.path) as reader:
                width, height = reader.info.width, reader.info.height
            if width and height:
                return width, height, f"the recording {camera.replay.path}"
        except FlagtrackError:  # (config check says so under camera.replay.path)
            return None
    return None


def _prepare_tracker(p: Preparation) -> None:
    from flagtrack.daemon.services.tracker import warm_up_kernels

    p.loading_kernels()
    warm_up_kernels(p.tracking().factory)


# -- viewer --------------------------------------------------------------------------------------


def _build_viewer(b: Build) -> Service:
    from dataclasses import replace

    from flagtrack.daemon.services.viewer import ViewerService  # rerun: only where a viewer runs

    cfg = replace(b.rig.viewer, camera_id=b.rig.camera.id)
    return ViewerService(b.bus, cfg, exit_after_final=b.exit_at_end_of_stream)


def _check_viewer(rig: RigSections, findings: Findings) -> None:
    from flagtrack.daemon.rig.sections import viewer_writes_file
    from flagtrack.daemon.typed_yaml import require_output_file

    if findings.files and viewer_writes_file(rig.viewer):
        require_output_file(rig.viewer.rrd_path, key="viewer.rrd_path", path=rig.path)


# -- point sensor --------------------------------------------------------------------------------


def _build_sensor(b: Build) -> Service:
    from flagtrack.daemon.errors import ConfigError
    from flagtrack.daemon.services.sensor import SensorService
    from flagtrack.drivers.sensor.setup import open_sensor

    rig, cfg = b.rig, b.rig.sensor
    assert cfg is not None  # a needed section (RigConfig checks it)
    camera = b.camera_adapter() if "camera" in b.names else None
    if cfg.driver == "simulated" and not hasattr(camera, "truth"):
        raise ConfigError(
            "the simulated sensor reads the simulated camera's flag: run the camera (adapter "
            "'simulated') in the same process",
            key="sensor.driver",
            path=rig.path,
        )
    return SensorService(b.bus, cfg, lambda: open_sensor(cfg, camera, rig.path))


def _check_sensor(rig: RigSections, findings: Findings) -> None:
    from flagtrack.daemon.rig.host import check_port

    if rig.sensor is not None and rig.sensor.driver != "simulated":
        check_port(rig.sensor.port, key="sensor.port", what="the sensor", findings=findings)


def _prepare_sensor(p: Preparation) -> None:
    p.warm_up_triggers()  # a point's sensor check reads the pulses of its raw file


# -- camera --------------------------------------------------------------------------------------


def _build_camera(b: Build) -> Service:
    from flagtrack.daemon.services.camera import CameraService

    return CameraService(b.bus, b.rig.camera, b.camera_adapter())


def _check_camera(rig: RigSections, findings: Findings) -> None:
    import importlib

    from flagtrack.daemon.rig.host import sdk_missing
    from flagtrack.daemon.rig.sections import HARDWARE_ADAPTERS
    from flagtrack.daemon.typed_yaml import require_file

    camera = rig.camera
    if camera.adapter == "replay" and camera.replay is not None and findings.files:
        require_file(camera.replay.path, key="camera.replay.path", path=rig.path)
        _check_recording(camera.replay.path, rig.path)  # (its header: before any service starts)
    if camera.adapter in HARDWARE_ADAPTERS:  # what only the device can say: when up opens it, first
        from flagtrack.daemon.rig.camera_auto import resolve_auto

        adapter = importlib.import_module(f"flagtrack.drivers.camera.{camera.adapter}")
        adapter.check_config(resolve_auto(rig).hardware, path=rig.path)
        missing = sdk_missing(camera.adapter) if findings.files else None
        if missing is not None:
            findings.later(f"{missing} is not installed here: {adapter.INSTALL_HINT}", key="camera.adapter")


def _check_recording(recording: Path, path: str | None) -> None:
    from flagtrack.daemon.errors import ConfigError, FormatError
    from flagtrack.drivers.formats.files import open_events

    try:
        with open_events(recording):
            pass
    except FormatError as exc:
        raise ConfigError(str(exc), key="camera.replay.path", path=path) from None


def _prepare_camera(p: Preparation) -> None:
    from flagtrack.daemon.rig.sections import HARDWARE_ADAPTERS

    camera = p.rig.camera
    if camera.adapter in HARDWARE_ADAPTERS:  # not opened here: its packets' kernels, before it streams
        from flagtrack.daemon.services.camera import load_packet_kernels

        load_packet_kernels()  # (0.3 s; 5 s on the first run after installing: no message)
        return
    if camera.adapter != "simulated":
        return  # a replay: its clock starts at its first read
    from flagtrack.drivers.camera.simulated import fast_forward

    p.loading_kernels()
    fast_forward(p.twin(), 0.05)  # the twin's kernels and the packets'
    if camera.simulated.trigger_period_ms > 0:
        p.warm_up_triggers()


# -- flag state ----------------------------------------------------------------------------------


def _build_flagstate(b: Build) -> Service:
    from flagtrack.daemon.services.flagstate import FlagStateService

    rig = b.rig
    tracker = rig.tracker
    root_x, root_y = tracker.root or (0.0, 0.0)
    params = rig.flag_state.params(
        float(tracker.length or 1.0), (float(root_x), float(root_y)), float(tracker.direction_deg)
    )
    return FlagStateService(b.bus, params, rig.camera.id)


# -- the table -----------------------------------------------------------------------------------

SERVICES: tuple[ServiceSpec, ...] = (
    ServiceSpec(
        "supervisor",
        "run the supervisor alone: tunnel, flag state from event rates, sweeps, feedback or control",
        sections=("supervisor", "tunnel", "tracker", "sensor"),
        needs=("tunnel",),
        publishes=("supervisor_state()", "tunnel_state()", "recorder_command()", "speed_reply()"),
        subscribes=(
            "event_rate(camera)",
            "centrelines()",
            "recorder_status()",
            "tunnel_command()",
            "sensor_samples(sensor)",
            "flag_state()",
            "speed_requests()",
        ),
        alive="supervisor",
        watches=True,
        build=_build_supervisor,
        check=_check_supervisor,
        prepare=_prepare_supervisor,
        finishes=_supervisor_finishes,
        stop_s=_supervisor_stop_s,
    ),
    ServiceSpec(
        "flagstate",
        "run the flag-state service alone: the flag's amplitude, frequency and phase cycle by cycle",
        sections=("flag_state", "tracker"),
        publishes=("flag_state()",),
        subscribes=("centrelines()", "tunnel_state()"),
        alive="flagstate",
        build=_build_flagstate,
    ),
    ServiceSpec(
        "recorder",
        "run the recorder alone: camera packets to .raw files on command",
        sections=("recorder", "tracker"),
        publishes=("recorder_status()",),
        subscribes=("camera_events(camera)", "centrelines()", "recorder_command()"),
        alive="recorder",
        build=_build_recorder,
        check=_check_recorder,
    ),
    ServiceSpec(
        "tracker",
        "run the live tracker alone: camera packets in, centrelines out",
        sections=("tracker", "tracker_service"),
        publishes=("centrelines()", "tracker_status()"),
        subscribes=("camera_events(camera)",),
        alive="tracker",
        build=_build_tracker,
        check=_check_tracker,
        prepare=_prepare_tracker,
    ),
    ServiceSpec(
        "viewer",
        "run the Rerun viewer bridge alone",
        sections=("viewer",),
        subscribes=(
            "centrelines()",
            "camera_events(camera)",
            "event_rate(camera)",
            "tunnel_state()",
            "supervisor_state()",
        ),
        alive="viewer",
        build=_build_viewer,
        check=_check_viewer,
    ),
    ServiceSpec(
        "sensor",
        "run the point sensor alone: publish its samples on the bus (docs/sensor.md)",
        sections=("sensor",),
        needs=("sensor",),
        publishes=("sensor_samples(sensor)",),
        alive="sensor/{sensor}",
        build=_build_sensor,
        check=_check_sensor,
        prepare=_prepare_sensor,
    ),
    ServiceSpec(
        "camera",
        "run the camera adapter alone: publish its event packets on the bus",
        sections=("camera",),
        publishes=("camera_events(camera)", "event_rate(camera)", "camera_status(camera)"),
        subscribes=("tunnel_state()",),  # a simulated camera follows the tunnel's speed
        alive="camera/{camera}",
        build=_build_camera,
        check=_check_camera,
        prepare=_prepare_camera,
    ),
)
"""Every service, in the order they are built and started."""

SERVICE_NAMES: tuple[str, ...] = tuple(spec.name for spec in SERVICES)
"""The names of the services (``services:`` entries, commands, access-control identities)."""


def service_spec(name: str) -> ServiceSpec:
    """The entry of service ``name``.

    Raises:
        KeyError: no such service.
    """
    for spec in SERVICES:
        if spec.name == name:
            return spec
    raise KeyError(f"unknown service {name!r} (known: {', '.join(SERVICE_NAMES)})")


def in_table_order(names: Iterable[str]) -> list[ServiceSpec]:
    """The entries of ``names``, in table order (each once)."""
    wanted = set(names)
    return [spec for spec in SERVICES if spec.name in wanted]
