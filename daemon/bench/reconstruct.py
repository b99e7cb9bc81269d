"""``flagtrack bench reconstruct``: events per second of the whole ``flagtrack reconstruct`` command.

Makes (once, cached) an EVT 3.0 recording of a flapping line (``drivers/sim/quickline``,
``WavyFlag`` L = 200 px at 20 Hz, about 6 Mev/s of camera data), then, pinned to one core (the
command tracks on two threads: ``--all-cores`` lets them use two):

- runs the command once to warm up (numba cache, .pyc files; the kernels built by ``flagtrack kernels
  build`` are used when there is a build: see the "kernels" line);
- times the real command end to end in a subprocess (interpreter start, imports, loading the
  compiled kernels, decoding, tracking, HDF5 writing), best of ``--repeat``, with its peak RSS;
- times the same command on a 0.1 s file: the fixed start-up cost;
- times the tracker core alone (``Tracker.feed`` on decoded chunks in memory, warm).

The paper's parameters: tau = dt = 250 us (tau/T = 5e-3), N_j = 10, alpha = 0.6, ds = L/50.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from flagtrack.daemon.bench._cores import one_core

COMMAND = "reconstruct"
HELP = "events/s of flagtrack reconstruct end to end (and of the tracker core) on a flapping-line recording"
DESCRIPTION = """\
Events/s of `flagtrack reconstruct` end to end on one core (and of the tracker core alone), with its
start-up cost and peak RSS, on a recording of a flapping line with the paper's parameters.
More: docs/tracking.md, docs/commands.md.
"""

ROOT, LENGTH, TAU_S = (100.0, 240.0), 200.0, 2.5e-4


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of the reconstruct benchmark."""
    parser.add_argument(
        "--seconds",
        type=float,
        default=6.0,
        help="recording length, s (6 s of flapping ~ 36 M events; >= 1.7 s for 10 M)",
    )
    parser.add_argument("--method", choices=("robust", "paper"), default="robust", help="tracker method")
    parser.add_argument("--format", choices=("raw", "npy"), default="raw", help="file format (raw = EVT 3.0)")
    parser.add_argument("--repeat", type=int, default=3, help="timed runs of the command (best is kept)")
    parser.add_argument("--core-events", type=int, default=10_000_000, help="events timed for the core alone")
    parser.add_argument(
        "--cache", type=Path, default=None, help="folder for the recordings (default: $TMPDIR/flagtrack-bench)"
    )
    parser.add_argument("--all-cores", action="store_true", help="do not pin to one core")
    parser.add_argument("--json", action="store_true", help="print the results as JSON")


RATE_PER_DENSITY_MEV_S = 0.305
"""Camera event rate of the flapping line per event per pixel area it sweeps (measured: 20 -> 6.1 Mev/s)."""


def make_recording(path: Path, seconds: float, seed: int = 0, rate_mev_s: float = 6.1) -> None:
    """Write ``seconds`` of a flapping line (about ``rate_mev_s`` of camera data) to ``path``,
    streaming (bounded memory)."""
    from flagtrack.drivers.atomic import atomic_path
    from flagtrack.drivers.formats import open_writer
    from flagtrack.drivers.sim.quickline import QuickLineParams, WavyFlag, line_events

    encoding = "evt3" if path.suffix == ".raw" else None
    with (
        atomic_path(path, keep_suffix=True) as tmp,
        open_writer(tmp, width=640, height=480, encoding=encoding) as writer,
    ):
        for chunk in line_events(
            WavyFlag(length=LENGTH, root=ROOT),
            0,
            int(seconds * 1e6),
            640,
            480,
            QuickLineParams(events_per_px2=rate_mev_s / RATE_PER_DENSITY_MEV_S),
            seed=seed,
            chunk_us=50_000,
        ):
            writer.write(chunk)


def _recording(cache: Path, seconds: float, fmt: str) -> Path:
    cache.mkdir(parents=True, exist_ok=True)
    path = cache / f"flapping_{seconds:g}s.{fmt}"
    if not path.is_file():
        print(f"writing {path} ...", file=sys.stderr)
        make_recording(path, seconds)
    return path


def _command(path: Path, out: Path, method: str, env: dict[str, str] | None = None) -> tuple[float, float, int]:
    """Run ``flagtrack reconstruct``; return (wall s, peak RSS MB, events)."""
    cmd = [
        sys.executable,
        "-m",
        "flagtrack.daemon",
        "reconstruct",
        str(path),
        "-o",
        str(out),
        "--root",
        str(ROOT[0]),
        str(ROOT[1]),
        "--length",
        str(LENGTH),
        "--tau",
        str(TAU_S),
        "--method",
        method,
        "--no-progress",
    ]
    with tempfile.TemporaryFile("w+") as log:
        start = time.perf_counter()
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=log, env=env)
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - start
        proc.returncode = os.waitstatus_to_exitcode(status)
        log.seek(0)
        err = log.read()
    if proc.returncode != 0:
        raise RuntimeError(f"flagtrack reconstruct failed ({proc.returncode}): {err.strip()}")
    events = int(err.split(" updates from ")[1].split()[0])
    return wall, usage.ru_maxrss / 1024, events


def _core(path: Path, method: str, max_events: int, repeat: int) -> tuple[float, int]:
    """(events/s, events) of Tracker.feed alone over decoded chunks held in memory (warm, best of repeat)."""
    from flagtrack.daemon.core.tracker import Tracker
    from flagtrack.daemon.tracking.section import Method, TrackingConfig
    from flagtrack.drivers.formats import open_events

    chunks, total = [], 0
    with open_events(path) as reader:
        for chunk in reader:
            chunks.append(chunk.events)
            total += len(chunk.events)
            if total >= max_events:
                break
    params = TrackingConfig(root=ROOT, length=LENGTH, tau_s=TAU_S, method=Method(method)).tracker_params()
    Tracker(params).feed(chunks[0][:200_000])
    best = float("inf")
    for _ in range(repeat):
        tracker = Tracker(params)
        start = time.perf_counter()
        for events in chunks:
            tracker.feed(events)
        tracker.finish()
        best = min(best, time.perf_counter() - start)
    return total / best, total


def _kernels_state() -> str:
    """Whether the command loads kernels compiled ahead of time (``flagtrack kernels build``) or numba's."""
    from flagtrack.daemon.aot.cache import build_dir, read_manifest

    return "compiled ahead of time" if read_manifest(build_dir()) is not None else "numba"


def run(args: argparse.Namespace) -> int:
    """Make (or reuse) the recording, time the command and the core, print the figures."""
    cache = args.cache or Path(tempfile.gettempdir()) / "flagtrack-bench"
    path = _recording(cache, args.seconds, args.format)
    tiny = _recording(cache, 0.1, args.format)
    with one_core(not args.all_cores) as pin, tempfile.TemporaryDirectory() as tmp:  # children inherit it
        out = Path(tmp) / "out.h5"
        # warm-up, as any earlier run of the command would: fills numba's cache and writes Python's
        # bytecode cache even where PYTHONDONTWRITEBYTECODE is set (without .pyc files, ~60
        # modules compile on each run: ~0.1 s)
        warm_env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
        _command(tiny, out, args.method, warm_env)
        startup = min(_command(tiny, out, args.method)[0] for _ in range(args.repeat))
        runs = [_command(path, out, args.method) for _ in range(args.repeat)]
        wall, rss, events = min(runs)
        core_rate, core_events = _core(path, args.method, args.core_events, args.repeat)
    result = {
        "kernels": _kernels_state(),
        "file": str(path),
        "format": args.format,
        "file_bytes": path.stat().st_size,
        "events": events,
        "method": args.method,
        "command_s": wall,
        "command_mev_s": events / wall / 1e6,
        "startup_s": startup,
        "steady_mev_s": events / max(wall - startup, 1e-9) / 1e6,
        "peak_rss_mb": rss,
        "core_mev_s": core_rate / 1e6,
        "core_events": core_events,
        "one_core": pin,
    }
    if args.json:
        print(json.dumps(result, indent=1))
    else:
        print(
            f"recording      {events / 1e6:.1f} M events, {result['file_bytes'] / 1e6:.0f} MB ({args.format}), "
            f"method {args.method}{', one core' if pin else ''}"
        )
        print(f"kernels        {result['kernels']}")
        print(f"command        {wall:.2f} s  {result['command_mev_s']:.1f} Mev/s end to end, peak RSS {rss:.0f} MB")
        print(f"start-up       {startup:.2f} s (same command on 0.1 s of data)")
        print(f"steady         {result['steady_mev_s']:.1f} Mev/s (command minus start-up)")
        print(
            f"core alone     {result['core_mev_s']:.1f} Mev/s (Tracker.feed on {core_events / 1e6:.1f} M "
            f"decoded events)"
        )
    return 0
