"""Run the benchmark's tasks on a process pool, with a progress bar, and collect the rows.

The clean recordings of the sweep kinematics go first: their event counts set the shot-noise rates
of part (c), whose tasks are submitted as they finish. Rows are sorted at the end, so the output
does not depend on the number of processes or the order of completion.
"""

from __future__ import annotations

import logging
import os
import sys
import time
from concurrent.futures import FIRST_COMPLETED, Executor, ProcessPoolExecutor, wait
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from flagtrack.daemon.bench.accuracy_suite import plan
from flagtrack.daemon.bench.accuracy_suite.evaluate import Outcome, run_task
from flagtrack.daemon.bench.serial_executor import SerialExecutor

log = logging.getLogger(__name__)

PARTS = ("family", "leak", "shot", "params", "lost")


@dataclass(frozen=True)
class RunSettings:
    """A benchmark run: preset, parts, methods, seed, processes, where recordings are simulated."""

    preset: plan.Preset
    parts: tuple[str, ...] = PARTS
    methods: tuple[str, ...] = tuple(plan.METHODS)
    seed: int = 0
    jobs: int = 0
    work_dir: Path = Path("recordings")
    keep_recordings: bool = False
    progress: bool = True


@dataclass
class RunResult:
    """Every row, plus the run's figures (wall time, events simulated)."""

    rows: list[dict[str, Any]] = field(default_factory=list)
    recordings: int = 0
    events: int = 0
    sim_wall_s: float = 0.0
    wall_s: float = 0.0


def initial_tasks(settings: RunSettings) -> list[plan.Task]:
    """Tasks that need nothing else first: sweep clean recordings, leak levels, the family."""
    p, m = settings.preset, settings.methods
    sweeps = any(part in settings.parts for part in ("leak", "shot", "params"))
    clean = plan.sweep_clean_tasks(settings.seed, p, m, "params" in settings.parts) if sweeps else []
    tasks = list(clean)
    if "leak" in settings.parts:
        tasks += plan.leak_tasks(clean, p, m)
    if "family" in settings.parts:
        tasks += plan.family_tasks(settings.seed, p, m)
    if "lost" in settings.parts:
        tasks += plan.lost_tasks(settings.seed, p, m)
    return tasks


def follow_up(outcome: Outcome, settings: RunSettings) -> list[plan.Task]:
    """Shot-noise tasks of a finished clean sweep recording (parts (c) and the noisy (d))."""
    if outcome.task.part != "clean" or not {"shot", "params"} & set(settings.parts):
        return []
    tasks = plan.shot_tasks(
        outcome.task,
        outcome.n_events,
        outcome.duration_s,
        settings.preset,
        settings.methods,
        "params" in settings.parts,
    )
    if "shot" not in settings.parts:
        tasks = [t for t in tasks if t.level == 20.0]
    return tasks


def run(settings: RunSettings) -> RunResult:
    """Run every task of ``settings``; return the rows sorted by part, name, method, N_j, tau."""
    from tqdm import tqdm

    started = time.perf_counter()
    settings.work_dir.mkdir(parents=True, exist_ok=True)
    jobs = settings.jobs if settings.jobs > 0 else os.cpu_count() or 1
    tasks = initial_tasks(settings)
    n_shot = len(settings.preset.shot_levels) if "shot" in settings.parts else int("params" in settings.parts)
    expected = len(tasks) + (settings.preset.n_sweep * n_shot if any(t.part == "clean" for t in tasks) else 0)
    result = RunResult()
    bar = tqdm(
        total=expected, desc="bench accuracy", unit="rec", file=sys.stderr, miniters=1, disable=not settings.progress
    )
    pool: Executor = SerialExecutor() if jobs == 1 else ProcessPoolExecutor(max_workers=jobs)
    with pool, bar:
        pending = {pool.submit(run_task, t, str(settings.work_dir), settings.keep_recordings) for t in tasks}
        while pending:
            done, pending = wait(pending, return_when=FIRST_COMPLETED)
            for future in done:
                outcome = future.result()
                result.rows.extend(outcome.rows)
                result.recordings += 1
                result.events += outcome.n_events
                result.sim_wall_s += outcome.sim_wall_s
                bar.update(1)
                for task in follow_up(outcome, settings):
                    pending.add(pool.submit(run_task, task, str(settings.work_dir), settings.keep_recordings))
    result.rows.sort(key=lambda r: (r["part"], r["name"], r["method"], r["joints"], r["tau_over_t"]))
    result.wall_s = time.perf_counter() - started
    return result
