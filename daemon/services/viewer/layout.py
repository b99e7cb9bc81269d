"""Where the viewer puts things: the entity paths (stable: recordings and docs name them)."""

from __future__ import annotations

#: The one timeline: seconds of the camera clock (Rerun "duration" time).
TIMELINE = "camera"

EVENTS = "camera/events"
CENTRELINE = "tracker/centreline"
JOINTS = "tracker/joints"
TIP_TRAIL = "tracker/tip_trail"
TIP_Y = "plots/tip_y"
EVENT_RATE = "plots/event_rate_hz"
WIND_SPEED = "plots/wind_speed_mps"
DELTA_RMS = "plots/delta_rms"
EVENTS_PER_UPDATE = "plots/events_per_update"
