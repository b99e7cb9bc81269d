"""Run every task of ``flagtrack bench verdicts`` on a process pool, with a progress bar: each
recording is made (unless cached) before the runs that track it; the still case is one task."""

from __future__ import annotations

import os
import sys
import time
from concurrent.futures import FIRST_COMPLETED, Executor, Future, ProcessPoolExecutor, wait
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from flagtrack.daemon.bench import verdict_recordings as recordings
from flagtrack.daemon.bench import verdict_runs as runs
from flagtrack.daemon.bench.serial_executor import SerialExecutor


@dataclass(frozen=True)
class Settings:
    """What to run.

    Attributes:
        cases: of ``verdicts.CASES``.
        seeds: kinematics seeds.
        periods: flapping periods of each recording.
        still_profile: the twin's speed profile (``full`` or ``quick``).
        folder: where the recordings are kept (made once).
        jobs: processes.
        progress: draw a progress bar.
    """

    cases: tuple[str, ...]
    seeds: tuple[int, ...]
    periods: float
    still_profile: str
    folder: Path
    jobs: int = 1
    progress: bool = False


@dataclass
class Outcome:
    """The rows of every run, the still case's figures (None when not run), the wall time."""

    rows: list[dict[str, Any]] = field(default_factory=list)
    still: dict[str, Any] | None = None
    wall_s: float = 0.0


def run_all(settings: Settings) -> Outcome:
    """Make the recordings, run and score every run, evaluate the still case."""
    from tqdm import tqdm

    from flagtrack.daemon.bench import verdict_still

    started = time.perf_counter()
    specs = runs.plan(settings.cases, settings.seeds, settings.periods)
    needs: dict[str, list[runs.RunSpec]] = {}
    for spec in specs:
        needs.setdefault(spec.key, []).append(spec)
    outcome = Outcome()
    total = len(needs) + len(specs) + ("still" in settings.cases)
    bar = tqdm(total=total, desc="bench verdicts", unit="task", file=sys.stderr, disable=not settings.progress)
    pool: Executor = SerialExecutor() if settings.jobs <= 1 else ProcessPoolExecutor(max_workers=settings.jobs)
    with pool, bar:
        tasks: dict[Future, Any] = {}
        if "still" in settings.cases:  # the longest task: first
            tasks[pool.submit(verdict_still.evaluate, settings.folder, settings.still_profile)] = "still"
        for key, spec_list in needs.items():
            spec = spec_list[0]
            tasks[pool.submit(recordings.ensure, settings.folder, spec.generator, spec.seed, spec.periods)] = key
        while tasks:
            done, _ = wait(set(tasks), return_when=FIRST_COMPLETED)
            for future in done:
                kind = tasks.pop(future)
                bar.update(1)
                if kind == "still":
                    outcome.still = future.result()
                elif isinstance(kind, runs.RunSpec):
                    outcome.rows.append(future.result())
                    bar.set_postfix_str(kind.name, refresh=False)
                else:  # a recording is ready: its runs can start
                    future.result()
                    tasks |= {pool.submit(runs.run_one, spec, settings.folder): spec for spec in needs[kind]}
    order = {spec.name: k for k, spec in enumerate(specs)}
    outcome.rows.sort(key=lambda row: order[row["name"]])
    outcome.wall_s = time.perf_counter() - started
    return outcome


def default_jobs() -> int:
    """All cores."""
    return os.cpu_count() or 1
