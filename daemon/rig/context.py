"""What the service table's steps get: :class:`Build` (to construct a service) and :class:`Preparation`
(to do its slow one-off work), each with the work the steps share, done once however many ask."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from flagtrack.daemon.rig.camera import BusSpeedSource, open_camera
from flagtrack.daemon.rig.sections import RigSections
from flagtrack.daemon.services.runner import Service
from flagtrack.daemon.tracking.setup import TrackingSetup, processing_attrs, tracking_setup
from flagtrack.daemon.transport import Bus
from flagtrack.drivers.camera.base import Camera

if TYPE_CHECKING:
    from flagtrack.drivers.camera.simulated import SimulatedCamera

KERNELS_MESSAGE = "loading the compiled kernels (the first run after installing compiles them: about a minute)"


@dataclass
class Build:
    """What the table's build steps get (:attr:`~flagtrack.daemon.rig.table.ServiceSpec.build`): the
    rig, the bus, the services of this process, and what the caller made ahead or the steps share.

    Attributes:
        rig: the rig config.
        bus: the bus every service gets.
        names: the services built in this process.
        exit_at_end_of_stream: end with the camera's stream (a replayed file).
        resume_dir: the sweep run the supervisor resumes.
        tracker: the rig's tracking set-up (made at the first :meth:`tracking` when not given).
        camera: the camera adapter (the caller's, opened ahead; else made at the first :meth:`camera_adapter`).
        built: the services built so far, by name.
    """

    rig: RigSections
    bus: Bus
    names: tuple[str, ...]
    exit_at_end_of_stream: bool = False
    resume_dir: Path | None = None
    tracker: TrackingSetup | None = None
    camera: Camera | None = None
    built: dict[str, Service] = field(default_factory=dict)

    def tracking(self) -> TrackingSetup:
        """The rig's tracking set-up (checked, its calibration loaded: once)."""
        if self.tracker is None:
            self.tracker = tracking_setup(self.rig.tracker, path=self.rig.path)
        return self.tracker

    def centreline_attrs(self) -> dict[str, Any]:
        """What the centreline files carry: the tracking set-up's attributes when the tracker runs here,
        else the processing parameters of the ``tracker:`` section."""
        return self.tracking().attrs if "tracker" in self.names else processing_attrs(self.rig.tracker)

    def camera_adapter(self) -> Camera:
        """The camera adapter of this process (not opened here; made once)."""
        if self.camera is None:
            self.camera = open_camera(self.rig.camera, self._speed_source(), self.rig.path)
        return self.camera

    def _speed_source(self) -> Callable[[], float] | None:
        """Where a simulated camera reads the wind speed: the simulated tunnel of the supervisor of
        this process (once it has started), else the tunnel state on the bus (its own setting until
        one arrives)."""
        rig = self.rig
        if rig.camera.adapter != "simulated" or rig.tunnel is None:
            return None
        own = rig.camera.simulated.speed_mps
        supervisor = self.built.get("supervisor")
        if supervisor is None:
            return BusSpeedSource(self.bus, own)

        def tunnel_speed() -> float:
            simulator = getattr(getattr(supervisor, "tunnel", None), "simulator", None)
            return float(simulator.speed_mps) if simulator is not None else own

        return tunnel_speed


@dataclass
class Preparation:
    """What the table's prepare steps get, and the work they share (done once however many ask).

    Attributes:
        rig: the rig config.
        names: the services to prepare.
        say: tells the user of slow work (the kernels).
        tracker: the rig's tracking set-up (made at the first :meth:`tracking` when not given).
    """

    rig: RigSections
    names: tuple[str, ...]
    say: Callable[[str], None]
    tracker: TrackingSetup | None = None
    _done: set[str] = field(default_factory=set)

    def tracking(self) -> TrackingSetup:
        """The rig's tracking set-up (made once)."""
        if self.tracker is None:
            self.tracker = tracking_setup(self.rig.tracker, path=self.rig.path)
        return self.tracker

    def once(self, key: str, step: Callable[[], object]) -> None:
        """Run ``step`` unless a step of the same ``key`` ran already."""
        if key not in self._done:
            self._done.add(key)
            step()

    def loading_kernels(self) -> None:
        """Say (once) that kernels are being loaded, or compiled on a first run."""
        self.once("kernels message", lambda: self.say(KERNELS_MESSAGE))

    def twin(self) -> SimulatedCamera:
        """The digital twin of the ``camera:`` section (not opened), for a step to exercise."""
        from flagtrack.drivers.camera.simulated import SimulatedCamera

        return SimulatedCamera(self.rig.camera.simulated)

    def warm_up_triggers(self) -> None:
        """Load (or compile) the kernels of trigger pulses: packets and raw files (once)."""
        self.once("triggers", warm_up_triggers)


def warm_up_triggers() -> None:
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
