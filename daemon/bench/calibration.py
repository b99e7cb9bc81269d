"""``flagtrack bench calibration``: the cost of mapping every event through the calibration polynomial.

Fits a pixel -> plane polynomial (degrees 2-5) to the paper's tilted camera, then, on one core:

- times ``PolynomialMapping.map`` alone on float32 pixel arrays (the tracker's event buffer) in
  calls of ``--chunk`` events (as the tracker maps each chunk it ingests), warm, best of
  ``--repeat``, against the numpy design-matrix evaluation of the same polynomial;
- times the tracker core (``Tracker.feed``) on a flapping-line stream with no mapping and with a
  degree-``--degree`` polynomial that is a near-identity in pixels (so the tracking work is the
  same and only the mapping differs), and the time spent in the mapping's calls inside it: the
  mapping's share of the tracker's time (measured directly; the difference of the two rates is
  noisier than the share itself).
"""

from __future__ import annotations

import argparse
import json
import time

from flagtrack.daemon.bench._cores import one_core

COMMAND = "calibration"
HELP = "events/s of the calibration mapping (pixels -> metres), alone and inside the tracker"
DESCRIPTION = """\
Events/s of the calibration mapping (pixels -> metres): alone, against a numpy evaluation, and its
share of the tracker's time. More: docs/calibration.md, docs/commands.md.
"""

ROOT, LENGTH, TAU_S = (100.0, 240.0), 200.0, 2.5e-4


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of the calibration benchmark."""
    parser.add_argument("--events", type=int, default=5_000_000, help="events per timed map call (default 5 M)")
    parser.add_argument("--chunk", type=int, default=100_000, help="events per map call (default 100 k)")
    parser.add_argument("--repeat", type=int, default=5, help="timed repetitions (best kept)")
    parser.add_argument("--degree", type=int, default=3, help="degree used inside the tracker (default 3)")
    parser.add_argument(
        "--tracker-seconds",
        type=float,
        default=1.0,
        help="seconds of flapping line for the tracker comparison (default 1, ~6 M events)",
    )
    parser.add_argument("--all-cores", action="store_true", help="do not pin to one core")
    parser.add_argument("--json", action="store_true", help="print the results as JSON")


def _fit(degree: int, near_identity: bool):  # noqa: ANN202
    import numpy as np

    from flagtrack.calibration.fit import fit_mapping
    from flagtrack.drivers.sim.optics import tilted_pinhole

    jj, ii = np.mgrid[0:480:24, 0:640:32]
    u, v = ii.ravel().astype(float), jj.ravel().astype(float)
    if near_identity:  # pixels -> pixels with a small smooth distortion: same tracking work
        x, y = u + 1e-4 * (u - 320) ** 2 / 320, v - 1e-4 * (v - 240) * (u - 320) / 320
    else:
        x, y = tilted_pinhole().unproject(u, v)
    return fit_mapping(np.column_stack([u, v]), np.column_stack([x, y]), degree, (640, 480))


def _best_rate(fn, n: int, repeat: int) -> float:  # noqa: ANN001
    best = float("inf")
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - start)
    return n / best


def _map_rates(n: int, chunk: int, repeat: int) -> list[dict[str, float]]:
    import numpy as np

    rng = np.random.default_rng(0)
    x = rng.integers(0, 640, n).astype(np.float32)
    y = rng.integers(0, 480, n).astype(np.float32)
    starts = range(0, n, chunk)

    def chunked(fn) -> None:  # noqa: ANN001
        for i in starts:
            fn(x[i : i + chunk], y[i : i + chunk])

    warm = _fit(3, near_identity=False)
    for _ in range(3):  # let the pinned core and the allocator settle before the first timing
        chunked(warm.map)
    rows = []
    for degree in (2, 3, 4, 5):
        mapping = _fit(degree, near_identity=False)
        chunked(mapping.map)  # compile / load the cache, settle the allocator
        fast = _best_rate(lambda m=mapping: chunked(m.map), n, repeat)
        ref = _best_rate(lambda m=mapping: chunked(m.forward.evaluate_numpy), n, max(1, repeat // 2))
        rows.append({"degree": degree, "map_mev_s": fast / 1e6, "numpy_mev_s": ref / 1e6})
    return rows


def _tracker_rates(seconds: float, degree: int) -> dict[str, float]:
    from flagtrack.daemon.core.tracker import Tracker
    from flagtrack.daemon.tracking.section import TrackingConfig
    from flagtrack.drivers.sim.quickline import QuickLineParams, WavyFlag, line_events

    chunks = list(
        line_events(
            WavyFlag(length=LENGTH, root=ROOT),
            0,
            int(seconds * 1e6),
            640,
            480,
            QuickLineParams(events_per_px2=20),
            seed=0,
            chunk_us=50_000,
        )
    )
    total = sum(len(c) for c in chunks)
    params = TrackingConfig(root=ROOT, length=LENGTH, tau_s=TAU_S).tracker_params()
    mapping = _TimedMapping(_fit(degree, near_identity=True))
    out: dict[str, float] = {"events": total}
    for name, m in (("none", None), ("polynomial", mapping)):
        Tracker(params, mapping=m).feed(chunks[0][:200_000])  # warm-up (numba)
        best, share = float("inf"), 0.0
        for _ in range(2):
            tracker = Tracker(params, mapping=m)
            mapping.spent_s = 0.0
            start = time.perf_counter()
            for events in chunks:
                tracker.feed(events)
            tracker.finish()
            elapsed = time.perf_counter() - start
            if elapsed < best:
                best, share = elapsed, mapping.spent_s / elapsed
        out[f"tracker_{name}_mev_s"] = total / best / 1e6
    out["mapping_share"] = share
    return out


class _TimedMapping:
    """A mapping that adds up the time spent in its calls."""

    units = "px"

    def __init__(self, inner) -> None:  # noqa: ANN001
        self.inner = inner
        self.spent_s = 0.0

    def map(self, x_px, y_px):  # noqa: ANN001, ANN202 - whatever the wrapped mapping takes and gives
        start = time.perf_counter()
        out = self.inner.map(x_px, y_px)
        self.spent_s += time.perf_counter() - start
        return out


def run(args: argparse.Namespace) -> int:
    """Time the mapping alone and inside the tracker; print the figures."""
    with one_core(not args.all_cores) as pin:
        maps = _map_rates(args.events, args.chunk, args.repeat)
        tracker = _tracker_rates(args.tracker_seconds, args.degree)
    if args.json:
        print(
            json.dumps({"map": maps, "tracker": tracker, "degree_in_tracker": args.degree, "one_core": pin}, indent=1)
        )
        return 0
    for row in maps:
        print(
            f"map degree {row['degree']}   {row['map_mev_s']:7.1f} Mev/s compiled   "
            f"{row['numpy_mev_s']:6.1f} Mev/s numpy design matrix  ({args.events / 1e6:.0f} M float32 events, "
            f"{args.chunk} per call)"
        )
    print(
        f"tracker core   {tracker['tracker_none_mev_s']:.1f} Mev/s without mapping, "
        f"{tracker['tracker_polynomial_mev_s']:.1f} Mev/s with degree {args.degree} "
        f"(mapping calls: {100 * tracker['mapping_share']:.1f} % of its time), {tracker['events'] / 1e6:.1f} M events"
        f"{', one core' if pin else ''}"
    )
    return 0
