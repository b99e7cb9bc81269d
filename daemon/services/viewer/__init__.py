"""The viewer service: bridges the bus to Rerun (this package is the only code that imports rerun).

Entities (stable paths, :mod:`.layout`), all on the ``camera`` timeline (seconds of the camera
clock): ``camera/events`` recent events coloured by age, ``tracker/joints``, ``tracker/centreline``,
``tracker/tip_trail``, and time series under ``plots/`` (event rate, Δ_RMS, events per update, tip
lateral position, wind speed).

Rows are queued per entity and sent in one ``send_columns`` call per entity: every ``flush_s`` to a
live viewer, in chunks of up to ``chunk_bytes`` (or every ``rrd_flush_s``) to an .rrd file, so a
file holds few large chunks (:mod:`.batching`). Point clouds and the trail are drawn at most
``geometry_rate_hz`` times a second.

No message stops the viewer: one that cannot be shown (EVT bytes that do not decode, times Rerun
cannot place, ...) is counted (``ViewerService.unusable``) and logged as a rate-limited summary,
and centreline messages of another tracker setup (other samples or joints) are sent apart.
"""

from __future__ import annotations

from .config import ViewerConfig, effective_sink
from .layout import TIMELINE
from .logger import RerunLogger, age_colours, open_recording
from .service import ViewerService

__all__ = [
    "TIMELINE",
    "RerunLogger",
    "ViewerConfig",
    "ViewerService",
    "age_colours",
    "effective_sink",
    "open_recording",
]
