"""``flagtrack bench twin``: can the simulated camera (the digital twin) render its events in real time?

Runs the twin of ``flagtrack demo`` (``drivers/camera/simulated``, a flapping flag of 300 px above
its onset speed) as fast as possible on one core, for each ``--events-per-px2`` asked, and prints:
the event rate it delivers (events per second of camera time), the rate it generates them at (per
second of this machine's time), and their ratio, the real-time margin: above 1, the twin keeps up
with real time alone on a core; in a process shared with the rest of the rig it has less.
"""

from __future__ import annotations

import argparse
import json
import time

from flagtrack.daemon.bench._cores import one_core

COMMAND = "twin"
HELP = "event rate of the simulated camera and how fast one core renders it (real-time margin)"
DESCRIPTION = __doc__


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of the twin benchmark."""
    parser.add_argument(
        "--events-per-px2",
        type=float,
        nargs="+",
        default=[2.0, 10.0],
        help="event densities to measure (2: the demo's default, ~1 Mev/s)",
    )
    parser.add_argument("--speed-mps", type=float, default=6.0, help="wind speed (flapping above 4.9 m/s)")
    parser.add_argument("--seconds", type=float, default=2.0, help="camera time generated per measurement")
    parser.add_argument("--all-cores", action="store_true", help="do not pin to one core")
    parser.add_argument("--json", action="store_true", help="print the results as JSON")


def measure(events_per_px2: float, speed_mps: float, seconds: float) -> dict[str, float]:
    """Generate ``seconds`` of the flapping twin as fast as possible; return its rates."""
    from flagtrack.drivers.camera.simulated import SimulatedCamera, SimulatedCameraConfig, fast_forward

    cfg = SimulatedCameraConfig(speed_mps=speed_mps, events_per_px2=events_per_px2)
    warm = SimulatedCamera(cfg)
    fast_forward(warm, 1.0)  # compiles the kernels and lets the flag reach its flapping amplitude
    camera = SimulatedCamera(cfg)
    fast_forward(camera, 1.0)
    start = time.perf_counter()
    events = sum(len(chunk) for chunk in fast_forward(camera, seconds))
    wall_s = time.perf_counter() - start
    camera_rate = events / seconds
    return {
        "events_per_px2": events_per_px2,
        "speed_mps": speed_mps,
        "flapping": bool(camera.state.flapping),
        "events": events,
        "camera_mev_s": camera_rate / 1e6,
        "generated_mev_s": events / wall_s / 1e6,
        "real_time_margin": seconds / wall_s,
    }


def run(args: argparse.Namespace) -> int:
    """Measure each density on one core and print the figures."""
    with one_core(not args.all_cores) as pin:
        rows = [measure(density, args.speed_mps, args.seconds) for density in args.events_per_px2]
    if args.json:
        print(json.dumps({"one_core": pin, "rows": rows}, indent=1))
        return 0
    print(f"simulated camera at {args.speed_mps:g} m/s, {args.seconds:g} s of camera time{', one core' if pin else ''}")
    for row in rows:
        print(
            f"  events_per_px2 {row['events_per_px2']:5.1f}: {row['camera_mev_s']:5.2f} Mev/s of camera data, "
            f"generated at {row['generated_mev_s']:5.2f} Mev/s: real-time margin x{row['real_time_margin']:.1f}"
            f"{'' if row['flapping'] else ' (flag not flapping)'}"
        )
    return 0
