"""``flagtrack simulate OUT_DIR``: simulated event recordings of flapping flags with their ground truth."""

from __future__ import annotations

import argparse
import json
import math
import os

COMMAND = "simulate"
HELP = "simulate event-camera recordings of flapping flags (EVT 3.0 .raw + ground-truth .h5 + .json)"
DESCRIPTION = """\
Simulated event recordings of flapping flags with their ground truth: per seed an EVT 3.0 .raw, a
truth .h5 (the centreline file layout) and a .json; --checkerboard makes a calibration recording
instead. More: docs/simulator.md, docs/commands.md.
"""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Recording count, duration, sensor defects, sensor size, parallelism, checkerboard."""
    parser.add_argument("out_dir", help="output folder (created)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the first recording (default 0)")
    parser.add_argument("--n", type=int, default=1, help="number of recordings (default 1)")
    parser.add_argument("--duration", type=float, default=None, help="seconds per recording (default: 3-6 periods)")
    parser.add_argument("--leak-rate", type=float, default=0.0, help="leak events per pixel per second (default 0)")
    parser.add_argument("--shot-noise", type=float, default=0.0, help="noise events per pixel per second (default 0)")
    parser.add_argument("--contrast", type=float, default=0.3, help="mean ON/OFF threshold, log units (default 0.3)")
    parser.add_argument("--refractory-us", type=float, default=10.0, help="pixel refractory period, µs (default 10)")
    parser.add_argument("--width", type=int, default=640, help="sensor width, px (default 640)")
    parser.add_argument("--height", type=int, default=480, help="sensor height, px (default 480)")
    parser.add_argument("--tilted", action="store_true", help="view through the paper's tilted camera (truth in m)")
    parser.add_argument("--jobs", type=int, default=1, help="processes (0: all cores; default 1)")
    board = parser.add_argument_group("checkerboard (calibration)")
    board.add_argument("--checkerboard", action="store_true", help="simulate a blinking checkerboard instead")
    board.add_argument("--corners", default="9x6", help="inner corners NxM (default 9x6)")
    board.add_argument("--square-mm", type=float, default=20.0, help="square side, mm (default 20)")
    board.add_argument("--blink-ms", type=float, default=100.0, help="blink period, ms (default 100)")
    board.add_argument("--periods", type=int, default=3, help="blink periods recorded (default 3)")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Simulate and print one JSON line per recording."""
    from flagtrack.daemon.core.events import MAX_SENSOR_PX
    from flagtrack.daemon.errors import ConfigError
    from flagtrack.drivers.sim.dvs import DvsParams
    from flagtrack.drivers.sim.simulate import RecordingSpec, simulate_checkerboard, simulate_many

    if args.n < 1 or not (16 <= args.width <= MAX_SENSOR_PX and 16 <= args.height <= MAX_SENSOR_PX):
        raise ConfigError(f"need --n >= 1 and a sensor of 16 to {MAX_SENSOR_PX} px a side")
    if args.duration is not None and not (math.isfinite(args.duration) and 0 < args.duration <= 3600):
        raise ConfigError(f"--duration: must be above 0 and at most 3600 s, got {args.duration}")
    rates = {"--leak-rate": args.leak_rate, "--shot-noise": args.shot_noise, "--refractory-us": args.refractory_us}
    for option, value in {**rates, "--contrast": args.contrast}.items():
        if not (math.isfinite(value) and value >= 0):
            raise ConfigError(f"{option}: must be a finite number >= 0, got {value}")
    try:
        dvs = DvsParams(
            contrast_on=args.contrast,
            contrast_off=args.contrast,
            refractory_us=args.refractory_us,
            leak_rate_hz=args.leak_rate,
            shot_noise_hz=args.shot_noise,
        )
    except ValueError as exc:
        raise ConfigError(str(exc)) from exc
    if args.checkerboard:
        return _checkerboard(args, dvs, simulate_checkerboard)
    jobs = args.jobs if args.jobs > 0 else os.cpu_count() or 1
    specs = [
        RecordingSpec(
            seed=args.seed + i,
            duration_s=args.duration,
            width=args.width,
            height=args.height,
            tilted=args.tilted,
            dvs=dvs,
        )
        for i in range(args.n)
    ]
    for result in simulate_many(specs, args.out_dir, jobs=jobs):
        print(
            json.dumps(
                {
                    "events": result.events_path,
                    "truth": result.truth_path,
                    "n_events": result.n_events,
                    "duration_s": round(result.duration_s, 6),
                    "wall_s": round(result.wall_s, 3),
                    "events_per_s": round(result.events_per_s),
                }
            )
        )
    return 0


def _checkerboard(args: argparse.Namespace, dvs: object, simulate_checkerboard: object) -> int:
    from flagtrack.daemon.errors import ConfigError
    from flagtrack.drivers.sim.scenes import BlinkParams, CheckerboardSpec

    try:
        n, m = (int(v) for v in args.corners.lower().split("x"))
    except ValueError as exc:
        raise ConfigError(f"--corners must look like 9x6, got {args.corners!r}", key="corners") from exc
    if not (2 <= n <= 100 and 2 <= m <= 100):
        raise ConfigError(f"--corners: 2 to 100 a side, got {args.corners}")
    for option, value in (("--square-mm", args.square_mm), ("--blink-ms", args.blink_ms)):
        if not (math.isfinite(value) and 0 < value <= 1e5):
            raise ConfigError(f"{option}: must be a positive number up to 1e5, got {value}")
    if not 1 <= args.periods <= 1000:
        raise ConfigError(f"--periods: 1 to 1000, got {args.periods}")
    square = args.square_mm * 1e-3
    spec = CheckerboardSpec(
        inner_corners=(n, m), square=square, origin=(0.09 - square * (n - 1) / 2, -square * (m - 1) / 2)
    )
    blink = BlinkParams(period_us=int(args.blink_ms * 1e3))
    result = simulate_checkerboard(
        args.out_dir, spec, blink, n_periods=args.periods, width=args.width, height=args.height, dvs=dvs, seed=args.seed
    )  # type: ignore[operator]
    print(json.dumps({"events": result.events_path, "params": result.params_path, "n_events": result.n_events}))
    return 0
