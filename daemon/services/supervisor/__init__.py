"""The supervisor: wind tunnel, flag state from event rates, sweeps, feedback control, safe state."""

from __future__ import annotations

from flagtrack.daemon.services.supervisor.section import FeedbackConfig, SupervisorConfig
from flagtrack.daemon.services.supervisor.service import FlagGeometry, SupervisorService

__all__ = ["FeedbackConfig", "FlagGeometry", "SupervisorConfig", "SupervisorService"]
