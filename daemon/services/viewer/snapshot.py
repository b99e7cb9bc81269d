"""The picture of ``flagtrack aim --snapshot OUT.png``: what the camera saw last, headless (matplotlib's
Agg canvas, no pyplot state, no display, no Rerun).

The events of the last window as grey levels (:func:`~flagtrack.daemon.core.aim.display_levels`),
the calibration's grid (dotted), the chain's search areas (cyan) and the chain at rest (yellow, root
marked), the places the line's width was measured (green, a tick across the line as long as the
width there) and the hot pixels (red circles); the figures in the title and a list of the hot pixels.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from flagtrack.daemon.core.aim import AimFrame, display_levels
from flagtrack.daemon.core.aim_overlay import AimOverlays

#: Hot pixels listed under the picture (all are circled).
LISTED_HOT = 8
#: Places of the line-width measurement drawn, at most.
DRAWN_TICKS = 40


def _figure(size: tuple[float, float]) -> Any:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=size, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def rate_text(rate_hz: float) -> str:
    """``4.94 Mev/s``, ``12.3 kev/s``, ``87 ev/s``."""
    for scale, unit in ((1e6, "Mev/s"), (1e3, "kev/s")):
        if rate_hz >= scale:
            return f"{rate_hz / scale:.3g} {unit}"
    return f"{rate_hz:.3g} ev/s"


def figures_text(frame: AimFrame) -> str:
    """One line: the window, the rate, the line width and the hot pixels."""
    line = frame.line
    width = f"line width {line.width_px:.2f} px ({line.n_profiles} places)" if line.n_profiles and not line.reason else (
        f"line width: {line.reason}"
    )  # fmt: skip
    return (
        f"last {frame.window_us / 1e3:g} ms to t = {frame.t_end_us * 1e-6:.3f} s ({int(frame.image.sum())} events) · "
        f"rate {rate_text(frame.rate_hz)} · {width} · hot pixels {len(frame.hot)}"
    )


def width_ticks(frame: AimFrame, most: int = DRAWN_TICKS) -> np.ndarray:
    """(k, 2, 2) segments across the line at up to ``most`` of the measured places, each as long as
    the width measured there."""
    line = frame.line
    pick = np.unique(np.linspace(0, line.n_profiles - 1, min(most, line.n_profiles)).round().astype(np.int64))
    half = 0.5 * line.widths[pick, None] * line.normals[pick]
    return np.stack([line.centres[pick] - half, line.centres[pick] + half], axis=1)


def _draw_overlays(ax: Any, frame: AimFrame, overlays: AimOverlays) -> None:
    if overlays.grid is not None:
        for line in overlays.grid.lines:
            ax.plot(line[:, 0], line[:, 1], color="white", linewidth=0.6, linestyle=":", alpha=0.6)
    if overlays.chain is not None:
        for area in overlays.chain.areas:
            ax.plot(area[:, 0], area[:, 1], color="cyan", linewidth=0.7, alpha=0.8)
        joints = overlays.chain.joints
        ax.plot(joints[:, 0], joints[:, 1], color="yellow", linewidth=1.2, marker="o", markersize=2.5)
        ax.plot(joints[0, 0], joints[0, 1], marker="s", color="yellow", markersize=7, fillstyle="none")
    for a, b in width_ticks(frame):
        ax.plot([a[0], b[0]], [a[1], b[1]], color="lime", linewidth=0.8)
    if len(frame.hot):
        ax.scatter(frame.hot.x, frame.hot.y, s=60, facecolors="none", edgecolors="red", linewidths=1.0)


def _hot_text(frame: AimFrame) -> str:
    if not len(frame.hot):
        return "hot pixels: none"
    listed = [f"({x}, {y}) {r:.0f} Hz" for x, y, r in zip(frame.hot.x[:LISTED_HOT], frame.hot.y[:LISTED_HOT],
                                                         frame.hot.rate_hz[:LISTED_HOT], strict=True)]  # fmt: skip
    more = f" and {len(frame.hot) - LISTED_HOT} more" if len(frame.hot) > LISTED_HOT else ""
    return f"hot pixels ({len(frame.hot)}): " + ", ".join(listed) + more


def write_snapshot(path: str | Path, frame: AimFrame, overlays: AimOverlays, title: str = "") -> Path:
    """Write the picture of ``frame`` with ``overlays`` to ``path`` (PNG; parents created); return it."""
    path = Path(path)
    height, width = frame.image.shape
    fig = _figure((10.0, 10.0 * height / width + 1.4))
    ax = fig.add_subplot()
    ax.imshow(display_levels(frame.image, frame.hot), cmap="gray", vmin=0, vmax=255, interpolation="nearest")
    _draw_overlays(ax, frame, overlays)
    ax.set_xlim(-0.5, width - 0.5)
    ax.set_ylim(height - 0.5, -0.5)
    ax.set_xlabel("x (px)")
    ax.set_ylabel("y (px)")
    grid = overlays.grid
    grid_note = f" · grid every {grid.step:g} {overlays.units}" if grid is not None and np.isfinite(grid.step) else ""
    ax.set_title(((title + "\n") if title else "") + figures_text(frame) + grid_note, fontsize=9)
    fig.text(0.01, 0.005, _hot_text(frame), fontsize=8, ha="left", va="bottom")
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    return path
