"""``flagtrack bench damage``: how much of a recording with a few flipped bits the readers keep.

Each try flips 1 to 3 random bits in the body of one of the recordings (round robin; by default the
real recordings of the folder ``FLAGTRACK_SHARED_DATA`` names, where a developer has them, else a
simulated flag in EVT 3.0 and EVT 2.0), then reads it
twice: stopping at the first fault (``strict``, the events before it kept: the readers before issue 20)
and as ``flagtrack reconstruct`` now reads it (resynchronised after a corrupt stretch). ``kept`` counts
the events read back that are events of the intact file (same t, x, y, p), so an event with a wrong
time is not kept.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import warnings
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # NumPy is imported when the benchmark runs (fast --help)
    import numpy as np

COMMAND = "damage"
HELP = "events kept from recordings with 1-3 flipped bits: stopping at the first fault vs resynchronising"
DESCRIPTION = """\
Flips 1-3 random bits in recordings and counts the events each way of reading keeps: stopping at the
first fault, or resynchronising as `flagtrack reconstruct` does. More: docs/reliability.md,
docs/commands.md.
"""
REAL = Path(os.environ.get("FLAGTRACK_SHARED_DATA", Path(__file__).resolve().parents[2].parent / "shared/data/real"))
"""A developer's folder of real recordings (as the tests find it); absent in a user's clone."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of the damage benchmark."""
    parser.add_argument(
        "files",
        nargs="*",
        type=Path,
        help="RAW recordings (default: the .raw files of the folder of real recordings that $FLAGTRACK_SHARED_DATA names)",
    )
    parser.add_argument("--tries", type=int, default=186, help="damaged copies read")
    parser.add_argument("--seed", type=int, default=0, help="random seed of the flips")
    parser.add_argument("--json", action="store_true", help="print one JSON object")


def _keys(events: np.ndarray) -> np.ndarray:
    """One int64 per event (t, x, y, p), for matching events against the intact file."""
    import numpy as np

    t = events["t"].astype(np.int64)
    return (t << 23) | (events["x"].astype(np.int64) << 12) | (events["y"].astype(np.int64) << 1) | events["p"]


def _read(path: Path, strict: bool) -> tuple[np.ndarray, int, int]:
    """(events read, skipped ranges, events lost at most); ``strict``: the events before the first fault."""
    import numpy as np

    from flagtrack.daemon.core.events import empty_events
    from flagtrack.daemon.errors import FormatError
    from flagtrack.drivers.formats import open_events

    parts, skipped, at_most = [empty_events()], 0, 0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            with open_events(path, strict=strict) as reader:
                for chunk in reader:
                    parts.append(chunk.events)
                skipped, at_most = len(reader.skipped), reader.events_lost_at_most
        except FormatError:
            pass
    return np.concatenate(parts), skipped, at_most


def _sources(files: list[Path], folder: Path) -> list[Path]:
    import numpy as np

    if files:
        return files
    real = sorted(REAL.glob("*.raw")) if REAL.is_dir() else []
    if real:
        return real
    from flagtrack.drivers.formats import write_events
    from flagtrack.drivers.sim.quickline import QuickLineParams, WavyFlag, line_events

    events = np.concatenate(list(line_events(WavyFlag(), 0, 300_000, 640, 480, QuickLineParams(noise_rate_hz=1e5))))
    made = []
    for encoding in ("evt3", "evt2"):
        made.append(folder / f"sim_{encoding}.raw")
        write_events(made[-1], events, width=640, height=480, encoding=encoding)
    return made


def measure(files: list[Path], tries: int, seed: int) -> dict:
    """Flip bits ``tries`` times; the figures of both ways of reading (see the module doc)."""
    import numpy as np

    from flagtrack.drivers.formats.raw_file import RawReader

    rng = np.random.default_rng(seed)
    rows = []
    with tempfile.TemporaryDirectory(prefix="flagtrack-damage-") as tmp:
        sources = _sources(files, Path(tmp))
        intact = {}
        for path in sources:
            events, _, _ = _read(path, strict=True)
            intact[path] = (path.read_bytes(), RawReader(path).body_offset, np.sort(_keys(events)))
        damaged = Path(tmp) / "damaged.raw"
        for i in range(tries):
            path = sources[i % len(sources)]
            data, body, keys = intact[path]
            copy = bytearray(data)
            flips = int(rng.integers(1, 4))
            for _ in range(flips):
                at = int(rng.integers(body, len(copy)))
                copy[at] ^= 1 << int(rng.integers(0, 8))
            damaged.write_bytes(bytes(copy))
            row = {"file": path.name, "flips": flips}
            for mode, strict in (("stop", True), ("resync", False)):
                events, skipped, at_most = _read(damaged, strict)
                matched = int(np.isin(_keys(events), keys).sum())
                row[mode] = matched / max(len(keys), 1)
                if not strict:
                    row["skipped_ranges"], row["lost_at_most"] = skipped, at_most
                    row["lost"] = len(keys) - matched
            rows.append(row)
    return summarise(rows, [p.name for p in sources], tries, seed)


def summarise(rows: list[dict], files: list[str], tries: int, seed: int) -> dict:
    """The figures over every try, and over the tries where reading stopped short."""
    import numpy as np

    cut = [r for r in rows if r["stop"] < 0.999]
    out = {"files": files, "tries": tries, "seed": seed, "tries_cut_short_when_stopping": len(cut)}
    for mode in ("stop", "resync"):
        kept = np.array([r[mode] for r in cut]) if cut else np.ones(1)
        out[f"{mode}_kept_median_of_those"] = round(float(np.median(kept)), 4)
        out[f"{mode}_kept_min_of_those"] = round(float(kept.min()), 4)
        out[f"{mode}_tries_below_99pct"] = sum(r[mode] < 0.99 for r in rows)
    out["resync_tries_with_skips"] = sum(r["skipped_ranges"] > 0 for r in rows)
    # the bound covers the skipped ranges; another flip that decodes as another valid word changes an
    # event elsewhere without a fault, so it is checked on the tries of one flip
    out["resync_one_flip_tries_lost_beyond_bound"] = sum(
        r["flips"] == 1 and r["skipped_ranges"] > 0 and r["lost"] > r["lost_at_most"] for r in rows
    )
    out["resync_lost_events_median_of_skips"] = int(np.median([r["lost"] for r in rows if r["skipped_ranges"]] or [0]))
    out["resync_lost_at_most_median_of_skips"] = int(
        np.median([r["lost_at_most"] for r in rows if r["skipped_ranges"]] or [0])
    )
    return out


def run(args: argparse.Namespace) -> int:
    """Measure and print."""
    result = measure(list(args.files), args.tries, args.seed)
    if args.json:
        print(json.dumps(result))
        return 0
    print(f"{result['tries']} tries over {', '.join(result['files'])} (seed {result['seed']})")
    print(f"stopping at the first fault cut {result['tries_cut_short_when_stopping']} short:")
    for mode, what in (("stop", "stopping at the fault"), ("resync", "resynchronising")):
        print(
            f"  {what:>22}: median {100 * result[f'{mode}_kept_median_of_those']:.1f} % kept, "
            f"min {100 * result[f'{mode}_kept_min_of_those']:.1f} %; "
            f"{result[f'{mode}_tries_below_99pct']} of all tries below 99 %"
        )
    print(
        f"resync skipped ranges in {result['resync_tries_with_skips']} tries (median {result['resync_lost_events_median_of_skips']}"
        f" events lost, bound {result['resync_lost_at_most_median_of_skips']}); lost more than the bound in "
        f"{result['resync_one_flip_tries_lost_beyond_bound']} of the tries of one flip"
    )
    sys.stdout.flush()
    return 0
