"""The supervisor: wind tunnel, flag state from event rates, sweeps, feedback control, safe state.

The sweep's state machine and the safe session it runs in are ``daemon/sweep/`` (runner.py,
session.py); this package wires them to the bus (busside.py), each point's analysis (measure.py)
and the feedback law (feedback.py, feedback_loop.py).

The service itself (and the analysis it imports: SciPy's signal processing, ~0.5-1 s) is imported
when first used, so a process that only reads the ``supervisor:`` section of a rig (every service's
config) starts without it.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from flagtrack.daemon.services.supervisor.section import FeedbackConfig, SupervisorConfig

if TYPE_CHECKING:
    from flagtrack.daemon.services.supervisor.measure import FlagGeometry
    from flagtrack.daemon.services.supervisor.service import SupervisorService

__all__ = ["FeedbackConfig", "FlagGeometry", "SupervisorConfig", "SupervisorService"]
_LAZY = {"FlagGeometry": ".measure", "SupervisorService": ".service"}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name], __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
