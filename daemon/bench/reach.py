"""``flagtrack bench reach``: how well the events' reach along the chain tells a chain's length from
the flag's, on the recordings of ``flagtrack bench geometry`` (their truth known).

Each recording is tracked from its true root and direction with the true length and with lengths
10 % short and long, and the reach sampled as ``flagtrack reconstruct`` does. At the true length the
events should end at the tip (reach 1); at 0.9 L at 1 / 0.9 of the chain, at 1.1 L at 1 / 1.1.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import asdict
from typing import Any

from flagtrack.daemon.bench.geometry import Case, add_grid_arguments, evaluate_grid

COMMAND = "reach"
HELP = "accuracy of the chain's reach (reconstruct's length warning) on simulated recordings"
FACTORS = (1.0, 0.9, 1.1)
"""Chain lengths tried, as fractions of the true one."""
CHUNK_EVENTS = 250_000


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Grid size, seed, duration, output (the grid of ``flagtrack bench geometry``)."""
    add_grid_arguments(parser)
    parser.set_defaults(run=run)


def evaluate(case: Case) -> dict[str, Any]:
    """Simulate ``case``; its reach at each of :data:`FACTORS` times its length (None: not judged)."""
    from flagtrack.daemon.bench.geometry import _Unproject, simulate
    from flagtrack.daemon.core.tracker import Tracker
    from flagtrack.daemon.tracking.reach import ReachSampler
    from flagtrack.daemon.tracking.section import TrackingConfig
    from flagtrack.daemon.tracking.setup import tracking_setup

    events, optics = simulate(case)
    row: dict[str, Any] = {"case": asdict(case), "events": len(events), "reach": {}}
    for factor in FACTORS:
        config = TrackingConfig(
            root=(float(case.root[0]), float(case.root[1])),
            length=factor * case.length,
            direction_deg=case.direction_deg,
        )
        params = tracking_setup(config).params
        tracker = Tracker(
            params, mapping=_Unproject(optics) if case.tilted else None, sensor_size=(case.width, case.height)
        )
        sampler = ReachSampler(params)
        for start in range(0, len(events), CHUNK_EVENTS):
            chunk = tracker.prepare(events[start : start + CHUNK_EVENTS])
            sampler.observe(chunk, tracker.advance(chunk))
        reach = sampler.reach()
        row["reach"][str(factor)] = None if reach is None else reach.reach
    return row


def summary(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Per length factor: the recordings judged, and the largest miss of ``reach * factor`` from 1."""
    out: dict[str, Any] = {"recordings": len(rows)}
    for factor in FACTORS:
        judged = [r["reach"][str(factor)] * factor for r in rows if r["reach"][str(factor)] is not None]
        out[str(factor)] = {
            "judged": len(judged),
            "max_miss": max((abs(v - 1.0) for v in judged), default=None),
        }
    return out


def run(args: argparse.Namespace) -> int:
    """Simulate the grid, track each recording at three lengths, print the figures."""
    rows = evaluate_grid(args, evaluate)
    figures = summary(rows)
    if args.json:
        print(json.dumps({"summary": figures, "cases": rows}))
        return 0
    for i, r in enumerate(rows):
        reaches = "  ".join(
            f"{factor:.1f} L: " + ("-" if r["reach"][str(factor)] is None else f"{r['reach'][str(factor)]:.4f}")
            for factor in FACTORS
        )
        print(f"case {i:2d} ({r['events']} events): reach at {reaches}")
    for factor in FACTORS:
        f = figures[str(factor)]
        miss = "-" if f["max_miss"] is None else f"{100 * f['max_miss']:.2f} %"
        print(
            f"chain {factor:.1f} L: {f['judged']} of {figures['recordings']} judged; "
            f"reach x {factor:.1f} off 1 by at most {miss}"
        )
    return 0
