"""The ``viewer:`` section of a rig: where the Rerun data goes, how much of it, how often it is sent."""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from flagtrack.daemon.errors import ConfigError


@dataclass(frozen=True)
class ViewerConfig:
    """Where the Rerun data goes and how much of it.

    Attributes:
        sink: ``auto`` (a viewer window when a display exists, else an .rrd file), ``spawn``, ``serve``
            (gRPC + web viewer for a browser), ``rrd`` (headless file) or ``none``.
        rrd_path: the .rrd file for the ``rrd`` sink (and ``auto`` without display).
        web_port: port of the web viewer for ``serve``.
        serve_host: the address ``serve`` listens on (web viewer and gRPC): loopback by default,
            ``0.0.0.0`` for every interface (see docs/security.md).
        grpc_port: port of the gRPC server that ``serve`` streams through.
        camera_id: the camera whose events are shown.
        recent_events_ms: events younger than this are drawn.
        max_points: at most this many event points per frame (subsampled beyond).
        update_rate_hz: tracker updates shown per second of camera time at most (centreline, joints,
            tip y, Delta_RMS, events per update; ``lost`` keeps every change too): the first update of
            each ``1 / update_rate_hz`` slot. None: every update. The full stream stays in the
            centreline files; 200 Hz draws a 5 s plot at about one update per pixel column.
        trail_s: length of the tip trail.
        geometry_rate_hz: frames per second for event clouds, the tip trail and A/L.
        amplitude_window_s: A/L is half the peak-to-peak of the tip over this much of the latest updates.
        flush_s: a live viewer (``spawn``, ``serve``) gets what is queued at least this often, seconds.
        rrd_flush_s: an .rrd file gets an entity's queued rows when they reach ``chunk_bytes`` or the
            oldest has waited this long (so the file holds few large chunks; a crash loses at most this).
        chunk_bytes: an entity's queued rows are sent when they reach this size (Rerun's target chunk
            size for stored recordings is 2 MiB).
    """

    sink: Literal["auto", "spawn", "serve", "rrd", "none"] = "auto"
    rrd_path: Path = Path("flagtrack.rrd")
    web_port: int = 9090
    serve_host: str = "127.0.0.1"
    grpc_port: int = 9876
    camera_id: str = "cam0"
    recent_events_ms: float = 10.0
    max_points: int = 20_000
    update_rate_hz: float | None = 200.0
    trail_s: float = 0.5
    geometry_rate_hz: float = 30.0
    amplitude_window_s: float = 1.0
    flush_s: float = 0.25
    rrd_flush_s: float = 30.0
    chunk_bytes: int = 2 << 20

    def __post_init__(self) -> None:
        names = ("geometry_rate_hz", "flush_s", "rrd_flush_s", "amplitude_window_s", "chunk_bytes", "update_rate_hz")
        for name in names:
            value = getattr(self, name)
            if value is None and name == "update_rate_hz":
                continue
            if not (math.isfinite(value) and value > 0):
                raise ConfigError(f"must be a positive number, got {value!r}", key=f"viewer.{name}")
        for name in ("web_port", "grpc_port"):
            if not 1 <= getattr(self, name) <= 65535:
                raise ConfigError(f"must be a port, 1 to 65535, got {getattr(self, name)}", key=f"viewer.{name}")


def effective_sink(cfg: ViewerConfig) -> str:
    """The sink the viewer uses: ``auto`` is a window where a display exists, else the .rrd file."""
    if cfg.sink != "auto":
        return cfg.sink
    return "spawn" if os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY") else "rrd"
