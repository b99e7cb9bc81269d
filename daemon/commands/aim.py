"""``flagtrack aim``: what the camera sees, for setting it up (focus, laser sheet, hot pixels, chain)."""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from flagtrack.daemon.core.aim import AimFrame
    from flagtrack.daemon.core.aim_overlay import AimOverlays
    from flagtrack.daemon.tracking.section import TrackingConfig

COMMAND = "aim"
HELP = "the set-up view: the camera's recent events, event rate, hot pixels, line width (focus), chain"
DESCRIPTION = """\
Show what the camera sees while you set it up: the recent events as an image, the event rate, hot
pixels, the laser line's width in pixels (the focus figure: make it smallest) and the configured
chain and calibration grid; live in Rerun, as a PNG (--snapshot) or as JSON (--json).
See docs/commands.md and docs/viewer.md.
"""

#: The Rerun view is drawn this often (camera time), a status line printed this often.
FRAME_S = 0.5
STATUS_S = 1.0
#: Hot pixels in the JSON object (busiest first; n_hot_pixels counts them all).
JSON_HOT = 100


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``flagtrack aim``."""
    parser.error = lambda message: parser.exit(2, f"flagtrack aim: error: {message}\n")  # type: ignore[method-assign]  # one line, as every other error
    source = parser.add_argument_group("source (the rig's camera, or a recording)")
    source.add_argument("-c", "--config", type=Path, metavar="RIG.yaml", help="the rig's camera, tracker and viewer")
    source.add_argument("--replay", type=Path, metavar="REC", help="a recording instead of the rig's camera")
    source.add_argument(
        "--speed", type=float, help="replay speed (default: 1 with a live view, else 0: as fast as possible)"
    )
    source.add_argument("--sensor", type=int, nargs=2, metavar=("W", "H"),
                        help="sensor size, pixels, where the recording does not say (a .dat file)")  # fmt: skip
    parser.add_argument("--window-ms", type=float, default=2.0, metavar="MS",
                        help="the image holds the events of the last MS ms (default 2: a moving line stays thin)")  # fmt: skip
    parser.add_argument("--duration", type=float, metavar="S", help="stop after S seconds")
    parser.add_argument("--snapshot", type=Path, metavar="OUT.png", help="write a picture of the end (no Rerun needed)")
    parser.add_argument("--json", action="store_true", help="print the figures as one JSON object")
    parser.add_argument("--rrd", type=Path, metavar="OUT.rrd", help="write the Rerun view to this file")
    parser.add_argument("--viewer", choices=("auto", "spawn", "serve", "none"), help="where the Rerun view goes")
    parser.add_argument("-q", "--quiet", action="store_true", help="no line per second")
    chain = parser.add_argument_group("chain (override the rig's tracker: section)")
    chain.add_argument("--root", type=float, nargs=2, metavar=("X", "Y"), help="root of the flag")
    chain.add_argument("--length", type=float, metavar="L", help="flag length L")
    chain.add_argument("--direction", type=float, metavar="DEG", help="rest direction, degrees")
    chain.add_argument("--joints", type=int, metavar="N", help="number of links N_j")
    chain.add_argument("--alpha", type=float, metavar="A", help="search radius parameter")
    chain.add_argument(
        "--calibration", type=Path, metavar="CAL.yaml", help="pixel -> plane calibration (its grid is drawn)"
    )
    hot = parser.add_argument_group("hot pixels")
    hot.add_argument("--hot-factor", type=float, default=10.0, metavar="F",
                     help="hot: at least F times the rate of the second-busiest other pixel of its 5x5 neighbourhood (default 10)")  # fmt: skip
    hot.add_argument(
        "--hot-min-rate", type=float, default=20.0, metavar="HZ", help="and at least HZ events/s (default 20)"
    )


@dataclass(frozen=True)
class _Plan:
    """What a run will do, every option checked before anything opens."""

    rig: Any
    tracker: TrackingConfig
    params: Callable[[int, int], Any]
    viewer: Any
    note: str
    speed: float
    sensor: tuple[int, int] | None


def _plan(args: argparse.Namespace) -> _Plan:
    from flagtrack.daemon.commands._outputs import RRD, check_output, check_picture
    from flagtrack.daemon.core.events import MAX_SENSOR_PX
    from flagtrack.daemon.errors import ConfigError
    from flagtrack.daemon.typed_yaml import require_output_file

    rig, tracker = _rig_and_tracker(args)  # (reads only: nothing is written before the outputs are checked)
    inputs = (args.replay, args.config, tracker.calibration)
    if args.snapshot is not None:
        require_output_file(args.snapshot, key="--snapshot", path=None)
        check_picture(args.snapshot, "--snapshot", inputs, makes_folder=True)
    if args.rrd is not None:
        require_output_file(args.rrd, key="--rrd", path=None)
        check_output(args.rrd, "--rrd", inputs, replaceable=RRD, holds="a Rerun view (.rrd)", makes_folder=True)
    params = _params(args)
    viewer, note = _viewer(args, rig)
    speed = args.speed if args.speed is not None else (1.0 if viewer is not None and viewer.sink != "rrd" else 0.0)
    if not (math.isfinite(speed) and speed >= 0):  # (nan passed)
        raise ConfigError(f"--speed must be 0 or more, got {speed}")
    if args.sensor is not None and not all(1 <= v <= MAX_SENSOR_PX for v in args.sensor):
        raise ConfigError(f"--sensor must be two sizes of 1 to {MAX_SENSOR_PX}, got {args.sensor[0]} {args.sensor[1]}")
    sensor = (args.sensor[0], args.sensor[1]) if args.sensor else None
    return _Plan(rig, tracker, params, viewer, note, speed, sensor)


def run(args: argparse.Namespace) -> int:
    """Open the source, feed the figures, show them; the figures at the end."""
    from flagtrack.daemon.commands._aim_run import Cadence, feed, open_source, overlays_for
    from flagtrack.daemon.core.aim import AimAccumulator

    plan = _plan(args)
    source = open_source(plan.rig, args.replay, plan.speed, plan.sensor)
    try:
        overlays, _ = overlays_for(plan.tracker, source.info, plan.rig.path if plan.rig is not None else None)
        acc = AimAccumulator(plan.params(source.info.width, source.info.height))
    except BaseException:
        source.camera.close()
        raise
    if plan.note:
        print(plan.note, file=sys.stderr)
    view = _View(plan.viewer, overlays) if plan.viewer is not None else None
    status = None if args.quiet or not (source.live or plan.speed > 0) else _print_status
    cadence = Cadence(args.duration, FRAME_S if view is not None else None, STATUS_S if status else None)
    try:
        frame = feed(source, acc, cadence, view.frame if view is not None else None, status)
        if view is not None:
            view.frame(frame)
    finally:
        if view is not None:
            view.close()
    if args.snapshot is not None:
        from flagtrack.daemon.services.viewer.snapshot import write_snapshot

        write_snapshot(args.snapshot, frame, overlays, title=source.description)
    figures = _figures(frame, overlays, plan.tracker, source, args)
    print(json.dumps(figures) if args.json else _summary(figures))
    return 0


def _rig_and_tracker(args: argparse.Namespace) -> tuple[Any, TrackingConfig]:
    """The rig config (None without -c) and its tracker section with the options applied."""
    from flagtrack.daemon.errors import ConfigError
    from flagtrack.daemon.rig.config import load_rig
    from flagtrack.daemon.tracking.section import TrackingConfig

    if args.config is None and args.replay is None:
        raise ConfigError("give a rig config (-c RIG.yaml) or a recording (--replay REC)")
    if args.config is not None:
        from flagtrack.daemon.commands._aim_run import check_input_file

        check_input_file(args.config, "-c")
    rig = load_rig(args.config, services=() if args.replay else ("camera",)) if args.config else None
    tracker = rig.tracker if rig is not None else TrackingConfig()
    tracker = tracker.with_overrides(
        root=tuple(args.root) if args.root else None, length=args.length, direction_deg=args.direction,
        joints=args.joints, alpha=args.alpha, calibration=args.calibration,
    )  # fmt: skip
    return rig, tracker


def _params(args: argparse.Namespace) -> Any:
    """A function of the sensor size giving the accumulator's settings (ConfigError naming the option)."""
    from flagtrack.daemon.core.aim import AimParams, HotPixelParams
    from flagtrack.daemon.errors import ConfigError

    try:
        hot = HotPixelParams(factor=args.hot_factor, min_rate_hz=args.hot_min_rate)
    except ValueError as exc:
        raise ConfigError(f"--hot-factor/--hot-min-rate: {exc}") from exc
    if not (args.window_ms > 0 and args.window_ms <= 1000):
        raise ConfigError(f"--window-ms must be more than 0 and at most 1000, got {args.window_ms}")
    if args.duration is not None and not args.duration > 0:
        raise ConfigError(f"--duration must be positive, got {args.duration}")
    return lambda width, height: AimParams(width, height, window_ms=args.window_ms, hot=hot)


def _viewer(args: argparse.Namespace, rig: Any) -> tuple[Any, str]:
    """The viewer section of aim's Rerun view (None: no Rerun), and a note when a window was wanted
    but cannot be shown."""
    from flagtrack.daemon.commands._aim_run import has_display, rerun_config
    from flagtrack.daemon.services.viewer.config import ViewerConfig

    base = rig.viewer if rig is not None else ViewerConfig()
    headless_use = args.snapshot is not None or args.json
    cfg = rerun_config(base, args.rrd, args.viewer, headless_use)
    note = ""
    if cfg is None and not headless_use and args.viewer is None and not has_display():
        note = "flagtrack aim: no display: no Rerun window (--rrd FILE writes the view to a file, --snapshot OUT.png a picture)"
    return cfg, note


class _View:
    """The Rerun view (rerun is imported only here, when a sink is asked for)."""

    def __init__(self, cfg: Any, overlays: AimOverlays) -> None:
        from flagtrack.daemon.services.viewer.aim_view import AimView, open_aim_recording

        self.rec, description = open_aim_recording(cfg)
        self.view = AimView(self.rec, overlays)
        print(f"flagtrack aim: Rerun view: {description}", file=sys.stderr)

    def frame(self, frame: AimFrame) -> None:
        self.view.frame(frame)

    def close(self) -> None:
        from flagtrack.daemon.services.viewer import close_recording

        self.rec.flush()
        close_recording(self.rec)


def _print_status(frame: AimFrame) -> None:
    from flagtrack.daemon.services.viewer.snapshot import rate_text

    width = f"{frame.line.width_px:.2f} px" if frame.line.n_profiles and not frame.line.reason else frame.line.reason
    print(f"t {frame.t_end_us * 1e-6:8.2f} s  rate {rate_text(frame.rate_hz):>12}  line width {width}  "
          f"hot pixels {len(frame.hot)}", file=sys.stderr, flush=True)  # fmt: skip


def _figures(frame: AimFrame, overlays: AimOverlays, tracker: TrackingConfig, source: Any, args: Any) -> dict[str, Any]:
    """The figures as plain values (the JSON object)."""
    import math

    line, hot = frame.line, frame.hot
    measured = math.isfinite(line.width_px)
    chain = None
    if overlays.chain is not None and tracker.root is not None:
        chain = {"root": [float(v) for v in tracker.root], "direction_deg": float(tracker.direction_deg),
                 "length": float(tracker.length or 0.0), "joints": int(tracker.joints), "units": overlays.units}  # fmt: skip
    calibration = None
    if overlays.grid is not None:
        step = overlays.grid.step
        calibration = {
            "path": str(tracker.calibration),
            "units": overlays.units,
            "grid_step": step if math.isfinite(step) else None,
        }
    return {
        "source": source.description,
        "sensor": [source.info.width, source.info.height],
        "t_end_s": frame.t_end_us * 1e-6,
        "window_ms": frame.window_us / 1e3,
        "events_in_window": int(frame.image.sum()),
        "events": frame.n_events,
        "events_outside_sensor": frame.n_outside,
        "event_rate_hz": frame.rate_hz,
        "rate_span_s": frame.rate_span_s,
        "line_width_px": line.width_px if measured else None,
        "line_width_spread_px": line.spread_px if measured else None,
        "line_places": line.n_profiles if measured else 0,
        "line_note": line.reason,
        "n_hot_pixels": len(hot),
        "hot_pixels": [
            {
                "x": int(hot.x[i]),
                "y": int(hot.y[i]),
                "rate_hz": float(hot.rate_hz[i]),
                "neighbour_rate_hz": float(hot.neighbour_rate_hz[i]),
            }  # fmt: skip
            for i in range(min(len(hot), JSON_HOT))
        ],
        "chain": chain,
        "calibration": calibration,
        "snapshot": str(args.snapshot) if args.snapshot is not None else None,
    }


def _summary(figures: dict[str, Any]) -> str:
    """The figures as a few lines."""
    from flagtrack.daemon.services.viewer.snapshot import rate_text

    width, height = figures["sensor"]
    lines = [
        f"{figures['source']}, {width}x{height}: last {figures['window_ms']:g} ms to t = {figures['t_end_s']:.3f} s "
        f"({figures['events_in_window']} events)",
        f"event rate: {rate_text(figures['event_rate_hz'])} (over the last {figures['rate_span_s']:.2f} s)",
    ]
    if figures["events_outside_sensor"]:
        lines.append(f"events outside the {width}x{height} sensor, left out: {figures['events_outside_sensor']}")
    if figures["line_width_px"] is not None:
        lines.append(f"line width: {figures['line_width_px']:.2f} px across the line (median of {figures['line_places']} "
                     f"places, interquartile range {figures['line_width_spread_px']:.2f} px): focus to make it smallest")  # fmt: skip
    else:
        lines.append(f"line width: not measured ({figures['line_note']})")
    hot = figures["hot_pixels"][:8]
    listed = ", ".join(f"({p['x']}, {p['y']}) {p['rate_hz']:.0f} Hz" for p in hot)
    more = f" and {figures['n_hot_pixels'] - len(hot)} more" if figures["n_hot_pixels"] > len(hot) else ""
    lines.append(f"hot pixels: {figures['n_hot_pixels']}" + (f": {listed}{more}" if hot else ""))
    chain = figures["chain"]
    if chain is not None:
        lines.append(f"chain: root ({chain['root'][0]:g}, {chain['root'][1]:g}), direction {chain['direction_deg']:g} deg, "
                     f"length {chain['length']:g} {chain['units']}, {chain['joints']} links")  # fmt: skip
    else:
        lines.append("chain: not configured (the rig's tracker: section, or --root X Y --length L)")
    calibration = figures["calibration"]
    if calibration is not None:
        step = (
            f"grid every {calibration['grid_step']:g} {calibration['units']}" if calibration["grid_step"] else "no grid"
        )
        lines.append(f"calibration: {calibration['path']} ({step})")
    if figures["snapshot"]:
        lines.append(f"snapshot: {figures['snapshot']}")
    return "\n".join(lines)
