"""``flagtrack bench simulate``: events generated per second by the event-camera simulator."""

from __future__ import annotations

import argparse
import json
import os

COMMAND = "simulate"
HELP = "events generated per second by the simulator, on one core and on all cores"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Recording count, duration, parallelism."""
    parser.add_argument("--n", type=int, default=4, help="recordings per measurement (default 4)")
    parser.add_argument("--duration", type=float, default=0.2, help="seconds per recording (default 0.2)")
    parser.add_argument("--jobs", type=int, default=0, help="processes for the all-cores figure (0: all cores)")
    parser.add_argument("--out-dir", default=None, help="keep the files here (default: a temporary folder)")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.set_defaults(run=run)


def _measure(n: int, duration_s: float, jobs: int, out_dir: str, seed0: int) -> dict[str, float]:
    import time

    from flagtrack.drivers.sim.simulate import RecordingSpec, simulate_many

    specs = [RecordingSpec(seed=seed0 + i, duration_s=duration_s) for i in range(n)]
    start = time.perf_counter()
    results = list(simulate_many(specs, out_dir, jobs=jobs))
    wall_s = time.perf_counter() - start
    n_events = sum(r.n_events for r in results)
    camera_s = sum(r.wall_s for r in results)
    return {
        "jobs": jobs,
        "recordings": n,
        "events": n_events,
        "wall_s": wall_s,
        "events_per_s": n_events / wall_s,
        "camera_events_per_s": n_events / camera_s,  # events + file writing only, per process
        "simulated_s_per_wall_s": n * duration_s / wall_s,
    }


def run(args: argparse.Namespace) -> int:
    """Warm up (numba compile), then measure one core and all cores."""
    import tempfile

    from flagtrack.drivers.sim.simulate import RecordingSpec, simulate_recording

    jobs = args.jobs if args.jobs > 0 else os.cpu_count() or 1
    with tempfile.TemporaryDirectory() as tmp:
        out_dir = args.out_dir or tmp
        simulate_recording(RecordingSpec(seed=999, duration_s=0.01), out_dir, name="warmup")
        one = _measure(args.n, args.duration, 1, out_dir, 1000)
        many = _measure(args.n, args.duration, jobs, out_dir, 1000)
    figures = {"one_core": one, "all_cores": many, "cpu_count": os.cpu_count()}
    if args.json:
        print(json.dumps(figures))
        return 0
    for label, row in (("1 core", one), (f"{jobs} processes", many)):
        print(
            f"{label:>12s}: {row['events']:>10d} events in {row['wall_s']:7.2f} s = "
            f"{row['events_per_s'] / 1e6:6.2f} Mev/s  ({row['simulated_s_per_wall_s']:.3f} simulated s per s; "
            f"camera alone {row['camera_events_per_s'] / 1e6:.2f} Mev/s per process)"
        )
    return 0
