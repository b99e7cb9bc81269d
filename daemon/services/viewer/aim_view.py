"""The Rerun view of ``flagtrack aim``: the camera image of the last window with the chain, its search
areas, the calibration's grid, the line-width places and the hot pixels over it; the event rate and
the line width over time; the figures as a text document.

Entities (on the ``camera`` timeline; static where they do not change): ``aim/camera/image``
(Image, grey levels), ``aim/camera/grid`` (static LineStrips2D), ``aim/camera/search_areas`` (static
LineStrips2D), ``aim/camera/chain`` (static LineStrips2D) and ``aim/camera/joints`` (static
Points2D), ``aim/camera/line_width`` (LineStrips2D: a tick across the line per measured place),
``aim/camera/hot_pixels`` (Points2D, labelled with their rates), ``aim/plots/event_rate_hz``,
``aim/plots/line_width_px``, ``aim/plots/hot_pixels`` (Scalars) and ``aim/figures`` (TextDocument).
"""

from __future__ import annotations

import math

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from flagtrack.daemon.core.aim import AimFrame, display_levels
from flagtrack.daemon.core.aim_overlay import AimOverlays

from .config import ViewerConfig
from .layout import TIMELINE
from .logger import open_recording
from .snapshot import figures_text, width_ticks

IMAGE = "aim/camera/image"
GRID = "aim/camera/grid"
SEARCH_AREAS = "aim/camera/search_areas"
CHAIN = "aim/camera/chain"
JOINTS = "aim/camera/joints"
LINE_WIDTH = "aim/camera/line_width"
HOT_PIXELS = "aim/camera/hot_pixels"
EVENT_RATE = "aim/plots/event_rate_hz"
WIDTH_SERIES = "aim/plots/line_width_px"
HOT_SERIES = "aim/plots/hot_pixels"
FIGURES = "aim/figures"

#: Hot pixels listed in the figures document.
LISTED_HOT = 20


def aim_blueprint() -> rrb.Blueprint:
    """The camera view on the left; event rate, line width and the figures on the right."""
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial2DView(name="camera (aim)", origin="aim/camera"),
            rrb.Vertical(
                rrb.TimeSeriesView(name="event rate", origin=EVENT_RATE),
                rrb.TimeSeriesView(name="line width (px)", origin=WIDTH_SERIES),
                rrb.TextDocumentView(name="figures", origin=FIGURES),
                row_shares=[1, 1, 2],
            ),
            column_shares=[3, 1],
        ),
        collapse_panels=False,
    )


def open_aim_recording(cfg: ViewerConfig) -> tuple[rr.RecordingStream, str]:
    """The viewer's recording stream on ``cfg``'s sink, with the aim layout; it and a description."""
    rec, description = open_recording(cfg)
    rec.send_blueprint(aim_blueprint(), make_active=True, make_default=True)
    return rec, description


def figures_markdown(frame: AimFrame) -> str:
    """The figures as Markdown: one line of them, then the busiest hot pixels as a table."""
    lines = [figures_text(frame), ""]
    if len(frame.hot):
        lines += ["| x | y | rate | 2nd neighbour |", "|---|---|---|---|"]
        for i in range(min(len(frame.hot), LISTED_HOT)):
            lines.append(
                f"| {frame.hot.x[i]} | {frame.hot.y[i]} | {frame.hot.rate_hz[i]:.0f} Hz "
                f"| {frame.hot.neighbour_rate_hz[i]:.0f} Hz |"
            )
        if len(frame.hot) > LISTED_HOT:
            lines.append(f"\nand {len(frame.hot) - LISTED_HOT} more")
    return "\n".join(lines)


class AimView:
    """Logs :class:`AimFrame` s to a recording stream; the overlays once, as static data."""

    def __init__(self, rec: rr.RecordingStream, overlays: AimOverlays) -> None:
        self.rec = rec
        if overlays.grid is not None and overlays.grid.lines:
            strips = [line.astype(np.float32) for line in overlays.grid.lines]
            rec.log(GRID, rr.LineStrips2D(strips, colors=[200, 200, 200], radii=0.3, draw_order=10.0), static=True)
        if overlays.chain is not None:
            areas = [area.astype(np.float32) for area in overlays.chain.areas]
            rec.log(SEARCH_AREAS, rr.LineStrips2D(areas, colors=[0, 220, 220], radii=0.4, draw_order=20.0), static=True)
            joints = overlays.chain.joints.astype(np.float32)
            rec.log(CHAIN, rr.LineStrips2D([joints], colors=[255, 230, 0], radii=0.8, draw_order=30.0), static=True)
            rec.log(JOINTS, rr.Points2D(joints, colors=[255, 230, 0], radii=1.5, draw_order=31.0), static=True)
        for path, name in (
            (EVENT_RATE, "event rate (ev/s)"),
            (WIDTH_SERIES, "line width (px)"),
            (HOT_SERIES, "hot pixels"),
        ):
            rec.log(path, rr.SeriesLines(names=name), static=True)

    def frame(self, frame: AimFrame) -> None:
        """Log one frame at its camera time."""
        rec = self.rec
        rec.set_time(TIMELINE, duration=frame.t_end_us * 1e-6)
        rec.log(IMAGE, rr.Image(display_levels(frame.image, frame.hot), color_model="L", draw_order=0.0))
        ticks = width_ticks(frame).astype(np.float32)
        rec.log(LINE_WIDTH, rr.LineStrips2D(list(ticks), colors=[0, 255, 0], radii=0.3, draw_order=40.0))
        labels = [f"{rate:.0f} Hz" for rate in frame.hot.rate_hz[:LISTED_HOT]] + [""] * max(
            0, len(frame.hot) - LISTED_HOT
        )
        positions = np.stack([frame.hot.x, frame.hot.y], axis=1).astype(np.float32)
        rec.log(HOT_PIXELS, rr.Points2D(positions, colors=[255, 0, 0], radii=3.0, labels=labels, draw_order=50.0))
        rec.log(EVENT_RATE, rr.Scalars(frame.rate_hz))
        if math.isfinite(frame.line.width_px):
            rec.log(WIDTH_SERIES, rr.Scalars(frame.line.width_px))
        rec.log(HOT_SERIES, rr.Scalars(float(len(frame.hot))))
        rec.log(FIGURES, rr.TextDocument(figures_markdown(frame), media_type=rr.MediaType.MARKDOWN))
