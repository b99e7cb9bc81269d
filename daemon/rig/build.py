"""Build the services a rig config asks for, from the service table (:mod:`.table`): constructed in
table order, opening nothing (the runner starts them, in that order, before any runs)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from flagtrack.daemon.rig.camera import BusSpeedSource, OpenedCamera, open_camera, open_hardware_camera
from flagtrack.daemon.rig.config import RigConfig
from flagtrack.daemon.rig.context import Build
from flagtrack.daemon.rig.table import in_table_order
from flagtrack.daemon.services.runner import Service
from flagtrack.daemon.tracking.setup import TrackingSetup
from flagtrack.daemon.transport import Bus
from flagtrack.drivers.camera.base import Camera

__all__ = ["Build", "BusSpeedSource", "OpenedCamera", "build_services", "open_camera", "open_hardware_camera"]


def build_services(
    rig: RigConfig,
    bus: Bus,
    names: Sequence[str],
    *,
    exit_at_end_of_stream: bool = False,
    resume_dir: Path | None = None,
    tracker: TrackingSetup | None = None,
    camera: Camera | None = None,
) -> list[Service]:
    """Construct the named services of ``rig`` on ``bus``, in table order, opening nothing (the runner
    starts them, in that order, before any runs).

    ``tracker``: the rig's :func:`~flagtrack.daemon.tracking.setup.tracking_setup`, if the caller
    already made it; ``camera``: the camera, if the caller opened it (:func:`open_hardware_camera`).

    Raises:
        ConfigError: a combination of services this process cannot run (a simulated sensor without
            the simulated camera).
    """
    build = Build(
        rig, bus, tuple(names), exit_at_end_of_stream, resume_dir, tracker, camera if "camera" in names else None
    )
    for spec in in_table_order(list(names)):
        build.built[spec.name] = spec.build(build)
    return list(build.built.values())
