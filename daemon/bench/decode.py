"""``flagtrack bench decode``: events per second decoding EVT 2.0 and EVT 3.0 RAW files.

Makes a recording of a flapping line (``drivers/sim/quickline``, about 6 Mev/s of camera data),
writes it as EVT 2.0 and EVT 3.0 with flagtrack's writer into a cache folder, then times, on one
core, flagtrack's streaming reader over each file (chunks of EVENT_DTYPE arrays) against the
maintained PyPI decoders on the same file (``evt3`` for EVT 3.0, ``faery`` for both), best of
``--repeat`` passes. Every decoder is first checked to give exactly the written events; the
ratio is against the fastest exact one.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from collections.abc import Callable
from pathlib import Path

from flagtrack.daemon.bench._cores import one_core

COMMAND = "decode"
HELP = "events/s decoding EVT 2.0 / 3.0 files: flagtrack's streaming reader vs the fastest PyPI decoder"
DESCRIPTION = """\
Events/s of flagtrack's streaming EVT 2.0 / 3.0 reader against the fastest exact PyPI decoder, on
one core, on a recording of a flapping line. More: docs/formats.md, docs/commands.md.
"""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of the decode benchmark."""
    parser.add_argument("--events", type=int, default=6_000_000, help="events in the recording (>= 5e6 for the report)")
    parser.add_argument("--repeat", type=int, default=5, help="timed passes per decoder (best is kept)")
    parser.add_argument(
        "--cache",
        type=Path,
        default=None,
        help="folder for the recordings (default: $XDG_CACHE_HOME/flagtrack/bench or ~/.cache/flagtrack/bench)",
    )
    parser.add_argument("--all-cores", action="store_true", help="do not pin the process to one core")
    parser.add_argument("--json", action="store_true", help="print the results as JSON")


def _cache_dir(given: Path | None) -> Path:
    if given is not None:
        return given
    base = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache"))
    return base / "flagtrack" / "bench"


def make_recording(n_events: int, seed: int = 0):  # noqa: ANN201
    """At least ``n_events`` events of a flapping line on a 640x480 sensor, about 6 Mev/s."""
    import numpy as np

    from flagtrack.drivers.sim.quickline import QuickLineParams, WavyFlag, line_events

    parts, total = [], 0
    for chunk in line_events(WavyFlag(), 0, 3_600_000_000, 640, 480, QuickLineParams(events_per_px2=20), seed=seed):
        parts.append(chunk)
        total += len(chunk)
        if total >= n_events:
            break
    return np.concatenate(parts)[:n_events]


def _files(n_events: int, cache: Path):  # noqa: ANN202
    """The recording (events) and its EVT 2.0 / 3.0 files, written once per size."""
    import numpy as np

    from flagtrack.drivers.formats import write_events

    cache.mkdir(parents=True, exist_ok=True)
    events = make_recording(n_events)
    paths = {enc: cache / f"flapping_{n_events}_{enc}.raw" for enc in ("evt2", "evt3")}
    stamp = cache / f"flapping_{n_events}.sum"
    digest = str(int(np.bitwise_xor.reduce(events["t"] * 31 + events["x"].astype(np.int64) * 7 + events["y"])))
    if not stamp.is_file() or stamp.read_text() != digest or not all(p.is_file() for p in paths.values()):
        for enc, path in paths.items():
            write_events(path, events, width=640, height=480, encoding=enc)
        stamp.write_text(digest)
    return events, paths


def _ours(path: Path):  # noqa: ANN202
    from flagtrack.drivers.formats import open_events

    def full():  # noqa: ANN202
        import numpy as np

        with open_events(path) as reader:
            return np.concatenate([c.events for c in reader])

    def count() -> int:
        with open_events(path) as reader:
            return sum(len(c.events) for c in reader)

    return full, count


def _evt3_lib(path: Path):  # noqa: ANN202
    import evt3
    import numpy as np

    def full():  # noqa: ANN202
        parts = [
            (b.timestamp.copy(), b.x.copy(), b.y.copy(), b.polarity.copy()) for b in evt3.decode_file_batches(str(path))
        ]
        return tuple(np.concatenate([p[i] for p in parts]) for i in range(4))

    def count() -> int:
        return sum(len(b.x) for b in evt3.decode_file_batches(str(path)))

    return full, count


def _faery(path: Path):  # noqa: ANN202
    import faery
    import numpy as np

    def packets():  # noqa: ANN202
        with faery.evt.Decoder(str(path), None, None) as decoder:
            for packet in decoder:
                if "events" in packet:
                    yield packet["events"]

    def full():  # noqa: ANN202
        ev = np.concatenate(list(packets()))
        return ev["t"], ev["x"], ev["y"], ev["on"]

    def count() -> int:
        return sum(len(ev) for ev in packets())

    return full, count


def _exact(result, events) -> bool:  # noqa: ANN001
    import numpy as np

    if isinstance(result, np.ndarray):
        result = (result["t"], result["x"], result["y"], result["p"])
    t, x, y, p = result
    return (
        len(t) == len(events)
        and np.array_equal(np.asarray(t, np.int64), events["t"])
        and np.array_equal(x, events["x"])
        and np.array_equal(y, events["y"])
        and np.array_equal(np.asarray(p, np.uint8), events["p"])
    )


def _best_rates(counters: dict[str, Callable[[], int]], repeat: int) -> dict[str, float]:
    """Events/s of each counter, best of ``repeat`` rounds; rounds interleave the decoders so
    that load from other processes falls on all of them alike."""
    best = dict.fromkeys(counters, float("inf"))
    counts = {}
    for _ in range(repeat):
        for name, count in counters.items():
            start = time.perf_counter()
            counts[name] = count()
            best[name] = min(best[name], time.perf_counter() - start)
    return {name: counts[name] / best[name] for name in counters}


def _measure(encoding: str, path: Path, events, repeat: int) -> dict:  # noqa: ANN001
    """Check every decoder for exactness on ``path``, then time them together."""
    makers = {"flagtrack": _ours, "evt3": _evt3_lib, "faery": _faery}
    if encoding != "evt3":
        del makers["evt3"]
    exact, counters = {}, {}
    for name, make in makers.items():
        try:
            full, count = make(path)
        except ImportError:
            continue
        exact[name] = _exact(full(), events)
        counters[name] = count
    rates = _best_rates(counters, repeat)
    refs = {k: {"mev_s": rates[k] / 1e6, "exact": exact[k]} for k in counters if k != "flagtrack"}
    exact_refs = [k for k, v in refs.items() if v["exact"]]
    best = max(exact_refs, key=lambda k: refs[k]["mev_s"]) if exact_refs else None
    ours = rates["flagtrack"] / 1e6
    return {
        "encoding": encoding,
        "events": len(events),
        "file_bytes": path.stat().st_size,
        "flagtrack_mev_s": ours,
        "flagtrack_exact": exact["flagtrack"],
        "reference": best,
        "reference_mev_s": refs[best]["mev_s"] if best else None,
        "ratio": ours / refs[best]["mev_s"] if best else None,
        "all_references": refs,
    }


def run(args: argparse.Namespace) -> int:
    """Make (or reuse) the recordings, time every decoder, print the table."""
    with one_core(not args.all_cores):  # one core, as the target says
        events, paths = _files(args.events, _cache_dir(args.cache))
        rows = [_measure(encoding, path, events, args.repeat) for encoding, path in paths.items()]
    _print(rows, args.json)
    return 0 if all(r["flagtrack_exact"] for r in rows) else 1


def _print(rows: list[dict], as_json: bool) -> None:
    if as_json:
        print(json.dumps(rows, indent=1))
        return
    print(
        f"{'encoding':8} {'events':>10} {'flagtrack Mev/s':>16} {'reference':>10} {'ref Mev/s':>10} {'ratio':>6}  others"
    )
    for r in rows:
        others = ", ".join(
            f"{k} {v['mev_s']:.1f}{'' if v['exact'] else ' (NOT exact)'}"
            for k, v in r["all_references"].items()
            if k != r["reference"]
        )
        ref = f"{r['reference_mev_s']:10.1f} {r['ratio']:6.2f}" if r["reference"] else f"{'-':>10} {'-':>6}"
        exact = "" if r["flagtrack_exact"] else " (NOT exact)"
        print(
            f"{r['encoding']:8} {r['events']:10d} {r['flagtrack_mev_s']:16.1f} {r['reference'] or '-':>10} {ref}  "
            f"{others}{exact}"
        )
    sys.stdout.flush()
