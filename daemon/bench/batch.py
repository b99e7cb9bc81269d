"""``flagtrack bench batch``: what ``flagtrack batch reconstruct`` gains over one ``flagtrack reconstruct``
process per file, and what the Dask path costs per file against the local pool.

Makes (once, cached) ``--files`` EVT 3.0 recordings of a flapping line (``drivers/sim/quickline``,
the recording of ``bench reconstruct``, ~6 Mev/s of camera data, one seed each) and, in one run, times
as real commands in subprocesses (wall clock, fresh output folders, the numba cache warmed first):

- a shell-style loop of ``flagtrack reconstruct`` over the files, one process per file;
- ``flagtrack batch reconstruct`` of the folder with ``--jobs 1`` and ``--jobs 2`` (local pool);
- the same with ``--scheduler local:2`` (a Dask ``LocalCluster``), where Dask is installed;
- the fixed and per-file costs of each executor: batches of 1 and of ``--tiny`` recordings of 10 ms
  (per file = the difference divided by the extra files; fixed = the one-file batch).

Every configuration runs once per round (``--repeat`` rounds, interleaved, so a change in the machine's
load falls on all of them) and its best time is kept.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

COMMAND = "batch"
HELP = "flagtrack batch (pool and Dask) against one flagtrack reconstruct per file; Dask's per-file cost"
DESCRIPTION = """\
Times `flagtrack batch reconstruct` (local pool, and Dask where installed) against one
`flagtrack reconstruct` process per file, and each executor's fixed and per-file cost.
More: docs/batch.md, docs/commands.md.
"""

ROOT, LENGTH, TAU_S = (100.0, 240.0), 200.0, 2.5e-4
TINY_S = 0.01
TRACK = ["--root", str(ROOT[0]), str(ROOT[1]), "--length", str(LENGTH), "--tau", str(TAU_S)]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of the batch benchmark."""
    parser.add_argument("--files", type=int, default=8, help="recordings in the campaign (default 8)")
    parser.add_argument("--seconds", type=float, default=0.85, help="length of each recording, s (0.85 s ~ 5 M events)")
    parser.add_argument("--tiny", type=int, default=48, help="10 ms recordings for the per-file cost (default 48)")
    parser.add_argument("--repeat", type=int, default=3, help="rounds; the best time of each configuration is kept")
    parser.add_argument("--no-dask", action="store_true", help="leave the Dask path out")
    parser.add_argument(
        "--cache", type=Path, default=None, help="folder for the recordings (default: $TMPDIR/flagtrack-bench/batch)"
    )
    parser.add_argument("--json", action="store_true", help="print the results as JSON")


def _recordings(folder: Path, count: int, seconds: float) -> Path:
    """``folder`` holding ``count`` recordings of ``seconds`` (made once; other files removed)."""
    from flagtrack.daemon.bench.reconstruct import make_recording

    folder.mkdir(parents=True, exist_ok=True)
    wanted = {f"flapping_{i:03d}.raw" for i in range(count)}
    for stale in folder.iterdir():
        if stale.name not in wanted:
            stale.unlink()
    for i in range(count):
        path = folder / f"flapping_{i:03d}.raw"
        if not path.is_file():
            print(f"writing {path} ...", file=sys.stderr)
            make_recording(path, seconds, seed=i)
    return folder


def _flagtrack(*args: str) -> float:
    """Wall seconds of ``flagtrack ARGS`` in a subprocess (raises if it fails)."""
    start = time.perf_counter()
    proc = subprocess.run(
        [sys.executable, "-m", "flagtrack.daemon", *args], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True
    )
    wall = time.perf_counter() - start
    if proc.returncode != 0:
        raise RuntimeError(f"flagtrack {' '.join(args[:2])} failed ({proc.returncode}): {proc.stderr.strip()[-500:]}")
    return wall


def _batch(folder: Path, out: Path, *executor: str) -> tuple[float, int, float]:
    """(wall s, events, sum of the rows' seconds) of one ``flagtrack batch reconstruct`` into a fresh ``out``."""
    shutil.rmtree(out, ignore_errors=True)
    wall = _flagtrack("batch", "reconstruct", str(folder), "-o", str(out), *TRACK, *executor, "--no-progress")
    rows = json.loads((out / "batch.json").read_text())["rows"]
    if any(r["status"] != "done" for r in rows):
        raise RuntimeError(f"flagtrack batch did not do every file: {[r for r in rows if r['status'] != 'done']}")
    return wall, sum(r["events"] for r in rows), sum(r["seconds"] for r in rows)


def run(args: argparse.Namespace) -> int:
    """Make (or reuse) the recordings, time the loop and the batches, print the figures."""
    cache = args.cache or Path(tempfile.gettempdir()) / "flagtrack-bench" / "batch"
    campaign = _recordings(cache / f"campaign_{args.files}x{args.seconds:g}s", args.files, args.seconds)
    tiny_many = _recordings(cache / f"tiny_{args.tiny}x{TINY_S:g}s", args.tiny, TINY_S)
    tiny_one = _recordings(cache / f"tiny_1x{TINY_S:g}s", 1, TINY_S)
    dask = not args.no_dask and importlib.util.find_spec("distributed") is not None
    executors = {"pool:1": ["--jobs", "1"], "pool:2": ["--jobs", "2"]}
    if dask:
        executors["dask local:2"] = ["--scheduler", "local:2"]
    files = sorted(campaign.iterdir())
    load_start = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    loop_s = float("inf")
    results: dict[str, dict[str, float]] = {}
    costs: dict[str, dict[str, float]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        # warm-up: numba's cache and Python's bytecode, as any earlier run would have left them
        _flagtrack("reconstruct", str(files[0]), "-o", str(out / "warm.h5"), *TRACK, "--no-progress")
        _batch(tiny_one, out / "warm", "--jobs", "1")
        for _ in range(args.repeat):  # rounds: every configuration once per round, the best of each kept
            start = time.perf_counter()
            for path in files:
                _flagtrack("reconstruct", str(path), "-o", str(out / f"{path.stem}.h5"), *TRACK, "--no-progress")
            loop_s = min(loop_s, time.perf_counter() - start)
            for name, option in executors.items():
                wall, events, work = _batch(campaign, out / "batch", *option)
                if name not in results or wall < results[name]["wall_s"]:
                    results[name] = {"wall_s": wall, "events": events, "work_s": work}
                if name == "pool:1":
                    continue
                one = _batch(tiny_one, out / "tiny", *option)[0]
                many = _batch(tiny_many, out / "tiny", *option)[0]
                best = costs.setdefault(name, {"fixed_s": one, "many_s": many})
                best["fixed_s"], best["many_s"] = min(best["fixed_s"], one), min(best["many_s"], many)
    for r in results.values():
        r["speedup_over_loop"] = loop_s / r["wall_s"]
    for c in costs.values():
        c["per_file_s"] = (c["many_s"] - c["fixed_s"]) / (args.tiny - 1)
    events = int(results["pool:1"]["events"])
    load = os.getloadavg() if hasattr(os, "getloadavg") else (float("nan"),) * 3
    result = {
        "files": len(files),
        "events": events,
        "bytes": sum(p.stat().st_size for p in files),
        "loop_s": loop_s,
        "batch": results,
        "tiny_files": args.tiny,
        "repeat": args.repeat,
        "costs": costs,
        "cores": len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count(),
        "load_average": [load_start, load[0]],
    }
    if args.json:
        print(json.dumps(result, indent=1))
        return 0
    print(
        f"campaign       {len(files)} recordings, {events / 1e6:.1f} M events, {result['bytes'] / 1e6:.0f} MB "
        f"(EVT 3.0); {result['cores']} cores, load {load_start:.1f} -> {load[0]:.1f}, best of {args.repeat}"
    )
    print(f"{'reconstruct loop':<16} {loop_s:6.2f} s  {events / loop_s / 1e6:5.2f} Mev/s  1.00x")
    for name, r in results.items():
        print(
            f"{'batch ' + name:<16} {r['wall_s']:6.2f} s  {events / r['wall_s'] / 1e6:5.2f} Mev/s  "
            f"{r['speedup_over_loop']:.2f}x  (work in the tasks {r['work_s']:.2f} s)"
        )
    for name, c in costs.items():
        print(
            f"{name:<16} fixed {c['fixed_s']:.2f} s (a one-file batch), {1e3 * c['per_file_s']:.0f} ms per 10 ms file"
        )
    if "dask local:2" in costs:
        extra = costs["dask local:2"]["per_file_s"] - costs["pool:2"]["per_file_s"]
        print(
            f"Dask over the pool: {1e3 * extra:+.0f} ms per file, {costs['dask local:2']['fixed_s'] - costs['pool:2']['fixed_s']:+.2f} s fixed"
        )
    return 0
