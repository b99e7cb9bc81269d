"""``flagtrack bench fuzz --minutes M``: the fuzzing properties of the test suite, run for longer.

Every parser that takes bytes or text from outside is a target: the event-file readers (damaged files
of each format), the packet decoder, the wire-schema decoder, the rig's YAML loader, the serial
protocol parsers (the tunnel's line protocol, the sensor's line parser, Modbus RTU request frames).
A target's property: whatever the input, it is parsed or refused with flagtrack's own error type
(naming the file, key or device), within a time limit and a bounded allocation. The tests
(``tests/unit/test_fuzz_*.py``) run a few dozen cases of each; this runs hypothesis in rounds over
every target until the time is up and reports the cases run and every failure found.

Needs hypothesis (the ``dev`` extra).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

from flagtrack.daemon.errors import FlagtrackError

COMMAND = "fuzz"
HELP = "fuzz the readers, decoders, YAML loader and serial parsers for M minutes (hypothesis)"
DESCRIPTION = """\
Runs the test suite's fuzzing properties (readers, decoders, YAML loader, serial parsers) for
--minutes and reports the cases run and every failure. Needs hypothesis (the dev extra).
More: docs/reliability.md, docs/commands.md.
"""


def _round_in_child(folder: str, index: int, examples: int, deadline_s: float, seed: int) -> tuple[int, list[str], int]:
    """One round of target ``index`` in a worker process: (cases, failures, the worker's max RSS in KiB)."""
    import resource

    from flagtrack.daemon.bench.fuzz_targets import run_target, targets

    target = targets(Path(folder))[index]
    run_target(target, examples, deadline_s, seed)
    return target.cases, target.failures, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss


def fuzz(minutes: float, examples_per_round: int = 200, deadline_s: float = 10.0, seed: int = 0) -> dict:
    """Fuzz every target in rounds until ``minutes`` have passed; the cases and failures of each.

    Each round of a target runs in a worker process, so a parser that aborts the process (a Rust
    panic that cannot unwind) is a finding, not the end of the run.
    """
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor
    from concurrent.futures.process import BrokenProcessPool

    from flagtrack.daemon.bench.fuzz_targets import targets

    started = time.monotonic()
    rss: dict[int, list[int]] = {}  # max RSS of the worker after each round, KiB, by target
    with tempfile.TemporaryDirectory(prefix="flagtrack-fuzz-") as tmp:
        all_targets = targets(Path(tmp))
        context = multiprocessing.get_context("fork")
        pool = ProcessPoolExecutor(1, mp_context=context)
        rounds = 0
        while rounds == 0 or time.monotonic() - started < minutes * 60:
            for i, target in enumerate(all_targets):  # a target that failed is not run again (its finding stands)
                in_time = time.monotonic() - started < minutes * 60
                if not (rounds == 0 or (in_time and not target.failures)):
                    continue
                try:
                    cases, failures, max_rss = pool.submit(
                        _round_in_child, tmp, i, examples_per_round, deadline_s, seed + rounds
                    ).result()
                except BrokenProcessPool:
                    target.failures.append("the process aborted (a crash no exception handler can catch)")
                    pool = ProcessPoolExecutor(1, mp_context=context)
                    continue
                target.cases += cases
                target.failures += failures
                rss.setdefault(i, []).append(max_rss)
            rounds += 1
        pool.shutdown()
    worker_mb = max((max(r) for r in rss.values() if r), default=0) / 1024
    return {
        "minutes": round((time.monotonic() - started) / 60, 2),
        "rounds": rounds,
        "cases": sum(t.cases for t in all_targets),
        "targets": {t.name: {"cases": t.cases, "failures": t.failures} for t in all_targets},
        "failures": sum(len(t.failures) for t in all_targets),
        "worker_max_rss_mb": round(worker_mb, 1),
    }


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of the fuzz benchmark."""
    parser.add_argument("--minutes", type=float, default=5.0, help="how long to fuzz")
    parser.add_argument("--examples", type=int, default=200, help="cases per target per round")
    parser.add_argument("--deadline", type=float, default=10.0, help="seconds one case may take (a hang beyond)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the first round (each round adds one)")
    parser.add_argument("--json", action="store_true", help="end with one JSON object")


def run(args: argparse.Namespace) -> int:
    """Fuzz and print the cases and findings; exit 1 if something was found."""
    try:
        import hypothesis  # noqa: F401 - checked before anything runs
    except ImportError:
        raise FlagtrackError(
            "flagtrack bench fuzz needs hypothesis: pip install -e '.[dev]' in flagtrack's folder"
        ) from None
    result = fuzz(args.minutes, args.examples, args.deadline, args.seed)
    for name, figures in result["targets"].items():
        found = "; ".join(figures["failures"]) or "nothing found"
        print(f"{name:>20}: {figures['cases']:>7} cases, {found}", file=sys.stderr)
    print(
        f"{result['cases']} cases in {result['minutes']} min ({result['rounds']} rounds), {result['failures']} failure(s), "
        f"the worker's largest RSS {result['worker_max_rss_mb']} MB",
        file=sys.stderr,
    )
    if args.json:
        print(json.dumps(result))
    return 1 if result["failures"] else 0
