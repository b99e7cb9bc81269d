"""What the viewer shows, where: the entity paths (stable: recordings, blueprints and docs name them)
and the Rerun blueprint sent with every recording, so the first look at a live rig or an .rrd file is
the useful one. docs/viewer.md has the table of entities; a test reads it back from a demo's file."""

from __future__ import annotations

import rerun.blueprint as rrb

#: The one timeline: seconds of the camera clock (Rerun "duration" time).
TIMELINE = "camera"

EVENTS = "camera/events"
CENTRELINE = "tracker/centreline"
JOINTS = "tracker/joints"
TIP_TRAIL = "tracker/tip_trail"
TIP_Y = "plots/tip_y"
AMPLITUDE = "plots/amplitude_over_l"
EVENT_RATE = "plots/event_rate_hz"
WIND_SPEED = "plots/wind_speed_mps"
DELTA_RMS = "plots/delta_rms"
EVENTS_PER_UPDATE = "plots/events_per_update"
LOST = "plots/lost"  # the tracker's lost flag of each update (1: the flag was not found)
SHED = "plots/shed"  # the share of each update's camera time the tracker shed for its latency budget
SUPERVISOR_STATE = "supervisor/state"
SUPERVISOR_LOG = "supervisor/log"

#: Legend of each time series ({units}: the centrelines' length unit).
SERIES_NAMES = {
    TIP_Y: "tip y ({units})",
    AMPLITUDE: "A/L",
    EVENT_RATE: "event rate (ev/s)",
    WIND_SPEED: "wind speed (m/s)",
    DELTA_RMS: "event-cloud distance Δ_RMS ({units})",
    EVENTS_PER_UPDATE: "events per update",
    LOST: "lost",
    SHED: "shed",
}

#: Time series of kHz data show the last this many seconds before the time cursor.
RECENT_S = 5.0


def blueprint() -> rrb.Blueprint:
    """The layout: the camera view (events, centreline, joints, tip trail) over the supervisor's state
    and log on the left; tip y, A/L, event rate, wind speed, Δ_RMS, lost flags and shed on the right."""
    recent = rrb.VisibleTimeRange(
        TIMELINE,
        start=rrb.TimeRangeBoundary.cursor_relative(seconds=-RECENT_S),
        end=rrb.TimeRangeBoundary.cursor_relative(),
    )
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                rrb.Spatial2DView(name="camera", origin="/", contents=[EVENTS, "tracker/**"]),
                rrb.Horizontal(
                    rrb.TextDocumentView(name="supervisor", origin=SUPERVISOR_STATE),
                    rrb.TextLogView(name="sweep log", origin=SUPERVISOR_LOG),
                ),
                row_shares=[3, 1],
            ),
            rrb.Vertical(
                rrb.TimeSeriesView(name="tip y", origin=TIP_Y, time_ranges=recent),
                rrb.TimeSeriesView(name="A/L", origin=AMPLITUDE),
                rrb.TimeSeriesView(name="event rate", origin=EVENT_RATE),
                rrb.TimeSeriesView(name="wind speed", origin=WIND_SPEED),
                rrb.TimeSeriesView(name="Δ_RMS", origin=DELTA_RMS, time_ranges=recent),
                rrb.TimeSeriesView(name="lost", origin=LOST),
                rrb.TimeSeriesView(name="shed", origin=SHED),
            ),
            column_shares=[3, 2],
        ),
        collapse_panels=False,
    )
