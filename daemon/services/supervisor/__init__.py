"""The supervisor: wind tunnel, flag state from event rates, sweeps, feedback control, safe state."""

from __future__ import annotations

from typing import Any

from flagtrack.daemon.services.supervisor.config import FeedbackConfig, SupervisorConfig
from flagtrack.daemon.services.supervisor.service import FlagGeometry, SupervisorService

__all__ = ["FeedbackConfig", "FlagGeometry", "SupervisorConfig", "SupervisorService", "build_supervisor"]


def build_supervisor(rig: Any, bus: Any, tunnel: Any, resume_dir: Any = None) -> SupervisorService:
    """The supervisor of a rig config, with its (opened, not started) tunnel."""
    tracker = rig.tracker
    flag = FlagGeometry(float(tracker.length or 1.0), tuple(tracker.root or (0.0, 0.0)), float(tracker.direction_deg))
    return SupervisorService(bus, rig.supervisor, tunnel, rig.camera.id, flag, rig.snapshot(), resume_dir,
                             getattr(rig, "sensor", None))
