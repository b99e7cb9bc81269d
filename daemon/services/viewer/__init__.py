"""The viewer service: bridges the bus to Rerun (this package is the only code that imports rerun).

Entities (stable paths, :mod:`.layout`; the table is in docs/viewer.md), all on the ``camera``
timeline (seconds of the camera clock): ``camera/events`` recent events coloured by age,
``tracker/joints``, ``tracker/centreline``, ``tracker/tip_trail``, time series under ``plots/`` (tip
y, A/L, event rate, wind speed, Δ_RMS, events per update, the tracker's lost flags and shed share) and the supervisor's state and sweep log under ``supervisor/``. A blueprint (:func:`.layout.blueprint`)
goes with every recording.

Rows are queued per entity and sent in one ``send_columns`` call per entity: every ``flush_s`` to a
live viewer, in chunks of up to ``chunk_bytes`` (or every ``rrd_flush_s``) to an .rrd file, so a
file holds few large chunks (:mod:`.batching`). Point clouds, the trail and A/L are drawn at most
``geometry_rate_hz`` times a second.

No message stops the viewer: one that cannot be shown (EVT bytes that do not decode, times Rerun
cannot place, ...) is counted (``ViewerService.unusable``) and logged as a rate-limited summary,
and centreline messages of another tracker setup (other samples or joints) are sent apart.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from .config import ViewerConfig, effective_sink

if TYPE_CHECKING:
    from .layout import TIMELINE, blueprint
    from .logger import RerunLogger, age_colours, close_recording, open_recording, supervisor_text
    from .service import ViewerService

__all__ = [
    "TIMELINE",
    "RerunLogger",
    "ViewerConfig",
    "ViewerService",
    "age_colours",
    "blueprint",
    "close_recording",
    "effective_sink",
    "open_recording",
    "supervisor_text",
]
_LAZY = {
    "TIMELINE": ".layout",
    "blueprint": ".layout",
    "RerunLogger": ".logger",
    "age_colours": ".logger",
    "close_recording": ".logger",
    "open_recording": ".logger",
    "supervisor_text": ".logger",
    "ViewerService": ".service",
}


def __getattr__(name: str) -> Any:
    """What needs rerun is imported when first used: a process that only reads the ``viewer:``
    section of a rig (every service's config) starts without rerun (~0.5 s)."""
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name], __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
